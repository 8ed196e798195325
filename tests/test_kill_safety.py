"""Kill-safety: a command killed at any moment and re-run as it was leaves complete outputs and no
temporaries; several outputs of one command are published all together or not at all.

Kills are exact: ``LFPROC_TEST_KILL_AT`` makes the process SIGKILL itself at a named point of
lfproc.io._atomic (the ``run_lfproc`` fixture of conftest.py checks that it died there).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lfproc.sensor import load_profile
from lfproc.cli.main import main
from lfproc.io._atomic import atomic_outputs, clean_stale
from lfproc.io import read_lightfield, write_lightfield
from lfproc.lightfield import LightField


def _hidden(*folders: Path) -> list[str]:
    return sorted(p.name for f in folders if f.is_dir() for p in f.rglob(".lfproc-*"))


def _dead_pid() -> int:
    out = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    return int(out.stdout)


# -- the mechanism --------------------------------------------------------------------------------

_WRITER = """
import sys
from pathlib import Path
from lfproc.io import atomic_outputs
root, tag, force = Path(sys.argv[1]), sys.argv[2], sys.argv[3] == "1"
outs = [root / "a" / "one.txt", root / "a" / "views", root / "b" / "two.txt"]
with atomic_outputs(outs, force=force) as (one, views, two):
    one.write_text(tag)
    views.mkdir()
    (views / "v.txt").write_text(tag)
    two.write_text(tag)
"""


def _write(root: Path, tag: str, *, force: bool, kill_at: str | None = None) -> None:
    env = dict(os.environ)
    env.pop("LFPROC_TEST_KILL_AT", None)
    if kill_at:
        env["LFPROC_TEST_KILL_AT"] = kill_at
    proc = subprocess.run([sys.executable, "-c", _WRITER, str(root), tag, "1" if force else "0"], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == (-9 if kill_at else 0), proc.stderr


def _state(root: Path) -> tuple:
    files = (root / "a" / "one.txt", root / "a" / "views" / "v.txt", root / "b" / "two.txt")
    return tuple(p.read_text() if p.exists() else None for p in files)


# the fast run kills before the journal (staged), in the middle of the moves (moved#1, new and
# replacing) and after the commit; the other cases (three or four subprocesses each) are slow
_FAST_KILLS = {("staged", False), ("moved#1", False), ("moved#1", True), ("committed", False)}


@pytest.mark.parametrize("point, replace", [
    pytest.param(point, replace, id=f"{point}-{'replace' if replace else 'new'}",
                 marks=[] if (point, replace) in _FAST_KILLS else [pytest.mark.slow])
    for replace in (False, True) for point in ("staged", "journal", "moved#1", "moved#2", "moved#3", "committed")])
def test_outputs_are_all_new_or_all_as_before_after_a_kill(tmp_path, point, replace):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    if replace:
        _write(tmp_path, "old", force=False)
    before = _state(tmp_path)
    _write(tmp_path, "new", force=replace, kill_at=point)
    killed = _state(tmp_path)
    if point == "moved#1":  # the kill really left a partial state behind
        assert killed[0] == "new" and killed[2] == before[2] and _hidden(tmp_path)
    # the next writer into these folders recovers them (here: the check every output makes)
    clean_stale(tmp_path / "a")
    clean_stale(tmp_path / "b")
    expected = ("new",) * 3 if point == "committed" else before
    assert _state(tmp_path) == expected
    assert _hidden(tmp_path) == []
    # and writing again as before works
    _write(tmp_path, "again", force=True)
    assert _state(tmp_path) == ("again",) * 3 and _hidden(tmp_path) == []


def test_only_dead_processes_entries_are_recovered(tmp_path):
    mine = tmp_path / f".lfproc-tmp-{os.getpid()}-x.exr"
    mine.write_text("live")
    dead = _dead_pid()
    stale = tmp_path / f".lfproc-tmp-{dead}-x-abc.exr"
    stale.write_text("stale")
    legacy = tmp_path / ".lfproc-tmp-x-abc.exr"  # no pid (older lfproc): cannot be proven stale
    legacy.write_text("?")
    aside = tmp_path / f".lfproc-old-{dead}-out.exr-1234abcd"  # moved aside, replacement never came
    aside.write_text("previous")
    assert sorted(p.name for p in clean_stale(tmp_path)) == sorted([stale.name, aside.name])
    assert mine.exists() and legacy.exists() and not stale.exists()
    assert (tmp_path / "out.exr").read_text() == "previous"


def test_a_journal_cannot_remove_files_outside_its_folders(tmp_path):
    """A planted journal naming a file elsewhere (a folder without a journal) does not touch it."""
    (tmp_path / "a").mkdir()
    (tmp_path / "c").mkdir()
    victim = tmp_path / "c" / "victim.txt"
    victim.write_text("keep")
    dead = _dead_pid()
    doc = {"pid": dead, "committed": False, "journals": [], "stage_dirs": [str(tmp_path / "c")],
           "moves": [{"final": str(victim), "staged": str(tmp_path / "a" / "gone"), "old": str(tmp_path / "c")}]}
    (tmp_path / "a" / f".lfproc-txn-{dead}-0000.json").write_text(json.dumps(doc))
    clean_stale(tmp_path / "a")
    assert victim.read_text() == "keep" and (tmp_path / "c").is_dir()
    assert _hidden(tmp_path) == []


def test_atomic_outputs_refuses_existing_outputs_and_writer_failures(tmp_path):
    (tmp_path / "x.txt").write_text("there")
    from lfproc.errors import InputError, OutputExistsError

    with pytest.raises(OutputExistsError, match="x.txt: output exists"):
        with atomic_outputs([tmp_path / "y.txt", tmp_path / "x.txt"]):
            pass
    with pytest.raises(InputError, match="the same path is given twice"):
        with atomic_outputs([tmp_path / "y.txt", tmp_path / "y.txt"]):
            pass
    with pytest.raises(OSError, match="z.txt: the writer produced no output"):
        with atomic_outputs([tmp_path / "y.txt", tmp_path / "z.txt"]) as (y, _):
            y.write_text("only one")
    with pytest.raises(RuntimeError):
        with atomic_outputs([tmp_path / "y.txt"]) as (y,):
            y.write_text("x")
            raise RuntimeError("writer crashed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.txt"]  # nothing published, nothing left


# -- the commands -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    root = tmp_path_factory.mktemp("frames")
    assert main(["calibrate", "simulate-frames", "--profile", "paper-high", "-o", str(root / "frames"),
                 "--size", "32", "32", "--iso", "100"]) == 0
    return root / "frames" / "manifest.csv"


# calibrate --report stages p.json (itself staged with its bias and flat-field sidecars: journal#1,
# moved#1-3), then publishes p.json, p.bias.npz, p.flat.npz and the report folder together
# (journal#2, moved#4-7, committed#2)
@pytest.mark.slow  # calibration with report in killed subprocesses
@pytest.mark.parametrize("point", ["dir-written", "journal#2", "moved#4", "moved#6", "committed#2"])
def test_calibrate_with_report_killed_then_rerun(tmp_path, frames, run_lfproc, capsys, point):
    args = ["calibrate", frames, "-o", tmp_path / "p.json", "--report", tmp_path / "rep"]
    run_lfproc(*args, kill_at=point)
    if point == "moved#4":  # the profile is in place, its sidecars and the report are not
        assert (tmp_path / "p.json").exists() and not (tmp_path / "rep").exists()
    code = main(list(map(str, args)))
    err = capsys.readouterr().err
    if point == "committed#2":  # the killed run had finished publishing: a plain re-run finds its outputs
        assert code == 2 and "output exists" in err
    else:
        assert code == 0, err
    profile = load_profile(tmp_path / "p.json")
    assert profile.bias_frames[100].shape == (32, 32) and profile.flat_field.shape == (32, 32)
    assert sorted(p.name for p in (tmp_path / "rep").iterdir()) == [  # one ISO: no read noise against ISO
        "dark_level.png", "dark_variance.png", "figures.json", "linearity.png", "photon_transfer.png",
        "prnu_dsnu_histograms.png", "snr.png", "summary.md"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.bias.npz", "p.flat.npz", "p.json", "rep"]


def _bracket(root: Path) -> list[str]:
    from lfproc.sensor import expose
    from lfproc.synth import synthesize

    truth = synthesize("layers", size=(16, 16), views=(1, 1), random_state=0).data.astype(np.float64) * 2e4
    flat = truth.reshape(-1, truth.shape[-2] * truth.shape[-1])
    paths = []
    for k, t in enumerate([0.01, 0.02, 0.04]):
        dn = expose(flat, exposure_s=t, iso=100, profile="illum", random_state=k).reshape(truth.shape)
        paths.append(str(write_lightfield(LightField(dn.astype(np.float32), units="dn", exposure_s=t, iso=100),
                                          root / f"e{k}.exr")))
    return paths


@pytest.mark.parametrize("point", [pytest.param("file-written#2", marks=pytest.mark.slow),  # fast: one point
                                   "moved#1", pytest.param("committed", marks=pytest.mark.slow)])
def test_merge_with_mask_killed_then_rerun(tmp_path, run_lfproc, point):
    inputs = _bracket(tmp_path)
    (tmp_path / "out").mkdir()
    args = ["merge", *inputs, "--profile", "illum", "-o", tmp_path / "out" / "hdr.exr", "--mask",
            tmp_path / "out" / "mask.exr"]
    run_lfproc(*args, kill_at=point)
    if point == "moved#1":
        assert [p.name for p in (tmp_path / "out").iterdir() if not p.name.startswith(".")] == ["hdr.exr"]
    rerun = run_lfproc(*args)
    assert rerun.returncode == (2 if point == "committed" else 0), rerun.stderr
    hdr = read_lightfield(tmp_path / "out" / "hdr.exr")
    mask = read_lightfield(tmp_path / "out" / "mask.exr")
    assert hdr.units == "e-/s" and mask.shape[:4] == hdr.shape[:4]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["hdr.exr", "mask.exr"]


@pytest.mark.parametrize("output, point", [("lf.exr", "file-written"),  # fast: one point, the others slow
                                           pytest.param("views", "file-written#4", marks=pytest.mark.slow),
                                           pytest.param("views", "dir-written", marks=pytest.mark.slow)])
def test_convert_killed_then_rerun(tmp_path, run_lfproc, output, point):
    lf = LightField(np.random.default_rng(0).random((3, 3, 6, 8, 3)).astype(np.float32))
    src = write_lightfield(lf, tmp_path / "src.exr")
    (tmp_path / "out").mkdir()
    args = ["convert", src, tmp_path / "out" / output]
    run_lfproc(*args, kill_at=point)
    assert _hidden(tmp_path / "out")  # the killed run left its temporary
    rerun = run_lfproc(*args)
    assert rerun.returncode == 0, rerun.stderr
    np.testing.assert_array_equal(read_lightfield(tmp_path / "out" / output).data, lf.data)
    assert [p.name for p in (tmp_path / "out").iterdir()] == [output] and _hidden(tmp_path / "out") == []
