"""lfproc's own warnings about saturation and convergence, raised where the user's call is."""

from __future__ import annotations

import warnings

from ..errors import SATURATION_WARNING_FRACTION, ConvergenceWarning, SaturationWarning

__all__ = ["warn_saturation", "warn_convergence"]


def warn_saturation(fraction: float, what: str, *, consequence: str, samples: str = "samples",
                    stacklevel: int = 3) -> bool:
    """Emit :class:`SaturationWarning` when ``fraction`` exceeds :data:`SATURATION_WARNING_FRACTION`.

    ``what`` names the data ("capture", "exposure bracket"...), ``consequence`` says what it
    means for the result. Returns whether a warning was emitted.
    """
    if not fraction > SATURATION_WARNING_FRACTION:
        return False
    warnings.warn(
        f"{what}: {100 * fraction:.1f} % of the {samples} are saturated (more than "
        f"{100 * SATURATION_WARNING_FRACTION:g} %); {consequence}",
        SaturationWarning,
        stacklevel=stacklevel,
    )
    return True


def warn_convergence(message: str, *, stacklevel: int = 3) -> None:
    """Emit :class:`ConvergenceWarning` (an iterative estimate stopped before its tolerance)."""
    warnings.warn(message, ConvergenceWarning, stacklevel=stacklevel)
