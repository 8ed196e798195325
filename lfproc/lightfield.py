"""The light-field type: one float32 array ``(V, U, H, W, C)`` plus metadata.

Axes (used by every module of lfproc):

======  ==============================================================
``V``   angular row (top to bottom), view ``(V // 2, U // 2)`` is the centre
``U``   angular column (left to right)
``H``   pixel row
``W``   pixel column
``C``   colour channel (3 for RGB, 1 for luminance or a single channel)
======  ==============================================================

Values are linear and scene-referred. ``units`` says what they are:
``"relative"`` (linear, arbitrary scale), ``"e-/s"`` (photo-electrons per second,
the calibrated radiance of :mod:`lfproc.camera.sensor`), ``"cd/m2"`` (absolute luminance)
or ``"dn"`` (raw sensor counts).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from ._shared.frozen import ReadOnlyState, frozen_array
from .errors import InputError, ShapeError

__all__ = ["LightField", "UNITS", "luminance", "clean_nonfinite", "REC709_LUMA"]

UNITS = ("relative", "e-/s", "cd/m2", "dn")
#: Rec. 709 / sRGB luminance weights of linear R, G, B.
REC709_LUMA = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Luminance of linear RGB (last axis): Rec. 709 weights; one channel is returned as is.

    Parameters
    ----------
    rgb : ndarray of shape (..., C) with C in {1, 3}

    Returns
    -------
    ndarray of shape (...), float32 (accumulated in float64).
    """
    c = rgb.shape[-1]
    if c == 1:
        return rgb[..., 0]
    if c != 3:
        raise ShapeError(f"luminance: expected 1 or 3 colour channels, got {c}")
    return np.tensordot(rgb.astype(np.float64, copy=False), REC709_LUMA, axes=([-1], [0])).astype(np.float32)


def clean_nonfinite(
    array: np.ndarray,
    *,
    policy: Literal["raise", "zero", "clip"] = "raise",
    negative: Literal["raise", "clip", "keep"] = "raise",
    name: str = "array",
) -> tuple[np.ndarray, dict[str, int]]:
    """Apply lfproc's documented policy for NaN, Inf and negative values.

    ``policy``: ``"raise"`` refuses NaN/Inf; ``"zero"`` replaces them by 0; ``"clip"``
    replaces NaN and -Inf by 0 and +Inf by the largest finite value.
    ``negative``: ``"raise"`` refuses values < 0; ``"clip"`` sets them to 0 (lossy EXR
    compression leaves tiny negatives); ``"keep"`` leaves them.

    Returns a new array (the input is never modified) and counts of what was replaced.
    """
    counts = {"nan": 0, "inf": 0, "negative": 0}
    finite = np.isfinite(array)
    out = array
    if not finite.all():
        counts["nan"] = int(np.isnan(array).sum())
        counts["inf"] = int(array.size - finite.sum() - counts["nan"])
        if policy == "raise":
            raise InputError(
                f"{name}: contains {counts['nan']} NaN and {counts['inf']} Inf values; expected finite radiance "
                "(use nonfinite='zero' or 'clip', or --nonfinite on the command line)"
            )
        if policy not in ("zero", "clip"):
            raise InputError(f"nonfinite: expected one of raise, zero, clip; got {policy!r}")
        out = array.copy()
        top = float(array[finite].max()) if finite.any() else 0.0
        out[np.isnan(out)] = 0
        out[np.isneginf(out)] = 0
        out[np.isposinf(out)] = top if policy == "clip" else 0
    if negative not in ("raise", "clip", "keep"):
        raise InputError(f"negative: expected one of raise, clip, keep; got {negative!r}")
    neg = out < 0
    n_neg = int(neg.sum())
    counts["negative"] = n_neg
    if n_neg and negative == "raise":
        raise InputError(
            f"{name}: contains {n_neg} negative values (min {float(out.min()):.4g}); expected non-negative "
            "radiance (use negative='clip', or --negative clip on the command line)"
        )
    if n_neg and negative == "clip":
        out = np.where(neg, 0, out).astype(array.dtype, copy=False)
    return out, counts


@dataclass(frozen=True, eq=False)
class LightField(ReadOnlyState):
    """A light field: float32 ``data`` of shape ``(V, U, H, W, C)`` and its metadata.

    Construction validates shape, dtype and values: data are converted to float32,
    must be finite and non-negative (see :func:`clean_nonfinite` to clean raw data
    first). Instances are immutable: use :meth:`replace` to derive a new one. The arrays
    are read-only (writing into ``lf.data`` raises ``ValueError``), so a validated light
    field cannot be corrupted; the caller's array is copied once unless it is already
    read-only (:func:`lfproc._util.frozen_array`), and views such as :meth:`crop` share
    memory with their parent.

    Parameters
    ----------
    data : array_like of shape (V, U, H, W, C)
        Linear radiance.
    variance : array_like of shape (V, U, H, W, C), optional
        Per-sample variance of ``data`` (same units squared).
    disparity : array_like of shape (H, W), optional
        Disparity of the centre view in pixels per view step (positive: a point moves
        right as the angular column ``u`` increases).
    units : {"relative", "e-/s", "cd/m2", "dn"}
    colour_space : str
        ``"linear-srgb"`` (Rec. 709 primaries), ``"camera-rgb"``, ``"luminance"``...
    exposure_s, iso : float, optional
        Exposure time in seconds and ISO, when the light field comes from one capture.
    saturation_level : float, optional
        Value at or above which a sample is clipped (e.g. 1.0 for decoded 8-bit views).
    source : str, optional
        Where the data came from (a path, ``"synth:layers"``...).
    attrs : mapping
        Further JSON-serialisable metadata (kept through files).

    Raises
    ------
    lfproc.errors.ShapeError
        ``data`` is not a 5-axis numeric array, or ``variance``/``disparity`` do not match it.
    lfproc.errors.InputError
        NaN, Inf or negative values, unknown ``units``, or a non-positive ``exposure_s``,
        ``iso`` or ``saturation_level``.

    Examples
    --------
    >>> import numpy as np
    >>> import lfproc
    >>> data = np.arange(5 * 5 * 2 * 3 * 3, dtype=np.float32).reshape(5, 5, 2, 3, 3)
    >>> lf = lfproc.LightField(data, units="e-/s")
    >>> lf.views, lf.size, lf.channels, lf.centre_index
    ((5, 5), (2, 3), 3, (2, 2))
    >>> centre = lf.centre()        # an (H, W, C) read-only array, not a LightField
    >>> centre.shape, bool(np.array_equal(centre, data[2, 2])), centre.flags.writeable
    ((2, 3, 3), True, False)
    >>> lf.central(3).views, lf.crop(0, 1, 2, 2).size
    ((3, 3), (2, 2))
    >>> lf.replace(units="relative").units
    'relative'
    """

    data: np.ndarray
    variance: np.ndarray | None = None
    disparity: np.ndarray | None = None
    units: str = "relative"
    colour_space: str = "linear-srgb"
    exposure_s: float | None = None
    iso: float | None = None
    saturation_level: float | None = None
    source: str | None = None
    attrs: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        data = np.asarray(self.data)
        if data.ndim != 5:
            raise ShapeError(
                f"light field: expected an array of shape (V, U, H, W, C) with 5 axes, got shape {data.shape}"
            )
        if not np.issubdtype(data.dtype, np.floating) and not np.issubdtype(data.dtype, np.integer):
            raise ShapeError(f"light field: expected a numeric array, got dtype {data.dtype}")
        if min(data.shape) < 1:
            raise ShapeError(f"light field: every axis needs at least one element, got shape {data.shape}")
        data = frozen_array(self.data, dtype=np.float32)
        clean_nonfinite(data, policy="raise", negative="raise", name="light field data")
        object.__setattr__(self, "data", data)
        if self.variance is not None:
            var = frozen_array(self.variance, dtype=np.float32)
            if var.shape != data.shape:
                raise ShapeError(f"light field variance: expected shape {data.shape}, got {var.shape}")
            clean_nonfinite(var, policy="raise", negative="raise", name="light field variance")
            object.__setattr__(self, "variance", var)
        if self.disparity is not None:
            disp = frozen_array(self.disparity, dtype=np.float32)
            if disp.shape != data.shape[2:4]:
                raise ShapeError(f"light field disparity: expected shape {data.shape[2:4]}, got {disp.shape}")
            if not np.isfinite(disp).all():
                raise InputError("light field disparity: contains NaN or Inf values")
            object.__setattr__(self, "disparity", disp)
        if self.units not in UNITS:
            raise InputError(f"light field units: expected one of {', '.join(UNITS)}; got {self.units!r}")
        for name in ("exposure_s", "iso", "saturation_level"):
            value = getattr(self, name)
            if value is not None:
                value = float(value)
                if not (np.isfinite(value) and value > 0):
                    raise InputError(f"light field {name}: expected a positive number, got {value}")
                object.__setattr__(self, name, value)
        object.__setattr__(self, "attrs", dict(self.attrs))

    # -- shape --------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int, int, int]:
        """``(V, U, H, W, C)``."""
        return self.data.shape  # type: ignore[return-value]

    @property
    def views(self) -> tuple[int, int]:
        """Angular shape ``(V, U)``."""
        return self.data.shape[0], self.data.shape[1]

    @property
    def size(self) -> tuple[int, int]:
        """Spatial shape ``(H, W)``."""
        return self.data.shape[2], self.data.shape[3]

    @property
    def channels(self) -> int:
        return self.data.shape[4]

    @property
    def centre_index(self) -> tuple[int, int]:
        """Index ``(v, u)`` of the centre view."""
        return self.data.shape[0] // 2, self.data.shape[1] // 2

    def __repr__(self) -> str:
        v, u, h, w, c = self.shape
        return (
            f"LightField(views={v}x{u}, size={h}x{w}, channels={c}, units={self.units!r}, "
            f"colour_space={self.colour_space!r}, range=[{self.data.min():.4g}, {self.data.max():.4g}])"
        )

    def replace(self, **changes) -> "LightField":
        """A new light field with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    # -- views and slices -----------------------------------------------------------
    def view(self, v: int, u: int) -> np.ndarray:
        """View ``(v, u)`` as a read-only ``(H, W, C)`` float32 array (negative indices allowed).

        An array, not a :class:`LightField`: index it directly (``lf.view(0, 0)[y, x]``).
        Its ``.data`` attribute is numpy's raw memory buffer, not the values (indexing that
        buffer with two indices raises ``NotImplementedError``). For a light field of views
        use :meth:`crop` or :meth:`central`.
        """
        nv, nu = self.views
        if not (-nv <= v < nv and -nu <= u < nu):
            raise InputError(f"view index: expected v in [0, {nv}) and u in [0, {nu}), got ({v}, {u})")
        return self.data[v, u]

    def centre(self) -> np.ndarray:
        """The centre view as a read-only ``(H, W, C)`` array (see :meth:`view`):
        ``lf.centre()[y, x]`` is a pixel; ``lf.central(1)`` is the centre view as a light field."""
        return self.view(*self.centre_index)

    def crop(self, top: int, left: int, height: int, width: int) -> "LightField":
        """Spatial crop of every view (variance and disparity cropped alike)."""
        h, w = self.size
        if not (0 <= top and 0 <= left and height > 0 and width > 0 and top + height <= h and left + width <= w):
            raise InputError(
                f"crop: rectangle top={top} left={left} height={height} width={width} does not fit in {h}x{w} views"
            )
        sl = (slice(None), slice(None), slice(top, top + height), slice(left, left + width))
        return self.replace(
            data=self.data[sl],
            variance=None if self.variance is None else self.variance[sl],
            disparity=None if self.disparity is None else self.disparity[top : top + height, left : left + width],
        )

    def central(self, n: int) -> "LightField":
        """The central ``n x n`` views (same centre view)."""
        nv, nu = self.views
        if n < 1 or n > min(nv, nu):
            raise InputError(f"central views: expected 1 <= n <= {min(nv, nu)}, got {n}")
        cv, cu = self.centre_index
        v0, u0 = cv - n // 2, cu - n // 2
        sl = (slice(v0, v0 + n), slice(u0, u0 + n))
        return self.replace(data=self.data[sl], variance=None if self.variance is None else self.variance[sl])

    def epi(self, *, axis: Literal["horizontal", "vertical"] = "horizontal", index: int | None = None) -> np.ndarray:
        """Epipolar-plane image through the centre view.

        ``axis="horizontal"``: pixel row ``index`` (default: middle row) of the views of
        the centre angular row, an array ``(U, W, C)``. ``"vertical"``: pixel column
        ``index`` of the views of the centre angular column, ``(V, H, C)``.
        """
        cv, cu = self.centre_index
        h, w = self.size
        if axis == "horizontal":
            index = h // 2 if index is None else index
            if not 0 <= index < h:
                raise InputError(f"epi index: expected a pixel row in [0, {h}), got {index}")
            return self.data[cv, :, index, :, :]
        if axis == "vertical":
            index = w // 2 if index is None else index
            if not 0 <= index < w:
                raise InputError(f"epi index: expected a pixel column in [0, {w}), got {index}")
            return self.data[:, cu, :, index, :]
        raise InputError(f"epi axis: expected 'horizontal' or 'vertical', got {axis!r}")

    # -- statistics -----------------------------------------------------------------
    def luminance(self) -> np.ndarray:
        """Luminance ``(V, U, H, W)`` (Rec. 709 weights for RGB)."""
        return luminance(self.data)

    def dynamic_range_stops(self, *, low_percentile: float = 0.1, high_percentile: float = 99.9) -> float:
        """Robust dynamic range: ``log2(P_high / P_low)`` of the positive luminances.

        Percentiles (not min/max) keep single hot or dark pixels from deciding the
        figure. Returns 0.0 for a light field with no positive luminance.
        """
        lum = self.luminance().ravel()
        lum = lum[lum > 0]
        if lum.size == 0:
            return 0.0
        lo, hi = np.percentile(lum, [low_percentile, high_percentile])
        return float(np.log2(hi / lo)) if lo > 0 else 0.0

    def saturated_fraction(self, level: float | None = None) -> float | None:
        """Fraction of samples at or above ``level`` (default: :attr:`saturation_level`).

        Returns ``None`` when neither is known: lfproc does not guess a clipping level.
        """
        level = self.saturation_level if level is None else level
        if level is None:
            return None
        return float(np.mean(self.data >= level * (1 - 1e-6)))
