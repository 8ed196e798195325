"""The white-image database: white images of a camera, their lenslet grids, and selection.

``lfproc whites CALDATA -o DB_DIR`` (:func:`build_white_db`) reads calibration data
(:func:`lfproc.lytro.caldata.iter_caldata`: pairing tar, MOD folder, ``data.C.N``), drops dark
frames, estimates each white image's lenslet grid and writes ``DB_DIR``:

* ``whites.json``: the index (``schema`` ``"lfproc.white_db"``, lfproc version, source, one
  entry per white image: name, file, serial, camera model, zoom/focus steps, exposure,
  geometry hash, levels, Bayer pattern, white-target responses, grid; and the skipped frames
  with the reason);
* ``<serial>_<MOD_xxxx>.npz``: the raw white image (uint16, compressed) and its metadata.

Selection (:func:`select_white`) for a capture, in this order: the white whose geometry hash
equals the capture's ``geometryCorrectionRef``; else among the white images of the same
serial, the nearest zoom step, then the nearest focus step. A failure raises
:class:`~lfproc.errors.NoWhiteImageError` listing what the database holds and why nothing
matched. ``--white FILE`` bypasses the database.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import _untrusted as ut
from .._shared.progress import progress
from .._shared.reprs import short_repr
from .._version import __version__
from ..errors import (CalibrationError, FileFormatError, InputError, MissingFileError, NoWhiteImageError,
                      UnsafeFileError)
from ..io._atomic import atomic_dir
from .grid import ILLUM_SPACING_PX, F01_SPACING_PX, LensletGrid, estimate_grid
from .caldata import iter_caldata, read_caldata

__all__ = ["WhiteEntry", "WhiteDatabase", "build_white_db", "load_white_db", "select_white", "read_white_file",
           "INDEX_NAME", "white_responses"]

INDEX_NAME = "whites.json"
SCHEMA = "lfproc.white_db"


def white_responses(metadata: dict[str, Any]) -> list[float]:
    """Camera response ``(r, g, b)`` of the white target from ``devices.sensor.normalizedResponses``
    (``[1, 1, 1]`` when absent)."""
    try:
        nr = metadata["devices"]["sensor"]["normalizedResponses"][0]
        g = float(nr.get("gr", nr.get("gb", 1.0)))
        return [float(nr["r"]) / g, 1.0, float(nr["b"]) / g]
    except (KeyError, IndexError, TypeError, ValueError, ZeroDivisionError):
        return [1.0, 1.0, 1.0]


@dataclass(frozen=True)
class WhiteEntry:
    """One white image of the database (the ``whites`` list of ``whites.json``)."""

    name: str
    file: str
    serial: str | None
    camera_model: str
    zoom_step: int | None
    focus_step: int | None
    exposure_s: float | None
    geometry_hash: str | None
    black_level: float
    white_level: float
    cfa_pattern: str
    responses: tuple[float, float, float]
    grid: LensletGrid
    mean_level: float

    def to_dict(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in ("name", "file", "serial", "camera_model", "zoom_step", "focus_step",
                                           "exposure_s", "geometry_hash", "black_level", "white_level",
                                           "cfa_pattern", "mean_level")}
        d["responses"] = list(self.responses)
        d["grid"] = self.grid.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any] | ut.Node, *, where: str) -> "WhiteEntry":
        """An entry of ``whites.json``; every field is checked (errors name the file and field)."""
        n = d if isinstance(d, ut.Node) else ut.Node(d, where, "whites[?]", FileFormatError)
        n.as_dict()
        steps = dict(low=-(1 << 31), high=1 << 31)
        level = dict(low=0, high=65535)
        serial = n.get("serial")
        serial = None if serial is None else (str(serial.value) if isinstance(serial.value, int)
                                              and not isinstance(serial.value, bool) else serial.as_str(max_len=256))
        grid_node = n["grid"]
        grid_node.as_dict()
        try:
            grid = LensletGrid.from_dict(grid_node.value, where=f"{where}: field {grid_node.path!r}")
        except InputError as exc:
            raise FileFormatError(str(exc)) from None
        ut.check_dims(grid.image_size, source=where, what=f"field {grid_node.path + '.image_size'!r}",
                      max_pixels=ut.MAX_PIXELS)
        black = n["black_level"].as_float(**level)
        white = n["white_level"].as_float(**level)
        if white <= black:
            raise n.fail(f"white_level {white:g} is not above black_level {black:g}")
        return cls(name=n["name"].as_str(max_len=256, nonempty=True), file=n["file"].as_str(max_len=4096, nonempty=True),
                   serial=serial, camera_model=n["camera_model"].as_str(choices=("B01", "F01")),
                   zoom_step=n.opt_int("zoom_step", **steps), focus_step=n.opt_int("focus_step", **steps),
                   exposure_s=n.opt_float("exposure_s", low=0, high=1e6),
                   geometry_hash=n.opt_str("geometry_hash", max_len=64),
                   black_level=black, white_level=white,
                   cfa_pattern=n["cfa_pattern"].as_str(choices=("RGGB", "GRBG", "GBRG", "BGGR")),
                   responses=tuple(n["responses"].as_floats(length=3, low=0, strict_low=True, high=1e6)),
                   grid=grid, mean_level=n.opt_float("mean_level", 0.0, low=-1e6, high=1e6))

    def describe(self) -> str:
        return (f"{self.name} (serial {self.serial}, zoom {self.zoom_step}, focus {self.focus_step}, "
                f"hash {self.geometry_hash or 'none'})")

    def load_raw(self, db_dir: Path) -> np.ndarray:
        """The raw white image (uint16, the grid's image size) from the database folder;
        its ``file`` must lie inside ``db_dir``."""
        index = Path(db_dir) / INDEX_NAME
        path = ut.resolve_inside(db_dir, self.file, source=index, field=f"file of {self.name}")
        if not path.is_file():
            raise MissingFileError(f"{path}: white image listed in {index} is missing")
        return ut.read_npz(path, names=["raw"], expect={"raw": (tuple(self.grid.image_size), "uint16")})["raw"]


@short_repr
@dataclass(frozen=True)
class WhiteDatabase:
    """A loaded white-image database (:func:`load_white_db`)."""

    path: Path
    entries: tuple[WhiteEntry, ...]
    skipped: tuple[dict, ...]
    index: dict

    def describe(self) -> str:
        if not self.entries:
            return "the database holds no white images"
        return "the database holds " + "; ".join(e.describe() for e in self.entries)


def _approx_spacing(model: str) -> float:
    return F01_SPACING_PX if model == "F01" else ILLUM_SPACING_PX


def build_white_db(caldata: str | os.PathLike, out_dir: str | os.PathLike, *, force: bool = False,
                   verify: bool = True) -> WhiteDatabase:
    """Build a white-image database from Lytro calibration data.

    Parameters
    ----------
    caldata : path
        ``caldata-<serial>.tar``, a folder of ``MOD_xxxx.RAW/.TXT``, or a ``data.C.N`` archive.
    out_dir : path
        Database folder (written atomically; must not exist unless ``force``).
    force : bool
        Replace an existing folder.
    verify : bool
        Verify SHA-1s of archive sections.

    Returns
    -------
    WhiteDatabase

    Raises
    ------
    MissingFileError, LfpFormatError
        Unreadable calibration data.
    NoWhiteImageError
        Only dark frames (or nothing usable) in ``caldata``.
    CalibrationError
        A white image has no measurable lenslet grid.
    """
    caldata = Path(caldata)
    entries: list[WhiteEntry] = []
    skipped: list[dict] = []
    with atomic_dir(out_dir, force=force) as tmp:
        for fr in progress(iter_caldata(caldata, load_raw=True, verify=verify), desc="white images"):
            info = {"name": fr.name, "serial": fr.serial, "zoom_step": fr.zoom_step, "focus_step": fr.focus_step}
            if fr.is_dark:
                skipped.append(info | {"reason": "dark frame"})
                continue
            black = float(fr.black_level.get("gr", next(iter(fr.black_level.values())))) if fr.black_level else 0.0
            white = float(fr.white_level) if fr.white_level is not None else float(fr.raw.max())
            mean = float((fr.raw.mean(dtype=np.float64) - black) / max(white - black, 1.0))
            try:
                grid = estimate_grid(fr.raw, approx_spacing_px=_approx_spacing(fr.camera_model))
            except CalibrationError as exc:
                raise CalibrationError(f"{fr.source or caldata}: {exc}") from None
            # the serial comes from the calibration data: it must be a plain name (see caldata)
            fname = ut.safe_filename(f"{fr.serial or 'unknown'}_{fr.name}.npz", what="white-image file name",
                                     source=caldata)
            if not ut.inside(tmp, tmp / fname):  # pragma: no cover - safe_filename already ensures it
                raise UnsafeFileError(f"{caldata}: {fname} would be written outside {out_dir}")
            np.savez_compressed(tmp / fname, raw=np.asarray(fr.raw, dtype=np.uint16),
                                metadata=np.array(json.dumps(fr.metadata)))
            entries.append(WhiteEntry(name=fr.name, file=fname, serial=fr.serial, camera_model=fr.camera_model,
                                      zoom_step=fr.zoom_step, focus_step=fr.focus_step, exposure_s=fr.exposure_s,
                                      geometry_hash=(fr.geometry_hash or None) and str(fr.geometry_hash).lower(),
                                      black_level=black, white_level=white, cfa_pattern=fr.cfa_pattern or "GRBG",
                                      responses=tuple(white_responses(fr.metadata)), grid=grid, mean_level=mean))
        if not entries:
            raise NoWhiteImageError(f"{caldata}: no white images to store: "
                                    + (", ".join(f"{s['name']} ({s['reason']})" for s in skipped) or "no frames"))
        index = {"schema": SCHEMA, "schema_version": 1, "lfproc_version": __version__, "source": str(caldata),
                 "whites": [e.to_dict() for e in entries], "skipped": skipped}
        (tmp / INDEX_NAME).write_text(json.dumps(index, indent=2))
    return WhiteDatabase(path=Path(out_dir), entries=tuple(entries), skipped=tuple(skipped), index=index)


def load_white_db(db_dir: str | os.PathLike) -> WhiteDatabase:
    """Load a database written by :func:`build_white_db`.

    Parameters
    ----------
    db_dir : str or os.PathLike
        The database folder (holds ``whites.json`` and one ``.npz`` per white image).

    Returns
    -------
    WhiteDatabase
        Its ``entries`` (one :class:`WhiteEntry` per white image: serial, zoom and focus
        steps, levels, lenslet grid...), the frames ``skipped`` when it was built, and the
        ``index`` as stored.

    Raises
    ------
    MissingFileError
        No such folder, or no index in it.
    FileFormatError
        The index is not a white-image database's, or an entry is malformed.
    UnsafeFileError
        An entry names a file outside the folder.
    """
    db_dir = Path(db_dir)
    index_path = db_dir / INDEX_NAME
    if not db_dir.is_dir():
        raise MissingFileError(f"{db_dir}: no such white-image database folder (make one with 'lfproc whites')")
    if not index_path.is_file():
        raise MissingFileError(f"{index_path}: missing: {db_dir} is not a white-image database "
                               "(make one with 'lfproc whites')")
    doc = ut.load_json(index_path)
    if not doc.is_dict() or doc.value.get("schema") != SCHEMA:
        found = doc.value.get("schema") if doc.is_dict() else doc.value
        raise FileFormatError(f"{index_path}: expected schema {SCHEMA!r}, found {ut.show(found)}")
    whites = doc.get("whites")
    entries = tuple(WhiteEntry.from_dict(d, where=str(index_path)) for d in (whites.as_list() if whites else []))
    for e in entries:  # entries must name files inside the database folder
        ut.resolve_inside(db_dir, e.file, source=index_path, field=f"file of {e.name}")
    skipped = doc.get("skipped")
    skipped = tuple(s.value for s in skipped.as_list()) if skipped is not None else ()
    return WhiteDatabase(path=db_dir, entries=entries, skipped=skipped, index=doc.value)


def select_white(db: WhiteDatabase, *, serial: str | None, zoom_step: int | None, focus_step: int | None,
                 geometry_hash: str | None = None, raw_shape: tuple[int, int] | None = None
                 ) -> tuple[WhiteEntry, str]:
    """Pick the white image for a capture; returns ``(entry, how)``.

    ``how`` is ``"geometry hash"`` or ``"serial, nearest zoom/focus"``. White images of
    another sensor size (``raw_shape``) are never chosen.

    Raises
    ------
    NoWhiteImageError
        Nothing matches; the message lists the database and the reason.
    """
    entries = list(db.entries)
    if raw_shape is not None:
        entries = [e for e in entries if tuple(e.grid.image_size) == tuple(raw_shape)]
        if not entries:
            raise NoWhiteImageError(f"{db.path}: no white image of the capture's size {raw_shape[1]} x {raw_shape[0]}; "
                                    f"{db.describe()} (sizes "
                                    f"{sorted({f'{e.grid.image_size[1]} x {e.grid.image_size[0]}' for e in db.entries})})")
    if geometry_hash:
        hits = [e for e in entries if e.geometry_hash and e.geometry_hash.lower() == str(geometry_hash).lower()]
        if hits:
            return hits[0], "geometry hash"
    if serial is None:
        raise NoWhiteImageError(f"{db.path}: the capture has no serial number"
                                f"{' and its geometry hash matches no white image' if geometry_hash else ''}; "
                                f"{db.describe()}; pass --white FILE")
    same = [e for e in entries if e.serial is not None and str(e.serial) == str(serial)]
    if not same:
        why = f"no white image of camera {serial}"
        if geometry_hash:
            why += f" and none with geometry hash {geometry_hash}"
        raise NoWhiteImageError(f"{db.path}: {why}; {db.describe()}; pass --white FILE or build the database "
                                "from this camera's calibration data")

    def key(e: WhiteEntry):
        dz = abs(e.zoom_step - zoom_step) if (e.zoom_step is not None and zoom_step is not None) else float("inf")
        df = abs(e.focus_step - focus_step) if (e.focus_step is not None and focus_step is not None) else float("inf")
        return dz, df

    return min(same, key=key), "serial, nearest zoom/focus"


def read_white_file(path: str | os.PathLike) -> tuple[np.ndarray, WhiteEntry]:
    """An explicit white image (``--white FILE``): a database ``.npz`` (next to its
    ``whites.json``) or a ``MOD_xxxx.RAW``/``.TXT`` pair (grid estimated now)."""
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such white image file")
    if path.suffix.lower() == ".npz":
        db = load_white_db(path.parent)
        for e in db.entries:
            if e.file == path.name:
                return e.load_raw(db.path), e
        raise InputError(f"{path}: not listed in {path.parent / INDEX_NAME}")

    frames = [f for f in read_caldata(path) if not f.is_dark]
    if len(frames) != 1:
        raise InputError(f"{path}: --white expects one white image (a MOD_xxxx.RAW/.TXT pair or a database .npz), "
                         f"found {len(frames)} white frames")
    fr = frames[0]
    black = float(fr.black_level.get("gr", 0.0)) if fr.black_level else 0.0
    white = float(fr.white_level) if fr.white_level is not None else float(fr.raw.max())
    grid = estimate_grid(fr.raw, approx_spacing_px=_approx_spacing(fr.camera_model))
    entry = WhiteEntry(name=fr.name, file=str(path), serial=fr.serial, camera_model=fr.camera_model,
                       zoom_step=fr.zoom_step, focus_step=fr.focus_step, exposure_s=fr.exposure_s,
                       geometry_hash=fr.geometry_hash, black_level=black, white_level=white,
                       cfa_pattern=fr.cfa_pattern or "GRBG", responses=tuple(white_responses(fr.metadata)),
                       grid=grid, mean_level=0.0)
    return fr.raw, entry
