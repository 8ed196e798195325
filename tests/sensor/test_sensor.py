"""The sensor model: known noiseless codes, saturation with a calibrated black level, validation."""

from dataclasses import replace

import numpy as np
import pytest

from lfproc.sensor import load_profile
from lfproc.errors import InputError, ProfileError, ShapeError
from lfproc.sensor import calibrated_observation, expose


def test_noiseless_codes_follow_the_formula():
    p = load_profile("paper-none")
    E = np.array([[0.0, 1e4, 1e5, 1e7]])
    dn = expose(E, exposure_s=0.004, iso=400, profile=p, noise=False)
    h = 4 * 4095 / 20000
    expected = np.minimum(4095, np.rint(h * np.minimum(E * 0.004, 20000) + 64))
    np.testing.assert_array_equal(dn, expected)
    # gamma: the power law acts on the signal normalised to I_max
    dn_g = expose(E, exposure_s=0.004, iso=400, profile=p, noise=False, gamma=2.2)
    expected_g = np.minimum(4095, np.rint(4095 * (h * E * 0.004 / 4095) ** (1 / 2.2) + 64))
    np.testing.assert_array_equal(dn_g, expected_g)
    obs = calibrated_observation(dn_g, exposure_s=0.004, iso=400, profile=p, gamma=2.2)
    np.testing.assert_allclose(obs.radiance[0, 1:3], E[0, 1:3], rtol=0.01)
    assert obs.saturated.tolist() == [[False, False, False, True]] and obs.weight[0, 3] == 0


def test_fractional_black_level_still_saturates_at_white():
    p = load_profile("paper-none")
    iso = {k: replace(f, black_level_dn=63.9974) for k, f in p.isos.items()}
    p = replace(p, isos=iso)
    dn = expose(np.full((1, 3), 1e9), exposure_s=0.004, iso=400, profile=p, noise=False)
    assert dn.tolist() == [[4095, 4095, 4095]] and p.saturation_dn(400) == 4095
    obs = calibrated_observation(dn, exposure_s=0.004, iso=400, profile=p)
    assert obs.saturated.all() and not obs.weight.any()


def test_unbiased_and_variance_matches_per_iso_map():
    p = load_profile("paper-high")
    rng = np.random.default_rng(0)
    iso = rng.choice([100, 400, 1600], size=(300, 300))
    E = np.full(iso.shape, 2e4)
    dn = expose(E, exposure_s=0.004, iso=iso, profile=p, random_state=1)
    obs = calibrated_observation(dn, exposure_s=0.004, iso=iso, profile=p, variance_from="estimate",
                                 radiance_estimate=E)
    for value in (100, 400, 1600):
        sel = iso == value
        z = (obs.radiance[sel] - E[sel]) * obs.weight[sel]
        assert abs(z.mean()) < 4 / np.sqrt(sel.sum())
        assert 0.95 < z.var() < 1.05


def test_bad_inputs():
    p = load_profile("paper-low")
    with pytest.raises(InputError, match="exposure_s"):
        expose(np.ones((2, 2)), exposure_s=0, iso=100, profile=p)
    with pytest.raises(ShapeError, match=r"\(H, W\)"):
        expose(np.ones((2, 2, 3)), exposure_s=1, iso=100, profile=p)
    with pytest.raises(InputError, match="non-negative"):
        expose(-np.ones((2, 2)), exposure_s=1, iso=100, profile=p)
    with pytest.raises(ProfileError, match="ISO 123 is not in camera profile 'paper-low'"):
        expose(np.ones((2, 2)), exposure_s=1, iso=123, profile=p)
    with pytest.raises(InputError, match="gamma"):
        expose(np.ones((2, 2)), exposure_s=1, iso=100, profile=p, gamma=0.5)


@pytest.mark.parametrize("name", ["paper-none", "paper-low", "paper-medium"])
def test_read_floor_adds_the_missing_read_noise_only(name):
    """Known answer (reference: the profile's read noise from lfproc.sensor.iso_maps and the variance without the
    floor): ``read_floor_e=F`` adds ``(F^2 - read^2) / (t g)^2`` where the read noise is below F (paper-none: 0 e-;
    its flat field g is 1) and leaves the observation bit for bit where it is not (paper-low 1.1 e-, -medium 2.0)."""
    from lfproc.sensor import iso_maps

    p = load_profile(name)
    rng = np.random.default_rng(2)
    iso = rng.choice([100, 1600], size=(40, 40))
    dn = expose(rng.uniform(0, 2e3, iso.shape), exposure_s=0.004, iso=iso, profile=p, random_state=2)
    plain = calibrated_observation(dn, exposure_s=0.004, iso=iso, profile=p)
    floored = calibrated_observation(dn, exposure_s=0.004, iso=iso, profile=p, read_floor_e=1.0)
    read = iso_maps(p, iso, iso.shape)["read_noise_e"]
    np.testing.assert_array_equal(floored.radiance, plain.radiance)
    if read.min() >= 1.0:
        np.testing.assert_array_equal(floored.variance, plain.variance)
        np.testing.assert_array_equal(floored.weight, plain.weight)
        return
    want = plain.variance.astype(np.float64) + (1.0 - read ** 2) / 0.004 ** 2
    np.testing.assert_allclose(floored.variance, want, rtol=1e-5)
    usable = plain.weight > 0
    np.testing.assert_allclose(floored.weight[usable], 1 / np.sqrt(want[usable]), rtol=1e-5)


@pytest.mark.parametrize("value, expected", [(-1.0, "a non-negative finite number, got -1.0"),
                                             (float("nan"), "a non-negative finite number, got nan"),
                                             ("one", "a number, got 'one'")])
def test_a_bad_read_floor_is_one_line(value, expected):
    with pytest.raises(InputError, match=rf"^read_floor_e: expected {expected}$"):
        calibrated_observation(np.full((2, 2), 100), exposure_s=0.01, iso=100, profile="paper-low",
                               read_floor_e=value)
