"""Building an HDR light-field data set from folders of exposure brackets.

As the natural HDR light-field data set of Miandji et al., "Compressive HDR Light Field Imaging
Using a Single Multi-ISO Sensor" (IEEE TCI 2021, section IV-A): Lytro Illum brackets of each
scene, decoded and merged into one HDR light field per scene.

Layout of ``SCENES_DIR``: one folder per scene holding its bracket (Lytro captures, or
decoded light-field EXRs / view folders, or 2-D images: anything :func:`lfproc.bracket.read_bracket`
reads), optionally calibration data (a folder or ``.tar`` whose name starts with ``caldata``,
used to build the white-image database of Lytro captures). When a scene holds Lytro
captures only those are the bracket; files named ``truth.*`` (the ground truth written by
``lfproc virtual-illum``) and hidden files are never part of it.

Exposure times come from each input's metadata (EXIF ``ExposureTime``, lfproc's ``exposure_s``,
Lytro metadata) unless the scene folder holds an **exposure file** (:data:`EXPOSURE_FILES`),
which then gives them for every input of the bracket: ``exposures.txt`` or ``exposures.json``
(see "Exposure files" below).

Layout of ``DATASET_DIR`` (every file written atomically)::

    scenes/<scene>/hdr.exr            the merged HDR light field
    scenes/<scene>/preview.png        tone-mapped centre view
    scenes/<scene>/histogram.png      histogram of log2 luminance (dynamic range)
    scenes/<scene>/record.json        the scene's manifest row
    done/<scene>.json                 done-record (written last: the scene is finished)
    manifest.json, manifest.csv       rebuilt from the done-records after every run
    failed.json                       scenes that failed in the last run and why

Resuming: a scene whose done-record and outputs exist is skipped; its output folder is
written as a whole (temporary folder, then rename) before the done-record, so an interrupted
run leaves either a finished scene or none. A failed scene is reported and does not stop the
others. A new run removes the hidden temporaries a killed run left (those whose process is gone:
:func:`lfproc.io.clean_stale`).

Exposure files
--------------
The forms :func:`read_exposure_file` reads (``#`` starts a comment):

* ``NAME SECONDS`` lines (``img_1.jpg 1/8``; seconds as a number or a fraction);
* ``SECONDS`` lines only, in the order of the inputs' sorted names (``bare_order="sorted"``,
  ``lfproc dataset build``) or in the inputs' order (``bare_order="inputs"``, ``lfproc merge``);
* Debevec's HDRShop image list (``memorial.hdr_image_list.txt`` of the Memorial bracket): an
  optional first line holding the number of images, then ``NAME 1/SHUTTER_SPEED F_STOP
  [GAIN_DB [ND_FILTERS]]`` lines. Recognised by its lines of 3 to 5 fields, or by a comment
  naming ``1/shutter_speed`` (then 2-field lines are ``NAME 1/t`` too). The second field is
  the *inverse* exposure time: ``memorial0061.png 0.03125 8 0 0`` is 32 s. The aperture,
  gain and ND filter must be the same on every line (lfproc merges exposure times only);
  the image count must match the lines;
* JSON (``.json``): ``{"NAME": SECONDS, ...}`` or a list of seconds.

Names are matched to the inputs' file names, or to the file names without their suffix when
that is unique (the Memorial list names ``.ppm`` files, usually shipped as ``.png``). Errors
name the file and line and what is missing or extra.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._version import __version__
from .._shared.hashing import file_sha256
from ..errors import InputError, LfprocWarning, MissingFileError
from .. import _untrusted as ut
from .._shared.parallel import dask_client, max_workers
from .._shared.progress import progress
from .._shared.validation import check_choice, check_count
from ..hdr import BRACKET_SUFFIXES, merge_files, read_exif_exposure
from ..hdr._bracket import IMAGE_SUFFIXES_LDR, LYTRO_SUFFIXES
from ..io import write_lightfield
from ..io._atomic import atomic_dir, atomic_file, clean_stale
from ..lytro import whites
from ..preview import write_preview
from ..sensor import load_profile

__all__ = [
    "Scene",
    "EXPOSURE_FILES",
    "read_exposure_file",
    "find_scenes",
    "process_scene",
    "build_dataset",
    "read_manifest",
    "SCENE_OUTPUTS",
    "MANIFEST_FIELDS",
]

SCENE_OUTPUTS = ("hdr.exr", "preview.png", "histogram.png", "record.json")
#: Per-scene exposure files, looked for in this order.
EXPOSURE_FILES = ("exposures.txt", "exposures.json")
MANIFEST_FIELDS = ("scene", "method", "exposures_s", "dynamic_range_stops", "saturated_fraction", "views", "size",
                   "units", "hdr", "preview", "histogram", "sources", "sha256")


@dataclass(frozen=True)
class Scene:
    """One scene folder: its name, bracket inputs and optional calibration data.

    Made by :func:`find_scenes`.

    Parameters
    ----------
    name : str
        The scene's name (its folder's name).
    folder : pathlib.Path
        The scene folder.
    inputs : tuple of pathlib.Path
        The bracket, sorted by name: the Lytro captures when there are any, else every image,
        light-field file and folder of views (``truth.*`` and hidden files left out).
    caldata : pathlib.Path, optional
        Lytro calibration data (a file or folder whose name starts with ``caldata``).
    exposure_file : pathlib.Path, optional
        ``exposures.txt`` or ``exposures.json`` when the folder holds one.
    """

    name: str
    folder: Path
    inputs: tuple[Path, ...]
    caldata: Path | None = None
    exposure_file: Path | None = None


def _scene_of(folder: Path) -> Scene:
    caldata = None
    inputs: list[Path] = []
    for p in sorted(folder.iterdir()):
        if p.name.startswith("."):
            continue
        if p.name.lower().startswith("caldata"):
            caldata = p
            continue
        if p.stem.lower() == "truth":
            continue
        if p.is_file() and p.suffix.lower() in BRACKET_SUFFIXES:
            inputs.append(p)
        elif p.is_dir():
            inputs.append(p)  # a folder of views
    lytro = [p for p in inputs if p.suffix.lower() in LYTRO_SUFFIXES]
    exposure_file = next((folder / n for n in EXPOSURE_FILES if (folder / n).is_file()), None)
    return Scene(name=folder.name, folder=folder, inputs=tuple(lytro or inputs), caldata=caldata,
                 exposure_file=exposure_file)


def _seconds(text: str, where: str) -> float:
    try:
        if "/" in text:
            num, den = text.split("/", 1)
            value = float(num) / float(den)
        else:
            value = float(text)
    except (ValueError, ZeroDivisionError):
        raise InputError(f"{where}: expected seconds (a number or a fraction like 1/8), found {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise InputError(f"{where}: expected a positive exposure time in seconds, found {text!r}")
    return value


def _match_names(path: Path, by_name: dict[str, float], names: list[str]) -> list[float]:
    """The times of ``names`` from ``by_name``: by file name, else by name without its suffix (a list
    written for ``.ppm`` or ``.hdr`` files of images since converted to ``.png``) when that is unique."""
    stems: dict[str, list[str]] = {}
    for key in by_name:
        stems.setdefault(Path(key).stem, []).append(key)
    used: set[str] = set()
    out: list[float | None] = []
    for name in names:
        key = name if name in by_name else None
        if key is None and len(stems.get(Path(name).stem, [])) == 1:
            key = stems[Path(name).stem][0]
        out.append(None if key is None else by_name[key])
        if key is not None:
            used.add(key)
    missing = [n for n, v in zip(names, out) if v is None]
    extra = sorted(set(by_name) - used)
    if missing or extra:
        raise InputError(f"{path}: " + "; ".join(
            ([f"no exposure time for {', '.join(missing)}"] if missing else [])
            + ([f"names not in the bracket: {', '.join(extra)}"] if extra else [])))
    return [float(v) for v in out]  # type: ignore[arg-type]


def read_exposure_file(path: str | os.PathLike, inputs, *, bare_order: str = "sorted") -> list[float]:
    """Exposure times (s) of ``inputs`` (paths, in bracket order) from an exposure file.

    Forms: ``NAME SECONDS`` lines, bare ``SECONDS`` lines, Debevec's HDRShop image list or JSON
    (see "Exposure files" in the module documentation). Errors name the file and line and what
    is missing or extra.

    Parameters
    ----------
    path : str or os.PathLike
        The exposure file (``.txt`` or ``.json``).
    inputs : sequence of str or os.PathLike
        The bracket's inputs, in bracket order.
    bare_order : {"sorted", "inputs"}, default "sorted"
        The order of bare ``SECONDS`` lines (see above).

    Returns
    -------
    list of float
        One exposure time in seconds per input, in the order of ``inputs``.

    Raises
    ------
    MissingFileError
        No such file.
    InputError
        A malformed line, a missing or extra name, a count that does not match, or different
        apertures, gains or filters in an HDRShop list.

    Examples
    --------
    >>> from pathlib import Path
    >>> from lfproc.dataset import read_exposure_file
    >>> _ = Path("exposures.txt").write_text("# name seconds\\nb.jpg 1/8\\na.jpg 2\\n")
    >>> read_exposure_file("exposures.txt", ["a.jpg", "b.jpg"])
    [2.0, 0.125]
    >>> _ = Path("list.txt").write_text("memorial0061.png 0.03125 8 0 0\\nmemorial0062.png 0.0625 8 0 0\\n")
    >>> read_exposure_file("list.txt", ["memorial0061.png", "memorial0062.png"])    # HDRShop: 1/t
    [32.0, 16.0]
    """
    path = Path(path)
    if bare_order not in ("sorted", "inputs"):
        raise InputError(f"bare_order: expected 'sorted' or 'inputs', got {bare_order!r}")
    names = [Path(p).name for p in inputs]
    order = sorted(range(len(names)), key=lambda i: names[i]) if bare_order == "sorted" else list(range(len(names)))
    by_name: dict[str, float] = {}
    in_order: list[float] = []
    if not path.is_file():
        raise MissingFileError(f"{path}: no such exposure file")

    data = ut.read_bytes(path, max_bytes=ut.MAX_TEXT_BYTES, source=path, error=InputError, what="exposure file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: expected a text (UTF-8) exposure file, found binary data") from None
    if path.suffix.lower() == ".json":  # size and nesting checked before parsing (a deep file is an error, no crash)
        doc = ut.parse_json(text, source=path, error=InputError, what="not a JSON exposure file")
        if isinstance(doc, dict):
            by_name = {str(k): _seconds(str(v), f"{path}: {k}") for k, v in doc.items()}
        elif isinstance(doc, list):
            in_order = [_seconds(str(v), f"{path}: item {i + 1}") for i, v in enumerate(doc)]
        else:
            raise InputError(f"{path}: expected an object {{\"NAME\": seconds}} or a list of seconds")
    else:
        rows = []
        hdrshop = False
        for number, raw in enumerate(text.splitlines(), start=1):
            line, _, comment = raw.partition("#")
            if "1/shutter" in comment.lower().replace(" ", ""):
                hdrshop = True
            if line.strip():
                rows.append((number, raw.strip(), line.split()))
        if any(len(parts) > 5 for _, _, parts in rows):
            number, raw, _ = next(r for r in rows if len(r[2]) > 5)
            raise InputError(f"{path} line {number}: expected 'NAME SECONDS', 'SECONDS' or an HDRShop line "
                             f"'NAME 1/t F_STOP [GAIN_DB [ND]]', found {raw!r}")
        hdrshop = hdrshop or any(len(parts) >= 3 for _, _, parts in rows)
        if hdrshop:
            count = None
            if rows and len(rows[0][2]) == 1:  # the number of images
                number, raw, parts = rows.pop(0)
                try:
                    count = int(parts[0])
                except ValueError:
                    raise InputError(f"{path} line {number}: expected the number of images of an HDRShop list, "
                                     f"found {raw!r}") from None
            extras = {}
            for number, raw, parts in rows:
                where = f"{path} line {number}"
                if len(parts) < 2:
                    raise InputError(f"{where}: expected 'NAME 1/t F_STOP ...' (an HDRShop image list), found {raw!r}")
                inverse = _seconds(parts[1], f"{where} (1/shutter_speed)")
                by_name[parts[0]] = 1.0 / inverse
                extras.setdefault(tuple(parts[2:]), number)
            if len(extras) > 1:
                (a, la), (b, lb) = list(extras.items())[:2]
                raise InputError(f"{path}: aperture, gain or ND filter differ between lines {la} ({' '.join(a)}) and "
                                 f"{lb} ({' '.join(b)}); lfproc merges by exposure time only: give times that "
                                 "include them (NAME SECONDS lines)")
            if count is not None and count != len(rows):
                raise InputError(f"{path}: the HDRShop list says {count} images, lists {len(rows)}")
        else:
            for number, raw, parts in rows:
                where = f"{path} line {number}"
                if len(parts) == 1:
                    in_order.append(_seconds(parts[0], where))
                else:
                    by_name[parts[0]] = _seconds(parts[1], where)
            if by_name and in_order:
                raise InputError(f"{path}: mixes 'NAME SECONDS' and 'SECONDS' lines; use one form")
    if by_name:
        return _match_names(path, by_name, names)
    if len(in_order) != len(names):
        raise InputError(f"{path}: {len(in_order)} exposure time(s) for {len(names)} inputs "
                         f"({', '.join(names[i] for i in order)})")
    out = [0.0] * len(names)
    for rank, i in enumerate(order):
        out[i] = in_order[rank]
    return out



def _check_exposures(scene: Scene) -> None:
    """Without an exposure file, every 2-D image of the bracket needs an EXIF exposure time."""
    for p in scene.inputs:
        if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES_LDR and read_exif_exposure(p)["exposure_s"] is None:
            raise InputError(
                f"scene {scene.name}: {p.name} has no exposure time (no EXIF ExposureTime); write the bracket's "
                f"times to {scene.folder / EXPOSURE_FILES[0]} ('NAME SECONDS' lines, e.g. '{p.name} 1/8') "
                f"or {EXPOSURE_FILES[1]}")


def find_scenes(scenes_dir: str | os.PathLike) -> list[Scene]:
    """The scene folders of ``scenes_dir`` (sorted by name; hidden folders ignored).

    Parameters
    ----------
    scenes_dir : str or os.PathLike
        A folder holding one folder per scene.

    Returns
    -------
    list of Scene
        One per scene folder, sorted by name.

    Raises
    ------
    MissingFileError
        No such folder.
    InputError
        No scene folder in it.

    Examples
    --------
    >>> from pathlib import Path
    >>> from lfproc.dataset import find_scenes
    >>> for name in ("scenes/b/img_1.jpg", "scenes/b/img_2.jpg", "scenes/a/view.exr", "scenes/a/truth.exr"):
    ...     Path(name).parent.mkdir(parents=True, exist_ok=True)
    ...     Path(name).touch()
    >>> [(s.name, [p.name for p in s.inputs]) for s in find_scenes("scenes")]
    [('a', ['view.exr']), ('b', ['img_1.jpg', 'img_2.jpg'])]
    """
    scenes_dir = Path(scenes_dir)
    if not scenes_dir.is_dir():
        raise MissingFileError(f"{scenes_dir}: no such scenes folder")
    scenes = [_scene_of(p) for p in sorted(scenes_dir.iterdir()) if p.is_dir() and not p.name.startswith(".")]
    if not scenes:
        raise InputError(f"{scenes_dir}: expected one folder per scene, found none")
    return scenes


def _white_db(scene: Scene, workdir: Path) -> Path | None:
    """Build the white-image database of a scene's calibration data (Lytro captures only)."""
    if scene.caldata is None:
        return None

    db = workdir / "whites"
    whites.build_white_db(scene.caldata, db)
    return db


def _write_previews(lf, folder: Path) -> None:
    write_preview(lf, folder / "preview.png", kind="centre")
    write_preview(lf, folder / "histogram.png", kind="histogram")


def process_scene(
    scene: Scene,
    out_dir: str | os.PathLike,
    *,
    method: str | None = None,
    profile=None,
    n_threads: int = 1,
    nonfinite: str = "raise",
    negative: str = "clip",
) -> dict[str, Any]:
    """Decode, merge and write one scene; return its manifest row (also written as records).

    Writes ``scenes/<name>/`` (atomically, as a whole) and then ``done/<name>.json``. lfproc's
    warnings raised while merging (:class:`lfproc.errors.SaturationWarning`...) are recorded
    in the row's ``warnings`` (``"Category: message"`` strings) instead of being emitted.

    Parameters
    ----------
    scene : Scene
        The scene (from :func:`find_scenes`).
    out_dir : str or os.PathLike
        The data-set folder.
    method : {"ml", "debevec"}, optional
        The merge (default: chosen by :func:`lfproc.hdr.merge_files`).
    profile : CameraProfile or str, optional
        Camera profile of the inputs.
    n_threads : int, default 1
        Threads of the merge.
    nonfinite, negative : str
        Value policies of light-field inputs (EXR files, folders of views): see :func:`lfproc.hdr.merge_files`.

    Returns
    -------
    dict
        The manifest row: ``scene``, ``method``, ``exposures_s``, ``dynamic_range_stops``,
        ``saturated_fraction``, ``views``, ``size``, ``units``, the output paths (relative to
        ``out_dir``), ``sources`` and their ``sha256``, ``seconds`` and ``warnings``.

    Raises
    ------
    InputError
        Fewer than two inputs, missing exposure times, or a bracket the merge refuses.

    Examples
    --------
    >>> from pathlib import Path
    >>> import numpy as np
    >>> import lfproc
    >>> from lfproc.dataset import find_scenes, process_scene
    >>> Path("scenes/room").mkdir(parents=True)
    >>> radiance = np.geomspace(0.05, 20, 16 * 16 * 3, dtype=np.float32).reshape(1, 1, 16, 16, 3)
    >>> for i, t in enumerate([0.05, 0.5]):       # a two-exposure bracket, clipping at 1
    ...     shot = lfproc.LightField(np.minimum(radiance * t, 1), saturation_level=1.0)
    ...     _ = lfproc.write_lightfield(shot, f"scenes/room/shot_{i}.exr")
    >>> _ = Path("scenes/room/exposures.txt").write_text("shot_0.exr 1/20\\nshot_1.exr 0.5\\n")
    >>> row = process_scene(find_scenes("scenes")[0], "dataset")
    >>> row["method"], row["exposures_s"], row["hdr"]
    ('debevec', [0.05, 0.5], 'scenes/room/hdr.exr')
    >>> hdr = lfproc.read_lightfield("dataset/scenes/room/hdr.exr")
    >>> bool(np.allclose(hdr.data, radiance, rtol=1e-4))
    True
    """
    out_dir = Path(out_dir)
    start = time.perf_counter()
    if len(scene.inputs) < 2:
        raise InputError(f"scene {scene.name}: a bracket needs at least two inputs, found "
                         f"{', '.join(p.name for p in scene.inputs) or 'none'} in {scene.folder}")
    scene_out = out_dir / "scenes" / scene.name
    (out_dir / "scenes").mkdir(parents=True, exist_ok=True)
    (out_dir / "done").mkdir(parents=True, exist_ok=True)
    exposures = None
    if scene.exposure_file is not None:
        exposures = read_exposure_file(scene.exposure_file, scene.inputs)
    else:
        _check_exposures(scene)
    with atomic_dir(scene_out, force=True) as tmp:
        white_db = _white_db(scene, tmp)
        # lfproc's warnings (saturation, convergence) belong to the scene: kept in its row, not
        # printed by (or raised in) a worker process
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LfprocWarning)
            try:
                merged, info = merge_files(scene.inputs, method=method, profile=profile, white_db=white_db,
                                           exposures_s=exposures, n_threads=n_threads,
                                           nonfinite=nonfinite, negative=negative)
            except InputError as exc:  # the command-line hint of lfproc merge does not apply here
                message = str(exc).replace("give --exposures-s", f"write the bracket's times to "
                                           f"{scene.folder / EXPOSURE_FILES[0]}")
                raise InputError(message) from None
        other = [w for w in caught if not issubclass(w.category, LfprocWarning)]
        for w in other:  # not ours: pass them on as they were
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if white_db is not None:
            shutil.rmtree(white_db, ignore_errors=True)
        write_lightfield(merged, tmp / "hdr.exr")
        _write_previews(merged, tmp)
        sat = info["saturated_everywhere_fraction"]
        row = {
            "scene": scene.name,
            "method": info["method"],
            "exposures_s": merged.attrs["exposures_s"],
            "dynamic_range_stops": round(float(info["dynamic_range_stops"]), 4),
            "saturated_fraction": float(sat),
            "views": list(merged.views),
            "size": list(merged.size),
            "units": merged.units,
            "hdr": f"scenes/{scene.name}/hdr.exr",
            "preview": f"scenes/{scene.name}/preview.png",
            "histogram": f"scenes/{scene.name}/histogram.png",
            "sources": [str(p) for p in scene.inputs],
            "exposure_file": str(scene.exposure_file) if scene.exposure_file else None,
            "sha256": [file_sha256(p) for p in scene.inputs],
            "lfproc_version": __version__,
            "seconds": round(time.perf_counter() - start, 3),
            "warnings": [f"{w.category.__name__}: {w.message}" for w in caught if issubclass(w.category, LfprocWarning)],
        }
        (tmp / "record.json").write_text(json.dumps(row, indent=2))
    with atomic_file(out_dir / "done" / f"{scene.name}.json", force=True) as tmp:
        tmp.write_text(json.dumps(row, indent=2))
    return row


def _is_done(scene: Scene, out_dir: Path) -> bool:
    record = out_dir / "done" / f"{scene.name}.json"
    folder = out_dir / "scenes" / scene.name
    return record.is_file() and all((folder / name).is_file() for name in SCENE_OUTPUTS)


def _write_manifest(out_dir: Path, scenes: list[Scene]) -> list[dict[str, Any]]:
    rows = []
    for scene in scenes:
        if _is_done(scene, out_dir):
            rows.append(json.loads((out_dir / "done" / f"{scene.name}.json").read_text()))
    doc = {"lfproc_version": __version__, "n_scenes": len(rows), "scenes": rows}
    with atomic_file(out_dir / "manifest.json", force=True) as tmp:
        tmp.write_text(json.dumps(doc, indent=2))
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(MANIFEST_FIELDS)
    for row in rows:
        writer.writerow([";".join(map(str, row[k])) if isinstance(row[k], list) else row[k] for k in MANIFEST_FIELDS])
    with atomic_file(out_dir / "manifest.csv", force=True) as tmp:
        tmp.write_text(buf.getvalue())
    return rows


def read_manifest(dataset_dir: str | os.PathLike) -> list[dict[str, Any]]:
    """The rows of a data set's ``manifest.json``.

    Parameters
    ----------
    dataset_dir : str or os.PathLike
        A folder written by :func:`build_dataset`.

    Returns
    -------
    list of dict
        One row per finished scene (see :func:`process_scene`).

    Raises
    ------
    MissingFileError
        The folder has no ``manifest.json``.
    """
    path = Path(dataset_dir) / "manifest.json"
    if not path.is_file():
        raise MissingFileError(f"{path}: no manifest; run lfproc dataset build first")
    return json.loads(path.read_text())["scenes"]


def _run_scene(scene: Scene, out_dir: str, method, profile, policies=None) -> dict[str, Any]:
    """Process one scene; a failure is returned as ``{"error": "Type: message"}`` (not raised, so
    that Dask workers do not log it with a traceback: the build reports it in one line)."""
    try:
        return {"row": process_scene(scene, out_dir, method=method, profile=profile, n_threads=1,
                                     **(policies or {}))}
    except Exception as exc:  # noqa: BLE001 - a failed scene must not stop the others
        return {"error": f"{type(exc).__name__}: {exc}"}


def build_dataset(
    scenes_dir: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    method: str | None = None,
    profile=None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress_bar: bool | None = None,
    nonfinite: str = "raise",
    negative: str = "clip",
) -> dict[str, Any]:
    """Process every scene of ``scenes_dir`` into ``out_dir`` in parallel with Dask (see the module notes).

    Parameters
    ----------
    scenes_dir : path
        One folder per scene.
    out_dir : path
        Data-set folder (created if missing; finished scenes in it are skipped).
    method, profile : str or CameraProfile, optional
        Merge options (see :func:`lfproc.hdr.merge_files`).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); default: a local cluster of
        ``workers`` processes with one thread each. ``"synchronous"`` runs the scenes one
        after the other in this process (debugging).
    workers : int, optional
        Processes of the local cluster (default: the CPU count, at most the number of scenes).
    progress_bar : bool, optional
        Show a progress bar (None: when stderr is a terminal).
    nonfinite, negative : str
        Value policies of light-field inputs (see :func:`process_scene`).

    Returns
    -------
    dict
        ``processed``, ``skipped`` and ``failed`` (scene -> error message) scene names,
        ``manifest`` (path) and ``rows`` (the manifest rows).
    """
    if workers is not None:  # before any folder is made or process started
        check_count("--workers", workers, high=max_workers(),
                    why=f"at most 4 per CPU core; this machine has {os.cpu_count() or 1}")
    check_choice("nonfinite", nonfinite, ("raise", "zero", "clip"))
    check_choice("negative", negative, ("raise", "clip", "keep"))
    policies = {"nonfinite": nonfinite, "negative": negative}
    scenes = find_scenes(scenes_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if profile is not None and not isinstance(profile, str):
        profile = load_profile(profile)

    for folder in (out, out / "scenes", out / "done"):
        clean_stale(folder)  # temporaries left by killed runs (their process is gone)
    todo = [s for s in scenes if not _is_done(s, out)]
    skipped = [s.name for s in scenes if s not in todo]
    processed: list[str] = []
    failed: dict[str, str] = {}
    if todo:
        bar = progress(total=len(todo), desc="scenes", disable=None if progress_bar is None else not progress_bar)
        if scheduler == "synchronous":
            for scene in todo:
                res = _run_scene(scene, str(out), method, profile, policies)
                if "error" in res:
                    failed[scene.name] = res["error"]
                else:
                    processed.append(scene.name)
                bar.update(1)
        else:
            _run_dask(todo, out, method, profile, scheduler, workers, bar, processed, failed, policies)
        bar.close()
    rows = _write_manifest(out, scenes)

    with atomic_file(out / "failed.json", force=True) as tmp:
        tmp.write_text(json.dumps(failed, indent=2))
    return {"scenes": len(scenes), "processed": processed, "skipped": skipped, "failed": failed,
            "manifest": str(out / "manifest.json"), "rows": rows}


def _run_dask(todo, out, method, profile, scheduler, workers, bar, processed, failed, policies) -> None:
    from dask.distributed import as_completed

    with dask_client(scheduler=scheduler, workers=workers, jobs=len(todo)) as client:
        futures = {client.submit(_run_scene, scene, str(out), method, profile, policies, key=f"scene-{scene.name}-{i}",
                                 pure=False): scene for i, scene in enumerate(todo)}
        for future in as_completed(futures):
            scene = futures[future]
            exc = future.exception()
            res = {"error": f"{type(exc).__name__}: {exc}"} if exc is not None else future.result()
            if "error" in res:
                failed[scene.name] = res["error"]
            else:
                processed.append(scene.name)
            bar.update(1)
