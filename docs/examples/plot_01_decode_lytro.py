"""
Decode a Lytro Illum capture
============================

lfproc's virtual Illum renders a light field through the camera's hexagonal microlens array
(vignetting, Bayer GRBG, photon and read noise, 10-bit packing) and writes real Illum files:
``.LFR`` captures and the camera's calibration data (white images). Here we make a small
virtual bracket (800 x 600 sensor crop, three exposures 2 EV apart) of a synthetic HDR scene,
build the white-image database, decode every capture into 5 x 5 views, and compare the 0 EV
decode and the merged bracket with the views the camera saw.

Command line: ``lfproc virtual-illum``, ``lfproc whites``, ``lfproc decode``, ``lfproc merge``
(see :doc:`/guide/lytro`).
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lfproc.io import read_lightfield
from lfproc.lytro import build_white_db, decode_capture, make_virtual_illum, read_capture, score_decode
from lfproc.lytro.score import clip_level
from lfproc.hdr import merge_lightfields
from lfproc.preview import tonemap
from lfproc.synth import synthesize

work = Path(tempfile.mkdtemp())
scene = synthesize("layers", size=(48, 64), views=5, random_state=1)

# %%
# The virtual camera writes one ``IMG_nnnn.LFR`` per exposure, ``caldata-<serial>.tar`` and the
# views a perfect decoder would return for the 0 EV capture (``truth.exr``).
info = make_virtual_illum(scene, work / "cam", sensor="small", exposures_ev=(-2, 0, 2), random_state=1)
print(sorted(p.name for p in (work / "cam").iterdir()))

# %%
# The white-image database holds each white image with its estimated lenslet grid; the decoder
# picks the white image that matches the capture.
db = build_white_db(work / "cam" / info["caldata"], work / "whites")
grid = db.entries[0].grid
print(f"{len(db.entries)} white images; lenslet spacing {grid.spacing_x_px:.3f} px, "
      f"rotation {grid.rotation_rad:.2e} rad")

decoded = [decode_capture(work / "cam" / c["file"], white_db=work / "whites") for c in info["captures"]]
zero_ev = decoded[[c["file"] for c in info["captures"]].index(info["truth_capture"])]
print(zero_ev)

# %%
# Score the 0 EV decode as :mod:`lfproc.lytro.score` does (linear PSNR with the truth's 99.9th
# percentile as peak, the samples the capture clipped left out, a 4-pixel border excluded).
# One exposure of this scene (a sun about 500 times brighter than the rest) is noisy in the
# dark; merging the bracket (stage 2, :doc:`/guide/merge`) fixes that. The merge is a radiance
# per second: multiplied by the 0 EV exposure time it is comparable with the truth.
truth = read_lightfield(work / "cam" / "truth.exr")
scores = score_decode(zero_ev.data, truth.data, clip=clip_level(info))
print({k: round(v, 2) for k, v in scores.items() if k.startswith("psnr")})
hdr, _ = merge_lightfields(decoded, method="ml", profile="illum")
t0 = next(c["exposure_s"] for c in info["captures"] if c["exposure_ev"] == 0)

# %%
# The raw lenslet image around its brightest spot (the hexagonal micro-images), the decoded
# centre view, the merged bracket and the truth, at the truth's tone curve.
raw = read_capture(work / "cam" / info["truth_capture"]).raw
y, x = np.unravel_index(np.argmax(raw), raw.shape)
y, x = min(max(y, 40), raw.shape[0] - 40), min(max(x, 40), raw.shape[1] - 40)
ref = truth.centre()
panels = [(raw[y - 40:y + 40, x - 40:x + 40], "raw lenslet image (crop)"),
          (tonemap(zero_ev.centre(), reference=ref), f"decoded 0 EV\n{scores['psnr_centre_db']:.1f} dB linear PSNR"),
          (tonemap(hdr.centre() * t0, reference=ref), "merged bracket\n(-2, 0, +2 EV)"),
          (tonemap(ref, reference=ref), "truth (what the camera saw)")]
fig, ax = plt.subplots(1, 4, figsize=(13, 3.4))
for a, (image, title) in zip(ax, panels):
    a.imshow(image, cmap="gray" if image.ndim == 2 else None)
    a.set_title(title)
    a.axis("off")
fig.tight_layout()
