"""Running the bench: scenes, cached cells, Dask.

Every cell is simulated with its recorded seed, reconstructed (jointly, or per shot and
merged), scored with :func:`lfproc.metrics.evaluate` against the scene, and written to
``BENCH_DIR/cells/<id>.npz`` (its results.csv row as JSON and the reconstructed centre view)
through :func:`lfproc.io.atomic_file`, so a killed bench leaves only whole cell files and a
new run computes just the missing ones. The cell id hashes the cell, the scene's SHA-256, the
crop, the dictionary, the reconstruction options and the simulation settings: changing any
of them makes new cells instead of reusing stale ones.

Jobs run on Dask like the project's other batch commands (:mod:`lfproc.dataset`): a
``LocalCluster`` of ``workers`` processes with one thread each (``processes=True``,
``dashboard_address=":0"``), or a running scheduler (``scheduler="tcp://..."``), or this
process (``scheduler="synchronous"``). Each job's reconstruction runs single-threaded inside
its worker; the results do not depend on where a job ran. Workers read the scenes and write
the cell files themselves: with a remote scheduler, the scenes and ``BENCH_DIR`` must be on a
file system every worker sees at the same paths.
"""

from __future__ import annotations

import csv
import math
import json
import os
import shutil
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .._shared.deprecate import renamed_keywords
from .._shared.hashing import file_sha256
from .._shared.parallel import dask_client
from .._shared.validation import check_choice
from .._shared.progress import progress
from .._shared.jsonable import to_jsonable
from .._version import __version__
from ..errors import InputError, OutputExistsError, SaturationWarning, ShapeError
from ..camera.iso import DEFAULT_BLOCK_PX
from ..recon import DEFAULTS as RECON_DEFAULTS, reconstruct, reconstruct_gmm, reconstruct_per_shot
from .grid import Cell, Job, Preset, cell_id, cell_seed, get_preset, grid_cells, group_jobs
from .cells import BenchScene, _cell_path, load_scene, read_cells, read_centre  # noqa: F401  (read_centre: its old path)
from ..camera.capture import observations
from ..camera.simulate import NOISE_PROFILES, simulate_capture
from ..dictionary import Dictionary, load_dictionary
from ..dictionary._files import shipped_path
from ..io import read_lightfield
from ..io._atomic import atomic_file, atomic_outputs, clean_stale
from ..metrics import evaluate
from .report import REPORT_FILES, write_report

__all__ = ["run_bench", "load_scene", "run_job", "read_cells", "COLUMNS", "BenchScene"]

#: Columns of results.csv, in order (the first ones are what other checks rely on).
COLUMNS = (
    "scene", "method", "iso_pattern", "shots", "isos", "noise", "pu21_psnr_db", "pu21_ssim", "seconds",
    "saturated_fraction", "cpu_seconds", "merge", "exposure", "relative_exposures", "isos_used", "pu2_psnr_db",
    "log_psnr_db", "mean_relative_error", "black_clipped_fraction", "sampling_rate_percent", "seed",
    "simulate_seconds", "iterations_mean", "empty_patches", "size", "views", "profile", "mask_period", "recon_method",
    "dictionary",
    "solver", "mu", "max_iter", "scale", "overlap", "lfproc_version", "cell_id",
)


def _policies(read_options: dict[str, str] | None) -> dict[str, str]:
    """The scenes' value policies from ``run_bench(read_options=...)``, checked."""
    options = dict(read_options or {})
    unknown = sorted(set(options) - {"nonfinite", "negative"})
    if unknown:
        raise InputError(f"read_options: expected the keys nonfinite and negative, got {', '.join(unknown)}")
    return {"nonfinite": check_choice("nonfinite", options.get("nonfinite", "raise"), ("raise", "zero", "clip")),
            "negative": check_choice("negative", options.get("negative", "raise"), ("raise", "clip", "keep"))}


def _scenes(paths, preset: Preset, dictionary, policies: dict[str, str]) -> list[BenchScene]:
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("scenes: expected at least one light field (LF...), got none")
    v_n, u_n, size, _, c_n = dictionary.patch
    out, names = [], set()
    for path in paths:
        lf = read_lightfield(path, **policies)
        if lf.views != (v_n, u_n):
            raise ShapeError(f"{path}: {lf.views[0]} x {lf.views[1]} views; the dictionary "
                             f"({dictionary.name or dictionary.preset}) needs {v_n} x {u_n}, like every scene of a "
                             "bench")
        if lf.channels != 3:
            raise ShapeError(f"{path}: {lf.channels} colour channels; the coded camera needs RGB light fields")
        h, w = lf.size
        crop = None
        if preset.crop is not None and (h > preset.crop[0] or w > preset.crop[1]):
            ch, cw = min(h, preset.crop[0]), min(w, preset.crop[1])
            crop = ((h - ch) // 2, (w - cw) // 2, ch, cw)
            h, w = ch, cw
        if min(h, w) < max(size, 11):
            raise ShapeError(f"{path}: views of {h} x {w} pixels; the bench needs at least {max(size, 11)} x "
                             f"{max(size, 11)} (the dictionary's patch and the SSIM window)")
        name = path.stem if path.suffix else path.name
        base, i = name, 2
        while name in names:
            name, i = f"{base}-{i}", i + 1
        names.add(name)
        out.append(BenchScene(name=name, path=str(path.resolve()), sha256=file_sha256(path) if path.is_file() else
                              _folder_sha(path), crop=crop, views=lf.views, size=(h, w), **policies))
    return out


def _folder_sha(path: Path) -> str:
    import hashlib

    h = hashlib.sha256()
    for f in sorted(p for p in path.iterdir() if p.is_file()):
        h.update(f.name.encode())
        h.update(file_sha256(f).encode())
    return h.hexdigest()


def _dictionary_id(dictionary, source) -> str:
    import hashlib

    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.exists() and str(source) in ("default",):
            path = shipped_path(str(source))
        if path.is_file():
            return f"{dictionary.name or dictionary.preset}:{file_sha256(path)[:16]}"
    digest = hashlib.sha256(np.ascontiguousarray(dictionary.atoms, dtype=np.float32).tobytes()).hexdigest()
    return f"{dictionary.name or dictionary.preset}:{digest[:16]}"


def _simulate(lf, cell: Cell, preset: Preset, seed: int):
    common = dict(profile=NOISE_PROFILES[cell.noise], isos=cell.isos, exposure_s=preset.exposure_s,
                  mask="random", mask_period=preset.mask_period, random_state=seed)
    if cell.method in ("joint", "dual-iso"):
        return simulate_capture(lf, iso_pattern_kind=cell.iso_pattern, shots=cell.shots,
                                relative_exposures=[cell.exposure] * cell.shots, **common)
    if cell.method == "individual-iso":
        return simulate_capture(lf, baseline="individual-iso", **common)
    return simulate_capture(lf, baseline="bracketing", shots=cell.shots, **common)


#: Reconstruction methods of the bench: ``auto`` is gmm for a preset with a periodic mask, else dictionary.
METHODS = ("auto", "gmm", "dictionary")


def recon_method(method: str, preset: Preset, dictionary_given: bool = False) -> str:
    """The method a bench cell uses (``auto``: :func:`lfproc.recon.reconstruct_gmm` when the preset's
    mask is periodic and no dictionary was given, as ``lfproc reconstruct`` chooses, else
    :func:`lfproc.recon.reconstruct`)."""
    check_choice("method", method, METHODS)
    if method == "auto":
        return "gmm" if preset.mask_period and not dictionary_given else "dictionary"
    if method == "gmm" and not preset.mask_period:
        raise InputError(f"method gmm: needs a periodic mask; preset {preset.name!r} has none (use dictionary)")
    return method


def run_job(spec: dict[str, Any], dictionary) -> list[dict[str, Any]]:
    """Simulate, reconstruct, score and write the cells of one job; returns their rows."""
    scene: BenchScene = spec["scene"]
    preset: Preset = spec["preset"]
    cells: list[Cell] = spec["cells"]
    ids: list[str] = spec["ids"]
    lf = load_scene(scene)
    first = cells[0]
    seed = cell_seed(spec["seed"], first)
    with warnings.catch_warnings():
        # the grid saturates some cells on purpose (wide ISO sets, the exposure sweep): their
        # saturated fraction is a column of results.csv instead of a warning per cell
        warnings.simplefilter("ignore", SaturationWarning)
        t0 = time.perf_counter()
        capture = _simulate(lf, first, preset, seed)
        simulate_seconds = time.perf_counter() - t0
        obs = observations(capture)
        options = dict(spec["recon"])
        method = recon_method(options.pop("method", "auto"), preset)
        t0, c0 = time.perf_counter(), time.process_time()
        if first.method in ("individual-iso", "bracketing"):
            recs = reconstruct_per_shot(capture, dictionary if method == "dictionary" else "default",
                                        merges=[c.merge for c in cells], method=method, **options)
            results = [recs[c.merge] for c in cells]
        elif method == "gmm":
            results = [reconstruct_gmm(capture, **options)]
        else:
            results = [reconstruct(capture, dictionary, **options)]
        seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    rows = []
    for cell, cid, rec in zip(cells, ids, results):
        scores = evaluate(rec, lf, scale_tolerance_stops=None)
        rec_info = rec.attrs["reconstruction"]
        per = rec_info.get("per_shot", [rec_info])
        row = {
            **cell.describe(),
            "relative_exposures": ";".join(f"{e / preset.exposure_s:g}" for e in capture.exposures_s),
            "isos_used": ",".join(str(int(v)) for v in capture.isos),
            "pu21_psnr_db": scores["pu21_psnr_db"], "pu21_ssim": scores["pu21_ssim"],
            "pu2_psnr_db": scores["pu2_psnr_db"], "log_psnr_db": scores["log_psnr_db"],
            "mean_relative_error": scores["mean_relative_error"],
            "seconds": seconds, "cpu_seconds": cpu_seconds, "simulate_seconds": simulate_seconds,
            "saturated_fraction": obs.saturated_fraction, "black_clipped_fraction": obs.black_clipped_fraction,
            "sampling_rate_percent": 100.0 * capture.sampling_rate, "seed": seed,
            "recon_method": method,
            "iterations_mean": float(np.mean([p.get("iterations_mean", math.nan) for p in per])),
            "empty_patches": int(sum(p.get("empty_patches", 0) for p in per)),
            "size": f"{lf.size[0]}x{lf.size[1]}", "views": f"{lf.views[0]}x{lf.views[1]}",
            "profile": capture.profile.name, "mask_period": preset.mask_period if preset.mask_period else "",
            "dictionary": spec["dictionary_id"] if method == "dictionary" else "", "solver": per[0].get("solver", ""),
            "mu": per[0].get("mu", ""), "max_iter": per[0].get("max_iter", ""), "scale": per[0].get("scale"),
            "overlap": per[0].get("overlap"),
            "lfproc_version": __version__, "cell_id": cid,
        }
        path = _cell_path(Path(spec["cells_dir"]), cid)
        with atomic_file(path, force=True) as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, row=np.array(json.dumps(to_jsonable(row))),
                                    centre=np.asarray(rec.centre(), dtype=np.float32))
        rows.append(row)
    return rows


def _is_done(path: Path) -> bool:
    if not path.is_file():
        return False
    try:
        with np.load(path, allow_pickle=False) as z:
            json.loads(str(z["row"]))
        return True
    except (OSError, ValueError, KeyError):
        return False


def _prepare_bench_dir(out: Path, *, force: bool) -> Path:
    """The bench folder ``out`` checked (a folder lfproc made as a bench, or empty, or ``force``) and its
    ``cells`` folder made and cleaned of killed runs' temporaries; returns the cells folder."""
    marker = out / "bench.json"
    if out.exists() and not out.is_dir():
        raise OutputExistsError(f"{out}: exists and is not a folder; expected a bench folder")
    if out.is_dir() and any(out.iterdir()) and not marker.is_file() and not force:
        raise OutputExistsError(f"{out}: a folder that is not a bench folder (no bench.json); pass --force to use it")
    cells_dir = out / "cells"
    if force and cells_dir.is_dir():
        shutil.rmtree(cells_dir)
    cells_dir.mkdir(parents=True, exist_ok=True)
    clean_stale(cells_dir)  # temporaries of killed runs (entries of live processes are left alone)
    return cells_dir


def _run_specs(specs, dictionary, *, workers, scheduler, progress_bar, failed: dict[str, str]) -> int:
    """Compute the jobs ``specs`` in this process (``scheduler="synchronous"``) or on Dask; a failed
    job is recorded in ``failed`` (cell label -> error) and does not stop the others. Returns the
    number of cells computed."""
    if not specs:
        return 0
    computed = 0
    bar = progress(total=sum(len(s["cells"]) for s in specs), desc="bench", unit="cell",
                   disable=None if progress_bar is None else not progress_bar)
    try:
        if scheduler == "synchronous":
            for spec in specs:
                try:
                    computed += len(run_job(spec, dictionary))
                except Exception as exc:  # noqa: BLE001 - one failed cell must not stop the others
                    failed[spec["cells"][0].label()] = f"{type(exc).__name__}: {exc}"
                bar.update(len(spec["cells"]))
        else:
            computed = _run_dask(specs, dictionary, workers, scheduler, bar, failed)
    finally:
        bar.close()
    return computed


def _publish(out: Path, rows, *, meta, report: bool) -> Path | None:
    """Write results.csv and, with ``report``, report.md and the plots, all together or none; returns the
    report's path (None without one)."""
    files = ["results.csv"] + (list(REPORT_FILES) if report and rows else [])
    # results.csv, report.md and the plots are published together: all from this run, or none
    with atomic_outputs([out / f for f in files], force=True) as staged:
        staged = dict(zip(files, staged))
        with open(staged["results.csv"], "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(COLUMNS), extrasaction="ignore")
            writer.writeheader()
            for row in rows:
                writer.writerow({k: _csv_value(row.get(k)) for k in COLUMNS})
        if len(files) > 1:
            write_report(out, rows, meta=meta, paths=staged)
            return out / "report.md"
    return None


def _bench_meta(preset: Preset, recon, seed: int, dictionary, dict_id, bench_scenes, scenes) -> dict[str, Any]:
    """The content of bench.json: what every cell of the folder was computed with."""
    return {
        "kind": "lfproc-bench", "lfproc_version": __version__, "preset": preset.name,
        "preset_description": preset.description, "crop": preset.crop, "mask_period": preset.mask_period,
        "exposure_s": preset.exposure_s, "recon": recon, "seed": int(seed), "dictionary": dict_id,
        "dictionary_patch": list(dictionary.patch), "dictionary_atoms": dictionary.n_atoms,
        "scenes": [{"name": s.name, "path": s.path, "given": str(g), "sha256": s.sha256, "crop": s.crop,
                    "size": list(s.size), "nonfinite": s.nonfinite, "negative": s.negative}
                   for s, g in zip(bench_scenes, scenes)],
    }


@renamed_keywords(seed="random_state")
def run_bench(
    scenes,
    out_dir: str | os.PathLike,
    *,
    preset: str | Preset = "quick",
    dictionary="default",
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    random_state: int = 0,
    recon_options: dict[str, Any] | None = None,
    report: bool = True,
    progress_bar: bool | None = None,
    read_options: dict[str, str] | None = None,
) -> dict[str, Any]:
    """Run the bench grid on light fields and write results.csv, report.md and plots (module notes).

    Parameters
    ----------
    scenes : sequence of paths
        HDR light fields (files or view folders), all with the dictionary's views.
    out_dir : path
        Bench folder (created; a folder lfproc did not make as a bench is refused without
        ``force``). Finished cells in it are reused; ``force`` recomputes every cell.
    preset : {"quick", "paper"} or Preset
    dictionary : ``"default"``, a dictionary file, or a Dictionary
    workers : int, optional
        Processes of the local Dask cluster (default: the CPU count, at most the number of jobs).
    scheduler : str, optional
        Address of a running Dask scheduler, or ``"synchronous"`` (this process).
    force : bool, default False
        Use a folder that is not a bench folder, and recompute (delete) every cached cell.
    random_state : int, default 0
        Bench seed (every cell's seed derives from it; recorded per cell as ``"seed"``; the keyword
        ``seed`` is deprecated).
    recon_options : dict, optional
        ``method`` (:data:`METHODS`; default ``auto``: gmm when the preset's mask is periodic, as
        ``lfproc reconstruct``) and the options of that method's function over the preset's
        (:func:`lfproc.recon.reconstruct_gmm`: stride...; :func:`lfproc.recon.reconstruct`:
        solver, mu, max_iter...).
    report : bool, default True
        Write report.md and the plots (results.csv is always written).
    progress_bar : bool, optional
        Show a progress bar of the jobs (None: when stderr is a terminal).
    read_options : dict, optional
        ``nonfinite`` and ``negative``, the scenes' value policies (:func:`lfproc.io.read_lightfield`;
        default ``"raise"`` both). A policy other than the default is part of every cell's identity.

    Returns
    -------
    dict
        ``cells``, ``computed``, ``cached``, ``failed`` (cell label -> error), ``seconds``,
        ``results`` (path), ``report`` (path or None), ``rows``.

    Raises
    ------
    InputError
        No scenes, a bad worker count or seed, an unknown preset.
    OutputExistsError
        ``out_dir`` is a non-empty folder that is not a bench folder and ``force`` is false.
    """
    started = time.perf_counter()
    preset = get_preset(preset)
    seed = random_state
    if workers is not None and (isinstance(workers, bool) or int(workers) != workers or workers < 1):
        raise InputError(f"workers: expected a positive integer, got {workers!r}")
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise InputError(f"random_state: expected a non-negative integer, got {seed!r}")
    scenes = list(scenes)
    if not scenes:
        raise InputError("scenes: expected at least one light field (LF...), got none")
    source = dictionary
    dictionary = load_dictionary(dictionary) if not isinstance(dictionary, Dictionary) else dictionary
    policies = _policies(read_options)
    bench_scenes = _scenes(scenes, preset, dictionary, policies)
    out = Path(out_dir)
    cells_dir = _prepare_bench_dir(out, force=force)

    recon = {**preset.recon, **(recon_options or {})}
    # the method resolved here (a bad one fails before any job) and part of every cell's identity
    given = not (isinstance(source, (str, os.PathLike)) and str(source) == "default")
    recon["method"] = recon_method(recon.get("method", "auto"), preset, given)
    # the library defaults a cell relies on: a later lfproc with other defaults recomputes the cell
    # instead of reusing a result made with the old ones
    defaults = {"recon": RECON_DEFAULTS, "block_px": DEFAULT_BLOCK_PX}
    dict_id = _dictionary_id(dictionary, source)
    by_name = {s.name: s for s in bench_scenes}
    cells = grid_cells(preset, [s.name for s in bench_scenes])
    ids: dict[Cell, str] = {}
    for c in cells:
        s = by_name[c.scene]
        context = {"scene_sha256": s.sha256, "crop": s.crop, "dictionary": dict_id, "recon": recon,
                   "mask_period": preset.mask_period, "exposure_s": preset.exposure_s, "seed": int(seed),
                   "defaults": defaults}
        # a policy other than the default is part of the cell (the default's cells keep their ids)
        ids[c] = cell_id(c, context | ({"values": policies} if set(policies.values()) != {"raise"} else {}))
    jobs = group_jobs(cells)
    # a job whose cells are partly done (killed between its cells) computes only the missing ones
    todo = [Job(key=j.key, cells=missing) for j in jobs
            if (missing := [c for c in j.cells if not _is_done(_cell_path(cells_dir, ids[c]))])]
    todo.sort(key=lambda j: -j.cost)  # longest first packs the workers better
    meta = _bench_meta(preset, recon, seed, dictionary, dict_id, bench_scenes, scenes)
    with atomic_file(out / "bench.json", force=True) as tmp:
        tmp.write_text(json.dumps(to_jsonable(meta), indent=1))

    failed: dict[str, str] = {}
    specs = [{"scene": by_name[j.cell.scene], "preset": preset, "cells": j.cells, "ids": [ids[c] for c in j.cells],
              "seed": int(seed), "recon": recon, "cells_dir": str(cells_dir), "dictionary_id": dict_id} for j in todo]
    computed = _run_specs(specs, dictionary, workers=workers, scheduler=scheduler, progress_bar=progress_bar,
                          failed=failed)
    rows = read_cells([_cell_path(cells_dir, ids[c]) for c in cells])
    results = out / "results.csv"
    report_path = _publish(out, rows, meta=meta, report=report)
    seconds = time.perf_counter() - started
    return {"bench": str(out), "preset": preset.name, "scenes": len(bench_scenes), "cells": len(cells),
            "computed": computed, "cached": len(cells) - sum(len(s["cells"]) for s in specs),
            "failed": failed, "seconds": seconds, "results": str(results),
            "report": None if report_path is None else str(report_path), "rows": rows}


def _csv_value(value):
    if isinstance(value, float):
        return f"{value:.6g}"
    return "" if value is None else value


def _run_dask(specs, dictionary, workers, scheduler, bar, failed) -> int:
    from dask.distributed import as_completed

    computed = 0
    with dask_client(scheduler=scheduler, workers=workers, jobs=len(specs)) as client:
        dict_future = client.scatter(dictionary, broadcast=True)
        futures = {client.submit(run_job, spec, dict_future, key=f"bench-{spec['ids'][0]}", pure=False): spec
                   for spec in specs}
        for future in as_completed(futures):
            spec = futures[future]
            exc = future.exception()
            if exc is None:
                computed += len(future.result())
            else:
                failed[spec["cells"][0].label()] = f"{type(exc).__name__}: {exc}"
            bar.update(len(spec["cells"]))
            future.release()
    return computed
