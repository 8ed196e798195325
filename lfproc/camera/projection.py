"""The projection operator ``Phi`` of the coded-mask camera.

The camera model of Miandji, Nguyen, Hajisharif, Unger and Guillemot, "Compressive HDR light
field imaging using a single multi-ISO sensor", IEEE TCI 2021, section III-A.

One shot ``s`` maps a light field ``L`` of shape ``(V, U, H, W, C)`` to one sensor image:

``y_s(p) = sum over views (v, u) of  M_s(v, u, p, c(p)) * L(v, u, p, c(p))``

where ``c(p)`` is the colour of the Bayer CFA at pixel ``p`` and ``M_s`` is the mask
transmittance (in [0, 1]) of shot ``s``. ``Phi`` stacks the shots: it maps
``(V, U, H, W, C)`` to ``(S, H, W)``. It is applied through its *weights*
``A[s, v, u, y, x] = M_s(v, u, y, x, c(y, x))`` (the mask seen through the CFA) and the CFA
colour map ``c``; it is never a dense matrix.

Mask models (:class:`MaskCode`):

``random``
    i.i.d. transmittance (uniform in [0, 1]) per pixel, view, colour and shot (the paper's
    model). Codes of shape ``(S, V, U, Ph, Pw, C)``; ``(Ph, Pw)`` is the tiling period, or
    the full sensor size when the mask is not periodic.
``shifted``
    one 2-D colour mask per shot, at a distance from the sensor, so each view sees it
    shifted by ``shift`` pixels per angular step: view ``(v, u)`` at pixel ``(y, x)`` sees
    ``base[s, y + shift * v, x + shift * u, c]``. Codes of shape ``(S, Bh, Bw, C)``: with a
    period ``P`` the base is ``P x P`` and indices wrap modulo ``P``; without, the base is
    ``(H + shift (V - 1), W + shift (U - 1))``.

Patch vectorisation (used by :meth:`ProjectionOperator.patch_matrix` and the
reconstruction): a patch of ``size x size`` pixels at ``(top, left)`` has

* measurement index ``row = (s * size + i) * size + j`` (C order of ``(S, size, size)``),
* unknown index ``col = (((v * U + u) * size + i) * size + j) * C + c`` (C order of
  ``(V, U, size, size, C)``, i.e. ``L[:, :, top:top+size, left:left+size, :].reshape(-1)``).

Sampling rate: ``S / (C V U)`` measurements per unknown (1.33 % for one shot of 5 x 5
RGB views, 2.67 % for two).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._shared.frozen import ReadOnlyState, freeze, frozen_array
from .._shared.validation import check_choice
from .._shared.random import check_random_state
from .._shared.reprs import short_repr
from .._shared.patches import patch_grid
from ..errors import InputError, ShapeError

__all__ = [
    "MASK_KINDS",
    "MASK_TRANSMITTANCES",
    "MIXED_SHARES",
    "CFA_PATTERNS",
    "MaskCode",
    "ProjectionOperator",
    "make_mask",
    "MASK_LEVELS",
    "encode_levels",
    "decode_levels",
    "cfa_index_map",
    "build_operator",
    "sampling_rate",
    "PatchOperators",
    "patch_operators",
    "patch_grid",
    "transmittance_map",
]

MASK_KINDS = ("random", "shifted")
#: Distributions of a mask's transmittances (:func:`make_mask`): uniform over the levels, 0 / 1 (binary), or mixed:
#: 1, 0 or a small level (below 1/4) with probabilities MIXED_SHARES.
MASK_TRANSMITTANCES = ("uniform", "binary", "mixed")
#: Shares of the codes 1, 0 and a level drawn uniformly from 0 .. 63 / 255 in a ``"mixed"`` mask (mean 0.4997).
MIXED_SHARES = (0.475, 0.325, 0.2)
CFA_PATTERNS = ("RGGB", "GRBG", "GBRG", "BGGR")
#: Number of transmittance levels of the masks :func:`make_mask` draws.
MASK_LEVELS = 256
_COLOUR_INDEX = {"R": 0, "G": 1, "B": 2}


def sampling_rate(*, shots: int, views: tuple[int, int], channels: int = 3) -> float:
    """Measurements per unknown: ``shots / (channels * V * U)`` (a fraction, not percent)."""
    return shots / (channels * views[0] * views[1])


def cfa_index_map(pattern: str, size: tuple[int, int], *, offset: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Colour index (0 = R, 1 = G, 2 = B) of every pixel of a Bayer sensor.

    Parameters
    ----------
    pattern : str
        Row-major 2 x 2 layout from the top-left pixel, one of ``RGGB, GRBG, GBRG, BGGR``.
    size : (H, W)
    offset : (row, column) of the top-left pixel of the returned window on the sensor.

    Returns
    -------
    ndarray of shape (H, W), int8
    """
    if str(pattern).lower() == "mono":
        raise InputError("cfa_pattern: the camera profile is monochrome ('mono'); the coded-mask camera simulates a "
                         f"Bayer colour sensor: use a colour profile or give one of {', '.join(CFA_PATTERNS)}")
    pattern = check_choice("cfa_pattern", str(pattern).upper(), CFA_PATTERNS)
    tile = np.array([_COLOUR_INDEX[ch] for ch in pattern], dtype=np.int8).reshape(2, 2)
    rows = (np.arange(size[0]) + offset[0]) % 2
    cols = (np.arange(size[1]) + offset[1]) % 2
    return tile[rows[:, None], cols[None, :]]


def _as_int(value, name: str, *, low: int) -> int:
    """An integer option (integral floats such as 4.0 accepted) >= ``low``, else InputError."""
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    if ok and np.isfinite(value) and int(value) == value and int(value) >= low:
        return int(value)
    raise InputError(f"{name}: expected an integer >= {low}, got {value!r}")


def _pair(value, name: str) -> tuple[int, int]:
    """Two positive integers (views or a size), else InputError: a zero-sized view has no pixels."""
    try:
        a, b = value
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected two integers >= 1, got {value!r}") from None
    try:
        return _as_int(a, name, low=1), _as_int(b, name, low=1)
    except InputError:
        raise InputError(f"{name}: expected two integers >= 1, got {tuple(value)!r}") from None


def check_transmittances(values: np.ndarray, name: str) -> None:
    """Raise :class:`InputError` unless every value is a finite transmittance in [0, 1]."""
    values = np.asarray(values)
    bad_nan = int(np.count_nonzero(~np.isfinite(values)))
    if bad_nan:
        raise InputError(f"{name}: expected finite transmittances in [0, 1], found {bad_nan} NaN or Inf values")
    lo, hi = float(values.min(initial=0)), float(values.max(initial=0))
    if lo < 0 or hi > 1:
        n = int(np.count_nonzero((values < 0) | (values > 1)))
        raise InputError(f"{name}: expected transmittances in [0, 1], found {n} values outside (range [{lo:.4g}, {hi:.4g}])")


@short_repr
@dataclass(frozen=True, eq=False)
class MaskCode(ReadOnlyState):
    """The mask codes of all shots (see the module documentation for the layouts).

    Parameters
    ----------
    kind : {"random", "shifted"}
    codes : ndarray
        ``(S, V, U, Ph, Pw, C)`` for ``random``; ``(S, Bh, Bw, C)`` for ``shifted``;
        transmittances in [0, 1], float32.
    period : int or None
        Tiling period in pixels (the codes hold one tile), or None (codes cover the sensor).
    shift : int
        Pixels of mask shift per angular step (``shifted`` only).
    """

    kind: str
    codes: np.ndarray
    period: int | None = None
    shift: int = 1

    def __post_init__(self):
        check_choice("mask kind", self.kind, MASK_KINDS)
        codes = np.asarray(self.codes)
        if not (np.issubdtype(codes.dtype, np.floating) or np.issubdtype(codes.dtype, np.integer)
                or codes.dtype == bool):
            raise ShapeError(f"mask codes: expected numeric transmittances, got dtype {codes.dtype}")
        codes = frozen_array(self.codes, dtype=np.float32)
        want = 6 if self.kind == "random" else 4
        if codes.ndim != want:
            raise ShapeError(f"mask codes ({self.kind}): expected {want} dimensions, got shape {codes.shape}")
        if codes.size == 0:
            raise ShapeError(f"mask codes ({self.kind}): every axis needs at least one element, got shape {codes.shape}")
        check_transmittances(codes, "mask codes")
        if self.period is not None:
            p = _as_int(self.period, "mask period", low=1)
            if codes.shape[-3:-1] != (p, p):
                raise ShapeError(f"mask codes: a period of {p} needs {p} x {p} tiles, got {codes.shape[-3:-1]}")
            object.__setattr__(self, "period", p)
        object.__setattr__(self, "shift", _as_int(self.shift, "mask shift", low=0))
        object.__setattr__(self, "codes", codes)

    @property
    def shots(self) -> int:
        return int(self.codes.shape[0])

    @property
    def channels(self) -> int:
        return int(self.codes.shape[-1])

    def expand(self, *, views: tuple[int, int], size: tuple[int, int], cfa_index: np.ndarray | None = None) -> np.ndarray:
        """Transmittance of every shot, view, pixel and colour: ``(S, V, U, H, W, C)`` float32.

        With ``cfa_index`` (``(H, W)`` colour indices) only each pixel's CFA colour is kept:
        ``(S, V, U, H, W)``, without building the full array.
        """
        nv, nu = views
        h, w = size
        if cfa_index is not None:
            cfa_index = np.asarray(cfa_index, dtype=np.intp)
            if cfa_index.shape != (h, w):
                raise ShapeError(f"cfa_index: expected shape {(h, w)}, got {cfa_index.shape}")
        colour = slice(None) if cfa_index is None else cfa_index
        self.check(views=views, size=size)
        if self.kind == "random":
            rows = np.arange(h) if self.period is None else np.arange(h) % self.period
            cols = np.arange(w) if self.period is None else np.arange(w) % self.period
            if cfa_index is None:
                return self.codes[:, :, :, rows[:, None], cols[None, :], :]
            return self.codes[:, :, :, rows[:, None], cols[None, :], colour]
        # shifted: view (v, u) sees base[y + shift v, x + shift u]
        sh = int(self.shift)
        rows = np.arange(nv)[:, None] * sh + np.arange(h)[None, :]  # (V, H)
        cols = np.arange(nu)[:, None] * sh + np.arange(w)[None, :]  # (U, W)
        if self.period is not None:
            rows, cols = rows % self.period, cols % self.period
        r = rows[:, None, :, None]
        c = cols[None, :, None, :]
        if cfa_index is None:
            return self.codes[:, r, c, :]
        return self.codes[:, r, c, colour[None, None]]

    def check(self, *, views: tuple[int, int], size: tuple[int, int]) -> None:
        """Raise :class:`ShapeError` unless the codes fit ``views`` of ``size`` pixels."""
        nv, nu = views
        h, w = size
        if self.kind == "random":
            if self.codes.shape[1:3] != (nv, nu):
                raise ShapeError(f"random mask: codes are for {self.codes.shape[1:3]} views, the light field has {tuple(views)}")
            if self.period is None and self.codes.shape[3:5] != (h, w):
                raise ShapeError(f"random mask: codes cover {self.codes.shape[3:5]} pixels, the sensor is {tuple(size)}")
        elif self.period is None:
            bh, bw = self.codes.shape[1:3]
            need = (h + self.shift * (nv - 1), w + self.shift * (nu - 1))
            if bh < need[0] or bw < need[1]:
                raise ShapeError(
                    f"shifted mask: base of {bh} x {bw} is too small for {tuple(views)} views of {tuple(size)} "
                    f"with shift {self.shift}; expected at least {need[0]} x {need[1]}"
                )

    def to_json(self) -> dict:
        return {"kind": self.kind, "period": self.period, "shift": int(self.shift), "codes_shape": list(self.codes.shape)}


def make_mask(
    kind: str = "random",
    *,
    shots: int,
    views: tuple[int, int],
    size: tuple[int, int],
    channels: int = 3,
    period: int | None = None,
    shift: int = 1,
    random_state=None,
    transmittance: str = "uniform",
) -> MaskCode:
    """Draw mask codes for ``shots`` shots (each its own code), transmittances i.i.d. with mean 1/2.

    Transmittances take the 256 levels ``k / 255`` (a printed mask has finitely many
    levels), so capture files store them exactly as 8-bit codes (:func:`encode_levels`):
    ``transmittance="uniform"`` draws every level with the same probability (the paper's model),
    ``"binary"`` draws 0 or 1 with probability 1/2 each (a chrome-on-glass mask), ``"mixed"`` 1, 0
    or a small level (``k / 255``, ``k < 64``) with the probabilities :data:`MIXED_SHARES`. All pass
    half the light on average; the code's variance (1/12 uniform, 1/4 binary, 0.23 mixed) is the
    part of a pixel's coded sum over the views that tells neighbouring pixels apart (at a disparity
    other than 0 each sum mixes ``V x U`` pixels; the mean code only blurs them), and the small
    levels let a light of a few pixels be seen unsaturated (binary codes have none).

    Parameters
    ----------
    kind : {"random", "shifted"}
    shots : int (>= 1)
    views : (V, U)
    size : (H, W) sensor size in pixels
    channels : int
    period : int, optional
        Tile the mask with this period (pixels); None: no repetition.
    shift : int
        Mask shift per angular step for ``shifted``.
    random_state : int, Generator or None
    transmittance : {"uniform", "binary", "mixed"}, default "uniform"
        The transmittances' distribution (:data:`MASK_TRANSMITTANCES`).

    Returns
    -------
    MaskCode

    Examples
    --------
    >>> from lfproc.camera import make_mask
    >>> m = make_mask(shots=1, views=(5, 5), size=(8, 8), period=4, transmittance="binary", random_state=0)
    >>> sorted(set(m.codes.ravel().tolist()))
    [0.0, 1.0]
    """
    check_choice("mask", kind, MASK_KINDS)
    check_choice("mask transmittance", transmittance, MASK_TRANSMITTANCES)
    shots = _as_int(shots, "shots", low=1)
    nv, nu = _pair(views, "mask views (V, U)")
    size = _pair(size, "mask size (H, W)")
    channels = _as_int(channels, "mask channels", low=1)
    period = None if period is None else _as_int(period, "mask period", low=1)
    shift = _as_int(shift, "mask shift", low=0)
    rng = check_random_state(random_state)
    if kind == "random":
        tile = (period, period) if period is not None else tuple(size)
        shape = (shots, nv, nu, *tile, channels)
    else:
        if period is not None:
            base = (period, period)
        else:
            base = (size[0] + shift * (nv - 1), size[1] + shift * (nu - 1))
        shape = (shots, *base, channels)
    if transmittance == "binary":
        levels = rng.integers(0, 2, shape, dtype=np.uint8) * np.uint8(MASK_LEVELS - 1)
    elif transmittance == "mixed":
        u = rng.random(shape)
        small = rng.integers(0, MASK_LEVELS // 4, shape, dtype=np.uint8)
        levels = np.where(u < MIXED_SHARES[0], np.uint8(MASK_LEVELS - 1),
                          np.where(u < MIXED_SHARES[0] + MIXED_SHARES[1], np.uint8(0), small)).astype(np.uint8)
    else:
        levels = rng.integers(0, MASK_LEVELS, shape, dtype=np.uint8)
    codes = decode_levels(levels)
    return MaskCode(kind=kind, codes=freeze(codes), period=period, shift=shift)


def decode_levels(levels: np.ndarray) -> np.ndarray:
    """8-bit mask levels -> transmittances ``k / 255`` (float32)."""
    return np.asarray(levels, dtype=np.uint8).astype(np.float32) / np.float32(MASK_LEVELS - 1)


def encode_levels(codes: np.ndarray) -> np.ndarray | None:
    """Transmittances -> 8-bit levels when every code is exactly ``k / 255``; else None."""
    levels = np.rint(np.asarray(codes, dtype=np.float32) * np.float32(MASK_LEVELS - 1))
    levels = np.clip(levels, 0, MASK_LEVELS - 1).astype(np.uint8)
    return levels if np.array_equal(decode_levels(levels), codes) else None


class ProjectionOperator:
    """The linear map ``Phi``: light field ``(V, U, H, W, C)`` -> sensor images ``(S, H, W)``.

    Parameters
    ----------
    weights : ndarray of shape (S, V, U, H, W)
        Transmittance of the mask at each pixel's CFA colour (``A`` in the module notes).
    cfa_index : ndarray of shape (H, W)
        Colour index of each pixel (0..C-1).
    channels : int
        Number of colours ``C`` of the light field.
    period : (int, int) or None
        Spatial period of the operator (mask and CFA together), when it has one.
    offset : (int, int)
        Position of this operator's top-left pixel on the full sensor (for restrictions).

    Notes
    -----
    Use :func:`build_operator` to make one from a :class:`MaskCode` and a CFA pattern.
    The operator is immutable and its arrays are read-only (weights are checked to be
    finite transmittances in [0, 1]); :meth:`restrict` shares memory with its parent.
    """

    def __init__(self, weights, cfa_index, *, channels: int = 3, period=None, offset=(0, 0)):
        weights = np.asarray(weights)
        if not (np.issubdtype(weights.dtype, np.floating) or np.issubdtype(weights.dtype, np.integer)
                or weights.dtype == bool):
            raise ShapeError(f"projection weights: expected numeric transmittances, got dtype {weights.dtype}")
        if weights.ndim != 5:
            raise ShapeError(f"projection weights: expected shape (S, V, U, H, W), got {weights.shape}")
        if weights.size == 0:
            raise ShapeError(f"projection weights: every axis needs at least one element, got shape {weights.shape}")
        weights = frozen_array(weights, dtype=weights.dtype if weights.dtype in (np.float32, np.float64) else np.float32)
        check_transmittances(weights, "projection weights")
        channels = _as_int(channels, "channels", low=1)
        cfa_index = np.asarray(cfa_index)
        if cfa_index.shape != weights.shape[3:]:
            raise ShapeError(f"cfa_index: expected shape {weights.shape[3:]}, got {cfa_index.shape}")
        if not np.issubdtype(cfa_index.dtype, np.integer):
            raise InputError(f"cfa_index: expected integer colour indices, got dtype {cfa_index.dtype}")
        if cfa_index.min() < 0 or cfa_index.max() >= channels:
            raise InputError(f"cfa_index: expected colour indices in 0..{channels - 1}")
        init = object.__setattr__
        init(self, "weights", weights)
        init(self, "cfa_index", frozen_array(cfa_index, dtype=np.intp))
        init(self, "channels", channels)
        init(self, "period", None if period is None else (_as_int(period[0], "period", low=1),
                                                          _as_int(period[1], "period", low=1)))
        init(self, "offset", (int(offset[0]), int(offset[1])))
        init(self, "_onehot", None)

    def __setattr__(self, name, value):
        raise AttributeError(f"ProjectionOperator is immutable (cannot set {name!r}); build a new operator")

    def __delattr__(self, name):
        raise AttributeError(f"ProjectionOperator is immutable (cannot delete {name!r})")

    def __setstate__(self, state):
        ReadOnlyState.__setstate__(self, state)

    # -- shapes ------------------------------------------------------------------------
    @property
    def shots(self) -> int:
        return self.weights.shape[0]

    @property
    def views(self) -> tuple[int, int]:
        return self.weights.shape[1], self.weights.shape[2]

    @property
    def size(self) -> tuple[int, int]:
        return self.weights.shape[3], self.weights.shape[4]

    @property
    def in_shape(self) -> tuple[int, int, int, int, int]:
        return (*self.views, *self.size, self.channels)

    @property
    def out_shape(self) -> tuple[int, int, int]:
        return (self.shots, *self.size)

    @property
    def shape(self) -> tuple[int, int]:
        """``(m, n)`` of the matrix ``Phi``."""
        return math.prod(self.out_shape), math.prod(self.in_shape)

    @property
    def sampling_rate(self) -> float:
        """``S / (C V U)`` (a fraction; multiply by 100 for percent)."""
        return sampling_rate(shots=self.shots, views=self.views, channels=self.channels)

    def __repr__(self) -> str:
        return (f"ProjectionOperator(shots={self.shots}, views={self.views}, size={self.size}, "
                f"channels={self.channels}, period={self.period}, offset={self.offset})")

    # -- application -------------------------------------------------------------------
    def _onehot_map(self, dtype) -> np.ndarray:
        if self._onehot is None:  # a cache, not state: (H, W, C)
            object.__setattr__(self, "_onehot", freeze(np.eye(self.channels, dtype=np.float32)[self.cfa_index]))
        return self._onehot.astype(dtype, copy=False)

    def forward(self, lf: np.ndarray) -> np.ndarray:
        """``Phi L``: sensor images ``(S, H, W)`` (noise-free, in the units of ``lf``).

        Parameters
        ----------
        lf : ndarray of shape (V, U, H, W, C)

        Returns
        -------
        ndarray of shape (S, H, W); float64 for float64 input, else float32
        """
        lf = np.asarray(lf)
        if lf.shape != self.in_shape:
            raise ShapeError(f"forward: expected a light field of shape {self.in_shape}, got {lf.shape}")
        dtype = np.result_type(lf.dtype, np.float32)
        # each pixel's CFA colour, (V, U, H, W), without a broadcast index array
        sel = np.einsum("vuhwc,hwc->vuhw", lf.astype(dtype, copy=False), self._onehot_map(dtype))
        return np.einsum("svuhw,vuhw->shw", self.weights.astype(dtype, copy=False), sel)

    def adjoint(self, y: np.ndarray) -> np.ndarray:
        """``Phi^T y``: light field ``(V, U, H, W, C)`` from sensor images ``(S, H, W)``."""
        y = np.asarray(y)
        if y.shape != self.out_shape:
            raise ShapeError(f"adjoint: expected sensor images of shape {self.out_shape}, got {y.shape}")
        dtype = np.result_type(y.dtype, np.float32)
        z = np.einsum("svuhw,shw->vuhw", self.weights.astype(dtype, copy=False), y.astype(dtype, copy=False))
        return z[..., None] * self._onehot_map(dtype)

    def normal_diagonal(self) -> np.ndarray:
        """Diagonal of ``Phi^T Phi`` as a light field ``(V, U, H, W, C)`` (useful for preconditioning)."""
        z = np.einsum("svuhw,svuhw->vuhw", self.weights, self.weights)
        return z[..., None] * self._onehot_map(self.weights.dtype)

    def as_linear_operator(self):
        """A :class:`scipy.sparse.linalg.LinearOperator` on flattened (C-order) vectors, float64."""
        from scipy.sparse.linalg import LinearOperator

        def matvec(x):
            return self.forward(np.asarray(x, dtype=np.float64).reshape(self.in_shape)).reshape(-1)

        def rmatvec(y):
            return self.adjoint(np.asarray(y, dtype=np.float64).reshape(self.out_shape)).reshape(-1)

        def matmat(x):
            return np.stack([matvec(col) for col in np.asarray(x).T], axis=1)

        def rmatmat(y):
            return np.stack([rmatvec(col) for col in np.asarray(y).T], axis=1)

        return LinearOperator(self.shape, matvec=matvec, rmatvec=rmatvec, matmat=matmat, rmatmat=rmatmat,
                              dtype=np.float64)

    # -- patches -----------------------------------------------------------------------
    def _check_window(self, top: int, left: int, size: int) -> None:
        h, w = self.size
        size = _as_int(size, "patch size", low=1)
        if not (0 <= top and 0 <= left and top + size <= h and left + size <= w):
            raise InputError(f"patch at ({top}, {left}) of size {size} does not fit in the sensor of {h} x {w}")

    def restrict(self, top: int, left: int, size: int = 9) -> "ProjectionOperator":
        """The operator of one ``size x size`` window at ``(top, left)`` (a view, no copy of the mask)."""
        self._check_window(top, left, size)
        return ProjectionOperator(
            self.weights[:, :, :, top:top + size, left:left + size],
            self.cfa_index[top:top + size, left:left + size],
            channels=self.channels,
            period=self.period,
            offset=(self.offset[0] + top, self.offset[1] + left),
        )

    def patch_sparse(self, tops, lefts, size: int = 9) -> tuple[np.ndarray, np.ndarray]:
        """Gather form of the patch matrices of many patches (vectorised).

        Each row of a patch matrix has one non-zero per view. For ``B`` patches at
        ``(tops[b], lefts[b])`` this returns

        * ``cols`` of shape ``(B, m, V*U)`` (int64): column indices (they depend on the
          patch only through its CFA phase);
        * ``vals`` of shape ``(B, m, V*U)``: the mask transmittances,

        with ``m = S * size * size`` and the vectorisation orders of the module notes, so
        ``Phi_p @ x == (vals * x[cols]).sum(-1)`` and ``Phi_p @ D == (vals[..., None] * D[cols]).sum(-2)``.
        """
        tops = np.atleast_1d(np.asarray(tops, dtype=np.intp))
        lefts = np.atleast_1d(np.asarray(lefts, dtype=np.intp))
        if tops.shape != lefts.shape or tops.ndim != 1:
            raise ShapeError(f"patch_sparse: tops and lefts must be 1-D of equal length, got {tops.shape}, {lefts.shape}")
        h, w = self.size
        size = _as_int(size, "patch size", low=1)
        if tops.size and (tops.min() < 0 or lefts.min() < 0 or tops.max() + size > h or lefts.max() + size > w):
            raise InputError(f"patch_sparse: patches of size {size} must lie inside the sensor of {h} x {w}")
        s_n, (nv, nu), c_n = self.shots, self.views, self.channels
        ii = np.arange(size)
        rows = tops[:, None] + ii[None, :]  # (B, size)
        cols_ = lefts[:, None] + ii[None, :]
        # vals[b, s, i, j, v, u] = weights[s, v, u, top+i, left+j]
        wv = self.weights[:, :, :, rows[:, :, None], cols_[:, None, :]]  # (S, V, U, B, size, size)
        vals = wv.transpose(3, 0, 4, 5, 1, 2).reshape(len(tops), s_n * size * size, nv * nu)
        colour = self.cfa_index[rows[:, :, None], cols_[:, None, :]]  # (B, size, size)
        view = np.arange(nv * nu)
        pix = (ii[:, None] * size + ii[None, :])  # (size, size)
        col = ((view[None, None, None, :] * size * size + pix[None, :, :, None]) * c_n + colour[..., None])
        col = np.broadcast_to(col[:, None], (len(tops), s_n, size, size, nv * nu)).reshape(len(tops), -1, nv * nu)
        return col.astype(np.int64), vals

    def patch_matrix(self, top: int, left: int, size: int = 9) -> np.ndarray:
        """Dense matrix ``Phi_p`` of one patch, shape ``(S size^2, V U size^2 C)`` (orders: module notes).

        ``patch_matrix(t, l, n) @ L[:, :, t:t+n, l:l+n, :].reshape(-1)`` equals
        ``forward(L)[:, t:t+n, l:l+n].reshape(-1)`` for a light field ``L`` that is zero
        outside the patch (and in general, since a pixel only sees its own position).
        """
        self._check_window(top, left, size)
        cols, vals = self.patch_sparse([top], [left], size)
        m = self.shots * size * size
        n = self.views[0] * self.views[1] * size * size * self.channels
        out = np.zeros((m, n), dtype=self.weights.dtype)
        np.put_along_axis(out, cols[0], vals[0], axis=1)
        return out

    # -- shared operators by phase -------------------------------------------------------
    def phase(self, top: int, left: int) -> tuple[int, int] | None:
        """Phase of a patch at ``(top, left)``: patches with equal phase have equal patch matrices.

        ``None`` when the operator is not periodic (every position is its own phase).
        """
        if self.period is None:
            return None
        return ((self.offset[0] + top) % self.period[0], (self.offset[1] + left) % self.period[1])

    def n_phases(self, stride: int) -> int | None:
        """Number of distinct patch operators for patches on a grid of ``stride``; None if not periodic.

        ``(P / gcd(P, stride))`` per axis, with ``P`` the operator's period (mask period and the
        CFA's 2, combined by their least common multiple).
        """
        if self.period is None:
            return None
        stride = int(stride)
        if stride < 1:
            raise InputError(f"stride: expected a positive integer, got {stride}")
        return (self.period[0] // math.gcd(self.period[0], stride)) * (self.period[1] // math.gcd(self.period[1], stride))

    def shares_operator(self, stride: int) -> bool:
        """True when all patches on a grid of ``stride`` pixels have the same patch matrix."""
        return self.n_phases(stride) == 1


def build_operator(mask: MaskCode, *, views: tuple[int, int], size: tuple[int, int], cfa_pattern: str = "RGGB",
                   dtype=np.float32) -> ProjectionOperator:
    """Make the projection operator of a mask and a Bayer CFA.

    Parameters
    ----------
    mask : MaskCode
    views : (V, U)
    size : (H, W) of the sensor (and of each view)
    cfa_pattern : str
        Row-major Bayer layout from the top-left pixel (``RGGB``...).
    dtype : float32 (default) or float64, the dtype of the weights.

    Returns
    -------
    ProjectionOperator
        With ``period = lcm(mask period, 2)`` per axis when the mask is periodic.

    Raises
    ------
    ShapeError
        A mask that does not have 3 colours.
    """
    if mask.channels != 3:
        raise ShapeError(f"a Bayer CFA needs a 3-colour mask, this one has {mask.channels} colours")
    cfa = cfa_index_map(cfa_pattern, size)
    weights = mask.expand(views=views, size=size, cfa_index=cfa)  # (S, V, U, H, W)
    period = None
    if mask.period is not None:
        p = math.lcm(int(mask.period), 2)
        period = (p, p)
    return ProjectionOperator(freeze(np.ascontiguousarray(weights, dtype=dtype)), freeze(cfa), channels=3, period=period)


# -- per-phase patch operators (the reconstruction's view of Phi) ------------------------------


@short_repr
@dataclass(frozen=True, eq=False)
class PatchOperators:
    """The distinct patch matrices ``Phi_p`` of a set of patches, and which patch uses which.

    Each patch matrix (``m x n``, ``m = S * size^2``, ``n = V * U * size^2 * C``; row and
    column orders of the module notes) has one non-zero per row and view. It is held in
    gather form: ``Phi_g @ x == (vals[g] * x[cols[g]]).sum(-1)``.

    Attributes
    ----------
    cols : ndarray of shape (G, m, V*U), int32
        Column index of every non-zero (it depends on the patch only through its CFA phase).
    vals : ndarray of shape (G, m, V*U), float32
        Mask transmittances.
    index : ndarray of shape (B,), intp
        ``index[b]`` is the operator of patch ``b`` (in the order the patches were given).
    positions : ndarray of shape (G, 2), intp
        Sensor position (top, left) of one patch that uses each operator.
    size, views, shots, channels : the patch geometry.
    periodic : bool
        True when operators are shared by phase (a periodic mask): ``G`` does not grow with
        the sensor; False: one operator per patch position.
    """

    cols: np.ndarray
    vals: np.ndarray
    index: np.ndarray
    positions: np.ndarray
    size: int
    views: tuple[int, int]
    shots: int
    channels: int
    periodic: bool

    def __post_init__(self):
        # read-only like every array lfproc hands out (a copy only when the caller kept a writable reference)
        for name in ("cols", "vals", "index", "positions"):
            object.__setattr__(self, name, frozen_array(getattr(self, name)))

    @property
    def n_operators(self) -> int:
        return int(self.vals.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        """``(m, n)`` of each patch matrix."""
        nv, nu = self.views
        return self.shots * self.size**2, nv * nu * self.size**2 * self.channels

    def dense(self, g: int) -> np.ndarray:
        """Dense ``(m, n)`` matrix of operator ``g`` (for tests and small problems)."""
        out = np.zeros(self.shape, dtype=self.vals.dtype)
        np.put_along_axis(out, self.cols[g].astype(np.intp), self.vals[g], axis=1)
        return out

    def times(self, atoms: np.ndarray, g=None) -> np.ndarray:
        """``Phi_g @ atoms`` for operators ``g`` (default all): ``(G, m, K)`` (or ``(m, K)`` for one ``g``).

        ``atoms`` is ``(n, K)`` (a dictionary); computed as a sum over views of scaled row
        gathers, so no ``(m, V*U, K)`` intermediate is built.
        """
        atoms = np.asarray(atoms)
        one = g is not None and np.ndim(g) == 0
        gs = np.arange(self.n_operators) if g is None else np.atleast_1d(np.asarray(g, dtype=np.intp))
        dtype = np.result_type(atoms.dtype, np.float32)
        out = np.zeros((len(gs), self.shape[0], atoms.shape[1]), dtype=dtype)
        for i, gi in enumerate(gs):
            cols, vals = self.cols[gi], self.vals[gi].astype(dtype)
            for k in range(cols.shape[1]):
                out[i] += vals[:, k, None] * atoms[cols[:, k]]
        return out[0] if one else out

    def row_sums(self) -> np.ndarray:
        """Total transmittance seen by each measurement, ``(G, m)`` (``Phi_g @ ones``)."""
        return self.vals.sum(axis=-1, dtype=np.float64).astype(np.float32)


def _mask_values(mask: MaskCode, rows: np.ndarray, cols: np.ndarray, colour: np.ndarray,
                 views: tuple[int, int]) -> np.ndarray:
    """Transmittance of every shot and view at sensor pixels ``(rows, cols)`` in colour ``colour``.

    ``rows``, ``cols``, ``colour`` are integer arrays of one shape ``X``; returns ``(S, V, U, *X)``.
    Reads the codes directly (a periodic tile is indexed modulo its period), never the
    expanded ``(S, V, U, H, W)`` weights.
    """
    nv, nu = views
    if mask.kind == "random":
        if mask.period is not None:
            rows, cols = rows % mask.period, cols % mask.period
        return mask.codes[:, :, :, rows, cols, colour]
    sh = int(mask.shift)
    extra = (1,) * rows.ndim
    r = rows[None, None] + sh * np.arange(nv).reshape(nv, 1, *extra)
    c = cols[None, None] + sh * np.arange(nu).reshape(1, nu, *extra)
    if mask.period is not None:
        r, c = r % mask.period, c % mask.period
    return mask.codes[:, r, c, colour[None, None]]


def transmittance_map(mask: MaskCode, *, views: tuple[int, int], cfa_pattern: str, size: tuple[int, int],
                      rows_per_chunk: int = 64) -> np.ndarray:
    """Total mask transmittance over the views at every sensor pixel, ``(S, H, W)`` float64.

    The row sums of ``Phi``: a measurement of a light field that is constant over the views and
    the pixel's colour is that value times this. Computed from the codes in row chunks, never
    from the expanded ``(S, V, U, H, W)`` weights.
    """
    h, w = _pair(size, "size")
    colour = cfa_index_map(cfa_pattern, (h, w))
    out = np.empty((mask.shots, h, w), dtype=np.float64)
    cols = np.arange(w)
    for top in range(0, h, rows_per_chunk):
        rows = np.arange(top, min(h, top + rows_per_chunk))
        rr, cc = np.broadcast_arrays(rows[:, None], cols[None, :])
        out[:, rows] = _mask_values(mask, rr, cc, colour[rows], views).sum(axis=(1, 2), dtype=np.float64)
    return freeze(out)


def patch_operators(mask: MaskCode, *, views: tuple[int, int], cfa_pattern: str, tops, lefts, size: int,
                    sensor_size: tuple[int, int] | None = None) -> PatchOperators:
    """The distinct patch matrices of the patches at ``(tops[b], lefts[b])``, from the mask codes and the CFA.

    With a periodic mask (period ``P``) two patches have the same matrix when their
    positions agree modulo ``lcm(P, 2)`` (the mask tile and the Bayer quad), so only one
    operator per such phase is built: memory independent of the sensor size. Without a
    period every patch gets its own operator (build them per batch of patches).

    Parameters
    ----------
    mask : MaskCode
    views : (V, U)
    cfa_pattern : str
        Bayer layout from the sensor's top-left pixel.
    tops, lefts : 1-D int arrays of equal length
        Patch corners on the sensor.
    size : int
        Patch side in pixels.
    sensor_size : (H, W), optional
        Checks that the patches lie inside the sensor (and the codes cover it).

    Returns
    -------
    PatchOperators
        ``dense(index[b])`` equals ``build_operator(...).patch_matrix(tops[b], lefts[b], size)``.
    """
    tops = np.atleast_1d(np.asarray(tops, dtype=np.intp))
    lefts = np.atleast_1d(np.asarray(lefts, dtype=np.intp))
    if tops.shape != lefts.shape or tops.ndim != 1:
        raise ShapeError(f"patch_operators: tops and lefts must be 1-D of equal length, got {tops.shape}, {lefts.shape}")
    size = int(size)
    if size < 1:
        raise InputError(f"patch size: expected a positive integer, got {size}")
    if not isinstance(mask, MaskCode):
        raise InputError(f"patch_operators: expected a MaskCode, got {type(mask).__name__}")
    nv, nu = int(views[0]), int(views[1])
    if tops.size and (tops.min() < 0 or lefts.min() < 0):
        raise InputError("patch_operators: patch corners must be non-negative")
    if sensor_size is not None:
        h, w = sensor_size
        mask.check(views=(nv, nu), size=(h, w))
        if tops.size and (tops.max() + size > h or lefts.max() + size > w):
            raise InputError(f"patch_operators: patches of size {size} must lie inside the sensor of {h} x {w}")
    if mask.channels != 3:
        raise ShapeError(f"a Bayer CFA needs a 3-colour mask, this one has {mask.channels} colours")
    periodic = mask.period is not None
    if periodic:
        p = math.lcm(int(mask.period), 2)
        keys = np.stack([tops % p, lefts % p], axis=1)
    else:
        keys = np.stack([tops, lefts], axis=1)
    uniq, first, index = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    index = index.reshape(-1)
    positions = np.stack([tops[first], lefts[first]], axis=1) if len(first) else np.zeros((0, 2), np.intp)
    ii = np.arange(size)
    rows = positions[:, 0, None, None] + ii[None, :, None]  # (G, size, 1)
    cols_ = positions[:, 1, None, None] + ii[None, None, :]  # (G, 1, size)
    rows, cols_ = np.broadcast_arrays(rows, cols_)
    tile = np.array([_COLOUR_INDEX[ch] for ch in check_choice("cfa_pattern", str(cfa_pattern).upper(), CFA_PATTERNS)],
                    dtype=np.intp).reshape(2, 2)
    colour = tile[rows % 2, cols_ % 2]  # (G, size, size)
    values = _mask_values(mask, rows, cols_, colour, (nv, nu))  # (S, V, U, G, size, size)
    s_n = mask.shots
    g_n = len(positions)
    vals = values.transpose(3, 0, 4, 5, 1, 2).reshape(g_n, s_n * size * size, nv * nu)
    view = np.arange(nv * nu)
    pix = ii[:, None] * size + ii[None, :]
    col = (view[None, None, None, :] * size * size + pix[None, :, :, None]) * 3 + colour[..., None]  # (G, sz, sz, VU)
    col = np.broadcast_to(col[:, None], (g_n, s_n, size, size, nv * nu)).reshape(g_n, -1, nv * nu)
    return PatchOperators(cols=freeze(np.array(col, dtype=np.int32)),
                          vals=freeze(np.array(vals, dtype=np.float32)),
                          index=freeze(np.array(index, dtype=np.intp)),
                          positions=freeze(np.array(positions, dtype=np.intp)), size=size,
                          views=(nv, nu), shots=s_n, channels=3, periodic=periodic)
