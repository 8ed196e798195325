"""Lytro raw captures: Illum ``.LFR``, F01 raw ``.lfp`` and unpacked ``.RAW`` + ``.TXT``/``.json``.

:func:`read_capture` returns the raw lenslet image as ``uint16`` counts (DN) with the
metadata a decoder needs, read from wherever each camera keeps it:

===================  ==========================================  =========================================
field                Illum ``.LFR`` (``camera.model`` ILLUM)      F01 / white-image ``.TXT``
===================  ==========================================  =========================================
levels               ``image.pixelFormat.{black,white}``          ``image.rawDetails.pixelFormat``
mosaic               ``image.mosaic``                             ``image.rawDetails.mosaic``
packing              ``image.pixelPacking``                       ``image.rawDetails.pixelPacking``
CCM                  ``image.color.ccm``                          ``image.color.ccmRgbToSrgbArray``
ISO                  ``image.iso``                                ``devices.sensor.iso``
===================  ==========================================  =========================================

Exposure time is ``devices.shutter.frameExposureDuration`` (seconds), zoom/focus steps
``devices.lens.{zoomStep,focusStep}``, the serial ``camera.serialNumber`` of the private
metadata. The camera model is normalised to ``"B01"`` (Illum; ``ILLUM`` in pictures, ``B01`` in
white images) or ``"F01"`` (first generation).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import _untrusted as ut
from ..errors import LfpFormatError, MissingFileError
from .container import LFP_MAGIC, LfpContainer, _norm_sha1, _parse_json, _storage_entries, is_lfp, read_lfp
from .raw import raw_byte_count, unpack_raw
from .._shared.reprs import short_repr
from .extract import contents_summary, lfp_contents, require_raw_image

__all__ = [
    "LytroCapture",
    "read_capture",
    "describe_lytro",
    "normalise_camera_model",
    "frame_fields",
    "cfa_from_mosaic",
    "find_metadata_file",
    "split_txt_metadata",
]

CAMERA_MODELS = {"ILLUM": "B01", "B01": "B01", "F01": "F01"}


@short_repr
@dataclass(frozen=True)
class LytroCapture:
    """A Lytro raw capture (lenslet image) and its metadata, as :func:`read_capture` returns it.

    Parameters
    ----------
    raw : ndarray of shape (H, W), uint16
        Raw counts (DN), row-major from the top-left pixel.
    camera_model : {"B01", "F01"}
        ``"B01"`` = Illum, ``"F01"`` = first generation.
    serial : str or None
        Camera serial number (private metadata ``camera.serialNumber``).
    black_level : dict
        Black level in DN per Bayer channel ``{"r", "gr", "gb", "b"}``.
    white_level : float
        White (saturation) level in DN (the ``gr`` entry, as the Light Field Toolbox uses).
    cfa_pattern : str
        Bayer pattern row-major from the top-left pixel (``"GRBG"`` Illum, ``"BGGR"`` F01).
    ccm : ndarray of shape (3, 3) or None
        Colour matrix, camera RGB -> sRGB linear: ``out = ccm @ rgb`` (rows sum to ~1).
    white_balance : dict or None
        White-balance gains ``{"r", "g", "b"}`` (``g`` = the ``gr`` gain).
    exposure_bias_ev : float
        ``image.modulationExposureBias`` in EV (0 when absent).
    exposure_s : float or None
        Frame exposure duration in seconds.
    iso : float or None
        ISO speed; None when the file has none.
    zoom_step, focus_step : int or None
        Lens motor positions (white-image selection).
    geometry_hash : str or None
        ``"sha1-..."`` of the geometry-correction data (Illum ``geometryCorrectionRef``; F01
        ``picture.derivationArray[0]``), lower case; None when absent.
    metadata : dict
        The frame metadata as stored.
    path : Path
        The file read.
    private_metadata : dict
        The private frame metadata (``{}`` when absent).
    white_levels : dict
        White level per Bayer channel.
    limit_exposure_bias_ev : float
        ``image.limitExposureBias`` in EV.
    sha1_verified : bool or None
        For containers: whether every section's SHA-1 was checked (None for ``.RAW`` files).

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.lytro import read_capture
    >>> from lfproc.lytro.container import illum_metadata, write_lfr
    >>> raw = np.random.default_rng(0).integers(64, 1024, size=(8, 12), dtype=np.uint16)
    >>> meta = illum_metadata(height=8, width=12, exposure_s=0.01, iso=200)
    >>> _ = write_lfr("tiny.LFR", raw=raw, metadata=meta, serial="B5000000042")
    >>> cap = read_capture("tiny.LFR")
    >>> cap.shape, cap.camera_model, cap.serial, cap.cfa_pattern, cap.iso, cap.exposure_s
    ((8, 12), 'B01', 'B5000000042', 'GRBG', 200.0, 0.01)
    >>> cap.black_level_2x2().tolist(), cap.white_level, bool(np.array_equal(cap.raw, raw))
    ([[64.0, 64.0], [64.0, 64.0]], 1023.0, True)
    """

    raw: np.ndarray = field(repr=False, compare=False)
    camera_model: str
    serial: str | None
    black_level: dict[str, float]
    white_level: float
    cfa_pattern: str
    ccm: np.ndarray | None
    white_balance: dict[str, float] | None
    exposure_bias_ev: float
    exposure_s: float | None
    iso: float | None
    zoom_step: int | None
    focus_step: int | None
    geometry_hash: str | None
    metadata: dict[str, Any] = field(repr=False)
    path: Path | None = None
    private_metadata: dict[str, Any] = field(default_factory=dict, repr=False)
    white_levels: dict[str, float] = field(default_factory=dict, repr=False)
    limit_exposure_bias_ev: float = 0.0
    sha1_verified: bool | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the raw image."""
        return tuple(self.raw.shape)

    def black_level_2x2(self) -> np.ndarray:
        """Black levels as a 2x2 array laid out like :attr:`cfa_pattern` (``[0, 0]`` = top-left)."""
        return _levels_2x2(self.black_level, self.metadata)

    def white_level_2x2(self) -> np.ndarray:
        """White levels as a 2x2 array laid out like :attr:`cfa_pattern`."""
        return _levels_2x2(self.white_levels or {c: self.white_level for c in "r gr gb b".split()}, self.metadata)


# -- metadata helpers ----------------------------------------------------------------------
def _get(obj: Any, *keys, default=None):
    for key in keys:
        if isinstance(obj, dict) and key in obj:
            obj = obj[key]
        elif isinstance(obj, list) and isinstance(key, int) and -len(obj) <= key < len(obj):
            obj = obj[key]
        else:
            return default
    return obj


def normalise_camera_model(model: Any, *, source=None) -> str:
    """``"ILLUM"``/``"B01"`` -> ``"B01"``, ``"F01"`` -> ``"F01"``; anything else is an error.

    Raises
    ------
    LfpFormatError
        Naming the unknown model (and the file when ``source`` is given).
    """
    key = str(model).strip().upper() if model is not None else None
    if key in CAMERA_MODELS:
        return CAMERA_MODELS[key]
    where = f"{source}: " if source is not None else ""
    raise LfpFormatError(f"{where}unknown camera model {model!r}: lfproc reads Lytro Illum ('ILLUM'/'B01') "
                         "and first-generation ('F01') files")


def _meta_node(metadata: Any, source) -> ut.Node:
    node = metadata if isinstance(metadata, ut.Node) else ut.Node(metadata, source, error=LfpFormatError)
    node.as_dict()
    return node


def _tile_and_ulp(metadata: Any, source=None) -> tuple[str, str]:
    meta = _meta_node(metadata, source)
    mosaic = meta.first("image.mosaic", "image.rawDetails.mosaic", "devices.sensor.mosaic")
    if mosaic is None:
        return "r,gr:gb,b", ""
    return (mosaic.opt_str("tile", "r,gr:gb,b", max_len=64), mosaic.opt_str("upperLeftPixel", "", max_len=16))


_BAYER_NAMES = {"r": "R", "gr": "G", "gb": "G", "b": "B"}


def _tile_rows(tile: str, source=None) -> list[list[str]]:
    rows = [r.split(",") for r in str(tile).replace(" ", "").split(":")]
    if len(rows) != 2 or any(len(r) != 2 for r in rows) or sorted(sum(rows, [])) != sorted(_BAYER_NAMES):
        raise LfpFormatError(f"{f'{source}: ' if source else ''}mosaic tile {ut.show(tile)} is not a 2x2 Bayer tile "
                             "of r, gr, gb, b like 'r,gr:gb,b'")
    return rows


def cfa_from_mosaic(tile: str, upper_left_pixel: str, *, source=None) -> str:
    """Row-major Bayer pattern from Lytro ``mosaic.tile`` and ``mosaic.upperLeftPixel``.

    Examples
    --------
    >>> cfa_from_mosaic("r,gr:gb,b", "gr")
    'GRBG'
    >>> cfa_from_mosaic("r,gr:gb,b", "b")
    'BGGR'
    """
    rows = _tile_rows(tile, source)
    where = [(i, j) for i in range(2) for j in range(2) if rows[i][j] == upper_left_pixel]
    if not where:
        raise LfpFormatError(f"{f'{source}: ' if source else ''}mosaic upperLeftPixel {ut.show(upper_left_pixel)} "
                             f"is not in tile {ut.show(tile)}")
    i0, j0 = where[0]
    return "".join(_BAYER_NAMES[rows[(i0 + y) % 2][(j0 + x) % 2]] for y in range(2) for x in range(2))


def _levels_2x2(levels: dict[str, float], metadata: dict) -> np.ndarray:
    tile, ulp = _tile_and_ulp(metadata)
    rows = _tile_rows(tile)
    i0, j0 = next(((i, j) for i in range(2) for j in range(2) if rows[i][j] == (ulp or "gr")), (0, 0))
    return np.array([[float(levels[rows[(i0 + y) % 2][(j0 + x) % 2]]) for x in range(2)] for y in range(2)])


#: Largest DN level of a Lytro raw (16-bit words at most).
_MAX_DN = 65535.0


def _levels(fmt: ut.Node, key: str) -> dict[str, float]:
    node = fmt[key]
    node.as_dict()
    out = {}
    for c in ("r", "gr", "gb", "b"):
        value = node.get(c) or node.get("gr")
        if value is None:
            raise node.fail(f"missing the level of channel 'gr' (needed for {c!r})")
        out[c] = value.as_float(low=0, high=_MAX_DN)
    return out


def frame_fields(metadata: dict[str, Any], private_metadata: dict[str, Any] | None, *, source=None) -> dict[str, Any]:
    """The capture fields of :class:`LytroCapture` (all but ``raw``/``path``) from frame metadata.

    Works for Illum picture metadata, Illum/F01 white-image metadata and F01 frame metadata.
    Every value is checked for type, range and finiteness (:mod:`lfproc._untrusted`); an
    error names the file and the field.
    """
    meta = _meta_node(metadata, source)
    model_node = meta.at("camera.model", None)
    model = normalise_camera_model(model_node.value if model_node is not None else None, source=source)
    image = meta.opt_dict("image")
    fmt = image.get("pixelFormat") or image.at("rawDetails.pixelFormat", None)
    if fmt is None or not fmt.is_dict() or "black" not in fmt.value or "white" not in fmt.value:
        raise LfpFormatError(f"{source}: metadata has no black/white levels "
                             "(image.pixelFormat or image.rawDetails.pixelFormat)")
    black = _levels(fmt, "black")
    whites = _levels(fmt, "white")
    for c in ("r", "gr", "gb", "b"):
        if whites[c] <= black[c]:
            raise fmt.fail(f"white level {whites[c]:g} of channel {c!r} is not above its black level {black[c]:g}")
    color = image.opt_dict("color")
    ccm_node = color.get("ccm") if model == "B01" and color.has("ccm") and color.value["ccm"] else \
        color.get("ccmRgbToSrgbArray")
    ccm = None
    if ccm_node is not None:
        ccm = np.asarray(ccm_node.as_floats(length=9, low=-1e3, high=1e3), dtype=np.float64).reshape(3, 3)
    wbg = color.get("whiteBalanceGain")
    wb = None
    if wbg is not None and wbg.as_dict():
        gain = dict(low=0, strict_low=True, high=1e3)
        g = wbg.get("gr") or wbg.get("gb")
        wb = {"r": wbg["r"].as_float(**gain), "g": 1.0 if g is None else g.as_float(**gain),
              "b": wbg["b"].as_float(**gain)}
    iso_node = image.get("iso") or meta.at("devices.sensor.iso", None)
    iso = None if iso_node is None else iso_node.as_float(low=0, strict_low=True, high=1e7)
    shutter = meta.at("devices.shutter", None) or ut.Node({}, source, "devices.shutter", LfpFormatError)
    exposure_node = shutter.get("frameExposureDuration") or shutter.get("pixelExposureDuration")
    exposure = None if exposure_node is None else exposure_node.as_float(low=0, strict_low=True, high=1e6)
    lens = meta.at("devices.lens", None) or ut.Node({}, source, "devices.lens", LfpFormatError)
    steps = dict(low=-(1 << 31), high=1 << 31)
    serial = None
    if private_metadata:
        private = ut.Node(private_metadata, source, "privateMetadata", LfpFormatError)
        serial_node = private.at("camera.serialNumber", None)
        if serial_node is not None:
            if isinstance(serial_node.value, int) and not isinstance(serial_node.value, bool):
                serial = str(serial_node.value)
            else:
                serial = serial_node.as_str(max_len=256)
    tile, ulp = _tile_and_ulp(meta, source)
    if not ulp:
        ulp = "gr" if model == "B01" else "b"
    bias = dict(low=-100.0, high=100.0)
    return {
        "camera_model": model,
        "serial": serial,
        "black_level": black,
        "white_level": whites["gr"],
        "white_levels": whites,
        "cfa_pattern": cfa_from_mosaic(tile, ulp, source=source),
        "ccm": ccm,
        "white_balance": wb,
        "exposure_bias_ev": image.opt_float("modulationExposureBias", 0.0, **bias),
        "limit_exposure_bias_ev": image.opt_float("limitExposureBias", 0.0, **bias),
        "exposure_s": exposure,
        "iso": iso,
        "zoom_step": lens.opt_int("zoomStep", **steps),
        "focus_step": lens.opt_int("focusStep", **steps),
    }


def _packing(metadata: dict, source=None) -> tuple[int, str]:
    meta = _meta_node(metadata, source)
    image = meta.opt_dict("image")
    pk = image.get("pixelPacking") or image.at("rawDetails.pixelPacking", None)
    if pk is None or not pk.is_dict() or "bitsPerPixel" not in pk.value:
        raise LfpFormatError(f"{f'{source}: ' if source else ''}metadata has no image.pixelPacking / "
                             "image.rawDetails.pixelPacking")
    return pk["bitsPerPixel"].as_int(low=1, high=32), pk.opt_str("endianness", "little", max_len=16)


#: Largest raw sensor lfproc reads (pixels); the Illum's has 41.5 million.
MAX_SENSOR_PIXELS = 1 << 28


def _size(metadata: dict, source) -> tuple[int, int]:
    meta = _meta_node(metadata, source)
    image = meta.opt_dict("image")
    if image.get("height") is None or image.get("width") is None:
        raise LfpFormatError(f"{source}: metadata has no image.width/image.height")
    height = image["height"].as_int(low=1, high=ut.MAX_DIMENSION)
    width = image["width"].as_int(low=1, high=ut.MAX_DIMENSION)
    ut.check_dims((height, width), source=source, what="raw image", error=LfpFormatError,
                  max_pixels=MAX_SENSOR_PIXELS)
    return height, width


def split_txt_metadata(doc: dict[str, Any], *, source=None) -> tuple[dict, dict, dict]:
    """Split a metadata document into ``(frame metadata, private metadata, extra)``.

    Accepts a white-image ``MOD_xxxx.TXT`` (``master.picture.frameArray[0].frame``), an LFP
    table of contents with inline metadata (``frames[0].frame``), imageio's
    ``{"metadata", "privateMetadata"}`` and bare frame metadata (F01 ``__frame.json``).
    ``extra`` holds ``derivation`` (the ``sha1-...`` of ``derivationArray[0]``, lower case,
    or None) and ``tags`` (``com.lytro.tags``).
    """
    if not isinstance(doc, dict):
        raise LfpFormatError(f"{source}: expected a JSON object, found {ut.show(doc)}")
    frame_entry = (_get(doc, "master", "picture", "frameArray", 0) or _get(doc, "picture", "frameArray", 0)
                   or _get(doc, "frames", 0))
    derivation = (_get(doc, "master", "picture", "derivationArray", 0) or _get(doc, "picture", "derivationArray", 0))
    if isinstance(frame_entry, dict) and isinstance(frame_entry.get("frame"), dict):
        frame = frame_entry["frame"]
        meta, private = frame.get("metadata") or {}, frame.get("privateMetadata") or {}
        tags = _get(frame_entry, "parameters", "vendorContent", "com.lytro.tags", default={}) or {}
    elif isinstance(doc.get("metadata"), dict):
        meta, private, tags = doc["metadata"], doc.get("privateMetadata") or {}, {}
    else:
        meta, private, tags = doc, {}, {}
    derivation = _norm_sha1(derivation) if isinstance(derivation, str) and derivation.lower().startswith("sha1-") else None
    for name, value in (("frame metadata", meta), ("private metadata", private), ("com.lytro.tags", tags)):
        if not isinstance(value, dict):
            raise LfpFormatError(f"{source}: {name}: expected a JSON object, found {ut.show(value)}")
    return meta, private, {"derivation": derivation, "tags": tags}


def find_metadata_file(raw_path: Path) -> tuple[Path | None, Path | None]:
    """Metadata and private-metadata sidecars of an unpacked raw file.

    Looks for ``STEM.TXT/.txt/.json/.JSON``; for LFP-Reader names (``NAME__frame.raw``) also
    ``NAME__frame.json``, ``NAME__metadata.json`` and ``NAME__private_metadata.json``.
    """
    raw_path = Path(raw_path)
    stem = raw_path.with_suffix("")
    meta = next((stem.with_suffix(ext) for ext in (".TXT", ".txt", ".json", ".JSON")
                 if stem.with_suffix(ext).is_file()), None)
    private = None
    name = raw_path.stem
    for sep in ("__frame", "_frame"):
        if name.endswith(sep):
            base = raw_path.parent / name[: -len(sep)]
            if meta is None:
                cand = Path(f"{base}__metadata.json")
                meta = cand if cand.is_file() else None
            for cand in (Path(f"{base}__private_metadata.json"), Path(f"{base}_private_metadata.json")):
                if cand.is_file():
                    private = cand
                    break
    return meta, private


# -- readers -------------------------------------------------------------------------------
def _read_raw_pair(path: Path) -> LytroCapture:
    meta_path, private_path = find_metadata_file(path)
    if meta_path is None:
        raise MissingFileError(f"{path}: no metadata file next to the raw image (expected "
                               f"{path.with_suffix('.TXT').name} or {path.with_suffix('.json').name})")
    doc = _parse_json(ut.read_bytes(meta_path, max_bytes=ut.MAX_JSON_BYTES, error=LfpFormatError,
                                    what="metadata file"), str(meta_path))
    meta, private, extra = split_txt_metadata(doc, source=meta_path)
    if private_path is not None:
        private = _parse_json(ut.read_bytes(private_path, max_bytes=ut.MAX_JSON_BYTES, error=LfpFormatError,
                                            what="metadata file"), str(private_path))
    fields = frame_fields(meta, private, source=meta_path)
    height, width = _size(meta, meta_path)
    bits, endian = _packing(meta, meta_path)
    nbytes = path.stat().st_size
    if nbytes == height * width * 2 and bits != 16:  # third-party extractors write 16-bit words
        bits, endian = 16, "little"
    expected = raw_byte_count(height, width, bits)
    if nbytes != expected:  # checked before the file is read
        raise LfpFormatError(f"{path}: wrong raw size: {meta_path.name} says {width} x {height} at {bits} bit "
                             f"= {expected} bytes, the file has {nbytes}")
    raw = unpack_raw(path.read_bytes(), height, width, bits_per_pixel=bits, endianness=endian, source=path)
    return LytroCapture(raw=raw, metadata=meta, private_metadata=private, path=path,
                        geometry_hash=extra["derivation"], sha1_verified=None, **fields)


def _capture_from_container(c: LfpContainer) -> LytroCapture:
    path = c.path
    require_raw_image(c)  # a processed file: say what it holds before anything else
    meta = c.json("metadataRef") if (c.ref("metadataRef") or c.frame().get("metadata")) else None
    if meta is None:
        raise LfpFormatError(f"{path}: missing metadata: the table of contents has no frame metadataRef")
    private = c.json("privateMetadataRef") if (c.has("privateMetadataRef") or c.frame().get("privateMetadata")) else {}
    fields = frame_fields(meta, private, source=path)
    frame_ref = c.frame().get("imageRef", "")
    if not c.has("imageRef") or not isinstance(frame_ref, str) or c.ref("imageRef") != frame_ref.lower():
        raise LfpFormatError(f"{path}: missing raw section: the file has no raw sensor image "
                             "(frame imageRef absent or not in the file; a processed desktop LFP holds only "
                             "rendered images)")
    sec = c.section(c.ref("imageRef"))
    height, width = _size(meta, path)
    bits, endian = _packing(meta, path)
    expected = raw_byte_count(height, width, bits)
    if sec.size != expected:
        raise LfpFormatError(f"{path}: wrong raw size: metadata says {width} x {height} at {bits} bit "
                             f"= {expected} bytes, the raw section has {sec.size}")
    raw = unpack_raw(sec.data, height, width, bits_per_pixel=bits, endianness=endian, source=path)
    geo = c.ref("geometryCorrectionRef")
    if geo is None:
        derivation = _get(c.toc or {}, "picture", "derivationArray", 0) or _get(c.toc or {}, "derivations", 0)
        geo = _norm_sha1(derivation) if isinstance(derivation, str) and derivation.lower().startswith("sha1-") else None
    return LytroCapture(raw=raw, metadata=meta, private_metadata=private, path=path, geometry_hash=geo,
                        sha1_verified=c.sha1_verified, **fields)


def read_capture(path: str | os.PathLike, *, verify: bool = True) -> LytroCapture:
    """Read a Lytro raw capture.

    Parameters
    ----------
    path : str or Path
        Illum ``.LFR``, F01 raw ``.lfp`` (any LFP container with a raw frame), or an unpacked
        ``.RAW`` with its ``.TXT``/``.json`` metadata next to it.
    verify : bool, default True
        Check the SHA-1 of every container section.

    Returns
    -------
    LytroCapture
        The raw image (uint16 DN) and its metadata; see :class:`LytroCapture` for an example.

    Raises
    ------
    MissingFileError
        The file (or a ``.RAW``'s metadata) does not exist.
    LfpFormatError
        Truncated file, wrong magic, missing raw section, wrong raw size, unknown camera
        model (named), missing levels/packing.
    ChecksumError
        A section does not match its SHA-1.
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such file")
    if path.suffix.lower() == ".raw" and not is_lfp(path):
        return _read_raw_pair(path)
    return _capture_from_container(read_lfp(path, verify=verify))


def describe_lytro(path: str | os.PathLike) -> dict[str, Any]:
    """Figures of a Lytro file for ``lfproc info``: camera, settings, sections, embedded images.

    Raw captures also get raw statistics. Processed LFPs without a raw frame report the
    metadata they carry (camera fields are None when the file has no frame metadata).

    Parameters
    ----------
    path : str or os.PathLike
        A Lytro container (``.LFR``, ``.lfp``) or an unpacked ``.RAW`` with its metadata.

    Returns
    -------
    dict
        JSON-ready figures: ``kind`` (``"lytro"``), ``path``, ``file_kind`` (``"lfp"`` or
        ``"raw"``), ``sections``, ``sha1_verified``, ``embedded_images``, ``has_raw``, ``holds``,
        the camera fields (``camera_model``, ``serial``, ``zoom_step``, ``focus_step``,
        ``exposure_s``, ``iso``, levels, ``cfa_pattern``, ``ccm``, ``white_balance``...) and for
        raw captures ``height``, ``width``, ``raw_min_dn``, ``raw_max_dn``, ``raw_mean_dn`` and
        ``saturated_fraction``.

    Raises
    ------
    MissingFileError
        No such file.
    LfpFormatError, ChecksumError
        As :func:`read_capture`.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.lytro import describe_lytro
    >>> from lfproc.lytro.container import illum_metadata, write_lfr
    >>> raw = np.full((8, 12), 1023, dtype=np.uint16)
    >>> raw[:4] = 100
    >>> _ = write_lfr("tiny.LFR", raw=raw, metadata=illum_metadata(height=8, width=12))
    >>> info = describe_lytro("tiny.LFR")
    >>> info["file_kind"], info["has_raw"], info["camera_model"], (info["height"], info["width"])
    ('lfp', True, 'B01', (8, 12))
    >>> info["raw_min_dn"], info["raw_max_dn"], info["saturated_fraction"]
    (100, 1023, 0.5)
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such file")
    out: dict[str, Any] = {"kind": "lytro", "path": str(path)}
    with open(path, "rb") as fh:
        is_container = fh.read(len(LFP_MAGIC)) == LFP_MAGIC
    cap = None
    fields: dict[str, Any] = {}
    if is_container:
        c = read_lfp(path)
        frame = c.frame()
        lfm = [i for i, s in enumerate(c.sections) if s.kind == "LFM"]
        out.update({
            "file_kind": "lfp",
            "sections": len(c.sections),
            "content_sections": sum(s.kind == "LFC" for s in c.sections),
            "sha1_verified": c.sha1_verified,
            "toc_position": ("first" if lfm and lfm[0] == 0 else "last" if lfm and lfm[0] == len(c.sections) - 1
                             else "middle" if lfm else None),
            "embedded_images": len(c.images()),
            "embedded_image_kinds": sorted({im["representation"] for im in c.images()}),
            "has_raw": c.has("imageRef") and bool(frame.get("imageRef")),
            "storage_files": len(_storage_entries(c.toc, path)),
        })

        out["holds"] = contents_summary(lfp_contents(c))
        if out["has_raw"]:
            cap = _capture_from_container(c)
        elif c.ref("metadataRef") and c.has("metadataRef") or isinstance(frame.get("metadata"), dict):
            meta = c.json("metadataRef")
            private = c.json("privateMetadataRef") if (c.has("privateMetadataRef")
                                                         or isinstance(frame.get("privateMetadata"), dict)) else {}
            fields = frame_fields(meta, private, source=path)
            dims = [_get(meta, "image", k) for k in ("width", "height")]
            fields["width"], fields["height"] = (d if isinstance(d, int) and not isinstance(d, bool) else None
                                                 for d in dims)
        out["frame_metadata"] = "inline" if isinstance(frame.get("metadata"), dict) else (
            "section" if c.has("metadataRef") else ("referenced but absent" if frame.get("metadataRef") else None))
    else:
        out.update({"file_kind": "raw", "sections": 0, "sha1_verified": None, "embedded_images": 0, "has_raw": True})
        cap = read_capture(path)
    if cap is not None:
        raw = cap.raw
        fields = {k: getattr(cap, k) for k in ("camera_model", "serial", "black_level", "white_level", "cfa_pattern",
                                               "ccm", "white_balance", "exposure_bias_ev", "exposure_s", "iso",
                                               "zoom_step", "focus_step", "geometry_hash")}
        fields.update({"height": raw.shape[0], "width": raw.shape[1], "raw_min_dn": int(raw.min()),
                       "raw_max_dn": int(raw.max()), "raw_mean_dn": float(raw.mean(dtype=np.float64)),
                       "saturated_fraction": float(np.mean(raw >= cap.white_level))})
    for key in ("camera_model", "serial", "zoom_step", "focus_step", "exposure_s", "iso"):
        out[key] = fields.get(key)
    for key, value in fields.items():
        if key not in out and key != "white_levels":
            out[key] = value.tolist() if isinstance(value, np.ndarray) else value
    return out
