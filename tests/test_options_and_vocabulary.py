"""Option objects, the deprecated keyword names, and known answers of steps split out of long functions.

Option objects (issue 21): a function with more than 12 settings takes a frozen dataclass or its fields
as keywords; both give the same result, and both at once is one clear TypeError. Vocabulary:
``random_state``, ``max_iter``, ``n_nonzero_coefs``; the old names (``seed``, ``n_iter``/``iterations``,
``sparsity``) still work for one release with a DeprecationWarning naming the new one.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from lfproc._shared.deprecate import REMOVED_IN, rename_keywords, renamed_keywords, resolve_options
from lfproc.errors import InputError
from lfproc.synth import synthesize


# -- the shared helpers ------------------------------------------------------------------------------

def test_renamed_keywords_warns_names_the_new_keyword_and_keeps_the_signature():
    import inspect

    @renamed_keywords(old="new")
    def f(x, *, new=1):
        return x + new

    with pytest.warns(DeprecationWarning, match=r"f\(\): the keyword 'old' is deprecated .* use 'new'"):
        assert f(1, old=5) == 6
    assert REMOVED_IN in _message(lambda: f(1, old=5))
    assert f(1, new=5) == 6
    assert list(inspect.signature(f).parameters) == ["x", "new"]
    with pytest.raises(TypeError, match="got both 'old' and its new name 'new'"):
        f(1, old=2, new=3)


def test_the_deprecation_points_at_the_caller():
    @renamed_keywords(old="new")
    def f(*, new=1):
        return new

    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        f(old=2)
    assert w[0].filename == __file__


def _message(call) -> str:
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        call()
    return str(w[0].message)


@dataclasses.dataclass(frozen=True)
class _Opt:
    a: int = 1
    b: int = 2


def test_resolve_options_object_or_keywords_not_both():
    assert resolve_options(_Opt, None, {"b": 5}, func_name="g", argument="opt") == _Opt(b=5)
    assert resolve_options(_Opt, _Opt(a=3), {}, func_name="g", argument="opt") == _Opt(a=3)
    with pytest.raises(TypeError, match=r"^g\(\): a, b given both in opt and as keywords: pass one"):
        resolve_options(_Opt, _Opt(), {"a": 1, "b": 2}, func_name="g", argument="opt")
    with pytest.raises(TypeError, match="unexpected keyword argument 'c'"):
        resolve_options(_Opt, None, {"c": 1}, func_name="g", argument="opt")
    with pytest.raises(TypeError, match="opt must be a _Opt, got dict"):
        resolve_options(_Opt, {"a": 1}, {}, func_name="g", argument="opt")
    kw = {"old": 4}
    with pytest.warns(DeprecationWarning, match="use 'a'"):
        assert resolve_options(_Opt, None, kw, func_name="g", argument="opt", renames={"old": "a"}) == _Opt(a=4)
    with pytest.raises(TypeError, match="got both"):
        rename_keywords("g", {"old": 1, "a": 2}, {"old": "a"})


# -- option objects -----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def small():
    """A 5x5-view light field, its capture and a small DCT dictionary (seconds to reconstruct)."""
    from lfproc.camera.simulate import simulate_capture
    from lfproc.dictionary import dct_dictionary

    lf = synthesize("layers", size=(16, 20), views=5, random_state=2)
    capture = simulate_capture(lf, shots=2, random_state=4)
    return lf, capture, dct_dictionary((5, 5, 4, 4, 3), 100, n_nonzero_coefs=4)


def _record(rec):
    return {k: v for k, v in rec.attrs["reconstruction"].items() if k not in ("seconds", "scheduler")}


def test_reconstruction_settings_object_equals_keywords(small):
    from lfproc.recon import reconstruct
    from lfproc.recon._reconstruct import ReconstructionSettings

    _, capture, dct = small
    for kw in ({"solver": "omp", "n_nonzero_coefs": 3, "stride": 2},
               {"mu": 0.3, "max_iter": 20, "overlap": "mean", "scale": "patch", "block_patches": 30}):
        by_kw = reconstruct(capture, dct, threads=1, **kw)
        by_obj = reconstruct(capture, dct, threads=2, settings=ReconstructionSettings(**kw))
        np.testing.assert_array_equal(by_kw.data, by_obj.data)
        assert _record(by_kw) == _record(by_obj)
    with pytest.raises(TypeError, match=r"reconstruct\(\): mu given both in settings and as keywords"):
        reconstruct(capture, dct, settings=ReconstructionSettings(), mu=0.1)
    with pytest.raises(TypeError, match="unexpected keyword argument 'muu'"):
        reconstruct(capture, dct, muu=0.1)


def test_reconstruct_sparsity_is_deprecated_for_n_nonzero_coefs(small):
    from lfproc.recon import reconstruct

    _, capture, dct = small
    new = reconstruct(capture, dct, solver="omp", n_nonzero_coefs=2, threads=1)
    with pytest.warns(DeprecationWarning, match="'sparsity' is deprecated.*use 'n_nonzero_coefs'") as rec:
        old = reconstruct(capture, dct, solver="omp", sparsity=2, threads=1)
    assert rec[0].filename == __file__  # the warning points at the caller
    np.testing.assert_array_equal(new.data, old.data)
    assert _record(new) == _record(old) and _record(new)["sparsity"] == 2
    with pytest.raises(TypeError, match="got both 'sparsity' and its new name 'n_nonzero_coefs'"):
        reconstruct(capture, dct, sparsity=2, n_nonzero_coefs=2)


def test_capture_design_object_equals_keywords(small):
    from lfproc.camera.simulate import CaptureDesign, simulate_capture

    lf = small[0]
    for kw in ({"shots": 2, "iso_pattern_kind": "row", "exposure_s": 0.008},
               {"baseline": "bracketing", "shots": 3, "profile": "paper-high", "noise": False}):
        a = simulate_capture(lf, random_state=1, **kw)
        b = simulate_capture(lf, random_state=1, design=CaptureDesign(**kw))
        np.testing.assert_array_equal(a.dn, b.dn)
        np.testing.assert_array_equal(a.mask.codes, b.mask.codes)
        assert dict(a.parameters) == dict(b.parameters) and a.exposures_s == b.exposures_s
    with pytest.raises(TypeError, match=r"simulate_capture\(\): shots given both in design and as keywords"):
        simulate_capture(lf, design=CaptureDesign(), shots=2)


def test_capture_design_steps_known_answers():
    from lfproc.sensor import load_profile
    from lfproc.camera.simulate import CaptureDesign, _mask_period, _seeded, _shot_plan

    assert _mask_period(CaptureDesign()) == 4
    assert _mask_period(CaptureDesign(mask="shifted")) is None
    assert _mask_period(CaptureDesign(mask_period=8)) == 8
    with pytest.raises(InputError, match="mask_period"):
        _mask_period(CaptureDesign(mask_period="auto"))
    design = CaptureDesign(profile=load_profile("paper-low"), baseline="bracketing", shots=3, isos=[400.0, 100.0])
    maps, info, rel = _shot_plan(design, (4, 6), np.random.default_rng(0))
    assert rel == [0.5, 2.0, 8.0] and maps.shape == (3, 4, 6) and np.all(maps == 100)
    assert info == {"kind": "global", "baseline": "bracketing", "isos": [100]}
    assert _seeded(7)[1] == 7 and _seeded(np.random.default_rng(1))[1] == "generator"


def test_illum_frame_settings_object_equals_keywords():
    from lfproc.lytro.container import IllumFrameSettings, illum_metadata

    kw = {"height": 8, "width": 16, "iso": 200, "zoom_step": 3, "white_balance": {"r": 2.0, "b": 1.5}}
    assert illum_metadata(**kw, extra={"a": 1}) == illum_metadata(IllumFrameSettings(**kw), extra={"a": 1})
    with pytest.raises(TypeError, match="iso given both in settings and as keywords"):
        illum_metadata(IllumFrameSettings(), iso=100)


def test_lenslet_sensor_object_equals_keywords():
    from lfproc.lytro.decode import LensletSensor, decode_lenslet
    from lfproc.lytro.virtual import illum_grid, white_irradiance

    grid = illum_grid((120, 160), random_state=3)
    white = np.clip(64 + 900 * white_irradiance(grid, scale_e_per_s=1.0) / 1.0, 0, 1023).astype(np.uint16)
    raw = np.clip(64 + (white.astype(np.float32) - 64) * 0.5, 0, 1023).astype(np.uint16)
    kw = {"black_level": 64, "white_level": 1023, "gain_dn_per_e": 0.5, "read_noise_dn": 2.0}
    a = decode_lenslet(raw, white, grid, n_views=3, **kw)
    b = decode_lenslet(raw, white, grid, LensletSensor(**kw), n_views=3)
    for key in ("data", "variance", "weight"):
        np.testing.assert_array_equal(a[key], b[key])
    with pytest.raises(TypeError, match="white_level given both in sensor and as keywords"):
        decode_lenslet(raw, white, grid, LensletSensor(**kw), white_level=1000)


def test_training_sizes_object_equals_keywords_and_old_names_are_deprecated():
    from lfproc.dictionary import train_dictionary
    from lfproc.dictionary._train import TrainingSizes

    lf = synthesize("layers", size=(24, 24), views=5, random_state=1)
    kw = {"atoms": 40, "patches": 400, "n_nonzero_coefs": 3, "max_iter": 1}
    a = train_dictionary([lf], preset="tiny", random_state=2, **kw)
    b = train_dictionary([lf], preset="tiny", random_state=2, sizes=TrainingSizes(**kw))
    with pytest.warns(DeprecationWarning) as rec:
        c = train_dictionary([lf], preset="tiny", seed=2, atoms=40, patches=400, sparsity=3, iterations=1)
    assert {str(w.message).split("'")[1] for w in rec} == {"seed", "sparsity", "iterations"}
    for other in (b, c):
        np.testing.assert_array_equal(a.atoms, other.atoms)
        assert a.sparsity == other.sparsity == 3 and a.provenance == other.provenance
    with pytest.raises(TypeError, match="atoms given both in sizes and as keywords"):
        train_dictionary([lf], preset="tiny", sizes=TrainingSizes(atoms=40), atoms=40)


# -- deprecated keywords: warns, same result -----------------------------------------------------------

def _same(new_call, old_call, old: str, new: str):
    expected = new_call()
    with pytest.warns(DeprecationWarning, match=f"the keyword '{old}' is deprecated.*use '{new}'"):
        got = old_call()
    return expected, got


def test_seed_is_deprecated_for_random_state(tmp_path):
    from lfproc.calib.simulate_frames import simulate_frames
    from lfproc.camera.iso import describe_iso_pattern
    from lfproc.dictionary._train import synthetic_lightfields

    a, b = _same(lambda: describe_iso_pattern("random", [100, 400], random_state=3),
                 lambda: describe_iso_pattern("random", [100, 400], seed=3), "seed", "random_state")
    assert a == b == {"kind": "random", "isos": [100, 400], "seed": 3}
    a, b = _same(lambda: list(synthetic_lightfields(2, views=(3, 3), size=(16, 16), random_state=1)),
                 lambda: list(synthetic_lightfields(2, views=(3, 3), size=(16, 16), seed=1)), "seed", "random_state")
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.data, y.data)
    a, b = _same(lambda: simulate_frames("paper-low", tmp_path / "a", isos=[100], size=(8, 8), random_state=5),
                 lambda: simulate_frames("paper-low", tmp_path / "b", isos=[100], size=(8, 8), seed=5),
                 "seed", "random_state")
    files_a = sorted(p.relative_to(a.parent) for p in a.parent.rglob("*") if p.is_file())
    files_b = sorted(p.relative_to(b.parent) for p in b.parent.rglob("*") if p.is_file())
    assert files_a == files_b
    for rel in files_a:
        if rel.suffix != ".json":  # simulation.json names its folder
            assert (a.parent / rel).read_bytes() == (b.parent / rel).read_bytes(), rel


def test_seed_reaches_random_state_of_the_slow_functions(tmp_path):
    """make_virtual_illum and run_bench take minutes for a same-result check: the old keyword's value is
    shown to arrive as ``random_state`` by the validation it fails."""
    from lfproc.bench import run_bench
    from lfproc.lytro.virtual import make_virtual_illum

    lf = synthesize("layers", size=(16, 16), views=3, random_state=1)
    with pytest.warns(DeprecationWarning, match="'seed'.*use 'random_state'"):
        with pytest.raises(InputError, match="random_state: expected a non-negative integer, got -1"):
            make_virtual_illum(lf, tmp_path / "v", seed=-1)
    with pytest.warns(DeprecationWarning, match="'seed'.*use 'random_state'"):
        with pytest.raises(InputError, match="random_state: expected a non-negative integer, got -1"):
            run_bench(["x.exr"], tmp_path / "b", seed=-1)


def test_sparsity_is_deprecated_for_n_nonzero_coefs():
    from lfproc.dictionary import approximate, dct_dictionary, evaluate_dictionary
    from lfproc.dictionary._ksvd import ksvd

    a, b = _same(lambda: dct_dictionary((3, 3, 2, 2, 3), 40, n_nonzero_coefs=4),
                 lambda: dct_dictionary((3, 3, 2, 2, 3), 40, sparsity=4), "sparsity", "n_nonzero_coefs")
    assert a.sparsity == b.sparsity == 4
    lf = synthesize("layers", size=(16, 16), views=3, random_state=1)
    a, b = _same(lambda: approximate(a, lf, n_nonzero_coefs=2), lambda: approximate(a, lf, sparsity=2),
                 "sparsity", "n_nonzero_coefs")
    np.testing.assert_array_equal(a, b)
    d = dct_dictionary((3, 3, 2, 2, 3), 40, n_nonzero_coefs=4)
    a, b = _same(lambda: evaluate_dictionary(d, [lf], n_nonzero_coefs=2, compare_dct=False),
                 lambda: evaluate_dictionary(d, [lf], sparsity=2, compare_dct=False), "sparsity", "n_nonzero_coefs")
    assert {k: v for k, v in a.items() if k != "seconds"} == {k: v for k, v in b.items() if k != "seconds"}
    x = np.random.default_rng(0).normal(size=(60, 12)).astype(np.float32)
    a = ksvd(x, 8, n_nonzero_coefs=2, max_iter=2, random_state=0)
    with pytest.warns(DeprecationWarning) as rec:
        b = ksvd(x, 8, sparsity=2, n_iter=2, random_state=0)
    assert sorted(str(w.message).split("'")[1] for w in rec) == ["n_iter", "sparsity"]
    np.testing.assert_array_equal(a.atoms, b.atoms)
    assert a.errors == b.errors


def test_n_iter_is_deprecated_for_max_iter(tmp_path):
    from PIL import Image

    from lfproc.hdr import merge_files, simulate_ldr_bracket
    from lfproc.sensor import expose
    from lfproc.lightfield import LightField
    from lfproc.hdr import merge_lightfields, merge_ml, merge_ml_codes8

    times = [0.01, 0.02, 0.04]
    truth = synthesize("layers", size=(16, 16), views=1, random_state=0).data[0, 0].astype(np.float64)
    truth *= 2e5 / truth.max()  # brightest: 8000 e- in the longest exposure, nothing saturated
    dn = np.stack([expose(truth.reshape(-1, 3), exposure_s=t, iso=100, profile="illum", random_state=k)
                   .reshape(truth.shape) for k, t in enumerate(times)])
    a, b = _same(lambda: merge_ml(dn, exposures_s=times, isos=100, profile="illum", max_iter=3),
                 lambda: merge_ml(dn, exposures_s=times, isos=100, profile="illum", n_iter=3), "n_iter", "max_iter")
    np.testing.assert_array_equal(a[0], b[0])
    assert a[2]["n_iter"] == b[2]["n_iter"] == 3
    lfs = [LightField(data=d[None, None].astype(np.float32), units="dn", exposure_s=t, iso=100)
           for d, t in zip(dn, times)]
    a, b = _same(lambda: merge_lightfields(lfs, profile="illum", max_iter=4),
                 lambda: merge_lightfields(lfs, profile="illum", n_iter=4), "n_iter", "max_iter")
    np.testing.assert_array_equal(a[0].data, b[0].data)
    assert a[0].attrs["n_iter"] == b[0].attrs["n_iter"] == 4
    ldr_times = [1 / 64, 1 / 8, 1]  # a scene under 10 % saturated everywhere (no SaturationWarning)
    scene = synthesize("layers", size=(16, 16), views=1, random_state=0).data[0, 0].astype(np.float64)
    codes, _ = simulate_ldr_bracket(scene, ldr_times, random_state=1, jpeg_quality=None, mid_grey=0.05)
    codes = np.stack(codes)
    a, b = _same(lambda: merge_ml_codes8(codes, exposures_s=ldr_times, max_iter=3, random_state=0),
                 lambda: merge_ml_codes8(codes, exposures_s=ldr_times, n_iter=3, random_state=0), "n_iter", "max_iter")
    np.testing.assert_array_equal(a[0], b[0])
    paths = []
    for k, c in enumerate(codes):
        paths.append(tmp_path / f"s{k}.png")
        Image.fromarray(c).save(paths[-1])
    a, b = _same(lambda: merge_files(paths, exposures_s=ldr_times, method="ml", max_iter=2),
                 lambda: merge_files(paths, exposures_s=ldr_times, method="ml", n_iter=2), "n_iter", "max_iter")
    np.testing.assert_array_equal(a[0].data, b[0].data)


def test_the_cli_uses_the_new_names(tmp_path, capsys):
    """The CLI keeps its flags (--seed, --iterations, --sparsity) and passes the new keywords: no warning
    (pytest turns any DeprecationWarning into an error)."""
    from lfproc.cli.main import main

    assert main(["calibrate", "simulate-frames", "--profile", "paper-low", "-o", str(tmp_path / "f"), "--size", "8", "8",
                 "--iso", "100", "--seed", "3", "--json"]) == 0
    capsys.readouterr()


# -- known answers of split steps ---------------------------------------------------------------------

def test_hdr_figure_steps_known_answers():
    from lfproc.metrics._metrics import _detail, _figure_mask, _stops_by_decade

    ref = np.array([1.5, 2.0, 20.0, 300.0, 0.01])
    res = np.array([3.0, 2.0, 10.0, 0.0, 5.0])
    by_decade, zeros, n_above = _stops_by_decade(res, ref, 0.05)
    assert n_above == 4 and zeros == 0.25
    assert [d["decade"] for d in by_decade] == [(1.0, 10.0), (10.0, 100.0), (100.0, 1000.0)]
    assert [d["median_stops"] for d in by_decade] == [0.5, 1.0, math.inf]
    assert [d["samples"] for d in by_decade] == [2, 1, 1]
    keep, n = _figure_mask(np.array([[True, False]]), (2, 1, 2))
    assert n == 2 and keep.shape == (2, 1, 2)
    assert _figure_mask(None, (2, 3)) == (None, 6)
    p = np.random.default_rng(0).random((2, 6, 7))
    top = np.array([0])  # the first sample of the first view: it and its cross of neighbours are "near"
    zero = _detail(np.zeros_like(p), p, None, top)
    assert zero["detail_ratio"] == zero["detail_ratio_off_highlights"] == 0.0
    flat = _detail(-p, p, None, top)  # the error cancels the reference: as much wrong detail as it has
    assert flat["detail_ratio"] == pytest.approx(1.0) and flat["detail_ratio_off_highlights"] == pytest.approx(1.0)
    assert 0 < flat["highlight_detail_share"] < 1


def test_reconstruction_steps_known_answers():
    from lfproc.recon._reconstruct import ReconstructionSettings, _checked_settings, _execution

    s = _checked_settings(ReconstructionSettings(solver="fista"))
    assert s.tol == 2.0**-15 and s.max_iter == 1000 and isinstance(s.mu, float)
    s = _checked_settings(ReconstructionSettings(solver="omp"))
    assert s.tol == 0.0 and s.max_iter == 1
    with pytest.raises(InputError, match="stride: expected a positive integer"):
        _checked_settings(ReconstructionSettings(stride=2.5))
    assert _execution(None, 3) == (None, 3)
    with pytest.raises(InputError, match="workers"):
        _execution(0, 1)


def test_merge_steps_known_answers():
    from lfproc.hdr._merge import _bias_of, _CodeGrid

    flat, scalar = _bias_of(np.array([1.0, 2.0]), (3, 2))
    assert scalar is None and flat.tolist() == [1.0, 2.0] * 3
    assert _bias_of(5, (3,)) == (None, 5.0) and _bias_of(None, (3,)) == (None, None)
    x64 = np.repeat(np.linspace(0.0, 2.55, 256)[:, None], 2, axis=1)  # x(z) = z / 100
    grid = _CodeGrid.build(x64, 254, 2)
    for z in (1, 7, 100, 253):  # the grid point of exposure x predicts the code z of x = z / 100
        k = int(round((math.log(z / 100) - grid.ln_lo[0]) * grid.grid_scale[0]))
        assert grid.code_grid[k, 0] == z and grid.code_grid[k, 1] == z


def test_lfr_steps_known_answers():
    import struct

    from lfproc.lytro.container import _hot_pixel_section, _lfr_frame_metadata

    section = _hot_pixel_section("x", [[3, 1], [5, 2]], 8, 4)
    assert section == struct.pack("<I", 2) + struct.pack("<2H", 3, 5) + struct.pack("<2H", 1, 2)
    assert _hot_pixel_section("x", None, 8, 4) == struct.pack("<I", 0)
    meta = _lfr_frame_metadata("x", {"camera": {"model": "ILLUM"}}, (4, 8))
    assert meta["image"]["width"] == 8 and meta["image"]["height"] == 4
    assert meta["image"]["pixelPacking"] == {"bitsPerPixel": 10, "endianness": "little"}
    assert meta["camera"] == {"model": "ILLUM", "make": "Lytro, Inc."}


def test_emva_linearity_of_a_linear_sensor_is_zero():
    from types import SimpleNamespace

    from lfproc.calib.emva import _linearity

    u_p = np.linspace(100.0, 10000.0, 12)
    y = 0.3 * u_p
    out, unknown = {}, {}
    _linearity(SimpleNamespace(u_p=u_p), y, len(y) - 1, out, unknown, photons=True)
    assert out["LE_min"] == pytest.approx(0.0, abs=1e-9) and out["LE_max"] == pytest.approx(0.0, abs=1e-9)
    out, unknown = {}, {}
    _linearity(SimpleNamespace(u_p=u_p), y, len(y) - 1, out, unknown, photons=False)
    assert out == {"LE_min": None, "LE_max": None} and set(unknown) == {"LE_min", "LE_max"}


def test_sensor_steps_known_answers():
    from lfproc.sensor._model import _bias_map, _variance_signal

    T = np.array([[-1.0, 2.0]])
    np.testing.assert_array_equal(_variance_signal("measurement", None, T), [[0.0, 2.0]])
    np.testing.assert_array_equal(_variance_signal("estimate", 3.0, T), [[3.0, 3.0]])
    with pytest.raises(InputError, match="needs radiance_estimate"):
        _variance_signal("estimate", None, T)
    m = {"black_level_dn": np.full((1, 2), 64.0), "gain_dn_per_e": np.full((1, 2), 0.5),
         "dark_current_e_per_s": np.full((1, 2), 10.0)}
    np.testing.assert_array_equal(_bias_map(None, m, 2.0, (1, 2)), [[74.0, 74.0]])
    np.testing.assert_array_equal(_bias_map(60, m, 2.0, (1, 2)), [[60.0, 60.0]])


def test_merge_warnings_still_point_at_the_caller():
    """merge_ml is wrapped by the keyword-renaming decorator; its ConvergenceWarning and SaturationWarning
    keep pointing at the code that called it."""
    from lfproc.sensor import expose
    from lfproc.errors import ConvergenceWarning, SaturationWarning
    from lfproc.hdr import merge_ml

    times = [0.01, 0.02, 0.04]
    truth = synthesize("lamps", size=(16, 16), views=1, random_state=0).data[0, 0].astype(np.float64) * 2e5
    dn = np.stack([expose(truth.reshape(-1, 3), exposure_s=t, iso=100, profile="illum", random_state=k)
                   .reshape(truth.shape) for k, t in enumerate(times)])
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        merge_ml(dn, exposures_s=times, isos=100, profile="illum", max_iter=1)
    kinds = {type(w.message) for w in rec}
    assert ConvergenceWarning in kinds and SaturationWarning in kinds
    assert all(w.filename == __file__ for w in rec), [(type(w.message).__name__, w.filename) for w in rec]
