"""HDR quality metrics against a reference (PU21 PSNR/SSIM, log errors, evaluate; a stage).

The implementation is :mod:`lfproc.metrics._metrics`; this package was the module ``lfproc.metrics``,
whose other (private) names are still found here.
"""

from .._shared.deprecate import former_module_names
from . import _metrics
from ._metrics import (
    ALIGN_MODES, align_result, EMITTER_SHARE_DOMINATES, error_stops, evaluate, evaluation_mask, hdr_figures,
    log_luminance_error, log_psnr, mean_relative_error, metric_luminance, psnr, pu21_decode, pu21_encode, PU21_L_MAX,
    PU21_L_MIN, PU21_LUMA, PU21_PARAMETERS, pu21_psnr, PU21_PSNR_PEAK, pu21_ssim, PU21_VARIANTS, pu2_encode,
    pu2_psnr,
)

__all__ = list(_metrics.__all__)  # the public names, listed once (tests/test_api_surface.py pins them)


# names of the former flat module lfproc.metrics that are not public
__getattr__ = former_module_names(_metrics, __name__)
