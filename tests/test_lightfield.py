"""The light-field type: validation, helpers and their known answers."""

import numpy as np
import pytest

from lfproc import LightField
from lfproc.errors import InputError, LfprocError, ShapeError
from lfproc.lightfield import clean_nonfinite, luminance


def make_lf(v=3, u=5, h=6, w=7, c=3, seed=0):
    rng = np.random.default_rng(seed)
    return LightField(rng.uniform(0.1, 1.0, size=(v, u, h, w, c)).astype(np.float32))


def test_shape_properties_and_dtype():
    lf = LightField(np.ones((3, 5, 6, 7, 3), dtype=np.float64))
    assert lf.data.dtype == np.float32
    assert lf.shape == (3, 5, 6, 7, 3)
    assert lf.views == (3, 5) and lf.size == (6, 7) and lf.channels == 3
    assert lf.centre_index == (1, 2)


@pytest.mark.parametrize(
    "array, match",
    [
        (np.ones((5, 5, 4, 4)), "5 axes"),
        (np.ones((5, 5, 0, 4, 3)), "at least one element"),
        (np.array([[[[["a"]]]]]), "numeric"),
    ],
)
def test_bad_shapes_are_refused(array, match):
    with pytest.raises(ShapeError, match=match):
        LightField(array)


def test_nonfinite_and_negative_are_refused_with_counts():
    data = np.ones((1, 1, 2, 2, 3), dtype=np.float32)
    data[0, 0, 0, 0, 0] = np.nan
    data[0, 0, 1, 1, 2] = np.inf
    with pytest.raises(InputError, match="1 NaN and 1 Inf"):
        LightField(data)
    neg = np.ones((1, 1, 2, 2, 1), dtype=np.float32)
    neg[0, 0, 0, 0, 0] = -0.5
    with pytest.raises(InputError, match="1 negative"):
        LightField(neg)
    # the tree: one base class, builtin-compatible leaves
    assert issubclass(InputError, LfprocError) and issubclass(InputError, ValueError)


def test_clean_nonfinite_policies_do_not_modify_input():
    data = np.array([1.0, np.nan, np.inf, -np.inf, -2.0, 3.0], dtype=np.float32)
    before = data.copy()
    zero, counts = clean_nonfinite(data, policy="zero", negative="keep")
    assert counts == {"nan": 1, "inf": 2, "negative": 1}
    np.testing.assert_array_equal(zero, [1, 0, 0, 0, -2, 3])
    clip, _ = clean_nonfinite(data, policy="clip", negative="clip")
    np.testing.assert_array_equal(clip, [1, 0, 3, 0, 0, 3])
    np.testing.assert_array_equal(np.isnan(data), np.isnan(before))
    with pytest.raises(InputError, match="nonfinite"):
        clean_nonfinite(data, policy="bogus")


def test_variance_and_disparity_shapes_checked():
    data = np.ones((3, 3, 4, 5, 3))
    with pytest.raises(ShapeError, match="variance"):
        LightField(data, variance=np.ones((3, 3, 4, 4, 3)))
    with pytest.raises(ShapeError, match="disparity"):
        LightField(data, disparity=np.ones((5, 4)))
    with pytest.raises(InputError, match="units"):
        LightField(data, units="lux")
    with pytest.raises(InputError, match="exposure_s"):
        LightField(data, exposure_s=-1)


def test_views_crop_central_and_epi_known_answers():
    v, u, h, w = 5, 5, 8, 10
    # value encodes (v, u, y, x) so every slice has a known answer
    grid = np.indices((v, u, h, w)).astype(np.float32)
    data = (grid[0] * 1000 + grid[1] * 100 + grid[2] * 10 + grid[3] * 0.1)[..., None] + 1
    lf = LightField(data, disparity=np.zeros((h, w)))
    assert lf.centre()[3, 4, 0] == pytest.approx(1 + 2000 + 200 + 30 + 0.4)
    assert lf.view(-1, 0)[0, 0, 0] == pytest.approx(1 + 4000)
    crop = lf.crop(2, 3, 4, 5)
    assert crop.size == (4, 5) and crop.disparity.shape == (4, 5)
    assert crop.data[0, 0, 0, 0, 0] == pytest.approx(1 + 20 + 0.3)
    c3 = lf.central(3)
    assert c3.views == (3, 3)
    np.testing.assert_array_equal(c3.centre(), lf.centre())
    epi = lf.epi(index=2)
    assert epi.shape == (u, w, 1)
    np.testing.assert_allclose(epi[:, 0, 0], 1 + 2000 + np.arange(u) * 100 + 20)
    vepi = lf.epi(axis="vertical", index=7)
    assert vepi.shape == (v, h, 1)
    np.testing.assert_allclose(vepi[:, 0, 0], 1 + np.arange(v) * 1000 + 200 + 0.7, rtol=1e-6)
    with pytest.raises(InputError, match="crop"):
        lf.crop(5, 0, 4, 4)
    with pytest.raises(InputError, match="central"):
        lf.central(7)
    with pytest.raises(InputError, match="view index"):
        lf.view(5, 0)
    with pytest.raises(InputError, match="epi axis"):
        lf.epi(axis="diagonal")


def test_dynamic_range_and_saturation():
    # luminance spans exactly 2^-8 .. 2^8 in equal parts: robust range with 0/100 percentiles is 16 stops
    values = np.repeat(2.0 ** np.arange(-8, 9), 4).astype(np.float32)
    lf = LightField(np.broadcast_to(values[None, None, None, :, None], (1, 1, 2, values.size, 3)).copy())
    assert lf.dynamic_range_stops(low_percentile=0, high_percentile=100) == pytest.approx(16.0)
    assert 15.0 < lf.dynamic_range_stops() <= 16.0
    assert lf.saturated_fraction() is None  # no clipping level known: not guessed
    assert lf.saturated_fraction(level=2.0**8) == pytest.approx(4 / values.size)
    sat = lf.replace(saturation_level=1.0)
    assert sat.saturated_fraction() == pytest.approx(9 * 4 / values.size)
    assert LightField(np.zeros((1, 1, 2, 2, 3))).dynamic_range_stops() == 0.0


def test_luminance_weights():
    rgb = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
    np.testing.assert_allclose(luminance(rgb), [0.2126, 0.7152, 0.0722, 1.0], rtol=1e-6)
    with pytest.raises(ShapeError, match="1 or 3"):
        luminance(np.ones((2, 2)))


def test_replace_is_validated_and_original_unchanged():
    lf = make_lf()
    other = lf.replace(units="e-/s", exposure_s=0.01)
    assert lf.units == "relative" and other.units == "e-/s"
    with pytest.raises(InputError):
        lf.replace(iso=0)
