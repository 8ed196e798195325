"""lfproc dataset build: per-scene outputs, manifest, failures, resuming after an interruption."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from lfproc.cli.main import main
from lfproc.dataset import build_dataset, find_scenes, read_manifest
from lfproc.io import read_lightfield, write_lightfield
from lfproc.lightfield import LightField
from lfproc.sensor import expose
from lfproc.synth import synthesize

TIMES = [0.01 * 2**k for k in range(5)]


def _make_scene(folder, seed, *, size=(24, 32)):
    """A scene folder: a 5-exposure bracket of raw-code light-field EXRs (and a truth file to ignore)."""
    folder.mkdir(parents=True)
    truth = synthesize("lamps", size=size, views=3, random_state=seed)
    e = truth.data.astype(np.float64) * 2e5
    flat = e.reshape(-1, e.shape[-2] * e.shape[-1])
    for k, t in enumerate(TIMES):
        dn = expose(flat, exposure_s=t, iso=100, profile="illum", random_state=seed * 10 + k).reshape(e.shape)
        write_lightfield(LightField(data=dn.astype(np.float32), units="dn", exposure_s=t, iso=100),
                         folder / f"exposure_{k}.exr")
    write_lightfield(truth, folder / "truth.exr")


@pytest.fixture()
def scenes(tmp_path):
    root = tmp_path / "scenes"
    for i in range(3):
        _make_scene(root / f"scene{i}", seed=i)
    return root


def _done_records(out):
    """The published done-records of ``out`` (a writer's hidden ``.lfproc-tmp-*.json`` is not one)."""
    return [p for p in (out / "done").glob("*.json") if not p.name.startswith(".")] if (out / "done").is_dir() else []


def _record_mtimes(out):
    return {p.name: p.stat().st_mtime_ns for p in _done_records(out)}


def _first_scene_done(out):
    """Ready test for ``kill_when``: ``out/done`` holds a done-record."""
    return lambda: bool(_done_records(out))


def test_build_failure_reported_then_resumed(scenes, tmp_path):
    broken = scenes / "zbroken"
    broken.mkdir()
    (broken / "only.exr").write_bytes(b"not an exr")
    (broken / "other.exr").write_bytes(b"not an exr either")
    found = find_scenes(scenes)
    assert [s.name for s in found] == ["scene0", "scene1", "scene2", "zbroken"]
    assert [p.name for p in found[0].inputs] == [f"exposure_{k}.exr" for k in range(5)]  # truth.exr left out
    out = tmp_path / "dataset"
    report = build_dataset(scenes, out, profile="illum", scheduler="synchronous")
    assert sorted(report["processed"]) == ["scene0", "scene1", "scene2"]
    assert list(report["failed"]) == ["zbroken"] and "only.exr" in report["failed"]["zbroken"]
    rows = read_manifest(out)
    assert [r["scene"] for r in rows] == ["scene0", "scene1", "scene2"]
    for row in rows:
        assert row["method"] == "ml" and row["exposures_s"] == TIMES
        assert row["dynamic_range_stops"] > 8 and 0 < row["saturated_fraction"] < 0.5
        scene = scenes / row["scene"]
        assert row["sha256"] == [hashlib.sha256((scene / f"exposure_{k}.exr").read_bytes()).hexdigest()
                                 for k in range(5)]
        for key in ("hdr", "preview", "histogram"):
            assert (out / row[key]).is_file()
        lf = read_lightfield(out / row["hdr"])
        assert lf.variance is not None and lf.units == "e-/s" and lf.shape == (3, 3, 24, 32, 3)
        # radiometry: the scene was exposed at 2e5 e-/s per unit of truth.exr; where some exposure
        # is unsaturated the merge recovers it (median relative error well under 1 %)
        truth = read_lightfield(scene / "truth.exr").data * 2e5
        ok = lf.data < 0.99 * lf.data.max()
        assert abs(np.median(lf.data[ok] / truth[ok] - 1)) < 0.01
        assert row["saturated_fraction"] == pytest.approx(1 - ok.mean(), abs=0.01)
        assert row["dynamic_range_stops"] == pytest.approx(lf.dynamic_range_stops(), abs=1e-4)
        # lfproc's warnings are kept in the row: the lamps clip in more than 10 % of some scenes
        expected = ["SaturationWarning"] if row["saturated_fraction"] > 0.1 else []
        assert [w.split(":")[0] for w in row["warnings"]] == expected
    with open(out / "manifest.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [r["scene"] for r in table] == ["scene0", "scene1", "scene2"]
    assert json.loads((out / "failed.json").read_text()) == report["failed"]
    # fix the broken scene: only it is processed on the next run
    before = _record_mtimes(out)
    (broken / "only.exr").unlink()
    (broken / "other.exr").unlink()
    _make_scene(tmp_path / "fixed", seed=7)
    for p in (tmp_path / "fixed").iterdir():
        p.rename(broken / p.name)
    report2 = build_dataset(scenes, out, profile="illum", scheduler="synchronous")
    assert report2["processed"] == ["zbroken"] and sorted(report2["skipped"]) == ["scene0", "scene1", "scene2"]
    assert report2["failed"] == {}
    after = _record_mtimes(out)
    assert all(after[name] == mtime for name, mtime in before.items())
    assert len(read_manifest(out)) == 4


@pytest.mark.slow  # killed subprocess, Dask
def test_cli_dataset_build_killed_then_resumed(scenes, tmp_path, capsys, kill_when):
    _make_scene(scenes / "scene3", seed=3)
    out = tmp_path / "dataset"
    cmd = [sys.executable, "-m", "lfproc.cli.main", "dataset", "build", str(scenes), "-o", str(out),
           "--workers", "1", "--profile", "illum"]
    kill_when(cmd, _first_scene_done(out), timeout_s=120)
    done_at_kill = _record_mtimes(out)
    assert 1 <= len(done_at_kill) < 4, "the run should have been killed after its first scene"
    # run again through the CLI (Dask local cluster): finishes the rest, keeps the done scenes
    assert main(["dataset", "build", str(scenes), "-o", str(out), "--workers", "1", "--profile", "illum",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["skipped"] == len(done_at_kill) and doc["processed"] == 4 - len(done_at_kill) and doc["failed"] == 0, (
        doc, sorted(done_at_kill))
    after = _record_mtimes(out)
    assert len(after) == 4 and all(after[k] == v for k, v in done_at_kill.items())
    rows = read_manifest(out)
    assert [r["scene"] for r in rows] == ["scene0", "scene1", "scene2", "scene3"]
    for r in rows:
        assert (out / r["preview"]).is_file() and (out / r["histogram"]).is_file()
    assert not list(out.glob("scenes/.lfproc-tmp-*"))  # the killed run's temporary folder was cleaned up


def test_cli_dataset_errors(tmp_path, capsys):
    assert main(["dataset", "build", str(tmp_path / "missing"), "-o", str(tmp_path / "o")]) == 2
    assert "no such scenes folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["dataset", "build", str(tmp_path / "empty"), "-o", str(tmp_path / "o")]) == 2
    assert "found none" in capsys.readouterr().err
    scene = tmp_path / "one" / "s"
    scene.mkdir(parents=True)
    write_lightfield(LightField(data=np.ones((1, 1, 4, 4, 3), np.float32), exposure_s=1.0), scene / "a.exr")
    assert main(["dataset", "build", str(tmp_path / "one"), "-o", str(tmp_path / "o"),
                 "--scheduler", "synchronous"]) == 2
    err = capsys.readouterr().err
    assert "scene s failed" in err and "at least two inputs" in err and "1 of 1 scenes failed" in err
    assert main(["dataset", "build", str(tmp_path / "one"), "-o", str(tmp_path / "o"), "--workers", "0"]) == 2
    assert "--workers: expected an integer from 1 to " in capsys.readouterr().err
    # a worker count far beyond the machine is refused before any folder is made or process started
    assert main(["dataset", "build", str(tmp_path / "one"), "-o", str(tmp_path / "p"), "--workers", "1000"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lfproc dataset: error: --workers: expected an integer from 1 to") and "got 1000" in err
    assert "\n" not in err and not (tmp_path / "p").exists()


@pytest.mark.slow  # virtual Illum brackets decoded and merged
def test_dataset_build_virtual_illum_brackets(tmp_path):
    lf = synthesize("lamps", size=(32, 32), views=5, random_state=2)
    write_lightfield(lf, tmp_path / "lf.exr")
    (tmp_path / "scenes").mkdir()
    assert main(["virtual-illum", str(tmp_path / "lf.exr"), "-o", str(tmp_path / "scenes" / "v1"), "--sensor", "small",
                 "--exposures-ev", "-2,-1,0,1,2"]) == 0
    out = tmp_path / "dataset"
    report = build_dataset(tmp_path / "scenes", out, scheduler="synchronous")
    assert report["failed"] == {} and report["processed"] == ["v1"]
    (row,) = read_manifest(out)
    assert row["method"] == "ml" and len(row["sources"]) == 5 and all(s.endswith(".LFR") for s in row["sources"])
    assert row["exposures_s"] == sorted(row["exposures_s"]) and len(set(row["exposures_s"])) == 5
    assert (out / row["preview"]).is_file() and (out / row["histogram"]).is_file()
    merged = read_lightfield(out / row["hdr"])
    assert merged.views == (5, 5) and merged.variance is not None
    assert row["dynamic_range_stops"] == pytest.approx(merged.dynamic_range_stops(), abs=1e-4)
    assert row["sha256"] == [hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in row["sources"]]
    # radiometry: times the 0 EV exposure the merge is the 0 EV decode (truth.exr of virtual-illum)
    info = json.loads((tmp_path / "scenes" / "v1" / "truth.json").read_text())
    t0 = next(c["exposure_s"] for c in info["captures"] if c["exposure_ev"] == 0)
    truth = read_lightfield(tmp_path / "scenes" / "v1" / "truth.exr").data
    bright = truth > 0.1 * truth.max()
    assert 0.8 < np.median(merged.data[bright] * t0 / truth[bright]) < 1.2


def _virtual_illum_scenes(root, tmp_path, n):
    """``n`` scene folders, each a 5-exposure virtual-Illum bracket (LFR captures, caldata tar, truth)."""
    root.mkdir()
    for i in range(n):
        lf = synthesize("lamps", size=(32, 32), views=5, random_state=20 + i)
        write_lightfield(lf, tmp_path / f"lf{i}.exr")
        assert main(["virtual-illum", str(tmp_path / f"lf{i}.exr"), "-o", str(root / f"v{i}"), "--sensor", "small",
                     "--exposures-ev", "-2,-1,0,1,2", "--seed", str(i), "--json"]) == 0
    return root


def _scene_mtimes(out, names):
    """mtimes of the done-records and every output file of the scenes ``names``."""
    files = [out / "done" / f"{name}.json" for name in names]
    files += [p for name in names for p in sorted((out / "scenes" / name).iterdir())]
    return {str(p.relative_to(out)): p.stat().st_mtime_ns for p in files}


@pytest.mark.slow  # killed subprocess, Dask
def test_cli_dataset_build_virtual_illum_killed_then_resumed(tmp_path, capsys, kill_when):
    names = ["v0", "v1", "v2"]
    scenes = _virtual_illum_scenes(tmp_path / "scenes", tmp_path, len(names))
    capsys.readouterr()
    assert [s.name for s in find_scenes(scenes)] == names
    out = tmp_path / "dataset"
    cmd = [sys.executable, "-m", "lfproc.cli.main", "dataset", "build", str(scenes), "-o", str(out),
           "--workers", "1"]
    # first run: a local Dask cluster of one worker (scenes one after the other), killed as soon as the
    # first done-record appears
    kill_when(cmd, _first_scene_done(out), timeout_s=60)
    done_at_kill = sorted(p.stem for p in _done_records(out))
    assert 1 <= len(done_at_kill) < len(names), f"the run should have been killed after its first scene: {done_at_kill}"
    assert not (out / "manifest.json").exists()  # the killed run never reached its manifest
    before = _scene_mtimes(out, done_at_kill)
    assert len(before) == len(done_at_kill) * 5  # done-record + hdr, preview, histogram, record
    # second run, to completion: the rest is processed, the done scenes are skipped and not rewritten
    result = subprocess.run(cmd + ["--json"], capture_output=True, text=True, env=dict(os.environ, LFPROC_PROGRESS="0"), timeout=120)
    assert result.returncode == 0, result.stderr
    doc = json.loads(result.stdout)
    assert doc["scenes"] == 3 and doc["failed"] == 0
    assert doc["skipped"] == len(done_at_kill) and doc["processed"] == 3 - len(done_at_kill)
    assert _scene_mtimes(out, done_at_kill) == before
    assert not list((out / "scenes").glob(".lfproc-tmp-*"))  # the killed run's temporary folder was removed
    rows = read_manifest(out)
    assert [r["scene"] for r in rows] == names
    with open(out / "manifest.csv", newline="") as fh:
        assert [r["scene"] for r in csv.DictReader(fh)] == names
    for row in rows:
        folder = scenes / row["scene"]
        truth_info = json.loads((folder / "truth.json").read_text())
        captures = truth_info["captures"]
        assert row["method"] == "ml"
        assert row["exposures_s"] == pytest.approx([c["exposure_s"] for c in captures], rel=1e-9)
        assert row["sources"] == [str(folder / c["file"]) for c in captures]
        assert row["sha256"] == [hashlib.sha256((folder / c["file"]).read_bytes()).hexdigest() for c in captures]
        merged = read_lightfield(out / row["hdr"])
        assert merged.views == (5, 5) and merged.variance is not None
        assert row["dynamic_range_stops"] == pytest.approx(merged.dynamic_range_stops(), abs=1e-4)
        assert row["dynamic_range_stops"] > 15
        assert row["saturated_fraction"] == merged.attrs["saturated_everywhere_fraction"]
        assert 0 <= row["saturated_fraction"] < 0.01
        for key in ("preview", "histogram"):
            image = iio.imread(out / row[key])
            assert image.ndim == 3 and image.shape[0] > 16 and image.std() > 0
        # radiometry: the merge is per second; times the 0 EV exposure it is the 0 EV decode (truth.exr)
        truth = read_lightfield(folder / "truth.exr")
        assert truth.shape == merged.shape
        t0 = next(c["exposure_s"] for c in captures if c["exposure_ev"] == 0)
        bright = truth.data > 0.1 * truth.data.max()
        ratio = merged.data[bright] * t0 / truth.data[bright]
        assert bright.sum() > 1000
        assert 0.8 < np.median(ratio) < 1.2, (row["scene"], float(np.median(ratio)))


def _png_bracket(folder, n=2):
    """``n`` 8-bit PNGs without EXIF (a bracket whose exposure times only a file can give)."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    base = rng.random((20, 30, 3))
    for k in range(n):
        iio.imwrite(folder / f"img{k}.png", (np.clip(base * 2.0**k * 0.3, 0, 1) * 255).astype(np.uint8))


def test_exposure_file_forms_and_errors(tmp_path):
    from lfproc.dataset import read_exposure_file
    from lfproc.errors import InputError

    inputs = [tmp_path / "b.png", tmp_path / "a.png", tmp_path / "c.png"]
    f = tmp_path / "exposures.txt"
    f.write_text("# name seconds\na.png 1/8\nb.png 0.5\nc.png 2  # long\n")
    assert read_exposure_file(f, inputs) == [0.5, 0.125, 2.0]
    f.write_text("1/8\n0.5\n2\n")  # bare seconds: in the order of the sorted names a, b, c
    assert read_exposure_file(f, inputs) == [0.5, 0.125, 2.0]
    j = tmp_path / "exposures.json"
    j.write_text(json.dumps({"a.png": 0.125, "b.png": "1/2", "c.png": 2}))
    assert read_exposure_file(j, inputs) == [0.5, 0.125, 2.0]
    j.write_text(json.dumps([0.125, 0.5, 2]))
    assert read_exposure_file(j, inputs) == [0.5, 0.125, 2.0]
    for text, match in (("a.png 1/8\nb.png 0.5\n", "no exposure time for c.png"),
                        ("a.png 1\nb.png 1\nc.png 1\nd.png 1\n", "names not in the bracket: d.png"),
                        ("1\n2\n", "2 exposure time\\(s\\) for 3 inputs"),
                        ("a.png 1\n2\n3\n", "mixes"),
                        ("a.png -1\nb.png 1\nc.png 1\n", "line 1: expected a positive exposure time"),
                        ("a.png x\nb.png 1\nc.png 1\n", "line 1: expected seconds")):
        f.write_text(text)
        with pytest.raises(InputError, match=match):
            read_exposure_file(f, inputs)


@pytest.mark.slow  # a Dask cluster in a subprocess
def test_bracket_without_exif_points_to_the_exposure_file(tmp_path):
    """No EXIF: the build says to write SCENE/exposures.txt (lfproc merge's --exposures-s does not exist
    here) in one line, with no Dask traceback; with the file the scene is built with its times."""
    _png_bracket(tmp_path / "scenes" / "s")
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "lfproc.cli.main", "dataset", "build", str(tmp_path / "scenes"), "-o", str(out),
           "--workers", "1"]  # a Dask local cluster in a process of its own, as a user runs it
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                         env=dict(os.environ, LFPROC_PROGRESS="0", PYTHONWARNINGS="ignore"))
    assert res.returncode == 2
    err = res.stderr
    assert "exposures.txt" in err and "img0.png" in err and "--exposures-s" not in err
    assert "Traceback" not in err and "distributed.worker" not in err
    (tmp_path / "scenes" / "s" / "exposures.txt").write_text("img0.png 1/100\nimg1.png 1/50\n")
    assert main(["dataset", "build", str(tmp_path / "scenes"), "-o", str(out), "--scheduler", "synchronous"]) == 0
    (row,) = read_manifest(out)
    assert row["exposures_s"] == pytest.approx([0.01, 0.02])
    assert row["exposure_file"].endswith("exposures.txt")


def test_hostile_exposure_files_get_one_line(tmp_path):
    """A JSON exposure list nested 100,000 levels deep raised RecursionError; NaN and binary files are refused."""
    from lfproc.dataset import read_exposure_file
    from lfproc.errors import InputError

    inputs = [tmp_path / "a.png", tmp_path / "b.png"]
    for name, data, message in [("deep.json", b"[" * 100000 + b"]" * 100000, "nested 100000 levels deep"),
                                ("nan.txt", b"a.png nan\nb.png 1\n", "expected a positive exposure time"),
                                ("bin.txt", bytes(range(256)), "found binary data")]:
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(InputError, match=message):
            read_exposure_file(path, inputs)
