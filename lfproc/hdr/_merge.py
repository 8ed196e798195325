"""HDR merging of exposure brackets (how Miandji et al., IEEE TCI 2021, section IV-A, build their HDR data set).

Two estimators, both vectorised over samples of any shape (2-D images ``(H, W[, C])`` or
light fields ``(V, U, H, W, C)``: every view and pixel is merged on its own, all views share
the bracket's exposures) and processed in chunks to bound memory:

* :func:`merge_ml` -- the noise-aware maximum-likelihood estimator of linear sensor codes
  (Granados et al. 2010; analysed by Aguerrebere et al. 2014). Each exposure ``i`` gives
  ``T_i`` (e-/s) with variance ``var_i(x) = var_i(0) + x / t_i`` (read noise, dark current and
  quantisation in ``var_i(0)``, photon noise ``x / t_i``; :func:`lfproc.camera.sensor.calibrated_observation`
  with ``variance_from="estimate"``). The estimate is the inverse-variance weighted mean
  ``x = sum_i w_i T_i / sum_i w_i`` with ``w_i = 1 / var_i(x)`` evaluated at the current
  estimate: first at ``x = 0`` (read-noise weights), then ``max_iter`` fixed-point updates;
  :class:`lfproc.errors.ConvergenceWarning` when the last update still moved a sample by more
  than :data:`ML_TOLERANCE_STD` of its standard deviation.
  Saturated and black-clipped samples get weight 0, and so does every longer exposure of a
  pixel that saturated in a shorter one (blooming and motion guard). The variance of the
  result is ``1 / sum_i w_i`` at the final estimate.
* :func:`merge_debevec` -- Debevec & Malik (1997) eq. 6: a hat-weighted mean in the log domain,
  ``ln E = sum_i w(z_i) (g(z_i) - ln t_i) / sum_i w(z_i)``, on linear data (``g = ln``) or on
  non-linear 8-bit codes with a camera response ``g`` recovered by :func:`recover_response`
  (the paper's least-squares ``gsolve`` with a smoothness term, on many pixels chosen across
  the radiance range, pixel unknowns eliminated). A sample clipped in a shorter exposure is
  not used in the longer ones of the same pixel and channel.
* :func:`merge_ml_codes8` -- the inverse-variance estimator for 8-bit images: recovered
  response, code variance measured on the bracket (no profile, no ISO).

:func:`check_exposure_order` refuses exposure times that contradict the images.

Pixels with no usable sample are never left as garbage. A pixel **saturated in every
exposure** is filled with the radiance of the saturation level in the shortest exposure
(a lower bound of its true value), its variance set to the square of that value (relative
standard deviation 1) and it is flagged in ``info["saturated_everywhere"]``. A pixel
**black in every exposure** (no weighted sample and not saturated) gets the longest exposure's
value (0 for clipped linear data) and is flagged in ``info["dark_everywhere"]``.

Noise-aware merge of 8-bit codes
--------------------------------
The ML estimator of :func:`merge_ml` needs the sensor's gain and read noise (a profile and
an ISO); a JPEG has neither. :func:`merge_ml_codes8` measures the noise on the bracket itself:

1. the codes are linearised with the response ``x = exp(g(z))`` (recovered with
   :func:`recover_response` unless given), each exposure giving ``X_i = x_i / t_i``;
2. a first estimate ``E0`` is the hat-weighted mean of the ``X_i`` (linear domain);
3. the variance ``V(x)`` of a linearised code around the exposure ``x`` it should read is
   measured on the bracket: for every sample of a pixel with at least two usable exposures,
   the squared leave-one-out residual ``(x_i - t_i E_-i)^2`` (``E_-i``: the hat-weighted mean
   of the pixel's other exposures), binned by the code that ``t_i E_-i`` predicts and averaged
   per code and channel (smoothed over 9 codes; on at most 200 000 pixels, a regular
   subsample of larger images). It holds whatever noise the camera's
   pipeline leaves (photon and read noise, quantisation, film grain, JPEG) and the error of
   the recovered response; it is never below the quantisation ``(dx/dz)^2 / 12``;
4. the estimate is the inverse-variance mean ``E = sum_i w_i X_i / sum_i w_i`` with
   ``w_i = t_i^2 / V(t_i E)``: like :func:`merge_ml`, the variance is evaluated at the
   current *estimate*, never at the sample's own code: starting from ``E0``, ``max_iter``
   fixed-point updates (all are run; the keyword ``n_iter`` is deprecated) (at least one; the error changed by under 10 % between 1 and 4
   updates on the brackets of ``benchmarks/merge_8bit.py``). Weights taken at the observed
   code, ``t_i^2 / V(z_i)``, favour the samples that noise pushed down, since ``V`` grows
   with ``x``: on a noisy 16-exposure bracket of a real photograph (``tests/hdr/test_merge.py``)
   that mean had a log error of 0.21 against 0.075 now, and 0.61-0.96 of the Debevec merge.
   Its variance is ``1 / sum_i w_i``.

Codes 0 and ``>= saturation_code`` get weight 0 (clipped), and so does every longer exposure
of a pixel and channel clipped in a shorter one. Samples with no usable code are filled as
in :func:`merge_debevec` and flagged. The weights are tabulated scaled to a largest value of 1
(``t_i^2`` alone spans 30 stops for a bracket of 1/1000 s to 30 s): float32 when their range
allows, float64 otherwise; no cast can overflow.

References
----------
P. E. Debevec, J. Malik, "Recovering high dynamic range radiance maps from photographs",
SIGGRAPH 1997, doi:10.1145/258734.258884.
M. Granados, B. Ajdin, M. Wand, C. Theobalt, H.-P. Seidel, H. P. A. Lensch, "Optimal HDR
reconstruction with linear digital cameras", CVPR 2010, doi:10.1109/CVPR.2010.5540208.
C. Aguerrebere, J. Delon, Y. Gousseau, P. Muse, "Best algorithms for HDR image generation.
A study of performance bounds", SIAM J. Imaging Sci. 7(1), 2014, doi:10.1137/120891952.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._shared.deprecate import renamed_keywords
from .._shared.validation import check_choice
from .._shared.random import check_random_state
from .._shared.frozen import freeze
from .._shared.warn import warn_convergence, warn_saturation
from .._version import __version__
from ..errors import InputError, ShapeError, option_name
from ..lightfield import LightField
from ..sensor import calibrated_observation, iso_maps, load_profile

__all__ = [
    "MERGE_METHODS",
    "ML_TOLERANCE_STD",
    "merge_ml",
    "merge_debevec",
    "merge_ml_codes8",
    "recover_response",
    "hat_weight",
    "merge_lightfields",
    "merge_with_variances",
    "check_exposure_order",
]

MERGE_METHODS = ("ml", "debevec")
#: Convergence test of the ML merge's fixed-point updates: the last update must move every
#: sample by at most this fraction of its standard deviation, else :class:`ConvergenceWarning`.
#: Measured with merge_ml at max_iter = 0..5 on the simulated brackets of tests/hdr/test_merge.py and
#: tests/test_warnings.py: each update shrinks the change 6-15x; the second update (default
#: max_iter=2) moves samples by at most 0.03-0.12 sd, the first by up to 1.8 sd.
ML_TOLERANCE_STD = 0.25
_DEFAULT_CHUNK = 1 << 16
#: merge_ml_codes8 measures its code variance on a regular subsample of at most this many pixels
_V_MAX_PIXELS = 200_000


# -- validation helpers -------------------------------------------------------------------

def _as_stack(stack, name: str) -> np.ndarray:
    if isinstance(stack, np.ndarray):
        arr = stack
    else:
        items = [np.asarray(a) for a in stack]
        if not items:
            raise InputError(f"{name}: expected at least two exposures, got none")
        shapes = {a.shape for a in items}
        if len(shapes) != 1:
            raise ShapeError(f"{name}: every exposure must have the same shape, got {', '.join(map(str, shapes))}")
        arr = np.stack(items)
    if arr.ndim < 2:
        raise ShapeError(f"{name}: expected an array (N, ...) of N exposures, got shape {arr.shape}")
    if arr.shape[0] < 2:
        raise InputError(f"{name}: a bracket needs at least two exposures, got {arr.shape[0]}")
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ShapeError(f"{name}: expected numeric samples, got dtype {arr.dtype}")
    return arr


def _per_exposure(name: str, values, n: int) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(values, dtype=np.float64))
    if arr.ndim != 1 or arr.size not in (1, n):
        raise InputError(f"{name}: expected one value or {n} values (one per exposure), got {arr.size}")
    arr = np.broadcast_to(arr, (n,)).copy()
    if not (np.isfinite(arr).all() and (arr > 0).all()):
        raise InputError(f"{name}: expected positive finite values, got {arr.tolist()}")
    return arr


def _n_threads(n_threads: int | None) -> int:
    if n_threads is None:
        return max(1, min(4, os.cpu_count() or 1))
    if int(n_threads) < 1:
        raise InputError(f"n_threads: expected a positive integer, got {n_threads}")
    return int(n_threads)


def _run_chunks(func, total: int, chunk_size: int, n_threads: int) -> None:
    if chunk_size < 1:
        raise InputError(f"chunk_size: expected a positive integer, got {chunk_size}")
    bounds = [(a, min(a + chunk_size, total)) for a in range(0, total, chunk_size)]
    if n_threads == 1 or len(bounds) == 1:
        for a, b in bounds:
            func(a, b)
        return
    with ThreadPoolExecutor(max_workers=n_threads) as pool:  # numpy ufuncs release the GIL
        for _ in pool.map(lambda ab: func(*ab), bounds):
            pass


def _summary(mask_sat: np.ndarray, mask_dark: np.ndarray, *, stacklevel: int = 4) -> dict[str, Any]:
    """Saturated- and dark-everywhere masks and counts; :class:`SaturationWarning` at ``stacklevel``
    (4: the caller of the estimator that calls this; 5 when a keyword-renaming decorator wraps it)."""
    n = mask_sat.size
    count = int(mask_sat.sum())
    warn_saturation(count / n if n else 0.0, "exposure bracket", samples="samples (in every exposure)",
                    stacklevel=stacklevel, consequence="their merged values are lower bounds (the saturation level of the "
                    "shortest exposure); add a shorter exposure")
    return {
        "saturated_everywhere": mask_sat,
        "saturated_everywhere_count": count,
        "saturated_everywhere_fraction": count / n if n else 0.0,
        "dark_everywhere": mask_dark,
        "dark_everywhere_count": int(mask_dark.sum()),
    }


# -- the ML estimator ---------------------------------------------------------------------

@renamed_keywords(n_iter="max_iter")
def merge_ml(
    dn_stack,
    *,
    exposures_s: Sequence[float],
    isos: float | Sequence[float],
    profile,
    gamma: float | None = None,
    bias_dn: float | np.ndarray | None = None,
    max_iter: int = 2,
    saturation_margin_dn: float = 0.5,
    chunk_size: int = _DEFAULT_CHUNK,
    n_threads: int | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Noise-aware maximum-likelihood merge of linear sensor codes (see the module notes).

    Parameters
    ----------
    dn_stack : ndarray of shape (N, ...) or sequence of N arrays of one shape
        Sensor codes (DN, black level included) of N exposures; any sample shape, e.g.
        ``(N, H, W)``, ``(N, H, W, C)`` or ``(N, V, U, H, W, C)``. ``uint8``/``uint16`` codes
        use exact lookup tables; float codes are converted sample by sample.
    exposures_s : sequence of N floats
        Exposure times in seconds.
    isos : float or sequence of N floats
        ISO of each exposure (must be in ``profile``).
    profile : CameraProfile or name
        Gain, read noise, dark current, levels (:func:`lfproc.calib.load_profile`).
    gamma : float, optional
        Power-law response of the codes (default: the profile's).
    bias_dn : float or ndarray broadcastable to the sample shape, optional
        Bias frame (default: black level plus mean dark signal, see
        :func:`lfproc.camera.sensor.calibrated_observation`).
    max_iter : int
        Fixed-point updates of the weights after the read-noise start (>= 0, all are run; 0 keeps the
        read-noise weights and is not iterative, so it is never warned about). The keyword
        ``n_iter`` is deprecated.
    saturation_margin_dn : float
        Codes at or above saturation minus this margin get weight 0.
    chunk_size : int
        Samples processed at once (bounds the temporary memory to about 40 bytes x N x chunk).
    n_threads : int or None
        Threads working on chunks (None: up to 4, the CPU count).

    Returns
    -------
    radiance : ndarray, float32, sample shape
        Estimate in photo-electrons per second (may be slightly negative in the dark:
        the estimator is unbiased there).
    variance : ndarray, float32, sample shape
        ``1 / sum_i w_i`` at the estimate ((e-/s)^2).
    info : dict
        ``saturated_everywhere`` / ``dark_everywhere`` masks, their counts and the
        saturated fraction, ``n_used`` (usable exposures per sample, uint8), ``fill_radiance``
        (value given to saturated-everywhere samples), ``converged`` (None for ``max_iter=0``),
        method parameters.

    Warns
    -----
    ConvergenceWarning
        The last fixed-point update moved a sample by more than :data:`ML_TOLERANCE_STD` of
        its standard deviation.
    SaturationWarning
        More than :data:`lfproc.errors.SATURATION_WARNING_FRACTION` of the samples are
        saturated in every exposure (also :func:`merge_debevec`, :func:`merge_with_variances`).
    """
    profile = load_profile(profile)
    stack = _as_stack(dn_stack, "dn_stack")
    n = stack.shape[0]
    t = _per_exposure("exposures_s", exposures_s, n)
    iso = _per_exposure("isos", isos, n)
    n_iter = max_iter
    if int(n_iter) != n_iter or n_iter < 0 or n_iter > 100:
        raise InputError(f"max_iter: expected an integer from 0 to 100, got {n_iter}")
    n_threads = _n_threads(n_threads)
    sample_shape = stack.shape[1:]
    total = math.prod(sample_shape)
    bias_flat, bias_scalar = _bias_of(bias_dn, sample_shape)
    ml = _MlBracket.build(stack.reshape(n, total), t, iso, profile, gamma=gamma, bias_flat=bias_flat,
                          bias_scalar=bias_scalar, saturation_margin_dn=saturation_margin_dn)
    out = {"radiance": np.empty(total, dtype=np.float32), "variance": np.empty(total, dtype=np.float32),
           "sat": np.empty(total, dtype=bool), "dark": np.empty(total, dtype=bool),
           "n_used": np.empty(total, dtype=np.uint8), "moved": np.empty(total, dtype=bool)}
    _run_chunks(functools.partial(_ml_chunk, ml, out, n_iter=int(n_iter)), total, chunk_size, n_threads)
    n_moved = int(out["moved"].sum())
    if n_iter and n_moved:
        warn_convergence(
            f"ML merge: the weights did not converge in {int(n_iter)} fixed-point update(s): the last update moved "
            f"{n_moved} sample(s) ({100 * n_moved / total:.2g} %) by more than {ML_TOLERANCE_STD:g} of their "
            f"standard deviation; use more iterations ({option_name('max_iter', '--iterations')})", stacklevel=4
        )
    info = _summary(out["sat"].reshape(sample_shape), out["dark"].reshape(sample_shape), stacklevel=5)
    info.update({
        "method": "ml",
        "converged": not n_moved if n_iter else None,
        "n_used": out["n_used"].reshape(sample_shape),
        "fill_radiance": ml.fill,
        "fill": "saturated-everywhere samples = saturation level of the shortest exposure (lower bound), "
                "variance = value^2",
        "exposures_s": t.tolist(),
        "isos": iso.tolist(),
        "n_iter": int(n_iter),
        "profile": profile.name,
    })
    return out["radiance"].reshape(sample_shape), out["variance"].reshape(sample_shape), info


def _bias_of(bias_dn, sample_shape) -> tuple[np.ndarray | None, float | None]:
    """``bias_dn`` as a flat per-sample array (an array given) or a scalar (a number or None: both None)."""
    if bias_dn is not None and np.ndim(bias_dn) > 0:
        try:
            flat = np.broadcast_to(np.asarray(bias_dn, dtype=np.float64), sample_shape).reshape(math.prod(sample_shape))
        except ValueError:
            raise ShapeError(f"bias_dn: shape {np.shape(bias_dn)} does not broadcast to the samples {sample_shape}") from None
        return flat, None
    return None, None if bias_dn is None else float(bias_dn)


@dataclass
class _MlBracket:
    """A bracket of linear codes being merged by :func:`merge_ml`: codes ``(N, P)``, exposures, ISOs, the
    sensor model's observation of a code, the exposure order (least exposed first, time x gain), lookup
    tables of integer codes and the fill value of saturated-everywhere samples."""
    flat: np.ndarray
    t: np.ndarray
    iso: np.ndarray
    profile: Any
    gamma: float | None
    bias_flat: np.ndarray | None
    bias_scalar: float | None
    saturation_margin_dn: float
    order: np.ndarray | None = None
    luts: list | None = None
    fill: float = 0.0

    @classmethod
    def build(cls, flat, t, iso, profile, **kw) -> "_MlBracket":
        ml = cls(flat=flat, t=t, iso=iso, profile=profile, **kw)
        # exposures from the least to the most exposed (time x gain) for the saturation guard
        gains = np.array([iso_maps(profile, i, (1,))["gain_dn_per_e"][0] for i in iso])
        ml.order = np.argsort(t * gains, kind="stable")
        if flat.dtype in (np.uint8, np.uint16) and ml.bias_flat is None:
            codes = np.arange(np.iinfo(flat.dtype).max + 1, dtype=np.float64)
            ml.luts = [ml.observe(i, codes, ml.bias_scalar) for i in range(len(t))]
        # fill value of saturated-everywhere samples: the saturation code of the least exposed shot
        first = int(ml.order[0])
        sat_code = iso_maps(profile, iso[first], (1,))["saturation_dn"][0]
        bias = ml.bias_scalar if ml.bias_flat is None else float(np.mean(ml.bias_flat))
        ml.fill = max(float(ml.observe(first, np.array([sat_code]), bias)[0][0]), 0.0)
        return ml

    def observe(self, i: int, codes: np.ndarray, bias) -> tuple[np.ndarray, ...]:
        """Radiance (e-/s), read-noise variance, saturated and black-clipped flags of ``codes`` in exposure ``i``."""
        obs = calibrated_observation(
            codes[None, :], exposure_s=self.t[i], iso=self.iso[i], profile=self.profile, gamma=self.gamma,
            bias_dn=bias, saturation_margin_dn=self.saturation_margin_dn, variance_from="estimate",
            radiance_estimate=0.0,
            correct_fixed_pattern=False,  # codes here are tables or samples, not one sensor image
        )
        return obs.radiance[0], obs.variance[0], obs.saturated[0], obs.black_clipped[0]


def _ml_chunk(ml: _MlBracket, out: dict[str, np.ndarray], a: int, b: int, *, n_iter: int) -> None:
    """The ML estimate of samples ``a:b`` (module notes): observations, the saturation guard, read-noise
    weights then ``n_iter`` fixed-point updates, the fills; written into ``out``."""
    n, c = len(ml.t), b - a
    flat, order = ml.flat, ml.order
    inv_t = (1.0 / ml.t).astype(np.float32)
    T = np.empty((n, c), np.float32)
    V0 = np.empty((n, c), np.float32)
    S = np.empty((n, c), bool)
    B = np.empty((n, c), bool)
    for i in range(n):
        if ml.luts is not None:
            idx = flat[i, a:b]
            T[i], V0[i], S[i], B[i] = (lut[idx] for lut in ml.luts[i])
        else:
            bias = ml.bias_scalar if ml.bias_flat is None else ml.bias_flat[a:b]
            T[i], V0[i], S[i], B[i] = ml.observe(i, flat[i, a:b].astype(np.float64), bias)
    # saturated in a less exposed shot -> unusable in every more exposed one
    S[order] = np.logical_or.accumulate(S[order], axis=0)
    usable = ~(S | B)
    tmp = np.empty((n, c), np.float32)
    w = np.empty((n, c), np.float32)

    def weights(x):
        np.multiply(inv_t[:, None], np.maximum(x, 0)[None, :], out=tmp)
        np.add(tmp, V0, out=tmp)
        np.divide(usable, tmp, out=w)
        return w.sum(axis=0)

    def mean(wsum):
        return np.einsum("ij,ij->j", w, T) / np.where(wsum > 0, wsum, 1)

    x = mean(weights(np.zeros(c, np.float32)))  # read-noise weights
    x_prev = x
    for _ in range(n_iter):
        x_prev, x = x, mean(weights(x))
    wsum = weights(x)  # variance at the final estimate
    none = wsum <= 0
    var = 1.0 / np.where(none, 1, wsum)
    out["moved"][a:b] = ~none & (np.abs(x - x_prev) > ML_TOLERANCE_STD * np.sqrt(var))
    sat = none & S.any(axis=0)
    dark = none & ~sat
    x[sat] = ml.fill
    var[sat] = ml.fill * ml.fill
    if dark.any():
        last = int(order[-1])
        x[dark] = np.maximum(T[last, dark], 0)
        var[dark] = V0[last, dark]
    out["radiance"][a:b] = x
    out["variance"][a:b] = var
    out["sat"][a:b] = sat
    out["dark"][a:b] = dark
    out["n_used"][a:b] = usable.sum(axis=0)


def merge_with_variances(
    values,
    variances,
    *,
    exposures_s: Sequence[float],
    unusable_variance: float = 1.0e6,
    saturation_value: float = 0.5,
    chunk_size: int = _DEFAULT_CHUNK,
    n_threads: int | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Inverse-variance merge of linear inputs that carry their own per-sample variance.

    For decoded captures (e.g. :func:`lfproc.lytro.decode.decode_capture`, whose variances come
    from the sensor noise model): ``x = sum_i w_i v_i / t_i / sum_i w_i`` with
    ``w_i = t_i^2 / var_i``, 0 where ``var_i >= unusable_variance`` (saturated or unusable
    samples, and every longer exposure of a sample unusable-and-bright in a shorter one). The
    variances are the inputs' own (evaluated at each measurement), so this is the plug-in
    form of the ML estimator. Samples with no usable exposure take the shortest exposure's
    ``v / t`` and are flagged as saturated everywhere when that value is at least
    ``saturation_value``, else as dark everywhere.

    Parameters
    ----------
    values : ndarray of shape (N, ...) or sequence of N arrays
        Linear values of the N exposures (any sample shape, the same for all).
    variances : ndarray of shape (N, ...) or sequence of N arrays
        Variance of every value, in the values' units squared.
    exposures_s : sequence of N floats
        Exposure times in seconds (or relative exposures).
    unusable_variance : float, default 1e6
        Samples with a variance at or above it (or non-finite values) get weight 0.
    saturation_value : float, default 0.5
        An unusable sample at or above this value counts as saturated: longer exposures of the
        sample are not used either, and a sample with no usable exposure is flagged as
        saturated everywhere.
    chunk_size, n_threads : int
        As for :func:`merge_ml`.

    Returns
    -------
    radiance : ndarray, float32, sample shape
        Input units per second.
    variance : ndarray, float32, sample shape
        ``1 / sum_i w_i`` (``value^2`` where no exposure was usable).
    info : dict
        Masks and counts as :func:`merge_ml` (``saturated_everywhere``, ``dark_everywhere``...),
        ``method``, ``weights``, ``fill``, ``exposures_s``.

    Raises
    ------
    lfproc.errors.ShapeError
        ``values`` and ``variances`` differ in shape.
    lfproc.errors.InputError
        Exposure times that are not one positive number per exposure.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.hdr import merge_with_variances
    >>> values = np.array([[0.1, 0.2], [0.4, 1.0]])      # 2 exposures (rows) of 2 samples
    >>> variances = np.array([[1e-4, 1e-4], [4e-4, 1e9]])  # the second sample saturates at 4 s
    >>> x, var, info = merge_with_variances(values, variances, exposures_s=[1.0, 4.0])
    >>> [round(float(v), 4) for v in x], info["saturated_everywhere_count"]
    ([0.1, 0.2], 0)
    >>> [round(float(v) * 1e5, 3) for v in var]    # 1 / (1 / 1e-4 + 4^2 / 4e-4), and 1e-4
    [2.0, 10.0]
    """
    vals = _as_stack(values, "values")
    var_in = _as_stack(variances, "variances")
    if vals.shape != var_in.shape:
        raise ShapeError(f"variances: shape {var_in.shape} differs from the values {vals.shape}")
    n = vals.shape[0]
    t = _per_exposure("exposures_s", exposures_s, n)
    sample_shape = vals.shape[1:]
    total = math.prod(sample_shape)
    fv = vals.reshape(n, total)
    fvar = var_in.reshape(n, total)
    order = np.argsort(t, kind="stable")
    first = int(order[0])
    t2 = (t**2).astype(np.float32)[:, None]
    inv_t = (1 / t).astype(np.float32)[:, None]
    radiance = np.empty(total, np.float32)
    variance = np.empty(total, np.float32)
    sat_all = np.empty(total, bool)
    dark_all = np.empty(total, bool)

    def work(a: int, b: int) -> None:
        v = fv[:, a:b].astype(np.float32)
        s2 = fvar[:, a:b].astype(np.float32)
        bad = ~(s2 < unusable_variance) | ~np.isfinite(v)
        bright_bad = bad & (v >= saturation_value)
        bad[order] |= np.logical_or.accumulate(bright_bad[order], axis=0)
        w = np.where(bad, 0, t2 / np.maximum(s2, 1e-30)).astype(np.float32)
        wsum = w.sum(axis=0)
        none = wsum <= 0
        x = (w * np.where(bad, 0, v) * inv_t).sum(axis=0) / np.where(none, 1, wsum)
        var = 1 / np.where(none, 1, wsum)
        fill = np.maximum(np.nan_to_num(v[first]), 0) / t[first]
        sat = none & (v[first] >= saturation_value)
        x = np.where(none, fill, x)
        var = np.where(none, np.maximum(fill, 1e-30) ** 2, var)
        radiance[a:b] = x
        variance[a:b] = var
        sat_all[a:b] = sat
        dark_all[a:b] = none & ~sat

    _run_chunks(work, total, chunk_size, _n_threads(n_threads))
    info = _summary(sat_all.reshape(sample_shape), dark_all.reshape(sample_shape))
    info.update({
        "method": "ml",
        "weights": "inverse of the inputs' own variances",
        "fill": "samples with no usable exposure = shortest exposure's value (lower bound when saturated), "
                "variance = value^2",
        "exposures_s": t.tolist(),
    })
    return radiance.reshape(sample_shape), variance.reshape(sample_shape), info


# -- Debevec & Malik ------------------------------------------------------------------------

def hat_weight(z: np.ndarray) -> np.ndarray:
    """Debevec & Malik's hat weight of normalised codes ``z`` in [0, 1]: ``min(z, 1 - z)``, 0 outside.

    Parameters
    ----------
    z : array_like
        Codes divided by their largest value; any shape.

    Returns
    -------
    ndarray
        Weights in [0, 0.5], float32, the shape of ``z``.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.hdr import hat_weight
    >>> [round(float(w), 3) for w in hat_weight(np.array([-0.1, 0.0, 0.25, 0.5, 0.9, 1.2]))]
    [0.0, 0.0, 0.25, 0.5, 0.1, 0.0]
    """
    z = np.asarray(z, dtype=np.float32)
    return np.clip(np.minimum(z, 1 - z), 0, None)


def _check_codes8(images: np.ndarray, name: str) -> None:
    if images.dtype != np.uint8:
        raise InputError(f"{name}: response recovery needs 8-bit codes (uint8), got dtype {images.dtype}")


def _flatness(stack: np.ndarray, ref: int, spatial: tuple[int, int] | None) -> np.ndarray | None:
    """Local variance (5 x 5 box) of exposure ``ref`` of one channel, flattened; None without 2-D images."""
    import cv2

    if spatial is None:
        return None
    h, w = spatial
    img = stack[ref].reshape(-1, h, w).astype(np.float32)
    out = np.empty_like(img)
    for k in range(img.shape[0]):  # every view of a light field on its own
        m = cv2.blur(img[k], (5, 5))
        out[k] = cv2.blur(img[k] * img[k], (5, 5)) - m * m
    return np.maximum(out, 0).ravel()


def _select_pixels(codes: np.ndarray, t: np.ndarray, n_samples: int, flat: np.ndarray | None, rng,
                   max_candidates: int = 100_000) -> np.ndarray:
    """Pixels for the response recovery: stratified over the scene's radiance, flattest first.

    The sum of a pixel's codes over the exposures grows with its radiance, so 256 buckets of that
    sum cover the radiance range from the darkest to the brightest pixel (Debevec's sampling of
    one exposure's codes lumps every pixel that is black or white in it). Within a bucket the
    pixels with the lowest local variance come first: they are least affected by JPEG
    compression, demosaicing and small misalignment (Debevec & Malik's advice to sample
    regions of low intensity variance).
    """
    n, total = codes.shape
    step = max(1, -(-total // max_candidates))
    cand = np.arange(rng.integers(step), total, step)  # a regular lattice of candidates
    ksum = codes[:, cand].sum(axis=0, dtype=np.int32)
    buckets = 256
    b = (ksum * buckets // (255 * n + 1)).astype(np.float64)
    key2 = flat[cand].astype(np.float64) if flat is not None else rng.random(cand.size)
    order = np.argsort(b + key2 / (key2.max() + 1.0))  # bucket, then flattest first
    bs = b[order]
    rank = np.arange(bs.size) - np.searchsorted(bs, bs, side="left")
    per = max(1, -(-n_samples // buckets))
    picked = order[rank < per]
    if picked.size < n_samples:  # few occupied buckets: fill with the next flattest pixels
        rest = order[(rank >= per)]
        picked = np.concatenate([picked, rest[: n_samples - picked.size]])
    return cand[picked]


#: Default relative weight of the response recovery's curvature term (see :func:`recover_response`).
DEFAULT_SMOOTHNESS = 3000.0


def recover_response(
    images,
    *,
    exposures_s: Sequence[float],
    n_samples: int = 4000,
    smoothness: float = DEFAULT_SMOOTHNESS,
    random_state=None,
) -> np.ndarray:
    """Recover the log inverse camera response ``g(z) = ln f^-1(z)`` from 8-bit brackets.

    The least-squares problem of Debevec & Malik (1997), ``gsolve``: for sampled pixels ``j``
    and exposures ``i``, ``w(z_ij) [g(z_ij) - ln E_j - ln t_i] = 0``; ``g(128) = 0``; and
    ``lambda * w(z) [g(z-1) - 2 g(z) + g(z+1)] = 0`` for z in 1..254, with Debevec's hat
    ``w(z) = min(z, 255 - z)`` (the extreme codes 0 and 255 carry no data weight: they are
    clipped). Differences from the paper's (and OpenCV's ``CalibrateDebevec``) solution:

    * many more pixels (``n_samples``, default 4000 per channel, against Debevec's 50 and
      OpenCV's 70), chosen stratified over the radiance range and flattest first
      (:func:`_select_pixels`);
    * the unknown log radiances ``ln E_j`` are eliminated in closed form (each is the weighted
      mean of its pixel's ``g(z_ij) - ln t_i``), which leaves a dense 256 x 256 normal system
      whatever the number of pixels: solved with LAPACK in milliseconds instead of an SVD of a
      ``(P N + 255) x (256 + P)`` matrix;
    * ``smoothness`` is relative to the data: the curvature term is scaled by the total data
      weight over the total smoothness weight, so the same value means the same trade-off
      for any number of pixels and exposures. The default (:data:`DEFAULT_SMOOTHNESS`, 3000;
      10 before) was measured with ``benchmarks/merge_8bit.py`` on 8-bit JPEG brackets simulated
      from 13 real HDR photographs (512 x 768), RMS log-luminance error of merge_debevec against
      the photograph (gain fitted): with 10 the recovered ``g`` had bumps of 0.1-0.2 between the codes where the
      bracket's radiances cluster, and lfproc's merge was worse than OpenCV's on 7 of 13 images
      of 3 exposures 3 stops apart (mean 0.123 against OpenCV's 0.112; 3000: 0.050, none worse)
      and on 3 of 13 of 16 exposures one stop apart (3000: none worse; ``interior`` ties).
      With 3 exposures one stop apart the means are 0.050 (10), 0.048 (1000) and 0.049 (3000);
      there 3000 is worse than OpenCV on ``interior`` (0.048 against 0.041), 1000 and 10 are not;
    * ``g`` is made non-decreasing afterwards (a response is monotonic; noise can break it).

    Parameters
    ----------
    images : ndarray of shape (N, ..., C), uint8
        N exposures; channels on the last axis (a 2-D ``(N, H, W)`` stack is one channel).
        Images (or light-field views) of at least 5 x 5 pixels rank pixels by local variance.
    exposures_s : sequence of N floats
    n_samples : int
        Pixels used per channel (>= 2).
    smoothness : float
        Relative weight ``lambda`` of the second-derivative term (> 0).
    random_state : int, Generator or None
        Seeds the offset of the candidate lattice of images larger than 100 000 pixels.

    Returns
    -------
    ndarray of shape (256, C), float64
        ``g`` per channel, ``g(128) = 0``.
    """
    stack = _as_stack(images, "images")
    _check_codes8(stack, "images")
    n = stack.shape[0]
    t = _per_exposure("exposures_s", exposures_s, n)
    if stack.ndim == 3:
        stack = stack[..., None]
    if int(n_samples) < 2:
        raise InputError(f"n_samples: expected at least 2, got {n_samples}")
    if not (np.isfinite(smoothness) and smoothness > 0):
        raise InputError(f"smoothness: expected a positive number, got {smoothness}")
    rng = check_random_state(random_state)
    c = stack.shape[-1]
    spatial = stack.shape[-3:-1] if stack.ndim >= 4 and min(stack.shape[-3:-1]) >= 5 else None
    flat = stack.reshape(n, -1, c)
    mid = int(np.argsort(t)[n // 2])
    w = np.minimum(np.arange(256), 255 - np.arange(256)).astype(np.float64)  # Debevec's hat on codes
    log_t = np.log(t)
    out = np.empty((256, c))
    for ch in range(c):
        codes = flat[:, :, ch]
        picks = _select_pixels(codes, t, int(n_samples), _flatness(stack[..., ch], mid, spatial), rng)
        Z = codes[:, picks].T.astype(np.intp)  # (P, N)
        out[:, ch] = _gsolve(Z, log_t, float(smoothness), w)
    return out


def _gsolve(Z: np.ndarray, log_t: np.ndarray, smoothness: float, w: np.ndarray) -> np.ndarray:
    """Debevec's least squares with the pixel unknowns eliminated (see :func:`recover_response`).

    Pixel ``j`` contributes ``sum_i w_ij^2 (g(z_ij) - ln t_i - m_j)^2`` with ``m_j`` its weighted
    mean of ``g(z_ij) - ln t_i`` (the optimal ``ln E_j``); its normal-equation terms are
    ``diag(sum_i w_ij^2 e_z) - u_j u_j^T / S_j`` (``u_j = sum_i w_ij^2 e_{z_ij}``,
    ``S_j = sum_i w_ij^2``), accumulated for all pixels with ``bincount``.
    """
    W2 = w[Z] ** 2
    usable = (W2 > 0).sum(axis=1) >= 2  # one weighted exposure says nothing about g
    Z, W2 = Z[usable], W2[usable]
    if Z.shape[0] == 0:
        raise InputError("response recovery: no pixel is well exposed (codes 1..254) in two exposures")
    S = W2.sum(axis=1)
    m = (W2 * log_t).sum(axis=1) / S
    M = np.diag(np.bincount(Z.ravel(), W2.ravel(), 256))
    rhs = np.bincount(Z.ravel(), (W2 * (log_t[None, :] - m[:, None])).ravel(), 256)
    pair = (Z[:, :, None] * 256 + Z[:, None, :]).ravel()
    M -= np.bincount(pair, (W2[:, :, None] * W2[:, None, :] / S[:, None, None]).ravel(), 65536).reshape(256, 256)
    zz = np.arange(1, 255)
    D = np.zeros((254, 256))
    D[np.arange(254), zz - 1] = 1.0
    D[np.arange(254), zz] = -2.0
    D[np.arange(254), zz + 1] = 1.0
    ws = w[zz] ** 2
    M += smoothness * W2.sum() / ws.sum() * (D.T * ws) @ D
    # g(128) = 0: drop the unknown (its row and column become the identity)
    M[128, :] = 0.0
    M[:, 128] = 0.0
    M[128, 128] = 1.0
    rhs[128] = 0.0
    # a 256 x 256 solve takes ~1 ms on one thread; a multithreaded BLAS waking its pool on a busy
    # machine can take hundreds of times longer, so it gets one thread
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        g = np.linalg.solve(M, rhs)
    # monotonic from the anchor outwards
    g[128:] = np.maximum.accumulate(g[128:])
    g[:129] = -np.maximum.accumulate(-g[:129][::-1])[::-1]
    return g - g[128]


def merge_debevec(
    images,
    *,
    exposures_s: Sequence[float],
    response: np.ndarray | str | None = None,
    white_level: float | None = None,
    black_level: float = 0.0,
    n_samples: int = 4000,
    smoothness: float = DEFAULT_SMOOTHNESS,
    saturation_code: int = 254,
    random_state=None,
    chunk_size: int = _DEFAULT_CHUNK,
    n_threads: int | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Debevec & Malik (1997) merge: hat weights, log-domain mean (see the module notes).

    Parameters
    ----------
    images : ndarray of shape (N, ...) or sequence of N arrays
        8-bit non-linear codes (``uint8``, channels last when ``response`` has several
        channels) or linear data (``uint16`` DN or floats) clipping at ``white_level``.
    exposures_s : sequence of N floats
        Exposure times in seconds (or relative exposures).
    response : None, "linear" or ndarray of shape (256,) or (256, C)
        ``g(z) = ln f^-1(z)`` of 8-bit codes. None: recovered with :func:`recover_response`
        for uint8 input, linear for other input. "linear": ``g(z) = ln(z / 255)``.
    white_level : float, optional
        Saturation value of linear input (default: the dtype's maximum for integers; required
        for floats).
    black_level : float
        Offset subtracted from linear input.
    n_samples, smoothness, random_state : response recovery options.
    saturation_code : int
        8-bit codes at or above it count as clipped: such a sample gets weight 0 in every
        *longer* exposure of the same pixel and channel (a longer exposure cannot be darker;
        when it reads darker, JPEG ringing, chroma subsampling or blooming made it so). Linear
        input uses ``white_level``.
    chunk_size, n_threads : as for :func:`merge_ml`.

    Returns
    -------
    radiance : ndarray, float32, sample shape
        Relative radiance: for linear input, units of ``(white - black) / s``; for 8-bit
        input, ``exp(g)`` per second with ``g(128) = 0``.
    info : dict
        Masks and counts as for :func:`merge_ml`, ``response`` (the ``g`` used, 8-bit only).

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.hdr import merge_debevec
    >>> radiance = np.geomspace(0.01, 100, 12).reshape(3, 4)     # 4 decades
    >>> t = np.array([0.01, 0.1, 1.0])
    >>> bracket = np.clip(radiance * t[:, None, None], 0, 1)      # linear, clipping at 1
    >>> merged, info = merge_debevec(bracket, exposures_s=t, white_level=1.0)
    >>> bool(np.allclose(merged, radiance, rtol=1e-4)), info["saturated_everywhere_count"]
    (True, 1)
    """
    stack = _as_stack(images, "images")
    n = stack.shape[0]
    t = _per_exposure("exposures_s", exposures_s, n)
    log_t = np.log(t).astype(np.float32)
    if not 1 <= int(saturation_code) <= 255:
        raise InputError(f"saturation_code: expected an 8-bit code in 1..255, got {saturation_code}")
    sample_shape = stack.shape[1:]
    codes8 = stack.dtype == np.uint8
    g = None
    if stack.dtype == np.uint8:
        g = _response_lut(stack, t, response, n_samples, smoothness, random_state)
        if g.shape[1] not in (1, stack.shape[-1]) or (g.shape[1] > 1 and stack.ndim < 3):
            raise ShapeError(f"response: {g.shape[1]} channels do not match the images' last axis {stack.shape[-1]}")
    else:
        codes8 = False
        if isinstance(response, np.ndarray) or (response is not None and response != "linear"):
            raise InputError("response: a camera response applies to 8-bit codes only; linear input takes None or 'linear'")
        if white_level is None:
            if np.issubdtype(stack.dtype, np.integer):
                white_level = float(np.iinfo(stack.dtype).max)
            else:
                raise InputError("white_level: float input needs its saturation level (white_level=...)")
    n_threads = _n_threads(n_threads)
    order = np.argsort(t, kind="stable")
    first = int(order[0])
    channels = stack.shape[-1] if (codes8 and g.shape[1] > 1) else 1
    total = math.prod(sample_shape) // channels
    flat = stack.reshape(n, total, channels)
    radiance = np.empty((total, channels), np.float32)
    sat_all = np.empty((total, channels), bool)
    dark_all = np.empty((total, channels), bool)
    if codes8:
        g32 = g.astype(np.float32)
        w_lut = hat_weight(np.arange(256) / 255.0)
        fill_log = g32[255, np.arange(channels)] - log_t[first]
        # one table per exposure: weight and g(z) - ln t_i; zero weight from the clipping code up
        luts = [(g32 - log_t[i]).astype(np.float32) for i in range(n)]
        w8 = np.repeat(w_lut[:, None], channels, axis=1).astype(np.float32)
        span = None
    else:
        span = float(white_level) - float(black_level)
        if span <= 0:
            raise InputError(f"white_level ({white_level}) must exceed black_level ({black_level})")
        fill_log = np.full(channels, -log_t[first], np.float32)
        luts = w8 = None
    deb = _DebevecBracket(flat=flat, t=t, log_t=log_t, order=order, codes8=codes8, saturation_code=saturation_code,
                          luts=luts, w8=w8, black_level=black_level, span=span, fill_log=fill_log)
    out = {"radiance": radiance, "sat": sat_all, "dark": dark_all}
    _run_chunks(functools.partial(_debevec_chunk, deb, out), total, max(1, chunk_size // channels), n_threads)
    info = _summary(sat_all.reshape(sample_shape), dark_all.reshape(sample_shape))
    info.update({
        "method": "debevec",
        "exposures_s": t.tolist(),
        "fill": "saturated-everywhere samples = saturation level of the shortest exposure (lower bound)",
        "response": None if g is None else g,
        "response_kind": None if g is None else ("recovered" if response is None else "given"),
    })
    return radiance.reshape(sample_shape), info


@dataclass(frozen=True)
class _DebevecBracket:
    """A bracket being merged by :func:`merge_debevec`: samples ``(N, P, C)``, exposures (and their logs,
    order shortest first), 8-bit tables (weight, ``g(z) - ln t_i``) or the linear span, the fill of
    saturated-everywhere samples (log)."""
    flat: np.ndarray
    t: np.ndarray
    log_t: np.ndarray
    order: np.ndarray
    codes8: bool
    saturation_code: int
    luts: list | None
    w8: np.ndarray | None
    black_level: float
    span: float | None
    fill_log: np.ndarray


def _debevec_chunk(deb: _DebevecBracket, out: dict[str, np.ndarray], a: int, b: int) -> None:
    """The hat-weighted log-domain mean of samples ``a:b`` and the fills of those without a usable sample."""
    flat, codes8, black_level, span = deb.flat, deb.codes8, deb.black_level, deb.span
    first, last = int(deb.order[0]), int(deb.order[-1])
    c, channels = b - a, flat.shape[2]
    num = np.zeros((c, channels), np.float32)
    den = np.zeros((c, channels), np.float32)
    clipped = np.zeros((c, channels), bool)
    for i in deb.order:  # shortest exposure first: a clipped sample voids the longer ones
        zc = flat[i, a:b]
        if codes8:
            clipped |= zc >= deb.saturation_code
            w = _lut8(zc, deb.w8)
            lg = _lut8(zc, deb.luts[i])
        else:
            z = (zc.astype(np.float32) - np.float32(black_level)) / np.float32(span)
            clipped |= z >= 1
            w = hat_weight(z)
            lg = np.log(np.maximum(z, np.float32(1e-30))) - deb.log_t[i]
        w[clipped] = 0
        num += w * lg
        den += w
    none = den <= 0
    lnE = num / np.where(none, 1, den)
    zf = flat[first, a:b]
    sat = none & ((zf >= 128) if codes8 else ((zf.astype(np.float32) - black_level) / span >= 0.5))
    dark = none & ~sat
    lnE = np.where(sat, deb.fill_log[None, :], lnE)
    x = np.exp(lnE)
    if dark.any():
        zl = flat[last, a:b]
        if codes8:
            dark_value = np.exp(_lut8(zl, deb.luts[last]))
        else:
            dark_value = np.maximum((zl.astype(np.float32) - black_level) / span, 0) / np.float32(deb.t[last])
        x = np.where(dark, dark_value, x)
    out["radiance"][a:b] = x
    out["sat"][a:b] = sat
    out["dark"][a:b] = dark


def _lut8(codes: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """``lut[codes, channel]`` for uint8 ``codes`` of shape (P, C) and a (256, C) float32 table.

    OpenCV's LUT (per-channel tables for up to 4 channels) is about twice as fast as numpy's
    fancy indexing; other channel counts use numpy.
    """
    import cv2

    ch = codes.shape[1]
    if ch in (1, 3, 4) and codes.shape[0] > 0:
        out = cv2.LUT(np.ascontiguousarray(codes).reshape(-1, 1, ch), np.ascontiguousarray(lut, dtype=np.float32).reshape(1, 256, ch) if ch > 1
                      else np.ascontiguousarray(lut[:, 0], dtype=np.float32).reshape(1, 256))
        return out.reshape(codes.shape)
    return lut[codes.astype(np.intp), np.arange(ch)]


def _response_lut(stack: np.ndarray, t: np.ndarray, response, n_samples, smoothness, random_state) -> np.ndarray:
    """``g`` of shape (256, C) for 8-bit codes: recovered (None), ``"linear"`` or given."""
    if response is None:
        return recover_response(stack, exposures_s=t, n_samples=n_samples, smoothness=smoothness,
                                random_state=random_state)
    if isinstance(response, str):
        check_choice("response", response, ("linear",))
        with np.errstate(divide="ignore"):
            g = np.log(np.arange(256) / 255.0)[:, None]
        g[0] = g[1]
        return g
    g = np.asarray(response, dtype=np.float64)
    if g.ndim == 1:
        g = g[:, None]
    if g.shape[0] != 256 or g.ndim != 2 or not np.isfinite(g).all():
        raise ShapeError(f"response: expected a finite array of shape (256,) or (256, C), got {g.shape}")
    return g


@renamed_keywords(n_iter="max_iter")
def merge_ml_codes8(
    images,
    *,
    exposures_s: Sequence[float],
    response: np.ndarray | str | None = None,
    max_iter: int = 2,
    n_samples: int = 4000,
    smoothness: float = DEFAULT_SMOOTHNESS,
    saturation_code: int = 254,
    random_state=None,
    chunk_size: int = _DEFAULT_CHUNK,
    n_threads: int | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Noise-aware (inverse-variance) merge of non-linear 8-bit codes through a camera response.

    The ML estimator of :func:`merge_ml` needs the sensor's gain and read noise (a profile and
    an ISO); a JPEG has neither: the code variance is measured on the bracket itself (see
    "Noise-aware merge of 8-bit codes" in the module documentation).

    Parameters
    ----------
    images : ndarray of shape (N, ...), uint8, or sequence of N arrays
        Non-linear 8-bit codes of the N exposures (channels last when ``response`` has several).
    exposures_s : sequence of N floats
        Exposure times in seconds (or relative exposures).
    response : None, "linear" or ndarray of shape (256,) or (256, C)
        ``g(z) = ln f^-1(z)``, as for :func:`merge_debevec` (None: recovered).
    max_iter : int, default 2
        Fixed-point updates of the weights at the current estimate (>= 0).
    n_samples, smoothness, random_state
        Response recovery options (:func:`recover_response`).
    saturation_code : int, default 254
        Codes at or above it are clipped (1..255).
    chunk_size, n_threads : int
        As for :func:`merge_ml`.

    Returns
    -------
    radiance : ndarray, float32, sample shape
        Relative radiance per second (``exp(g)`` units, ``g(128) = 0``), as :func:`merge_debevec`.
    variance : ndarray, float32
        ``1 / sum_i w_i`` (the noise measured on the bracket, propagated).
    info : dict
        As :func:`merge_debevec`, plus ``code_variance`` (the measured ``V`` at each code's
        exposure ``exp(g(z))``, shape (256, C)) and ``n_iter`` (the updates run).
    """
    stack = _as_stack(images, "images")
    _check_codes8(stack, "images")
    n = stack.shape[0]
    t = _per_exposure("exposures_s", exposures_s, n)
    if not 1 <= int(saturation_code) <= 255:
        raise InputError(f"saturation_code: expected an 8-bit code in 1..255, got {saturation_code}")
    n_iter = max_iter
    if int(n_iter) < 0:
        raise InputError(f"max_iter: expected a non-negative integer, got {n_iter}")
    sample_shape = stack.shape[1:]
    g = _response_lut(stack, t, response, n_samples, smoothness, random_state)
    channels = g.shape[1]
    if channels > 1 and (stack.ndim < 3 or stack.shape[-1] != channels):
        raise ShapeError(f"response: {channels} channels do not match the images' last axis {stack.shape[-1]}")
    total = math.prod(sample_shape) // channels
    flat = stack.reshape(n, total, channels)
    n_threads = _n_threads(n_threads)
    order = np.argsort(t, kind="stable")
    first, last = int(order[0]), int(order[-1])
    x_lut = np.exp(g).astype(np.float32)  # (256, C)
    if x_lut.shape[1] != channels:
        x_lut = np.repeat(x_lut, channels, axis=1)
    x64 = x_lut.astype(np.float64)
    c8 = _Codes8(flat=flat, t=t, order=order, saturation_code=saturation_code, channels=channels,
                 x_t=[(x_lut / np.float32(t[i])) for i in range(n)],  # X_i = x / t_i per exposure
                 grid=_CodeGrid.build(x64, saturation_code, channels))
    chunk = max(1, chunk_size // channels)
    V = _code_variance(c8, x64, total=total, chunk=chunk, n_threads=n_threads)
    w_tables, w_scale, w_dtype = _weight_tables(V, t, c8.grid)
    fill = (x_lut[255] / t[first]).astype(np.float32)
    out = {"radiance": np.empty((total, channels), np.float32), "variance": np.empty((total, channels), np.float32),
           "sat": np.empty((total, channels), bool), "dark": np.empty((total, channels), bool)}

    def work(a: int, b: int) -> None:
        _codes8_chunk(c8, a, b, out, n_iter=n_iter, w_tables=w_tables, w_scale=w_scale, w_dtype=w_dtype,
                      fill=fill, last=last)

    _run_chunks(work, total, chunk, n_threads)
    info = _summary(out["sat"].reshape(sample_shape), out["dark"].reshape(sample_shape), stacklevel=5)
    info.update({
        "method": "ml",
        "weights": "inverse of the code variance measured on the bracket at the estimate, t^2 / V(t E)",
        "exposures_s": t.tolist(),
        "fill": "saturated-everywhere samples = saturation level of the shortest exposure (lower bound), "
                "variance = value^2",
        "response": g,
        "response_kind": "recovered" if response is None else "given",
        "code_variance": V,
        "n_iter": int(n_iter),
    })
    return out["radiance"].reshape(sample_shape), out["variance"].reshape(sample_shape), info


@dataclass(frozen=True)
class _CodeGrid:
    """The code an exposure ``x`` predicts: the usable code whose ``x_lut`` is nearest (``x_lut`` is
    non-decreasing), tabulated on a fine grid of ``ln x`` per channel (a table look-up instead of a
    search per sample). Grid index of ``x``: ``(ln x - ln_lo) * scale``."""
    n_grid: int
    ln_lo: np.ndarray
    grid_scale: np.ndarray
    code_grid: np.ndarray  # (n_grid, C) codes
    ln_lo32: np.ndarray
    scale32: np.ndarray

    @classmethod
    def build(cls, x64: np.ndarray, saturation_code: int, channels: int) -> "_CodeGrid":
        lo_code, hi_code = 1, int(saturation_code) - 1
        n_grid = 4096
        ln_lo = np.log(np.maximum(x64[lo_code], 1e-300))
        ln_hi = np.log(np.maximum(x64[hi_code], 1e-300))
        grid_scale = (n_grid - 1) / np.maximum(ln_hi - ln_lo, 1e-12)
        code_grid = np.empty((n_grid, channels), np.intp)
        for c in range(channels):
            xs_c = np.exp(np.linspace(ln_lo[c], ln_hi[c], n_grid))
            mids = (x64[lo_code:hi_code, c] + x64[lo_code + 1:hi_code + 1, c]) / 2
            code_grid[:, c] = lo_code + np.searchsorted(mids, xs_c)
        return cls(n_grid=n_grid, ln_lo=ln_lo, grid_scale=grid_scale, code_grid=code_grid,
                   ln_lo32=np.asarray(ln_lo, np.float32).reshape(-1),
                   scale32=np.broadcast_to(np.asarray(grid_scale, np.float32), (channels,)).copy())


@dataclass(frozen=True)
class _Codes8:
    """An 8-bit bracket being merged by :func:`merge_ml_codes8`: codes ``(N, P, C)``, exposures, their
    order (shortest first), the clipping code, ``X_i = x(z) / t_i`` tables and the code grid."""
    flat: np.ndarray
    t: np.ndarray
    order: np.ndarray
    saturation_code: int
    channels: int
    x_t: list
    grid: _CodeGrid

    @functools.cached_property
    def hat(self) -> np.ndarray:
        """Hat weights per code and channel, 0 for code 0 and from the clipping code up."""
        codes = np.arange(256)
        usable_lut = (codes > 0) & (codes < int(self.saturation_code))
        return np.repeat((hat_weight(codes / 255.0) * usable_lut)[:, None], self.channels, axis=1).astype(np.float32)


def _hat_pass(c8: _Codes8, a: int, b: int, src: np.ndarray | None = None, hat: np.ndarray | None = None):
    """Hat-weighted pass over samples ``a:b`` (shortest first, clipping guard): sum w X, sum w, per-exposure
    weights and X."""
    src = c8.flat if src is None else src
    hat = c8.hat if hat is None else hat
    c, channels = b - a, c8.channels
    num = np.zeros((c, channels), np.float32)
    den = np.zeros((c, channels), np.float32)
    clipped = np.zeros((c, channels), bool)
    ws, xs = [], []
    for i in c8.order:
        zc = src[i, a:b]
        clipped |= zc >= c8.saturation_code
        w = _lut8(zc, hat)
        w[clipped] = 0
        xi = _lut8(zc, c8.x_t[i])
        ws.append(w)
        xs.append(xi)
        num += w * xi
        den += w
    return num, den, ws, xs


def _residual_bins(c8: _Codes8, sub: np.ndarray, a: int, b: int, hat: np.ndarray):
    """Leave-one-out squared residuals of every usable sample of a pixel with >= 2 usable samples, binned by
    the code the other exposures predict: (count, sum of squares), each ``(256 * C,)``."""
    channels, grid = c8.channels, c8.grid
    num, den, ws, xs = _hat_pass(c8, a, b, sub, hat)
    n_ok = sum((w > 0).astype(np.int8) for w in ws)
    ch_index = np.broadcast_to(np.arange(channels), num.shape)
    cnt = np.zeros(256 * channels)
    tot = np.zeros(256 * channels)
    for k, i in enumerate(c8.order):
        w, xi = ws[k], xs[k]
        rest = den - w
        ok = (w > 0) & (rest > 0) & (n_ok >= 2)
        if not ok.any():
            continue
        ti = np.float32(c8.t[i])
        pred = (num[ok] - w[ok] * xi[ok]) / rest[ok] * ti  # t_i E_-i of the usable samples, 1-D
        r = xi[ok] * ti - pred
        ch = ch_index[ok]
        with np.errstate(divide="ignore"):
            kg = (np.log(pred) - grid.ln_lo32[ch]) * grid.scale32[ch]
        kg = np.clip(np.nan_to_num(kg, nan=0.0, neginf=0.0), 0, grid.n_grid - 1).astype(np.intp)
        key = grid.code_grid[kg, ch] * channels + ch
        cnt += np.bincount(key, minlength=256 * channels)
        tot += np.bincount(key, (r.astype(np.float64)) ** 2, minlength=256 * channels)
    return cnt, tot


def _code_variance(c8: _Codes8, x64: np.ndarray, *, total: int, chunk: int, n_threads: int) -> np.ndarray:
    """Step 3 of :func:`merge_ml_codes8`: the variance ``V`` (256, C) of a linearised code, measured on the
    bracket (a regular subsample of at most :data:`_V_MAX_PIXELS` pixels), smoothed over 9 codes, never
    below the quantisation."""
    channels = c8.channels
    codes = np.arange(256)
    step = max(1, -(-total // _V_MAX_PIXELS))
    sub = np.ascontiguousarray(c8.flat[:, ::step]) if step > 1 else c8.flat
    bounds = [(a, min(a + chunk, sub.shape[1])) for a in range(0, sub.shape[1], chunk)]
    hat = c8.hat

    def pass1(ab):
        return _residual_bins(c8, sub, ab[0], ab[1], hat)

    if n_threads == 1 or len(bounds) == 1:
        stats = [pass1(ab) for ab in bounds]
    else:
        with ThreadPoolExecutor(max_workers=n_threads) as pool:
            stats = list(pool.map(pass1, bounds))
    count = sum(st[0] for st in stats).reshape(256, channels)
    sq = sum(st[1] for st in stats).reshape(256, channels)
    kernel = np.ones(9)
    V = np.empty((256, channels))
    for c in range(channels):
        cnt_c = np.convolve(count[:, c], kernel, mode="same")
        V_c = np.convolve(sq[:, c], kernel, mode="same") / np.maximum(cnt_c, 1)
        # codes without measurements (per channel): the nearest measured code's variance
        seen = np.flatnonzero(cnt_c >= 2)
        if seen.size == 0:
            raise InputError("images: no pixel is usable (codes 1..254) in two exposures; cannot measure the noise")
        V[:, c] = V_c[seen[np.abs(codes[:, None] - seen[None, :]).argmin(axis=1)]]
    dx = np.gradient(x64, axis=0)
    # never below the quantisation of a code, nor (a flat stretch of g) below a 1e-6 relative error
    return np.maximum(V, np.maximum(dx * dx / 12.0, (1e-6 * x64) ** 2))


def _weight_tables(V: np.ndarray, t: np.ndarray, grid: _CodeGrid) -> tuple[list[np.ndarray], float, type]:
    """Weight tables ``t_i^2 / V`` over the code grid, scaled so the largest is 1: float32 when their range
    allows it (half the memory traffic), float64 otherwise; the variance takes the scale back."""
    channels = V.shape[1]
    t2 = t**2
    inv_v_grid = (1.0 / V[grid.code_grid, np.arange(channels)]).ravel()  # 1 / V at the code each grid exposure predicts
    w_scale = float(t2.max() * inv_v_grid.max())
    w_tables = [t2[i] * inv_v_grid / w_scale for i in range(len(t))]
    w_dtype = np.float32 if min(float(wt.min()) for wt in w_tables) > 1e-30 else np.float64
    return [wt.astype(w_dtype) for wt in w_tables], w_scale, w_dtype


def _codes8_chunk(c8: _Codes8, a: int, b: int, out: dict[str, np.ndarray], *, n_iter, w_tables, w_scale, w_dtype,
                  fill, last) -> None:
    """Step 4 of :func:`merge_ml_codes8` on samples ``a:b``: the inverse-variance fixed point from the hat
    estimate, the fills of samples without a usable code; written into ``out``."""
    grid, channels, flat = c8.grid, c8.channels, c8.flat
    cidx = np.arange(channels)
    ln_t_grid = [np.float32(np.log(c8.t[i]) * grid.grid_scale) for i in range(len(c8.t))]
    num, den, ws, xs = _hat_pass(c8, a, b)
    usable = [w > 0 for w in ws]
    none = den <= 0
    e = (num / np.where(none, 1, den)).astype(w_dtype)
    wsum = np.zeros(e.shape, w_dtype)
    for _ in range(max(1, int(n_iter))):  # weights at the current estimate, never at the sample's own code
        acc = np.zeros(e.shape, w_dtype)
        wsum = np.zeros(e.shape, w_dtype)
        with np.errstate(divide="ignore"):
            k0 = ((np.log(e) - grid.ln_lo32) * grid.scale32).astype(np.float32)
        k0 = np.nan_to_num(k0, nan=-1e30, neginf=-1e30, posinf=1e30)
        for k, i in enumerate(c8.order):
            idx = np.clip(k0 + ln_t_grid[i], 0, grid.n_grid - 1).astype(np.intp) * channels + cidx
            w = w_tables[i][idx]
            w *= usable[k]
            acc += w * xs[k]
            wsum += w
        e = np.where(wsum > 0, acc / np.where(wsum > 0, wsum, 1), e)
    var = 1.0 / (np.where(none | (wsum <= 0), 1, wsum).astype(np.float64) * w_scale)
    sat = none & (flat[c8.order[0], a:b] >= 128)
    dark = none & ~sat
    e = np.where(sat, fill[None, :], e)
    var = np.where(sat, fill[None, :].astype(np.float64) ** 2, var)
    if dark.any():
        xd = _lut8(np.maximum(flat[last, a:b], 1), c8.x_t[last])
        e = np.where(dark, xd, e)
        var = np.where(dark, xd.astype(np.float64) ** 2, var)
    out["radiance"][a:b] = e
    out["variance"][a:b] = np.clip(var, np.finfo(np.float32).tiny, np.finfo(np.float32).max)
    out["sat"][a:b] = sat
    out["dark"][a:b] = dark


# -- light fields ------------------------------------------------------------------------------

def _exposure_of(lf: LightField, i: int, given, what: str) -> float:
    if given is not None:
        return float(given[i])
    value = getattr(lf, what)
    if value is None:
        name = lf.source or f"input {i + 1}"
        raise InputError(f"{name}: no {what.replace('_s', ' time (s)')} in its metadata; give --exposures-s")
    return float(value)


def check_exposure_order(
    stack,
    exposures_s: Sequence[float],
    *,
    names: Sequence[str] | None = None,
    saturation: Sequence[float | None] | None = None,
    max_samples: int = 1_000_000,
) -> None:
    """Refuse exposure times that contradict the images (a longer exposure must not be darker).

    For every two exposures adjacent in the given times (equal times are skipped), the samples
    that are neither 0 nor clipped (``>= saturation``, default: that image's maximum) in both are
    compared: if the longer exposure is darker in more than half of them and in more than twice as
    many as it is brighter, the times are in the wrong order (typically ``1/t`` given for ``t``,
    or files listed against their times) and :class:`InputError` names the two inputs. Up to
    ``max_samples`` samples per image are compared (a regular subsample).
    """
    arr = _as_stack(stack, "stack")
    n = arr.shape[0]
    t = _per_exposure("exposures_s", exposures_s, n)
    names = list(names) if names is not None else [f"input {i + 1}" for i in range(n)]
    flat = arr.reshape(n, -1)
    step = max(1, flat.shape[1] // max_samples)
    flat = flat[:, ::step].astype(np.float32)
    sat = [None] * n if saturation is None else list(saturation)
    top = np.array([float(flat[i].max()) if sat[i] is None else float(sat[i]) for i in range(n)], np.float32)
    order = np.argsort(t, kind="stable")
    for a, b in zip(order[:-1], order[1:]):
        if t[b] <= t[a]:
            continue
        ok = (flat[a] > 0) & (flat[b] > 0) & (flat[a] < top[a]) & (flat[b] < top[b])
        count = int(ok.sum())
        if count < 16:
            continue
        darker = float(np.mean(flat[b][ok] < flat[a][ok]))
        brighter = float(np.mean(flat[b][ok] > flat[a][ok]))
        if darker > 0.5 and darker > 2 * brighter:
            raise InputError(
                f"exposure times contradict the images: {names[b]} ({t[b]:g} s) is darker than {names[a]} "
                f"({t[a]:g} s) in {darker:.0%} of the pixels usable in both; give the times in seconds, one per "
                "input in the inputs' order (1/t given for t?)"
            )


@renamed_keywords(n_iter="max_iter")
def merge_lightfields(
    lfs: Sequence[LightField],
    *,
    method: str = "ml",
    profile=None,
    exposures_s: Sequence[float] | None = None,
    isos: Sequence[float] | float | None = None,
    response: np.ndarray | str | None = None,
    max_iter: int = 2,
    random_state=None,
    n_threads: int | None = None,
    chunk_size: int = _DEFAULT_CHUNK,
) -> tuple[LightField, dict[str, Any]]:
    """Merge a bracket of light fields (or 1x1 light fields of 2-D images) into one HDR light field.

    All views share the bracket's exposures; every view and pixel is merged on its own.

    How the data are read, per input ``units`` (all inputs must agree):

    * ``"dn"``: raw sensor codes with the black level included (what :mod:`lfproc.camera.sensor`
      produces). ``ml`` uses them directly with ``profile``; ``debevec`` normalises them with the
      profile's black and white levels.
    * ``attrs["codes_bits"] == 8``: non-linear 8-bit camera output stored as ``code / 255``
      (see :func:`lfproc.bracket.read_bracket`): the camera response is recovered (or ``response``
      given); ``debevec`` merges in the log domain, ``ml`` with :func:`merge_ml_codes8` (no
      profile or ISO needed: the noise is measured on the bracket).
    * anything else: linear values clipping at ``saturation_level`` (required). ``ml`` maps them to
      codes with the profile's levels, ``dn = black + value / saturation_level * (white - black)``
      (for decoded raw data that are the raw codes normalised by the ADC range).

    Parameters
    ----------
    lfs : sequence of LightField
        The bracket (at least two, one shape).
    method : {"ml", "debevec"}
    profile : CameraProfile or name, optional
        Required for ``ml`` and for ``dn`` input.
    exposures_s, isos : optional
        Override the inputs' ``exposure_s`` / ``iso`` metadata (one value per input).
    response : see :func:`merge_debevec`.
    max_iter, random_state, n_threads, chunk_size : see :func:`merge_ml` / :func:`recover_response`
        (the keyword ``n_iter`` is deprecated).

    Returns
    -------
    merged : LightField
        ``ml``: radiance in e-/s, with ``variance``; ``debevec``: relative radiance. Negative
        ML estimates (noise in the dark) are set to 0 in ``data`` (their number is reported).
        ``attrs`` records method, exposures, ISOs, sources, saturated-everywhere count and
        fraction, the fill rule and the lfproc version.
    info : dict
        As returned by the estimator, plus ``dynamic_range_stops``, ``negative_clipped``.
    """
    check_choice("method", method, MERGE_METHODS)
    br = _light_field_bracket(lfs, exposures_s, isos, profile)
    run = _merge_bracket_ml if method == "ml" else _merge_bracket_debevec
    return run(br, response=response, n_iter=max_iter, random_state=random_state, n_threads=n_threads,
               chunk_size=chunk_size)


@dataclass
class _LightFieldBracket:
    """A bracket of light fields checked for :func:`merge_lightfields`: the light fields, their names,
    exposures (s), ISOs (None when one is unknown), units, whether they are 8-bit codes, the stacked data
    and the camera profile (or None)."""
    lfs: list
    names: list[str]
    t: np.ndarray
    iso: np.ndarray | None
    unit: str
    codes8: bool
    data: np.ndarray | None
    prof: Any


def _light_field_bracket(lfs, exposures_s, isos, profile) -> _LightFieldBracket:
    """Check a bracket of light fields (shapes, exposures, ISOs, units, exposure order)."""
    lfs = list(lfs)
    if len(lfs) < 2:
        raise InputError(f"a bracket needs at least two exposures, got {len(lfs)} input")
    for i, lf in enumerate(lfs):
        if not isinstance(lf, LightField):
            raise InputError(f"input {i + 1}: expected a LightField, got {type(lf).__name__}")
    names = [lf.source or f"input {i + 1}" for i, lf in enumerate(lfs)]
    shape = lfs[0].shape
    for lf, name in zip(lfs[1:], names[1:]):
        if lf.shape != shape:
            raise ShapeError(f"{name}: shape {lf.shape} differs from {names[0]} {shape}")
    n = len(lfs)
    if exposures_s is not None and len(exposures_s) != n:
        raise InputError(f"exposures_s: expected {n} values (one per input), got {len(exposures_s)}")
    t = np.array([_exposure_of(lf, i, exposures_s, "exposure_s") for i, lf in enumerate(lfs)])
    _per_exposure("exposures_s", t, n)
    if isos is not None:
        iso = _per_exposure("isos", isos, n)
    else:
        iso_raw = [lf.iso for lf in lfs]
        iso = None if any(v is None for v in iso_raw) else np.array(iso_raw, dtype=np.float64)
    units = {lf.units for lf in lfs}
    if len(units) != 1:
        raise InputError(f"inputs mix units {', '.join(sorted(units))}; a bracket needs one kind of data")
    codes8 = [lf.attrs.get("codes_bits") == 8 for lf in lfs]
    if any(codes8) and not all(codes8):
        raise InputError("inputs mix 8-bit non-linear images with linear data")
    codes8 = codes8[0]
    data = np.stack([lf.data for lf in lfs])
    check_exposure_order(data, t, names=names, saturation=[1.0 if codes8 else lf.saturation_level for lf in lfs])
    prof = None
    if profile is not None:
        prof = load_profile(profile)
    return _LightFieldBracket(lfs=lfs, names=names, t=t, iso=iso, unit=units.pop(), codes8=codes8, data=data,
                              prof=prof)


def _ml_codes(br: _LightFieldBracket) -> tuple[np.ndarray, str]:
    """The bracket's data as sensor codes for :func:`merge_ml` (uint16 when they are integers) and how they
    were mapped (``"dn"``, or linear data mapped to the profile's levels)."""
    data, prof, n = br.data, br.prof, len(br.lfs)
    mapping = "dn"
    if prof is None:
        raise InputError(f"method ml needs a camera profile ({option_name('profile=', '--profile')}): gain and "
                         "read noise set its weights")
    if br.iso is None:
        missing = next(nm for lf, nm in zip(br.lfs, br.names) if lf.iso is None)
        raise InputError(f"{missing}: no ISO in its metadata; method ml needs one per exposure "
                         f"(give {option_name('isos=', '--isos')})")
    if br.unit != "dn":
        sat = [lf.saturation_level for lf in br.lfs]
        if any(s is None for s in sat):
            bad = next(nm for s, nm in zip(sat, br.names) if s is None)
            raise InputError(f"{bad}: linear {br.unit} data without a saturation level cannot be mapped to sensor "
                             "codes for method ml")
        span = prof.white_level_dn - prof.black_level_dn
        scale = np.array(sat, dtype=np.float32).reshape((n,) + (1,) * (data.ndim - 1))
        data = prof.black_level_dn + data / scale * span
        mapping = "relative-to-profile-levels"
    if np.all(data <= 65535) and np.array_equal(data, np.round(data)):
        return data.astype(np.uint16), mapping
    return data, mapping


def _merge_bracket_ml(br: _LightFieldBracket, *, response, n_iter, random_state, n_threads, chunk_size):
    """Method ``ml`` of :func:`merge_lightfields`: 8-bit codes, the inputs' own variances, or sensor codes."""
    t, iso = br.t, br.iso
    if br.codes8:
        # non-linear 8-bit camera images: recovered response, noise measured on the bracket
        stack = np.clip(np.round(br.data * 255), 0, 255).astype(np.uint8)
        br.data = None
        radiance, variance, info = merge_ml_codes8(stack, exposures_s=t, response=response, max_iter=n_iter,
                                                   random_state=random_state, n_threads=n_threads,
                                                   chunk_size=chunk_size)
        return _finish(br, "ml", "codes8", radiance, variance, info, "relative", n_iter, per_second_iso=None)
    if br.unit != "dn" and all(lf.variance is not None for lf in br.lfs):
        # decoded captures: their own noise-model variances give the weights
        variances = np.stack([lf.variance for lf in br.lfs])
        radiance, variance, info = merge_with_variances(br.data, variances, exposures_s=t, n_threads=n_threads,
                                                        chunk_size=chunk_size)
        same_iso = None if iso is None or len(set(iso.tolist())) != 1 else float(iso[0])
        return _finish(br, "ml", "input-variances", radiance, variance, info, br.unit, n_iter,
                       per_second_iso=same_iso)
    dn, mapping = _ml_codes(br)
    br.data = None
    radiance, variance, info = merge_ml(dn, exposures_s=t, isos=iso, profile=br.prof, max_iter=n_iter,
                                        n_threads=n_threads, chunk_size=chunk_size)
    return _finish(br, "ml", mapping, radiance, variance, info, "e-/s", n_iter, per_second_iso=None)


def _merge_bracket_debevec(br: _LightFieldBracket, *, response, n_iter, random_state, n_threads, chunk_size):
    """Method ``debevec`` of :func:`merge_lightfields`: 8-bit codes, raw codes or linear data."""
    data, prof, iso = br.data, br.prof, br.iso
    if br.codes8:
        stack = np.clip(np.round(data * 255), 0, 255).astype(np.uint8)
        kwargs = {}
    elif br.unit == "dn":
        if prof is None:
            raise InputError(f"raw (dn) input needs a camera profile ({option_name('profile=', '--profile')}) "
                             "for its black and white levels")
        stack, kwargs = data, {"white_level": prof.white_level_dn, "black_level": prof.black_level_dn}
    else:
        sat = {lf.saturation_level for lf in br.lfs}
        if None in sat or len(sat) != 1:
            raise InputError("method debevec on linear data needs one saturation level shared by all inputs")
        stack, kwargs = data, {"white_level": sat.pop()}
    # ISO enters the exposure as a gain: relative exposure t * ISO / 100
    exp_rel = br.t * (iso / 100.0 if iso is not None else 1.0)
    radiance, info = merge_debevec(stack, exposures_s=exp_rel, response=response, random_state=random_state,
                                   n_threads=n_threads, chunk_size=chunk_size, **kwargs)
    return _finish(br, "debevec", "codes8" if br.codes8 else br.unit, radiance, None, info, "relative", n_iter,
                   per_second_iso=100.0 if iso is not None else None)


def _finish(br: _LightFieldBracket, method, mapping, radiance, variance, info, out_units, n_iter, *,
            per_second_iso=None):
    """The merged light field. Relative (not e-/s) output is a radiance per second: it carries
    ``exposure_s = 1`` (and the ISO it refers to, when known), so later stages (``evaluate
    --align exposure``) can compare it with a capture of another exposure."""
    lfs, names, t, iso, prof = br.lfs, br.names, br.t, br.iso, br.prof
    negative = int((radiance < 0).sum())
    data_out = np.maximum(radiance, 0)
    attrs = {
        "merge_method": method,
        "exposures_s": t.tolist(),
        "isos": None if iso is None else iso.tolist(),
        "sources": names,
        "profile": None if prof is None else prof.name,
        "input_mapping": mapping,
        "saturated_everywhere_count": info["saturated_everywhere_count"],
        "saturated_everywhere_fraction": info["saturated_everywhere_fraction"],
        "dark_everywhere_count": info["dark_everywhere_count"],
        "fill": info["fill"],
        "negative_clipped": negative,
        "lfproc_version": __version__,
    }
    if method == "ml":
        attrs["n_iter"] = int(n_iter)
    if info.get("response") is not None:
        attrs["response_g"] = np.asarray(info["response"]).round(6).tolist()
    per_second = out_units == "relative"
    attrs["value_per"] = "second of exposure" if per_second else out_units
    merged = LightField(data=freeze(data_out), variance=None if variance is None else freeze(variance), units=out_units, colour_space=lfs[0].colour_space,
                        exposure_s=1.0 if per_second else None, iso=per_second_iso if per_second else None,
                        source=f"merge:{method}", attrs=attrs)
    info["dynamic_range_stops"] = merged.dynamic_range_stops()
    info["negative_clipped"] = negative
    return merged, info
