"""Joint reconstruction (lfproc.recon): per-phase operators, solvers, Dask, round trips, bad input."""

from __future__ import annotations

from collections import namedtuple

import dataclasses
import json
import re
import zipfile

import numpy as np
import pytest

import lfproc
from lfproc.camera.capture import load_capture, observations
from lfproc.camera.projection import MASK_KINDS, build_operator, make_mask, patch_grid, patch_operators
from lfproc.camera.simulate import auto_radiance_scale, simulate_capture
from lfproc.cli.main import main
from lfproc.dictionary import Dictionary, dct_dictionary, save_dictionary
from lfproc.errors import InputError, ShapeError
from lfproc.recon import DEFAULTS, SOLVERS, reconstruct

VIEWS = (5, 5)


# -- per-phase patch operators ----------------------------------------------------------------

@pytest.mark.parametrize("kind", MASK_KINDS)
@pytest.mark.parametrize("period", [None, 4, pytest.param(3, marks=pytest.mark.slow)])  # fast: aperiodic, period 4
def test_patch_operators_equal_the_operators_patch_matrices(kind, period):
    """The reference is ProjectionOperator.patch_matrix, built from the expanded weights array."""
    size = (21, 19)
    for cfa in ("RGGB", "GBRG"):
        mask = make_mask(kind, shots=2, views=VIEWS, size=size, period=period, random_state=4)
        op = build_operator(mask, views=VIEWS, size=size, cfa_pattern=cfa)
        tops, lefts = patch_grid(size, 9, 4)
        t, l = np.repeat(tops, len(lefts)), np.tile(lefts, len(tops))
        ops = patch_operators(mask, views=VIEWS, cfa_pattern=cfa, tops=t, lefts=l, size=9, sensor_size=size)
        for b in range(len(t)):
            np.testing.assert_array_equal(ops.dense(ops.index[b]), op.patch_matrix(t[b], l[b], 9))
        D = np.random.default_rng(0).standard_normal((ops.shape[1], 5)).astype(np.float32)
        np.testing.assert_allclose(ops.times(D), np.stack([ops.dense(g) @ D for g in range(ops.n_operators)]),
                                   rtol=1e-5, atol=1e-5)
        if period is None:
            assert ops.n_operators == len(t)
        else:  # phases modulo lcm(period, 2): grid phases plus the border row and column
            p = np.lcm(period, 2)
            assert ops.n_operators == len({(a % p, b % p) for a, b in zip(t, l)})


def test_periodic_operators_do_not_grow_with_the_sensor():
    small, large = (4 * 10 + 8, 4 * 10 + 8), (4 * 100 + 8, 4 * 120 + 8)
    counts = []
    for size in (small, large):
        mask = make_mask("random", shots=2, views=VIEWS, size=size, period=4, random_state=1)
        tops, lefts = patch_grid(size, 8, 4)
        ops = patch_operators(mask, views=VIEWS, cfa_pattern="RGGB", tops=np.repeat(tops, len(lefts)),
                              lefts=np.tile(lefts, len(tops)), size=8)
        counts.append((ops.n_operators, ops.vals.nbytes, len(ops.index)))
    assert counts[0][:2] == counts[1][:2] == (1, 1 * 2 * 64 * 25 * 4)
    assert counts[1][2] == 101 * 121


def test_patch_grid_covers_the_sensor():
    tops, lefts = patch_grid((30, 26), 9, 4)
    assert tops.tolist() == [0, 4, 8, 12, 16, 20, 21]
    assert lefts.tolist() == [0, 4, 8, 12, 16, 17]
    with pytest.raises(ShapeError):
        patch_grid((8, 30), 9, 4)


# -- a planted sparse patch ---------------------------------------------------------------------

def _planted(seed=0, k_atoms=300):
    """A 5x5 x 9x9 x 3 patch exactly 10-sparse in a random dictionary (a constant atom plus 9 Gaussian ones).

    Gaussian atoms make Phi D a well-conditioned sensing matrix at 2.67 % sampling (162
    measurements for 300 atoms); the constant atom's coefficient keeps the light field positive.
    """
    rng = np.random.default_rng(seed)
    patch = (5, 5, 9, 9, 3)
    n = int(np.prod(patch))
    atoms = rng.standard_normal((n, k_atoms))
    atoms[:, 0] = 1.0
    atoms /= np.linalg.norm(atoms, axis=0)
    dictionary = Dictionary(atoms=atoms.astype(np.float32), patch=patch, sparsity=10, preset="random")
    code = np.zeros(k_atoms)
    support = rng.choice(np.arange(1, k_atoms), 9, replace=False)
    code[support] = rng.choice([-1.0, 1.0], 9) * (0.5 + rng.random(9))
    varying = dictionary.atoms.astype(np.float64) @ code
    code[0] = 3 * max(-varying.min(), 1e-3) / dictionary.atoms[0, 0]
    lf = lfproc.LightField((dictionary.atoms.astype(np.float64) @ code).reshape(patch).astype(np.float32))
    return dictionary, code, lf


@pytest.fixture(scope="module")
def planted():
    dictionary, code, lf = _planted()
    # noise-free, and a scale that saturates no pixel at the higher ISO (else fewer than 162 measurements)
    scale = 0.5 * auto_radiance_scale(lf.data, profile="paper-none", iso=400, exposure_s=0.004)
    capture = simulate_capture(lf, profile="paper-none", noise=False, shots=2, isos=[100, 400],
                               iso_pattern_kind="random", radiance_scale=scale, random_state=1)
    return dictionary, code, lf, capture


@pytest.mark.parametrize("solver", SOLVERS)
def test_a_10_sparse_patch_is_recovered_from_two_noise_free_shots(planted, solver):
    dictionary, _, lf, capture = planted
    assert capture.sampling_rate == pytest.approx(2 / 75)
    # noise-free data: a weaker l1 weight than the default (1) removes the lasso's shrinkage bias (the data term is
    # the chi-square, huge for noise-free data; a far smaller weight leaves ADMM's l1 drift below the tolerance),
    # and the paper's tolerance (the default stops early, for noisy data); OMP has no weight
    out = reconstruct(capture, dictionary, solver=solver, max_iter=2000, mu=1e-2, tol=2.0**-15)
    err = out.data.astype(np.float64) - lf.data
    psnr = 10 * np.log10(float(lf.data.max()) ** 2 / np.mean(err**2))
    assert psnr >= 50, f"{solver}: {psnr:.1f} dB"
    assert out.units == "relative" and out.shape == lf.shape
    rec = out.attrs["reconstruction"]
    assert rec["solver"] == solver and rec["patches"] == 1 and rec["lfproc_version"] == lfproc.__version__


def test_the_paper_settings_recover_the_planted_patch(planted):
    """The paper-faithful formulation (per-patch data term, plain averages) on the same patch."""
    from lfproc.recon import PAPER

    dictionary, _, lf, capture = planted
    options = dict(PAPER, mu=1e-7, max_iter=2000)
    out = reconstruct(capture, dictionary, **options)
    err = out.data.astype(np.float64) - lf.data
    assert 10 * np.log10(float(lf.data.max()) ** 2 / np.mean(err**2)) >= 50


def test_omp_finds_the_planted_support(planted):
    from lfproc.recon._reconstruct import _gather
    from lfproc.recon._solvers import SharedOperator, omp
    from lfproc.camera.capture import observations

    dictionary, code, _, capture = planted
    obs = observations(capture)
    ops = patch_operators(capture.mask, views=VIEWS, cfa_pattern=capture.cfa_pattern, tops=[0], lefts=[0], size=9)
    y = _gather(obs.radiance, np.array([0]), np.array([0]), 9)
    w = _gather(obs.weight, np.array([0]), np.array([0]), 9)
    z, used = omp(SharedOperator(ops.times(dictionary.atoms)[0]), w, y / y.max(), 10)
    assert set(np.flatnonzero(z[0])) == set(np.flatnonzero(code)) and used[0] == 10


def _lasso_problem():
    rng = np.random.default_rng(3)
    m, k = 60, 120
    A = rng.standard_normal((m, k)).astype(np.float32)
    w = (0.5 + rng.random((2, m))).astype(np.float32)
    w[1, :7] = 0  # unusable measurements
    y = rng.standard_normal((2, m)).astype(np.float32)
    return A, w, y


def _sklearn_lasso(A, w, y, mu):
    """Independent reference: scikit-learn's coordinate-descent Lasso on the same weighted problem
    (its objective divides the data term by m, hence alpha = mu / m)."""
    from sklearn.linear_model import Lasso

    m = A.shape[0]
    return [Lasso(alpha=mu / m, fit_intercept=False, tol=1e-12, max_iter=100000).fit(
        w[b, :, None] * A.astype(np.float64), w[b] * y[b].astype(np.float64)).coef_ for b in range(len(w))]


@pytest.mark.slow  # 40,000 FISTA iterations (FISTA reaches 1e-3 of the optimum only near the end: with numpy
# 2.4.6 / scipy 1.17.1 / scikit-learn 1.9.1, 1.01e-3 after 20,000 and 4.6e-4 after 40,000 on the first problem)
def test_admm_and_fista_reach_the_lasso_optimum():
    from lfproc.recon._solvers import BatchOperator, SharedOperator, admm, fista

    A, w, y = _lasso_problem()
    mu = 0.5
    refs = _sklearn_lasso(A, w, y, mu)
    for op in (SharedOperator(A), BatchOperator(np.stack([A, A]))):
        z_admm, _ = admm(op, w, y, mu, max_iter=3000, tol=1e-7)
        z_fista, _ = fista(op, w, y, mu, max_iter=40000, tol=1e-8)
        for b, ref in enumerate(refs):
            scale = np.linalg.norm(ref)
            assert np.linalg.norm(z_admm[b] - ref) / scale < 1e-3
            assert np.linalg.norm(z_fista[b] - ref) / scale < 1e-3


def test_admm_reaches_the_lasso_optimum():
    """The fast variant: ADMM alone, 1000 iterations (measured 2e-5 of the optimum), same reference."""
    from lfproc.recon._solvers import BatchOperator, SharedOperator, admm

    A, w, y = _lasso_problem()
    refs = _sklearn_lasso(A, w, y, 0.5)
    for op in (SharedOperator(A), BatchOperator(np.stack([A, A]))):
        z, _ = admm(op, w, y, 0.5, max_iter=1000, tol=1e-7)
        for b, ref in enumerate(refs):
            assert np.linalg.norm(z[b] - ref) / np.linalg.norm(ref) < 1e-3


# -- captures of a smooth scene ----------------------------------------------------------------

#: Electrons/s per unit of the smooth scene: its brightest samples stay below saturation at ISO 1600
#: (the automatic scale saturates ISO 100 at the scene's peak, and this scene is almost all peak).
SMOOTH_SCALE = 2.5e3


def _smooth_lf(size=(20, 22)):
    """Smooth, positive, with a little parallax: well represented by a low-frequency DCT dictionary."""
    v, u, y, x = np.meshgrid(np.arange(5), np.arange(5), np.arange(size[0]), np.arange(size[1]), indexing="ij")
    base = 1.0 + 0.5 * np.sin((x + 0.3 * (u - 2)) / 7.0) * np.cos(y / 9.0)
    rgb = np.stack([base, 0.8 * base + 0.1 * y / size[0], 1.2 - 0.4 * base / base.max()], axis=-1)
    return lfproc.LightField(rgb.astype(np.float32) * 5.0)


@pytest.fixture(scope="module")
def small_dictionary():
    return dct_dictionary((5, 5, 8, 8, 3), 200, n_nonzero_coefs=6)


@pytest.fixture(scope="module")
def smooth_capture():
    return simulate_capture(_smooth_lf(), profile="paper-low", shots=2, mask_period=4, random_state=2,
                            radiance_scale=SMOOTH_SCALE)


def test_reconstruction_is_in_the_units_of_the_simulated_light_field(smooth_capture, small_dictionary):
    truth = _smooth_lf()
    out = reconstruct(smooth_capture, small_dictionary, solver="omp")
    assert out.units == "relative"
    ratio = out.data.mean() / truth.data.mean()
    assert 0.9 < ratio < 1.1
    rel = np.abs(out.data - truth.data).mean() / truth.data.mean()
    assert rel < 0.1
    # a real capture (no radiance scale) comes out in e-/s: the same numbers times the scale
    real = dataclasses.replace(smooth_capture, radiance_scale=None)
    out_e = reconstruct(real, small_dictionary, solver="omp")
    assert out_e.units == "e-/s"
    np.testing.assert_allclose(out_e.data / smooth_capture.radiance_scale, out.data, rtol=1e-4,
                               atol=1e-6 * out.data.max())


def test_reconstruct_does_not_mutate_its_inputs(smooth_capture, small_dictionary):
    dn, codes, atoms = smooth_capture.dn.copy(), smooth_capture.mask.codes.copy(), small_dictionary.atoms.copy()
    reconstruct(smooth_capture, small_dictionary, solver="fista", max_iter=5)
    assert np.array_equal(dn, smooth_capture.dn) and np.array_equal(codes, smooth_capture.mask.codes)
    assert np.array_equal(atoms, small_dictionary.atoms)


@pytest.mark.parametrize("options", [dict(iso_pattern_kind="row", shots=1), dict(baseline="bracketing", shots=3),
                                     dict(baseline="individual-iso", isos=[100, 1600]),
                                     dict(mask="shifted", mask_period=None, shots=2)])
def test_every_capture_kind_reconstructs(small_dictionary, options):
    truth = _smooth_lf((16, 16))
    capture = simulate_capture(truth, profile="paper-low", random_state=5, radiance_scale=SMOOTH_SCALE, **options)
    out = reconstruct(capture, small_dictionary, solver="omp", stride=4)
    assert out.shape == truth.shape
    assert 0.8 < out.data.mean() / truth.data.mean() < 1.25


def test_block_layout_changes_nothing_but_rounding(smooth_capture, small_dictionary):
    a = reconstruct(smooth_capture, small_dictionary, solver="omp", block_patches=5)
    b = reconstruct(smooth_capture, small_dictionary, solver="omp", block_patches=10_000)
    np.testing.assert_allclose(a.data, b.data, rtol=1e-4, atol=1e-6 * a.data.max())


@pytest.fixture(scope="module")
def dask_scheduler():
    import logging

    from dask.distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    yield cluster.scheduler_address
    cluster.close()


def test_arrays_a_worker_receives_at_any_offset_are_realigned():
    """Dask hands a worker arrays at any byte offset (measured: 7); numpy's matmul skips BLAS for them and
    sums in another order, so they are copied to an aligned buffer first; aligned ones are not copied."""
    from lfproc._shared.parallel import realign

    raw = bytearray(4 * 12 + 1)
    odd = np.frombuffer(raw, dtype=np.float32, count=12, offset=1).reshape(3, 4)
    assert odd.ctypes.data % 16 and not odd.flags.aligned
    ok = np.arange(12.0, dtype=np.float32).reshape(3, 4)
    out = realign({"task": [odd, (ok, 3)], "x": "keep"})
    moved, (same, three) = out["task"][0], out["task"][1]
    assert moved.ctypes.data % 16 == 0 and moved.flags.aligned and np.array_equal(moved, odd)
    assert same is ok and three == 3 and out["x"] == "keep"
    Pair = namedtuple("Pair", "a b")  # a named tuple (the lights refit's windows) keeps its type
    pair = realign(Pair(odd, 2))
    assert isinstance(pair, Pair) and pair.a.ctypes.data % 16 == 0 and np.array_equal(pair.a, odd) and pair.b == 2


@pytest.mark.parametrize("source, expected", [
    ('import lfproc\n\nif __name__ == "__main__":\n    lfproc.main()\n', True),
    ("if '__main__' == __name__:\n    pass\n", True),
    ("import lfproc\nlfproc.reconstruct_gmm(None)\n", False),  # a script without the guard
    ("def f():\n    if __name__ == '__main__':\n        pass\n", False),  # not at the top level
    ("if __name__ == '__mp_main__':\n    pass\n", False),
    ("this is not python\n", False),
])
def test_worker_processes_start_only_where_the_callers_script_is_guarded(tmp_path, monkeypatch, source, expected):
    """A forkserver or spawn worker imports the main module: lfproc starts processes only where that does not run
    the caller's script again (a top-level ``if __name__ == "__main__":``), or where there is no main file (a
    notebook, ``python -c``) or the main module is a package's ``__main__`` (``python -m``, not imported); never in a
    daemonic process (a Dask worker may not start children)."""
    import sys
    import types

    from lfproc._shared import parallel

    script = tmp_path / "script.py"  # a directory of its own per case: _guarded caches by path
    script.write_text(source, encoding="utf-8")
    main = types.ModuleType("__main__")
    main.__file__, main.__spec__ = str(script), None
    monkeypatch.setitem(sys.modules, "__main__", main)
    assert parallel.can_start_processes() is expected
    del main.__file__  # an interactive session
    assert parallel.can_start_processes() is True
    main.__spec__ = types.SimpleNamespace(name="pytest.__main__")  # python -m pytest
    assert parallel.can_start_processes() is True
    main.__spec__ = types.SimpleNamespace(name="myscript")  # python -m myscript: imported again as __mp_main__
    assert parallel.can_start_processes() is False
    main.__spec__ = None  # an interactive session again, but in a daemonic process (a Dask worker): no children
    monkeypatch.setattr(parallel.multiprocessing, "current_process", lambda: types.SimpleNamespace(daemon=True))
    assert parallel.can_start_processes() is False


@pytest.mark.slow  # a Dask cluster
@pytest.mark.parametrize("period, solver", [(4, "admm"), (None, "fista"), (4, "fista"), (4, "omp")])
def test_dask_and_in_process_reconstructions_are_identical(dask_scheduler, small_dictionary, period, solver):
    capture = simulate_capture(_smooth_lf((20, 22)), profile="paper-medium", shots=2, mask_period=period,
                               random_state=7, radiance_scale=SMOOTH_SCALE)
    options = dict(solver=solver, max_iter=30, block_patches=12)
    here = reconstruct(capture, small_dictionary, **options)
    there = reconstruct(capture, small_dictionary, scheduler=dask_scheduler, **options)
    assert np.array_equal(here.data, there.data)
    assert here.attrs["reconstruction"]["patches"] == 20 and there.attrs["reconstruction"]["scheduler"] == dask_scheduler


# -- the command line --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def files(tmp_path_factory, smooth_capture, small_dictionary):
    root = tmp_path_factory.mktemp("recon")
    truth = root / "truth.exr"
    lfproc.write_lightfield(_smooth_lf(), truth)
    capture = root / "shot.capture.npz"
    from lfproc.camera.simulate import simulate_file

    simulate_file(truth, capture, profile="paper-low", shots=2, mask_period=4, random_state=2,
                  radiance_scale=SMOOTH_SCALE)
    dictionary = root / "dct.npz"
    save_dictionary(small_dictionary, dictionary)
    return root, truth, capture, dictionary


def test_simulate_reconstruct_evaluate_round_trip(files, capsys):
    root, truth, capture, dictionary = files
    out = root / "out.exr"
    assert main(["reconstruct", str(capture), "-o", str(out), "--dictionary", str(dictionary), "--solver", "admm",
                 "--max-iter", "50", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["patches"] == 20 and summary["solver"] == "admm" and summary["seconds"] > 0
    assert summary["dictionary"] == str(dictionary)
    assert main(["evaluate", str(out), str(truth), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out)
    assert scores["pu21_psnr_db"] > 30, scores["pu21_psnr_db"]
    lf = lfproc.read_lightfield(out)
    rec = lf.attrs["reconstruction"]
    assert rec["mu"] == DEFAULTS["mu"] and rec["stride"] == 4 and rec["lfproc_version"] == lfproc.__version__
    # no overwrite without --force
    assert main(["reconstruct", str(capture), "-o", str(out), "--dictionary", str(dictionary)]) == 2
    assert "exists" in capsys.readouterr().err


def _bad_capture_all_saturated(capture_path, root):
    capture = load_capture(capture_path)
    dn = np.full_like(capture.dn, int(capture.profile.white_level_dn))
    bad = dataclasses.replace(capture, dn=dn)
    path = root / "saturated.capture.npz"
    bad.save(path, force=True)
    return path


@pytest.mark.parametrize("case", ["views", "colours", "weights", "stride", "solver", "variance", "corrupt-capture",
                                  "corrupt-dictionary", "missing-default"])
def test_bad_input_gets_one_line_and_exit_2(files, capsys, case, tmp_path):
    root, _, capture, dictionary = files
    out = tmp_path / "out.exr"
    args = ["reconstruct", str(capture), "-o", str(out), "--dictionary", str(dictionary)]
    expect = {
        "views": "3 x 3",
        "colours": "3 colours",
        "weights": "weight zero",
        "stride": "stride",
        "solver": "solver",
        "variance": "variance: expected one of local, measurement; got 'bogus'",
        "corrupt-capture": "capture",
        "corrupt-dictionary": "bad.npz",
        "missing-default": "default",
    }[case]
    if case in ("views", "colours"):
        patch = (3, 3, 8, 8, 3) if case == "views" else (5, 5, 8, 8, 1)
        other = tmp_path / "other.npz"
        save_dictionary(dct_dictionary(patch, 50), other)
        args[5] = str(other)
        expect = "5 x 5 views and 3 colours"
    elif case == "weights":
        args[1] = str(_bad_capture_all_saturated(capture, tmp_path))
    elif case == "stride":
        args += ["--stride", "9"]
    elif case == "solver":
        args += ["--solver", "lbfgs"]
    elif case == "variance":
        args += ["--variance", "bogus"]
    elif case == "corrupt-capture":
        bad = tmp_path / "bad.capture.npz"
        bad.write_bytes(b"PK\x03\x04" + b"\x00" * 100)
        args[1] = str(bad)
    elif case == "corrupt-dictionary":
        bad = tmp_path / "bad.npz"
        with zipfile.ZipFile(bad, "w") as zf:
            zf.writestr("lfproc-dictionary.json", "{not json")
        args[5] = str(bad)
    elif case == "missing-default":
        from lfproc.dictionary._files import shipped_path

        if shipped_path("default").is_file():
            pytest.skip("the default dictionary is shipped in this installation")
        args = args[:4]
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2
    # warnings (e.g. the saturated capture's) may precede the one error line
    lines = [line for line in err.strip().splitlines() if not line.startswith("lfproc reconstruct: warning:")]
    assert len(lines) == 1 and lines[0].startswith("lfproc reconstruct: error:"), err
    assert expect in lines[0], lines[0]
    assert not out.exists()


def test_api_bad_options(smooth_capture, small_dictionary):
    with pytest.raises(InputError, match="solver"):
        reconstruct(smooth_capture, small_dictionary, solver="cg")
    with pytest.raises(InputError, match="stride"):
        reconstruct(smooth_capture, small_dictionary, stride=0)
    with pytest.raises(InputError, match="mu"):
        reconstruct(smooth_capture, small_dictionary, mu=-1)
    with pytest.raises(InputError, match="max_iter"):
        reconstruct(smooth_capture, small_dictionary, max_iter=0)
    with pytest.raises(ShapeError, match="sensor"):
        reconstruct(simulate_capture(_smooth_lf((6, 30)), profile="paper-low", random_state=1), small_dictionary)


# -- quality on an HDR-photo-textured scene the dictionary never saw ------------------------------

@pytest.mark.slow  # 96 x 96 reconstructions
def test_two_shots_beat_one_on_a_textured_hdr_scene(shared_data):
    """The shipped dictionary (trained on procedural scenes only) on a scene textured with an HDR photograph.

    Measured with the defaults (scale "universal", mu 0.5, 100 iterations, photon variance from the
    neighbours): 2 shots 21.76 dB, 1 shot 21.46 dB PU21-PSNR at 96 x 96 (with the defaults of the previous
    stop 21.85 / 21.68; at the Lytro size the README's table). The ISO pattern's effect (random/row vs block) is within the capture-to-capture spread at this
    size and is not asserted (README).
    """
    from lfproc.dictionary import load_dictionary
    from lfproc.dictionary._files import shipped_path
    from lfproc.metrics import evaluate
    from lfproc.synth import synthesize

    texture = shared_data / "hdr" / "ScanLines_Desk.exr"
    if not texture.is_file() or not shipped_path("default").is_file():
        pytest.skip("needs the shared HDR photographs and the shipped default dictionary")
    dictionary = load_dictionary("default")
    lf = synthesize("layers", size=(96, 96), views=5, textures=[texture], random_state=11)
    scores = {}
    # no warning expected (warnings are errors in this suite): not more than 10 % of the ISO-100
    # pixels saturate (a catch-all filter here used to hide any warning)
    for shots in (1, 2):
        capture = simulate_capture(lf, profile="paper-medium", shots=shots, iso_pattern_kind="random",
                                   mask_period=4, random_state=11)
        scores[shots] = evaluate(reconstruct(capture, dictionary), lf)["pu21_psnr_db"]
    assert scores[2] > scores[1] + 0.1, scores
    assert scores[1] > 21.0, scores


def test_new_options_are_checked_and_recorded(smooth_capture, small_dictionary, tmp_path, capsys):
    with pytest.raises(InputError, match="overlap"):
        reconstruct(smooth_capture, small_dictionary, overlap="median")
    with pytest.raises(InputError, match="scale"):
        reconstruct(smooth_capture, small_dictionary, scale="log")
    with pytest.raises(InputError, match="threads"):
        reconstruct(smooth_capture, small_dictionary, threads=0)
    with pytest.raises(InputError, match="debias"):
        reconstruct(smooth_capture, small_dictionary, debias=-1)
    with pytest.raises(InputError, match="variance"):
        reconstruct(smooth_capture, small_dictionary, variance="estimate")
    # threads change nothing (one-thread BLAS per block, blocks added in order)
    one = reconstruct(smooth_capture, small_dictionary, threads=1, block_patches=6)
    two = reconstruct(smooth_capture, small_dictionary, threads=2, block_patches=6)
    assert np.array_equal(one.data, two.data)
    rec = one.attrs["reconstruction"]
    assert (rec["scale"], rec["overlap"], rec["variance"], rec["mu"], rec["max_iter"], rec["tol"]) == (
        "universal", "scale-window-fit", "local", 0.5, 100, 1e-3)
    # the record is what ran: with no option given, the library's DEFAULTS (before: DEFAULTS["mu"] against
    # its own literal)
    expected = {k: DEFAULTS[k][rec["solver"]] if isinstance(DEFAULTS[k], dict) else DEFAULTS[k]
                for k in ("scale", "overlap", "variance", "mu", "max_iter", "tol")}
    assert {k: rec[k] for k in expected} == expected


@pytest.mark.slow  # a 2000-measurement chi-square
def test_fit_weights_use_the_reduced_chi_square_of_each_patch():
    """The overlap weight of a patch falls as 1 / (reduced chi-square) once its fit is worse than the noise.

    Statistics: with every code shrunk to zero (a huge l1 weight) the residual is the data, here pure
    noise of the weights' standard deviation, so the reduced chi-square is 1 within sqrt(2/m)."""
    from lfproc.recon._reconstruct import _overlap_weights, _Settings, _solve_group
    from lfproc.recon._solvers import SharedOperator

    rng = np.random.default_rng(3)
    m, k, n = 2000, 40, 64
    op = SharedOperator(rng.standard_normal((m, k)).astype(np.float32))
    sigma = rng.uniform(0.5, 2.0, (3, m))
    y = (sigma * rng.standard_normal((3, m)) + 1e-3).astype(np.float32)
    settings = _Settings(solver="admm", mu=1e9, max_iter=20, tol=1e-3, sparsity=5, scale="noise",
                         overlap="scale-window-fit", c_global=1.0, w_global=1.0)
    codes, _, _, chi2 = _solve_group(op, y, (1 / sigma).astype(np.float32), np.ones((1, m)), settings, n)
    assert not codes.any()
    np.testing.assert_allclose(chi2, 1.0, atol=4 * np.sqrt(2 / m))
    # known answer: equal scales, fits of 0.5, 1 and 4 times the noise -> weights 1 : 1 : 1/4 at every pixel
    w = _overlap_weights("scale-window-fit", np.ones(3), 4, np.array([0.5, 1.0, 4.0]))
    np.testing.assert_allclose(w[1] / w[0], 1.0)
    np.testing.assert_allclose(w[2] / w[0], 0.25, rtol=1e-6)
    assert _overlap_weights("scale-window", np.ones(3), 4).shape == (3, 4, 4)


@pytest.mark.slow  # three 48 x 48 reconstructions
def test_a_dark_floor_beside_a_bright_light_is_not_shrunk_away():
    """Known answer: a flat floor of level 1 beside a light 12 stops brighter, about 5 electrons per
    pixel and shot on the floor. The defaults keep the floor (measured 0.92 of its level). The
    plug-in photon variance (``variance="measurement"``, the defaults of the previous stop) weighs
    the measurements that fell low more and brings it to 0.80, the light to 0.27 of its level
    (0.58 with the defaults); the scale of the stop before ("noise": shrinkage ~ mu / SNR^2 of a
    single measurement) lost most of the floor (0.39)."""
    from lfproc.camera.capture import observations

    data = np.ones((5, 5, 48, 48, 3), np.float32)
    data[:, :, 40:46, 40:46] = 2.0**12
    # the light saturates some high-ISO pixels, far fewer than 10 % of the ISO-100 ones: no warning
    # (warnings are errors in this suite)
    # uniform codes, as measured (with mixed codes the older scale's floor comes back at 0.503, not below 0.5)
    capture = simulate_capture(lfproc.LightField(data, units="relative"), profile="paper-medium", shots=2,
                               iso_pattern_kind="random", mask_period=4, random_state=3, mask_transmittance="uniform")
    obs = observations(capture)
    assert 0 < obs.saturated_fraction < 0.1
    electrons = obs.radiance[:, :30, :30].mean() * capture.exposures_s[0]
    assert 3 < electrons < 8
    out = reconstruct(capture)
    plug_in = reconstruct(capture, variance="measurement", mu=0.25)
    old = reconstruct(capture, scale="noise", mu=1.0, max_iter=50, tol=1e-2, variance="measurement")
    floor = out.data[:, :, 4:30, 4:30].mean()
    assert 0.85 < floor < 1.1, floor
    assert plug_in.data[:, :, 4:30, 4:30].mean() < floor - 0.05
    assert old.data[:, :, 4:30, 4:30].mean() < 0.5
    light = out.data[:, :, 41:45, 41:45].mean() / 2.0**12
    assert light > 1.5 * plug_in.data[:, :, 41:45, 41:45].mean() / 2.0**12 and light < 1.1, light


def test_cli_paper_settings(files, capsys, tmp_path):
    from lfproc.recon import PAPER

    _, _, capture, dictionary = files
    out = tmp_path / "paper.exr"
    assert main(["reconstruct", str(capture), "-o", str(out), "--dictionary", str(dictionary), "--paper",
                 "--max-iter", "40", "--json"]) == 0
    capsys.readouterr()
    rec = lfproc.read_lightfield(out).attrs["reconstruction"]
    assert (rec["scale"], rec["overlap"], rec["mu"], rec["tol"]) == (PAPER["scale"], PAPER["overlap"], PAPER["mu"],
                                                                     PAPER["tol"])
    assert rec["max_iter"] == 40  # an explicit option wins over --paper


@pytest.mark.parametrize("kind", MASK_KINDS)
def test_grouped_operator_product_equals_the_gather_form(kind):
    """The non-periodic path's Phi_b D (one GEMM per patch pixel) against PatchOperators.times (a gather per view)."""
    from lfproc.recon._reconstruct import _operator_times

    size = (21, 19)
    atoms = dct_dictionary((5, 5, 8, 8, 3), 150).atoms.astype(np.float32)
    by_pixel = np.ascontiguousarray(atoms.reshape(25, 192, -1).transpose(1, 0, 2))
    for cfa in ("RGGB", "GBRG"):
        mask = make_mask(kind, shots=2, views=VIEWS, size=size, period=None, random_state=4)
        tops, lefts = patch_grid(size, 8, 4)
        ops = patch_operators(mask, views=VIEWS, cfa_pattern=cfa, tops=np.repeat(tops, len(lefts)),
                              lefts=np.tile(lefts, len(tops)), size=8, sensor_size=size)
        sel = np.arange(ops.n_operators)[1:]
        np.testing.assert_allclose(_operator_times(ops, sel, atoms, by_pixel), ops.times(atoms, sel),
                                   rtol=1e-5, atol=1e-6)


def test_a_noise_free_sensor_on_a_mostly_black_scene_is_not_returned_black(small_dictionary):
    """Regression (the quick bench's noise level "none" scored 3.6 dB low): on a sensor without read
    noise or dark current most measurements of a dark scene are exactly 0, their median was 0, and the
    overlap weights 1 / (c_p / median)^2 underflowed to 0 everywhere: the output was black. Known answer
    (a short exposure, so the lit square does not saturate): its level, 1 (measured 0.993 with both
    profiles; before the fix 0 with "none")."""
    data = np.zeros((5, 5, 32, 32, 3), np.float32)
    data[:, :, 8:24, 8:24] = 1.0
    lf = lfproc.LightField(data, units="relative")
    levels = {}
    for profile in ("paper-none", "paper-low"):  # nothing saturates: no warning (they are errors here)
        cap = simulate_capture(lf, profile=profile, shots=2, mask_period=4, random_state=4, exposure_s=0.0005)
        levels[profile] = reconstruct(cap, small_dictionary).data[:, :, 12:20, 12:20].mean()
    assert all(0.95 < v < 1.05 for v in levels.values()), levels


def test_view_mismatch_message_says_which_side_has_which():
    rng = np.random.default_rng(0)
    lf3 = np.broadcast_to(0.1 + rng.random((1, 1, 16, 16, 3), dtype=np.float32), (3, 3, 16, 16, 3)).copy()
    # uniform codes: with mixed codes this capture saturates 11.7 % at ISO 100 and warns (warnings are errors here)
    capture = simulate_capture(lf3, profile="paper-low", random_state=0, mask_transmittance="uniform")
    with pytest.raises(ShapeError) as info:
        reconstruct(capture, "default")
    message = str(info.value)
    assert "dictionary 'default' has 5 x 5 views and 3 colours" in message
    assert "the capture has 3 x 3 views" in message


# -- BLAS threads, factors, empty patches (issue 19) ---------------------------------------------

def _blas_threads():
    from threadpoolctl import threadpool_info

    return [(i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_limit_around_the_pool_and_outputs_identical_for_any_thread_count(smooth_capture,
                                                                                   small_dictionary, monkeypatch):
    """threadpoolctl changes the BLAS state of the whole process and is not thread-safe: the limit is set once
    around the pool (not per block, where overlapping enter/exit pairs restored the wrong count), every block
    runs on one BLAS thread, the process's BLAS thread count is the same after reconstruct, and the output does
    not depend on the number of threads."""
    import threadpoolctl

    import lfproc.recon._reconstruct as rr

    before = _blas_threads()
    entered = []
    seen = []
    real_limits, real_block = threadpoolctl.threadpool_limits, rr._solve_block_here

    def counting_limits(*args, **kwargs):
        entered.append(args)
        return real_limits(*args, **kwargs)

    def block(task, shared):
        seen.append({n for _, n in _blas_threads()})
        return real_block(task, shared)

    monkeypatch.setattr(threadpoolctl, "threadpool_limits", counting_limits)
    monkeypatch.setattr(rr, "threadpool_limits", counting_limits)
    monkeypatch.setattr(rr, "_solve_block_here", block)
    outs = {t: reconstruct(smooth_capture, small_dictionary, max_iter=20, block_patches=4, threads=t).data
            for t in (1, 2, 4)}
    assert np.array_equal(outs[1], outs[2]) and np.array_equal(outs[1], outs[4])
    assert len(seen) >= 3 * 3 and all(s == {1} for s in seen)
    assert len(entered) <= 2 * 3  # per reconstruction: the pool, and the factors of the phases (not per block)
    assert _blas_threads() == before


def test_the_admm_factor_of_a_phase_is_built_once_per_reconstruction(smooth_capture, small_dictionary, monkeypatch):
    from lfproc.recon import _solvers

    built = []
    real = _solvers._Factor.build.__func__

    def counting(cls, gram):
        built.append(np.shape(gram))
        return real(cls, gram)

    monkeypatch.setattr(_solvers._Factor, "build", classmethod(counting))
    out = reconstruct(smooth_capture, small_dictionary, max_iter=10, block_patches=4, threads=1)
    phases = out.attrs["reconstruction"]["operators"]
    assert len(built) == phases < out.attrs["reconstruction"]["patches"]


def test_patches_without_a_usable_measurement_are_left_out_of_the_plain_mean(small_dictionary):
    """Known answer: a flat scene (level 1, the dictionary's constant atom, noise-free) with a square 2^14
    brighter that saturates every shot. The patches inside the square have no usable measurement; the patches
    that overlap it fit the flat level from their unsaturated pixels and extrapolate it. With the paper's plain
    mean, the pixels of the square covered by both had the empty patches averaged in as zeros (0.25-0.75 of
    the level); left out, every pixel covered by a non-empty patch is at the level, and the pixels covered by
    empty patches only are 0 (nothing was measured there)."""
    from lfproc.errors import SaturationWarning

    data = np.ones((5, 5, 32, 32, 3), np.float32)
    data[:, :, 8:24, 8:24] = 2.0**14
    # the square saturates every shot: the capture warns where it is made and again where it is
    # reconstructed (reconstruct reads its observations); only that warning, and with its share
    expected = r"capture: (\d+\.\d) % of the least sensitive pixels \(ISO 100 at 0\.004 s\) are saturated"
    with pytest.warns(SaturationWarning, match=expected) as made:
        cap = simulate_capture(lfproc.LightField(data, units="relative"), profile="paper-none", noise=False,
                               shots=2, mask_period=4, random_state=4, radiance_scale=SMOOTH_SCALE)
    with pytest.warns(SaturationWarning, match=expected) as solved:
        out = reconstruct(cap, small_dictionary, solver="omp", n_nonzero_coefs=1, overlap="mean", scale="patch").data
    assert len(made) == len(solved) == 1 and str(made[0].message) == str(solved[0].message)
    share = observations(cap, warn_saturation=False).saturated[cap.iso == 100].mean()  # the ISO-100 pixels' share
    assert float(re.match(expected, str(made[0].message)).group(1)) == pytest.approx(100 * share, abs=0.05)
    assert 0.2 < share < 0.4  # the square is a quarter of the pixels; the ISO-100 ones are a random quarter
    rec_empty = np.zeros((32, 32), bool)
    rec_empty[12:20, 12:20] = True  # covered by the empty patches (tops and lefts 8, 12, 16) only
    level = out.mean(axis=(0, 1, 4))
    assert out.max() > 0.5
    np.testing.assert_allclose(level[~rec_empty], 1.0, rtol=0.03)
    assert not level[rec_empty].any()


def _lsq_problem(seed=5, m=60, k=120, b=3):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((m, k)).astype(np.float32)
    w = (0.5 + rng.random((b, m))).astype(np.float32)
    y = rng.standard_normal((b, m)).astype(np.float32)
    return A, w, y


@pytest.mark.parametrize("mu", [0.0, 1e-30])
def test_admm_with_mu_0_solves_the_weighted_least_squares_problem(mu):
    """mu = 0 (and a threshold below float32's resolution) is weighted least squares: with m < K and positive
    weights ADMM started from 0 reaches the minimum-norm solution. Before: the threshold floored at 1e-30 and
    the state kept in its units overflowed float32 (inf norms), every patch "converged" after 5 iterations
    with a weighted residual of 1.41."""
    from lfproc.recon._solvers import BatchOperator, SharedOperator, admm

    A, w, y = _lsq_problem()
    for op in (SharedOperator(A), BatchOperator(np.stack([A] * 3))):
        z, it = admm(op, w, y, mu, max_iter=3000, tol=1e-6)
        assert np.isfinite(z).all() and (it > 5).all()
        for b in range(3):
            wa = w[b, :, None].astype(np.float64) * A
            ref = np.linalg.pinv(wa) @ (w[b] * y[b].astype(np.float64))
            assert np.linalg.norm(wa @ z[b] - w[b] * y[b]) < 1e-3 * np.linalg.norm(w[b] * y[b])
            assert np.linalg.norm(z[b] - ref) < 1e-3 * np.linalg.norm(ref)


def test_admm_stops_at_once_when_the_code_is_zero_and_soon_when_it_is_small():
    """Relative plus absolute stopping (Boyd et al. 2011, 3.3.1). A mu above ||A^T W^2 y||_inf makes 0 the exact
    answer: 0 iterations (before: 300 of 300, a zero code never passed the relative test). Just below it the
    code is tiny and nonzero: it stops well before max_iter, within tolerance of the optimum."""
    from lfproc.recon._solvers import SharedOperator, admm

    A, w, y = _lsq_problem(seed=6)
    op = SharedOperator(A)
    lam = np.abs((w * w * y) @ A).max(axis=1)
    z, it = admm(op, w, y, 1.5 * lam, max_iter=300, tol=2.0**-15)
    assert not z.any() and not it.any()
    z, it = admm(op, w, y, 0.999 * lam, max_iter=300, tol=1e-3)
    assert z.any() and (it < 300).all()


def test_admm_norms_do_not_overflow_for_large_data():
    """Data of 1e20 (squares overflow float32): the same codes, scaled, as for data of 1."""
    from lfproc.recon._solvers import SharedOperator, admm

    A, w, y = _lsq_problem(seed=7)
    op = SharedOperator(A)
    z1, it1 = admm(op, w, y, 0.5, max_iter=500, tol=1e-5)
    zb, itb = admm(op, w, y * np.float32(1e20), 0.5e20, max_iter=500, tol=1e-5)
    assert np.isfinite(zb).all()
    np.testing.assert_allclose(zb / 1e20, z1, rtol=1e-3, atol=1e-4 * np.abs(z1).max())


def test_adjoint_into_an_array_is_the_gemm_for_both_operators():
    """SharedOperator.adj_t (numpy's GEMM into the output, GIL released) and BatchOperator.adj_t (one matrix per
    patch) against numpy's float64 product: ``A^T e_b`` for every column."""
    from lfproc.recon._solvers import BatchOperator, SharedOperator

    rng = np.random.default_rng(4)
    for m, k, b in ((128, 2560, 117), (60, 120, 5)):
        a = rng.standard_normal((m, k)).astype(np.float32)
        E = rng.standard_normal((m, b)).astype(np.float32)
        ref = a.astype(np.float64).T @ E.astype(np.float64)
        for op in (SharedOperator(a), BatchOperator(np.broadcast_to(a, (b, m, k)))):
            out = rng.standard_normal((k, b)).astype(np.float32)  # overwritten, not added to
            op.adj_t(E, out)
            np.testing.assert_allclose(out, ref, rtol=0, atol=1e-5 * np.abs(ref).max())


def test_compiled_z_u_step_equals_numpy():
    """admm's compiled z and dual step against the numpy steps it replaced: x = z + (1 - alpha) u + g,
    u = clip(x, -1, 1) (0 in a threshold-0 column), z = x - u, v = z - u; float32, in place; with check, the
    squared column norms of the changes of z and u and of the new z (numpy's, in float64)."""
    from lfproc.recon._solvers import _z_u_step

    rng = np.random.default_rng(5)
    lim = np.array([1, 1, 0, 1, 1, 1, 0], np.float32)
    a = np.float32(1 - 1.6)
    for check in (False, True):
        z, u, g = (rng.standard_normal((300, 7)).astype(np.float32) * 2 for _ in range(3))
        z0, u0 = z.copy(), u.copy()
        x = z + a * u + g
        u_ref = np.clip(x, -1, 1) * lim
        z_ref = x - u_ref
        v, stats = np.empty_like(z), np.zeros((3, 7))
        _z_u_step(z, u, g, lim, a, v, stats, check)
        tol = dict(rtol=0, atol=4 * np.finfo(np.float32).eps * np.abs(x).max())
        np.testing.assert_allclose(u, u_ref, **tol)
        np.testing.assert_allclose(z, z_ref, **tol)
        np.testing.assert_allclose(v, z_ref - u_ref, **tol)
        assert (u[:, lim == 0] == 0).all() and np.abs(u).max() <= 1
        on = lim == 1
        assert ((np.abs(x[:, on]) <= 1) == (z[:, on] == 0)).mean() > 0.99  # inside the threshold the code is 0
        want = [((z.astype(np.float64) - z0) ** 2).sum(0), ((u.astype(np.float64) - u0) ** 2).sum(0),
                (z.astype(np.float64) ** 2).sum(0)] if check else np.zeros((3, 7))
        np.testing.assert_allclose(stats, want, rtol=1e-6)


def test_compiled_measurement_side_steps_equal_numpy():
    """admm's compiled (m, B) steps against the numpy expressions they replaced: t *= unit, r = s - d - t; then
    h = alpha (t + q) + (1 - alpha) s + d, s = (w2y + rb h) / denom, d = h - s (float32, in place)."""
    from lfproc.recon._solvers import _s_d_step, _scale_residual

    rng = np.random.default_rng(6)
    t, s, d, q, w2y = (rng.standard_normal((40, 9)).astype(np.float32) for _ in range(5))
    unit, rb = rng.uniform(0.5, 2, 9).astype(np.float32), rng.uniform(0.5, 2, 9).astype(np.float32)
    denom = rng.uniform(1, 3, (40, 9)).astype(np.float32)
    alpha = np.float32(1.6)
    t_ref = t * unit
    r_ref = s - d - t_ref
    h = alpha * (t_ref + q) + (1 - alpha) * s + d
    s_ref = (w2y + rb * h) / denom
    d_ref = h - s_ref
    r = np.empty_like(s)
    _scale_residual(t, s, d, unit, r)
    tol = dict(rtol=0, atol=1e-5)
    np.testing.assert_allclose(t, t_ref, **tol)
    np.testing.assert_allclose(r, r_ref, **tol)
    _s_d_step(t, q, s, d, w2y, rb, denom, alpha)
    np.testing.assert_allclose(s, s_ref, **tol)
    np.testing.assert_allclose(d, d_ref, **tol)


@pytest.mark.parametrize("stride", [4, 3, 8, 5])
def test_overlap_add_groups_do_not_overlap_and_cover_every_used_patch(stride):
    """_solve_block_here adds a block's estimates one group of non-overlapping patches at a time (an indexed add
    each; it was one Python step per patch, holding the GIL): every patch with an estimate in exactly one group,
    no two patches of a group sharing a pixel, the last row and column (flush with the border) included."""
    from lfproc.recon._reconstruct import _disjoint_groups

    size = 8
    tops, lefts = patch_grid((37, 50), size, stride)
    gt, gl = np.repeat(tops, len(lefts)), np.tile(lefts, len(tops))
    use = np.random.default_rng(stride).random(len(gt)) > 0.1
    groups = _disjoint_groups(gt, gl, use, size, stride)
    listed = np.concatenate(groups)
    assert sorted(listed) == list(np.flatnonzero(use))
    for g in groups:
        cover = np.zeros((37, 50), dtype=int)
        for b in g:
            cover[gt[b]:gt[b] + size, gl[b]:gl[b] + size] += 1
        assert cover.max() == 1
    assert len(groups) <= -(-size // stride) ** 2 + 37 + 50  # a few groups, not one per patch


def test_dictionary_weights_assume_at_least_one_electron_of_read_noise():
    """Known answer (reference: lfproc.camera.capture.observations with and without ``read_floor_e``): the dictionary
    method weighs a capture without read noise (paper-none) as one with one electron of it, the gmm method's floor,
    and a capture with more read noise (paper-medium, 2 e-) as its sensor model says, bit for bit."""
    from lfproc.camera.capture import READ_FLOOR_E
    from lfproc.recon._reconstruct import _weighted_observations
    from lfproc.synth import synthesize

    assert READ_FLOOR_E == 1.0
    lf = synthesize("layers", size=(16, 16), views=5, random_state=4)
    for profile, floored in (("paper-none", True), ("paper-medium", False)):
        cap = simulate_capture(lf, profile=profile, shots=2, mask_period=4, random_state=4, radiance_scale=1e2)
        _, W = _weighted_observations(cap, "local")
        plain = observations(cap, variance_from="local", warn_saturation=False).weight
        want = observations(cap, variance_from="local", warn_saturation=False, read_floor_e=1.0).weight
        np.testing.assert_array_equal(W, want)
        assert (W < plain).any() if floored else np.array_equal(W, plain)
