"""Lytro raw pixel packings: Illum 10-bit little-endian and F01 12-bit big-endian.

* Illum (``bitsPerPixel`` 10, ``endianness`` ``"little"``): every 5 bytes ``b0..b4`` hold 4
  consecutive pixels, ``p_k = (b_k << 2) | ((b4 >> 2k) & 3)`` for ``k = 0..3``.
* F01 (``bitsPerPixel`` 12, ``endianness`` ``"big"``): every 3 bytes ``t0 t1 t2`` hold 2
  pixels, ``p0 = (t0 << 4) | (t1 >> 4)`` and ``p1 = ((t1 & 0xF) << 8) | t2``.

Pixels are stored row-major from the top-left pixel. Unpacking returns raw ``uint16`` counts
(DN); nothing is rescaled (linearising is a separate, explicit step).
"""

from __future__ import annotations

import numpy as np

from ..errors import LfpFormatError, ShapeError

__all__ = [
    "raw_byte_count",
    "unpack_raw",
    "unpack_raw10",
    "pack_raw10",
    "unpack_raw12",
    "pack_raw12",
    "unpack_raw16",
    "pack_raw16",
]

_SHIFTS10 = np.array([0, 2, 4, 6], dtype=np.uint16)


def raw_byte_count(height: int, width: int, bits_per_pixel: int) -> int:
    """Bytes of a packed raw image of ``height`` x ``width`` pixels at ``bits_per_pixel``.

    Examples
    --------
    >>> raw_byte_count(5368, 7728, 10)
    51854880
    >>> raw_byte_count(3280, 3280, 12)
    16137600
    """
    n_bits = int(height) * int(width) * int(bits_per_pixel)
    return n_bits // 8


def _where(source) -> str:
    return f"{source}: " if source is not None else ""


def _check_buffer(buf, height: int, width: int, bits: int, group: int, source) -> np.ndarray:
    if height <= 0 or width <= 0:
        raise ShapeError(f"{_where(source)}raw size must be positive, got {height} x {width}")
    if (height * width) % group:
        raise ShapeError(f"{_where(source)}a {bits}-bit raw needs a pixel count divisible by {group}, "
                         f"got {height} x {width}")
    expected = raw_byte_count(height, width, bits)
    data = np.frombuffer(buf, dtype=np.uint8)
    if data.size != expected:
        raise LfpFormatError(f"{_where(source)}wrong raw size: a {width} x {height} {bits}-bit image needs "
                             f"{expected} bytes, found {data.size}")
    return data


def unpack_raw10(buf: bytes, height: int, width: int, *, source=None) -> np.ndarray:
    """Unpack an Illum 10-bit little-endian raw buffer (4 pixels in 5 bytes).

    Parameters
    ----------
    buf : bytes-like
        Exactly ``height * width * 10 / 8`` bytes.
    height, width : int
        Image size in pixels (rows, columns).
    source : str or Path, optional
        File named in error messages.

    Returns
    -------
    ndarray of shape (height, width), uint16
        Raw counts 0..1023 (DN).

    Raises
    ------
    LfpFormatError
        When the buffer does not have the expected size.
    """
    data = _check_buffer(buf, height, width, 10, 4, source).reshape(-1, 5)
    out = data[:, :4].astype(np.uint16)
    out <<= 2
    out |= (data[:, 4:5] >> _SHIFTS10.astype(np.uint8)) & np.uint8(3)
    return out.reshape(height, width)


def pack_raw10(raw) -> bytes:
    """Pack raw counts 0..1023 into the Illum 10-bit little-endian layout (inverse of
    :func:`unpack_raw10`).

    Parameters
    ----------
    raw : array_like of shape (H, W), integers
        ``H * W`` must be a multiple of 4.
    """
    arr = _check_values(raw, 10, 4)
    px = arr.reshape(-1, 4)
    out = np.empty((px.shape[0], 5), dtype=np.uint8)
    out[:, :4] = (px >> 2).astype(np.uint8)
    low = (px & 3).astype(np.uint8)
    out[:, 4] = low[:, 0] | (low[:, 1] << 2) | (low[:, 2] << 4) | (low[:, 3] << 6)
    return out.tobytes()


def unpack_raw12(buf: bytes, height: int, width: int, *, source=None) -> np.ndarray:
    """Unpack an F01 12-bit big-endian raw buffer (2 pixels in 3 bytes).

    Returns
    -------
    ndarray of shape (height, width), uint16
        Raw counts 0..4095 (DN).

    Raises
    ------
    LfpFormatError
        When the buffer does not have the expected size.
    """
    data = _check_buffer(buf, height, width, 12, 2, source).reshape(-1, 3)
    out = np.empty((data.shape[0], 2), dtype=np.uint16)
    t1 = data[:, 1].astype(np.uint16)
    out[:, 0] = (data[:, 0].astype(np.uint16) << 4) | (t1 >> 4)
    out[:, 1] = ((t1 & 0xF) << 8) | data[:, 2]
    return out.reshape(height, width)


def pack_raw12(raw) -> bytes:
    """Pack raw counts 0..4095 into the F01 12-bit big-endian layout (inverse of
    :func:`unpack_raw12`); ``H * W`` must be even."""
    arr = _check_values(raw, 12, 2)
    px = arr.reshape(-1, 2)
    out = np.empty((px.shape[0], 3), dtype=np.uint8)
    out[:, 0] = (px[:, 0] >> 4).astype(np.uint8)
    out[:, 1] = (((px[:, 0] & 0xF) << 4) | (px[:, 1] >> 8)).astype(np.uint8)
    out[:, 2] = (px[:, 1] & 0xFF).astype(np.uint8)
    return out.tobytes()


def unpack_raw16(buf: bytes, height: int, width: int, *, source=None) -> np.ndarray:
    """Unpack little-endian 16-bit raw data (written by some third-party extractors)."""
    data = _check_buffer(buf, height, width, 16, 1, source)
    return data.view("<u2").astype(np.uint16).reshape(height, width)


def pack_raw16(raw) -> bytes:
    """Pack raw counts as little-endian 16-bit words (inverse of :func:`unpack_raw16`)."""
    return _check_values(raw, 16, 1).astype("<u2").tobytes()


def unpack_raw(buf: bytes, height: int, width: int, *, bits_per_pixel: int, endianness: str, source=None) -> np.ndarray:
    """Unpack with the packing named by Lytro metadata (``pixelPacking``).

    Supported: 10 bit ``little`` (Illum), 12 bit ``big`` (F01), 16 bit ``little``.
    """
    key = (int(bits_per_pixel), str(endianness).lower())
    if key == (10, "little"):
        return unpack_raw10(buf, height, width, source=source)
    if key == (12, "big"):
        return unpack_raw12(buf, height, width, source=source)
    if key == (16, "little"):
        return unpack_raw16(buf, height, width, source=source)
    raise LfpFormatError(f"{_where(source)}unsupported pixel packing {key[0]} bit {key[1]}-endian; "
                         "expected 10 bit little (Illum), 12 bit big (F01) or 16 bit little")


def _check_values(raw, bits: int, group: int) -> np.ndarray:
    arr = np.asarray(raw)
    if arr.ndim != 2:
        raise ShapeError(f"raw must be a 2-D array (H, W), got shape {arr.shape}")
    if arr.size % group:
        raise ShapeError(f"a {bits}-bit raw needs a pixel count divisible by {group}, got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        raise ShapeError(f"raw must hold integer counts (DN), got dtype {arr.dtype}")
    top = (1 << bits) - 1
    if arr.size and (int(arr.min()) < 0 or int(arr.max()) > top):
        raise ShapeError(f"raw values must lie in 0..{top} for {bits}-bit packing, "
                         f"found {int(arr.min())}..{int(arr.max())}")
    return np.ascontiguousarray(arr, dtype=np.uint16)
