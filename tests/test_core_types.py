"""The core types own read-only arrays and close the validation gaps of issue 13.

Every validated object (LightField, Capture, MaskCode, ProjectionOperator, Observation,
CameraProfile) must refuse writes into its arrays, must not be changed by later writes into
the caller's arrays, and must not copy arrays that are already read-only.
"""

from __future__ import annotations

import copy
import pickle
from dataclasses import replace

import numpy as np
import pytest

from lfproc import LightField
from lfproc._shared.frozen import FrozenDict, freeze, frozen_array, is_frozen
from lfproc.sensor import load_profile
from lfproc.camera.capture import Capture, load_capture, observations
from lfproc.camera.projection import MaskCode, ProjectionOperator, build_operator, make_mask
from lfproc.sensor import Observation, calibrated_observation
from lfproc.errors import InputError, ProfileError, ShapeError


def _lf(seed=0, shape=(3, 3, 8, 10, 3)):
    return np.random.default_rng(seed).uniform(0.1, 1.0, shape).astype(np.float32)


def _capture(seed=0):
    mask = make_mask("random", shots=2, views=(3, 3), size=(8, 10), period=4, random_state=seed)
    dn = np.random.default_rng(seed).integers(64, 4000, (2, 8, 10)).astype(np.uint16)
    return Capture(dn=dn, iso=400, exposures_s=[0.01, 0.02], mask=mask, profile="paper-low", views=(3, 3),
                   bias_dn=np.full((8, 10), 64.0))


# -- the helper -----------------------------------------------------------------------------

def test_frozen_array_copies_only_when_someone_else_can_write():
    own = np.arange(6.0)
    a = frozen_array(own)
    assert not a.flags.writeable and not np.shares_memory(a, own) and own.flags.writeable  # caller untouched
    b = frozen_array(a)
    assert b is a  # already frozen: no copy
    c = frozen_array(own, dtype=np.float32)
    assert c.dtype == np.float32 and not c.flags.writeable  # the conversion is the one copy
    view = a[1:4]
    assert is_frozen(view) and frozen_array(view) is view  # views of frozen arrays are shared
    # a read-only view of a writeable array is not frozen: it must be copied
    ro = own[1:4]
    ro.flags.writeable = False
    assert not is_frozen(ro)
    assert not np.shares_memory(frozen_array(ro), own)
    assert is_frozen(np.frombuffer(b"abcd", dtype=np.uint8))
    assert not is_frozen(np.frombuffer(bytearray(b"abcd"), dtype=np.uint8))
    assert frozen_array([1, 2]).tolist() == [1, 2]


def test_frozen_dict_refuses_changes_and_survives_pickle():
    d = FrozenDict({1: "a"})
    for change in (lambda: d.__setitem__(2, "b"), lambda: d.pop(1), lambda: d.update({3: 4}),
                   lambda: d.clear(), lambda: d.setdefault(5, 6), lambda: d.__delitem__(1)):
        with pytest.raises(TypeError, match="read-only"):
            change()
    assert dict(d) == {1: "a"}
    e = pickle.loads(pickle.dumps(d))
    assert isinstance(e, FrozenDict) and e == {1: "a"} and copy.deepcopy(d) == d


# -- light field ------------------------------------------------------------------------------

def test_light_field_arrays_are_read_only_and_independent_of_the_caller():
    data = _lf()
    var = np.full(data.shape, 0.01, np.float32)
    disp = np.zeros(data.shape[2:4], np.float32)
    lf = LightField(data, variance=var, disparity=disp)
    for arr in (lf.data, lf.variance, lf.disparity, lf.centre(), lf.epi(), lf.view(0, 0)):
        with pytest.raises(ValueError, match="read-only"):
            arr[...] = -1.0
    data[0, 0, 0, 0, 0] = np.nan  # writing into the caller's array does not reach the light field
    assert np.isfinite(lf.data).all()
    with pytest.raises(ValueError, match="read-only"):
        np.multiply(lf.data, 2, out=lf.data)


def test_light_field_takes_frozen_arrays_without_a_copy_and_crops_share_memory():
    data = freeze(_lf())
    lf = LightField(data)
    assert lf.data is data
    crop = lf.crop(1, 2, 4, 5)
    assert np.shares_memory(crop.data, lf.data) and not crop.data.flags.writeable
    assert np.shares_memory(lf.central(1).data, lf.data)
    converted = LightField(_lf().astype(np.float64))  # the float32 conversion is the only copy
    assert converted.data.dtype == np.float32 and converted.data.base is None


@pytest.mark.parametrize("clone", [lambda x: pickle.loads(pickle.dumps(x)), copy.deepcopy, copy.copy])
def test_copies_and_pickles_stay_read_only(clone):
    lf = LightField(_lf(), variance=np.ones((3, 3, 8, 10, 3), np.float32))
    cap = _capture()
    op = cap.operator()
    for obj, arrays in ((lf, ("data", "variance")), (cap, ("dn", "iso", "bias_dn")), (cap.mask, ("codes",)),
                        (op, ("weights", "cfa_index"))):
        other = clone(obj)
        for name in arrays:
            with pytest.raises(ValueError, match="read-only"):
                getattr(other, name)[...] = 0
    np.testing.assert_array_equal(clone(lf).data, lf.data)
    profile = clone(replace(load_profile("paper-low"), bias_frames={100: np.full((2, 2), 64.0)}))
    with pytest.raises(ValueError, match="read-only"):
        profile.bias_frames[100][0, 0] = 0
    with pytest.raises(TypeError, match="read-only"):
        profile.isos[1] = None


# -- capture, mask, operator, observation, profile -------------------------------------------

def test_capture_arrays_are_read_only(tmp_path):
    cap = _capture()
    for arr in (cap.dn, cap.iso, cap.bias_dn, cap.mask.codes):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 1
    cap.save(tmp_path / "c.capture.npz")
    loaded = load_capture(tmp_path / "c.capture.npz")
    with pytest.raises(ValueError, match="read-only"):
        loaded.dn[0, 0, 0] = 0
    obs = observations(cap)
    for name in ("radiance", "variance", "weight", "saturated", "black_clipped"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(obs, name)[0] = 0


def test_operator_is_immutable_and_restrict_shares_its_weights():
    op = _capture().operator()
    with pytest.raises(ValueError, match="read-only"):
        op.weights[0, 0, 0, 0, 0] = 0.5
    with pytest.raises(ValueError, match="read-only"):
        op.cfa_index[0, 0] = 2
    with pytest.raises(AttributeError, match="immutable"):
        op.weights = np.zeros_like(op.weights)
    with pytest.raises(AttributeError, match="immutable"):
        del op.channels
    sub = op.restrict(2, 3, 4)
    assert np.shares_memory(sub.weights, op.weights)
    # the caller's weights are copied: a later write does not change the operator
    w = np.full((1, 1, 1, 2, 2), 0.5, np.float32)
    own = ProjectionOperator(w, np.zeros((2, 2), int), channels=3)
    w[...] = 0.9
    assert (own.weights == 0.5).all()


def test_patch_operators_and_fixed_pattern_maps_are_read_only():
    from lfproc.camera.projection import patch_operators
    from lfproc.sensor import fixed_pattern_correction

    cap = _capture()
    ops = patch_operators(cap.mask, views=(3, 3), cfa_pattern="RGGB", tops=np.array([0, 4]),
                          lefts=np.array([0, 2]), size=4)
    for arr in (ops.cols, ops.vals, ops.index, ops.positions):
        with pytest.raises(ValueError, match="read-only"):
            arr.flat[0] = 1
    assert all(is_frozen(a) for a in (ops.cols, ops.vals, ops.index, ops.positions))
    fp = fixed_pattern_correction(replace(load_profile("paper-low"), prnu=0.01, dsnu_e=0.5), (8, 10), iso=400)
    for arr in (fp.gain, fp.offset_e, fp.gain_var, fp.offset_var_e2):
        with pytest.raises(ValueError, match="read-only"):
            arr[0, 0] = 0
    assert 0.9 < fp.gain.mean() < 1.1 and fp.offset_e.std() > 0  # the maps were drawn, not left at their defaults


def test_profile_bias_frames_and_isos_are_read_only():
    p = load_profile("paper-low")
    frame = np.full((4, 4), 64.0)
    q = replace(p, bias_frames={100: frame})
    frame[0, 0] = 1e9
    assert q.bias_frames[100][0, 0] == 64.0
    with pytest.raises(ValueError, match="read-only"):
        q.bias_frames[100][0, 0] = 0
    with pytest.raises(TypeError, match="read-only"):
        q.bias_frames[400] = frame
    with pytest.raises(TypeError, match="read-only"):
        p.isos[100] = p.isos[400]
    with pytest.raises(ProfileError, match="bias frame of ISO 100: expected a finite 2-D array"):
        replace(p, bias_frames={100: np.full((4, 4), np.nan)})
    with pytest.raises(ProfileError, match="bias frame of ISO 100: expected a finite 2-D array"):
        replace(p, bias_frames={100: np.zeros(4)})


# -- validation gaps ---------------------------------------------------------------------------

def test_nan_dn_codes_are_refused():
    with pytest.raises(InputError, match="sensor image: expected finite DN codes, found 2 NaN or Inf"):
        calibrated_observation(np.array([[100.0, np.nan], [np.inf, 200.0]]), exposure_s=0.01, iso=400,
                               profile="paper-low")
    cap = _capture()
    dn = cap.dn.astype(np.float64)
    dn[0, 0, 0] = np.nan
    with pytest.raises(InputError, match="capture dn: expected integer sensor codes, found 1 NaN or Inf and 0 fractional"):
        replace(cap, dn=dn)
    dn[0, 0, 0] = 100.5
    with pytest.raises(InputError, match="found 0 NaN or Inf and 1 fractional"):
        replace(cap, dn=dn)
    with pytest.raises(InputError, match=r"capture dn: expected codes in \[0, 65535\], found range \[-3"):
        replace(cap, dn=np.full((2, 8, 10), -3))
    ok = replace(cap, dn=cap.dn.astype(np.float64))  # integral floats are codes
    np.testing.assert_array_equal(ok.dn, cap.dn)
    with pytest.raises(InputError, match="bias_dn: expected finite DN values"):
        calibrated_observation(np.full((2, 2), 100), exposure_s=0.01, iso=400, profile="paper-low",
                               bias_dn=np.array([[64, np.nan], [64, 64]]))


def test_gamma_below_one_is_refused_by_the_calibrated_observation():
    dn = np.full((2, 2), 500)
    with pytest.raises(InputError, match="gamma: expected a value >= 1, got 0.5"):
        calibrated_observation(dn, exposure_s=0.01, iso=400, profile="paper-low", gamma=0.5)
    with pytest.raises(InputError, match="gamma: expected a positive finite number"):
        calibrated_observation(dn, exposure_s=0.01, iso=400, profile="paper-low", gamma=float("nan"))


@pytest.mark.parametrize("bad, found", [(1.5, "found 1 values outside"), (-0.25, "found 1 values outside"),
                                        (np.nan, "found 1 NaN or Inf")])
def test_mask_and_operator_weights_outside_unit_interval_are_refused(bad, found):
    codes = np.full((1, 3, 3, 4, 4, 3), 0.5, np.float32)
    codes[0, 1, 1, 2, 2, 1] = bad
    with pytest.raises(InputError, match=f"mask codes: expected .*transmittances in \\[0, 1\\], {found}"):
        MaskCode("random", codes, period=4)
    w = np.full((1, 3, 3, 4, 4), 0.5, np.float32)
    w[0, 0, 0, 1, 1] = bad
    with pytest.raises(InputError, match=f"projection weights: expected .*transmittances in \\[0, 1\\], {found}"):
        ProjectionOperator(w, np.zeros((4, 4), int), channels=3)


def test_zero_sized_views_and_patches_are_refused():
    with pytest.raises(InputError, match=r"mask views \(V, U\): expected two integers >= 1, got \(0, 5\)"):
        make_mask("random", shots=1, views=(0, 5), size=(8, 8))
    with pytest.raises(InputError, match=r"mask size \(H, W\): expected two integers >= 1, got \(8, 0\)"):
        make_mask("shifted", shots=1, views=(3, 3), size=(8, 0))
    with pytest.raises(InputError, match="mask channels: expected an integer >= 1, got 0"):
        make_mask("random", shots=1, views=(3, 3), size=(8, 8), channels=0)
    with pytest.raises(ShapeError, match="every axis needs at least one element"):
        MaskCode("random", np.zeros((1, 0, 3, 4, 4, 3)))
    with pytest.raises(ShapeError, match="projection weights: every axis needs at least one element"):
        ProjectionOperator(np.zeros((1, 3, 3, 0, 4)), np.zeros((0, 4), int))
    op = build_operator(make_mask("random", shots=1, views=(3, 3), size=(8, 8), random_state=1), views=(3, 3),
                        size=(8, 8))
    for call in (lambda: op.patch_matrix(0, 0, 0), lambda: op.restrict(0, 0, 0),
                 lambda: op.patch_sparse([0], [0], 0), lambda: op.patch_sparse([0], [0], -2)):
        with pytest.raises(InputError, match="patch size: expected an integer >= 1"):
            call()


def test_observation_checks_its_arrays():
    a = np.ones((2, 2), np.float32)
    m = np.zeros((2, 2), bool)
    with pytest.raises(ShapeError, match=r"observation weight: expected shape \(2, 2\)"):
        Observation(a, a, np.ones(3), m, m)
    with pytest.raises(InputError, match="observation saturated: expected a boolean mask"):
        Observation(a, a, a, a, m)


# -- issue 20, item 6: messages name the argument in Python and the option in the CLI ------------

def test_output_exists_message_names_force_for_the_interface_in_use(tmp_path, capsys):
    from lfproc.cli.main import main
    from lfproc.errors import OutputExistsError
    from lfproc.io import write_lightfield

    lf = LightField(_lf())
    path = write_lightfield(lf, tmp_path / "lf.exr")
    with pytest.raises(OutputExistsError) as info:
        write_lightfield(lf, path)
    assert "pass force=True to overwrite" in str(info.value) and "--force" not in str(info.value)
    assert main(["convert", str(path), str(path)]) == 2
    err = capsys.readouterr().err
    assert "pass --force to overwrite" in err and "force=True" not in err


def test_large_objects_print_a_short_summary():
    """Issue 20, item 6: str/repr of a capture and the other large objects name shapes, not values."""
    from lfproc.camera.simulate import simulate_capture

    cap = simulate_capture(np.random.default_rng(0).uniform(0.1, 1, (5, 5, 64, 64, 3)).astype(np.float32),
                           profile="paper-low", random_state=0)
    for text in (str(cap), repr(cap)):
        assert text.count("\n") == 0 and len(text) < 400, text
        assert text.startswith("Capture(1 shot(s) of 64 x 64 pixels, views=5x5") and "paper-low" in text
    obs = observations(cap)
    for obj in (cap.mask, cap.profile, obs, cap.operator(), LightField(_lf())):
        text = repr(obj)
        assert str(obj) == text and "\n" not in text and len(text) < 800 and "[[" not in text, text
    assert "<array 1 x 64 x 64 float32>" in repr(obs)
