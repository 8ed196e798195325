"""Refocusing a light field by shift-and-sum over its views (``lfproc refocus``).

As LFToolbox's ``LFFiltShiftSum`` (Dansereau): every view ``(v, u)`` is translated by
``slope`` pixels per view step towards the centre view and the views are averaged, so a
surface whose disparity equals ``slope`` lines up in every view and comes out sharp while the
rest blurs with its distance from that plane. Values stay linear (HDR in, HDR out).

Sign convention (the one of :class:`lfproc.LightField` and :mod:`lfproc.synth`): a surface of
disparity ``d`` is seen at ``(y + d dv, x + d du)`` in the view ``(dv, du)`` steps from the
centre; the refocused image at ``slope`` is::

    I_s(y, x) = sum_{v, u} w_vu(y, x) L_vu(y + s dv, x + s du) / sum_{v, u} w_vu(y, x)

with bilinear interpolation for fractional shifts and ``w_vu`` = 1 where the shifted view
covers the pixel, 0 where it falls outside (near the border fewer views are averaged, as
LFFiltShiftSum's weight channel does; the centre view always covers every pixel). So
``refocus(lf, lf.disparity)`` of a fronto-parallel plane is a noise-averaged copy of the
centre view. LFToolbox's ``Slope`` may have the opposite sign for its own view ordering.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import InputError
from ..lightfield import LightField

__all__ = ["refocus", "focal_stack", "check_slopes"]


def check_slopes(slopes, lf: LightField, *, name: str = "slope") -> list[float]:
    """Finite slopes whose largest shift (slope times the farthest view's offset) stays inside
    the views; else :class:`InputError` naming ``name``."""
    values = [slopes] if isinstance(slopes, (int, float, np.integer, np.floating)) else list(slopes)
    if not values:
        raise InputError(f"{name}: expected at least one slope (pixels per view step)")
    out = []
    nv, nu = lf.views
    cv, cu = lf.centre_index
    reach = max(cv, nv - 1 - cv, cu, nu - 1 - cu)
    h, w = lf.size
    for s in values:
        if isinstance(s, bool) or not isinstance(s, (int, float, np.integer, np.floating)) or not math.isfinite(s):
            raise InputError(f"{name}: expected finite numbers (pixels per view step), got {s!r}")
        if abs(s) * reach >= max(h, w):
            raise InputError(f"{name}: {s:g} pixels per view step shifts the outer views by {abs(s) * reach:g} "
                             f"pixels, beyond the {h} x {w} views")
        out.append(float(s))
    return out


def refocus(lf: LightField, slope: float) -> np.ndarray:
    """The image focused on the plane of disparity ``slope`` (module documentation).

    Parameters
    ----------
    lf : LightField
        Any number of views (a 1 x 1 light field returns its view).
    slope : float
        Disparity of the plane in focus, in pixels per view step (``lf.disparity``'s units).

    Returns
    -------
    ndarray of shape (H, W, C), float32
        Linear values in the light field's units; ``lf`` is not changed.

    Raises
    ------
    InputError
        A slope that is not a finite number, or that shifts the outer views beyond the image.
    """
    return focal_stack(lf, [slope])[0]


def focal_stack(lf: LightField, slopes: Sequence[float]) -> np.ndarray:
    """:func:`refocus` at each of ``slopes``: an array of shape ``(N, H, W, C)``, float32."""
    import cv2

    if not isinstance(lf, LightField):
        raise InputError(f"refocus: expected a LightField, got {type(lf).__name__}")
    slopes = check_slopes(slopes, lf)
    nv, nu, h, w, c = lf.shape
    cv_, cu = lf.centre_index
    out = np.empty((len(slopes), h, w, c), np.float32)
    ones = np.ones((h, w), np.float32)
    for k, s in enumerate(slopes):
        acc = np.zeros((h, w, c), np.float64)
        weight = np.zeros((h, w), np.float64)
        for v in range(nv):
            for u in range(nu):
                dy, dx = s * (v - cv_), s * (u - cu)
                view = lf.data[v, u]
                if dy == 0 and dx == 0:
                    acc += view
                    weight += 1.0
                    continue
                # dst(x, y) = src(x + dx, y + dy): the inverse map of a translation
                m = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]], np.float64)
                flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
                shifted = [cv2.warpAffine(np.ascontiguousarray(view[..., i]), m, (w, h), flags=flags,
                                          borderMode=cv2.BORDER_CONSTANT, borderValue=0.0) for i in range(c)]
                cover = cv2.warpAffine(ones, m, (w, h), flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
                acc += np.stack(shifted, axis=-1)
                weight += cover
        out[k] = (acc / np.maximum(weight, 1e-12)[..., None]).astype(np.float32)
    np.maximum(out, 0, out=out)  # bilinear weights are non-negative; guards float rounding only
    return out
