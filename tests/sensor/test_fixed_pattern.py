"""PRNU and DSNU in the calibrated observations: today's bias, the correction, its variance.

The reference is the sensor model itself: ``expose`` applies the fixed pattern drawn from the
profile's seed, and many independent noise draws of the same scene give, per pixel, the
mean of ``T`` to compare with the true irradiance ``E`` (the test of
tests/test_simulate.py, per pixel instead of pooled).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lfproc.sensor import load_profile
from lfproc.camera.capture import load_capture, observations
from lfproc.sensor import FixedPattern, calibrated_observation, expose, fixed_pattern, fixed_pattern_correction
from lfproc.camera.simulate import simulate_capture
from lfproc.errors import InputError, ShapeError

T_EXP = 0.01
SHAPE = (48, 48)
DRAWS = 160


def _profile(prnu=0.015, dsnu_e=3.0):
    # paper-medium (read noise 2 e-, dark current 1 e-/s) with a fixed pattern
    return replace(load_profile("paper-medium"), prnu=prnu, dsnu_e=dsnu_e, fixed_pattern_seed=21)


def _scene(seed=0):
    """Per-pixel ISO (100/400/1600) and irradiance from 30 to 3000 electrons per exposure, log-uniform,
    inside the range of every ISO (ISO 1600 saturates at about 1230 e-: its pixels get at most 1000)."""
    rng = np.random.default_rng(seed)
    iso = rng.choice([100.0, 400.0, 1600.0], size=SHAPE)
    electrons = np.exp(rng.uniform(np.log(30), np.log(3000), size=SHAPE))
    electrons = np.where(iso == 1600, np.minimum(electrons, 1000), electrons)
    return iso, electrons / T_EXP


def _draws(profile, iso, E, *, seed=1, **options):
    rng = np.random.default_rng(seed)
    T, V = [], []
    for _ in range(DRAWS):
        dn = expose(E, exposure_s=T_EXP, iso=iso, profile=profile, random_state=rng)
        obs = calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile, variance_from="estimate",
                                     radiance_estimate=E, **options)
        assert not obs.saturated.any() and not obs.black_clipped.any()
        T.append(obs.radiance.astype(np.float64))
        V.append(obs.variance.astype(np.float64))
    return np.stack(T), np.stack(V)


def test_uncorrected_prnu_biases_t_per_pixel():
    """Today's observation (no correction): each pixel's mean T is off by its PRNU gain."""
    profile = _profile()
    iso, E = _scene()
    T, V = _draws(profile, iso, E, correct_fixed_pattern=False)
    gain, offset = fixed_pattern(profile, SHAPE)
    rel_bias = T.mean(0) / E - 1
    # the relative bias of a pixel is its gain error (plus DSNU / signal), slope 1 on g - 1
    slope = np.polyfit(gain.ravel() - 1, rel_bias.ravel(), 1)[0]
    assert slope == pytest.approx(1.0, abs=0.08)
    expected = gain - 1 + offset / (E * T_EXP)
    assert np.corrcoef(rel_bias.ravel(), expected.ravel())[0, 1] > 0.9
    # in standard errors of the mean of 160 draws the bias is far beyond the noise
    z_mean = (T.mean(0) - E) / np.sqrt(V.mean(0) / DRAWS)
    assert z_mean.var() > 20


@pytest.mark.parametrize("prnu, dsnu_e", [(0.01, 0.0), (0.02, 3.0), (0.0, 5.0)])
def test_corrected_t_is_unbiased_per_pixel_with_the_predicted_variance(prnu, dsnu_e):
    profile = _profile(prnu, dsnu_e)
    iso, E = _scene()
    T, V = _draws(profile, iso, E)
    fp = fixed_pattern_correction(profile, SHAPE, iso)
    assert fp.gain_source == ("simulated" if prnu else "none")
    assert fp.offset_source == ("simulated" if dsnu_e else "none")
    assert not fp.gain_var.any() and not fp.offset_var_e2.any()  # a simulated sensor's maps are exact
    # per pixel, the mean of 160 draws is within its standard error of E
    z_mean = (T.mean(0) - E) / np.sqrt(V.mean(0) / DRAWS)
    n = z_mean.size
    assert abs(z_mean.mean()) < 4.5 / np.sqrt(n)
    assert z_mean.var() == pytest.approx(1.0, abs=0.1)
    if prnu:  # no pixel keeps its PRNU: the relative error no longer follows the gain (slope 1 uncorrected)
        gain = fixed_pattern(profile, SHAPE)[0]
        assert abs(np.polyfit(gain.ravel() - 1, (T.mean(0) / E - 1).ravel(), 1)[0]) < 0.08
    # each single observation: z-scores of variance 1 (pooled over pixels and draws)
    z = (T - E) / np.sqrt(V)
    assert z.var() == pytest.approx(1.0, abs=0.02)
    for value in (100, 400, 1600):
        assert z[:, iso == value].var() == pytest.approx(1.0, abs=0.04)


def test_measured_profile_without_maps_models_the_fixed_pattern_as_noise():
    """A measured profile knows the PRNU/DSNU only as numbers: no correction, their variance is added,
    so z-scores over pixels (whose gains are independent draws) have variance 1 again."""
    truth = _profile(0.02, 3.0)
    measured = replace(truth, fixed_pattern_seed=0, source={"kind": "calibrated"})
    iso, E = _scene()
    fp = fixed_pattern_correction(measured, SHAPE, iso)
    assert fp.gain_source.startswith("uncorrected") and fp.offset_source.startswith("uncorrected")
    np.testing.assert_array_equal(fp.gain, 1.0)
    np.testing.assert_allclose(fp.gain_var, 0.02**2)
    np.testing.assert_allclose(fp.offset_var_e2, 9.0)
    rng = np.random.default_rng(3)
    z, z_plain = [], []
    for _ in range(8):
        dn = expose(E, exposure_s=T_EXP, iso=iso, profile=truth, random_state=rng)
        kw = dict(exposure_s=T_EXP, iso=iso, variance_from="estimate", radiance_estimate=E)
        obs = calibrated_observation(dn, profile=measured, **kw)
        plain = calibrated_observation(dn, profile=measured, correct_fixed_pattern=False, **kw)
        z.append((obs.radiance - E) / np.sqrt(obs.variance))
        z_plain.append((plain.radiance - E) / np.sqrt(plain.variance))
        np.testing.assert_array_equal(obs.radiance, plain.radiance)  # nothing corrected
    assert np.var(z) == pytest.approx(1.0, abs=0.05)
    assert np.var(z_plain) > 1.2  # without the added variance the model is overconfident (1.3 here)


def test_no_fixed_pattern_changes_nothing():
    profile = load_profile("paper-medium")
    iso, E = _scene()
    dn = expose(E, exposure_s=T_EXP, iso=iso, profile=profile, random_state=0)
    a = calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile)
    b = calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile, correct_fixed_pattern=False)
    for f in ("radiance", "variance", "weight"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


def test_given_bias_frame_holds_the_dsnu():
    """A bias frame passed in is the dark signal with the DSNU: only the flat field is corrected then."""
    profile = _profile(0.02, 4.0)
    iso, E = _scene()
    gain, offset = fixed_pattern(profile, SHAPE)
    h = np.vectorize(lambda i: profile.isos[int(i)].gain_dn_per_e)(iso)
    bias = 64 + h * (T_EXP * profile.dark_current_e_per_s + offset)
    dn = expose(E, exposure_s=T_EXP, iso=iso, profile=profile, noise=False)
    obs = calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile, bias_dn=bias)
    # noise-free codes: T is E up to the rounding of the codes (0.5 DN)
    np.testing.assert_allclose(obs.radiance, E, atol=0.0, rtol=0.5 / (h * E * T_EXP * gain).min() + 1e-6)
    auto = calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile)
    np.testing.assert_allclose(auto.radiance, obs.radiance, rtol=1e-5, atol=1e-2)


def test_explicit_maps_and_bad_options():
    profile = _profile()
    iso, E = _scene()
    dn = expose(E, exposure_s=T_EXP, iso=iso, profile=profile, noise=False)
    fp = fixed_pattern_correction(profile, SHAPE, iso)
    a = calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile, correct_fixed_pattern=fp)
    b = calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile)
    np.testing.assert_array_equal(a.radiance, b.radiance)
    small = FixedPattern(*(np.ones((4, 4)),) * 2, *(np.zeros((4, 4)),) * 2)
    with pytest.raises(ShapeError, match=r"maps of shape \(4, 4\) do not fit the sensor image \(48, 48\)"):
        calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile, correct_fixed_pattern=small)
    with pytest.raises(InputError, match="correct_fixed_pattern: expected True, False or a FixedPattern"):
        calibrated_observation(dn, exposure_s=T_EXP, iso=iso, profile=profile, correct_fixed_pattern="yes")


def test_capture_observations_correct_prnu_and_survive_the_file(tmp_path):
    """Through simulate_capture and the capture file: z-scores of T against Phi L have variance 1 with
    the correction and far more without it (bright pixels, where PRNU dominates the noise)."""
    profile = _profile(0.02, 2.0)
    rng = np.random.default_rng(0)
    lf = np.broadcast_to(0.2 + rng.random((1, 1, 64, 64, 3)).astype(np.float32), (5, 5, 64, 64, 3)).copy()
    cap = simulate_capture(lf, profile=profile, iso_pattern_kind="row", isos=[100, 400], shots=4,
                           exposure_s=0.01, radiance_scale=4000 / (0.01 * 12.5), random_state=4)
    truth = cap.operator(dtype=np.float64).forward(lf.astype(np.float64)) * cap.radiance_scale
    obs = observations(cap, variance_from="estimate", radiance_estimate=truth)
    plain = observations(cap, variance_from="estimate", radiance_estimate=truth, correct_fixed_pattern=False)
    ok = obs.weight > 0
    assert ok.mean() > 0.95
    z = ((obs.radiance - truth) * obs.weight)[ok]
    z_plain = ((plain.radiance - truth) * plain.weight)[ok]
    assert abs(z.mean()) < 4.5 / np.sqrt(z.size) and z.var() == pytest.approx(1.0, abs=0.04)
    assert z_plain.var() > 2.0
    back = load_capture(cap.save(tmp_path / "fpn.capture.npz"))
    again = observations(back, variance_from="estimate", radiance_estimate=truth)
    np.testing.assert_array_equal(again.radiance, obs.radiance)
    np.testing.assert_array_equal(again.variance, obs.variance)


# a constant light field at the automatic radiance scale saturates 37 % of the ISO-100 pixels: a
# legitimate SaturationWarning (tests/test_warnings.py), not what this test is about
@pytest.mark.filterwarnings("ignore::lfproc.errors.SaturationWarning")
def test_capture_file_keeps_a_measured_profiles_maps(tmp_path):
    """A measured profile's flat field and bias frames travel inside the capture file (the JSON header
    cannot hold them), so observations after loading equal those before."""
    truth = _profile(0.02, 3.0)
    rng = np.random.default_rng(2)
    flat = (1 + 0.02 * rng.standard_normal(SHAPE)).astype(np.float32)
    bias = {iso: (64 + rng.normal(0, 0.7, SHAPE)).astype(np.float32) for iso in (100, 400)}
    measured = replace(truth, source={"kind": "calibrated"}, flat_field=flat, flat_field_std=0.002, bias_frames=bias,
                       bias_frame_std_dn={100: 0.1, 400: 0.2})
    iso = np.where(np.arange(SHAPE[0])[:, None] % 4 < 2, 100.0, 400.0) * np.ones(SHAPE)
    fp = fixed_pattern_correction(measured, SHAPE, iso)
    assert fp.gain_source == "flat_field" and fp.offset_source == "bias_frames (ISO 100, 400)"
    np.testing.assert_allclose(fp.gain_var, 0.002**2)
    h = np.where(iso == 100, truth.isos[100].gain_dn_per_e, truth.isos[400].gain_dn_per_e)
    np.testing.assert_allclose(fp.offset_var_e2, (np.where(iso == 100, 0.1, 0.2) / h) ** 2)
    want = np.where(iso == 100, (bias[100] - bias[100].mean()) / h, (bias[400] - bias[400].mean()) / h)
    np.testing.assert_allclose(fp.offset_e, want, atol=1e-4)  # float32 frames
    lf = np.full((5, 5, *SHAPE, 3), 0.5, np.float32)
    np.save(tmp_path / "iso.npy", iso)
    cap = simulate_capture(lf, profile=measured, iso_pattern_kind=tmp_path / "iso.npy", shots=1, mask_period=4,
                           random_state=1)
    back = load_capture(cap.save(tmp_path / "m.capture.npz"))
    np.testing.assert_array_equal(back.profile.flat_field, flat)
    assert sorted(back.profile.bias_frames) == [100, 400] and back.profile.bias_frame_std_dn == {100: 0.1, 400: 0.2}
    a, b = observations(cap), observations(back)
    np.testing.assert_array_equal(a.radiance, b.radiance)
    np.testing.assert_array_equal(a.variance, b.variance)
    # the simulated sensor of a measured profile is the measured one: T is corrected with its own maps
    truth_lf = cap.operator(dtype=np.float64).forward(lf.astype(np.float64)) * cap.radiance_scale
    obs = observations(cap, variance_from="estimate", radiance_estimate=truth_lf)
    ok = obs.weight > 0
    z = ((obs.radiance - truth_lf) * obs.weight)[ok]
    assert abs(z.mean()) < 4.5 / np.sqrt(z.size) and z.var() < 1.05
