"""Calibration frames: manifests and the raw frames they list.

A *manifest* lists bias, dark and flat frames with their ISO and exposure time, as CSV
(header ``path,kind,iso,exposure_s[,temperature_c][,group][,cfa_pattern]``) or JSON (a
list of such objects, or ``{"frames": [...], "cfa_pattern": ..., "adc_bits": ...}``).
Relative paths are resolved against the manifest's folder, and every frame must lie inside
that folder (or inside a folder the caller names, ``root=`` / ``--frames-root``): a path that
leads elsewhere (``../..``, an absolute path, a symlink out) is refused.

Frames are read as 2-D ``uint16`` counts (DN) with what the file says about its levels:

* camera raws through rawpy (``raw_image_visible``, ``black_level_per_channel``,
  ``white_level``, the CFA of the visible area);
* Lytro raws (``.lfr``, ``.lfp``, ``.raw``) through :func:`lfproc.lytro.read_capture`;
* 16-bit (or 8-bit) single-channel PNG/TIFF through OpenCV (``IMREAD_UNCHANGED``).

Frames of one group must agree in size, bit depth and CFA: :class:`FrameChecker` raises
:class:`~lfproc.errors.CalibrationError` naming the files that differ.
"""

from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfproc import _untrusted as ut
from lfproc.errors import CalibrationError, FileFormatError, InputError, MissingFileError
from lfproc.lytro.capture import read_capture
from lfproc._shared.reprs import short_repr
from lfproc.io.images import imread
from lfproc._shared.deps import require

__all__ = [
    "FrameRecord",
    "Frame",
    "FRAME_KINDS",
    "read_manifest",
    "write_manifest",
    "read_frame",
    "FrameChecker",
    "RAW_SUFFIXES",
    "LYTRO_SUFFIXES",
    "IMAGE_SUFFIXES",
]

FRAME_KINDS = ("bias", "dark", "flat")
LYTRO_SUFFIXES = (".lfr", ".lfp", ".raw")
IMAGE_SUFFIXES = (".png", ".tif", ".tiff")
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf", ".pef", ".srw", ".3fr", ".iiq",
                ".erf", ".mrw", ".nrw", ".x3f", ".rwl", ".kdc", ".dcr", ".sr2", ".mef", ".mos")
_CFA = ("RGGB", "GRBG", "GBRG", "BGGR")
_MONO = "mono"  # a monochrome sensor (calib.profile.MONO)
_COLUMNS = ("path", "kind", "iso", "exposure_s", "temperature_c", "group", "cfa_pattern")


@dataclass(frozen=True)
class FrameRecord:
    """One manifest row.

    Attributes
    ----------
    path : Path
        Absolute (resolved) frame path.
    kind : {"bias", "dark", "flat"}
    iso : float or None
        ``None`` only for EMVA 1288 data, which give no ISO.
    exposure_s : float
        Exposure time in seconds (>= 0).
    temperature_c : float or None
        Sensor temperature in degrees Celsius, when known.
    group : str
        Flats with the same ISO, exposure and group form one level (pairs are taken in
        manifest order); empty by default.
    cfa_pattern : str or None
        Bayer layout when the manifest gives one (PNG/TIFF frames carry none).
    where : str
        ``"manifest.csv row 3"``, for error messages.
    """

    path: Path
    kind: str
    iso: float | None
    exposure_s: float
    temperature_c: float | None = None
    group: str = ""
    cfa_pattern: str | None = None
    where: str = ""


@short_repr
@dataclass(frozen=True)
class Frame:
    """A frame's counts and what its file says about them.

    Attributes
    ----------
    data : ndarray of shape (H, W), uint16
    path : Path
    bit_depth : int
        Storage bits of the file (8 or 16 for PNG/TIFF; the ADC bits for raws).
    cfa_pattern : str or None
        Bayer layout of the top-left 2x2 pixels, row-major (e.g. ``"RGGB"``).
    black_level_dn : tuple of float or None
        Black level per CFA position (0,0), (0,1), (1,0), (1,1), when the file gives it.
    white_level_dn : float or None
    iso, exposure_s : float or None
        From the file's metadata, when it has them.
    source : str
        ``"rawpy"``, ``"lytro"`` or ``"image"``.
    """

    data: np.ndarray = field(repr=False)
    path: Path
    bit_depth: int
    cfa_pattern: str | None = None
    black_level_dn: tuple[float, ...] | None = None
    white_level_dn: float | None = None
    iso: float | None = None
    exposure_s: float | None = None
    source: str = "image"

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.data.shape)


# -- manifests -----------------------------------------------------------------------------
def _number(value: Any, *, name: str, where: str, required: bool, low: float | None = 0.0) -> float | None:
    if value is None or (isinstance(value, str) and not value.strip()):
        if required:
            raise InputError(f"{where}: missing {name}; every frame needs its {name}")
        return None
    if isinstance(value, bool):
        raise InputError(f"{where}: {name}: expected a number, found {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{where}: {name}: expected a number, found {ut.show(value)}") from None
    if not math.isfinite(number) or (low is not None and number < low):
        what = "a finite number" + (f" >= {low:g}" if low is not None else "")
        raise InputError(f"{where}: {name}: expected {what}, found {ut.show(value)}")
    return number


def _text(value: Any, *, name: str, where: str, max_len: int = 4096) -> str:
    if value is None:
        return ""
    if not isinstance(value, (str, int, float)) or isinstance(value, bool) or len(str(value)) > max_len:
        raise InputError(f"{where}: {name}: expected text of at most {max_len} characters, found {ut.show(value)}")
    return str(value)


def _record(row: dict[str, Any], *, base: Path, where: str, defaults: dict[str, Any],
            root: Path | None = None) -> FrameRecord:
    row = {str(k).strip().lower(): v for k, v in row.items() if k is not None}
    path = row.get("path")
    if path is None or not _text(path, name="path", where=where).strip():
        raise InputError(f"{where}: missing path")
    kind = _text(row.get("kind"), name="kind", where=where).strip().lower()
    if kind not in FRAME_KINDS:
        raise InputError(f"{where}: kind: expected one of {', '.join(FRAME_KINDS)}, found {row.get('kind')!r}")
    iso = _number(row.get("iso"), name="ISO", where=where, required=True, low=1e-9)
    exposure_s = _number(row.get("exposure_s"), name="exposure_s", where=where, required=True)
    temperature = _number(row.get("temperature_c"), name="temperature_c", where=where, required=False, low=None)
    cfa = row.get("cfa_pattern") or defaults.get("cfa_pattern")
    if cfa is not None:
        cfa = _text(cfa, name="cfa_pattern", where=where).strip().upper() or None
        if cfa == _MONO.upper():
            cfa = _MONO
        if cfa is not None and cfa not in _CFA + (_MONO,):
            raise InputError(f"{where}: cfa_pattern: expected one of {', '.join(_CFA + (_MONO,))}, found {cfa!r}")
    p = ut.resolve_inside(base, str(path), source=where, field="path", root=root)
    return FrameRecord(path=p, kind=kind, iso=iso, exposure_s=exposure_s, temperature_c=temperature,
                       group=_text(row.get("group"), name="group", where=where, max_len=256).strip(),
                       cfa_pattern=cfa, where=where)


#: Most frames one manifest may list.
MAX_MANIFEST_FRAMES = 100000


def read_manifest(path: str | os.PathLike, *, root: str | os.PathLike | None = None
                  ) -> tuple[list[FrameRecord], dict[str, Any]]:
    """Read a frame manifest (CSV or JSON).

    Parameters
    ----------
    path : str or Path
        ``.csv`` or ``.json`` manifest.
    root : str or Path, optional
        A folder the frames may lie in (absolute paths allowed inside it); by default every
        frame must lie inside the manifest's folder.

    Returns
    -------
    records : list of FrameRecord
        In manifest order.
    options : dict
        Manifest-wide settings (JSON only): ``cfa_pattern``, ``adc_bits``, ``name``.

    Raises
    ------
    MissingFileError
        The manifest does not exist.
    FileFormatError
        Not a readable CSV/JSON manifest.
    InputError
        A row lacks its path, kind, ISO or exposure time (the row is named).
    UnsafeFileError
        A frame path leads outside the manifest's folder (or ``root``).
    """
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: no such manifest file")
    base = path.parent
    if root is not None:
        root = Path(root)
        if not root.is_dir():
            raise MissingFileError(f"{root}: no such folder (frames root)")
    text = ut.read_text(path, what="text manifest (CSV or JSON)", encoding="utf-8-sig")
    options: dict[str, Any] = {}
    if path.suffix.lower() == ".json" or text.lstrip().startswith(("{", "[")):
        try:
            doc = ut.parse_json(text, source=path)
        except FileFormatError as exc:
            raise FileFormatError(f"{path}: not a JSON manifest ({str(exc).removeprefix(f'{path}: ')})") from None
        if isinstance(doc, dict):
            rows = doc.get("frames")
            node = ut.Node(doc, path, error=FileFormatError)
            if node.has("cfa_pattern"):
                options["cfa_pattern"] = node["cfa_pattern"].as_str(choices=_CFA)
            if node.has("adc_bits"):
                options["adc_bits"] = node["adc_bits"].as_int(low=1, high=32)
            if node.has("name"):
                options["name"] = node["name"].as_str(max_len=256)
        else:
            rows = doc
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise FileFormatError(f"{path}: expected a list of frame objects (or {{\"frames\": [...]}})")
        if len(rows) > MAX_MANIFEST_FRAMES:
            raise FileFormatError(f"{path}: {len(rows)} frames, above the limit of {MAX_MANIFEST_FRAMES}")
        records = [_record(r, base=base, where=f"{path.name} frame {i}", defaults=options, root=root)
                   for i, r in enumerate(rows)]
    else:
        try:
            reader = csv.DictReader(text.splitlines())
            header = [h.strip().lower() if isinstance(h, str) else "" for h in (reader.fieldnames or [])]
            missing = [c for c in ("path", "kind", "iso", "exposure_s") if c not in header]
            if missing:
                raise FileFormatError(f"{path}: CSV header lacks column(s) {', '.join(missing)}; found "
                                      f"{ut.show(', '.join(header) or 'none', 200)}")
            # row numbers as a text editor shows them (the header is line 1)
            records = []
            for i, r in enumerate(reader):
                if i >= MAX_MANIFEST_FRAMES:
                    raise FileFormatError(f"{path}: more than {MAX_MANIFEST_FRAMES} frames")
                records.append(_record(r, base=base, where=f"{path.name} line {i + 2}", defaults=options, root=root))
        except csv.Error as exc:
            raise FileFormatError(f"{path}: not a readable CSV manifest ({exc})") from None
    if not records:
        raise FileFormatError(f"{path}: the manifest lists no frames")
    return records, options


def write_manifest(records: list[FrameRecord], path: str | os.PathLike, *, relative_to: Path | None = None,
                   options: dict[str, Any] | None = None) -> None:
    """Write records as CSV (``.csv``) or JSON (``.json``) to ``path`` (not atomically: call it
    inside :func:`lfproc.io.atomic_dir` or on a temporary path)."""
    path = Path(path)
    base = Path(relative_to) if relative_to is not None else path.parent

    def row(r: FrameRecord) -> dict[str, Any]:
        p = r.path
        try:
            p = p.relative_to(base)
        except ValueError:
            pass
        return {"path": p.as_posix(), "kind": r.kind, "iso": r.iso, "exposure_s": r.exposure_s,
                "temperature_c": r.temperature_c, "group": r.group, "cfa_pattern": r.cfa_pattern}

    rows = [row(r) for r in records]
    if path.suffix.lower() == ".json":
        doc = {"frames": rows, **(options or {})}
        path.write_text(json.dumps(doc, indent=1))
    else:
        with open(path, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(_COLUMNS))
            writer.writeheader()
            for r in rows:
                writer.writerow({k: ("" if v is None else (repr(v) if isinstance(v, float) else v)) for k, v in r.items()})


# -- frames ---------------------------------------------------------------------------------
def _cfa_from_rawpy(raw) -> str | None:
    try:
        desc = raw.color_desc.decode()
        colors = raw.raw_colors_visible[:2, :2].ravel()
        pattern = "".join(desc[int(i)] for i in colors)
    except Exception:  # pragma: no cover - exotic raws
        return None
    return pattern if pattern in _CFA else None


def _read_rawpy(path: Path) -> Frame:
    require("rawpy", purpose="reading camera raw files")
    import rawpy

    try:
        with rawpy.imread(str(path)) as raw:
            data = np.array(raw.raw_image_visible, dtype=np.uint16, copy=True)
            colors = raw.raw_colors_visible[:2, :2].ravel()
            black = tuple(float(raw.black_level_per_channel[int(i)]) for i in colors)
            white = float(raw.white_level)
            cfa = _cfa_from_rawpy(raw)
            iso = exposure = None
            other = getattr(raw, "other", None)
            if other is not None:
                iso = float(other.iso_speed) or None
                exposure = float(other.shutter_speed) or None
    except (rawpy.LibRawError, OSError) as exc:
        raise FileFormatError(f"{path}: cannot read the camera raw ({type(exc).__name__}: {exc})") from None
    bits = max(1, int(math.ceil(math.log2(white + 1)))) if white > 0 else 16
    return Frame(data=data, path=path, bit_depth=bits, cfa_pattern=cfa, black_level_dn=black, white_level_dn=white,
                 iso=iso, exposure_s=exposure, source="rawpy")


def _read_lytro(path: Path) -> Frame:
    cap = read_capture(path)
    cfa = getattr(cap, "cfa_pattern", None)
    levels = getattr(cap, "black_level", None)
    black = None
    if isinstance(levels, dict) and cfa in _CFA:
        names = _channel_names(cfa)
        lookup = {"R": "r", "Gr": "gr", "Gb": "gb", "B": "b"}
        try:
            black = tuple(float(levels[lookup[n]]) for n in names)
        except KeyError:
            black = None
    white = getattr(cap, "white_level", None)
    bits = int(math.ceil(math.log2(float(white) + 1))) if white else 16
    return Frame(data=np.asarray(cap.raw, dtype=np.uint16), path=path, bit_depth=bits, cfa_pattern=cfa,
                 black_level_dn=black, white_level_dn=float(white) if white else None,
                 iso=getattr(cap, "iso", None), exposure_s=getattr(cap, "exposure_s", None), source="lytro")


def _read_image(path: Path) -> Frame:
    import cv2

    try:
        data = imread(path, cv2.IMREAD_UNCHANGED)
    except FileFormatError as exc:
        detail = str(exc).removeprefix(f"{path}: ")
        raise FileFormatError(f"{path}: cannot read the image (corrupt, truncated or not a PNG/TIFF: {detail})") \
            from None
    if data.ndim != 2:
        raise FileFormatError(f"{path}: expected a single-channel raw frame, found {data.shape[2]} channels")
    if data.dtype == np.uint8:
        bits = 8
    elif data.dtype == np.uint16:
        bits = 16
    else:
        raise FileFormatError(f"{path}: expected 8- or 16-bit unsigned integer counts, found {data.dtype}")
    return Frame(data=data.astype(np.uint16, copy=False), path=path, bit_depth=bits, source="image")


def read_frame(path: str | os.PathLike) -> Frame:
    """Read one calibration frame (camera raw, Lytro raw or 16-bit PNG/TIFF).

    Raises
    ------
    MissingFileError
        No such file.
    FileFormatError
        The file cannot be read as a frame (the message names it).
    """
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such frame file")
    if path.is_dir():
        raise FileFormatError(f"{path}: expected a frame file, found a folder")
    suffix = path.suffix.lower()
    if suffix in LYTRO_SUFFIXES:
        return _read_lytro(path)
    if suffix in IMAGE_SUFFIXES:
        return _read_image(path)
    if suffix in RAW_SUFFIXES:
        return _read_rawpy(path)
    raise FileFormatError(
        f"{path}: unknown frame type {suffix or '(no suffix)'}; expected a camera raw, a Lytro raw "
        f"({', '.join(LYTRO_SUFFIXES)}) or a 16-bit image ({', '.join(IMAGE_SUFFIXES)})"
    )


def _channel_names(cfa: str | None) -> tuple[str, str, str, str]:
    """Names of the CFA positions (0,0), (0,1), (1,0), (1,1): R, Gr, Gb, B (Gr = green in the red row)."""
    if cfa is None or cfa == _MONO:
        return ("c00", "c01", "c10", "c11")
    names = []
    for i, letter in enumerate(cfa):
        if letter != "G":
            names.append(letter)
        else:
            row = cfa[:2] if i < 2 else cfa[2:]
            names.append("Gr" if "R" in row else "Gb")
    return tuple(names)


class FrameChecker:
    """Checks that frames of one group agree in size, bit depth and CFA.

    The first frame sets the reference; a frame that differs raises
    :class:`CalibrationError` naming both files.
    """

    def __init__(self, group: str):
        self.group = group
        self.first: Frame | None = None

    def check(self, frame: Frame, *, cfa_override: str | None = None) -> None:
        cfa = frame.cfa_pattern or cfa_override
        if self.first is None:
            self.first = frame
            self.cfa = cfa
            return
        ref = self.first
        problems = []
        if frame.shape != ref.shape:
            problems.append(f"size {frame.shape[0]}x{frame.shape[1]} vs {ref.shape[0]}x{ref.shape[1]}")
        if frame.bit_depth != ref.bit_depth:
            problems.append(f"bit depth {frame.bit_depth} vs {ref.bit_depth}")
        if cfa != self.cfa:
            problems.append(f"CFA {cfa} vs {self.cfa}")
        if problems:
            raise CalibrationError(
                f"mixed frames in {self.group}: {frame.path} differs from {ref.path} ({'; '.join(problems)})"
            )
