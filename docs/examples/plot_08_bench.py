"""
Run the bench: which acquisition to build?
==========================================

:func:`lfproc.bench.run_bench` answers the paper's question on any HDR light field: every cell
of a grid of acquisitions (ISO pattern, number of shots, noise, exposure, and the baselines
that bracket exposures or ISOs and merge per shot) is simulated, reconstructed and scored.
The ``quick`` preset has 35 cells per scene at 48 x 48 pixels; here a smaller grid (one noise
level and ISO set, 32 x 32 pixels, at most 30 ADMM iterations) keeps it to a few seconds.
See :doc:`/guide/bench`.

Command line: ``lfproc bench scene.exr -o bench --preset quick --workers 2``.
"""

import csv
import dataclasses
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from lfproc.bench import get_preset, run_bench
from lfproc.io import write_lightfield
from lfproc.synth import synthesize

work = Path(tempfile.mkdtemp())
write_lightfield(synthesize("lamps", size=(48, 48), views=5, random_state=3), work / "lamps.exr")

quick = get_preset("quick")
tiny = dataclasses.replace(quick, name="tiny", description="the gallery's grid", crop=(32, 32),
                           noise_levels=("low", "high"), iso_sets=quick.iso_sets[:1], exposures=(1.0, 32.0))
summary = run_bench([work / "lamps.exr"], work / "bench", preset=tiny, scheduler="synchronous",
                    recon_options={"max_iter": 30}, progress_bar=False)
print(f"{summary['cells']} cells in {summary['seconds']:.1f} s")
print(sorted(p.name for p in (work / "bench").iterdir()))

# %%
# ``results.csv`` has one row per cell; ``report.md`` lays the results out like the paper's
# tables and decides its claims. Here: quality against the number of shots per method.
rows = list(csv.DictReader(open(work / "bench" / "results.csv")))
fig, ax = plt.subplots(figsize=(7, 4))
for (method, pattern) in sorted({(r["method"], r["iso_pattern"]) for r in rows}):
    cells = sorted((int(r["shots"]), float(r["pu21_psnr_db"])) for r in rows
                   if (r["method"], r["iso_pattern"]) == (method, pattern) and r["noise"] == "low"
                   and float(r["exposure"]) == 1.0 and r["merge"] in ("", "ml"))
    if cells:
        ax.plot(*zip(*cells), "o-", label=f"{method} {pattern}".strip())
ax.set_xlabel("shots")
ax.set_ylabel("PU21-PSNR (dB)")
ax.legend(fontsize=7)
ax.set_title("lamps scene, 32 x 32 pixels, noise low")
fig.tight_layout()
