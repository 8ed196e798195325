"""``lfproc bench``: the paper's experiments and baselines on any HDR light fields (an application).

* :mod:`lfproc.bench.grid` -- presets ``quick`` and ``paper``, the grid of cells and their seeds;
* :mod:`lfproc.bench.run` -- :func:`run_bench`: cached cells (one file each, atomic), Dask;
* :mod:`lfproc.bench.cells` -- the scenes and cell files of a bench folder (read by both others);
* :mod:`lfproc.bench.report` -- results.csv, report.md (Tables I-IV beside the paper's numbers,
  the claims) and the plots.

The baselines (per-shot reconstruction merged with Debevec hat weights or the noise-aware ML
merge) are a reconstruction mode: :func:`lfproc.recon.reconstruct_per_shot` (re-exported here).
"""

from ..recon import MERGES, merge_reconstructions, reconstruct_per_shot, reexpose, split_shots
from .grid import METHODS, PRESETS, Cell, get_preset, grid_cells
from .report import claims, write_report
from .run import COLUMNS, run_bench

__all__ = ["run_bench", "reconstruct_per_shot", "merge_reconstructions", "reexpose", "split_shots", "MERGES",
           "METHODS", "PRESETS", "Cell", "get_preset", "grid_cells", "claims", "write_report", "COLUMNS"]
