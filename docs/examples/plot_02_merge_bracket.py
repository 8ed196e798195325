"""
Merge an exposure bracket into HDR
==================================

An 8-bit bracket of a synthetic HDR scene (a camera-like response, photon and read noise,
8-bit rounding and a JPEG round trip, :func:`lfproc.hdr.simulate_ldr_bracket`) is merged
with Debevec and Malik's estimator, which also recovers the camera response, and with the
noise-aware ML estimator (:doc:`/guide/merge`).

Command line: ``lfproc merge IMG_*.jpg --method ml -o hdr.exr`` (exposure times from EXIF or
``--exposures-file``).
"""

import matplotlib.pyplot as plt
import numpy as np

from lfproc.hdr import simulate_ldr_bracket
from lfproc.hdr import merge_debevec, merge_ml_codes8
from lfproc.preview import tonemap
from lfproc.synth import synthesize

radiance = synthesize("lamps", size=(96, 128), views=1, random_state=2).centre()
exposures = [1 / 64, 1 / 16, 1 / 4, 1.0]
images, truth = simulate_ldr_bracket(radiance, exposures, random_state=0)
print(images.shape, images.dtype, f"scene: {np.log2(radiance.max() / radiance[radiance > 0].min()):.1f} stops")

# %%
# Merge: both estimators return radiance per second (up to one unknown scale for 8-bit data).
hdr_debevec, info = merge_debevec(images, exposures_s=exposures, random_state=0)
hdr_ml, variance, _ = merge_ml_codes8(images, exposures_s=exposures, random_state=0)


def log_error(estimate):
    """RMS ln-luminance error after fitting the one unknown scale, over the pixels well exposed
    (codes 8..247) in at least one shot: the pixels any merge can recover."""
    ok = truth["well_exposed"] & (estimate.sum(-1) > 0)
    d = np.log(estimate.sum(-1)[ok]) - np.log(radiance.sum(-1)[ok])
    return float(np.sqrt(np.mean((d - np.median(d)) ** 2)))


print(f"{truth['well_exposed'].mean():.0%} of the pixels are well exposed in some shot")
print(f"RMS ln error: debevec {log_error(hdr_debevec):.3f}, ml {log_error(hdr_ml):.3f}")

# %%
# The bracket, the merged HDR image at one tone curve, and the recovered response.
fig, ax = plt.subplots(1, len(exposures) + 2, figsize=(14, 2.8))
for a, img, t in zip(ax, images, exposures):
    a.imshow(img)
    a.set_title(f"{t:g} s" if t >= 1 else f"1/{1 / t:g} s")
    a.axis("off")
ax[-2].imshow(tonemap(hdr_ml))
ax[-2].set_title("ML merge")
ax[-2].axis("off")
g = info["response"]  # log exposure for each code and channel
for c, colour in enumerate("rgb"):
    ax[-1].plot(g[:, c] - g[128, c], color=colour, lw=1)  # g(128) = 0, as the true curve
ax[-1].plot(truth["response_g"], "k--", lw=1, label="true")
ax[-1].legend()
ax[-1].set_xlabel("code")
ax[-1].set_ylabel("g(z) = ln f^-1(z)")
ax[-1].set_title("recovered response")
fig.tight_layout()
