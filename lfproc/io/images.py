"""Single images: OpenEXR (any part and channel layout), Radiance ``.hdr``, PNG/TIFF/JPEG.

OpenEXR goes through the ``OpenEXR`` bindings, Radiance and 8/16-bit formats
through OpenCV, sRGB decoding through colour-science. All readers return a
float32 ``(H, W, C)`` array (C = 3 for colour, 1 for a single channel) and a dict
of what the file says about itself.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .. import _untrusted as ut
from ..errors import FileFormatError, InputError, MissingFileError, UnsafeFileError
from ..lightfield import clean_nonfinite
from ._atomic import atomic_file
from .._shared.stdio import quiet
from ._exr import open_exr

__all__ = [
    "read_image",
    "write_image",
    "exr_parts",
    "srgb_decode",
    "srgb_encode",
    "IMAGE_SUFFIXES",
    "LDR_SUFFIXES",
    "HDR_SUFFIXES",
    "check_image_size",
    "imread",
]

HDR_SUFFIXES = (".exr", ".hdr", ".pic")
LDR_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
IMAGE_SUFFIXES = HDR_SUFFIXES + LDR_SUFFIXES

Transfer = Literal["auto", "srgb", "linear"]


def srgb_decode(values: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear (IEC 61966-2-1, via colour-science).

    Parameters
    ----------
    values : array_like
        sRGB-encoded values, nominally in [0, 1]; any shape.

    Returns
    -------
    ndarray
        Linear values, float32, the shape of ``values``.

    See Also
    --------
    srgb_encode : the inverse.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.io import srgb_decode, srgb_encode
    >>> [round(float(x), 4) for x in srgb_decode(np.array([0.0, 0.5, 1.0]))]
    [0.0, 0.214, 1.0]
    >>> x = np.linspace(0, 1, 11)
    >>> bool(np.allclose(srgb_decode(srgb_encode(x)), x, atol=1e-5))
    True
    """
    import colour

    return np.asarray(colour.cctf_decoding(values, function="sRGB"), dtype=np.float32)


def srgb_encode(values: np.ndarray) -> np.ndarray:
    """Linear values to sRGB encoding (IEC 61966-2-1, via colour-science).

    Parameters
    ----------
    values : array_like
        Linear values, any shape; clipped to [0, 1] before encoding.

    Returns
    -------
    ndarray
        sRGB-encoded values in [0, 1], float32, the shape of ``values``.

    See Also
    --------
    srgb_decode : the inverse.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.io import srgb_encode
    >>> [round(float(x), 4) for x in srgb_encode(np.array([-1.0, 0.0031308, 0.214, 1.0, 4.0]))]
    [0.0, 0.0404, 0.5, 1.0, 1.0]
    """
    import colour

    return np.asarray(colour.cctf_encoding(np.clip(values, 0, 1), function="sRGB"), dtype=np.float32)


def _require_file(path: Path) -> None:
    if not path.exists():
        raise MissingFileError(f"{path}: no such file")
    if path.is_dir():
        raise FileFormatError(f"{path}: expected an image file, found a folder")


# -- OpenEXR ---------------------------------------------------------------------------

def exr_parts(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Describe the parts of an OpenEXR file: name, view, channels, size (header only).

    Parameters
    ----------
    path : str or os.PathLike
        An OpenEXR file (single- or multi-part). Only the headers are read.

    Returns
    -------
    list of dict
        One dict per part, in file order, with keys ``index`` (int), ``name`` (str, ``""`` when
        the part has none), ``view`` (the part's ``view`` attribute or None), ``multiView``
        (list of view names of a single-part multi-view file, or None), ``channels`` (sorted
        channel names, or None) and ``size`` (``[height, width]`` of the data window).

    Raises
    ------
    lfproc.errors.MissingFileError
        ``path`` does not exist.
    lfproc.errors.FileFormatError
        ``path`` is a folder or not a readable OpenEXR file.

    Examples
    --------
    >>> import numpy as np
    >>> import lfproc
    >>> from lfproc.io import exr_parts
    >>> _ = lfproc.write_image("grey.exr", np.full((4, 6, 3), 0.5, np.float32))
    >>> [(p["index"], p["channels"], p["size"]) for p in exr_parts("grey.exr")]
    [(0, ['B', 'G', 'R'], [4, 6])]
    """
    path = Path(path)
    _require_file(path)
    f = open_exr(path, header_only=True)
    out = []
    for i, part in enumerate(f.parts):
        h = part.header
        (x0, y0), (x1, y1) = h["dataWindow"]
        out.append(
            {
                "index": i,
                "name": part.name() or "",
                "view": h.get("view"),
                "multiView": list(h["multiView"]) if "multiView" in h else None,
                "channels": sorted(c.name for c in h["channels"]) if "channels" in h else None,
                "size": [int(y1 - y0 + 1), int(x1 - x0 + 1)],
            }
        )
    return out


_COLOUR_SETS = (("R", "G", "B"), ("Y",))


def _pick_channels(names: list[str], prefix: str) -> tuple[str, ...] | None:
    """The colour channels of a layer or view prefix ('' for the default).

    R,G,B (3 channels) or Y (1) first; else a lone unprefixed channel other than alpha or
    depth (e.g. the single ``G`` of ``TestImages_WideFloatRange.exr``) is read as one channel.
    """
    for group in _COLOUR_SETS:
        full = tuple(prefix + c for c in group)
        if all(n in names for n in full):
            return full
    if not prefix:
        lone = [n for n in names if "." not in n and n not in ("A", "Z")]
        if len(lone) == 1 and lone[0] in ("R", "G", "B", "L"):
            return (lone[0],)
    return None


def _read_exr(path: Path, part: int | str | None, view: str | None) -> tuple[np.ndarray, dict[str, Any]]:
    f = open_exr(path)
    parts = f.parts
    # choose the part
    if part is None and view is not None and any(p.header.get("view") == view and _pick_channels(list(p.channels), "")
                                                 for p in parts):
        index = next(i for i, p in enumerate(parts) if p.header.get("view") == view and _pick_channels(list(p.channels), ""))
    elif part is None:
        candidates = [i for i, p in enumerate(parts) if _pick_channels(list(p.channels), "")]
        if not candidates:
            # single-part multi-view, or a layer: accept any one colour layer
            candidates = [i for i, p in enumerate(parts) if any(c.endswith((".R", ".Y")) for c in p.channels)]
        if not candidates:
            found = ", ".join(sorted({c for p in parts for c in p.channels}))
            raise FileFormatError(f"{path}: expected R,G,B or Y channels in some part, found channels {found}")
        index = candidates[0]
    elif isinstance(part, int) or (isinstance(part, str) and part.isdigit()):
        index = int(part)
        if not 0 <= index < len(parts):
            raise InputError(f"{path}: part index {index} out of range; the file has {len(parts)} parts")
    else:
        names = [p.name() for p in parts]
        if part not in names:
            raise InputError(f"{path}: no part named {part!r}; parts are {', '.join(names)}")
        index = names.index(part)
    p = parts[index]
    names = list(p.channels)
    header = p.header
    # choose the view / layer within the part
    prefix = ""
    multiview = list(header["multiView"]) if "multiView" in header else None
    if view is not None and multiview:
        if view not in multiview:
            raise InputError(f"{path}: no view named {view!r}; views are {', '.join(multiview)}")
        prefix = "" if view == multiview[0] else f"{view}."
    chans = _pick_channels(names, prefix)
    if chans is None:
        layers = sorted({n.rsplit(".", 1)[0] + "." for n in names if "." in n})
        chans = next((c for lay in layers if (c := _pick_channels(names, lay))), None)
    if chans is None:
        raise FileFormatError(
            f"{path}: part {index} has channels {', '.join(sorted(names))}; expected R,G,B or Y (optionally in a layer)"
        )
    planes = [p.channels[c].pixels for c in chans]
    if any(not isinstance(q, np.ndarray) or q.ndim != 2 or q.shape != planes[0].shape for q in planes):
        raise FileFormatError(f"{path}: part {index} channels {', '.join(chans)} differ in size or hold no pixels")
    array = np.stack([q.astype(np.float32) for q in planes], axis=-1)
    (x0, y0), (x1, y1) = header["dataWindow"]
    (dx0, dy0), (dx1, dy1) = header.get("displayWindow", header["dataWindow"])
    meta = {
        "format": "exr",
        "part": index,
        "n_parts": len(parts),
        "part_name": p.name() or None,
        "view": header.get("view") or (view if multiview else None),
        "channels_read": list(chans),
        "pixel_type": str(p.channels[chans[0]].pixels.dtype),
        "data_window": [int(x0), int(y0), int(x1), int(y1)],
        "display_window": [int(dx0), int(dy0), int(dx1), int(dy1)],
        "compression": str(header.get("compression", "")).split(".")[-1],
        "header": header,
    }
    return array, meta


# -- OpenCV formats ---------------------------------------------------------------------

#: Largest expansion of a PNG/TIFF/JPEG/Radiance file's pixels over its size (deflate, the
#: strongest of their codecs, stays below about 1032:1).
MAX_IMAGE_RATIO = 1100


def _radiance_size(path: Path) -> tuple[int, int] | None:
    """``(H, W)`` from a Radiance header (text lines, a blank line, then ``-Y H +X W``)."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    end = head.find(b"\n\n")
    if end < 0:
        return None
    line = head[end + 2:].split(b"\n", 1)[0].split()
    if len(line) != 4 or not all(t.lstrip(b"+-").isdigit() for t in (line[1], line[3])):
        return None
    a, b = int(line[1]), int(line[3])
    return (a, b) if line[0][1:2] == b"Y" else (b, a)


def _check_png_chunks(path: Path, size: int) -> None:
    """Walk a PNG's chunks (length, type, data, CRC): a chunk announcing more bytes than the file
    holds is refused before a decoder tries to read (and allocate) it."""
    with open(path, "rb") as fh:
        if fh.read(8) != b"\x89PNG\r\n\x1a\n":
            raise FileFormatError(f"{path}: not a PNG file (wrong signature)")
        offset = 8
        while offset < size:
            head = fh.read(8)
            if len(head) < 8:
                raise FileFormatError(f"{path}: truncated PNG (chunk header at byte {offset} is cut off)")
            length = int.from_bytes(head[:4], "big")
            if length > 2**31 - 1 or offset + 12 + length > size:
                raise FileFormatError(f"{path}: corrupt or truncated PNG: chunk {head[4:8]!r} at byte {offset} "
                                      f"announces {length} bytes, the file has {size}")
            if head[4:8] == b"IEND":
                return
            fh.seek(length + 4, 1)
            offset += 12 + length


def check_image_size(path: str | os.PathLike) -> None:
    """Refuse an image whose header announces more pixels than the limits allow or than its
    file could hold (:data:`MAX_IMAGE_RATIO`), before a decoder allocates them.

    Reads the header only (Pillow for PNG/TIFF/JPEG, the text header for Radiance);
    files Pillow cannot identify are left to the decoder, which reports them.
    """
    import warnings

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".png":
        _check_png_chunks(path, path.stat().st_size)
    size = None
    bands = 3
    try:
        if suffix in (".hdr", ".pic"):
            size = _radiance_size(path)
        else:
            from PIL import Image

            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # Pillow's bomb warning: lfproc applies its own limits below
                    with Image.open(path) as im:
                        w, h = im.size
                        size, bands = (h, w), len(im.getbands())
            except Image.DecompressionBombError as exc:
                raise UnsafeFileError(f"{path}: {exc}; refused as a possible decompression bomb") from None
    except UnsafeFileError:
        raise
    except Exception as exc:  # Pillow raises OSError and assorted others on damaged headers
        if suffix in (".png", ".tif", ".tiff", ".jpg", ".jpeg"):
            # a header Pillow cannot parse is not worth handing to a decoder (libpng can spend seconds on one)
            raise FileFormatError(f"{path}: not a readable {suffix[1:].upper()} image ({type(exc).__name__}: "
                                  f"{str(exc)[:120]})") from None
        return
    if size is None:
        return
    h, w = ut.check_dims(size, source=path, what="image", error=FileFormatError)
    nbytes = h * w * max(bands, 1) * 4
    limit = max(ut.EXPANSION_FLOOR, MAX_IMAGE_RATIO * path.stat().st_size)
    if nbytes > limit:
        raise UnsafeFileError(f"{path}: the header announces a {w} x {h} image ({nbytes} bytes decoded) in a file of "
                              f"{path.stat().st_size} bytes; refused as corrupt or a decompression bomb")

def imread(path: str | os.PathLike, flags: int | None = None, *, what: str = "image") -> np.ndarray:
    """``cv2.imread`` of an untrusted file: its header size checked first
    (:func:`check_image_size`), the decoders' own messages kept off the terminal, and a
    :class:`FileFormatError` quoting the first of them when nothing could be decoded."""
    import cv2

    path = Path(path)
    check_image_size(path)
    flags = cv2.IMREAD_UNCHANGED if flags is None else flags
    with quiet() as lines:
        raw = cv2.imread(str(path), flags)
    if raw is None:
        detail = next((line for line in lines if "rror" in line), lines[0] if lines else "")
        raise FileFormatError(f"{path}: not a readable {what} (OpenCV could not decode it"
                              + (f": {detail[:160]})" if detail else ")"))
    return raw


def _read_cv(path: Path, transfer: Transfer) -> tuple[np.ndarray, dict[str, Any]]:
    import cv2

    raw = imread(path, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    if raw.ndim == 3:
        if raw.shape[2] == 4:
            raw = raw[..., :3]
        raw = raw[..., ::-1]  # OpenCV is BGR
    else:
        raw = raw[..., None]
    meta: dict[str, Any] = {"format": path.suffix.lower().lstrip("."), "bit_depth": None}
    if np.issubdtype(raw.dtype, np.floating):  # Radiance .hdr (or float TIFF): linear already
        return np.ascontiguousarray(raw, dtype=np.float32), meta | {"transfer": "linear"}
    if raw.dtype == np.uint8:
        meta["bit_depth"] = 8
    elif raw.dtype == np.uint16:
        meta["bit_depth"] = 16
    else:
        raise FileFormatError(f"{path}: expected 8- or 16-bit integer or float samples, found {raw.dtype}")
    scaled = raw.astype(np.float32) / np.float32(np.iinfo(raw.dtype).max)
    if transfer == "auto":
        transfer = "srgb"
    if transfer == "srgb":
        scaled = srgb_decode(scaled)
    elif transfer != "linear":
        raise InputError(f"transfer: expected auto, srgb or linear; got {transfer!r}")
    meta["transfer"] = transfer
    meta["saturation_level"] = 1.0
    return np.ascontiguousarray(scaled, dtype=np.float32), meta


def read_image(
    path: str | os.PathLike,
    *,
    part: int | str | None = None,
    view: str | None = None,
    transfer: Transfer = "auto",
    nonfinite: Literal["raise", "zero", "clip"] = "raise",
    negative: Literal["raise", "clip", "keep"] = "clip",
) -> tuple[np.ndarray, dict[str, Any]]:
    """Read one image as linear float32 ``(H, W, C)``.

    Parameters
    ----------
    path : str or os.PathLike
        An ``.exr``, ``.hdr``/``.pic``, ``.png``, ``.tif``/``.tiff`` or ``.jpg``/``.jpeg`` file.
    part : int or str, optional
        OpenEXR part index or name (default: the first part with R,G,B or Y channels).
    view : str, optional
        OpenEXR view name (multi-part ``view`` attribute, or single-part ``multiView``).
    transfer : {"auto", "srgb", "linear"}, default "auto"
        How 8/16-bit values are decoded: ``"srgb"`` (what ``"auto"`` means) or ``"linear"``
        (values divided by the maximum code). Float formats are linear already.
    nonfinite : {"raise", "zero", "clip"}, default "raise"
        NaN/Inf policy, see :func:`lfproc.lightfield.clean_nonfinite`.
    negative : {"clip", "raise", "keep"}, default "clip"
        Negative-value policy (lossy EXR compression leaves tiny negatives; the number clipped
        is reported in the metadata as ``clipped_negative``).

    Returns
    -------
    image : ndarray of shape (H, W, C), float32
        Linear values; C is 3 (RGB) or 1 (grey).
    meta : dict
        ``format``, ``transfer``, ``saturation_level`` (1.0 for integer formats), EXR part
        details, ``clipped_negative`` and ``replaced_nonfinite`` counts.

    Raises
    ------
    lfproc.errors.MissingFileError
        ``path`` does not exist.
    lfproc.errors.FileFormatError
        ``path`` is a folder, has an unknown suffix or cannot be decoded.
    lfproc.errors.InputError
        Non-finite or negative values under the ``"raise"`` policy, or a bad ``transfer``.

    Examples
    --------
    >>> import numpy as np
    >>> import lfproc
    >>> _ = lfproc.write_image("ramp.png", np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4, 1))
    >>> image, meta = lfproc.read_image("ramp.png")
    >>> image.shape, image.dtype, meta["transfer"]
    ((3, 4, 1), dtype('float32'), 'srgb')
    >>> float(image.max())
    1.0
    """
    path = Path(path)
    _require_file(path)
    suffix = path.suffix.lower()
    if suffix == ".exr":
        image, meta = _read_exr(path, part, view)
    elif suffix in (".hdr", ".pic") + LDR_SUFFIXES:
        image, meta = _read_cv(path, transfer)
    else:
        raise FileFormatError(f"{path}: unknown image type {suffix!r}; expected one of {', '.join(IMAGE_SUFFIXES)}")
    image, counts = clean_nonfinite(image, policy=nonfinite, negative=negative, name=str(path))
    meta["clipped_negative"] = counts["negative"]
    meta["replaced_nonfinite"] = counts["nan"] + counts["inf"]
    return image, meta


def write_image(
    path: str | os.PathLike,
    image: np.ndarray,
    *,
    force: bool = False,
    dtype: Literal["float32", "half"] = "float32",
    bit_depth: Literal[8, 16] | None = None,
    transfer: Literal["srgb", "linear"] = "srgb",
    attributes: dict[str, Any] | None = None,
) -> Path:
    """Write ``(H, W, C)`` linear data atomically; the format follows the suffix.

    EXR: float32 or half, ZIP (lossless) compression, ``attributes`` added to the header.
    ``.hdr``: Radiance RGBE. PNG/TIFF/JPEG: ``bit_depth`` 8 or 16 (default 16 for TIFF, 8 for
    PNG and JPEG), values clipped to [0, 1] and sRGB-encoded unless ``transfer="linear"``.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; the suffix (``.exr``, ``.hdr``/``.pic``, ``.png``, ``.tif``/``.tiff``,
        ``.jpg``/``.jpeg``) picks the format.
    image : array_like of shape (H, W), (H, W, 1) or (H, W, 3)
        Linear values (grey or RGB).
    force : bool, default False
        Overwrite an existing file.
    dtype : {"float32", "half"}, default "float32"
        EXR sample type.
    bit_depth : {8, 16}, optional
        Integer formats' depth (JPEG: 8 only).
    transfer : {"srgb", "linear"}, default "srgb"
        Encoding of integer formats.
    attributes : dict, optional
        Extra EXR header attributes.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    lfproc.errors.OutputExistsError
        ``path`` exists and ``force`` is false.
    lfproc.errors.InputError
        A bad shape, suffix, ``dtype`` or ``bit_depth``, or a missing output folder.
    lfproc.errors.FileFormatError
        OpenCV could not write the file.

    Examples
    --------
    >>> import numpy as np
    >>> import lfproc
    >>> image = np.random.default_rng(0).random((5, 7, 3), dtype=np.float32) * 100
    >>> lfproc.write_image("hdr.exr", image)
    PosixPath('hdr.exr')
    >>> back, meta = lfproc.read_image("hdr.exr")
    >>> back.shape, bool(np.array_equal(back, image))
    ((5, 7, 3), True)
    """
    import cv2

    path = Path(path)
    image = np.asarray(image)
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[2] not in (1, 3):
        raise InputError(f"{path}: expected an image of shape (H, W, 1 or 3), got {image.shape}")
    suffix = path.suffix.lower()
    with atomic_file(path, force=force) as tmp:
        if suffix == ".exr":
            import OpenEXR

            np_dtype = {"float32": np.float32, "half": np.float16}.get(dtype)
            if np_dtype is None:
                raise InputError(f"dtype: expected float32 or half, got {dtype!r}")
            names = ("R", "G", "B") if image.shape[2] == 3 else ("Y",)
            channels = {n: np.ascontiguousarray(image[..., i], dtype=np_dtype) for i, n in enumerate(names)}
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            header.update(attributes or {})
            OpenEXR.File(header, channels).write(str(tmp))
        elif suffix in (".hdr", ".pic"):
            bgr = np.ascontiguousarray(np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[..., ::-1])
            if not cv2.imwrite(str(tmp), bgr.astype(np.float32)):
                raise FileFormatError(f"{path}: OpenCV could not write a Radiance file")
        elif suffix in LDR_SUFFIXES:
            depth = bit_depth or (16 if suffix in (".tif", ".tiff") else 8)
            if depth not in (8, 16) or (depth == 16 and suffix in (".jpg", ".jpeg")):
                raise InputError(f"{path}: bit depth {depth} is not available for {suffix} (8 or 16; JPEG only 8)")
            values = np.clip(image, 0, 1)
            if transfer == "srgb":
                values = srgb_encode(values)
            maxval = 255 if depth == 8 else 65535
            ints = np.round(values * maxval).astype(np.uint8 if depth == 8 else np.uint16)
            ints = ints[..., 0] if ints.shape[2] == 1 else ints[..., ::-1]
            if not cv2.imwrite(str(tmp), np.ascontiguousarray(ints)):
                raise FileFormatError(f"{path}: OpenCV could not write this image")
        else:
            raise InputError(f"{path}: unknown image type {suffix!r}; expected one of {', '.join(IMAGE_SUFFIXES)}")
    return path
