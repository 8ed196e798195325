"""lfproc bench: the paper's baselines against the truth, the grid, resume after a kill, bad input."""

from __future__ import annotations

import csv
import json
import sys

import numpy as np
import pytest

import lfproc
from lfproc.bench import grid_cells, merge_reconstructions, reconstruct_per_shot, run_bench, split_shots
from lfproc.bench.grid import PRESETS, cell_seed
from lfproc.bench.report import claims
from lfproc.bench.run import COLUMNS
from lfproc.sensor import load_profile
from lfproc.camera.simulate import simulate_capture
from lfproc.cli.main import main
from lfproc.dictionary import dct_dictionary, save_dictionary
from lfproc.errors import InputError, SaturationWarning, ShapeError
from lfproc.metrics import evaluate
from lfproc.recon import PAPER, reconstruct
from lfproc.synth import synthesize


# -- a smooth 14-stop scene the small DCT dictionary represents well -----------------------------

def _ramp_lf(size=(16, 24), stops=14.0) -> lfproc.LightField:
    """An exponential ramp over ``stops`` stops with a little texture and parallax.

    The automatic radiance scale saturates ISO 100 at the bright end, so ISO 1600 (and the 8x
    exposure) saturate its brightest 4 stops, while ISO 100 (and the 0.5x exposure) sees the
    dark end with a few electrons: neither single shot gets the whole scene right.
    """
    v, u, y, x = np.meshgrid(np.arange(5), np.arange(5), np.arange(size[0]), np.arange(size[1]), indexing="ij")
    xs = x + 0.3 * (u - 2)
    base = 2.0 ** (stops * xs / size[1]) * (1.0 + 0.3 * np.sin(xs / 3.0) * np.cos(y / 4.0))
    rgb = np.stack([base, 0.8 * base * (1 + 0.1 * y / size[0]), 0.6 * base], axis=-1)
    return lfproc.LightField(rgb.astype(np.float32))


@pytest.fixture(scope="module")
def ramp():
    return _ramp_lf()


@pytest.fixture(scope="module")
def dct8():
    return dct_dictionary((5, 5, 8, 8, 3), 200, n_nonzero_coefs=6)


def _alone(shot, dictionary):
    """One shot reconstructed on its own. Higher ISOs and longer exposures saturate by design: a shot
    with more than 10 % of its pixels saturated must warn (SaturationWarning, nothing else), the
    others must not warn at all (warnings are errors in this suite)."""
    if shot.saturated_fraction(pixels="least-sensitive") > 0.10:
        with pytest.warns(SaturationWarning, match="of the least sensitive pixels"):
            return reconstruct(shot, dictionary, **PAPER)
    return reconstruct(shot, dictionary, **PAPER)


def _scores(result, truth):
    return evaluate(result, truth, scale_tolerance_stops=None)


def _flat(truth):
    """The trivial estimate: every sample the truth's mean colour."""
    return lfproc.LightField(np.broadcast_to(truth.data.mean(axis=(0, 1, 2, 3)), truth.shape).astype(np.float32))


# -- baselines -------------------------------------------------------------------------------------
# The reconstructions below use the paper's settings (lfproc.recon.PAPER: mu 1e-4 on unit-norm
# patches, tolerance 2^-15, 300 iterations, plain averages), under which the bounds were measured:
# they test the baselines' plumbing and merging, not the reconstruction defaults of the day.

@pytest.mark.parametrize("baseline,shots", [("individual-iso", 4), ("bracketing", 3)])
@pytest.mark.parametrize("merge", ["debevec", "ml"])
def test_merging_exact_reconstructions_returns_the_truth(ramp, baseline, shots, merge):
    """Known answer: if every shot were reconstructed exactly, the merge must give the truth back
    (re-exposure, gains, exposures and units all cancel); only samples saturated in every usable
    shot could differ, and the least exposed shot saturates none of this scene."""
    capture = simulate_capture(ramp, profile="paper-low", baseline=baseline, shots=shots, mask_period=4,
                               random_state=0, noise=False)
    parts = split_shots(capture)
    assert [p.shots for p in parts] == [1] * capture.shots
    assert [p.exposures_s[0] for p in parts] == list(capture.exposures_s)
    merged = merge_reconstructions([ramp] * len(parts), parts, merge=merge, guard_px=0)
    assert merged.units == ramp.units and merged.shape == ramp.shape
    rel = np.abs(merged.data - ramp.data) / ramp.data
    assert np.median(rel) < 1e-3 and rel.max() < 0.02, (np.median(rel), rel.max())


@pytest.mark.slow  # 8 reconstructions at the paper's settings
def test_individual_iso_baseline_against_the_truth(ramp, dct8):
    """Four single-ISO shots, each reconstructed, merged: close to the truth and better than any
    single shot (log-PSNR: every shot misses the dark end or the bright end). Bounds measured
    31.2 (Debevec) and 31.7 dB (ML) PU21-PSNR; merged log-PSNR 31.0 / 34.0 dB against at most
    30.1 dB for the best single shot (ISO 100)."""
    # the paper's uniform codes, with which the bounds were measured (mixed codes: Debevec 28.5 dB)
    capture = simulate_capture(ramp, profile="paper-low", baseline="individual-iso", mask_period=4, random_state=3,
                               mask_transmittance="uniform")
    assert [float(np.unique(capture.iso[s])[0]) for s in range(4)] == [100, 400, 800, 1600]
    out = reconstruct_per_shot(capture, dct8, merges=("debevec", "ml"), **PAPER)
    singles = [_scores(_alone(s, dct8), ramp) for s in split_shots(capture)]
    best_single = max(s["log_psnr_db"] for s in singles)
    flat = _scores(_flat(ramp), ramp)
    for merge, lf in out.items():
        s = _scores(lf, ramp)
        assert s["pu21_psnr_db"] > 29.0, (merge, s["pu21_psnr_db"])
        assert s["pu21_psnr_db"] > flat["pu21_psnr_db"] + 15
        assert s["log_psnr_db"] > best_single + 0.5, (merge, s["log_psnr_db"], best_single)
        rec = lf.attrs["reconstruction"]
        assert rec["mode"] == "per-shot" and len(rec["per_shot"]) == 4 and rec["seconds"] > 0
        assert lf.attrs["per_shot_merge"]["isos"] == [100, 400, 800, 1600]
    # the noise-aware merge weighs the noisy dark end better than hat weights
    assert _scores(out["ml"], ramp)["log_psnr_db"] > _scores(out["debevec"], ramp)["log_psnr_db"] + 1


def test_bracketing_baseline_against_the_truth(ramp, dct8):
    """Two ISO-100 shots at 0.5x and 8x, each reconstructed, merged. Measured 31.7 / 31.8 dB
    PU21-PSNR (Debevec / ML); merged log-PSNR 34.4 / 37.2 dB against 26.0 and 23.5 dB for the
    shots alone."""
    capture = simulate_capture(ramp, profile="paper-low", baseline="bracketing", shots=2, mask_period=4,
                               random_state=3)
    assert np.allclose(np.array(capture.exposures_s) / capture.exposures_s[0], [1, 16])
    out = reconstruct_per_shot(capture, dct8, merges=("debevec", "ml"), **PAPER)
    singles = [_scores(_alone(s, dct8), ramp)["log_psnr_db"] for s in split_shots(capture)]
    for merge, lf in out.items():
        s = _scores(lf, ramp)
        assert s["pu21_psnr_db"] > 29.5, (merge, s["pu21_psnr_db"])
        assert s["log_psnr_db"] > max(singles) + 5, (merge, s["log_psnr_db"], singles)


def test_bracketing_joint_solve_against_the_truth(ramp, dct8):
    """The same two bracketing shots solved jointly (lfproc's variant). Measured 23.7 dB PU21-PSNR
    and 32.8 dB log-PSNR (the joint solve shrinks the brightest, half-saturated patches: see the
    bench report), against 4.4 / 10.1 dB for the flat estimate."""
    capture = simulate_capture(ramp, profile="paper-low", baseline="bracketing", shots=2, mask_period=4,
                               random_state=3)
    s = _scores(reconstruct(capture, dct8, **PAPER), ramp)
    flat = _scores(_flat(ramp), ramp)
    assert s["pu21_psnr_db"] > 21.0 and s["log_psnr_db"] > 30.0, s
    assert s["pu21_psnr_db"] > flat["pu21_psnr_db"] + 15


def test_dual_iso_against_the_truth(ramp, dct8):
    """Dual-ISO rows (100, 1600), 2 shots, jointly reconstructed: measured 30.4 dB PU21-PSNR, 29.8 dB log-PSNR."""
    capture = simulate_capture(ramp, profile="paper-low", iso_pattern_kind="dual", shots=2, mask_period=4,
                               random_state=3)
    assert capture.isos == [100.0, 1600.0]
    s = _scores(reconstruct(capture, dct8, **PAPER), ramp)
    assert s["pu21_psnr_db"] > 28.0 and s["log_psnr_db"] > 27.0, s


def test_per_shot_mode_refuses_what_it_cannot_merge(ramp, dct8):
    joint = simulate_capture(ramp, profile="paper-low", shots=2, mask_period=4, random_state=1)
    with pytest.raises(InputError, match="global ISO"):
        reconstruct_per_shot(joint, dct8)
    one = split_shots(simulate_capture(ramp, profile="paper-low", baseline="bracketing", shots=2, mask_period=4,
                                       random_state=1))[0]
    with pytest.raises(InputError, match="at least two shots"):
        reconstruct_per_shot(one, dct8)
    capture = simulate_capture(ramp, profile="paper-low", baseline="bracketing", shots=2, mask_period=4, random_state=1)
    with pytest.raises(InputError, match="merge"):
        reconstruct_per_shot(capture, dct8, merges=("median",))
    with pytest.raises(InputError, match="method"):
        reconstruct_per_shot(capture, dct8, method="lasso")
    with pytest.raises(InputError, match="patch model .* not a dictionary"):
        reconstruct_per_shot(capture, dct8, method="gmm")


# -- the grid ------------------------------------------------------------------------------------------

def test_grid_sizes_seeds_and_methods():
    quick = grid_cells("quick", ["a", "b"])
    assert len(quick) == 70 and len(set(quick)) == 70
    paper = grid_cells("paper", ["a"])
    # 4 patterns x 3 shots x 3 ISO sets x 4 noise levels + 3 exposures + 4 x (2 + 3 x 3) baselines
    assert len(paper) == 144 + 3 + 44
    assert {c.method for c in paper} == {"joint", "dual-iso", "individual-iso", "bracketing", "bracketing-joint"}
    assert {c.isos for c in paper} == {(100, 400, 800, 1600), (100, 800, 1600, 3200), (100, 1600, 3200, 6400)}
    # every ISO of the three sets is in the shipped noise profiles
    for level in ("none", "low", "medium", "high"):
        prof = load_profile(f"paper-{level}")
        assert {100, 400, 800, 1600, 3200, 6400} <= set(prof.iso_values)
    # seeds: shared across noise level, ISO set and pattern (common random numbers), not across shots
    by = {(c.iso_pattern, c.shots, c.noise, c.isos, c.method): cell_seed(0, c) for c in paper}
    a = by[("random", 2, "low", (100, 400, 800, 1600), "joint")]
    assert a == by[("random", 2, "high", (100, 1600, 3200, 6400), "joint")]
    assert a != by[("random", 3, "low", (100, 400, 800, 1600), "joint")]
    assert a == by[("row", 2, "low", (100, 400, 800, 1600), "joint")] == \
        by[("block", 2, "high", (100, 400, 800, 1600), "joint")]
    assert by[("global", 4, "low", (100, 400, 800, 1600), "individual-iso")] != \
        by[("global", 4, "low", (100, 400, 800, 1600), "bracketing")]  # another acquisition
    assert by[("global", 3, "low", (100, 400, 800, 1600), "bracketing")] == \
        by[("global", 3, "low", (100, 400, 800, 1600), "bracketing-joint")]
    with pytest.raises(InputError, match="preset"):
        grid_cells("fast", ["a"])
    with pytest.raises(InputError, match="at least one"):
        grid_cells("quick", [])


def _rows(**overrides):
    base = {"scene": "s", "merge": "", "isos": "100,400,800,1600", "noise": "low", "exposure": 1.0,
            "saturated_fraction": 0.01}
    return {**base, **overrides}


def test_claims_are_computed_from_the_rows():
    """The claims section decides from the numbers: planted rows that satisfy or break each claim."""
    good = []
    for pattern, offset in (("random", 0.0), ("row", 0.0), ("block", -2.0)):
        for shots, psnr in ((1, 30.0), (2, 32.0), (3, 32.2)):
            good.append(_rows(method="joint", iso_pattern=pattern, shots=shots, pu21_psnr_db=psnr + offset))
    good.append(_rows(method="bracketing", iso_pattern="global", shots=4, merge="debevec", pu21_psnr_db=32.1))
    for noise, d in (("none", 0.1), ("medium", -0.2), ("high", -0.4)):
        good.append(_rows(method="joint", iso_pattern="random", shots=2, noise=noise, pu21_psnr_db=32.0 + d))
    for sat, psnr in ((0.05, 31.9), (0.12, 31.5), (0.3, 28.0)):
        good.append(_rows(method="joint", iso_pattern="random", shots=2, exposure=sat * 100,
                          saturated_fraction=sat, pu21_psnr_db=psnr))
    verdicts = [c["verdict"] for c in claims(good)]
    assert verdicts == ["holds"] * 5, claims(good)
    bad = [dict(r) for r in good]
    for r in bad:
        if r["method"] == "joint" and r["iso_pattern"] == "block":
            r["pu21_psnr_db"] += 5  # block now wins
        if r["method"] == "bracketing":
            r["pu21_psnr_db"] = 40.0
        if r["noise"] == "high":
            r["pu21_psnr_db"] = 25.0
    out = {c["claim"]: c["verdict"] for c in claims(bad)}
    assert out["Random and row ISO patterns beat block"] == "does not hold"
    assert out["Joint reconstruction with 2 shots matches or beats bracketing with 4"] == "does not hold"
    assert out["The noise level barely matters"] == "does not hold"
    assert claims([])[0]["verdict"] == "not testable"


# -- the bench end to end: quick on tiny scenes, killed and resumed --------------------------------------

@pytest.fixture(scope="module")
def tiny_inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench")
    scenes = []
    for name, scene, seed in (("layers", "layers", 1), ("checker", "checker", 2)):
        lf = synthesize(scene, size=(16, 16), views=5, random_state=seed)
        path = root / f"{name}.exr"
        lfproc.write_lightfield(lf, path)
        scenes.append(path)
    dictionary = root / "dct4.npz"
    save_dictionary(dct_dictionary((5, 5, 4, 4, 3), 100, n_nonzero_coefs=4), dictionary)
    return root, scenes, dictionary


def _cell_by_hand(scene_path, dictionary_path, seed):
    """Independent recomputation of the reference cell (joint, random ISO pattern, 2 shots, ISO
    100-1600, noise low, relative exposure 1) from the grid's documented settings (lfproc.bench.grid:
    paper-low profile, 4 ms, random mask of period 4) with the public API, not the bench's code."""
    from lfproc.dictionary import load_dictionary

    lf = lfproc.read_lightfield(scene_path)
    capture = simulate_capture(lf, profile="paper-low", isos=(100, 400, 800, 1600), exposure_s=0.004, mask="random",
                               mask_period=4, iso_pattern_kind="random", shots=2, relative_exposures=[1.0, 1.0],
                               random_state=seed)
    return evaluate(reconstruct(capture, load_dictionary(dictionary_path)), lf, scale_tolerance_stops=None)


def _check_rows_against_known_answers(table, scene_names):
    """Checks of results.csv rows that can fail: the seed of each row is its cell's (shared within a draw
    group, so cells differing only in noise level or ISO set share it); the sampling rate is the
    known shots / (5 x 5 views x 3 colours); the saturation sweep saturates more at each step of
    exposure (same seed, so same mask, ISO map and noise draws)."""
    cells = {(c.scene, c.method, c.iso_pattern, c.shots, ",".join(map(str, c.isos)), c.noise, c.exposure, c.merge): c
             for c in grid_cells("quick", scene_names)}
    assert len(table) == len(cells)
    for r in table:
        cell = cells[(r["scene"], r["method"], r["iso_pattern"], int(r["shots"]), r["isos"], r["noise"],
                      float(r["exposure"]), r["merge"])]
        assert int(r["seed"]) == cell_seed(0, cell)
        assert float(r["sampling_rate_percent"]) == pytest.approx(100 * cell.shots / 75, rel=1e-5)
    for scene in scene_names:
        sweep = sorted((float(r["exposure"]), float(r["saturated_fraction"])) for r in table
                       if r["scene"] == scene and r["method"] == "joint" and r["iso_pattern"] == "random"
                       and r["shots"] == "2" and r["noise"] == "low" and r["isos"] == "100,400,800,1600")
        assert [e for e, _ in sweep] == [1, 4, 32, 256]
        fractions = [f for _, f in sweep]
        assert fractions == sorted(fractions) and fractions[-1] > fractions[0], sweep


def _cell_files(out):
    # pathlib's glob matches dot files: leave out the temporary files of atomic writes
    return {p.name: (p.stat().st_mtime_ns, p.stat().st_ino) for p in (out / "cells").glob("*.npz")
            if not p.name.startswith(".")}


@pytest.mark.slow  # a 70-cell bench in a killed subprocess, resumed on Dask
def test_bench_quick_killed_then_resumed(tiny_inputs, capsys, kill_when):
    root, scenes, dictionary = tiny_inputs
    out = root / "run"
    cmd = [sys.executable, "-m", "lfproc.cli.main", "bench", *map(str, scenes), "-o", str(out), "--preset", "quick",
           "--dictionary", str(dictionary), "--scheduler", "synchronous"]
    kill_when(cmd, lambda: (out / "cells").is_dir() and len(_cell_files(out)) >= 10, timeout_s=120, poll_s=0.01)
    done_at_kill = _cell_files(out)
    assert 10 <= len(done_at_kill) < 70, "the run should have been killed part-way"
    assert not (out / "results.csv").exists()
    # resume on a local Dask cluster: only the missing cells are computed, the done ones are untouched
    assert main(["bench", *map(str, scenes), "-o", str(out), "--dictionary", str(dictionary), "--workers", "1",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["cells"] == 70 and doc["failed"] == 0
    assert doc["cached"] == len(done_at_kill) and doc["computed"] == 70 - len(done_at_kill)
    after = _cell_files(out)
    assert len(after) == 70 and all(after[k] == v for k, v in done_at_kill.items())
    assert not list((out / "cells").glob(".lfproc-tmp-*"))
    with open(out / "results.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == 70 and list(table[0])[:len(COLUMNS)] == list(COLUMNS)
    assert {r["scene"] for r in table} == {"layers", "checker"}
    assert {r["method"] for r in table} == {"joint", "individual-iso", "bracketing", "bracketing-joint", "dual-iso"}
    _check_rows_against_known_answers(table, ["layers", "checker"])
    # one cell recomputed by hand through the public API (simulate, reconstruct, evaluate)
    (ref_row,) = [r for r in table if r["scene"] == "layers" and r["method"] == "joint" and r["iso_pattern"] == "random"
                  and r["shots"] == "2" and r["noise"] == "low" and r["isos"] == "100,400,800,1600"
                  and r["exposure"] == "1"]
    expected = _cell_by_hand(scenes[0], dictionary, int(ref_row["seed"]))
    assert float(ref_row["pu21_psnr_db"]) == pytest.approx(expected["pu21_psnr_db"], abs=1e-3)
    assert float(ref_row["pu21_ssim"]) == pytest.approx(expected["pu21_ssim"], abs=1e-5)
    report = (out / "report.md").read_text()
    for heading in ("Table I", "Table II", "Table III", "Table IV", "The paper's claims", "not available"):
        assert heading in report
    # the five claims, each decided from these rows (lfproc.bench.report.claims) and printed with its verdict
    decided = claims(run_bench(scenes, out, dictionary=dictionary, scheduler="synchronous", report=False)["rows"])
    assert len(decided) == 5
    for c in decided:
        assert f"**{c['claim']}: {c['verdict']}.**" in report, c
    for png in ("quality_vs_shots", "quality_vs_noise", "quality_vs_saturation", "joint_vs_bracketing", "best_worst"):
        assert (out / f"{png}.png").stat().st_size > 1000 and f"({png}.png)" in report
    # a further run computes nothing
    again = run_bench(scenes, out, dictionary=dictionary, scheduler="synchronous", report=False)
    assert again["computed"] == 0 and again["cached"] == 70


def test_a_bench_cell_is_the_score_of_its_reconstruction(tiny_inputs, tmp_path):
    """The fast check of the bench's cell pipeline (lfproc.bench.run.run_job, one cell, this process):
    its row equals the reference cell recomputed by hand (_cell_by_hand), it records the cell's seed
    and the known sampling rate 2 / 75, and its cell file holds that row and the centre view."""
    from lfproc.bench.grid import PRESETS, Cell, cell_seed
    from lfproc.bench.run import BenchScene, read_cells, run_job
    from lfproc.dictionary import load_dictionary

    root, scenes, dictionary = tiny_inputs
    cell = Cell("layers", "joint", "random", 2, (100, 400, 800, 1600), "low")
    scene = BenchScene(name="layers", path=str(scenes[0]), sha256="-", crop=None, views=(5, 5), size=(16, 16))
    spec = {"scene": scene, "preset": PRESETS["quick"], "cells": [cell], "ids": ["one"], "seed": 0,
            "recon": {"method": "dictionary"}, "cells_dir": str(tmp_path), "dictionary_id": "dct4"}
    (row,) = run_job(spec, load_dictionary(dictionary))
    assert row["seed"] == cell_seed(0, cell)
    expected = _cell_by_hand(scenes[0], dictionary, row["seed"])
    for key in ("pu21_psnr_db", "pu21_ssim", "log_psnr_db", "mean_relative_error"):
        assert row[key] == pytest.approx(expected[key], rel=1e-6), key
    assert row["sampling_rate_percent"] == pytest.approx(100 * 2 / 75)
    assert (row["isos_used"], row["relative_exposures"], row["size"]) == ("100,400,800,1600", "1;1", "16x16")
    (stored,) = read_cells([tmp_path / "one.npz"])
    assert stored["pu21_psnr_db"] == row["pu21_psnr_db"] and stored["cell_id"] == "one"


@pytest.mark.slow  # two 35-cell bench runs
def test_cells_made_with_other_library_defaults_are_not_reused(tiny_inputs, monkeypatch):
    """A cell's identity includes lfproc's reconstruction defaults and block size, so an upgrade that
    changes them recomputes the cells instead of reporting results of the old defaults."""
    import lfproc.bench.run as bench_run

    root, scenes, dictionary = tiny_inputs
    out = root / "defaults"
    first = run_bench(scenes[:1], out, dictionary=dictionary, scheduler="synchronous", report=False)
    assert first["computed"] == first["cells"] > 0
    monkeypatch.setattr(bench_run, "RECON_DEFAULTS", {**bench_run.RECON_DEFAULTS, "overlap": "mean"})
    changed = run_bench(scenes[:1], out, dictionary=dictionary, scheduler="synchronous", report=False)
    assert changed["cached"] == 0 and changed["computed"] == first["cells"]


# -- bad input -------------------------------------------------------------------------------------------

def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lfproc bench: error: "), err
    return err[0]


def test_bench_bad_input_one_line_exit_2(tiny_inputs, tmp_path, capsys):
    root, scenes, dictionary = tiny_inputs
    out = str(tmp_path / "b")
    assert main(["bench", str(scenes[0]), "-o", out, "--preset", "fast", "--dictionary", str(dictionary)]) == 2
    assert "preset" in _one_error_line(capsys) and not (tmp_path / "b").exists()
    assert main(["bench", "-o", out, "--dictionary", str(dictionary)]) == 2
    assert "at least one light field" in _one_error_line(capsys)
    three = tmp_path / "three.exr"
    lfproc.write_lightfield(lfproc.read_lightfield(scenes[0]).central(3), three)
    assert main(["bench", str(scenes[0]), str(three), "-o", out, "--dictionary", str(dictionary)]) == 2
    line = _one_error_line(capsys)
    assert "three.exr" in line and "3 x 3 views" in line and "5 x 5" in line
    assert main(["bench", str(tmp_path / "missing.exr"), "-o", out, "--dictionary", str(dictionary)]) == 2
    assert "missing.exr" in _one_error_line(capsys)
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "mine.txt").write_text("not a bench")
    assert main(["bench", str(scenes[0]), "-o", str(tmp_path / "taken"), "--dictionary", str(dictionary)]) == 2
    assert "not a bench folder" in _one_error_line(capsys)
    assert main(["bench", str(scenes[0]), "-o", out, "--dictionary", str(dictionary), "--workers", "0"]) == 2
    assert "--workers" in _one_error_line(capsys)
    with pytest.raises(ShapeError, match="views"):
        run_bench([scenes[0], three], tmp_path / "lib", dictionary=dictionary, scheduler="synchronous")
    with pytest.raises(InputError, match="at least one"):
        run_bench([], tmp_path / "lib", dictionary=dictionary)
    assert set(PRESETS) == {"quick", "paper"}


def test_cli_reconstruct_per_shot_mode(ramp, dct8, tmp_path, capsys):
    """`lfproc reconstruct --per-shot ml` on a bracketing capture file equals the library's result."""
    truth = tmp_path / "ramp.exr"
    lfproc.write_lightfield(ramp, truth)
    capture = simulate_capture(ramp, profile="paper-low", baseline="bracketing", shots=2, mask_period=4,
                               random_state=3)
    cap_path = tmp_path / "b.capture.npz"
    capture.save(cap_path)
    dpath = tmp_path / "d.npz"
    save_dictionary(dct8, dpath, dtype="float32")
    out = tmp_path / "out.exr"
    assert main(["reconstruct", str(cap_path), "-o", str(out), "--dictionary", str(dpath), "--per-shot", "ml",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["patches"] == 2 * 15 and doc["units"] == "relative"
    lib = reconstruct_per_shot(capture, lfproc.dictionary.load_dictionary(dpath), merges=("ml",))["ml"]
    np.testing.assert_allclose(lfproc.read_lightfield(out).data, lib.data, rtol=1e-5, atol=1e-6 * lib.data.max())
    assert main(["reconstruct", str(cap_path), "-o", str(tmp_path / "x.exr"), "--dictionary", str(dpath),
                 "--per-shot", "median"]) == 2
    assert "merge" in capsys.readouterr().err


def test_recon_method_rules():
    """``auto`` is gmm for a preset with a periodic mask (quick) unless a dictionary is given, dictionary
    otherwise (paper: non-periodic mask); gmm on a non-periodic preset and unknown names are refused."""
    from lfproc.bench.run import recon_method

    quick, paper = PRESETS["quick"], PRESETS["paper"]
    assert quick.mask_period and not paper.mask_period
    assert recon_method("auto", quick) == "gmm" and recon_method("gmm", quick) == "gmm"
    assert recon_method("auto", quick, dictionary_given=True) == "dictionary"
    assert recon_method("auto", paper) == "dictionary" and recon_method("dictionary", quick) == "dictionary"
    with pytest.raises(InputError, match="needs a periodic mask"):
        recon_method("gmm", paper)
    with pytest.raises(InputError, match="method"):
        recon_method("lasso", quick)


@pytest.mark.slow
def test_bench_default_method_is_gmm_and_a_cell_matches_the_public_api(tiny_inputs, tmp_path):
    """The quick preset without a dictionary reconstructs every cell with gmm (``recon_method``); the
    reference joint cell equals simulate -> reconstruct_gmm -> evaluate by hand (the grid's documented
    settings, as _cell_by_hand)."""
    from lfproc.recon import reconstruct_gmm

    root, scenes, _ = tiny_inputs
    result = run_bench(scenes[:1], tmp_path / "b", preset="quick", scheduler="synchronous", report=False,
                       progress_bar=False)
    rows = result["rows"]
    assert rows and {r["recon_method"] for r in rows} == {"gmm"} and result["failed"] == {}
    (ref,) = [r for r in rows if r["method"] == "joint" and r["iso_pattern"] == "random" and r["shots"] == 2
              and r["noise"] == "low" and r["isos"] == "100,400,800,1600" and r["exposure"] == 1]
    lf = lfproc.read_lightfield(scenes[0])
    capture = simulate_capture(lf, profile="paper-low", isos=(100, 400, 800, 1600), exposure_s=0.004, mask="random",
                               mask_period=4, iso_pattern_kind="random", shots=2, relative_exposures=[1.0, 1.0],
                               random_state=int(ref["seed"]))
    expected = evaluate(reconstruct_gmm(capture), lf, scale_tolerance_stops=None)
    assert ref["pu21_psnr_db"] == pytest.approx(expected["pu21_psnr_db"], abs=1e-6)


def test_report_settings_name_the_patch_model_for_gmm_cells():
    """A gmm cell has no solver, mu or dictionary (its results.csv columns are empty): the report's settings say gmm
    and name no dictionary, where they used to print 'solver , mu , at most  iterations'; a dictionary cell keeps
    its solver's settings."""
    from lfproc.bench.report import _settings_section

    meta = {"preset": "quick", "preset_description": "two small scenes", "crop": (48, 48), "mask_period": 4,
            "exposure_s": 0.004, "dictionary": "default:0", "dictionary_patch": (5, 5, 8, 8, 3),
            "dictionary_atoms": 2560, "seed": 0, "lfproc_version": "0", "recon": {}, "scenes": []}
    blank = dict(solver="", mu="", max_iter="", scale="", overlap="", seconds=1.0, cpu_seconds=1.0, scene="a")
    gmm_text = "\n".join(_settings_section([dict(blank, recon_method="gmm")], meta))
    assert "reconstruct_gmm" in gmm_text and "solver ," not in gmm_text and "2560 atoms" not in gmm_text
    dictionary_row = dict(blank, recon_method="dictionary", solver="admm", mu=0.5, max_iter=100, scale="universal",
                          overlap="scale-window-fit")
    dict_text = "\n".join(_settings_section([dictionary_row], meta))
    assert "solver admm, mu 0.5, at most 100 iterations" in dict_text and "2560 atoms" in dict_text
