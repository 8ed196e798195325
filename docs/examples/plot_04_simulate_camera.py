"""
Simulate the paper's multi-ISO coded-mask camera
================================================

The camera of Miandji et al. puts a random colour-coded mask in front of a Bayer sensor whose
pixels have different ISOs, and captures an HDR light field in one or a few shots.
:func:`lfproc.camera.simulate_capture` simulates it with a camera profile's noise
model (photon, dark-current and read noise, full well, quantisation) and returns a
:class:`~lfproc.camera.Capture`: the sensor codes, the ISO map, the mask codes and
everything needed to reconstruct. See :doc:`/guide/camera`.

Command line: ``lfproc simulate scene.exr -o shot.capture.npz --shots 2 --noise medium``.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from lfproc.camera import load_capture, observations, simulate_capture
from lfproc.camera.simulate import capture_summary
from lfproc.preview import render_capture_preview
from lfproc.synth import synthesize

scene = synthesize("lamps", size=(64, 64), views=5, random_state=3)
capture = simulate_capture(scene, profile="paper-medium", iso_pattern_kind="random", isos=(100, 400, 800, 1600),
                           shots=2, mask_period=4, random_state=0)
print(capture)
summary = capture_summary(capture)
print(f"sampling rate {summary['sampling_rate']}, saturated {summary['saturated_fraction']:.1%}")

# %%
# A capture file (``.capture.npz``) holds all of it; loading gives the same capture.
path = capture.save(Path(tempfile.mkdtemp()) / "shot.capture.npz")
again = load_capture(path)
print(path.name, again.shots, again.isos)

# %%
# The calibrated observations ``T`` (radiance per measurement, with weights ``1/std(T)``,
# zero where saturated or black-clipped) are what the reconstruction fits.
obs = observations(capture, warn_saturation=False)
print(f"{(obs.weight > 0).mean():.1%} of the measurements are usable")

fig, ax = plt.subplots(1, 3, figsize=(12, 4))
for a, kind, title in zip(ax, ("sensor", "iso", "mask"), ("sensor codes, shot 1", "ISO map", "mask (one view)")):
    a.imshow(render_capture_preview(capture, kind, zoom=4))
    a.set_title(title)
    a.axis("off")
fig.tight_layout()
