"""HDR quality metrics against a reference (PU21 PSNR/SSIM, log errors, evaluate; a stage).

The implementation is :mod:`lfproc.metrics._metrics`; this package was the module ``lfproc.metrics``,
whose other (private) names are still found here.
"""

from . import _metrics
from ._metrics import (
    ALIGN_MODES, align_result, EMITTER_SHARE_DOMINATES, error_stops, evaluate, evaluation_mask, hdr_figures,
    log_luminance_error, log_psnr, mean_relative_error, metric_luminance, psnr, pu21_decode, pu21_encode, PU21_L_MAX,
    PU21_L_MIN, PU21_LUMA, PU21_PARAMETERS, pu21_psnr, PU21_PSNR_PEAK, pu21_ssim, PU21_VARIANTS, pu2_encode,
    pu2_psnr,
)

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
    "evaluation_mask",
    "error_stops",
    "evaluate",
]


def __getattr__(name):  # names of the former flat module lfproc.metrics that are not public
    try:
        return getattr(_metrics, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
