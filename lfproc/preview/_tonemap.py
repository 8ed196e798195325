"""Exposure and tone mapping for display-referred (8/16-bit) outputs of HDR light fields.

8/16-bit files hold values in [0, 1]; an HDR light field written there as is clips everything
above 1. :func:`display_transform` first scales by ``2 ** exposure_ev`` and then, optionally,
compresses the range with one of OpenCV's global tone mappers (``cv2.createTonemapReinhard``
with global light adaptation, ``light_adapt=0``; ``cv2.createTonemapDrago`` with its defaults;
Reinhard & Devlin 2005, Drago et al. 2003), gamma 1 (the sRGB encoding is applied by the writer). All views are tone mapped as
one mosaic, so they share the operator's global statistics (a point looks the same in every
view). :func:`clipped_fraction` counts what an 8/16-bit encoding would clip.
"""

from __future__ import annotations

import math

import numpy as np

from .._shared.validation import check_choice
from ..errors import InputError
from ..lightfield import LightField

__all__ = ["TONEMAPS", "display_transform", "clipped_fraction"]

TONEMAPS = ("none", "reinhard", "drago")


def clipped_fraction(lf: LightField) -> float:
    """Fraction of samples above 1 (clipped by an 8/16-bit encoding).

    Parameters
    ----------
    lf : LightField

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc import LightField
    >>> from lfproc.preview import clipped_fraction
    >>> data = np.full((1, 1, 2, 2, 3), 0.5, dtype=np.float32)
    >>> data[..., 0, 0, :] = 4.0  # one pixel of four over 1
    >>> clipped_fraction(LightField(data))
    0.25
    """
    return float(np.mean(lf.data > 1.0))


def display_transform(lf: LightField, *, exposure_ev: float = 0.0, tonemap: str = "none") -> LightField:
    """A new light field scaled by ``2 ** exposure_ev`` and tone mapped (see the module notes).

    ``tonemap="none"`` only scales. Tone-mapped output lies in [0, 1] (``saturation_level = 1``);
    the variance is dropped (it no longer applies), the disparity kept, and ``attrs["display"]``
    records the exposure and operator.

    Parameters
    ----------
    lf : LightField
    exposure_ev : float, default 0.0
        Exposure change in stops (finite).
    tonemap : {"none", "reinhard", "drago"}, default "none"
        Global operator (OpenCV's Reinhard with no light adaptation, or Drago), applied to all
        views together.

    Returns
    -------
    LightField

    Raises
    ------
    InputError
        Not a light field, a non-finite exposure, or a black light field to tone map.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc import LightField
    >>> from lfproc.preview import display_transform
    >>> lf = LightField(np.full((1, 1, 2, 2, 3), 0.25, dtype=np.float32))
    >>> out = display_transform(lf, exposure_ev=2)  # two stops brighter
    >>> float(out.data.max()), out.attrs["display"]["tonemap"]
    (1.0, 'none')
    >>> tm = display_transform(LightField(np.geomspace(0.01, 100, 12, dtype=np.float32).reshape(1, 1, 2, 2, 3)),
    ...                        tonemap="reinhard")
    >>> bool(tm.data.min() >= 0 and tm.data.max() <= 1), tm.saturation_level
    (True, 1.0)
    """
    check_choice("tonemap", tonemap, TONEMAPS)
    if not isinstance(lf, LightField):
        raise InputError(f"display_transform: expected a LightField, got {type(lf).__name__}")
    if not math.isfinite(exposure_ev):
        raise InputError(f"exposure_ev: expected a finite number, got {exposure_ev}")
    gain = np.float32(2.0 ** exposure_ev)
    data = lf.data * gain
    if tonemap != "none":
        import cv2

        v, u, h, w, c = data.shape
        mosaic = data.transpose(0, 2, 1, 3, 4).reshape(v * h, u * w, c)
        rgb = np.ascontiguousarray(np.repeat(mosaic, 3, axis=2) if c == 1 else mosaic, dtype=np.float32)
        if not rgb.max() > 0:
            raise InputError("tonemap: the light field is black")
        # Reinhard with light_adapt=0: adaptation to the global mean (a global, monotonic curve per
        # channel); OpenCV's default 1 adapts each pixel to its own grey and can invert the order
        op = (cv2.createTonemapReinhard(1.0, 0.0, 0.0, 0.0) if tonemap == "reinhard"
              else cv2.createTonemapDrago(1.0))
        level = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)  # a notice on multi-channel MatExpr
        try:
            out = op.process(np.ascontiguousarray(rgb[..., ::-1]))[..., ::-1]  # OpenCV works in BGR
        finally:
            cv2.utils.logging.setLogLevel(level)
        out = np.clip(np.nan_to_num(out, nan=0.0), 0, 1)
        if c == 1:
            out = out[..., :1]
        data = out.reshape(v, h, u, w, c).transpose(0, 2, 1, 3, 4)
    display = {"exposure_ev": float(exposure_ev), "tonemap": tonemap,
               "implementation": None if tonemap == "none" else ("OpenCV createTonemapReinhard(gamma=1, intensity=0, light_adapt=0, color_adapt=0)"
                                                        if tonemap == "reinhard" else "OpenCV createTonemapDrago(gamma=1)")}
    return lf.replace(
        data=np.ascontiguousarray(data, dtype=np.float32),
        variance=None if tonemap != "none" or lf.variance is None else lf.variance * gain * gain,
        saturation_level=1.0 if tonemap != "none" else (None if lf.saturation_level is None
                                                       else lf.saturation_level * float(gain)),
        attrs=dict(lf.attrs) | {"display": display},
    )
