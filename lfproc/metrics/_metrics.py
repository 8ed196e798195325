"""HDR image and light-field quality metrics: PU21, PU2, PU-PSNR/SSIM, log-PSNR, relative error.

All metrics compare a *result* (test) with a *reference* of the same shape. They follow the
conventions of the reference implementation of PU21, ``pu21_metric.m`` of ``gfxdisp/pu21``
(Mantiuk and Azimi, PCS 2021):

* **Luminance.** Colour values are reduced to luminance with
  ``Y = 0.212656 R + 0.715158 G + 0.072186 B`` (:data:`PU21_LUMA`, the weights of
  ``pu21_metric.m``; :func:`lfproc.lightfield.luminance` uses the rounded Rec. 709 weights).
  One-channel data are taken as luminance.
* **Absolute scale.** PU encodings need absolute luminance in cd/m^2. Both images are
  multiplied by the *same* factor ``peak_luminance / max(reference)`` (the README recipe
  ``I = I / max(I) * L_peak`` with the maximum taken over every sample, all colour channels
  and, for light fields, all views of the *reference*). The reference peak therefore maps to
  the display peak, and the result keeps its scale relative to the reference: a result that
  is 2x too bright stays 2x too bright. ``peak_luminance=None`` skips the scaling for data
  that are already absolute cd/m^2.
* **PU21-PSNR** uses the peak 256 (``psnr(T, R, 256)`` in ``pu21_metric.m``): PU21 maps
  100 cd/m^2 to about 256. **PU21-SSIM** is :func:`skimage.metrics.structural_similarity`
  with ``data_range=256, gaussian_weights=True, sigma=1.5, use_sample_covariance=False``
  on PU21-encoded luminance (MATLAB's ``ssim(T, R, 'DynamicRange', 256)`` up to the border
  handling: scikit-image drops a 5-pixel border, MATLAB pads by replication).
* **PU2-PSNR** (PU2 = the HDR-VDP-2 CSF version of the perceptually uniform encoding of
  Aydin, Mantiuk and Seidel 2008, as in HDR Toolbox's ``pu2_encode.m``) uses the peak
  ``pu2_encode(max(scaled reference))``, which is ``pu2_encode(peak_luminance)`` after
  scaling (about 419.6 for 1000 cd/m^2). This is HDR Toolbox's ``PSNR(ref, dist, 'pu')``
  with its default ``max_value`` whenever the result does not exceed the reference peak.
  The convention of the paper's PU2-PSNR tables is not published; compare across papers
  with care.
* **log-PSNR** is PSNR in the log10 domain of the scaled luminance:
  ``l = log10(clip(Y, 0.005, 1e4))`` (the PU21 luminance range), peak
  ``log10(max(scaled reference) / 0.005)`` (5.30 for 1000 cd/m^2, the decades between the
  display peak and PU21's black level), ``log_psnr = 20 log10(peak / RMSE(l_result, l_ref))``.
* **Mean relative error** is computed on the linear values themselves (every colour sample,
  no luminance, no PU): ``mean(|result - reference| / (reference + eps))`` with
  ``eps = epsilon_relative * max(reference)`` and ``epsilon_relative = 1e-3`` by default
  (10 stops below the reference peak), so that black or nearly black reference samples do not
  dominate. It is independent of ``peak_luminance``.
* Identical images give PSNR ``inf`` and SSIM 1. Light fields are evaluated view by view;
  view-averaged figures are the means of the per-view figures (an ``inf`` view makes the
  average PSNR ``inf``). The array functions (:func:`pu21_psnr`...) instead treat their whole
  input as one signal (one MSE over every sample; SSIM averaged over the 2-D images).

PU21 maps the reference peak to the display peak, so its dark decades barely count and a few
emitters can decide the score. :func:`hdr_figures` gives what a user sees instead: the median
error in stops per decade of the reference luminance, the share of samples returned as 0 (or
:data:`ZERO_STOPS` under),
the energy kept by the brightest 1 %, a detail ratio (Laplacian energy of the PU21 error over
the reference's) and the share of the PU21 error held by the brightest 0.1 %;
:func:`evaluate` reports them too, and takes a mask (or ``exclude_above``) that restricts
every figure.

PU encodings are computed in float64 over whole arrays at once (every view of a light field
in one call); SSIM runs per 2-D view.

Perceptual metrics that are not provided
----------------------------------------
**HDR-VDP-2 / HDR-VDP-3** (Mantiuk et al.) are MATLAB only (hdrvdp.sourceforge.net, the
HDR-VDP-3 GitHub repository). There is no Python release on PyPI (``hdrvdp``, ``pyhdrvdp``,
``hdr-vdp`` do not exist); the unofficial ports are not packaged. Scores from the paper's
HDR-VDP-2 Q cannot be reproduced here without MATLAB or Octave.

**ColorVideoVDP** (``cvvdp`` 0.5.7 on PyPI, the SIGGRAPH 2024 metric) is not used and not a
dependency, for these reasons (checked on this project's machines):

* It requires ``torch`` and ``torchvision``, and ``import pycvvdp`` imports
  ``torchvision.transforms`` at module level (``cvvdp_metric.py``, ``cvvdp_ml_metric.py``),
  so even its PSNR/SSIM metrics need torchvision. The package index here offers a CPU torch
  only as ``torch==2.13.0`` (``2.13.0+cpu``) and no CPU build of torchvision. Tried in a
  throw-away virtual environment (not lfproc's): ``torch==2.13.0`` (CPU, 754 MB) plus
  ``torchvision==0.28.0`` (its matching version, a CUDA build) and ``cvvdp`` 0.5.7 install,
  but ``import torchvision`` (hence ``import pycvvdp``) fails with
  ``RuntimeError: operator torchvision::nms does not exist``: the compiled operators of the
  CUDA torchvision link against ``libtorch_cuda.so``/``libc10_cuda.so``, which the CPU torch
  does not ship. So cvvdp cannot run on the CPU here.
* Its other requirements include ``ffmpeg-python`` plus an ``ffmpeg`` binary (for video
  files), ``huggingface_hub`` (the ``cvvdp-ml-*`` variants download checkpoints, so they do
  not run offline), ``einops`` and ``PyEXR``.
* Its JOD scores are not comparable with the paper's HDR-VDP-2 Q, and its own PU-PSNR
  differs from ``pu21_metric.m``: ``pu_psnr_y`` (0.5.x) uses the peak PU21(100) = 256.4,
  older ``pycvvdp/pupsnr.py`` used PU21(10000) = 595.4.

Use the PU21/PU2 figures of this module; run cvvdp separately (its own environment, torch
with torchvision) on views exported with ``lfproc convert`` if a JOD score is needed.

References
----------
.. [1] R. K. Mantiuk and M. Azimi, "PU21: A novel perceptually uniform encoding for adapting
   existing quality metrics for HDR", Picture Coding Symposium 2021,
   doi:10.1109/PCS50896.2021.9477471. Code: https://github.com/gfxdisp/pu21
.. [2] T. O. Aydin, R. Mantiuk and H.-P. Seidel, "Extending quality metrics to full luminance
   range images", Proc. SPIE 6806, 2008, doi:10.1117/12.765095.
.. [3] R. Mantiuk, K. J. Kim, A. G. Rempel and W. Heidrich, "HDR-VDP-2", ACM TOG 30(4), 2011,
   doi:10.1145/2010324.1964935 (the CSF ``csf_sa`` used by PU2).
"""

from __future__ import annotations

import functools
import math
from typing import Any, Literal

import numpy as np

from .._shared.validation import check_choice, check_positive
from ..errors import InputError, ShapeError, option_name
from ..lightfield import LightField

__all__ = [
    "PU21_PARAMETERS",
    "PU21_VARIANTS",
    "PU21_L_MIN",
    "PU21_L_MAX",
    "PU21_PSNR_PEAK",
    "PU21_LUMA",
    "metric_luminance",
    "pu21_encode",
    "pu21_decode",
    "pu2_encode",
    "psnr",
    "pu21_psnr",
    "pu21_ssim",
    "pu2_psnr",
    "log_psnr",
    "mean_relative_error",
    "log_luminance_error",
    "align_result",
    "ALIGN_MODES",
    "hdr_figures",
    "EMITTER_SHARE_DOMINATES",
    "ZERO_STOPS",
    "evaluation_mask",
    "error_stops",
    "evaluate",
]

Pu21Variant = Literal["banding_glare", "banding", "peaks", "peaks_glare"]

#: Parameters p1..p7 of the PU21 variants (``pu21_encoder.m``, updated 06/02/2020).
PU21_PARAMETERS: dict[str, tuple[float, ...]] = {
    "banding_glare": (0.353487901, 0.3734658629, 8.277049286e-05, 0.9062562627, 0.09150303166,
                      0.9099517204, 596.3148142),
    "banding": (1.070275272, 0.4088273932, 0.153224308, 0.2520326168, 1.063512885, 1.14115047, 521.4527484),
    "peaks": (1.043882782, 0.6459495343, 0.3194584211, 0.374025247, 1.114783422, 1.095360363, 384.9217577),
    "peaks_glare": (816.885024, 1479.463946, 0.001253215609, 0.9329636822, 0.06746643971, 1.573435413,
                    419.6006374),
}
PU21_VARIANTS = tuple(PU21_PARAMETERS)
#: Luminance range of PU21 in cd/m^2; inputs are clamped to it.
PU21_L_MIN = 0.005
PU21_L_MAX = 10000.0
#: PSNR peak of PU21 values (``pu21_metric.m``).
PU21_PSNR_PEAK = 256.0
#: Luminance weights of linear R, G, B used by ``pu21_metric.m``.
PU21_LUMA = np.array([0.212656, 0.715158, 0.072186])

# PU2 (HDR Toolbox pu2_encode.m): HDR-VDP-2 joint rod-cone sensitivity, LUT and normalisation.
_PU2_CSF_SA = (30.162, 4.0627, 1.6596, 0.2712)
_PU2_LOG_RANGE = (-5.0, 10.0)
_PU2_LUT_SIZE = 4096
_PU2_LOW, _PU2_HIGH = 31.9270, 149.9244

_SSIM_OPTIONS = dict(gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=PU21_PSNR_PEAK)
_SSIM_MIN_SIZE = 11  # window of gaussian_weights=True, sigma=1.5 (truncate 3.5): 2 * 5 + 1


# -- encodings -----------------------------------------------------------------------------

def _as_numeric(values: Any, name: str) -> np.ndarray:
    """``values`` as a finite numeric array (not converted: callers convert what they need)."""
    arr = np.asarray(values)
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InputError(f"{name}: expected a numeric array, got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.floating) and not np.isfinite(arr).all():
        raise InputError(f"{name}: contains NaN or Inf values; expected finite values")
    return arr


def _as_float64(values: Any, name: str) -> np.ndarray:
    return _as_numeric(values, name).astype(np.float64, copy=False)


def _pu21_params(variant: str) -> tuple[float, ...]:
    return PU21_PARAMETERS[check_choice("variant", variant, PU21_VARIANTS)]


def pu21_encode(luminance_cd_m2: Any, *, variant: Pu21Variant = "banding_glare") -> np.ndarray:
    """PU21 perceptually uniform encoding of absolute luminance.

    ``V = p7 * (((p1 + p2 Y^p4) / (1 + p3 Y^p4))^p5 - p6)`` with ``Y`` clamped to
    [0.005, 10000] cd/m^2 (the reference warns outside that range; this function clamps
    silently: dark pixels below 0.005 cd/m^2 are common and all encode to the same value).

    Parameters
    ----------
    luminance_cd_m2 : array_like, any shape
        Absolute luminance in cd/m^2 (not relative values: scale first, see the module notes).
    variant : {"banding_glare", "banding", "peaks", "peaks_glare"}
        Parameter set; the PU21 authors recommend ``"banding_glare"``.

    Returns
    -------
    ndarray of the same shape, float64
        PU21 values: about 0 at 0.005, 256.4 at 100 and 595.4 at 10000 cd/m^2
        (``banding_glare``).

    Raises
    ------
    InputError
        Unknown variant, non-numeric or non-finite input.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.metrics import pu21_decode, pu21_encode
    >>> np.round(pu21_encode([0.005, 1.0, 100.0, 10000.0]), 1).tolist()
    [0.0, 36.5, 256.4, 595.4]
    >>> np.round(pu21_encode([1e-4, 1e5]), 1).tolist()  # clamped to [0.005, 10000] cd/m^2
    [0.0, 595.4]
    >>> np.round(pu21_decode(pu21_encode([0.1, 42.0, 5000.0])), 6).tolist()  # the inverse
    [0.1, 42.0, 5000.0]
    """
    p1, p2, p3, p4, p5, p6, p7 = _pu21_params(variant)
    arr = _as_float64(luminance_cd_m2, "luminance_cd_m2")
    y = np.clip(arr.reshape(-1), PU21_L_MIN, PU21_L_MAX)  # a new 1-d array, updated in place below
    np.power(y, p4, out=y)
    num = p2 * y
    num += p1
    y *= p3
    y += 1.0
    num /= y
    np.power(num, p5, out=num)
    num -= p6
    num *= p7
    return num.reshape(arr.shape)


@functools.lru_cache(maxsize=None)
def _pu21_encoded_range(variant: str) -> tuple[float, float]:
    lo, hi = pu21_encode(np.array([PU21_L_MIN, PU21_L_MAX]), variant=variant)  # type: ignore[arg-type]
    return float(lo), float(hi)


def pu21_decode(pu_values: Any, *, variant: Pu21Variant = "banding_glare") -> np.ndarray:
    """Inverse of :func:`pu21_encode`: PU21 values to absolute luminance in cd/m^2.

    ``Vp = max(V/p7 + p6, 0)^(1/p5)``, ``Y = (max(Vp - p1, 0) / (p2 - p3 Vp))^(1/p4)``.
    ``V`` is first clipped to ``[pu21_encode(0.005), pu21_encode(10000)]``, the range of
    the encoding, so the result lies in [0.005, 10000] cd/m^2 and
    ``pu21_decode(pu21_encode(Y)) == clip(Y, 0.005, 10000)`` to rounding.

    Parameters
    ----------
    pu_values : array_like, any shape
    variant : {"banding_glare", "banding", "peaks", "peaks_glare"}

    Returns
    -------
    ndarray of the same shape, float64, luminance in cd/m^2.
    """
    p1, p2, p3, p4, p5, p6, p7 = _pu21_params(variant)
    lo, hi = _pu21_encoded_range(variant)
    arr = _as_float64(pu_values, "pu_values")
    v = np.clip(arr.reshape(-1), lo, hi)
    v /= p7
    v += p6
    np.maximum(v, 0.0, out=v)
    np.power(v, 1.0 / p5, out=v)
    den = p2 - p3 * v
    v -= p1
    np.maximum(v, 0.0, out=v)
    v /= den
    np.power(v, 1.0 / p4, out=v)
    np.clip(v, PU21_L_MIN, PU21_L_MAX, out=v)
    return v.reshape(arr.shape)


@functools.lru_cache(maxsize=1)
def _pu2_lut() -> tuple[np.ndarray, np.ndarray]:
    from scipy.integrate import cumulative_trapezoid

    l_lut = np.linspace(*_PU2_LOG_RANGE, _PU2_LUT_SIZE)
    s1, s2, s3, s4 = _PU2_CSF_SA
    sensitivity = s1 * ((s2 / 10.0**l_lut) ** s3 + 1.0) ** (-s4)
    # dL/threshold integrated in the log10 domain: (S / L) * L * ln 10 = S ln 10
    jnd = cumulative_trapezoid(sensitivity * math.log(10.0), l_lut, initial=0.0)
    p_lut = 255.0 * (jnd - _PU2_LOW) / (_PU2_HIGH - _PU2_LOW)
    l_lut.setflags(write=False)
    p_lut.setflags(write=False)
    return l_lut, p_lut


def pu2_encode(luminance_cd_m2: Any) -> np.ndarray:
    """PU2 encoding (the HDR-VDP-2 CSF version of Aydin et al. 2008, HDR Toolbox ``pu2_encode.m``).

    The sensitivity ``S(L) = 30.162 ((4.0627 / L)^1.6596 + 1)^-0.2712`` is integrated
    (``cumtrapz``) over ``log10 L`` in [-5, 10] on 4096 points; the JND count is
    interpolated linearly at ``log10(clip(L, 1e-5, 1e10))`` and normalised so that
    0.8 cd/m^2 maps to 0 and 80 cd/m^2 to 255. Values can be negative or above 255.

    Parameters
    ----------
    luminance_cd_m2 : array_like, any shape
        Absolute luminance in cd/m^2.

    Returns
    -------
    ndarray of the same shape, float64 (100 -> 269.5, 1000 -> 419.6, 10000 -> 569.6).
    """
    lo, hi = 10.0 ** _PU2_LOG_RANGE[0], 10.0 ** _PU2_LOG_RANGE[1]
    arr = _as_float64(luminance_cd_m2, "luminance_cd_m2")
    y = np.clip(arr.reshape(-1), lo, hi)
    np.log10(y, out=y)
    l_lut, p_lut = _pu2_lut()
    return np.interp(y, l_lut, p_lut).reshape(arr.shape)


# -- preparation: luminance, scale -------------------------------------------------------------

def metric_luminance(values: np.ndarray, *, channel_axis: int | None = -1) -> np.ndarray:
    """Luminance with the weights of ``pu21_metric.m`` (:data:`PU21_LUMA`), float64.

    Parameters
    ----------
    values : ndarray
        Linear values; with ``channel_axis`` set, that axis holds 1 or 3 channels (RGB).
    channel_axis : int or None, default -1
        ``None``: ``values`` already are luminance and are returned as float64.

    Returns
    -------
    ndarray without the channel axis, float64.

    Raises
    ------
    ShapeError
        The channel axis holds neither 1 nor 3 channels.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.metrics import metric_luminance
    >>> np.round(metric_luminance(np.array([[1.0, 1.0, 1.0], [1.0, 0.0, 0.0]])), 6).tolist()  # white, red
    [1.0, 0.212656]
    """
    arr = np.asarray(values)
    if channel_axis is None:
        return arr.astype(np.float64, copy=False)
    arr = np.moveaxis(arr, channel_axis, -1)
    if arr.shape[-1] == 1:
        return arr[..., 0].astype(np.float64)
    if arr.shape[-1] != 3:
        raise ShapeError(f"luminance: expected 1 or 3 colour channels on axis {channel_axis}, got {arr.shape[-1]}")
    # channel by channel: float64 temporaries of the luminance size only, not of the colour array
    y = arr[..., 0].astype(np.float64)
    y *= PU21_LUMA[0]
    for i in (1, 2):
        y += arr[..., i].astype(np.float64) * PU21_LUMA[i]
    return y


def _check_pair(result: Any, reference: Any) -> tuple[np.ndarray, np.ndarray]:
    res = _as_numeric(result, "result")
    ref = _as_numeric(reference, "reference")
    if res.shape != ref.shape:
        raise ShapeError(f"result and reference: expected the same shape, got {res.shape} and {ref.shape}")
    if ref.size == 0:
        raise ShapeError("reference: expected at least one sample, got an empty array")
    return res, ref


def _scale_factor(ref: np.ndarray, peak_luminance: float | None) -> float:
    """The factor applied to both images: ``peak_luminance / max(reference)`` (1 when None)."""
    if peak_luminance is None:
        return 1.0
    peak_luminance = check_positive("peak_luminance", peak_luminance)
    top = float(ref.max())
    if not top > 0:
        raise InputError(
            f"reference: maximum value is {top:.4g}; expected a positive peak to scale to {peak_luminance:g} cd/m^2 "
            "(an all-black reference cannot be evaluated)"
        )
    return peak_luminance / top


def _scaled_luminance(result: Any, reference: Any, peak_luminance: float | None,
                      channel_axis: int | None) -> tuple[np.ndarray, np.ndarray, float]:
    """Scaled luminance of both (cd/m^2, float64) and the display peak ``max(scaled reference)``."""
    res, ref = _check_pair(result, reference)
    if peak_luminance is None and not ref.max() > 0:
        raise InputError(f"reference: maximum value is {float(ref.max()):.4g}; expected positive absolute luminance")
    factor = _scale_factor(ref, peak_luminance)
    display_peak = float(ref.max()) * factor
    y_res = metric_luminance(res, channel_axis=channel_axis)
    y_ref = metric_luminance(ref, channel_axis=channel_axis)
    if factor != 1.0:  # new arrays: never scale the caller's arrays in place
        y_res = y_res * factor
        y_ref = y_ref * factor
    return y_res, y_ref, display_peak


# -- PSNR and SSIM kernels -----------------------------------------------------------------------

def _psnr_from_mse(mse: np.ndarray | float, peak: float) -> np.ndarray:
    """PSNR of each MSE: ``inf`` for 0, ``nan`` for ``nan`` (a view a mask leaves empty)."""
    mse = np.asarray(mse, dtype=np.float64)
    with np.errstate(divide="ignore"):
        out = np.where(mse > 0, 10.0 * np.log10(peak * peak / np.where(mse > 0, mse, 1.0)), np.inf)
    return np.where(np.isnan(mse), np.nan, out)


def psnr(result: Any, reference: Any, *, data_range: float) -> float:
    """PSNR in dB: ``10 log10(data_range^2 / MSE)`` over every sample; ``inf`` when identical.

    Parameters
    ----------
    result, reference : array_like of the same shape
    data_range : float
        The peak value (required: no guess from the dtype).

    Returns
    -------
    float
        dB.

    Raises
    ------
    ShapeError
        Shapes that differ.
    InputError
        A non-positive ``data_range`` or non-finite values.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.metrics import psnr
    >>> psnr(np.zeros(4), np.full(4, 0.1), data_range=1.0)  # RMSE 0.1 of the range
    20.0
    >>> psnr(np.ones(4), np.ones(4), data_range=1.0)
    inf
    """
    data_range = check_positive("data_range", data_range)
    res, ref = _check_pair(result, reference)
    return float(_psnr_from_mse(np.mean(np.square(res.astype(np.float64) - ref)), data_range))


def _ssim_images(p_res: np.ndarray, p_ref: np.ndarray) -> np.ndarray:
    """SSIM of each 2-D image over the last two axes; returns an array of the leading shape."""
    from skimage.metrics import structural_similarity

    h, w = p_ref.shape[-2:]
    if min(h, w) < _SSIM_MIN_SIZE:
        raise ShapeError(
            f"SSIM: images must be at least {_SSIM_MIN_SIZE}x{_SSIM_MIN_SIZE} pixels (Gaussian window, sigma 1.5), "
            f"got {h}x{w}"
        )
    lead = p_ref.shape[:-2]
    flat_res = p_res.reshape(-1, h, w)
    flat_ref = p_ref.reshape(-1, h, w)
    out = np.empty(flat_ref.shape[0])
    for i in range(flat_ref.shape[0]):
        if np.array_equal(flat_res[i], flat_ref[i]):
            out[i] = 1.0  # identical images: SSIM is exactly 1 by definition
        else:
            out[i] = structural_similarity(flat_res[i], flat_ref[i], **_SSIM_OPTIONS)
    return out.reshape(lead)


# -- public array metrics ----------------------------------------------------------------------

_SHARED_PARAMS_DOC = """
    Parameters
    ----------
    result, reference : array_like of the same shape
        Linear values: luminance of shape (..., H, W), or colour of shape (..., H, W, C) with
        ``channel_axis=-1``.
    peak_luminance : float or None, default 1000
        Display peak in cd/m^2; both arrays are multiplied by ``peak_luminance / max(reference)``.
        ``None``: the values already are absolute cd/m^2.
    channel_axis : int or None, default None
        Axis holding 1 or 3 channels (converted with :data:`PU21_LUMA`); ``None`` for luminance.
"""


def pu21_psnr(result: Any, reference: Any, *, peak_luminance: float | None = 1000.0,
              channel_axis: int | None = None, variant: Pu21Variant = "banding_glare") -> float:
    """PU21-PSNR in dB on luminance (peak 256, ``pu21_metric.m``); ``inf`` for identical images.

    ``20 log10(256 / RMSE(P_result, P_reference))`` with ``P`` the PU21 encoding
    (:func:`pu21_encode`) of the scaled luminance (Mantiuk and Azimi, PCS 2021).

    Returns
    -------
    float
        dB; ``inf`` when the encoded images are identical.

    Raises
    ------
    ShapeError, InputError
        Shapes that differ, non-finite values, a reference without a positive maximum.

    Examples
    --------
    >>> import math
    >>> import numpy as np
    >>> from lfproc.metrics import pu21_encode, pu21_psnr
    >>> ref = np.random.default_rng(0).uniform(0.01, 1.0, (16, 16, 3))
    >>> pu21_psnr(ref, ref, channel_axis=-1)
    inf
    >>> a, b = np.full((4, 4), 100.0), np.full((4, 4), 1.0)  # cd/m^2: PU21 256.4 and 36.5
    >>> round(pu21_psnr(a, b, peak_luminance=None), 3)
    1.323
    >>> round(20 * math.log10(256 / float(pu21_encode(100.0) - pu21_encode(1.0))), 3)
    1.323
    """
    y_res, y_ref, _ = _scaled_luminance(result, reference, peak_luminance, channel_axis)
    mse = np.mean(np.square(pu21_encode(y_res, variant=variant) - pu21_encode(y_ref, variant=variant)))
    return float(_psnr_from_mse(mse, PU21_PSNR_PEAK))


def pu21_ssim(result: Any, reference: Any, *, peak_luminance: float | None = 1000.0,
              channel_axis: int | None = None, variant: Pu21Variant = "banding_glare") -> float:
    """PU21-SSIM on luminance: scikit-image SSIM (Gaussian window, sigma 1.5, data range 256).

    Arrays with more than two (luminance) axes are taken as a stack of 2-D images over the
    last two axes; the mean SSIM of the images is returned. Images must be at least 11x11.

    Returns
    -------
    float
        Mean SSIM, at most 1 (identical images).

    Raises
    ------
    ShapeError
        Shapes that differ, fewer than two axes, or images smaller than 11 x 11.
    """
    y_res, y_ref, _ = _scaled_luminance(result, reference, peak_luminance, channel_axis)
    if y_ref.ndim < 2:
        raise ShapeError(f"SSIM: expected images of shape (..., H, W), got shape {y_ref.shape}")
    ssim = _ssim_images(pu21_encode(y_res, variant=variant), pu21_encode(y_ref, variant=variant))
    return float(np.mean(ssim))


def pu2_psnr(result: Any, reference: Any, *, peak_luminance: float | None = 1000.0,
             channel_axis: int | None = None) -> float:
    """PU2-PSNR in dB on luminance with the peak ``pu2_encode(max(scaled reference))``.

    After scaling the peak is ``pu2_encode(peak_luminance)`` (419.6 for 1000 cd/m^2); see the
    module notes for why this convention.

    Returns
    -------
    float
        dB; ``inf`` for identical images.
    """
    y_res, y_ref, display_peak = _scaled_luminance(result, reference, peak_luminance, channel_axis)
    mse = np.mean(np.square(pu2_encode(y_res) - pu2_encode(y_ref)))
    return float(_psnr_from_mse(mse, float(pu2_encode(display_peak))))


def _log_luminance(y: np.ndarray) -> np.ndarray:
    return np.log10(np.clip(y, PU21_L_MIN, PU21_L_MAX))


def _log_peak(display_peak: float) -> float:
    return math.log10(min(max(display_peak, PU21_L_MIN), PU21_L_MAX) / PU21_L_MIN)


def log_psnr(result: Any, reference: Any, *, peak_luminance: float | None = 1000.0,
             channel_axis: int | None = None) -> float:
    """Log-domain PSNR in dB: PSNR of ``log10(clip(Y, 0.005, 1e4))`` with peak ``log10(Y_peak / 0.005)``.

    ``Y`` is the scaled luminance (cd/m^2) and ``Y_peak`` the scaled reference peak
    (``peak_luminance``), so the peak is the number of decades the display spans above
    PU21's black level (5.30 for 1000 cd/m^2). A uniform error of ``d`` decades gives
    ``20 log10(peak / d)``.

    Returns
    -------
    float
        dB; ``inf`` for identical images.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.metrics import log_psnr
    >>> ref = np.random.default_rng(0).uniform(0.1, 1.0, (16, 16))
    >>> round(log_psnr(10 * ref, ref), 2)  # one decade everywhere: 20 log10(5.30 / 1)
    14.49
    """
    y_res, y_ref, display_peak = _scaled_luminance(result, reference, peak_luminance, channel_axis)
    mse = np.mean(np.square(_log_luminance(y_res) - _log_luminance(y_ref)))
    return float(_psnr_from_mse(mse, _log_peak(display_peak)))


def log_luminance_error(result: Any, reference: Any, *, mask: Any = None, align: str = "gain") -> float:
    """RMS of the natural-log luminance difference, after one fitted gain (``align="gain"``).

    ``sqrt(mean((ln Y_res - ln Y_ref - c)^2))`` over the samples of ``mask`` (default: all)
    whose reference luminance is positive; ``c`` is the mean log ratio (the least-squares gain,
    since a merged radiance map from 8-bit images has an arbitrary scale) or 0 with
    ``align="none"``. Luminance with :data:`PU21_LUMA` weights (RGB on the last axis; one
    channel as is). Result luminances below 1e-12 of the reference mean are clamped there.

    Parameters
    ----------
    result, reference : array_like of the same shape
        Linear images or light fields, RGB (or one channel) on the last axis.
    mask : array_like of bool, optional
        Samples to use, of the luminance's shape (the input's without the colour axis).
    align : {"gain", "none"}, default "gain"
        Fit one gain (a constant log offset) first, or not.

    Returns
    -------
    float
        RMS error in natural-log units (``/ ln 2`` for stops).

    Raises
    ------
    ShapeError
        Shapes differ, or a mask of another shape.
    InputError
        No sample of positive reference luminance in the mask.

    Examples
    --------
    >>> import math
    >>> import numpy as np
    >>> from lfproc.metrics import log_luminance_error
    >>> ref = np.linspace(0.1, 10.0, 300).reshape(10, 10, 3)
    >>> round(log_luminance_error(4 * ref, ref), 6)  # a gain is fitted away
    0.0
    >>> round(log_luminance_error(4 * ref, ref, align="none") / math.log(2), 6)  # two stops
    2.0
    """
    check_choice("align", align, ("gain", "none"))
    res, ref = _check_pair(result, reference)
    y_res = metric_luminance(res) if res.shape[-1] in (1, 3) and res.ndim > 1 else res
    y_ref = metric_luminance(ref) if ref.shape[-1] in (1, 3) and ref.ndim > 1 else ref
    keep = y_ref > 0
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != keep.shape:
            raise ShapeError(f"mask: expected shape {keep.shape} (the luminance), got {m.shape}")
        keep &= m
    if not keep.any():
        raise InputError("log_luminance_error: no sample with a positive reference luminance in the mask")
    floor = 1e-12 * float(y_ref[keep].mean())
    d = np.log(np.maximum(y_res[keep], floor)) - np.log(y_ref[keep])
    if align == "gain":
        d = d - d.mean()
    return float(np.sqrt(np.mean(d * d)))


def mean_relative_error(result: Any, reference: Any, *, epsilon_relative: float = 1e-3) -> float:
    """Mean relative error of linear values: ``mean(|result - reference| / (reference + eps))``.

    Computed on every sample (every colour channel), without luminance, PU or scaling.
    ``eps = epsilon_relative * max(reference)`` keeps black reference samples from dominating
    (default ``1e-3``: 10 stops below the reference peak). 0 for identical arrays.

    Parameters
    ----------
    result, reference : array_like of the same shape
        Linear radiance in the same units.
    epsilon_relative : float, default 1e-3
        Regulariser relative to the reference peak (positive).

    Returns
    -------
    float

    Raises
    ------
    ShapeError
        Shapes that differ.
    InputError
        A non-positive ``epsilon_relative`` or a reference without a positive peak.
    """
    epsilon_relative = check_positive("epsilon_relative", epsilon_relative)
    res, ref = _check_pair(result, reference)
    eps = epsilon_relative * float(ref.max())
    if not eps > 0:
        raise InputError(f"reference: maximum value is {float(ref.max()):.4g}; expected a positive peak")
    return float(np.mean(_relative_error(res, ref, eps)))


def _relative_error(res: np.ndarray, ref: np.ndarray, eps: float) -> np.ndarray:
    ref = ref.astype(np.float64)
    err = np.abs(res.astype(np.float64) - ref)
    np.abs(ref, out=ref)
    ref += eps
    err /= ref
    return err


_VARIANT_DOC = """    variant : {"banding_glare", "banding", "peaks", "peaks_glare"}, default "banding_glare"
        PU21 parameter set.
"""
for _f, _extra in ((pu21_psnr, _VARIANT_DOC), (pu21_ssim, _VARIANT_DOC), (pu2_psnr, ""), (log_psnr, "")):
    # the shared Parameters go before the docstring's own sections (Returns, Raises, Examples)
    _head, _sep, _tail = (_f.__doc__ or "").partition("\n    Returns\n")
    _f.__doc__ = _head.rstrip() + "\n" + _SHARED_PARAMS_DOC + _extra + _sep + _tail
del _f, _extra, _head, _sep, _tail


# -- figures a user sees: error in stops per decade, zeros, highlight energy, detail -------------

#: :func:`hdr_figures` says the brightest 0.1 % of the reference dominate PU21 (``emitters_dominate``)
#: when they hold more than this share of the PU21 squared error.
EMITTER_SHARE_DOMINATES = 0.5
_HIGHLIGHT_FRACTION = 0.01  # "the brightest 1 %" of highlight_energy
_EMITTER_FRACTION = 0.001  # "the brightest 0.1 %" of emitter_share
#: A result more than this many stops below its reference counts as a zero in ``zeros_above_floor``
#: (a reconstruction can return 1e-14 of the truth, black on any display, but not exactly 0).
ZERO_STOPS = 20.0


def _figure_luminance(values: Any, name: str) -> np.ndarray:
    """Luminance (:data:`PU21_LUMA`, float64) of a LightField or an ``(..., C)`` array, C = 1 or 3."""
    data = values.data if isinstance(values, LightField) else values
    arr = _as_numeric(data, name)
    if arr.ndim < 3 or arr.shape[-1] not in (1, 3):
        raise ShapeError(f"{name}: expected a light field or an array of shape (..., H, W, 1 or 3), "
                         f"got shape {arr.shape}")
    return metric_luminance(arr, channel_axis=-1)


def _brightest(y: np.ndarray, fraction: float) -> np.ndarray:
    """Indices of the ``ceil(fraction * n)`` (at least one) largest values of the 1-d ``y``."""
    k = max(1, math.ceil(fraction * y.size))
    if k >= y.size:
        return np.arange(y.size)
    return np.argpartition(y, y.size - k)[y.size - k:]


def _figure_mask(mask, shape) -> tuple[np.ndarray | None, int]:
    """The mask of :func:`hdr_figures` broadcast to the luminance ``shape`` (None: every sample) and the
    number of samples it keeps."""
    if mask is None:
        keep = None
    else:
        m = np.asarray(mask)
        if m.dtype != bool:
            raise ShapeError(f"mask: expected a boolean array, got dtype {m.dtype}")
        if m.shape != shape and m.shape != shape[-2:]:
            raise ShapeError(f"mask: expected shape {shape[-2:]} or {shape}, got {m.shape}")
        keep = np.broadcast_to(m, shape)
    n = math.prod(shape) if keep is None else int(np.count_nonzero(keep))
    if n == 0:
        raise ShapeError("mask: expected at least one sample to evaluate, the mask selects none")
    return keep, n


def _stops_by_decade(res_k: np.ndarray, ref_k: np.ndarray, floor: float) -> tuple[list[dict], float, int]:
    """``stops_by_decade`` of :func:`hdr_figures` over the samples (1-d luminances) above ``floor``, the
    share of those whose result is ``<= 0`` or more than :data:`ZERO_STOPS` below the reference (``nan`` when none
    is above), and their number."""
    above = ref_k > floor
    n_above = int(np.count_nonzero(above))
    ref_a, res_a = ref_k[above], res_k[above]
    positive = res_a > 0
    stops = np.full(ref_a.shape, np.inf)
    stops[positive] = np.abs(np.log2(res_a[positive] / ref_a[positive]))
    near_zero = ~positive | (res_a < ref_a * 2.0 ** -ZERO_STOPS)
    decades = np.floor(np.log10(ref_a)).astype(np.int64)
    by_decade = []
    for k in np.unique(decades):
        sel = decades == k
        by_decade.append({"decade": (10.0 ** int(k), 10.0 ** (int(k) + 1)),
                          "median_stops": float(np.median(stops[sel])), "samples": int(np.count_nonzero(sel))})
    zeros = float(np.count_nonzero(near_zero) / n_above) if n_above else math.nan
    return by_decade, zeros, n_above


def _checked_floor(noise_floor) -> float:
    """``noise_floor`` of :func:`hdr_figures` as a float (None: 0), or InputError."""
    if noise_floor is None:
        return 0.0
    floor = float(noise_floor)
    if not (math.isfinite(floor) and floor >= 0):
        raise InputError(f"noise_floor: expected a finite value >= 0, got {noise_floor!r}")
    return floor


def _stops_below_floor(res_k: np.ndarray, ref_k: np.ndarray, floor: float) -> list[dict]:
    """``stops_below_floor`` of :func:`hdr_figures`: ``stops_by_decade`` of the samples of positive reference
    luminance at or below ``floor``."""
    below = (ref_k > 0) & (ref_k <= floor)
    return _stops_by_decade(res_k[below], ref_k[below], 0.0)[0] if below.any() else []


def _detail(err: np.ndarray, p_ref: np.ndarray, keep: np.ndarray | None, top: np.ndarray) -> dict:
    """``detail_ratio``, ``detail_ratio_off_highlights`` and ``highlight_detail_share`` of :func:`hdr_figures`.

    The Laplacian energies of the PU21 error and of the reference, per view, summed over the kept samples; then
    over the kept samples neither among the brightest ``top`` (indices into the kept samples, as ``ref_k``) nor
    next to one (the Laplacian's cross of each view reaches them), and the reference's share there (``nan`` for a
    reference without detail)."""
    from scipy.ndimage import binary_dilation, generate_binary_structure, laplace

    h, w = p_ref.shape[-2:]
    shape = (-1, h, w)
    near = np.zeros(p_ref.size, bool)
    near[top if keep is None else np.flatnonzero(keep)[top]] = True
    near = binary_dilation(near.reshape(shape), structure=generate_binary_structure(2, 1)[None])  # each view's cross
    flat_keep = np.ones(near.shape, bool) if keep is None else keep.reshape(shape)
    sums = np.zeros((2, 2))  # [error, reference] x [all kept, kept and near the highlights]
    for e, r, k, n in zip(err.reshape(shape), p_ref.reshape(shape), flat_keep, near):
        for j, lap in enumerate((np.square(laplace(e)), np.square(laplace(r)))):
            sums[j] += float(np.sum(lap[k])), float(np.sum(lap[k & n]))
    (err_all, err_near), (ref_all, ref_near) = sums
    ratio = err_all / ref_all if ref_all > 0 else math.nan
    off = (err_all - err_near) / (ref_all - ref_near) if ref_all - ref_near > 0 else math.nan
    share = ref_near / ref_all if ref_all > 0 else math.nan
    return {"detail_ratio": ratio, "detail_ratio_off_highlights": off, "highlight_detail_share": share}


def _emitters(err: np.ndarray, keep: np.ndarray | None, ref_k: np.ndarray) -> dict:
    """``emitter_share``, ``emitters_dominate`` and ``emitter_luminance`` of :func:`hdr_figures` from the PU21
    error ``err`` and the kept reference samples ``ref_k``."""
    sq = np.square(err.ravel() if keep is None else err[keep])
    total = float(sq.sum())
    emitters = _brightest(ref_k, _EMITTER_FRACTION)
    share = float(sq[emitters].sum()) / total if total > 0 else 0.0
    return {"emitter_share": share, "emitters_dominate": bool(share > EMITTER_SHARE_DOMINATES),
            "emitter_luminance": float(ref_k[emitters].min())}


def hdr_figures(result: Any, reference: Any, *, noise_floor: float | None = None, mask: Any = None,
                peak_luminance: float | None = 1000.0) -> dict[str, Any]:
    """Figures of an HDR result a user can check: error in stops per decade, zeros, highlights, detail.

    PU21-PSNR/SSIM map the reference peak to ``peak_luminance`` and barely see the dark
    decades, so a few bright emitters can decide them. These figures look at the whole range.
    Luminance uses the weights of :data:`PU21_LUMA`; a *sample* is one pixel of one view.

    Parameters
    ----------
    result, reference : LightField or ndarray of shape (..., H, W, C), C = 1 or 3
        Linear radiance in the same units and of the same shape (for example
        ``(V, U, H, W, 3)`` or ``(H, W, 3)``).
    noise_floor : float or None
        Reference luminance (data units, before any scaling) at or below which a sample is left
        out of ``stops_by_decade`` and ``zeros_above_floor``; ``None`` (default): 0.
    mask : array_like of bool, shape (H, W) or the luminance shape (e.g. (V, U, H, W)), optional
        Samples to include in every figure (an (H, W) mask applies to every view; default all).
    peak_luminance : float or None, default 1000
        Display peak in cd/m^2; both luminances are multiplied by
        ``peak_luminance / max(reference)`` (the maximum over every sample and channel, as
        :func:`pu21_psnr`; taken over the whole reference even with a mask) before the PU21
        encoding of ``detail_ratio`` and ``emitter_share``. ``None``: the data already are
        absolute cd/m^2.

    Returns
    -------
    dict
        ``stops_by_decade``
            list, ascending, of ``{"decade": (lo, hi), "median_stops": float, "samples": int}``:
            the decades ``[10^k, 10^(k+1))`` of the reference luminance (data units,
            ``k = floor(log10(Y_ref))``), and the median of ``|log2(Y_res / Y_ref)|`` over the
            samples above the noise floor in that decade. A result luminance ``<= 0`` is an
            infinite error (``inf`` stops), so a decade more than half zeros reads ``inf``.
        ``max_decade_stops``
            the largest ``median_stops`` (``nan`` when no sample is above the floor).
        ``stops_below_floor``
            as ``stops_by_decade``, over the samples of positive reference at or below the floor (empty
            without one): one measurement does not resolve them, but a user sees them (shadows).
        ``zeros_above_floor``
            share of the samples above the noise floor whose result luminance is ``<= 0`` or more
            than :data:`ZERO_STOPS` (20) stops below the reference's (``nan`` when there is none).
        ``highlight_energy``
            ``sum(Y_res) / sum(Y_ref)`` over the brightest 1 % of the reference samples
            (at least one sample): 1.0 keeps the highlights' energy, 0.8 loses a fifth.
        ``detail_ratio``
            ``sum(lap(P_res - P_ref)^2) / sum(lap(P_ref)^2)``, with ``P`` the PU21-encoded
            scaled luminance and ``lap`` the 2-D Laplacian of each view
            (:func:`scipy.ndimage.laplace`, reflected borders), summed over the mask: 0 is
            every detail right, 1.0 as much wrong detail as the reference has (a flat result
            scores about 1). ``nan`` for a reference without any detail.
        ``detail_ratio_off_highlights``, ``highlight_detail_share``
            ``detail_ratio`` away from the brightest 1 % (nor beside one in its view), and the share
            of the reference's Laplacian energy those hold: lights hold most of an HDR reference's
            detail (city-interior 98 %: 0.25 overall, 3.5 away from them; ``nan``: no detail there).
        ``emitter_share``, ``emitters_dominate``
            share of the PU21 squared error (the MSE of PU21-PSNR) that comes from the
            brightest 0.1 % of the reference samples (0.0 when there is no error), and
            whether it is above :data:`EMITTER_SHARE_DOMINATES` (a few emitters decide PU21);
            ``emitter_luminance`` is the reference luminance (data units) where those brightest
            0.1 % begin (``exclude_above`` just below it scores without them).
        ``noise_floor``, ``samples``, ``samples_above_floor``, ``scale_factor``
            the floor used, the number of samples in the mask, of those above the floor, and
            the PU21 scale factor (cd/m^2 per data unit).

    Raises
    ------
    ShapeError
        Different shapes, no colour axis, a mask of another shape, an empty mask.
    InputError
        Non-finite values, a negative noise floor, a reference without a positive maximum.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.metrics import hdr_figures
    >>> ref = np.random.default_rng(0).uniform(0.01, 1.0, (16, 16, 3))
    >>> f = hdr_figures(2 * ref, ref)  # one stop too bright everywhere
    >>> f["max_decade_stops"], f["zeros_above_floor"], f["highlight_energy"], f["samples"]
    (1.0, 0.0, 2.0, 256)
    """
    y_res = _figure_luminance(result, "result")
    y_ref = _figure_luminance(reference, "reference")
    if y_res.shape != y_ref.shape:
        raise ShapeError(f"result and reference: expected the same shape, got {y_res.shape} and {y_ref.shape} "
                         "(luminance)")
    floor = _checked_floor(noise_floor)
    ref_data = reference.data if isinstance(reference, LightField) else np.asarray(reference)
    factor = _scale_factor(ref_data, peak_luminance)
    keep, n = _figure_mask(mask, y_ref.shape)
    # the kept samples, 1-d (views of the luminance when every sample is kept)
    ref_k, res_k = (y_ref.ravel(), y_res.ravel()) if keep is None else (y_ref[keep], y_res[keep])
    by_decade, zeros, n_above = _stops_by_decade(res_k, ref_k, floor)
    max_stops = max((d["median_stops"] for d in by_decade), default=math.nan)

    top = _brightest(ref_k, _HIGHLIGHT_FRACTION)
    ref_energy = float(ref_k[top].sum())
    highlight = float(res_k[top].sum()) / ref_energy if ref_energy > 0 else math.nan

    p_ref = pu21_encode(y_ref * factor)
    err = pu21_encode(y_res * factor)
    err -= p_ref
    return {
        "stops_by_decade": by_decade,
        "max_decade_stops": float(max_stops),
        "stops_below_floor": _stops_below_floor(res_k, ref_k, floor),
        "zeros_above_floor": zeros,
        "highlight_energy": highlight,
        **_detail(err, p_ref, keep, top),
        **_emitters(err, keep, ref_k),
        "noise_floor": floor,
        "samples": n,
        "samples_above_floor": n_above,
        "scale_factor": factor,
    }


def error_stops(result: Any, reference: Any, *, view: tuple[int, int] | None = None) -> np.ndarray:
    """Per-pixel error in stops of one view: ``log2(Y_result / Y_reference)`` (:data:`PU21_LUMA`).

    Parameters
    ----------
    result, reference : LightField, or ndarray of shape (H, W, C) or (V, U, H, W, C), C = 1 or 3
    view : (v, u), optional
        The view of a light field (default: the centre view, ``(V // 2, U // 2)``).

    Returns
    -------
    ndarray (H, W), float64
        Positive where the result is too bright; ``nan`` where the reference luminance is
        ``<= 0`` (no defined error), ``-inf`` where the result is ``<= 0`` and the reference
        is not (a lost sample).

    Raises
    ------
    ShapeError
        Shapes that differ or have no colour axis.
    InputError
        A view outside the light field.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.metrics import error_stops
    >>> ref = np.ones((2, 2, 3))
    >>> res = ref.copy()
    >>> res[0, 0] = 2.0  # one stop too bright
    >>> res[1, 1] = 0.0  # lost
    >>> error_stops(res, ref).tolist()
    [[1.0, 0.0], [0.0, -inf]]
    """
    y_res = _figure_luminance(result, "result")
    y_ref = _figure_luminance(reference, "reference")
    if y_res.shape != y_ref.shape:
        raise ShapeError(f"result and reference: expected the same shape, got {y_res.shape} and {y_ref.shape} "
                         "(luminance)")
    if y_ref.ndim == 4:
        nv, nu = y_ref.shape[:2]
        v, u = (nv // 2, nu // 2) if view is None else view
        if not (0 <= v < nv and 0 <= u < nu):
            raise InputError(f"view: expected (v, u) with 0 <= v < {nv}, 0 <= u < {nu}, got {view!r}")
        y_res, y_ref = y_res[v, u], y_ref[v, u]
    elif y_ref.ndim != 2:
        raise ShapeError(f"reference: expected (H, W, C) or (V, U, H, W, C), got luminance of shape {y_ref.shape}")
    out = np.full(y_ref.shape, np.nan)
    both = (y_ref > 0) & (y_res > 0)
    out[both] = np.log2(y_res[both] / y_ref[both])
    out[(y_ref > 0) & ~(y_res > 0)] = -np.inf
    return out


# -- light fields ----------------------------------------------------------------------------------

def _describe(lf: LightField) -> str:
    v, u, h, w, c = lf.shape
    return f"{v}x{u} views of {h}x{w}x{c}"


ALIGN_MODES = ("none", "exposure", "gain")


def _exposure_product(lf: LightField) -> float | None:
    if lf.exposure_s is None:
        return None
    return lf.exposure_s * (lf.iso / 100.0 if lf.iso is not None else 1.0)


ALIGN_PYTHON = "align='exposure', or align='gain'"


def align_result(result: LightField, reference: LightField, align: str = "none") -> tuple[LightField, dict[str, Any]]:
    """Bring ``result`` to the reference's scale, or refuse a mismatch (``align="none"``).

    * ``"none"``: no change. Different ``units``, or ``relative`` data of different known
      exposures (``exposure_s`` x ISO/100; a merged radiance per second has ``exposure_s = 1``),
      raise :class:`InputError` naming the two and the ``align`` choices.
    * ``"exposure"``: same units required; the result is multiplied by the exposure ratio
      ``(t_ref ISO_ref) / (t_res ISO_res)`` (both exposures must be known): exact for linear
      data such as a decode and a merge of the same camera.
    * ``"gain"``: one gain fitted on the data, ``exp(median(ln(Y_ref / Y_res)))`` over the pixels
      whose reference luminance lies between its 1st and 99th percentiles of positive values
      (clipped and black samples left out), for any units (HDR comparisons of relative data).

    Parameters
    ----------
    result, reference : LightField
    align : {"none", "exposure", "gain"}, default "none"

    Returns
    -------
    aligned : LightField
        ``result`` (``"none"``) or a new light field scaled to the reference (data, variance and
        saturation level; the reference's units, exposure and ISO; ``attrs["evaluate_alignment"]``).
    info : dict
        ``{"align": mode, "gain": factor applied}``.

    Raises
    ------
    InputError
        A mismatch of units or exposures with ``"none"``, missing exposures with ``"exposure"``,
        too few usable pixels with ``"gain"``.
    ShapeError
        Shapes differ (``"gain"``).
    """
    check_choice("align", align, ALIGN_MODES)
    for name, lf in (("result", result), ("reference", reference)):
        if not isinstance(lf, LightField):
            raise InputError(f"evaluate: {name} must be a LightField, got {type(lf).__name__}")
    e_res, e_ref = _exposure_product(result), _exposure_product(reference)
    if align == "none":
        if result.units != reference.units:
            raise InputError(
                f"evaluate: result is in {result.units!r}, reference in {reference.units!r}; expected the same units "
                "(or align them: --align gain)"
            )
        if (result.units == "relative" and e_res is not None and e_ref is not None
                and abs(math.log2(e_res / e_ref)) > 0.01):
            raise InputError(
                f"evaluate: result exposure {_describe_exposure(result)} differs from the reference's "
                f"{_describe_exposure(reference)} ({math.log2(e_res / e_ref):+.2f} stops) in relative units; "
                f"align them ({option_name(ALIGN_PYTHON, '--align exposure, or --align gain')})"
            )
        return result, {"align": "none", "gain": 1.0}
    if align == "exposure":
        if result.units != reference.units:
            raise InputError(
                f"evaluate: --align exposure needs the same units, got result {result.units!r} and reference "
                f"{reference.units!r} (use --align gain)"
            )
        if e_res is None or e_ref is None:
            which = "result" if e_res is None else "reference"
            raise InputError(f"evaluate: --align exposure needs both exposure times; the {which} has none "
                             "(use --align gain)")
        gain = e_ref / e_res
    else:
        if result.shape != reference.shape:
            raise ShapeError(
                f"evaluate: result has {_describe(result)}, reference {_describe(reference)}; expected the same shape"
            )
        y_res = metric_luminance(result.data, channel_axis=-1)
        y_ref = metric_luminance(reference.data, channel_axis=-1)
        pos = y_ref > 0
        if not pos.any():
            raise InputError("evaluate: --align gain needs a reference with positive luminance")
        lo, hi = np.percentile(y_ref[pos], [1, 99])
        use = (y_ref >= lo) & (y_ref <= hi) & (y_res > 0)
        if use.sum() < 16:
            raise InputError("evaluate: --align gain found fewer than 16 pixels positive in both images")
        gain = float(np.exp(np.median(np.log(y_ref[use]) - np.log(y_res[use]))))
    attrs = dict(result.attrs) | {"evaluate_alignment": {"align": align, "gain": gain}}
    aligned = result.replace(
        data=result.data * np.float32(gain),
        variance=None if result.variance is None else result.variance * np.float32(gain * gain),
        units=reference.units, exposure_s=reference.exposure_s, iso=reference.iso,
        saturation_level=None if result.saturation_level is None else result.saturation_level * gain,
        attrs=attrs,
    )
    return aligned, {"align": align, "gain": float(gain)}


def _describe_exposure(lf: LightField) -> str:
    text = f"{lf.exposure_s:g} s"
    return text + (f" at ISO {lf.iso:g}" if lf.iso is not None else "")


def _check_lightfields(result: LightField, reference: LightField, scale_tolerance_stops: float | None) -> None:
    for name, lf in (("result", result), ("reference", reference)):
        if not isinstance(lf, LightField):
            raise InputError(f"evaluate: {name} must be a LightField, got {type(lf).__name__}")
    if result.views != reference.views:
        raise ShapeError(
            f"evaluate: result has {result.views[0]}x{result.views[1]} views, reference "
            f"{reference.views[0]}x{reference.views[1]}; expected the same views"
        )
    if result.shape != reference.shape:
        raise ShapeError(
            f"evaluate: result has {_describe(result)}, reference {_describe(reference)}; expected the same shape"
        )
    if result.units != reference.units:
        raise InputError(
            f"evaluate: result is in {result.units!r}, reference in {reference.units!r}; expected the same units "
            "(or align them: --align gain)"
        )
    ref_max = float(reference.data.max())
    if not ref_max > 0:
        raise InputError(
            f"evaluate: reference maximum is {ref_max:.4g}; an all-black reference cannot be scaled to the display peak"
        )
    if scale_tolerance_stops is not None:
        tol = check_positive("scale_tolerance_stops", scale_tolerance_stops)
        mean_res = float(np.mean(result.data, dtype=np.float64))
        mean_ref = float(np.mean(reference.data, dtype=np.float64))
        stops = math.log2(mean_res / mean_ref) if mean_res > 0 else -math.inf
        if abs(stops) > tol:
            raise InputError(
                f"evaluate: result mean {mean_res:.4g} and reference mean {mean_ref:.4g} ({result.units}) differ by "
                f"{abs(stops):.3g} stops, more than {tol:g}; expected the same scale (are the units or exposure "
                "different? raise scale_tolerance_stops / --scale-tolerance-stops to compare anyway)"
            )


def evaluation_mask(reference: LightField, *, mask: Any = None,
                    exclude_above: float | None = None) -> np.ndarray | None:
    """The samples :func:`evaluate` scores: ``mask`` and the reference luminance ``<= exclude_above``.

    Parameters
    ----------
    reference : LightField
    mask : array_like of bool, shape (H, W) or (V, U, H, W), optional
        Samples to include (an (H, W) mask applies to every view).
    exclude_above : float, optional
        Leave out the samples whose reference luminance (:data:`PU21_LUMA`, data units) is
        above this value (emitters, the sun).

    Returns
    -------
    ndarray of bool (V, U, H, W), or None when neither is given (every sample).

    Raises
    ------
    ShapeError
        A mask of another shape or not boolean; no sample left.
    InputError
        ``exclude_above`` not a finite number.
    """
    if mask is None and exclude_above is None:
        return None
    nv, nu, h, w, _ = reference.shape
    keep = np.ones((nv, nu, h, w), dtype=bool)
    if mask is not None:
        m = np.asarray(mask)
        if m.dtype != bool:
            raise ShapeError(f"mask: expected a boolean array, got dtype {m.dtype}")
        if m.shape not in ((h, w), (nv, nu, h, w)):
            raise ShapeError(f"mask: expected shape {(h, w)} or {(nv, nu, h, w)} (the reference), got {m.shape}")
        keep &= m
    if exclude_above is not None:
        limit = float(exclude_above)
        if not math.isfinite(limit):
            raise InputError(f"exclude_above: expected a finite luminance, got {exclude_above!r}")
        keep &= metric_luminance(reference.data, channel_axis=-1) <= limit
    if not keep.any():
        what = [] if mask is None else ["the mask"]
        what += [] if exclude_above is None else [f"exclude_above={float(exclude_above):g}"]
        raise ShapeError(f"evaluate: {' and '.join(what)} left no sample to evaluate; expected at least one")
    return keep


def _view_means(values: np.ndarray, keep: np.ndarray | None) -> np.ndarray:
    """Mean over the last two axes (pixels) of each view, over the kept pixels only (nan: none kept)."""
    if keep is None:
        return np.mean(values, axis=(-2, -1))
    count = keep.sum(axis=(-2, -1))
    total = np.where(keep, values, 0.0).sum(axis=(-2, -1))
    return np.divide(total, count, out=np.full(count.shape, np.nan), where=count > 0)


def _ssim_images_masked(p_res: np.ndarray, p_ref: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Per-view SSIM: the mean of scikit-image's SSIM map over the kept pixels inside its valid
    region (the same 5-pixel border as the unmasked figure is left out); nan when none is kept."""
    from skimage.metrics import structural_similarity

    h, w = p_ref.shape[-2:]
    lead = p_ref.shape[:-2]
    pad = (_SSIM_MIN_SIZE - 1) // 2
    out = np.empty(int(np.prod(lead)))
    for i, (a, b, k) in enumerate(zip(p_res.reshape(-1, h, w), p_ref.reshape(-1, h, w), keep.reshape(-1, h, w))):
        k = k[pad:h - pad, pad:w - pad]
        if not k.any():
            out[i] = np.nan
        elif np.array_equal(a, b):
            out[i] = 1.0
        else:
            _, smap = structural_similarity(a, b, full=True, **_SSIM_OPTIONS)
            out[i] = float(smap[pad:h - pad, pad:w - pad][k].mean())
    return out.reshape(lead)


def _luminance_figures(result, reference, keep, *, factor, display_peak, variant):
    """Per-view PU21-PSNR, PU21-SSIM, PU2-PSNR and log-PSNR of :func:`evaluate` (arrays (V, U)), and the
    PU2 and log peaks."""
    # luminance of every view at once, float64 (V, U, H, W), scaled by the one factor
    y_res = metric_luminance(result.data, channel_axis=-1)
    y_ref = metric_luminance(reference.data, channel_axis=-1)
    if factor != 1.0:
        y_res *= factor
        y_ref *= factor

    p_res, p_ref = pu21_encode(y_res, variant=variant), pu21_encode(y_ref, variant=variant)
    pu21_psnr_v = _psnr_from_mse(_view_means(np.square(p_res - p_ref), keep), PU21_PSNR_PEAK)
    pu21_ssim_v = _ssim_images(p_res, p_ref) if keep is None else _ssim_images_masked(p_res, p_ref, keep)
    del p_res, p_ref
    pu2_peak = float(pu2_encode(display_peak))
    pu2_psnr_v = _psnr_from_mse(_view_means(np.square(pu2_encode(y_res) - pu2_encode(y_ref)), keep), pu2_peak)
    log_peak = _log_peak(display_peak)
    log_psnr_v = _psnr_from_mse(_view_means(np.square(_log_luminance(y_res) - _log_luminance(y_ref)), keep),
                                log_peak)
    return {"pu21_psnr_db": pu21_psnr_v, "pu21_ssim": pu21_ssim_v, "pu2_psnr_db": pu2_psnr_v,
            "log_psnr_db": log_psnr_v}, (pu2_peak, log_peak)


def _colour_figures(result, reference, keep, *, epsilon_relative):
    """Per-view linear PSNR and mean relative error of the colour samples of :func:`evaluate`, and the
    linear peak (the reference's 99.9th percentile)."""
    nv = reference.shape[0]
    # relative error of the colour samples, one row of views at a time (bounds float64 temporaries);
    # the colour axis averaged first, then the pixels (the same mean when every pixel is kept)
    eps = epsilon_relative * float(reference.data.max())
    mre_v = np.stack([_view_means(np.mean(_relative_error(result.data[v], reference.data[v], eps), axis=-1),
                                  None if keep is None else keep[v]) for v in range(nv)])

    lin_peak = float(np.percentile(reference.data, 99.9))
    if not lin_peak > 0:
        lin_peak = float(reference.data.max())
    lin_mse = np.stack([_view_means(np.mean(np.square(result.data[v].astype(np.float64) - reference.data[v]),
                                            axis=-1), None if keep is None else keep[v]) for v in range(nv)])
    return {"linear_psnr_db": _psnr_from_mse(lin_mse, lin_peak), "mean_relative_error": mre_v}, lin_peak


def evaluate(result: LightField, reference: LightField, *, peak_luminance: float | None = 1000.0,
             variant: Pu21Variant = "banding_glare", epsilon_relative: float = 1e-3,
             scale_tolerance_stops: float | None = 4.0, align: str = "none", mask: Any = None,
             exclude_above: float | None = None, noise_floor: float | None = None) -> dict[str, Any]:
    """All metrics of a result light field against a reference, per view and averaged over views.

    Luminance (:data:`PU21_LUMA`) of every view is scaled by one factor,
    ``peak_luminance / max(reference.data)`` (maximum over all views and channels; the same
    factor for the result), PU-encoded in one batch over the ``(V, U, H, W)`` array, and
    compared view by view. See the module notes for every convention.

    Parameters
    ----------
    result, reference : LightField
        Same views, size and channels, same ``units``.
    peak_luminance : float or None, default 1000
        Display peak in cd/m^2 the reference peak is mapped to; ``None`` when both are
        already absolute luminance (``units="cd/m2"``).
    variant : PU21 variant (default ``"banding_glare"``).
    epsilon_relative : regulariser of :func:`mean_relative_error`.
    scale_tolerance_stops : float or None, default 4
        Refuse pairs whose mean values differ by more than this many stops (different units or
        exposure) after the alignment; ``None`` disables the check.
    align : {"none", "exposure", "gain"}
        How the result is brought to the reference's scale first (:func:`align_result`):
        ``"none"`` refuses different units or exposures.
    mask : array_like of bool, shape (H, W) or (V, U, H, W), optional
        Samples to score; every figure is restricted to them (SSIM: the mean of its map over
        them). The scale factor, the linear PSNR peak and the relative-error regulariser
        stay those of the whole reference, so masked and unmasked figures share one scale.
    exclude_above : float, optional
        Leave out samples whose reference luminance (data units) is above this value, e.g.
        to score without the emitters (combined with ``mask``).
    noise_floor : float, optional
        Reference luminance at or below which samples are left out of the error in stops
        and the zeros, and scored apart (``stops_below_floor``; see :func:`hdr_figures`;
        default: every positive sample).

    Returns
    -------
    dict
        ``pu21_psnr_db``, ``pu21_ssim``, ``pu2_psnr_db``, ``log_psnr_db``,
        ``mean_relative_error``: means over views (PSNR ``inf`` when identical);
        ``views``: list of dicts with ``v``, ``u`` and the same five figures, row-major;
        ``peak_luminance_cd_m2``, ``scale_factor`` (cd/m^2 per unit of the data),
        ``pu21_psnr_peak`` (256), ``pu2_psnr_peak``, ``log_psnr_peak``, ``angular_shape``,
        ``size``, ``channels``, ``units``, ``pu21_variant``; ``linear_psnr_db`` (PSNR of the
        linear colour samples, peak = the reference's 99.9th percentile, so a small bright
        source does not inflate it; per view too), ``linear_psnr_peak``; ``align`` and ``gain``
        (the factor applied to the result); the figures of :func:`hdr_figures` over all views
        (``stops_by_decade``, ``max_decade_stops``, ``zeros_above_floor``, ``highlight_energy``,
        ``detail_ratio``, ``detail_ratio_off_highlights``, ``highlight_detail_share``,
        ``emitter_share``, ``emitters_dominate``, ``emitter_luminance``, ``noise_floor``, ``samples``,
        ``samples_above_floor``; their PU21 figures use the ``banding_glare`` variant whatever
        ``variant`` says); ``exclude_above`` and ``masked`` (whether a mask or
        ``exclude_above`` restricted the figures). With a mask, view averages are over the
        views that keep at least one sample (a view without any has ``nan`` figures).

    Raises
    ------
    ShapeError
        Different views, size or channels; views smaller than 11x11 (SSIM window).
    InputError
        Different units, all-black reference, scales more than ``scale_tolerance_stops`` apart,
        ``peak_luminance=None`` with data not in cd/m2.

    Examples
    --------
    >>> from lfproc.metrics import evaluate
    >>> from lfproc.synth import synthesize
    >>> truth = synthesize("window", size=(24, 24), views=3, random_state=0)
    >>> evaluate(truth, truth)["pu21_psnr_db"], evaluate(truth, truth)["angular_shape"]
    (inf, [3, 3])
    >>> r = evaluate(truth.replace(data=2 * truth.data), truth, align="gain")  # a gain is fitted
    >>> r["pu21_psnr_db"], round(r["gain"], 6)
    (inf, 0.5)
    """
    result, alignment = align_result(result, reference, align)
    _check_lightfields(result, reference, scale_tolerance_stops)
    check_choice("variant", variant, PU21_VARIANTS)
    epsilon_relative = check_positive("epsilon_relative", epsilon_relative)
    if peak_luminance is None and reference.units != "cd/m2":
        raise InputError(
            f"evaluate: peak_luminance=None needs absolute luminance (units 'cd/m2'), the data are in "
            f"{reference.units!r}; give a display peak in cd/m^2"
        )
    nv, nu, h, w, _ = reference.shape
    if min(h, w) < _SSIM_MIN_SIZE:
        raise ShapeError(
            f"evaluate: views must be at least {_SSIM_MIN_SIZE}x{_SSIM_MIN_SIZE} pixels for SSIM, got {h}x{w}"
        )
    keep = evaluation_mask(reference, mask=mask, exclude_above=exclude_above)
    hdr = hdr_figures(result, reference, noise_floor=noise_floor, mask=keep, peak_luminance=peak_luminance)
    hdr.pop("scale_factor")
    factor = _scale_factor(reference.data, peak_luminance)
    display_peak = float(reference.data.max()) * factor
    figures, peaks = _luminance_figures(result, reference, keep, factor=factor, display_peak=display_peak,
                                        variant=variant)
    colour, lin_peak = _colour_figures(result, reference, keep, epsilon_relative=epsilon_relative)
    figures |= colour
    pu2_peak, log_peak = peaks
    views = [{"v": v, "u": u} | {k: float(a[v, u]) for k, a in figures.items()} for v in range(nv) for u in range(nu)]
    out: dict[str, Any] = {k: float(np.mean(a) if keep is None else _nanmean(a)) for k, a in figures.items()}
    out |= {
        "views": views,
        "peak_luminance_cd_m2": display_peak,
        "scale_factor": factor,
        "pu21_variant": variant,
        "pu21_psnr_peak": PU21_PSNR_PEAK,
        "pu2_psnr_peak": pu2_peak,
        "log_psnr_peak": log_peak,
        "linear_psnr_peak": lin_peak,
        "epsilon_relative": epsilon_relative,
        "angular_shape": [nv, nu],
        "size": [h, w],
        "channels": reference.channels,
        "units": reference.units,
    } | alignment | hdr | {"exclude_above": None if exclude_above is None else float(exclude_above),
                            "masked": keep is not None}
    return out


def _nanmean(values: np.ndarray) -> float:
    """Mean of the non-nan values (views a mask leaves empty); nan when every one is nan."""
    finite = values[~np.isnan(values)]
    return float(np.mean(finite)) if finite.size else math.nan
