"""Light-field files.

Layouts lfproc reads and writes:

* **One OpenEXR file** (``.exr``), one part per view named ``view_RR_CC`` (RR angular
  row, CC angular column, from 01), channels ``R, G, B`` (or ``Y``), optional variance
  channels ``var.R, var.G, var.B`` and a ``disparity`` channel in the centre view; ZIP
  (lossless) compression; every part carries the string attribute ``lfproc`` (JSON:
  lfproc version, angular shape, view index, units, colour space, exposure, ISO, source
  and free attributes) and ``lfproc_version``.
* **A folder of views** ``view_RR_CC.<ext>`` with ext ``exr``, ``png``, ``tif``/``tiff``
  or ``hdr``; ``RR`` and ``CC`` are the 1-based angular row and column (:func:`view_name`).
  8/16-bit views are sRGB decoded to linear. lfproc also writes ``lightfield.json`` (the same
  metadata) and, when the light field has one, the centre view's disparity ``disparity.pfm`` next to them; folders
  without them get defaults. Any name that is not ``.exr`` or an image suffix is a folder
  (``out``, ``out.views``). Writing 8/16-bit views clips values above 1 and warns
  (:class:`~lfproc.errors.SaturationWarning`).
* **A single image file** as output (``.hdr``, ``.png``, ``.tif``...): a 1 x 1 light field.
* **A single image** (any format of :func:`lfproc.io.read_image`): a 1 x 1 light field.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .. import _untrusted as ut
from .._shared.frozen import freeze
from .._version import __version__
from ..errors import FileFormatError, InputError, MissingFileError, option_name, SaturationWarning, ShapeError
from ..lightfield import LightField, clean_nonfinite
from ._atomic import atomic_dir, atomic_file, check_output
from .images import IMAGE_SUFFIXES, read_image, write_image
from ._exr import open_exr

__all__ = ["read_lightfield", "write_lightfield", "view_name", "parse_view_name", "lightfield_metadata", "SIDECAR"]

SIDECAR = "lightfield.json"
#: The centre view's disparity in a folder of views (greyscale PFM, pixels per view step).
DISPARITY_FILE = "disparity.pfm"
_VIEW_RE = re.compile(r"^view_(\d{2,})_(\d{2,})$")


def view_name(v: int, u: int) -> str:
    """File or part name of view ``(v, u)`` (0-based indices): ``view_RR_CC`` from 01.

    Parameters
    ----------
    v, u : int
        0-based angular row and column.

    Returns
    -------
    str
        ``view_RR_CC`` with 1-based, zero-padded (at least two digits) row and column.

    See Also
    --------
    parse_view_name : the inverse.

    Examples
    --------
    >>> from lfproc.io import parse_view_name, view_name
    >>> view_name(0, 4), view_name(11, 2)
    ('view_01_05', 'view_12_03')
    >>> parse_view_name(view_name(11, 2))
    (11, 2)
    """
    return f"view_{v + 1:02d}_{u + 1:02d}"


def parse_view_name(stem: str) -> tuple[int, int] | None:
    """0-based ``(v, u)`` from ``view_RR_CC``, or None when the name is not a view name.

    Parameters
    ----------
    stem : str
        A file name without its suffix (or an EXR part name).

    Returns
    -------
    tuple of int or None
        ``(v, u)``, 0-based; None for any other name (including ``view_00_..``).

    Examples
    --------
    >>> from lfproc.io import parse_view_name
    >>> parse_view_name("view_03_05"), parse_view_name("view_00_01"), parse_view_name("centre")
    ((2, 4), None, None)
    """
    m = _VIEW_RE.match(stem)
    if not m:
        return None
    v, u = int(m.group(1)) - 1, int(m.group(2)) - 1
    return (v, u) if v >= 0 and u >= 0 else None


def lightfield_metadata(lf: LightField) -> dict[str, Any]:
    """The JSON-serialisable metadata lfproc stores with a light field."""
    return {
        "lfproc_version": __version__,
        "views": list(lf.views),
        "size": list(lf.size),
        "channels": lf.channels,
        "units": lf.units,
        "colour_space": lf.colour_space,
        "exposure_s": lf.exposure_s,
        "iso": lf.iso,
        "saturation_level": lf.saturation_level,
        "source": lf.source,
        "attrs": dict(lf.attrs),
    }


def _meta_kwargs(meta: dict[str, Any]) -> dict[str, Any]:
    keys = ("units", "colour_space", "exposure_s", "iso", "saturation_level", "source", "attrs")
    return {k: meta[k] for k in keys if meta.get(k) is not None}


# -- reading ---------------------------------------------------------------------------

def _exr_metadata(path: Path, text: Any) -> dict[str, Any]:
    """The ``lfproc`` attribute of a light-field EXR, every field checked."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    if not isinstance(text, str):
        raise FileFormatError(f"{path}: the 'lfproc' attribute is not a string")
    doc = ut.Node(ut.parse_json(text, source=path, what="the 'lfproc' attribute"), path, error=FileFormatError)
    return _checked_metadata(doc, views=True)


def _checked_metadata(doc: ut.Node, *, views: bool) -> dict[str, Any]:
    """Light-field metadata (EXR attribute or ``lightfield.json``) with every field checked."""
    doc.as_dict()
    out: dict[str, Any] = {}
    if views:
        out["views"] = tuple(doc["views"].as_ints(length=2, low=1, high=MAX_VIEWS_PER_SIDE))
    transfer = doc.opt_str("transfer", max_len=32)
    if transfer is not None:
        out["transfer"] = transfer
    for key in ("units", "colour_space", "source"):
        value = doc.opt_str(key, max_len=4096)
        if value is not None:
            out[key] = value
    for key in ("exposure_s", "iso", "saturation_level"):
        value = doc.opt_float(key, low=0, strict_low=True)
        if value is not None:
            out[key] = value
    attrs = doc.get("attrs")
    if attrs is not None:
        out["attrs"] = attrs.as_dict()
    return out


#: Most views per side of a light field file (the HCI archive has 9, Stanford's 17).
MAX_VIEWS_PER_SIDE = 64


def _read_exr_lightfield(path: Path, nonfinite: str, negative: str) -> LightField | None:
    """Read a multi-part lfproc EXR; None when the file is not one (then it is an image)."""
    head = open_exr(path, header_only=True)
    if not any("lfproc" in p.header for p in head.parts):
        return None
    meta: dict[str, Any] | None = None
    expected: dict[tuple[int, int], int] = {}
    for i, part in enumerate(head.parts):
        idx = parse_view_name(part.name() or "")
        if idx is None or "lfproc" not in part.header:
            raise FileFormatError(f"{path}: part {part.name()!r} is not a view_RR_CC part of an lfproc light field")
        if idx in expected:
            raise FileFormatError(f"{path}: two parts are named {part.name()!r}")
        expected[idx] = i
        if meta is None:
            meta = _exr_metadata(path, part.header["lfproc"])
    if meta is None:  # open_exr refuses files without parts; kept as an error, not an assert
        raise FileFormatError(f"{path}: no view parts")
    nv, nu = meta["views"]
    missing = [view_name(v, u) for v in range(nv) for u in range(nu) if (v, u) not in expected]
    if missing or len(expected) != nv * nu:
        extra = [view_name(v, u) for v, u in expected if v >= nv or u >= nu]
        raise FileFormatError(f"{path}: the 'lfproc' attribute says {nv}x{nu} views; missing parts "
                              f"{', '.join(missing[:8]) or 'none'}{' ...' if len(missing) > 8 else ''}, "
                              f"unexpected parts {', '.join(extra[:8]) or 'none'}")
    f = open_exr(path)
    views = {idx: f.parts[i] for idx, i in expected.items()}
    first = views[(0, 0)]
    names = list(first.channels)
    colour = ["R", "G", "B"] if "R" in names else ["Y"]
    has_var = all(f"var.{c}" in names for c in colour)
    wanted = colour + ([f"var.{c}" for c in colour] if has_var else [])
    shape = None
    for (v, u), part in views.items():
        for c in wanted:
            pixels = part.channels[c].pixels if c in part.channels else None
            if not isinstance(pixels, np.ndarray) or pixels.ndim != 2:
                raise FileFormatError(f"{path}: part {view_name(v, u)} has no channel {c!r} (channels of "
                                      f"{view_name(0, 0)}: {', '.join(sorted(names))})")
            if shape is None:
                shape = pixels.shape
            elif pixels.shape != shape:
                raise FileFormatError(f"{path}: part {view_name(v, u)} channel {c!r} is {pixels.shape[1]} x "
                                      f"{pixels.shape[0]} pixels, {view_name(0, 0)} {shape[1]} x {shape[0]}")
    data = np.stack([np.stack([np.stack([views[(v, u)].channels[c].pixels for c in colour], -1) for u in range(nu)])
                     for v in range(nv)]).astype(np.float32, copy=False)
    variance = None
    if has_var:
        variance = np.stack([np.stack([np.stack([views[(v, u)].channels[f"var.{c}"].pixels for c in colour], -1)
                                       for u in range(nu)]) for v in range(nv)]).astype(np.float32, copy=False)
    centre = views[(nv // 2, nu // 2)]
    disparity = centre.channels["disparity"].pixels if "disparity" in centre.channels else None
    data, _ = clean_nonfinite(data, policy=nonfinite, negative=negative, name=str(path))
    try:
        return LightField(data=freeze(data), variance=None if variance is None else freeze(variance),
                          disparity=disparity, **_meta_kwargs(meta))
    except InputError as exc:
        raise FileFormatError(f"{path}: {exc}") from None


def _view_files(folder: Path) -> dict[tuple[int, int], Path]:
    found: dict[tuple[int, int], Path] = {}
    for p in sorted(folder.iterdir()):
        if p.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        idx = parse_view_name(p.stem)
        if idx is None:
            continue
        if idx in found:
            raise FileFormatError(f"{folder}: two files for view {p.stem}: {found[idx].name} and {p.name}")
        found[idx] = p
    return found


def _read_folder(folder: Path, nonfinite: str, negative: str, transfer: str) -> LightField:
    files = _view_files(folder)
    if not files:
        raise FileFormatError(
            f"{folder}: expected view files named view_RR_CC.<ext> ({', '.join(IMAGE_SUFFIXES)}), found none"
        )
    nv = max(v for v, _ in files) + 1
    nu = max(u for _, u in files) + 1
    missing = [view_name(v, u) for v in range(nv) for u in range(nu) if (v, u) not in files]
    if missing:
        raise FileFormatError(f"{folder}: the {nv}x{nu} grid of views is incomplete; missing {', '.join(missing[:6])}"
                              + (" ..." if len(missing) > 6 else ""))
    meta: dict[str, Any] = {}
    sidecar = folder / SIDECAR
    if sidecar.exists():
        meta = _checked_metadata(ut.load_json(sidecar), views=False)
    if transfer == "auto" and meta.get("transfer") in ("srgb", "linear"):
        transfer = meta["transfer"]
    images = {}
    shape = None
    sat = None
    for idx, p in files.items():
        img, m = read_image(p, nonfinite=nonfinite, negative=negative, transfer=transfer)  # type: ignore[arg-type]
        if shape is None:
            shape, first = img.shape, p
            sat = m.get("saturation_level")
        elif img.shape != shape:
            raise ShapeError(f"{p}: view size {img.shape} differs from {first.name} {shape}")
        images[idx] = img
    data = np.stack([np.stack([images[(v, u)] for u in range(nu)]) for v in range(nv)])
    kwargs = _meta_kwargs(meta)
    kwargs.setdefault("saturation_level", sat)
    kwargs.setdefault("source", str(folder))
    disparity = None
    if (folder / DISPARITY_FILE).exists():
        disparity = _read_pfm(folder / DISPARITY_FILE)
        if disparity.shape != data.shape[2:4]:
            raise ShapeError(f"{folder / DISPARITY_FILE}: disparity size {disparity.shape} differs from the views "
                             f"{data.shape[2:4]}")
    try:
        return LightField(data=freeze(data), disparity=disparity, **kwargs)
    except InputError as exc:
        raise FileFormatError(f"{sidecar}: {exc}") from None


def read_lightfield(
    path: str | os.PathLike,
    *,
    nonfinite: Literal["raise", "zero", "clip"] = "raise",
    negative: Literal["raise", "clip", "keep"] = "clip",
    transfer: Literal["auto", "srgb", "linear"] = "auto",
    part: int | str | None = None,
) -> LightField:
    """Read a light field from an lfproc EXR, a folder of views or a single image.

    Parameters
    ----------
    path : str or os.PathLike
        An lfproc multi-part EXR, a folder of ``view_RR_CC`` files (with or without
        ``lightfield.json``) or a single image (read as a 1 x 1 light field); see the module
        documentation for the layouts.
    nonfinite : {"raise", "zero", "clip"}, default "raise"
        NaN/Inf policy (see :func:`lfproc.lightfield.clean_nonfinite`).
    negative : {"clip", "raise", "keep"}, default "clip"
        Negative-value policy.
    transfer : {"auto", "srgb", "linear"}, default "auto"
        Decoding of 8/16-bit views (``"auto"`` = sRGB).
    part : int or str, optional
        For a single multi-part EXR image, which part to read.

    Returns
    -------
    LightField
        Data, variance, disparity and metadata as stored.

    Raises
    ------
    lfproc.errors.MissingFileError
        ``path`` does not exist.
    lfproc.errors.FileFormatError
        Not a light field or image, or a malformed one.
    lfproc.errors.InputError
        Values refused by the ``nonfinite``/``negative`` policies.

    Examples
    --------
    >>> import numpy as np
    >>> import lfproc
    >>> lf = lfproc.LightField(np.random.default_rng(0).random((3, 3, 4, 5, 3)), units="cd/m2")
    >>> lfproc.write_lightfield(lf, "lf.exr")
    PosixPath('lf.exr')
    >>> back = lfproc.read_lightfield("lf.exr")
    >>> back.shape, back.units, bool(np.array_equal(back.data, lf.data))
    ((3, 3, 4, 5, 3), 'cd/m2', True)
    """
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such file or folder")
    if path.is_dir():
        return _read_folder(path, nonfinite, negative, transfer)
    if path.suffix.lower() == ".exr" and part is None:
        lf = _read_exr_lightfield(path, nonfinite, negative)
        if lf is not None:
            return lf
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise FileFormatError(
            f"{path}: not a light field or image; expected a folder of view_RR_CC files, "
            f"or a file ending in {', '.join(IMAGE_SUFFIXES)}"
        )
    image, meta = read_image(path, part=part, nonfinite=nonfinite, negative=negative, transfer=transfer)
    attrs = {k: meta[k] for k in ("format", "part_name", "view") if meta.get(k) is not None}
    return LightField(
        data=freeze(image)[None, None],
        saturation_level=meta.get("saturation_level"),
        source=str(path),
        attrs=attrs,
    )


# -- writing ---------------------------------------------------------------------------

FolderFormat = Literal["exr", "png", "png16", "tiff", "hdr"]
_FOLDER_SUFFIX = {"exr": (".exr", None), "png": (".png", 8), "png16": (".png", 16), "tiff": (".tif", 16),
                  "hdr": (".hdr", None)}


def _exr_parts(lf: LightField, dtype: str) -> list:
    import OpenEXR

    np_dtype = {"float32": np.float32, "half": np.float16}.get(dtype)
    if np_dtype is None:
        raise InputError(f"dtype: expected float32 or half, got {dtype!r}")
    if lf.channels not in (1, 3):
        raise ShapeError(f"EXR light fields hold 1 or 3 channels, this one has {lf.channels}")
    names = ("R", "G", "B") if lf.channels == 3 else ("Y",)
    meta = lightfield_metadata(lf)
    parts = []
    nv, nu = lf.views
    for v in range(nv):
        for u in range(nu):
            chans = {n: np.ascontiguousarray(lf.data[v, u, :, :, i], dtype=np_dtype) for i, n in enumerate(names)}
            if lf.variance is not None:
                chans.update({f"var.{n}": np.ascontiguousarray(lf.variance[v, u, :, :, i], dtype=np_dtype)
                              for i, n in enumerate(names)})
            if lf.disparity is not None and (v, u) == lf.centre_index:
                chans["disparity"] = np.ascontiguousarray(lf.disparity, dtype=np.float32)
            header = {
                "compression": OpenEXR.ZIP_COMPRESSION,
                "type": OpenEXR.scanlineimage,
                "lfproc": json.dumps(meta | {"view": [v, u]}),
                "lfproc_version": __version__,
            }
            parts.append(OpenEXR.Part(header, chans, view_name(v, u)))
    return parts


def write_lightfield(
    lf: LightField,
    path: str | os.PathLike,
    *,
    force: bool = False,
    dtype: Literal["float32", "half"] = "float32",
    folder_format: FolderFormat = "exr",
    transfer: Literal["srgb", "linear"] = "srgb",
) -> Path:
    """Write a light field atomically.

    ``path`` ending in ``.exr``: one multi-part OpenEXR file. Any other path: a folder of
    ``view_RR_CC`` files in ``folder_format`` (``exr``, ``png`` (8-bit), ``png16``, ``tiff``
    (16-bit) or ``hdr``) plus ``lightfield.json``. 8/16-bit views are clipped to [0, 1]
    and sRGB-encoded (``transfer="linear"`` keeps them linear). float32 EXR round-trips
    bit-exactly. A path with an image suffix other than ``.exr`` holds a 1 x 1 light field.

    Parameters
    ----------
    lf : LightField
        The light field (its variance, disparity and metadata are written too).
    path : str or os.PathLike
        ``*.exr`` (one multi-part file), an image file (one view) or a folder name.
    force : bool, default False
        Replace an existing file or folder.
    dtype : {"float32", "half"}, default "float32"
        EXR sample type.
    folder_format : {"exr", "png", "png16", "tiff", "hdr"}, default "exr"
        Format of the views in a folder.
    transfer : {"srgb", "linear"}, default "srgb"
        Encoding of 8/16-bit views.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    lfproc.errors.OutputExistsError
        ``path`` exists and ``force`` is false.
    lfproc.errors.InputError
        ``lf`` is not a LightField, a bad ``folder_format`` or ``dtype``, or several views
        for a single-image path.

    Warns
    -----
    lfproc.errors.SaturationWarning
        Values above 1 are clipped by an 8/16-bit format.

    Examples
    --------
    >>> import numpy as np
    >>> import lfproc
    >>> lf = lfproc.LightField(np.random.default_rng(1).random((2, 2, 3, 4, 3)) * 0.9)
    >>> lfproc.write_lightfield(lf, "views", folder_format="png16")
    PosixPath('views')
    >>> import os
    >>> sorted(os.listdir("views"))
    ['lightfield.json', 'view_01_01.png', 'view_01_02.png', 'view_02_01.png', 'view_02_02.png']
    >>> back = lfproc.read_lightfield("views")
    >>> back.views, float(np.abs(back.data - lf.data).max()) < 1e-3
    ((2, 2), True)
    """
    if not isinstance(lf, LightField):
        raise InputError(f"write_lightfield: expected a LightField, got {type(lf).__name__}")
    path = Path(path)
    suffix_in = path.suffix.lower()
    if suffix_in == ".exr":
        import OpenEXR

        parts = _exr_parts(lf, dtype)
        with atomic_file(path, force=force) as tmp:
            OpenEXR.File(parts).write(str(tmp))
        return path
    if folder_format not in _FOLDER_SUFFIX:
        raise InputError(f"format: expected one of {', '.join(_FOLDER_SUFFIX)}; got {folder_format!r}")
    if suffix_in in IMAGE_SUFFIXES:  # one image file: a 1 x 1 light field
        if lf.views != (1, 1):
            raise InputError(
                f"{path}: a single image holds one view, this light field has {lf.views[0]}x{lf.views[1]}; write a "
                ".exr file or a folder (a name without an image suffix, e.g. out or out.views)"
            )
        depth = None if suffix_in in (".hdr", ".pic") else (
            16 if suffix_in in (".tif", ".tiff") or folder_format in ("png16", "tiff") else 8)
        if depth:
            _warn_clipping(lf, path)
        write_image(path, lf.data[0, 0], force=force, dtype=dtype, bit_depth=depth, transfer=transfer)
        return path
    suffix, depth = _FOLDER_SUFFIX[folder_format]
    check_output(path, force=force)
    if depth:
        _warn_clipping(lf, path)
    meta = lightfield_metadata(lf) | {"folder_format": folder_format, "transfer": transfer if depth else "linear"}
    if depth:  # values are clipped to [0, 1] by the 8/16-bit encoding
        meta["saturation_level"] = 1.0
    if lf.disparity is not None:
        meta["disparity_file"] = DISPARITY_FILE
    with atomic_dir(path, force=force) as tmp:
        nv, nu = lf.views
        for v in range(nv):
            for u in range(nu):
                attrs = {"lfproc": json.dumps(meta | {"view": [v, u]}), "lfproc_version": __version__}
                write_image(tmp / f"{view_name(v, u)}{suffix}", lf.data[v, u], dtype=dtype, bit_depth=depth,
                            transfer=transfer, attributes=attrs if suffix == ".exr" else None)
        if lf.disparity is not None:
            _write_pfm(tmp / DISPARITY_FILE, lf.disparity)
        (tmp / SIDECAR).write_text(json.dumps(meta, indent=2))
    return path


_TONEMAP_PYTHON = "lfproc.tonemap.display_transform(lf, exposure_ev=, tonemap=)"


def _warn_clipping(lf: LightField, path: Path) -> None:
    import warnings

    frac = float(np.mean(lf.data > 1.0))
    if frac > 0:
        warnings.warn(SaturationWarning(
            f"{path}: {frac:.1%} of the samples exceed 1 and are clipped by the 8/16-bit encoding "
            f"(lower the exposure or tone map: {option_name(_TONEMAP_PYTHON, '--exposure-ev, --tonemap')})"),
            stacklevel=3)


def _write_pfm(path: Path, disparity: np.ndarray) -> None:
    """Little-endian greyscale PFM (bottom row first, as the format says; the HCI benchmark's layout)."""
    d = np.ascontiguousarray(np.flipud(np.asarray(disparity, dtype="<f4")))
    with open(path, "wb") as fh:
        fh.write(f"Pf\n{d.shape[1]} {d.shape[0]}\n-1.0\n".encode("ascii"))
        fh.write(d.tobytes())


def _read_pfm(path: Path) -> np.ndarray:
    """Greyscale PFM to a (H, W) float32 array, top row first."""
    # untrusted: the header's sizes are checked against the limits and the bytes present
    raw = ut.read_bytes(path, max_bytes=ut.MAX_ARRAY_BYTES + 256)
    try:
        head, rest = raw.split(b"\n", 1)
        dims, rest = rest.split(b"\n", 1)
        scale, body = rest.split(b"\n", 1)
        if head.strip() != b"Pf":
            raise ValueError("not greyscale")
        w, h = (int(x) for x in dims.split())
        scale_value = float(scale)
        if not math.isfinite(scale_value) or scale_value == 0:
            raise ValueError(f"scale {scale_value!r}")
        endian = "<" if scale_value < 0 else ">"
    except ValueError as exc:
        raise FileFormatError(f"{path}: not a greyscale PFM file ({exc})") from None
    h, w = ut.check_dims((h, w), source=path, what="disparity map")
    if len(body) < 4 * w * h:
        raise FileFormatError(f"{path}: truncated PFM file: {w} x {h} floats need {4 * w * h} bytes, "
                              f"found {len(body)}")
    d = np.frombuffer(body, dtype=f"{endian}f4", count=w * h).reshape(h, w)
    return np.flipud(d).astype(np.float32)
