"""Bad input to the benchmark scripts the docs tell users to run: exit code 2 and one line naming the option or
file, before any scene is made or any dump is read (reference: argparse's own convention, exit code 2)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _run(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCHMARKS / argv[0]), *argv[1:]], capture_output=True, text=True,
                          timeout=120)


@pytest.mark.parametrize("argv, expected", [
    (("reconstruct_realistic.py", "--first-seed", "-1"), "--first-seed: expected a number >= 0, got -1"),
    (("reconstruct_realistic.py", "--seeds", "0"), "--seeds: expected a number of captures >= 1, got 0"),
    (("reconstruct_realistic.py", "--mask-transmittance", "grey"), "argument --mask-transmittance: invalid choice: 'grey'"),
    (("refit_stage.py", "dump", "x", "/tmp/x.pkl", "--mask-transmittance", "grey"),
     "argument --mask-transmittance: invalid choice: 'grey'"),
    (("train_patch_model.py", "--components", "4", "--orientations", "3"),
     "--orientations: expected 0 .. --components - 2 = 2, got 3"),
    (("train_patch_model.py", "--orientations", "-1"), "--orientations: expected 0 .. --components - 2 = 2, got -1"),
    (("refit_stage.py", "run", "/nonexistent/dump.pkl"), "/nonexistent/dump.pkl: not found"),
    (("refit_stage.py", "run", "/nonexistent/dump.pkl", "NOPE=1"), "'NOPE=1': expected NAME=VALUE"),
    (("refit_stage.py", "run", "/nonexistent/dump.pkl", "RATIO=abc"), "expected a number for RATIO, got 'abc'"),
    (("refit_stage.py", "bound", "/nonexistent/dump.pkl", "2", "2", "8"), "/nonexistent/dump.pkl: not found"),
    (("refit_stage.py", "bound", "/nonexistent/dump.pkl", "2", "2", "8", "--disparities", "0.6,a"),
     "--disparities: expected numbers like 0.6 or -1,0.5, got '0.6,a'"),
    (("refit_stage.py", "bound", "/nonexistent/dump.pkl", "2", "2", "8", "--disparities", "nan"),
     "--disparities: expected numbers like 0.6 or -1,0.5, got 'nan'"),
    (("refit_stage.py", "misfit", "/nonexistent/dump.pkl", "/nonexistent/r.npy"), "/nonexistent/dump.pkl: not found"),
    (("refit_stage.py", "misfit", "/nonexistent/dump.pkl", "/nonexistent/r.npy", "--thresholds", "20,a"),
     "--thresholds: expected numbers >= 0 like 20 or 20,8,4, got '20,a'"),
    (("refit_stage.py", "misfit", "/nonexistent/dump.pkl", "/nonexistent/r.npy", "--thresholds=20,-1"),
     "--thresholds: expected numbers >= 0 like 20 or 20,8,4, got '20,-1'"),
    (("prior_ceiling.py", "--crop", "0", "8", "0", "8"), "--crop: expected 0 <= Y0 < Y1 <= 434, 0 <= X0 < X1 <= 625, at"),
    (("prior_ceiling.py", "--crop", "a", "b", "c", "d"), "--crop: expected Y0 Y1 X0 X1 (integers) or 'none', got a b"),
    (("prior_ceiling.py", "--scenes", "nope"), "--scenes: unknown scene 'nope'; expected some of desk-cannon"),
    (("prior_ceiling.py", "--own-components", "0"), "--own-components: expected 1..32, got 0"),
    (("prior_ceiling.py", "--captures", "2 nope"), "--captures: expected names like '2 random'"),
    (("prior_ceiling.py", "--global-disparity", "3"), "--global-disparity: expected an integer in -2..2, got 3"),
    (("prior_ceiling.py", "--global-disparity", "1", "--global-weights", "1"),
     "--global-weights: expected LAM:MU pairs like 0.1:10,1:10, got '1'"),
    (("prior_ceiling.py", "--global-disparity", "1", "--global-weights", "0:1"),
     "--global-weights: expected positive weights, got '0:1'"),
    (("quality_figure.py", "--before", "/nonexistent", "--after", "/nonexistent", "--scenes", "a", "--zoom", "8",
      "--at", "a=1", "-o", "/nonexistent/f.png"), "--at: expected SCENE=Y,X (two integers), got 'a=1'"),
    (("quality_figure.py", "--before", "/nonexistent", "--after", "/nonexistent", "--scenes", "a", "--zoom", "8",
      "--at", "b=1,2", "-o", "/nonexistent/f.png"), "--at: expected a scene of --scenes (a), got 'b'"),
    (("quality_figure.py", "--before", "/nonexistent", "--after", "/nonexistent", "--scenes", "a",
      "--at", "a=1,2", "-o", "/nonexistent/f.png"), "--at: expected with --zoom N"),
    (("quality_figure.py", "--before", "/nonexistent", "--after", "/nonexistent", "--scenes", "a", "--zoom", "8",
      "--white-percentile", "0", "-o", "/nonexistent/f.png"), "--white-percentile: expected a percentile in (0, 100]"),
    (("quality_figure.py", "--before", "/nonexistent", "--after", "/nonexistent", "--scenes", "a",
      "--white-percentile", "99", "-o", "/nonexistent/f.png"), "--white-percentile: expected with --zoom N"),
    (("quality_figure.py", "--before", "/nonexistent", "--after", "/nonexistent", "--scenes", "a",
      "-o", "/nonexistent/f.png"), "/nonexistent/a__truth.npy: expected a result saved by reconstruct_realistic.py"),
])
def test_a_bad_option_or_file_is_one_line_and_exit_code_2(argv, expected):
    done = _run(*argv)
    assert done.returncode == 2
    assert expected in done.stderr.strip().splitlines()[-1]
    assert "Traceback" not in done.stderr and done.stdout == ""


def test_a_damaged_dump_is_one_line_and_exit_code_2(tmp_path):
    """A dump cut short, a pickle of the wrong thing, and one with every key but values of the wrong types and
    shapes, to ``run`` and ``bound`` (refit_stage.py's one reader, Python's pickle; a scratch file, loaded only from
    dumps you made)."""
    import pickle

    import numpy as np

    cut = tmp_path / "cut.pkl"
    cut.write_bytes(pickle.dumps({"T": list(range(1000))})[:50])
    wrong = tmp_path / "wrong.pkl"
    wrong.write_bytes(pickle.dumps({"T": 1}))
    keys = ("T", "W", "W_bound", "capture", "disparities", "first", "margin", "truth")
    types = tmp_path / "types.pkl"
    types.write_bytes(pickle.dumps(dict.fromkeys(keys, 1)))
    shapes = tmp_path / "shapes.pkl"
    shapes.write_bytes(pickle.dumps({**dict.fromkeys(keys, np.zeros((2, 4, 4))), "first": np.zeros((5, 5, 4, 4, 3)),
                                     "truth": np.zeros((5, 5, 4, 4, 3)), "capture": "a capture"}))
    for path, command in [(p, c) for p in (cut, wrong, types, shapes) for c in (["run"], ["bound", "2", "2", "8"])]:
        done = _run("refit_stage.py", command[0], str(path), *command[1:])
        assert done.returncode == 2, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0] and "not a dump" in lines[0]


def test_the_bound_of_a_window_outside_the_margin_is_one_line_and_exit_code_2(tmp_path):
    """refit_stage.py bound on a small dump (a real capture of a synthetic scene, the other arrays zeros): a window
    that leaves the margin is refused in one line; one inside prints a line per disparity, and a pixel no usable
    measurement sees (every weight 0) has no bound (infinite stops: the inverse of zero information)."""
    import pickle

    import numpy as np

    from lfproc.camera.simulate import simulate_capture
    from lfproc.synth import synthesize

    cap = simulate_capture(synthesize("layers", size=(16, 16), random_state=0), shots=2, random_state=0)
    zeros = np.zeros((2, 16, 16))
    lf = np.ones((5, 5, 16, 16, 3))
    path = tmp_path / "small.pkl"
    path.write_bytes(pickle.dumps({"T": zeros, "W": zeros, "W_bound": zeros, "capture": cap, "disparities": (0.0, 1.0),
                                   "first": lf, "margin": 2, "truth": lf}))
    done = _run("refit_stage.py", "bound", str(path), "0", "2", "8")
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "window 0 2 8: expected a window" in lines[0] and "margin 2" in lines[0]
    done = _run("refit_stage.py", "bound", str(path), "2", "2", "8")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 3 and lines[1].strip().startswith("+0.00:") and lines[2].strip().startswith("+1.00:")
    assert "1e0: 64" in lines[0]  # 8 x 8 pixels of truth 1, seen by no usable measurement: no bound
    assert "alone 1e0: inf" in lines[1] and "jointly 1e0: inf" in lines[1]
    grid = lines
    done = _run("refit_stage.py", "bound", str(path), "2", "2", "8", "--disparities", "1,0.5")  # one between the grid's
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 3 and lines[1] == grid[2] and lines[2].strip().startswith("+0.50:")  # +1.00: the grid's own
    done = _run("refit_stage.py", "bound", str(path), "2", "2", "8", "--disparities", "0.5,3")  # margin 2: |d| <= 1
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--disparities: disparity 3: translations of 6 pixels exceed" in lines[0]


def test_misfit_finds_where_a_result_contradicts_the_measurements(tmp_path):
    """refit_stage.py misfit on a noise-free dump made here (measurements Phi x of the truth, by the library's
    operator; every weight 1 / 1 % of the mean measurement): the truth itself misfits nowhere; the truth with a 4 x 4
    block 4 times too bright (every view) is flagged there, too bright, and the truth put back there gives the truth's
    figures (PU21-PSNR inf). A result of the wrong shape is one line and exit code 2."""
    import pickle

    import numpy as np

    from lfproc.camera.projection import build_operator
    from lfproc.camera.simulate import simulate_capture
    from lfproc.synth import synthesize

    lf = synthesize("layers", size=(24, 24), random_state=0)
    cap = simulate_capture(lf, shots=2, random_state=0)
    truth = lf.data.astype(np.float64)
    op = build_operator(cap.mask, views=cap.views, size=cap.size, cfa_pattern=cap.cfa_pattern, dtype=np.float64)
    t = op.forward(truth * cap.radiance_scale)
    w = np.full_like(t, 1.0 / (0.01 * t.mean()))
    path = tmp_path / "small.pkl"
    path.write_bytes(pickle.dumps({"T": t, "W": w, "W_bound": np.zeros_like(t), "capture": cap, "disparities": (0.0,),
                                   "first": truth, "margin": 2, "truth": truth}))
    np.save(tmp_path / "truth.npy", truth)
    wrong = truth.copy()
    wrong[:, :, 10:14, 10:14] *= 4.0
    np.save(tmp_path / "wrong.npy", wrong)
    np.save(tmp_path / "shape.npy", truth[:, :, :8])
    done = _run("refit_stage.py", "misfit", str(path), str(tmp_path / "truth.npy"), "--thresholds", "20")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert "PU21-PSNR inf dB" in lines[0] and "chi-square > 20: 0.0000 of pixels (0.0000 too bright)" in lines[1]
    done = _run("refit_stage.py", "misfit", str(path), str(tmp_path / "wrong.npy"), "--thresholds", "20")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    assert "PU21-PSNR inf dB" not in lines[0]
    flagged, too_bright = map(float, re.search(r"> 20: ([\d.]+) of pixels \(([\d.]+) too bright\)", lines[1]).groups())
    assert 16 / 24 ** 2 <= flagged < 0.5 and too_bright >= 16 / 24 ** 2  # the block and its 5 x 5 neighbourhood
    assert lines[1].count("PU21-PSNR inf dB") == 2  # the truth put back where it misfits: all, and the too bright
    done = _run("refit_stage.py", "misfit", str(path), str(tmp_path / "shape.npy"))
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "shape.npy: expected finite floats of the dump's shape (5, 5, 24, 24, 3)" in lines[0]
    (tmp_path / "empty.npy").write_bytes(b"")
    np.savez(tmp_path / "archive.npz", a=truth)
    for name in ("empty.npy", "archive.npz"):  # numpy's EOFError and an NpzFile: one line each, no traceback
        done = _run("refit_stage.py", "misfit", str(path), str(tmp_path / name))
        assert done.returncode == 2 and done.stdout == "" and "Traceback" not in done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and f"{name}: not a .npy array" in lines[0]


def _prior_ceiling():
    import importlib.util

    sys.path.insert(0, str(BENCHMARKS))
    try:
        spec = importlib.util.spec_from_file_location("prior_ceiling", BENCHMARKS / "prior_ceiling.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCHMARKS))
    return module


def test_the_global_deconvolution_prefers_the_true_disparity_of_a_planted_scene():
    """prior_ceiling.global_deconvolution on a planted Lambertian scene (random 4 x 4 pixel blocks at disparity 1,
    captured by lfproc's simulator without read noise, exposed so that nothing saturates): the shear's adjoint is its
    transpose (reference: the dot-product test); the true disparity explains the blocks better than the opposite one,
    yet even then the median error is about a quarter (measured 0.25 against 0.34): at disparity 1 every measurement
    is a coded sum over 5 x 5 pixels, badly conditioned, which is why classical priors lose to the patch prior."""
    from lfproc import LightField
    from lfproc.camera.simulate import simulate_capture

    pc = _prior_ceiling()
    rng = np.random.default_rng(0)
    c, lf = rng.normal(size=(24, 28, 3)), rng.normal(size=(5, 5, 24, 28, 3))
    assert np.isclose((pc._shear(c, 1, (5, 5)) * lf).sum(), (c * pc._shear_adjoint(lf, 1)).sum())

    centre = np.kron(rng.uniform(0.2, 0.8, (8, 8, 3)), np.ones((4, 4, 1)))
    truth = LightField(pc._shear(centre, 1, (5, 5)).astype(np.float32))
    options = dict(shots=2, profile="paper-none", mask_period=4, random_state=1)
    scale = simulate_capture(truth, **options).radiance_scale  # exposed for the peak at ISO 100
    cap = simulate_capture(truth, radiance_scale=scale / 32, **options)
    assert cap.saturated_fraction() == 0
    inner = (slice(4, -4), slice(4, -4))
    right = np.median(np.abs(pc.global_deconvolution(cap, 1, 1.0, 1.0)[inner] / centre[inner] - 1))
    wrong = np.median(np.abs(pc.global_deconvolution(cap, -1, 1.0, 1.0)[inner] / centre[inner] - 1))
    assert 0.1 < right < 0.3 and wrong > 1.2 * right


def test_no_photograph_of_a_test_scene_is_tuned_on_or_trained_on():
    """The held-out scenes share no photograph with the tune scenes nor with the shipped prior's training
    photographs (reference: the scene tables and the photographs the shipped model file records; stop 31 found the
    test scene sunrise-desk sharing ScanLines_Desk with the tune scene desk-cannon and the training set)."""
    from lfproc.recon._gmm import load_patch_model

    sys.path.insert(0, str(BENCHMARKS))
    try:
        import quality_scenes
    finally:
        sys.path.remove(str(BENCHMARKS))
    photos = {name: set(row[:2]) for name, row in quality_scenes.SETS["all"].items()}
    tuned = set().union(*(photos[name] for name in quality_scenes.TUNE))
    trained = set(load_patch_model().attrs["photographs"])
    assert trained <= tuned
    for name in (*quality_scenes.TEST, *quality_scenes.HOLDOUT):
        assert not photos[name] & tuned, name


def test_a_dump_of_a_small_scene_runs(tmp_path, shared_data):
    """``refit_stage.py dump`` then ``run`` on city-interior at 48 x 64 (its lamp refitted): the dump follows
    ``reconstruct_gmm``'s call of ``refit_lights`` (stop 31 changed that call and the dump failed with a TypeError
    until stop 32); ``run`` prints the first estimate's and the refit's figures. Reference: the dump's own record."""
    import pickle

    dump = tmp_path / "d.pkl"
    env = {"LFPROC_SHARED_DATA": str(shared_data)}
    done = subprocess.run([sys.executable, str(BENCHMARKS / "refit_stage.py"), "dump", "city-interior", str(dump),
                           "--size", "48", "64"], capture_output=True, text=True, timeout=300,
                          env={**os.environ, **env})
    assert done.returncode == 0, done.stderr
    record = pickle.loads(dump.read_bytes())
    assert record["first"].shape == (5, 5, 48, 64, 3) and record["disparities"][0] == -1.0
    done = _run("refit_stage.py", "run", str(dump))
    assert done.returncode == 0, done.stderr
    assert "first: PU21-PSNR" in done.stdout and "refit: PU21-PSNR" in done.stdout


def test_quality_figure_takes_the_after_column_from_another_capture(tmp_path):
    """``--after-capture`` (stop 46) reads the after column from its own capture's file: medium noise against
    noise-free from one ``--save`` folder. Reference: the files written here; a missing one is one line, exit 2."""
    import numpy as np

    rng = np.random.default_rng(0)
    truth = rng.uniform(0.1, 1.0, (5, 5, 12, 12, 3))
    np.save(tmp_path / "s__truth.npy", truth)
    np.save(tmp_path / "s__2_random.npy", truth * 1.1)
    np.save(tmp_path / "s__2_random_none.npy", truth)
    out = tmp_path / "f.png"
    done = _run("quality_figure.py", "--before", str(tmp_path), "--after", str(tmp_path), "--scenes", "s",
                "--after-capture", "2 random none", "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    done = _run("quality_figure.py", "--before", str(tmp_path), "--after", str(tmp_path), "--scenes", "s",
                "--after-capture", "2 random low", "-o", str(tmp_path / "g.png"))
    assert done.returncode == 2 and "s__2_random_low.npy: expected a result" in done.stderr.strip().splitlines()[-1]
    assert not (tmp_path / "g.png").exists()
