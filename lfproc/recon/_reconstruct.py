"""The reconstruction driver: patches, blocks, scale handling, Dask, the output light field.

Patches of the dictionary's size lie on a grid of ``stride`` pixels (plus one last row and
column flush with the sensor's border, so every pixel is covered). The grid is cut into
*blocks* of whole patch rows (about ``block_patches`` patches each); a block is the unit of
work: its patches are grouped by patch operator (phase), solved in batches, and their
estimates summed into the block's own accumulator. Blocks are the same whatever runs them
(this process or Dask workers), and the accumulators are added to the image in block order,
so the output does not depend on how the blocks were scheduled.

Scale handling (the data span 16 stops or more). With ``scale="patch"`` (the first
implementation; the paper-faithful reading of its ``mu``) each patch ``p`` is solved in its own
units: the measurements are divided by ``c_p = sqrt(n) * rms(T_i / r_i)`` over the usable
measurements (``r_i`` the total mask transmittance of measurement ``i``: ``T_i / r_i`` is the
radiance a flat patch would need; ``c_p`` is then the l2 norm of that flat patch, the norm
the dictionary's atoms and training patches are normalised to), and the weights by their
root mean square over the usable measurements, and the data term is taken as a mean over
the ``m`` measurements: each patch solves
``1/(2m) ||W' (Phi_p D b - T_p / c_p)||^2 + mu ||b||_1``. ``mu`` is therefore relative to a
light-field patch of unit l2 norm with weights of mean square one, the same for dark and
bright patches, and does not change with the number of shots; the code is scaled back by
``c_p``. With this reading the paper's ``mu = 1e-4`` works on a smooth noisy scene
(tests/recon/test_reconstruct.py), whereas ``1e-4`` against the summed data term (100x less
regularisation) overfits the noise. ``scale="global"`` uses one ``c`` and one weight scale for
the whole capture instead (the 99.9th percentile of the usable ``T`` over the mean row
transmittance, and the rms of all usable weights): what normalising the capture to its peak
would do. ``scale="noise"`` (the previous default) keeps the per-patch units of ``"patch"`` for the
code but not its per-patch weighting of the data term: each patch solves
``1/(2m) ||W (Phi_p D a - T_p)||^2 + (mu / c_p) ||a||_1`` with the raw weights ``W = 1/std(T)``:
the data term is the chi-square of the patch (its residuals in units of their noise), the l1
weight is relative to the patch's norm (a scale-free prior), and ``mu`` is a pure number (in
``"patch"`` units: ``mu_p = mu m / (c_p omega_p)^2``). Bright, high-SNR patches then fit their
data and dark, noisy ones are regularised more, in any capture. With ``"patch"`` a patch with a
bright light on a dark background has a tiny data term (its ``c_p`` is the light's level, its
weight rms the dark pixels'), and the lasso shrinks the light away (measured: street lamps
lost, 15 dB PU21; README). But its shrinkage of a patch goes as ``mu / SNR^2`` with the
*per-measurement* SNR: a dark patch of 5 electrons per pixel (SNR ~1.5 each, ~20 for the patch's
mean over 128 measurements) was shrunk to zero, and the dark half of a 24-stop scene came out
black (README). ``scale="universal"`` (the default) sets the l1 weight where the noise is: the
raw problem ``1/2 ||W (Phi_p D a - T_p)||^2 + lambda_p ||a||_1`` with
``lambda_p = mu sqrt(2 ln K) s_p``, ``s_p = rms_j ||W Phi_p d_j||`` the standard deviation of the
noise in an atom's correlation ``d_j^T Phi_p^T W^2 T_p`` (``mu = 1`` is Donoho and Johnstone's
universal threshold; 0.5 measured best). An atom then enters when its correlation stands out
of the noise of the *whole* patch, so the shrinkage goes as ``1 / SNR`` of the patch, not of a pixel.

The weights ``W = 1/std(T)`` need each measurement's expected signal for its photon noise.
``variance="measurement"`` (the previous default) plugs in ``T`` itself: a measurement that fell
low gets a smaller variance and a larger weight, so every weighted fit is biased low (by about
one electron per measurement: 0.853 of a flat scene at 8 electrons, the darkest regions black;
README). ``variance="local"`` (the default) takes the signal from the measurement's
same-colour neighbours (:func:`lfproc.camera.capture.local_signal`), independent of its own noise.

Overlapping estimates are averaged (``overlap="mean"``, the paper's) or weighted per pixel
(``"scale"``: by ``1 / c_p^2``, the inverse of a patch's error variance when its error is
relative to its norm, so a dark pixel is taken from the patches without a bright light in them;
``"window"``: by a centre-weighted ``sin^2`` window; ``"scale-window"``: both;
``"scale-window-fit"``, the default: both and ``1 / max(1, chi2_p / m_p)``, so a patch that
fits its own measurements worse than their noise (reduced chi-square above 1: an edge the
dictionary does not represent, a light the lasso cut) counts less where others overlap it).
In every mode a patch without any usable measurement (all saturated or clipped) is left out:
it has no estimate, and averaging it in as zeros darkened saturated regions.
"""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._shared.deprecate import resolve_options
from .._shared.validation import check_choice
from .._shared.progress import progress
from .._shared.parallel import available_cpus, dask_client, realign
from .._version import __version__
from ..errors import InputError, ShapeError
from ..lightfield import LightField
from threadpoolctl import threadpool_limits

from ._solvers import SOLVERS, BatchOperator, SharedOperator, _Factor, admm, fista, omp
from .._shared.patches import patch_grid
from ..camera.capture import READ_FLOOR_E, Capture, load_capture, observations
from ..camera.projection import patch_operators, PatchOperators
from ..dictionary import Dictionary, load_dictionary

__all__ = ["reconstruct", "ReconstructionSettings", "DEFAULTS", "PAPER", "SCALES", "OVERLAPS", "VARIANCES", "patch_count"]

SCALES = ("patch", "global", "noise", "universal")
OVERLAPS = ("mean", "scale", "window", "scale-window", "scale-window-fit")
VARIANCES = ("local", "measurement")
#: Defaults of :func:`reconstruct`, measured on HDR-photo-textured light fields (README, benchmarks/
#: reconstruct_quality.py, tuned on scenes other than the README's): the chi-square data term with the
#: l1 weight at 0.5 of its universal noise level (``scale="universal"``), weights from a photon-noise variance
#: of the neighbours' signal (``variance="local"``), overlaps weighted by scale, a centre window and the fit,
#: ADMM stopped at a tolerance of 1e-3 or 100 iterations. The paper's settings are :data:`PAPER`.
DEFAULTS = {"stride": 4, "mu": 0.5, "tol": {"admm": 1e-3, "fista": 2.0**-15, "omp": None},
            "max_iter": {"admm": 100, "fista": 1000, "omp": None},
            "block_patches": 512, "scale": "universal", "overlap": "scale-window-fit", "variance": "local"}
#: The paper's settings (Miandji et al., IEEE TCI 2021, eq. 9: mu 1e-4 on patches of unit norm,
#: tolerance 2^-15, plain averages;
#: the paper weighs measurements by their noise model, which its text does not detail: the plug-in here).
PAPER = {"stride": 4, "mu": 1e-4, "tol": 2.0**-15, "max_iter": 300, "scale": "patch", "overlap": "mean",
         "variance": "measurement"}
#: Bytes of per-patch operators ``A_p`` materialised at once for non-periodic masks.
_BATCH_OPERATOR_BYTES = 256 * 2**20


@dataclass(frozen=True)
class _Settings:
    solver: str
    mu: float
    max_iter: int
    tol: float
    sparsity: int
    scale: str
    overlap: str
    c_global: float
    w_global: float
    c_median: float = 1.0
    debias: int = 0


def patch_count(size: tuple[int, int], patch: int, stride: int) -> int:
    """Number of patches :func:`reconstruct` solves for a sensor of ``size``.

    The grid steps by ``stride`` and adds a last patch flush with the bottom/right edge.

    Parameters
    ----------
    size : tuple of 2 int
        Sensor size ``(H, W)`` in pixels.
    patch : int
        Patch side ``P`` in pixels.
    stride : int
        Step between patches in pixels.

    Returns
    -------
    int

    Examples
    --------
    >>> from lfproc.recon import patch_count
    >>> patch_count((24, 24), 8, 4), patch_count((25, 25), 8, 4)
    (25, 36)
    """
    tops, lefts = patch_grid(size, patch, stride)
    return len(tops) * len(lefts)


def _int_option(name: str, value, *, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or int(value) < low:
        raise InputError(f"{name}: expected an integer >= {low}, got {value!r}")
    return int(value)


def _gather(array: np.ndarray, tops: np.ndarray, lefts: np.ndarray, size: int) -> np.ndarray:
    """``array[:, t:t+size, l:l+size]`` of every patch, ``(B, S * size * size)`` (measurement order)."""
    ii = np.arange(size)
    rows = tops[:, None, None] + ii[None, :, None]
    cols = lefts[:, None, None] + ii[None, None, :]
    out = array[:, rows, cols]  # (S, B, size, size)
    return np.ascontiguousarray(out.transpose(1, 0, 2, 3).reshape(len(tops), -1))


def _solve_group(op, y, w, rowsum, settings: _Settings, n: int):
    """Codes of one batch sharing an operator type; returns (codes (B, K), scale c_p (B,), iterations (B,),
    reduced chi-square of the fit (B,))."""
    usable = w > 0
    m_use = usable.sum(axis=1)
    flat = np.where(usable, y / np.maximum(rowsum, 1e-12), 0.0).astype(np.float64)
    c_p = np.sqrt(n * (flat * flat).sum(axis=1) / np.maximum(m_use, 1))
    w64 = w.astype(np.float64)
    omega = np.sqrt((w64 * w64).sum(axis=1) / np.maximum(m_use, 1))
    ok = (m_use > 0) & (c_p > 0) & (omega > 0)
    b_n, k_n = len(y), op.shape[1]
    codes = np.zeros((b_n, k_n), dtype=np.float32)
    iters = np.zeros(b_n, dtype=np.int32)
    chi2 = np.ones(b_n)
    if not ok.any():
        return codes, np.where(ok, c_p, 0.0), iters, chi2
    rows = np.flatnonzero(ok)
    sub = op if ok.all() else op.subset(rows)
    cp, om = c_p[rows], omega[rows]
    yn = (y[rows] / cp[:, None]).astype(np.float32)
    wn = (w[rows] / om[:, None]).astype(np.float32)
    m = y.shape[1]  # mu weighs the data term's mean over the measurements (module notes)
    if settings.scale == "noise":  # the raw chi-square data term (module notes)
        mu = settings.mu * m / (cp * om) ** 2
    elif settings.scale == "universal":  # chi-square data term, l1 weight at the noise level of A^T W^2 T
        s_n = np.sqrt(sub.colnorm2(wn * wn).astype(np.float64).mean(axis=1))  # rms_j ||W' A_j||
        mu = settings.mu * math.sqrt(2.0 * math.log(k_n)) * s_n / (om * cp)
    elif settings.scale == "patch":
        mu = np.full(len(rows), settings.mu * m)
    else:  # one mu for the raw problem of every patch (module notes)
        mu = settings.mu * m * (settings.c_global / cp) * (settings.w_global / om) ** 2
    if settings.solver == "admm":
        z, it = admm(sub, wn, yn, mu, max_iter=settings.max_iter, tol=settings.tol)
    elif settings.solver == "fista":
        z, it = fista(sub, wn, yn, mu, max_iter=settings.max_iter, tol=settings.tol)
    else:
        z, it = omp(sub, wn, yn, settings.sparsity)
    if settings.debias and settings.solver != "omp":
        z = _debias(sub, wn, yn, z, settings.debias)
    codes[rows] = z
    iters[rows] = it
    if "fit" in settings.overlap.split("-"):  # reduced chi-square of the patch's fit (module notes)
        res = (sub.fwd(z) - yn).astype(np.float64) * (w[rows] * cp[:, None])
        chi2[rows] = (res * res).sum(axis=1) / m_use[rows]
    return codes, np.where(ok, c_p, 0.0), iters, chi2


def _debias(op, w, y, z, k_max: int) -> np.ndarray:
    """Least-squares refit of every code on its ``k_max`` largest atoms (the found support, capped).

    The lasso's codes are shrunk by the l1 weight; refitting the support by weighted least squares
    removes that bias. The support of a noisy patch has more atoms than measurements, so it is
    capped at ``k_max`` (a tiny ridge keeps the systems positive definite).
    """
    b_n, k_n = z.shape
    k = int(min(k_max, k_n, w.shape[1]))
    idx = np.argpartition(-np.abs(z), k - 1, axis=1)[:, :k]  # (B, k)
    keep = np.take_along_axis(z, idx, axis=1) != 0
    cols = op.columns(idx).astype(np.float64) * w[:, :, None].astype(np.float64)  # (B, m, k) of W A
    cols *= keep[:, None, :]
    gram = np.matmul(cols.transpose(0, 2, 1), cols)
    ridge = 1e-8 * np.maximum(np.trace(gram, axis1=1, axis2=2), 1e-30) / k
    gram[:, np.arange(k), np.arange(k)] += ridge[:, None]
    rhs = np.matmul(cols.transpose(0, 2, 1), (w * y).astype(np.float64)[:, :, None])
    sol = np.linalg.solve(gram, rhs)[:, :, 0] * keep
    out = np.zeros_like(z)
    np.put_along_axis(out, idx, sol.astype(np.float32), axis=1)
    return out


def _operator_times(ops, sel: np.ndarray, atoms: np.ndarray, atoms_by_pixel: np.ndarray | None) -> np.ndarray:
    """``Phi_b D`` of the patches ``sel`` of a non-periodic mask, ``(B, m, K)``, as GEMMs.

    A measurement sums one patch pixel and colour ``q`` over the views: its row of ``Phi_b D``
    is its ``V U`` mask values times ``D`` restricted to ``q`` (``(V U, K)``). Grouping the
    measurements of every patch by ``q`` makes that one GEMM per ``q`` for the whole batch,
    which reads ``D`` once instead of gathering ``V U`` rows of it per measurement
    (``PatchOperators.times``, memory-bound: ~10 ms per patch of the default dictionary).
    Falls back to ``PatchOperators.times`` for operators without that layout.
    """
    if atoms_by_pixel is None:
        return ops.times(atoms, sel)
    n_pix, vu, k_n = atoms_by_pixel.shape
    cols = ops.cols[sel].astype(np.int64)  # (B, m, V U)
    pix = cols[:, :, 0]
    if cols.shape[-1] != vu or not np.array_equal(cols, pix[:, :, None] + n_pix * np.arange(vu)):
        return ops.times(atoms, sel)
    b_n, m = pix.shape
    pix = pix.reshape(-1)
    vals = ops.vals[sel].reshape(-1, vu).astype(np.float32)
    out = np.empty((b_n * m, k_n), dtype=np.float32)
    order = np.argsort(pix, kind="stable")
    bounds = np.searchsorted(pix[order], np.arange(n_pix + 1))
    for q in range(n_pix):
        rows = order[bounds[q]:bounds[q + 1]]
        if len(rows):
            out[rows] = vals[rows] @ atoms_by_pixel[q]
    return out.reshape(b_n, m, k_n)


def _solve_block(task: dict, shared: dict) -> dict:
    """Solve the patches of one block; return its accumulator and figures (the Dask task).

    BLAS runs on one thread: the same sums whoever runs the block (so Dask and in-process outputs
    are identical), and on a shared machine a two-thread GEMM spends most of its time waiting
    for its other thread (median 590 us instead of 5-40 us for one batch's ``A V``, measured
    at a load average of 15); cores are used by solving blocks in parallel instead. The limit
    is set once: in this process by :func:`reconstruct` around its thread pool, in a Dask worker
    process by the first block it runs (:func:`_limit_worker_blas`), never per block:
    threadpoolctl changes the BLAS library's state for the whole process and is not thread-safe,
    so overlapping enter/exit pairs of concurrent blocks restored the wrong thread count.
    """
    _limit_worker_blas()
    return _solve_block_here(realign(task), realign(shared))


_WORKER_BLAS = {"limited": False}
_WORKER_BLAS_LOCK = threading.Lock()


def _limit_worker_blas() -> None:
    """One BLAS thread in a Dask worker process, set once for the process's life (a worker is lfproc's)."""
    if _WORKER_BLAS["limited"]:
        return
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return  # not in a Dask worker: reconstruct() sets the limit around its pool
    with _WORKER_BLAS_LOCK:
        if not _WORKER_BLAS["limited"]:
            threadpool_limits(1)  # not a context: the worker process keeps it
            _WORKER_BLAS["limited"] = True


def _solve_block_here(task: dict, shared: dict) -> dict:
    atoms = shared["atoms"]
    n, k_n = atoms.shape
    v_n, u_n, size, _, c_n = shared["patch"]
    settings: _Settings = shared["settings"]
    row0 = task["row0"]
    tops, lefts = task["tops"], task["lefts"]
    y_all = _gather(task["T"], tops - row0, lefts, size)
    w_all = _gather(task["W"], tops - row0, lefts, size)
    b_n = len(tops)
    codes_scale = np.zeros(b_n)
    iters = np.zeros(b_n, dtype=np.int32)
    chi2 = np.ones(b_n)
    estimates = np.zeros((b_n, n), dtype=np.float32)
    if shared["periodic"]:
        index = task["phase"]
        for g in np.unique(index):
            sel = np.flatnonzero(index == g)
            op = SharedOperator(shared["A"][g], shared["gram"][g],
                                factor=shared["factor"][g] if shared.get("factor") else None)
            rowsum = shared["rowsum"][g][None, :]
            codes, cp, it, chi2[sel] = _solve_group(op, y_all[sel], w_all[sel], rowsum, settings, n)
            estimates[sel] = (codes @ atoms.T) * cp[:, None].astype(np.float32)
            codes_scale[sel], iters[sel] = cp, it
    else:
        ops = PatchOperators(**task["operators"])
        m = ops.shape[0]
        per = max(1, _BATCH_OPERATOR_BYTES // (4 * m * k_n))
        for start in range(0, b_n, per):
            sel = np.arange(start, min(start + per, b_n))
            A = _operator_times(ops, sel, atoms, shared.get("atoms_by_pixel"))
            op = BatchOperator(A)
            rowsum = ops.row_sums()[sel]
            codes, cp, it, chi2[sel] = _solve_group(op, y_all[sel], w_all[sel], rowsum, settings, n)
            estimates[sel] = (codes @ atoms.T) * cp[:, None].astype(np.float32)
            codes_scale[sel], iters[sel] = cp, it
            del A, op
    rows = int(tops.max() - row0 + size)
    width = task["width"]
    acc = np.zeros((v_n, u_n, rows, width, c_n), dtype=np.float32)
    weight = _overlap_weights(settings.overlap, codes_scale / settings.c_median, size, chi2)  # (B, P, P) or None
    wacc = np.zeros((rows, width), dtype=np.float32)
    patches = estimates.reshape(b_n, v_n, u_n, size, size, c_n)
    ii = np.arange(size)
    for group in _disjoint_groups(tops, lefts, codes_scale != 0, size, shared.get("stride")):
        # patches of a group do not overlap: one indexed add each (a fixed order: the groups', then the listed)
        rows_ = (tops[group] - row0)[:, None, None] + ii[None, :, None]
        cols_ = lefts[group][:, None, None] + ii[None, None, :]
        part = patches[group]
        wgt = np.ones((len(group), size, size), dtype=np.float32) if weight is None else weight[group]
        if weight is not None:
            part = part * wgt[:, None, None, :, :, None]
        acc[:, :, rows_, cols_, :] += part.transpose(1, 2, 0, 3, 4, 5)
        wacc[rows_, cols_] += wgt
    return {"row0": row0, "acc": acc, "weight": wacc, "empty": int((codes_scale == 0).sum()), "iterations": iters}


def _disjoint_groups(tops, lefts, use, size: int, stride: int | None) -> list[np.ndarray]:
    """The patches ``use`` of a block in groups whose patches do not overlap, in a fixed order.

    On the grid of ``stride`` (corners multiples of it), the patches whose corner indices agree modulo
    ``ceil(size / stride)`` lie at least ``size`` apart: one group each. The rest (the last row and column,
    flush with the sensor's border) are groups of one, as listed.
    """
    idx = np.flatnonzero(use)
    if not stride:
        return [idx[i:i + 1] for i in range(len(idx))]
    q = -(-size // stride)
    regular = (tops[idx] % stride == 0) & (lefts[idx] % stride == 0)
    reg = idx[regular]
    key = ((tops[reg] // stride) % q) * q + (lefts[reg] // stride) % q
    groups = [reg[key == k] for k in range(q * q) if (key == k).any()]
    return groups + [idx[~regular][i:i + 1] for i in range(int((~regular).sum()))]


def _overlap_weights(overlap: str, scale: np.ndarray, size: int, chi2=None) -> np.ndarray | None:
    """Per-pixel weights of every patch's estimate when overlaps are averaged (None: plain mean).

    ``scale``: the patches' ``c_p`` over one constant of the capture (the same in every block);
    ``chi2``: the reduced chi-square of every patch's fit (used by ``"...-fit"``).
    """
    if overlap == "mean":
        return None
    b_n = len(scale)
    w = np.ones((b_n, size, size), dtype=np.float32)
    parts = overlap.split("-")
    if "scale" in parts:
        # a patch's error is about relative to its own l2 norm c_p (the dictionary's coding error and the
        # lasso's): inverse-variance weights 1 / c_p^2 let the patches whose scale matches a pixel win
        good = scale > 0
        inv = np.zeros(b_n)  # an empty patch (no usable measurement) is left out (_solve_block_here)
        inv[good] = np.minimum(1.0 / scale[good] ** 2, 1e12)
        w *= inv.astype(np.float32)[:, None, None]
    if "fit" in parts:
        w *= (1.0 / np.maximum(chi2, 1.0)).astype(np.float32)[:, None, None]
    if "window" in parts:
        x = (np.arange(size) + 0.5) / size
        win = np.sin(np.pi * x) ** 2 + 1e-3  # centre-weighted: a patch's border pixels have the fewest measurements around them
        w *= np.outer(win, win).astype(np.float32)[None]
    return w


def _load_inputs(capture, dictionary):
    if isinstance(capture, (str, os.PathLike)):
        capture = load_capture(capture)
    if not isinstance(capture, Capture):
        raise InputError(f"reconstruct: expected a Capture or a capture file, got {type(capture).__name__}")
    if not isinstance(dictionary, Dictionary):
        dictionary = load_dictionary(dictionary)
    return capture, dictionary


@dataclass(frozen=True)
class ReconstructionSettings:
    """The options of :func:`reconstruct` that decide its result (see its parameters).

    ``max_iter`` and ``tol`` None: the solver's defaults (:data:`DEFAULTS`); ``n_nonzero_coefs``
    None: the dictionary's training sparsity. Values are validated by :func:`reconstruct`.

    Parameters
    ----------
    solver, stride, mu, max_iter, tol, n_nonzero_coefs, scale, block_patches, overlap, debias, variance
        The keywords of :func:`reconstruct` of the same names, with the same defaults.
    """
    solver: str = "admm"
    stride: int = DEFAULTS["stride"]
    mu: float = DEFAULTS["mu"]
    max_iter: int | None = None
    tol: float | None = None
    n_nonzero_coefs: int | None = None
    scale: str = DEFAULTS["scale"]
    block_patches: int = DEFAULTS["block_patches"]
    overlap: str = DEFAULTS["overlap"]
    debias: int = 0
    variance: str = DEFAULTS["variance"]


def _checked_settings(settings: ReconstructionSettings) -> ReconstructionSettings:
    """``settings`` validated, with ``tol``, ``mu`` as floats and ``max_iter`` filled in from the solver's
    defaults (``n_nonzero_coefs`` and the stride's range need the dictionary: :func:`_check_fit`)."""
    solver = settings.solver
    check_choice("solver", solver, SOLVERS)
    check_choice("scale", settings.scale, SCALES)
    check_choice("variance", settings.variance, VARIANCES)
    check_choice("overlap", settings.overlap, OVERLAPS)
    stride = settings.stride
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)):
        raise InputError(f"stride: expected a positive integer, got {stride!r}")
    mu, tol = settings.mu, settings.tol
    if tol is None:
        tol = DEFAULTS["tol"][solver] or 0.0
    try:
        mu = float(mu)
        tol = float(tol)
    except (TypeError, ValueError):
        raise InputError(f"mu and tol: expected numbers, got {mu!r} and {tol!r}") from None
    if not (math.isfinite(mu) and mu >= 0):
        raise InputError(f"mu: expected a non-negative number, got {mu}")
    if not (math.isfinite(tol) and tol >= 0):
        raise InputError(f"tol: expected a non-negative number, got {tol}")
    max_iter = settings.max_iter
    if max_iter is None:
        max_iter = DEFAULTS["max_iter"][solver] or 1
    return replace(settings, mu=mu, tol=tol, max_iter=_int_option("max_iter", max_iter),
                   block_patches=_int_option("block_patches", settings.block_patches))


def _check_fit(capture, dictionary, settings: ReconstructionSettings) -> ReconstructionSettings:
    """Refuse a dictionary whose patch does not fit the capture; the stride checked against the patch and
    ``n_nonzero_coefs`` filled in from the dictionary."""
    v_n, u_n, size, _, c_n = dictionary.patch
    if (v_n, u_n) != tuple(capture.views) or c_n != 3:
        raise ShapeError(
            f"dictionary {dictionary.name or dictionary.preset!r} has {v_n} x {u_n} views and {c_n} colours "
            f"(patch {list(dictionary.patch)}); the capture has {capture.views[0]} x {capture.views[1]} views and "
            f"3 colours: use a dictionary trained for {capture.views[0]} x {capture.views[1]} views")
    h, w = capture.size
    if size > min(h, w):
        raise ShapeError(f"dictionary patch of {size} x {size} pixels does not fit the capture's sensor of {h} x {w}")
    stride = int(settings.stride)
    if not 1 <= stride <= size:
        raise InputError(f"stride: expected 1..{size} (the dictionary's patch size), got {stride}")
    sparsity = settings.n_nonzero_coefs
    if sparsity is None:
        sparsity = dictionary.sparsity
    return replace(settings, stride=stride, n_nonzero_coefs=_int_option("n_nonzero_coefs", sparsity))


def _solver_settings(capture, dictionary, settings: ReconstructionSettings, T: np.ndarray, W: np.ndarray) -> _Settings:
    """The per-patch solver's settings, with the capture's global scales (module notes)."""
    usable = W > 0
    v_n, u_n = dictionary.patch[:2]
    n = dictionary.n
    mean_rowsum = float(np.mean(capture.mask.codes)) * v_n * u_n
    c_global = math.sqrt(n) * float(np.percentile(np.abs(T[usable]), 99.9)) / max(mean_rowsum, 1e-12)
    w_global = float(np.sqrt(np.mean(W[usable].astype(np.float64) ** 2)))
    # the constant the overlap weights' patch scales are divided by (the same in every block); from the
    # non-zero measurements: on a noise-free sensor most of a dark scene's measurements are exactly 0, and a
    # zero median made every 1 / c_p^2 weight underflow to 0 and the output black
    lit = np.abs(T[usable & (T != 0)])
    c_median = math.sqrt(n) * (float(np.median(lit)) if lit.size else 1.0) / max(mean_rowsum, 1e-12)
    return _Settings(solver=settings.solver, mu=settings.mu, max_iter=settings.max_iter, tol=settings.tol,
                     sparsity=settings.n_nonzero_coefs, scale=settings.scale, overlap=settings.overlap,
                     c_global=max(c_global, 1e-30), w_global=max(w_global, 1e-30),
                     c_median=max(c_median, 1e-30), debias=_int_option("debias", settings.debias, low=0))


def _execution(workers, threads) -> tuple[int | None, int]:
    """``workers`` (None: no Dask cluster) and ``threads`` (None: the CPUs available) checked."""
    if workers is not None:
        workers = _int_option("workers", workers)
    if threads is None:
        threads = available_cpus()
    return workers, _int_option("threads", threads)


def _weighted_observations(capture, variance: str) -> tuple[np.ndarray, np.ndarray]:
    """The calibrated observations ``T`` (e-/s) and their weights ``W = 1/std(T)``, float32 ``(S, H, W)``; the weights
    assume at least ``READ_FLOOR_E`` electrons of read noise (:func:`lfproc.camera.capture.observations`)."""
    obs = observations(capture, variance_from=variance, read_floor_e=READ_FLOOR_E)
    T = np.ascontiguousarray(obs.radiance, dtype=np.float32)
    W = np.ascontiguousarray(obs.weight, dtype=np.float32)
    if not (W > 0).any():
        raise InputError("capture: every measurement has weight zero (all saturated or black-clipped); nothing to "
                         "reconstruct from")
    return T, W


def _combine(solved: dict[str, Any], capture) -> tuple[np.ndarray, float, str]:
    """The weighted mean of the patch estimates over each pixel, negatives clipped to 0, in the units of the
    light field the capture was simulated from (e-/s for a real capture); returns it, the fraction of
    negatives and the units."""
    count = np.maximum(solved["wsum"], np.float32(1e-30))  # a pixel of empty patches only: 0 (nothing was measured)
    data = solved["acc"] / count[None, None, :, :, None]
    negative = float((data < 0).mean())
    np.maximum(data, 0, out=data)
    if capture.radiance_scale is None:
        return data, negative, "e-/s"
    data /= np.float32(capture.radiance_scale)
    return data, negative, capture.parameters.get("light_field_units") or "relative"


@dataclass
class _Plan:
    """The blocks of one reconstruction: what every block shares, the blocks, and how to attach a block's
    patch operators (non-periodic masks: made per block, when it is submitted)."""
    shared: dict[str, Any]
    tasks: list[dict]
    attach_operators: Any
    n_patches: int
    n_operators: int | None


def _plan(capture, dictionary, solver_settings: _Settings, T, W, *, stride: int, block_patches: int) -> _Plan:
    """Patches on the grid of ``stride``, cut into blocks of whole patch rows (module notes)."""
    v_n, u_n, size, _, c_n = dictionary.patch
    h, w = capture.size
    tops, lefts = patch_grid((h, w), size, stride)
    rows_per_block = max(1, block_patches // len(lefts))
    atoms = realign(np.ascontiguousarray(dictionary.atoms, dtype=np.float32))  # a dictionary a Dask worker received (bench)
    shared: dict[str, Any] = {"atoms": atoms, "patch": dictionary.patch, "settings": solver_settings,
                              "periodic": capture.mask.period is not None, "stride": int(stride)}
    if not shared["periodic"]:  # D's rows grouped by patch pixel and colour, for _operator_times
        shared["atoms_by_pixel"] = np.ascontiguousarray(
            atoms.reshape(v_n * u_n, size * size * c_n, -1).transpose(1, 0, 2))
    grid_t = np.repeat(tops, len(lefts))
    grid_l = np.tile(lefts, len(tops))
    op_args = dict(views=capture.views, cfa_pattern=capture.cfa_pattern, size=size, sensor_size=(h, w))
    phase = None
    n_operators = None
    if shared["periodic"]:
        ops = patch_operators(capture.mask, tops=grid_t, lefts=grid_l, **op_args)
        phase = ops.index
        A = ops.times(atoms)  # (G, m, K): the distinct patch matrices times D
        shared["A"] = A
        shared["gram"] = [a.astype(np.float64) @ a.T.astype(np.float64) for a in A]
        with threadpool_limits(1):  # the ADMM factor of every phase, once per reconstruction (small LAPACK calls)
            shared["factor"] = ([_Factor.build(g) for g in shared["gram"]] if solver_settings.solver == "admm"
                                else None)
        shared["rowsum"] = ops.row_sums()
        n_operators = ops.n_operators
    tasks = []
    for i in range(0, len(tops), rows_per_block):
        bt = tops[i:i + rows_per_block]
        sel = slice(i * len(lefts), (i + len(bt)) * len(lefts))
        row0, row1 = int(bt[0]), int(bt[-1] + size)
        task = {"row0": row0, "tops": grid_t[sel], "lefts": grid_l[sel], "width": w,
                "T": T[:, row0:row1], "W": W[:, row0:row1]}
        if phase is not None:
            task["phase"] = phase[sel]
        tasks.append(task)

    def attach_operators(task):
        if not shared["periodic"] and "operators" not in task:
            ops = patch_operators(capture.mask, tops=task["tops"], lefts=task["lefts"], **op_args)
            task["operators"] = {f: getattr(ops, f) for f in ("cols", "vals", "index", "positions", "size", "views",
                                                             "shots", "channels", "periodic")}
        return task

    return _Plan(shared=shared, tasks=tasks, attach_operators=attach_operators, n_patches=int(len(grid_t)),
                 n_operators=n_operators)


def _solve_plan(plan: _Plan, shape, *, workers, scheduler, threads: int, progress_bar) -> dict[str, Any]:
    """Solve every block (threads in this process, or Dask) and add their accumulators in block order.

    Returns ``acc`` (the weighted sums), ``wsum`` (their weights per pixel), ``empty`` (patches without
    a usable measurement), ``iterations`` (per patch) and ``scheduler`` (a label).
    """
    v_n, u_n, h, w, c_n = shape
    acc = np.zeros((v_n, u_n, h, w, c_n), dtype=np.float32)
    wsum = np.zeros((h, w), dtype=np.float32)  # with "mean": the number of non-empty patches over each pixel
    empty = 0
    iterations: list[np.ndarray] = []
    bar = progress(total=plan.n_patches, desc="reconstruct", unit="patch",
                   disable=None if progress_bar is None else not progress_bar)

    def add(result):
        nonlocal empty
        r0 = result["row0"]
        part = result["acc"]
        acc[:, :, r0:r0 + part.shape[2]] += part
        wsum[r0:r0 + part.shape[2]] += result["weight"]
        empty += result["empty"]
        iterations.append(result["iterations"])

    use_dask = workers is not None or (scheduler is not None and scheduler != "synchronous")
    try:
        if not use_dask:
            with threadpool_limits(1):  # once around the pool, never per block (_solve_block)
                _run_threads(plan.tasks, plan.shared, plan.attach_operators, add, bar, threads=threads)
        else:
            _run_dask(plan.tasks, plan.shared, plan.attach_operators, add, bar, workers=workers, scheduler=scheduler)
    finally:
        bar.close()
    return {"acc": acc, "wsum": wsum, "empty": empty,
            "iterations": np.concatenate(iterations) if iterations else np.zeros(0),
            "scheduler": f"in-process:{threads} threads" if not use_dask else (scheduler or f"local:{workers}")}


#: What ``mu`` means for each ``scale`` (recorded with the reconstruction).
_MU_MEANING = {"patch": "1/(2m)||W(Phi D b - T)||^2 + mu||b||_1 per patch, T scaled to a unit-l2 patch, W to "
                        "mean square one",
               "noise": "1/(2m)||W(Phi D a - T)||^2 + (mu/c_p)||a||_1 per patch, W = 1/std(T) (chi-square), "
                        "c_p the patch's l2 norm",
               "universal": "1/2||W(Phi D a - T)||^2 + mu sqrt(2 ln K) s_p ||a||_1 per patch, W = 1/std(T), "
                            "s_p = rms_j ||W Phi D_j|| (the noise level of Phi D^T W^2 T)",
               "global": "as 'patch' but with one scale for the whole capture"}


def _record(settings: ReconstructionSettings, dictionary, capture, plan: _Plan, solved: dict[str, Any], *,
            negative: float, seconds: float) -> dict[str, Any]:
    """``attrs["reconstruction"]`` of the output: the lfproc version, every parameter and figures."""
    solver = settings.solver
    its = solved["iterations"]
    return {
        "lfproc_version": __version__,
        "solver": solver,
        "dictionary": {"name": dictionary.name, "preset": dictionary.preset, "patch": list(dictionary.patch),
                       "atoms": dictionary.n_atoms, "sparsity": dictionary.sparsity},
        "stride": settings.stride,
        "mu": settings.mu,
        "mu_meaning": _MU_MEANING[settings.scale],
        "tol": settings.tol,
        "max_iter": settings.max_iter if solver != "omp" else None,
        "sparsity": settings.n_nonzero_coefs if solver == "omp" else None,
        "scale": settings.scale,
        "overlap": settings.overlap,
        "variance": settings.variance,
        "debias": int(settings.debias),
        "block_patches": settings.block_patches,
        "patches": plan.n_patches,
        "operators": plan.n_operators if plan.n_operators is not None else plan.n_patches,
        "periodic_operator": bool(plan.shared["periodic"]),
        "empty_patches": int(solved["empty"]),
        "negative_fraction_clipped": negative,
        "iterations_mean": float(its.mean()) if its.size else 0.0,
        "iterations_max": int(its.max()) if its.size else 0,
        "radiance_scale": capture.radiance_scale,
        "capture_ground_truth": capture.ground_truth,
        "seconds": seconds,
        "scheduler": solved["scheduler"],
    }


def reconstruct(
    capture,
    dictionary="default",
    *,
    settings: ReconstructionSettings | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress_bar: bool | None = None,
    threads: int | None = None,
    **options,
) -> LightField:
    """Reconstruct the HDR light field of a coded multi-ISO capture (Miandji et al., IEEE TCI 2021, eq. 9).

    Per patch ``p`` (the dictionary's patch: ``V x U`` views of ``P x P`` pixels, 3 colours), with
    the defaults: ``a* = argmin_a 1/2 ||W (Phi_p D a - T_p)||^2 + lambda_p ||a||_1`` with ``T`` the
    calibrated observations of every shot (e-/s), ``W = 1/std(T)`` from a photon-noise variance of
    each measurement's same-colour neighbours (``variance="local"``), zero where a pixel is
    saturated or black-clipped, and ``lambda_p = mu sqrt(2 ln K) s_p`` at the noise level of the
    patch (``scale="universal"``); the patch estimate is ``D a*``; overlapping estimates are
    weighted by scale, a centre window and their fit (``overlap="scale-window-fit"``). The
    paper's plain form (per-patch units, plain averages) is ``scale="patch", overlap="mean"``
    (:data:`PAPER`); the module notes describe every option.

    Parameters
    ----------
    capture : Capture or path of a capture file
    dictionary : Dictionary, ``"default"`` (the shipped one) or path of a dictionary file
    settings : ReconstructionSettings, optional
        Every option below that decides the result (not ``workers``, ``scheduler``, ``progress_bar``,
        ``threads``). Give either ``settings`` or its fields as keywords (``**options``), not both.
    solver : {"admm", "fista", "omp"}, default "admm"
        ``admm`` (default; Woodbury solve, one ``m x m`` system per patch), ``fista`` (step
        ``1/L``), ``omp`` (greedy, ``n_nonzero_coefs`` atoms: the fast mode).
    stride : int, default 4
        Patch spacing in pixels (1 .. patch size; 4 as the paper; patch operators carry their CFA phase).
    mu : float, default 0.5
        l1 weight, whose meaning depends on ``scale`` (module notes, "Scale handling"): with
        ``"universal"`` ``mu sqrt(2 ln K) s_p``, ``s_p`` the rms of the weighted atoms' norms; with
        ``"patch"`` relative to a unit-norm patch (the paper's 1e-4: :data:`PAPER`). Not for ``omp``.
    max_iter : int, optional
        Iteration limit (default 100 for ADMM, 1000 for FISTA). Ignored by ``omp``.
    tol : float, optional
        Stop a patch when the relative change of its code (and, for ADMM, its primal residual)
        is at most ``tol`` (default 1e-3 for ADMM, 2^-15 for FISTA; the paper's: 2^-15).
    n_nonzero_coefs : int, optional
        Atoms per patch for ``omp`` (default: the dictionary's training sparsity). The keyword
        ``sparsity`` is deprecated.
    scale : {"universal", "noise", "patch", "global"}, default "universal"
        How HDR scale is handled (module notes): chi-square data term, l1 weight at its noise level
        (``"universal"``) or relative to the patch's norm (``"noise"``); per-patch codes and data
        term (``"patch"``); one scale for the capture (``"global"``).
    block_patches : int, default 512
        About this many patches per block, the unit of work (memory is bounded by a block).
        The output depends on it only through float rounding in the batched products.
    workers : int, optional
        Solve blocks on a local Dask cluster of this many processes (one thread each).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); ``"synchronous"`` or None
        with ``workers=None``: in this process. The output is identical either way.
    progress_bar : bool, optional
        Show patches/s and the remaining time (None: when stderr is a terminal).
    threads : int, optional
        Blocks solved at once here, one BLAS thread each (default: the CPUs); the output is the same.
    overlap : {"scale-window-fit", "scale-window", "scale", "window", "mean"}, default "scale-window-fit"
        How overlapping patch estimates are combined (module notes); ``"mean"`` is the paper's.
    debias : int, default 0
        Refit each ADMM/FISTA code by least squares on its ``debias`` largest atoms (0: off, the
        default: measured to lose quality on noisy captures, README).
    variance : {"local", "measurement"}, default "local"
        The signal in each measurement's photon-noise variance (its weight): from its neighbours
        (:func:`lfproc.camera.capture.local_signal`) or its own value (a plug-in biased low).

    Returns
    -------
    LightField
        ``(V, U, H, W, 3)`` in the units of the light field the capture was simulated from (the
        ``radiance_scale`` divided out), or ``e-/s`` for a real capture; negatives clipped to zero.
        ``attrs["reconstruction"]``: lfproc version, every parameter, figures (patches, seconds...).

    Raises
    ------
    ShapeError
        The dictionary's patch does not fit the capture (views, colours, sensor size).
    TypeError
        ``settings`` together with field keywords, or an unknown keyword.
    InputError
        Unknown solver or scale, a stride outside 1..patch size, bad numbers, a capture
        whose measurements all have weight zero.
    FileFormatError, MissingFileError
        Unreadable capture or dictionary files.

    Examples
    --------
    >>> from lfproc import evaluate, reconstruct, simulate_capture
    >>> from lfproc.synth import synthesize
    >>> truth = synthesize("window", size=(24, 24), views=5, random_state=0)
    >>> capture = simulate_capture(truth, shots=2, mask_period=4, random_state=0)
    >>> result = reconstruct(capture, progress_bar=False)  # the shipped dictionary, ADMM
    >>> result.shape, result.units, bool(10 < evaluate(result, truth)["pu21_psnr_db"] < 40)
    ((5, 5, 24, 24, 3), 'relative', True)
    """
    started = time.perf_counter()
    settings = resolve_options(ReconstructionSettings, settings, options, func_name="reconstruct",
                               argument="settings", renames={"sparsity": "n_nonzero_coefs"})
    settings = _checked_settings(settings)
    workers, threads = _execution(workers, threads)
    capture, dictionary = _load_inputs(capture, dictionary)
    settings = _check_fit(capture, dictionary, settings)
    T, W = _weighted_observations(capture, settings.variance)
    plan = _plan(capture, dictionary, _solver_settings(capture, dictionary, settings, T, W), T, W,
                 stride=settings.stride, block_patches=settings.block_patches)
    v_n, u_n, _, _, c_n = dictionary.patch
    solved = _solve_plan(plan, (v_n, u_n, *capture.size, c_n), workers=workers, scheduler=scheduler,
                         threads=threads, progress_bar=progress_bar)
    data, negative, units = _combine(solved, capture)
    radiance_scale = capture.radiance_scale
    record = _record(settings, dictionary, capture, plan, solved, negative=negative,
                     seconds=time.perf_counter() - started)
    return LightField(data=data, units=units, colour_space="camera-rgb" if radiance_scale is None else "linear-srgb",
                      source="lfproc.reconstruct", attrs={"reconstruction": record})


def _run_threads(tasks, shared, attach_operators, add, bar, *, threads: int) -> None:
    """Blocks on a pool of threads (numpy releases the GIL in BLAS and ufuncs), added in block order."""
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    if threads == 1:
        for task in tasks:
            add(_solve_block_here(realign(attach_operators(task)), shared))
            bar.update(len(task["tops"]))
        return
    window: deque = deque()
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="lfproc-recon") as pool:
        for task in tasks:
            window.append((pool.submit(_solve_block_here, realign(attach_operators(task)), shared), len(task["tops"])))
            while len(window) > threads:  # a bounded number of blocks in memory
                future, count = window.popleft()
                add(future.result())
                bar.update(count)
        while window:
            future, count = window.popleft()
            add(future.result())
            bar.update(count)


def _run_dask(tasks, shared, attach_operators, add, bar, *, workers, scheduler) -> None:
    from dask.distributed import as_completed

    local = scheduler == "synchronous" or not scheduler  # "synchronous": a one-process local cluster
    with dask_client(scheduler=None if local else scheduler, workers=workers or 1, jobs=len(tasks)) as client:
        shared_future = client.scatter(shared, broadcast=True)
        futures = {}
        for i, task in enumerate(tasks):
            futures[client.submit(_solve_block, attach_operators(task), shared_future, key=f"recon-block-{i}-"
                                  f"{os.getpid()}-{id(tasks)}", pure=False)] = i
        done: dict[int, dict] = {}
        next_index = 0
        for future in as_completed(futures):
            i = futures[future]
            done[i] = future.result()
            bar.update(len(tasks[i]["tops"]))
            future.release()
            while next_index in done:  # add in block order: the same sums as in process
                add(done.pop(next_index))
                next_index += 1
