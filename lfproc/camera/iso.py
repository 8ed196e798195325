"""Per-pixel ISO layouts of a multi-ISO sensor.

The random, row and block patterns of Miandji, Nguyen, Hajisharif, Unger and Guillemot,
"Compressive HDR light field imaging using a single multi-ISO sensor", IEEE TCI 2021, section
IV-B.

Patterns (:func:`iso_pattern`): ``random`` (i.i.d. per pixel), ``row`` (rows alternate ISO
in 2-row units, so a Bayer quad shares one ISO, as in Magic Lantern's dual ISO), ``block``
(square blocks of ``block_px`` pixels, an even number; the ISOs of the set are laid out in a
``g x g`` arrangement of blocks, ``g = ceil(sqrt(n))``), ``dual`` (the row pattern with the
lowest and the highest ISO of the set: (100, 1600) for the default set), or a file (``.npy``
or a single-channel integer image, values = ISO).

The paper does not give its block size. :data:`DEFAULT_BLOCK_PX` is 8, the side of a
reconstruction patch: then, as in the paper, a patch sees one to four of the ISOs and the block
pattern is a different acquisition from rows. Blocks of 2 or 4 pixels hold every ISO in every
8 x 8 patch, like rows and random pixels, and reconstruct like them (README: 2 and 4 px tie or
beat rows, 8 px and more fall 2-4 dB behind, as the paper's blocks do on each of its scenes).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .._shared.deprecate import renamed_keywords
from .._shared.random import check_random_state
from ..errors import FileFormatError, InputError, MissingFileError, ShapeError
from .. import _untrusted as ut
from ..io.images import imread

__all__ = ["ISO_PATTERNS", "DEFAULT_ISOS", "DEFAULT_BLOCK_PX", "iso_pattern", "describe_iso_pattern"]

ISO_PATTERNS = ("random", "row", "block", "dual")
DEFAULT_ISOS = (100, 400, 800, 1600)
#: Side of the ``block`` pattern's blocks in pixels (module notes).
DEFAULT_BLOCK_PX = 8


def _num(v: float):
    """An ISO (or any figure) as a plain int when it is whole, else a float (for JSON records)."""
    return int(v) if float(v).is_integer() else float(v)


def _load_iso_file(path: Path, size: tuple[int, int]) -> np.ndarray:
    if not path.is_file():
        raise MissingFileError(f"{path}: no such ISO map file (or use one of {', '.join(ISO_PATTERNS)})")
    if path.suffix.lower() == ".npy":
        def check(shape, dtype):
            if dtype.kind not in "uif":
                raise FileFormatError(f"{path}: ISO map of dtype {dtype}; expected numbers")
            if tuple(shape) != tuple(size):
                raise ShapeError(f"{path}: ISO map of shape {tuple(shape)}; expected the sensor size {tuple(size)}")

        with open(path, "rb") as fh:
            values = ut.read_npy(fh, path.stat().st_size, source=path, what=".npy ISO map", check=check)
    else:
        import cv2

        values = imread(path, cv2.IMREAD_UNCHANGED, what="ISO map image (.npy, .png, .tif)")
        if values.ndim != 2:
            raise FileFormatError(f"{path}: ISO map image: expected one channel, found shape {values.shape}")
    values = np.asarray(values, dtype=np.float64)
    if values.shape != tuple(size):
        raise ShapeError(f"{path}: ISO map of shape {values.shape}; expected the sensor size {tuple(size)}")
    bad = int(np.count_nonzero(~np.isfinite(values)))
    if bad:
        raise FileFormatError(f"{path}: ISO map with {bad} NaN or Inf values; expected an ISO number per pixel")
    if (values <= 0).any():
        raise FileFormatError(f"{path}: ISO map with values <= 0 (smallest {values.min():g}); expected positive ISOs")
    return values



def iso_pattern(
    kind: str | os.PathLike,
    *,
    size: tuple[int, int],
    isos: Sequence[float] = DEFAULT_ISOS,
    block_px: int = DEFAULT_BLOCK_PX,
    random_state=None,
) -> np.ndarray:
    """ISO of every sensor pixel for a named pattern or a file (see the module documentation).

    Parameters
    ----------
    kind : {"random", "row", "block", "dual"} or path
        Pattern name, or a ``.npy``/integer image file holding the ISO of every pixel.
    size : (H, W)
    isos : sequence of float
        The ISO set.
    block_px : int
        Side of the blocks of ``block`` in pixels (even, so Bayer quads share one ISO).
    random_state : int, Generator or None (``random`` only)

    Returns
    -------
    ndarray of shape (H, W), float32

    Raises
    ------
    InputError
        An unknown pattern name, an empty ISO set, a bad block size or ISO file.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.camera import iso_pattern
    >>> iso_pattern("row", size=(8, 2))[:, 0].tolist()  # rows in pairs: a Bayer quad shares one ISO
    [100.0, 100.0, 400.0, 400.0, 800.0, 800.0, 1600.0, 1600.0]
    >>> print(iso_pattern("block", size=(4, 4), block_px=2).astype(int))
    [[ 100  100  400  400]
     [ 100  100  400  400]
     [ 800  800 1600 1600]
     [ 800  800 1600 1600]]
    >>> np.unique(iso_pattern("dual", size=(8, 8))).tolist()  # lowest and highest of the set
    [100.0, 1600.0]
    """
    h, w = (int(size[0]), int(size[1]))
    isos = np.asarray([float(v) for v in isos])
    if isos.size == 0:
        raise InputError("isos: expected at least one ISO value")
    name = str(kind)
    if name not in ISO_PATTERNS:
        path = Path(name)
        if path.suffix or path.exists():
            return _load_iso_file(path, (h, w)).astype(np.float32)
        raise InputError(f"iso pattern: expected one of {', '.join(ISO_PATTERNS)} or a file; got {name!r}")
    rows = np.arange(h)[:, None]
    cols = np.arange(w)[None, :]
    if name == "random":
        index = check_random_state(random_state).integers(0, isos.size, size=(h, w))
    elif name == "row":
        index = np.broadcast_to((rows // 2) % isos.size, (h, w))
    elif name == "dual":
        isos = np.array([isos.min(), isos.max()])
        index = np.broadcast_to((rows // 2) % 2, (h, w))
    else:
        b = int(block_px)
        if b < 2 or b % 2 or b != block_px:
            raise InputError(f"block size: expected an even number of pixels >= 2, got {block_px}")
        g = math.ceil(math.sqrt(isos.size))
        index = (((rows // b) % g) * g + (cols // b) % g) % isos.size
    return isos[index].astype(np.float32)


@renamed_keywords(seed="random_state")
def describe_iso_pattern(kind: str | os.PathLike, isos: Sequence[float], *, block_px: int = DEFAULT_BLOCK_PX,
                         random_state=None) -> dict:
    """The record of an ISO layout a capture keeps (``iso_pattern`` of its file).

    ``{"kind", "isos"}`` for a named pattern (with ``block_px`` for ``block`` and, when given, the
    integer ``random_state`` of ``random``, recorded as ``"seed"``; the keyword ``seed`` is deprecated), ``{"kind": "file", "path", "isos"}`` for a file.
    """
    name = str(kind)
    values = [_num(v) for v in isos]
    if name not in ISO_PATTERNS:
        return {"kind": "file", "path": name, "isos": values}
    info: dict = {"kind": name, "isos": values}
    if name == "block":
        info["block_px"] = int(block_px)
    if name == "random" and random_state is not None:
        info["seed"] = random_state
    return info
