"""Opening OpenEXR files without trusting them, and without the library's own chatter.

The ``OpenEXR`` bindings print the C library's error lines on the process's stderr and
their own ``Warning: Exception raised reading pixel data for part N`` lines on
``sys.stdout``, and then silently drop the parts they could not decode. :func:`open_exr`
reads the headers first (quietly), checks every part's size against
:mod:`lfproc._untrusted` limits and against the file's size *before* any pixel is
allocated, then reads the pixels (quietly) and turns dropped parts into one
:class:`~lfproc.errors.FileFormatError` naming them and quoting the library's first message.
"""

from __future__ import annotations

import os
from pathlib import Path

from .. import _untrusted as ut
from .._shared.stdio import quiet
from ..errors import FileFormatError

__all__ = ["open_exr", "MAX_EXR_RATIO", "MAX_EXR_PARTS"]

#: Largest expansion of an EXR's pixel data over its file size: ZIP/deflate cannot exceed
#: about 1032:1, so a file announcing more pixel bytes than this cannot be a valid one.
MAX_EXR_RATIO = 1100
#: Most parts lfproc reads from one file (a 17 x 17 light field has 289).
MAX_EXR_PARTS = 4096


def _first_error(lines: list[str], path: Path) -> str:
    """The library's first error line, without the file name it starts with."""
    for marks in (("EXR_ERR",), ("rror", "xception")):
        for line in lines:
            if any(m in line for m in marks):
                text = line
                for prefix in (f"{path}: ", f"{path.name}: "):
                    if text.startswith(prefix):
                        text = text[len(prefix):]
                return text[:200]
    return lines[0][:200] if lines else ""


def _check_headers(path: Path, parts) -> None:
    if len(parts) > MAX_EXR_PARTS:
        raise FileFormatError(f"{path}: {len(parts)} parts, above the limit of {MAX_EXR_PARTS}")
    size = path.stat().st_size
    total = 0
    for i, part in enumerate(parts):
        header = part.header
        storage = str(header.get("type", ""))
        if "deep" in storage.lower():
            raise FileFormatError(f"{path}: part {i} is a deep image ({storage.split('.')[-1]}); lfproc reads flat "
                                  "scanline or tiled images")
        try:
            (x0, y0), (x1, y1) = (tuple(int(v) for v in corner) for corner in header["dataWindow"])
            channels = list(header.get("channels", []))
        except (KeyError, TypeError, ValueError) as exc:
            raise FileFormatError(f"{path}: part {i} has no usable dataWindow/channels ({exc})") from None
        h, w = ut.check_dims((y1 - y0 + 1, x1 - x0 + 1), source=path, what=f"part {i} data window",
                             error=FileFormatError)
        if len(channels) > 1024:
            raise FileFormatError(f"{path}: part {i} has {len(channels)} channels, above the limit of 1024")
        for ch in channels:
            xs, ys = getattr(ch, "xSampling", 1), getattr(ch, "ySampling", 1)
            if (xs, ys) != (1, 1):
                raise FileFormatError(f"{path}: part {i} channel {ch.name!r} is subsampled ({xs} x {ys}); lfproc "
                                      "reads full-resolution channels only")
        total += h * w * 4 * len(channels)
    limit = max(ut.EXPANSION_FLOOR, MAX_EXR_RATIO * size)
    if total > limit:
        raise FileFormatError(f"{path}: the headers announce {total} bytes of pixels in a file of {size} bytes "
                              f"(limit {limit}); the file is corrupt or hostile")


def _guarded(open_file, path: Path, what: str):
    """``(open_file(), the library's captured message lines)``; any failure becomes one
    :class:`FileFormatError` line naming the file, ``what`` failed and the library's first error."""
    with quiet() as lines:
        try:
            value = open_file()
        except Exception as exc:  # the bindings raise plain RuntimeError/ValueError/UnicodeError on any failure
            failed = exc
        else:
            failed = None
    if failed is None:
        return value, lines
    detail = _first_error(lines, path) or str(failed)
    raise FileFormatError(f"{path}: {what} ({detail[:200]})")


def open_exr(path: str | os.PathLike, *, header_only: bool = False):
    """An ``OpenEXR.File`` whose headers were checked (sizes, parts, channel sampling) before
    any pixels were read; :class:`FileFormatError` naming parts the library cannot decode."""
    import OpenEXR

    path = Path(path)

    def read_head():
        head = OpenEXR.File(str(path), header_only=True)
        return head, list(head.parts)

    (head, parts), _ = _guarded(read_head, path, "not a readable OpenEXR file")
    if not parts:
        raise FileFormatError(f"{path}: the OpenEXR file has no parts")
    _check_headers(path, parts)
    if header_only:
        return head
    names = [p.name() or f"#{i}" for i, p in enumerate(parts)]

    def read_pixels():
        f = OpenEXR.File(str(path), separate_channels=True)
        return f, [p.name() or f"#{i}" for i, p in enumerate(f.parts)]

    (f, got), lines = _guarded(read_pixels, path, "OpenEXR could not decode the pixels")
    if len(got) != len(names):
        lost = [n for n in names if n not in got] or [f"{len(names) - len(got)} of {len(names)} parts"]
        detail = _first_error(lines, path)
        raise FileFormatError(f"{path}: OpenEXR could not decode part{'s' if len(lost) > 1 else ''} "
                              f"{', '.join(lost[:8])}{' ...' if len(lost) > 8 else ''}; the file is corrupt or "
                              f"truncated{f' ({detail})' if detail else ''}")
    return f
