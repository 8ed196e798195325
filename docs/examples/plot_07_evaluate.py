"""
Evaluate an HDR result with an error map
========================================

:func:`lfproc.metrics.evaluate` scores a light field against a reference with HDR metrics:
PU21-PSNR and PU21-SSIM (the PU21 encoding of Mantiuk and Azimi), PU2-PSNR, log-PSNR, a linear
PSNR and the mean relative error; :func:`lfproc.metrics.hdr_figures` adds the median error in
stops per decade of luminance. :func:`lfproc.preview.render_error_map` draws the centre view's
error in stops. See :doc:`/guide/evaluation`.

Command line: ``lfproc evaluate recon.exr scene.exr --error-map err.png``.
"""

import matplotlib.pyplot as plt

from lfproc.camera.capture import noise_floor
from lfproc.camera import simulate_capture
from lfproc.metrics import evaluate, hdr_figures
from lfproc.preview import render_error_map, tonemap
from lfproc.recon import reconstruct
from lfproc.synth import synthesize

scene = synthesize("window", size=(48, 48), views=5, random_state=4)
capture = simulate_capture(scene, profile="paper-medium", shots=2, random_state=4)
result = reconstruct(capture, threads=2)

scores = evaluate(result, scene)
for key in ("pu21_psnr_db", "pu21_ssim", "pu2_psnr_db", "log_psnr_db", "linear_psnr_db", "mean_relative_error"):
    print(f"{key:>20}: {scores[key]:.3f}")

# %%
# Per decade of the reference luminance (above the capture's noise floor): how far, in stops,
# the result is from the truth.
figures = hdr_figures(result, scene, noise_floor=noise_floor(capture))
for d in figures["stops_by_decade"]:
    print(f"luminance {d['decade'][0]:9.3g} to {d['decade'][1]:9.3g}: median error {d['median_stops']:.2f} stops "
          f"({d['samples']} samples)")
print(f"samples returned as 0 above the floor: {figures['zeros_above_floor']:.2%}; "
      f"highlight energy kept: {figures['highlight_energy']:.2f}")

# %%
# The centre view and its error in stops (red: too bright, blue: too dark).
fig, ax = plt.subplots(1, 2, figsize=(10, 4))
ax[0].imshow(tonemap(result.centre(), reference=scene.centre()))
ax[0].set_title("reconstruction, centre view")
ax[1].imshow(render_error_map(result, scene))
for a in ax:
    a.axis("off")
fig.tight_layout()
