"""
Decode a Lytro Illum capture
============================

lfproc's virtual Illum renders a light field through the camera's hexagonal microlens array
(vignetting, Bayer GRBG, photon and read noise, 10-bit packing) and writes real Illum files:
``.LFR`` captures and the camera's calibration data (white images). Here we make a small
virtual capture (800 x 600 sensor crop) of a synthetic scene, build the white-image database,
decode the capture into 5 x 5 views and compare with the views the camera saw.

Command line: ``lfproc virtual-illum``, ``lfproc whites``, ``lfproc decode``
(see :doc:`/guide/lytro`).
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lfproc.lytro.decode import decode_capture
from lfproc.lytro.score import clip_level, score_decode
from lfproc.lytro.virtual import make_virtual_illum
from lfproc.lytro.whites import build_white_db
from lfproc.preview import tonemap
from lfproc.synth import synthesize

work = Path(tempfile.mkdtemp())
scene = synthesize("layers", size=(48, 64), views=5, random_state=1)

# %%
# The virtual camera writes one ``IMG_nnnn.LFR`` per exposure, ``caldata-<serial>.tar`` and the
# views a perfect decoder would return (``truth.exr``).
info = make_virtual_illum(scene, work / "cam", sensor="small", exposures_ev=(0,), seed=1)
print(sorted(p.name for p in (work / "cam").iterdir()))

# %%
# The white-image database holds each white image with its estimated lenslet grid; the decoder
# picks the white image that matches the capture.
db = build_white_db(work / "cam" / info["caldata"], work / "whites")
grid = db.entries[0].grid
print(f"{len(db.entries)} white images; lenslet spacing {grid.spacing_x_px:.3f} px, "
      f"rotation {grid.rotation_rad:.2e} rad")

decoded = decode_capture(work / "cam" / info["truth_capture"], white_db=work / "whites")
print(decoded)

# %%
# Score against the truth as :mod:`lfproc.lytro.score` does (linear PSNR, the samples the
# capture clipped left out, a 4-pixel border excluded) and show the raw lenslet image, the
# decoded centre view and the truth at one tone curve.
from lfproc.io import read_lightfield
from lfproc.lytro import read_capture

truth = read_lightfield(work / "cam" / "truth.exr")
scores = score_decode(decoded.data, truth.data, clip=clip_level(info))
print({k: round(v, 2) for k, v in scores.items() if k.startswith("psnr")})

raw = read_capture(work / "cam" / info["truth_capture"]).raw
fig, ax = plt.subplots(1, 3, figsize=(11, 3.4))
ax[0].imshow(raw[250:330, 350:450], cmap="gray")
ax[0].set_title("raw lenslet image (crop)")
ref = truth.centre()
ax[1].imshow(tonemap(decoded.centre()[:, :, :3], reference=ref))
ax[1].set_title(f"decoded centre view\n{scores['psnr_centre_db']:.1f} dB")
ax[2].imshow(tonemap(ref, reference=ref))
ax[2].set_title("truth (what the camera saw)")
for a in ax:
    a.axis("off")
fig.tight_layout()
