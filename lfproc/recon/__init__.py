"""Joint HDR light-field reconstruction from coded multi-ISO captures (stage 5, its second half).

:func:`reconstruct` solves, for every patch of the sensor, the weighted lasso
``argmin_a 1/2 ||W (Phi_p D a - T_p)||^2 + mu ||a||_1`` (Miandji et al., IEEE TCI 2021, eq. 9) with a batched
ADMM (default), FISTA or OMP, and averages the overlapping patch estimates. Periodic masks
share one patch operator per phase (:func:`lfproc.camera.projection.patch_operators`), so the
solvers' work is matrix-matrix products; blocks of patches run in this process or on Dask.

:func:`reconstruct_gmm` uses disparity-sheared Gaussian patch models instead
(:func:`train_patch_model`). :func:`reconstruct_per_shot` is the paper's baselines (captures of
global-ISO shots reconstructed shot by shot and merged; formerly ``lfproc.bench.baselines``).
"""

from ._reconstruct import (DEFAULTS, OVERLAPS, PAPER, SCALES, VARIANCES, ReconstructionSettings, patch_count,
                           reconstruct)
from ._gmm import PatchModel, gmm_fits, load_patch_model, reconstruct_gmm, train_patch_model
from ._per_shot import MERGES, merge_reconstructions, reconstruct_per_shot, reexpose, split_shots
from ._solvers import SOLVERS

__all__ = ["reconstruct", "ReconstructionSettings", "reconstruct_gmm", "gmm_fits", "PatchModel", "load_patch_model", "train_patch_model", "patch_count",
           "DEFAULTS", "PAPER", "SCALES", "OVERLAPS", "VARIANCES", "SOLVERS", "reconstruct_per_shot",
           "merge_reconstructions", "reexpose", "split_shots", "MERGES"]
