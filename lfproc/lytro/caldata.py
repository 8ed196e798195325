"""Lytro camera calibration data: white images (``MOD_xxxx.RAW`` + ``MOD_xxxx.TXT``).

Sources read by :func:`read_caldata` / :func:`iter_caldata`:

* the Illum pairing-data tar ``caldata-<serial>.tar`` (files under any prefix folder, e.g.
  ``unitdata/`` or ``<serial>/``): ``MOD_xxxx.RAW/.TXT/.GCT``, ``cal_file_manifest.json``
  (``calibrationFiles[].{name,hash}``), ``unit_info.json``, ``mla_calibration.json``,
  ``HOTPIXEL.BIN``;
* a folder holding ``MOD_xxxx.RAW``/``.TXT`` pairs (also ``T1CALIB__MOD_xxxx.*``), or such a tar
  or Lytro Desktop archives;
* Lytro Desktop ``data.C.N`` storage archives (LFP containers whose table of contents lists
  ``files[].{name,dataRef}``; all ``data.C.*`` next to the given one are read, in order).

The serial comes from ``unit_info.json`` when present (it overrides the TXT, as the Light
Field Toolbox does), else from the TXT private metadata, else from the tar name. The
geometry hash of a white image is the ``cal_file_manifest.json`` hash of its ``.GCT`` (the
value an Illum capture's ``geometryCorrectionRef`` points to), else the SHA-1 of the
``.GCT`` file, else the TXT's ``derivationArray[0]`` (first generation).

:func:`write_caldata_tar` writes the same layout for the virtual camera.
"""

from __future__ import annotations

import io
import json
import os
import re
import struct
import tarfile
from copy import deepcopy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from .. import _untrusted as ut
from .._version import __version__
from ..errors import InputError, LfpFormatError, MissingFileError, ShapeError
from ..io._atomic import atomic_file
from .capture import _get, _packing, _size, frame_fields, split_txt_metadata
from .container import _deep_update, _parse_json, is_lfp, read_lfp, sha1_ref
from .raw import pack_raw10, pack_raw12, raw_byte_count, unpack_raw
from .._shared.reprs import short_repr

__all__ = [
    "WhiteFrame",
    "read_caldata",
    "iter_caldata",
    "write_caldata_tar",
    "white_metadata",
    "white_txt_document",
    "geometry_correction_bytes",
    "DARK_MEAN_FRACTION",
]

#: Without a ``darkFrame`` tag, a frame whose mean normalised level ``(raw - black) / (white -
#: black)`` is below this fraction is a dark frame (the Light Field Toolbox drops white images
#: with mean < 500 DN of 1023, about 0.45; dark frames sit near 0).
DARK_MEAN_FRACTION = 0.05

_MOD_RE = re.compile(r"(?:^|.*[/\\_])(MOD_\d+)\.TXT$", re.IGNORECASE)


@short_repr
@dataclass(frozen=True)
class WhiteFrame:
    """One calibration frame (white image or dark frame) and its metadata.

    Attributes
    ----------
    raw : ndarray of shape (H, W), uint16, or None
        Raw counts (DN); None when read with ``load_raw=False``.
    metadata : dict
        Frame metadata (white-image layout: levels under ``image.rawDetails``).
    name : str
        ``"MOD_0015"``.
    camera_model : {"B01", "F01"}
    serial : str or None
    zoom_step, focus_step : int or None
    exposure_s : float or None
        Frame exposure duration in seconds.
    is_dark : bool
        A dark (black) frame, to be dropped from the white-image database.
    geometry_hash : str or None
        ``"sha1-..."`` lower case (see the module documentation).
    source : str
        Where it was read (``caldata-B5.tar:unitdata/MOD_0015.RAW``).
    private_metadata : dict
    black_level : dict
        Black level per Bayer channel (DN).
    white_level : float
        White level (DN).
    cfa_pattern : str
        Row-major Bayer pattern from the top-left pixel.
    """

    raw: np.ndarray | None = field(repr=False, compare=False)
    metadata: dict[str, Any] = field(repr=False)
    name: str = "MOD_0000"
    camera_model: str = "B01"
    serial: str | None = None
    zoom_step: int | None = None
    focus_step: int | None = None
    exposure_s: float | None = None
    is_dark: bool = False
    geometry_hash: str | None = None
    source: str = ""
    private_metadata: dict[str, Any] = field(default_factory=dict, repr=False)
    black_level: dict[str, float] = field(default_factory=dict, repr=False)
    white_level: float | None = None
    cfa_pattern: str | None = None


# -- metadata in the white-image layout ----------------------------------------------------
def white_metadata(*, height: int = 5368, width: int = 7728, zoom_step: int = 0, focus_step: int = 0,
                   exposure_s: float = 0.008, iso: float = 100, black_level: float = 64, white_level: float = 1023,
                   mla_rotation_rad: float = 0.0, extra: dict | None = None) -> dict[str, Any]:
    """Illum white-image frame metadata in the layout of a real ``MOD_xxxx.TXT``.

    Levels, packing and mosaic sit under ``image.rawDetails``; ``camera.model`` is ``"B01"``;
    ISO under ``devices.sensor.iso``; exposure ``devices.shutter.frameExposureDuration`` (s).
    ``extra`` is merged in last (nested dicts merged).
    """
    levels = {"black": {c: black_level for c in ("r", "gr", "gb", "b")},
              "white": {c: white_level for c in ("r", "gr", "gb", "b")}, "rightShift": 0}
    meta: dict[str, Any] = {
        "camera": {"firmware": f"lfproc {__version__}", "make": "Lytro, Inc.", "model": "B01"},
        "devices": {
            "lens": {"exitPupilOffset": {"z": 0.05}, "fNumber": 2.0, "focalLength": 0.0095, "focusStep": int(focus_step),
                     "infinityLambda": 200, "opticalCenterOffset": {"x": 0.0, "y": 0.0}, "zoomStep": int(zoom_step)},
            "mla": {"config": "com.lytro.mla.3", "defectArray": [], "lensPitch": 2e-05,
                    "rotation": float(mla_rotation_rad), "scaleFactor": {"x": 1, "y": 1.0},
                    "sensorOffset": {"x": 0.0, "y": 0.0, "z": 4.06e-05}, "tiling": "hexUniformRowMajor"},
            "ndfilter": {"exposureBias": 0},
            "sensor": {"analogGain": {c: 1 for c in ("b", "gb", "gr", "r")}, "bitsPerPixel": 10, "iso": float(iso),
                       "mosaic": {"tile": "r,gr:gb,b", "upperLeftPixel": "gr"},
                       "normalizedResponses": [{"b": 1.0, "cct": 5100, "gb": 1, "gr": 1, "r": 1.0}],
                       "pixelPitch": 1.4e-06},
            "shutter": {"frameExposureDuration": float(exposure_s), "mechanism": "sensorOpenApertureClose",
                        "pixelExposureDuration": float(exposure_s)},
        },
        "image": {
            "color": {"applied": {}, "ccmRgbToSrgbArray": np.eye(3).ravel().tolist(), "gamma": 0.4,
                      "whiteBalanceGain": {"b": 1, "gb": 1, "gr": 1, "r": 1}},
            "height": int(height), "width": int(width), "limitExposureBias": 0, "modulationExposureBias": 0,
            "orientation": 1, "representation": "rawPacked",
            "rawDetails": {"mosaic": {"tile": "r,gr:gb,b", "upperLeftPixel": "gr"}, "pixelFormat": levels,
                           "pixelPacking": {"bitsPerPixel": 10, "endianness": "little"}},
        },
        "modes": {"creative": "auto", "exposureDurationMode": "auto", "isoMode": "auto"},
        "type": "lightField",
    }
    if extra:
        _deep_update(meta, deepcopy(extra))
    return meta


def _to_white_layout(metadata: dict[str, Any]) -> dict[str, Any]:
    """Picture-layout Illum metadata (``image.pixelFormat``, model ILLUM) -> white-image layout."""
    meta = deepcopy(metadata)
    image = meta.setdefault("image", {})
    raw_details = image.setdefault("rawDetails", {})
    for key in ("pixelFormat", "pixelPacking", "mosaic"):
        if key in image:
            raw_details.setdefault(key, image.pop(key))
    color = image.setdefault("color", {})
    if "ccm" in color and "ccmRgbToSrgbArray" not in color:
        color["ccmRgbToSrgbArray"] = color.pop("ccm")
    if "iso" in image:
        meta.setdefault("devices", {}).setdefault("sensor", {}).setdefault("iso", image.pop("iso"))
    model = _get(meta, "camera", "model")
    if model is None or str(model).upper() == "ILLUM":
        meta.setdefault("camera", {})["model"] = "B01"
    return meta


def geometry_correction_bytes(metadata: dict[str, Any], name: str) -> bytes:
    """Deterministic geometry-correction table (``.GCT``) content for a white image.

    Real ``.GCT`` files are opaque; lfproc stores a small JSON document naming the frame,
    its zoom/focus steps and microlens-array metadata. An Illum capture taken with this
    calibration points at it through ``geometryCorrectionRef = sha1-<SHA-1 of these bytes>``
    (pass the same bytes to :func:`lfproc.lytro.write_lfr`).
    """
    doc = {"kind": "geometryCorrection", "name": str(name), "generator": "lfproc",
           "zoomStep": _get(metadata, "devices", "lens", "zoomStep"),
           "focusStep": _get(metadata, "devices", "lens", "focusStep"),
           "mla": _get(metadata, "devices", "mla", default={})}
    return json.dumps(doc, sort_keys=True).encode("ascii")


def white_txt_document(metadata: dict[str, Any], *, serial: str, is_dark: bool = False,
                       derivation: str | None = None) -> dict[str, Any]:
    """The ``MOD_xxxx.TXT`` JSON document of a white/dark frame (layout of real Illum TXTs)."""
    meta = _to_white_layout(metadata)
    return {
        "compressedFrame": {"metadata": {"demodulated": False, "representation": "jpeg"}},
        "master": {
            "picture": {
                "accelerationArray": [],
                "derivationArray": [derivation or sha1_ref(json.dumps(meta, sort_keys=True).encode())],
                "frameArray": [{
                    "frame": {"imageRef": "unknown", "metadata": meta,
                              "privateMetadata": {"camera": {"serialNumber": str(serial)},
                                                  "devices": {"sensor": {"sensorSerial": "0x00000000"}}}},
                    "parameters": {"vendorContent": {"com.lytro.tags": {"darkFrame": bool(is_dark),
                                                                        "modulationFrame": not is_dark}}},
                }],
                "viewArray": [],
            },
            "thumbnailArray": [],
            "version": {"major": 1, "minor": 0, "provisionalDate": "2015-May-13"},
        },
    }


# -- reading -------------------------------------------------------------------------------
def _storage_name(name: str) -> str:
    """``C:\\T1CALIB\\MOD_0000.RAW`` -> ``T1CALIB__MOD_0000.RAW`` (Light Field Toolbox naming)."""
    name = re.sub(r"^[A-Za-z]:[\\/]", "", name)
    return name.replace("\\", "__").replace("/", "__")


#: Largest raw white image lfproc reads from calibration data (bytes; a full Illum frame has 52 MB).
MAX_RAW_BYTES = 1 << 30
#: Largest other calibration file (geometry tables, hot-pixel lists) read whole.
MAX_AUX_BYTES = 64 << 20


class _Files:
    """A flat view of named files (tar members, folder files, archive entries).

    ``loaders[name](max_bytes)`` returns the bytes of a file, refusing (before reading) one
    larger than ``max_bytes``; ``sizes[name]`` is its size as the container declares it.
    """

    def __init__(self, label: str):
        self.label = label
        self.loaders: dict[str, Callable[[int], bytes]] = {}
        self.sizes: dict[str, int] = {}

    def add(self, name: str, size: int, loader: Callable[[int], bytes]) -> None:
        self.loaders[name] = loader
        self.sizes[name] = size

    def load(self, name: str, max_bytes: int) -> bytes:
        if self.sizes[name] > max_bytes:
            raise LfpFormatError(f"{self.label}:{name}: {self.sizes[name]} bytes, above the limit of {max_bytes} "
                                 "for this file")
        return self.loaders[name](max_bytes)

    def find(self, basename: str, near: str | None = None) -> str | None:
        """Name whose base name equals ``basename`` (case-insensitive), preferring ``near``'s folder."""
        hits = [n for n in self.loaders if re.split(r"[/\\]", n)[-1].lower() == basename.lower()]
        if near is not None:
            folder = near.rsplit("/", 1)[0] if "/" in near else ""
            same = [n for n in hits if (n.rsplit("/", 1)[0] if "/" in n else "") == folder]
            hits = same or hits
        return sorted(hits)[0] if hits else None

    def json(self, name: str) -> dict[str, Any]:
        return _parse_json(self.load(name, ut.MAX_JSON_BYTES), f"{self.label}:{name}")

    def node(self, name: str) -> ut.Node:
        """A JSON file as an :class:`lfproc._untrusted.Node` (errors name the file and field)."""
        return ut.Node(self.json(name), f"{self.label}:{name}", error=LfpFormatError)


def _tar_files(path: Path, tar: tarfile.TarFile) -> _Files:
    """The regular files of a tar; ``..``/absolute names and links are refused."""
    files = _Files(str(path))
    for member in ut.safe_members(tar, source=path):
        files.add(member.name, member.size,
                  lambda limit, m=member: ut.read_member(tar, m, max_bytes=limit, source=path, error=LfpFormatError))
    return files


def _folder_files(folder: Path, paths: Iterable[Path]) -> _Files:
    files = _Files(str(folder))
    for p in paths:
        files.add(p.relative_to(folder).as_posix(), p.stat().st_size,
                  lambda limit, p=p: ut.read_bytes(p, max_bytes=limit, error=LfpFormatError, what="calibration file"))
    return files


def _archive_files(first: Path, verify: bool) -> _Files:
    m = re.fullmatch(r"(.*\.C\.)(\d+)", first.name, re.IGNORECASE)
    if m:
        siblings = [p for p in first.parent.iterdir() if re.fullmatch(re.escape(m.group(1)) + r"\d+", p.name,
                                                                      re.IGNORECASE)]
        paths = sorted(siblings, key=lambda p: int(p.name.rsplit(".", 1)[1]))
    else:
        paths = [first]
    files = _Files(str(first.parent / (m.group(1) + "N") if m else first))
    for p in paths:
        c = read_lfp(p, verify=verify)
        for name, sec in c.files().items():
            files.add(_storage_name(name), sec.size, lambda limit, d=sec.data: d)
    return files


def _is_tar(path: Path) -> bool:
    """A tar, or a compressed file that may hold one (its content is checked when read)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(512)
    except OSError:
        return False
    if head[:2] == b"\x1f\x8b" or head[:3] == b"BZh" or head[:6] == b"\xfd7zXZ\x00" or head[257:262] == b"ustar":
        return True
    try:
        return tarfile.is_tarfile(path)
    except Exception:  # a probe: anything unreadable is "not a tar" and reported as such below
        return False


def _serial_from_name(path: Path) -> str | None:
    m = re.search(r"caldata-([A-Za-z0-9]+)\.tar$", path.name, re.IGNORECASE)
    return m.group(1) if m else None


def _serial(node: ut.Node | None) -> str | None:
    if node is None:
        return None
    if isinstance(node.value, int) and not isinstance(node.value, bool):
        return str(node.value)
    return node.as_str(max_len=256)


def _check_serial(serial: str | None, label: str) -> str | None:
    """A serial number becomes part of file names (the white-image database): refuse one that
    is not a plain name (a path such as ``../../x`` or ``/abs``)."""
    if serial is None:
        return None
    return ut.safe_filename(serial, what="serial number", source=label)


def _frames(files: _Files, *, load_raw: bool, serial_hint: str | None) -> Iterator[WhiteFrame]:
    unit = files.find("unit_info.json")
    unit_serial = _serial(files.node(unit).at("camera.serialNumber", None)) if unit else None
    if unit:
        _check_serial(unit_serial, f"{files.label}:{unit}")
    manifest = files.find("cal_file_manifest.json")
    manifest_hash: dict[str, str] = {}
    if manifest:
        entries = files.node(manifest).get("calibrationFiles")
        for entry in (entries.as_list() if entries is not None else []):
            if entry.is_dict() and entry.has("name") and entry.has("hash"):
                name = entry["name"].as_str(max_len=1024)
                manifest_hash[re.split(r"[/\\]", name)[-1].upper()] = entry["hash"].as_str(max_len=64).lower()
    txts = sorted(n for n in files.loaders if _MOD_RE.match(n))
    if not txts:
        raise MissingFileError(f"{files.label}: no white images: expected MOD_xxxx.TXT + MOD_xxxx.RAW pairs, "
                               f"found {len(files.loaders)} other files")
    for txt in txts:
        stem = txt[: -len(".TXT")]
        name = _MOD_RE.match(txt).group(1).upper()
        raw_name = next((n for n in (stem + ".RAW", stem + ".raw") if n in files.loaders), None)
        if raw_name is None:
            raise MissingFileError(f"{files.label}: {txt} has no matching raw image {stem}.RAW")
        where = f"{files.label}:{raw_name}"
        doc = files.json(txt)
        meta, private, extra = split_txt_metadata(doc, source=f"{files.label}:{txt}")
        fields = frame_fields(meta, private, source=f"{files.label}:{txt}")
        height, width = _size(meta, f"{files.label}:{txt}")
        bits, endian = _packing(meta, f"{files.label}:{txt}")
        expected = raw_byte_count(height, width, bits)
        if files.sizes[raw_name] != expected:
            raise LfpFormatError(f"{where}: wrong raw size: {txt} says {width} x {height} at {bits} bit = "
                                 f"{expected} bytes, the file has {files.sizes[raw_name]}")
        raw = unpack_raw(files.load(raw_name, max(expected, 0)), height, width, bits_per_pixel=bits,
                         endianness=endian, source=where) if load_raw else None
        tags = ut.Node(extra["tags"], f"{files.label}:{txt}", "com.lytro.tags", LfpFormatError)
        if tags.has("darkFrame"):
            is_dark = tags["darkFrame"].as_bool()
        elif raw is not None:
            span = max(fields["white_level"] - fields["black_level"]["gr"], 1.0)
            is_dark = bool((raw.mean(dtype=np.float64) - fields["black_level"]["gr"]) / span < DARK_MEAN_FRACTION)
        else:
            is_dark = False
        gct_base = f"{name}.GCT"
        geo = manifest_hash.get(gct_base)
        if geo is None:
            gct = files.find(stem.rsplit("/", 1)[-1] + ".GCT", near=txt)
            geo = sha1_ref(files.load(gct, MAX_AUX_BYTES)) if gct else extra["derivation"]
        serial = _check_serial(unit_serial or fields["serial"] or serial_hint, f"{files.label}:{txt}")
        yield WhiteFrame(raw=raw, metadata=meta, name=name, camera_model=fields["camera_model"],
                         serial=None if serial is None else str(serial), zoom_step=fields["zoom_step"],
                         focus_step=fields["focus_step"], exposure_s=fields["exposure_s"], is_dark=is_dark,
                         geometry_hash=geo, source=where, private_metadata=private,
                         black_level=fields["black_level"], white_level=fields["white_level"],
                         cfa_pattern=fields["cfa_pattern"])


def iter_caldata(path: str | os.PathLike, *, load_raw: bool = True, verify: bool = True) -> Iterator[WhiteFrame]:
    """Yield the calibration frames of ``path`` one at a time (bounded memory).

    See :func:`read_caldata` for the parameters.
    """
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such file or folder")
    if path.is_file() and _is_tar(path):
        with ut.open_tar(path, error=LfpFormatError) as tar:
            yield from _frames(_tar_files(path, tar), load_raw=load_raw, serial_hint=_serial_from_name(path))
        return
    if path.is_file() and is_lfp(path):
        yield from _frames(_archive_files(path, verify), load_raw=load_raw, serial_hint=None)
        return
    if path.is_file():
        if _MOD_RE.match(path.name) or path.suffix.lower() == ".raw":
            pair = [p for p in path.parent.iterdir() if p.is_file() and p.stem == path.stem
                    and p.suffix.lower() in (".txt", ".raw", ".gct")]
            extra = [p for p in path.parent.iterdir() if p.name.lower() in ("unit_info.json", "cal_file_manifest.json")]
            yield from _frames(_folder_files(path.parent, pair + extra), load_raw=load_raw, serial_hint=None)
            return
        raise LfpFormatError(f"{path}: not Lytro calibration data: expected a caldata-<serial>.tar, a data.C.N "
                             "archive, a MOD_xxxx.TXT/.RAW pair or a folder of them")
    children = [p for p in path.rglob("*") if p.is_file()]
    if any(_MOD_RE.match(p.name) for p in children):
        yield from _frames(_folder_files(path, children), load_raw=load_raw, serial_hint=None)
        return
    archives = sorted({p.parent / re.sub(r"\d+$", "0", p.name) for p in children
                       if re.fullmatch(r".*\.C\.\d+", p.name, re.IGNORECASE)})
    tars = sorted(p for p in children if p.suffix.lower() == ".tar")
    if not archives and not tars:
        raise MissingFileError(f"{path}: no white images: the folder holds no MOD_xxxx.TXT/.RAW pairs, "
                               "caldata-<serial>.tar or data.C.N archives")
    for a in archives:
        yield from iter_caldata(a, load_raw=load_raw, verify=verify)
    for t in tars:
        yield from iter_caldata(t, load_raw=load_raw, verify=verify)


def read_caldata(path: str | os.PathLike, *, load_raw: bool = True, verify: bool = True) -> list[WhiteFrame]:
    """Read Lytro calibration frames (white and dark images) with their metadata.

    Parameters
    ----------
    path : str or Path
        ``caldata-<serial>.tar`` (files under any prefix), a folder of ``MOD_xxxx.RAW/.TXT``
        (or of tars / ``data.C.N`` archives), one ``MOD_xxxx.TXT``/``.RAW``, or a Lytro Desktop
        ``data.C.N`` archive (its ``data.C.*`` siblings are read too).
    load_raw : bool, default True
        Unpack the raw images; False reads metadata only (``raw`` is None). A full Illum
        white image takes 83 MB as uint16: use :func:`iter_caldata` to process many.
    verify : bool, default True
        Verify the SHA-1 of ``data.C.N`` archive sections.

    Returns
    -------
    list of WhiteFrame
        In file-name order; dark frames are included with ``is_dark=True``.

    Raises
    ------
    MissingFileError
        Nothing there, or a TXT without its RAW.
    LfpFormatError
        Wrong raw size, unknown camera model, bad JSON, bad archive.
    """
    return list(iter_caldata(path, load_raw=load_raw, verify=verify))


# -- writing -------------------------------------------------------------------------------
def write_caldata_tar(path: str | os.PathLike, frames: Iterable[Any], *, serial: str, prefix: str = "unitdata",
                      hot_pixels=None, force: bool = False) -> Path:
    """Write Illum pairing data ``caldata-<serial>.tar`` with the real layout.

    Parameters
    ----------
    path : str or Path
        Output tar (written atomically).
    frames : iterable of WhiteFrame-like
        Objects with ``raw`` (uint16 (H, W), 0..1023 DN) and ``metadata`` (frame metadata,
        picture layout or white-image layout; see :func:`white_metadata`); optional
        ``name`` (default ``MOD_%04d`` by position) and ``is_dark``.
    serial : str
        Camera serial number (TXT private metadata and ``unit_info.json``).
    prefix : str, default "unitdata"
        Folder inside the tar.
    hot_pixels : array_like of shape (N, 2), optional
        ``(x, y)`` of hot pixels for ``HOTPIXEL.BIN``.
    force : bool
        Overwrite an existing file.

    Returns
    -------
    Path

    Notes
    -----
    Each frame gets ``MOD_xxxx.RAW`` (10-bit packed, or 12-bit for F01 metadata),
    ``MOD_xxxx.TXT`` (``master.picture.frameArray[0].frame.{metadata,privateMetadata}``) and
    ``MOD_xxxx.GCT`` (:func:`geometry_correction_bytes`); ``cal_file_manifest.json`` lists every
    file with its ``sha1-`` hash, so a capture whose ``geometryCorrectionRef`` equals a
    ``.GCT`` hash selects that white image.
    """
    if not serial or not re.fullmatch(r"[A-Za-z0-9]+", str(serial)):
        raise InputError(f"{path}: serial must be letters and digits, got {serial!r}")
    members: list[tuple[str, bytes]] = []
    manifest = []
    mla = None
    names = set()
    frames = list(frames)
    if not frames:
        raise InputError(f"{path}: no frames to write")
    for i, fr in enumerate(frames):
        raw = getattr(fr, "raw", None)
        metadata = getattr(fr, "metadata", None)
        if raw is None or not isinstance(metadata, dict):
            raise InputError(f"{path}: frame {i} needs raw (H, W) and a metadata dict")
        name = str(getattr(fr, "name", None) or f"MOD_{i:04d}")
        if not re.fullmatch(r"MOD_\d{4}", name):
            raise InputError(f"{path}: frame {i} name {name!r} is not MOD_nnnn")
        if name in names:
            raise InputError(f"{path}: two frames are named {name}")
        names.add(name)
        meta = _to_white_layout(metadata)
        raw = np.asarray(raw)
        if raw.ndim != 2:
            raise ShapeError(f"{path}: frame {name} raw must be 2-D (H, W), got {raw.shape}")
        meta["image"]["height"], meta["image"]["width"] = int(raw.shape[0]), int(raw.shape[1])
        bits = int(_get(meta, "image", "rawDetails", "pixelPacking", "bitsPerPixel", default=10))
        packed = pack_raw12(raw) if bits == 12 else pack_raw10(raw)
        meta["image"]["rawDetails"]["pixelPacking"] = ({"bitsPerPixel": 12, "endianness": "big"} if bits == 12
                                                       else {"bitsPerPixel": 10, "endianness": "little"})
        gct = geometry_correction_bytes(meta, name)
        txt = json.dumps(white_txt_document(meta, serial=serial, is_dark=bool(getattr(fr, "is_dark", False)),
                                            derivation=sha1_ref(gct)), separators=(",", ":")).encode("ascii")
        for ext, data in (("RAW", packed), ("TXT", txt), ("GCT", gct)):
            members.append((f"{name}.{ext}", data))
            manifest.append({"name": f"{name}.{ext}", "hash": sha1_ref(data), "size": len(data)})
        mla = mla or _get(meta, "devices", "mla")
    hp = np.zeros((0, 2), dtype=np.int64) if hot_pixels is None else np.asarray(hot_pixels, dtype=np.int64)
    if hp.ndim != 2 or hp.shape[1] != 2 or (hp.size and hp.min() < 0):
        raise ShapeError(f"{path}: hot_pixels must be non-negative (x, y) pairs")
    hot = struct.pack("<I", hp.shape[0]) + hp[:, 0].astype("<u2").tobytes() + hp[:, 1].astype("<u2").tobytes()
    extras = [
        ("HOTPIXEL.BIN", hot),
        ("mla_calibration.json", json.dumps({"generator": f"lfproc {__version__}", "mla": mla or {}}).encode()),
        ("unit_info.json", json.dumps({"camera": {"serialNumber": str(serial), "model": "B01"},
                                       "generator": f"lfproc {__version__}"}).encode()),
    ]
    for fname, data in extras:
        members.append((fname, data))
        manifest.append({"name": fname, "hash": sha1_ref(data), "size": len(data)})
    members.append(("cal_file_manifest.json", json.dumps({"generator": f"lfproc {__version__}",
                                                         "calibrationFiles": manifest}, indent=1).encode()))
    with atomic_file(path, force=force) as tmp:
        with tarfile.open(tmp, "w", format=tarfile.USTAR_FORMAT) as tar:
            for fname, data in members:
                info = tarfile.TarInfo(f"{prefix.strip('/')}/{fname}" if prefix else fname)
                info.size = len(data)
                info.mtime = 1431492370  # fixed, so the tar is reproducible
                info.mode = 0o644
                tar.addfile(info, io.BytesIO(data))
    return Path(path)
