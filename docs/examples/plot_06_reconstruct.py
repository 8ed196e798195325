"""
Reconstruct a light field: dictionary and Gaussian patch models
===============================================================

Two coded shots of a small HDR scene are reconstructed with lfproc's two methods:

* ``method="dictionary"`` (:func:`lfproc.recon.reconstruct`): a weighted lasso per patch over
  the shipped HDR dictionary, solved by ADMM;
* ``method="gmm"`` (:func:`lfproc.recon.reconstruct_gmm`): disparity-sheared Gaussian patch
  models (a patch is the centre view's patch translated per view), the most likely
  (disparity, scale) per patch.

See :doc:`/guide/reconstruction`. Command line: ``lfproc reconstruct shot.capture.npz -o
recon.exr --method gmm|dictionary`` (the default, ``auto``, takes ``gmm`` for a
periodic random mask such as this one).
"""

import time

import matplotlib.pyplot as plt

from lfproc.camera import simulate_capture
from lfproc.metrics import evaluate
from lfproc.preview import tonemap
from lfproc.recon import reconstruct, reconstruct_gmm
from lfproc.synth import synthesize

scene = synthesize("layers", size=(48, 48), views=5, random_state=1)
capture = simulate_capture(scene, profile="paper-medium", shots=2, random_state=1)

results = {}
for name, method in (("dictionary", reconstruct), ("gmm", reconstruct_gmm)):
    t0 = time.perf_counter()
    out = method(capture, threads=2)
    scores = evaluate(out, scene)
    results[name] = out
    print(f"{name:>10}: PU21-PSNR {scores['pu21_psnr_db']:.2f} dB, PU21-SSIM {scores['pu21_ssim']:.3f}, "
          f"{time.perf_counter() - t0:.1f} s")

# %%
# The result is in the units of the scene (the capture's radiance scale is divided out) and
# records every parameter in ``attrs["reconstruction"]``.
print({k: results["dictionary"].attrs["reconstruction"][k] for k in ("solver", "patches", "stride")})

# %%
# Centre views at the truth's tone curve, and an epipolar image of each (the slopes are the
# disparities).
ref = scene.centre()
fig, ax = plt.subplots(2, 3, figsize=(10, 5.5), gridspec_kw={"height_ratios": [4, 1]})
for col, (title, lf) in enumerate([("truth", scene)] + list(results.items())):
    ax[0, col].imshow(tonemap(lf.centre(), reference=ref))
    ax[0, col].set_title(title)
    ax[1, col].imshow(tonemap(lf.epi(), reference=ref), aspect="auto")
    for a in ax[:, col]:
        a.axis("off")
fig.tight_layout()
