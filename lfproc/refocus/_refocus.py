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
    the views; else :class:`InputError` naming ``name``.

    Parameters
    ----------
    slopes : float or sequence of float
        Disparities in pixels per view step.
    lf : LightField
        The light field they will refocus (its views and size bound the shifts).
    name : str, default "slope"
        The parameter's name in messages (the CLI passes its option).

    Returns
    -------
    list of float
        The slopes.

    Raises
    ------
    InputError
        No slope, a non-finite or non-numeric one, or one that shifts the outer views by the
        views' size or more.

    Examples
    --------
    >>> import numpy as np
    >>> import lfproc
    >>> from lfproc.refocus import check_slopes
    >>> lf = lfproc.LightField(np.zeros((5, 5, 8, 8, 1)))
    >>> check_slopes([0, 1.5, -2], lf)
    [0.0, 1.5, -2.0]
    >>> check_slopes(4, lf)
    Traceback (most recent call last):
    ...
    lfproc.errors.InputError: slope: 4 pixels per view step shifts the outer views by 8 pixels, beyond the 8 x 8 views
    """
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

    Examples
    --------
    A fronto-parallel plane of disparity 1 (each view is the texture moved by one pixel per
    view step) is sharp at slope 1 and blurred at slope 0:

    >>> import numpy as np
    >>> import lfproc
    >>> from lfproc.refocus import refocus
    >>> texture = np.random.default_rng(0).random((24, 24, 1))
    >>> views = [[np.roll(texture, (v - 1, u - 1), axis=(0, 1)) for u in range(3)] for v in range(3)]
    >>> lf = lfproc.LightField(np.array(views))
    >>> sharp = refocus(lf, 1.0)
    >>> sharp.shape, bool(np.allclose(sharp[1:-1, 1:-1], texture[1:-1, 1:-1], atol=1e-6))
    ((24, 24, 1), True)
    >>> bool(refocus(lf, 0.0).std() < 0.5 * sharp.std())
    True
    """
    return focal_stack(lf, [slope])[0]


def focal_stack(lf: LightField, slopes: Sequence[float]) -> np.ndarray:
    """:func:`refocus` at each of ``slopes``: an array of shape ``(N, H, W, C)``, float32.

    Parameters
    ----------
    lf : LightField
        Any number of views.
    slopes : sequence of float
        Disparities of the planes in focus, pixels per view step (see :func:`check_slopes`).

    Returns
    -------
    ndarray of shape (N, H, W, C), float32
        One refocused image per slope, in the light field's units.

    Raises
    ------
    InputError
        ``lf`` is not a LightField, or a slope is refused by :func:`check_slopes`.

    Examples
    --------
    >>> import lfproc
    >>> from lfproc.refocus import focal_stack
    >>> from lfproc.synth import synthesize
    >>> lf = synthesize("layers", size=(32, 32), views=3, random_state=0)
    >>> stack = focal_stack(lf, [-1.0, 0.0, 1.0])
    >>> stack.shape, stack.dtype
    ((3, 32, 32, 3), dtype('float32'))
    """
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
