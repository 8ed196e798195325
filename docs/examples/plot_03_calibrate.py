"""
Calibrate a sensor (frame manifest and EMVA 1288)
=================================================

A camera profile holds, per ISO, the gain, read noise, dark current and full well that drive
lfproc's noise model. :func:`lfproc.calib.simulate_frames` writes the bias,
dark and flat frames a profile predicts; :func:`lfproc.calib.calibrate` measures the
profile back from them, either from a frame manifest or from an EMVA 1288 data set
(descriptor + images). See :doc:`/guide/calibration`.

Command line::

    lfproc calibrate simulate-frames --profile paper-high -o frames --seed 1
    lfproc calibrate frames -o profile.json --report calib-report
    lfproc calibrate simulate-frames --profile paper-high --format emva -o emva --iso 100
    lfproc calibrate emva/emva1288.txt -o emva.json     # or the folder holding the descriptor
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from lfproc.calib import calibrate, simulate_frames
from lfproc.calib.simulate_frames import expected_figures
from lfproc.sensor import load_profile

work = Path(tempfile.mkdtemp())
truth = load_profile("paper-high")
manifest = simulate_frames(truth, work / "frames", size=(64, 64), isos=[100, 400], random_state=1)
result = calibrate(manifest)

for iso in (100, 400):
    want, got = expected_figures(truth, iso), result.profile.iso_figures(iso)
    print(f"ISO {iso}: gain {got.gain_dn_per_e:.4f} DN/e- (true {want['gain_dn_per_e']:.4f}), "
          f"read noise {got.read_noise_e:.2f} e- (true {want['read_noise_e']:.2f})")

# %%
# The same sensor as an EMVA 1288 data set: one channel (recorded as a monochrome sensor), one
# ISO. With a dark stack and a bright stack (steps of more than two images), the profile also
# gets per-pixel maps: the master bias frame and the flat field (PRNU map), saved as sidecars
# ``<stem>.bias.npz`` and ``<stem>.flat.npz`` beside the profile JSON.
descriptor = simulate_frames(truth, work / "emva", format="emva", size=(64, 64), isos=[100], random_state=1)
print(descriptor.read_text().splitlines()[:4])
emva = calibrate(descriptor)
profile = emva.profile
figures = profile.source["emva1288"]["100"]
print(f"EMVA 1288: QE {figures['quantum_efficiency']:.3f}, "
      f"saturation capacity {figures['saturation_capacity_emva_e']:.0f} e-, "
      f"SNR max {figures['snr_max_db']:.1f} dB, dynamic range {figures['dynamic_range_emva_db']:.1f} dB")
print("per-pixel maps:", "bias" if profile.bias_frames else "no bias",
      "and flat field" if profile.flat_field is not None else "no flat field")

# %%
# Left: the photon transfer curves of the manifest's flats (temporal variance against mean
# signal; the slope is the gain ``K`` in DN per electron; clipped flats left out). Right: the
# flat field measured from the EMVA data set's stacks.
fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
for iso, curve in result.curves.items():
    signal, var = np.array(curve["flat_signal_dn"]), np.array(curve["flat_var_dn2"])
    ok = (signal > 0) & (np.array(curve["flat_clipped_fraction"]) == 0)
    ax[0].loglog(signal[ok], var[ok], "o-", ms=3, label=f"ISO {iso}")
ax[0].set_xlabel("mean signal above dark (DN)")
ax[0].set_ylabel("temporal variance (DN$^2$)")
ax[0].set_title("photon transfer (frame manifest)")
ax[0].legend()
im = ax[1].imshow(profile.flat_field, cmap="coolwarm")
ax[1].set_title("measured flat field (EMVA data)")
ax[1].axis("off")
fig.colorbar(im, ax=ax[1])
fig.tight_layout()
