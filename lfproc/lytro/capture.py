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

from ..errors import LfpFormatError, MissingFileError
from .container import LFP_MAGIC, LfpContainer, _norm_sha1, _parse_json, is_lfp, read_lfp
from .raw import raw_byte_count, unpack_raw

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


@dataclass(frozen=True)
class LytroCapture:
    """A Lytro raw capture (lenslet image) and its metadata.

    Attributes
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


def _tile_and_ulp(metadata: dict) -> tuple[str, str]:
    mosaic = (_get(metadata, "image", "mosaic") or _get(metadata, "image", "rawDetails", "mosaic")
              or _get(metadata, "devices", "sensor", "mosaic") or {})
    return str(mosaic.get("tile", "r,gr:gb,b")), str(mosaic.get("upperLeftPixel", ""))


def cfa_from_mosaic(tile: str, upper_left_pixel: str) -> str:
    """Row-major Bayer pattern from Lytro ``mosaic.tile`` and ``mosaic.upperLeftPixel``.

    Examples
    --------
    >>> cfa_from_mosaic("r,gr:gb,b", "gr")
    'GRBG'
    >>> cfa_from_mosaic("r,gr:gb,b", "b")
    'BGGR'
    """
    rows = [r.split(",") for r in tile.replace(" ", "").split(":")]
    if len(rows) != 2 or any(len(r) != 2 for r in rows):
        raise LfpFormatError(f"mosaic tile {tile!r} is not a 2x2 Bayer tile like 'r,gr:gb,b'")
    where = [(i, j) for i in range(2) for j in range(2) if rows[i][j] == upper_left_pixel]
    if not where:
        raise LfpFormatError(f"mosaic upperLeftPixel {upper_left_pixel!r} is not in tile {tile!r}")
    i0, j0 = where[0]
    letter = {"r": "R", "gr": "G", "gb": "G", "b": "B"}
    return "".join(letter[rows[(i0 + y) % 2][(j0 + x) % 2]] for y in range(2) for x in range(2))


def _levels_2x2(levels: dict[str, float], metadata: dict) -> np.ndarray:
    tile, ulp = _tile_and_ulp(metadata)
    rows = [r.split(",") for r in tile.replace(" ", "").split(":")]
    i0, j0 = next((i, j) for i in range(2) for j in range(2) if rows[i][j] == (ulp or "gr"))
    return np.array([[float(levels[rows[(i0 + y) % 2][(j0 + x) % 2]]) for x in range(2)] for y in range(2)])


def frame_fields(metadata: dict[str, Any], private_metadata: dict[str, Any] | None, *, source=None) -> dict[str, Any]:
    """The capture fields of :class:`LytroCapture` (all but ``raw``/``path``) from frame metadata.

    Works for Illum picture metadata, Illum/F01 white-image metadata and F01 frame metadata.
    """
    model = normalise_camera_model(_get(metadata, "camera", "model"), source=source)
    image = _get(metadata, "image", default={}) or {}
    fmt = image.get("pixelFormat") or _get(image, "rawDetails", "pixelFormat")
    if not isinstance(fmt, dict) or "black" not in fmt or "white" not in fmt:
        raise LfpFormatError(f"{source}: metadata has no black/white levels "
                             "(image.pixelFormat or image.rawDetails.pixelFormat)")
    black = {c: float(fmt["black"].get(c, fmt["black"].get("gr"))) for c in ("r", "gr", "gb", "b")}
    whites = {c: float(fmt["white"].get(c, fmt["white"].get("gr"))) for c in ("r", "gr", "gb", "b")}
    color = image.get("color") or {}
    ccm = color.get("ccm") if model == "B01" and color.get("ccm") else color.get("ccmRgbToSrgbArray")
    ccm = None if ccm is None else np.asarray(ccm, dtype=np.float64).reshape(3, 3)
    wbg = color.get("whiteBalanceGain")
    wb = None if not wbg else {"r": float(wbg["r"]), "g": float(wbg.get("gr", wbg.get("gb", 1.0))),
                               "b": float(wbg["b"])}
    iso = image.get("iso", _get(metadata, "devices", "sensor", "iso"))
    shutter = _get(metadata, "devices", "shutter", default={}) or {}
    exposure = shutter.get("frameExposureDuration", shutter.get("pixelExposureDuration"))
    lens = _get(metadata, "devices", "lens", default={}) or {}
    serial = _get(private_metadata or {}, "camera", "serialNumber")
    tile, ulp = _tile_and_ulp(metadata)
    if not ulp:
        ulp = "gr" if model == "B01" else "b"
    return {
        "camera_model": model,
        "serial": None if serial is None else str(serial),
        "black_level": black,
        "white_level": whites["gr"],
        "white_levels": whites,
        "cfa_pattern": cfa_from_mosaic(tile, ulp),
        "ccm": ccm,
        "white_balance": wb,
        "exposure_bias_ev": float(image.get("modulationExposureBias", 0.0) or 0.0),
        "limit_exposure_bias_ev": float(image.get("limitExposureBias", 0.0) or 0.0),
        "exposure_s": None if exposure is None else float(exposure),
        "iso": None if iso is None else float(iso),
        "zoom_step": None if lens.get("zoomStep") is None else int(lens["zoomStep"]),
        "focus_step": None if lens.get("focusStep") is None else int(lens["focusStep"]),
    }


def _packing(metadata: dict) -> tuple[int, str]:
    image = metadata.get("image", {}) or {}
    pk = image.get("pixelPacking") or _get(image, "rawDetails", "pixelPacking")
    if not isinstance(pk, dict) or "bitsPerPixel" not in pk:
        raise LfpFormatError("metadata has no image.pixelPacking / image.rawDetails.pixelPacking")
    return int(pk["bitsPerPixel"]), str(pk.get("endianness", "little"))


def _size(metadata: dict, source) -> tuple[int, int]:
    image = metadata.get("image", {}) or {}
    try:
        return int(image["height"]), int(image["width"])
    except (KeyError, TypeError, ValueError):
        raise LfpFormatError(f"{source}: metadata has no image.width/image.height") from None


def split_txt_metadata(doc: dict[str, Any]) -> tuple[dict, dict, dict]:
    """Split a metadata document into ``(frame metadata, private metadata, extra)``.

    Accepts a white-image ``MOD_xxxx.TXT`` (``master.picture.frameArray[0].frame``), an LFP
    table of contents with inline metadata (``frames[0].frame``), imageio's
    ``{"metadata", "privateMetadata"}`` and bare frame metadata (F01 ``__frame.json``).
    ``extra`` holds ``derivation`` (the ``sha1-...`` of ``derivationArray[0]``, lower case,
    or None) and ``tags`` (``com.lytro.tags``).
    """
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
    doc = _parse_json(meta_path.read_bytes(), str(meta_path))
    meta, private, extra = split_txt_metadata(doc)
    if private_path is not None:
        private = _parse_json(private_path.read_bytes(), str(private_path))
    fields = frame_fields(meta, private, source=meta_path)
    height, width = _size(meta, meta_path)
    bits, endian = _packing(meta)
    nbytes = path.stat().st_size
    if nbytes == height * width * 2 and bits != 16:  # third-party extractors write 16-bit words
        bits, endian = 16, "little"
    raw = unpack_raw(path.read_bytes(), height, width, bits_per_pixel=bits, endianness=endian, source=path)
    return LytroCapture(raw=raw, metadata=meta, private_metadata=private, path=path,
                        geometry_hash=extra["derivation"], sha1_verified=None, **fields)


def _capture_from_container(c: LfpContainer) -> LytroCapture:
    from .extract import require_raw_image

    path = c.path
    require_raw_image(c)  # a processed file: say what it holds before anything else
    meta = c.json("metadataRef") if (c.ref("metadataRef") or c.frame().get("metadata")) else None
    if meta is None:
        raise LfpFormatError(f"{path}: missing metadata: the table of contents has no frame metadataRef")
    private = c.json("privateMetadataRef") if (c.has("privateMetadataRef") or c.frame().get("privateMetadata")) else {}
    fields = frame_fields(meta, private, source=path)
    if not c.has("imageRef") or c.ref("imageRef") != c.frame().get("imageRef", "").lower():
        raise LfpFormatError(f"{path}: missing raw section: the file has no raw sensor image "
                             "(frame imageRef absent or not in the file; a processed desktop LFP holds only "
                             "rendered images)")
    sec = c.section(c.ref("imageRef"))
    height, width = _size(meta, path)
    bits, endian = _packing(meta)
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
            "storage_files": len(c.toc.get("files", []) or []) if isinstance(c.toc, dict) else 0,
        })
        if out["has_raw"]:
            cap = _capture_from_container(c)
        elif c.ref("metadataRef") and c.has("metadataRef") or isinstance(frame.get("metadata"), dict):
            meta = c.json("metadataRef")
            private = c.json("privateMetadataRef") if (c.has("privateMetadataRef")
                                                         or isinstance(frame.get("privateMetadata"), dict)) else {}
            fields = frame_fields(meta, private, source=path)
            fields["width"], fields["height"] = _get(meta, "image", "width"), _get(meta, "image", "height")
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
