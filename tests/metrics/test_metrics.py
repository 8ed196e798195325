"""PU21/PU2 encodings and the HDR quality metrics of lfproc.metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from lfproc import LightField, read_lightfield
from lfproc.errors import InputError, ShapeError
from lfproc.metrics import (
    PU21_VARIANTS, evaluate, log_psnr, mean_relative_error, metric_luminance, psnr, pu2_encode, pu2_psnr,
    pu21_decode, pu21_encode, pu21_psnr, pu21_ssim,
)

# Published constants (gfxdisp/pu21 pu21_encoder.m), written out again here on purpose.
PUBLISHED = {
    "banding": [1.070275272, 0.4088273932, 0.153224308, 0.2520326168, 1.063512885, 1.14115047, 521.4527484],
    "banding_glare": [0.353487901, 0.3734658629, 8.277049286e-05, 0.9062562627, 0.09150303166, 0.9099517204,
                      596.3148142],
    "peaks": [1.043882782, 0.6459495343, 0.3194584211, 0.374025247, 1.114783422, 1.095360363, 384.9217577],
    "peaks_glare": [816.885024, 1479.463946, 0.001253215609, 0.9329636822, 0.06746643971, 1.573435413,
                    419.6006374],
}


def reference_pu21(y, variant):
    p = PUBLISHED[variant]
    y = np.minimum(np.maximum(np.asarray(y, dtype=np.float64), 0.005), 10000.0)
    return p[6] * (((p[0] + p[1] * y ** p[3]) / (1 + p[2] * y ** p[3])) ** p[4] - p[5])


def reference_pu2(y):
    """HDR Toolbox pu2_encode.m, step by step (loop form of the LUT, as in the MATLAB)."""
    l_lut = np.linspace(-5, 10, 2**12)
    lum = 10.0 ** l_lut
    s = 30.162 * ((4.0627 / lum) ** 1.6596 + 1) ** -0.2712
    thr = lum / s
    dl = np.array([1 / thr[k] * lum[k] * math.log(10) for k in range(lum.size)])
    jnd = cumulative_trapezoid(dl, l_lut, initial=0)
    l = np.log10(np.clip(y, 1e-5, 1e10))
    return 255 * (np.interp(l, l_lut, jnd) - 31.9270) / (149.9244 - 31.9270)


# -- PU21 ----------------------------------------------------------------------------------------

@pytest.mark.parametrize(
    "lum, expected",
    [(0.005, 0.0), (0.1, 5.72), (1, 36.5), (10, 123.6), (80, 242.0), (100, 256.4), (1000, 420.1),
     (4000, 527.5), (10000, 595.4)],
)
def test_pu21_known_values(lum, expected):
    assert float(pu21_encode(lum)) == pytest.approx(expected, abs=0.051)


@pytest.mark.parametrize("variant", PU21_VARIANTS)
def test_pu21_matches_published_formula(variant):
    y = np.geomspace(1e-4, 3e4, 2001)  # includes values clamped at both ends
    np.testing.assert_allclose(pu21_encode(y, variant=variant), reference_pu21(y, variant), rtol=0, atol=1e-6)


@pytest.mark.parametrize("variant", PU21_VARIANTS)
def test_pu21_round_trip_and_monotonic(variant):
    y = np.geomspace(0.005, 10000, 501)
    v = pu21_encode(y, variant=variant)
    assert np.all(np.diff(v) > 0)
    np.testing.assert_allclose(pu21_decode(v, variant=variant), y, rtol=1e-9)
    # outside the range: clamped; decoding out-of-range values stays inside [0.005, 1e4]
    assert pu21_encode([1e-6, 1e6], variant=variant) == pytest.approx(v[[0, -1]])
    assert pu21_decode([-50.0, 5000.0], variant=variant) == pytest.approx([0.005, 10000.0])


def test_pu21_shapes_dtypes_and_input_untouched():
    lf = np.full((2, 3, 4, 5), 100.0, dtype=np.float32)
    before = lf.copy()
    out = pu21_encode(lf)
    assert out.shape == lf.shape and out.dtype == np.float64
    np.testing.assert_array_equal(lf, before)
    assert pu21_encode(100).shape == ()
    assert pu21_encode(np.array([100], dtype=np.uint16)) == pytest.approx(256.38, abs=0.01)
    # batched over views equals one view at a time
    rng = np.random.default_rng(1)
    y = rng.uniform(0, 2000, (3, 3, 8, 8))
    np.testing.assert_array_equal(pu21_encode(y)[1, 2], pu21_encode(y[1, 2]))


def test_pu21_bad_inputs():
    with pytest.raises(InputError, match="variant: expected one of banding_glare"):
        pu21_encode(1.0, variant="glare")
    with pytest.raises(InputError, match="luminance_cd_m2: contains NaN"):
        pu21_encode([1.0, np.nan])
    with pytest.raises(InputError, match="pu_values: expected a numeric array"):
        pu21_decode(np.array(["a"]))


# -- PU2 -----------------------------------------------------------------------------------------

@pytest.mark.parametrize(
    "lum, expected",
    [(0.8, 0.0), (80, 255.0), (100, 269.5), (1000, 419.6), (4000, 509.9), (10000, 569.6), (0.01, -59.7)],
)
def test_pu2_known_values(lum, expected):
    assert float(pu2_encode(lum)) == pytest.approx(expected, abs=0.06)


def test_pu2_matches_toolbox_formula():
    y = np.geomspace(1e-6, 1e11, 777)
    np.testing.assert_allclose(pu2_encode(y), reference_pu2(y), rtol=0, atol=1e-6)
    assert np.all(np.diff(pu2_encode(np.geomspace(1e-5, 1e10, 300))) > 0)


# -- PSNR / SSIM ---------------------------------------------------------------------------------

@pytest.fixture
def hdr_image():
    rng = np.random.default_rng(7)
    # a smooth HDR luminance image over ~14 stops with texture, relative units
    yy, xx = np.mgrid[0:48, 0:64]
    base = 2.0 ** (14 * xx / 63 - 10) * (1 + 0.3 * np.sin(yy / 3.0))
    return base * rng.uniform(0.8, 1.2, base.shape)


def test_identical_images_give_inf_and_one(hdr_image):
    assert pu21_psnr(hdr_image, hdr_image) == math.inf
    assert pu2_psnr(hdr_image, hdr_image) == math.inf
    assert log_psnr(hdr_image, hdr_image) == math.inf
    assert pu21_ssim(hdr_image, hdr_image) == 1.0
    assert mean_relative_error(hdr_image, hdr_image) == 0.0
    assert psnr(hdr_image, hdr_image, data_range=1.0) == math.inf


def test_pu21_psnr_equals_its_definition(hdr_image):
    rng = np.random.default_rng(3)
    noisy = hdr_image * (1 + 0.05 * rng.standard_normal(hdr_image.shape))
    factor = 4000 / hdr_image.max()
    p_t = reference_pu21(np.clip(noisy, 0, None) * factor, "banding_glare")
    p_r = reference_pu21(hdr_image * factor, "banding_glare")
    expected = 10 * math.log10(256**2 / np.mean((p_t - p_r) ** 2))
    assert pu21_psnr(noisy.clip(0), hdr_image, peak_luminance=4000) == pytest.approx(expected, abs=1e-9)
    # PU2 with the peak PU2(peak luminance)
    q_t, q_r = reference_pu2(np.clip(noisy, 0, None) * factor), reference_pu2(hdr_image * factor)
    expected2 = 10 * math.log10(float(reference_pu2(4000.0)) ** 2 / np.mean((q_t - q_r) ** 2))
    assert pu2_psnr(noisy.clip(0), hdr_image, peak_luminance=4000) == pytest.approx(expected2, abs=1e-6)


def test_psnr_scale_invariance_and_absolute_mode(hdr_image):
    noisy = hdr_image * 1.1
    a = pu21_psnr(noisy, hdr_image)
    assert pu21_psnr(noisy * 37.0, hdr_image * 37.0) == pytest.approx(a, abs=1e-9)  # same factor on both
    absolute = hdr_image / hdr_image.max() * 1000
    assert pu21_psnr(absolute * 1.1, absolute, peak_luminance=None) == pytest.approx(a, abs=1e-9)
    # a uniform error of d decades in log-PSNR: 20 log10(peak / d) where no value is clamped
    bright = np.full((16, 16), 500.0)
    d = math.log10(1.1)
    expected = 20 * math.log10(math.log10(1000 / 0.005) / d)
    assert log_psnr(bright * 1.1, bright, peak_luminance=1000) == pytest.approx(expected, abs=1e-9)


def test_more_noise_lower_psnr_and_ssim(hdr_image):
    rng = np.random.default_rng(11)
    z = rng.standard_normal(hdr_image.shape)
    figures = []
    for sigma in (0.01, 0.05, 0.2):
        noisy = np.clip(hdr_image * (1 + sigma * z), 0, None)
        figures.append((pu21_psnr(noisy, hdr_image), pu21_ssim(noisy, hdr_image), pu2_psnr(noisy, hdr_image),
                        log_psnr(noisy, hdr_image), -mean_relative_error(noisy, hdr_image)))
    for better, worse in zip(figures, figures[1:]):
        assert all(b > w for b, w in zip(better, worse)), (better, worse)
    assert 0 < figures[-1][1] < figures[0][1] < 1


def test_colour_input_uses_pu21_weights(hdr_image):
    rgb = np.stack([hdr_image, hdr_image * 0.5, hdr_image * 2], axis=-1)
    y = metric_luminance(rgb, channel_axis=-1)
    np.testing.assert_allclose(y, hdr_image * (0.212656 + 0.715158 * 0.5 + 0.072186 * 2))
    noisy = rgb * np.array([1.0, 1.05, 1.0])
    # colour input: scale from max over every channel of the reference, then luminance
    factor = 1000 / rgb.max()
    expected = 10 * math.log10(256**2 / np.mean(
        (reference_pu21(metric_luminance(noisy, channel_axis=-1) * factor, "banding_glare")
         - reference_pu21(y * factor, "banding_glare")) ** 2))
    assert pu21_psnr(noisy, rgb, channel_axis=-1) == pytest.approx(expected, abs=1e-9)


def test_ssim_matches_skimage_settings(hdr_image):
    from skimage.metrics import structural_similarity

    noisy = hdr_image * np.random.default_rng(5).uniform(0.9, 1.1, hdr_image.shape)
    f = 1000 / hdr_image.max()
    expected = structural_similarity(reference_pu21(noisy * f, "banding_glare"),
                                     reference_pu21(hdr_image * f, "banding_glare"), data_range=256,
                                     gaussian_weights=True, sigma=1.5, use_sample_covariance=False)
    assert pu21_ssim(noisy, hdr_image) == pytest.approx(expected, abs=1e-12)
    # a stack of images: mean of the per-image SSIM
    stack_r = np.stack([hdr_image, hdr_image])
    stack_t = np.stack([noisy, hdr_image])
    assert pu21_ssim(stack_t, stack_r) == pytest.approx((pu21_ssim(noisy, hdr_image, peak_luminance=1000) + 1) / 2)


def test_mean_relative_error_definition():
    ref = np.array([0.0, 1.0, 2.0, 4.0])
    res = np.array([0.01, 1.1, 2.0, 3.0])
    eps = 1e-3 * 4.0
    expected = np.mean(np.abs(res - ref) / (ref + eps))
    assert mean_relative_error(res, ref) == pytest.approx(expected)
    assert mean_relative_error(res * 3, ref * 3) == pytest.approx(expected)  # scale-free


def test_array_metric_errors(hdr_image):
    with pytest.raises(ShapeError, match=r"same shape, got \(48, 64\) and \(48, 63\)"):
        pu21_psnr(hdr_image, hdr_image[:, :63])
    with pytest.raises(InputError, match="reference: maximum value is 0; expected a positive peak"):
        pu21_psnr(hdr_image, np.zeros_like(hdr_image))
    with pytest.raises(InputError, match="peak_luminance: expected a positive finite number"):
        pu21_ssim(hdr_image, hdr_image, peak_luminance=-5)
    with pytest.raises(ShapeError, match="at least 11x11 pixels"):
        pu21_ssim(hdr_image[:8, :8], hdr_image[:8, :8])
    with pytest.raises(InputError, match="result: contains NaN"):
        log_psnr(np.full_like(hdr_image, np.nan), hdr_image)
    with pytest.raises(ShapeError, match="expected 1 or 3 colour channels"):
        pu21_psnr(np.ones((12, 12, 2)), np.ones((12, 12, 2)), channel_axis=-1)


# -- evaluate on light fields --------------------------------------------------------------------

@pytest.fixture(scope="module", params=["synthetic", "real"])
def bedroom(request):
    """A 5x5 light field: a synthetic HDR scene, and the real HCI bedroom when the shared data is there."""
    if request.param == "synthetic":
        from lfproc.synth import synthesize

        return synthesize("layers", size=(32, 48), views=5, random_state=1)
    return read_lightfield(request.getfixturevalue("shared_data") / "lightfields/lowres_5x5/hci_bedroom")


def _noisy(lf: LightField, sigma: float, seed: int) -> LightField:
    rng = np.random.default_rng(seed)
    data = np.clip(lf.data * (1 + sigma * rng.standard_normal(lf.shape, dtype=np.float32)), 0, None)
    return lf.replace(data=data)


def test_evaluate_identity_and_keys(bedroom):
    out = evaluate(bedroom, bedroom)
    for key in ("pu21_psnr_db", "pu2_psnr_db", "log_psnr_db"):
        assert out[key] == math.inf
    assert out["pu21_ssim"] == 1.0 and out["mean_relative_error"] == 0.0
    assert len(out["views"]) == 25
    assert out["views"][7]["v"] == 1 and out["views"][7]["u"] == 2
    assert out["peak_luminance_cd_m2"] == pytest.approx(1000.0)
    assert out["pu2_psnr_peak"] == pytest.approx(419.6, abs=0.05)


def test_evaluate_per_view_matches_array_functions(bedroom):
    noisy = _noisy(bedroom, 0.05, seed=2)
    out = evaluate(noisy, bedroom, peak_luminance=4000)
    factor = 4000 / float(bedroom.data.max())
    assert out["scale_factor"] == pytest.approx(factor)
    for row in (out["views"][0], out["views"][12], out["views"][24]):
        t, r = noisy.data[row["v"], row["u"]], bedroom.data[row["v"], row["u"]]
        # array functions scale by max of their own reference; pass absolute values instead
        t_abs, r_abs = t.astype(np.float64) * factor, r.astype(np.float64) * factor
        kw = dict(peak_luminance=None, channel_axis=-1)
        assert row["pu21_psnr_db"] == pytest.approx(pu21_psnr(t_abs, r_abs, **kw), abs=1e-9)
        assert row["pu21_ssim"] == pytest.approx(pu21_ssim(t_abs, r_abs, **kw), abs=1e-12)
        assert row["mean_relative_error"] == pytest.approx(
            mean_relative_error(t, r, epsilon_relative=1e-3 * bedroom.data.max() / r.max()), rel=1e-6)
    means = {k: np.mean([v[k] for v in out["views"]]) for k in ("pu21_psnr_db", "pu21_ssim", "log_psnr_db")}
    for key, value in means.items():
        assert out[key] == pytest.approx(value)


def test_evaluate_more_noise_lower_psnr(bedroom):
    results = [evaluate(_noisy(bedroom, s, seed=4), bedroom) for s in (0.01, 0.04, 0.16)]
    for key in ("pu21_psnr_db", "pu21_ssim", "pu2_psnr_db", "log_psnr_db"):
        values = [r[key] for r in results]
        assert values[0] > values[1] > values[2], (key, values)
    errors = [r["mean_relative_error"] for r in results]
    assert errors[0] < errors[1] < errors[2]
    # small noise: the PU and log encodings are locally linear, so 4 x the noise costs
    # 20 log10(4) = 12.04 dB
    for key in ("pu21_psnr_db", "log_psnr_db"):
        assert results[0][key] - results[1][key] == pytest.approx(20 * math.log10(4), abs=0.1)
    # log-PSNR of 1 % noise per channel: the luminance error is 0.01 sqrt(sum of the squared
    # luminance weights) relative, i.e. that / ln 10 decades, against a peak of log10(1000 / 0.005)
    # decades (a little higher in practice: samples below 0.005 cd/m^2 are clipped alike)
    rms = 0.01 * math.sqrt(0.212656**2 + 0.715158**2 + 0.072186**2) / math.log(10)
    expected = 20 * math.log10(math.log10(1000 / 0.005) / rms)  # 64.24 dB
    assert expected - 0.1 < results[0]["log_psnr_db"] < expected + 0.6


def test_evaluate_mismatches(bedroom):
    with pytest.raises(ShapeError, match="result has 3x3 views, reference 5x5"):
        evaluate(bedroom.central(3), bedroom)
    h, w = bedroom.size
    with pytest.raises(ShapeError, match=f"result has 5x5 views of {h // 2}x{w}x3, reference 5x5 views of {h}x{w}x3"):
        evaluate(bedroom.crop(0, 0, h // 2, w), bedroom)
    with pytest.raises(InputError, match="result is in 'e-/s', reference in 'relative'"):
        evaluate(bedroom.replace(units="e-/s"), bedroom)
    with pytest.raises(InputError, match="all-black reference"):
        evaluate(bedroom, bedroom.replace(data=np.zeros(bedroom.shape, np.float32)))
    with pytest.raises(InputError, match="differ by 8 stops, more than 4"):
        evaluate(bedroom.replace(data=bedroom.data * 256), bedroom)
    assert evaluate(bedroom.replace(data=bedroom.data * 256), bedroom, scale_tolerance_stops=None)["pu21_ssim"] < 1
    with pytest.raises(InputError, match="peak_luminance=None needs absolute luminance"):
        evaluate(bedroom, bedroom, peak_luminance=None)
    with pytest.raises(InputError, match="result must be a LightField"):
        evaluate(bedroom.data, bedroom)


def test_evaluate_absolute_luminance_lightfield():
    rng = np.random.default_rng(0)
    data = rng.uniform(0.01, 3000, (2, 2, 12, 12, 1)).astype(np.float32)
    ref = LightField(data=data, units="cd/m2", colour_space="luminance")
    res = ref.replace(data=data * 1.01)
    out = evaluate(res, ref, peak_luminance=None)
    assert out["scale_factor"] == 1.0
    assert out["peak_luminance_cd_m2"] == pytest.approx(float(data.max()))
    expected = pu21_psnr(data[1, 0, ..., 0] * 1.01, data[1, 0, ..., 0], peak_luminance=None)
    assert out["views"][2]["pu21_psnr_db"] == pytest.approx(expected, rel=1e-6)


def test_integer_inputs_do_not_wrap():
    a = np.array([[10, 200]], dtype=np.uint8)
    b = np.array([[20, 190]], dtype=np.uint8)
    assert psnr(a, b, data_range=255) == pytest.approx(10 * math.log10(255**2 / 100))
    assert mean_relative_error(a, b) == pytest.approx(np.mean([10 / (20 + 0.19), 10 / (190 + 0.19)]))
    assert pu21_psnr(a, b) == pytest.approx(pu21_psnr(a.astype(float), b.astype(float)))


# -- hdr_figures: error in stops per decade, zeros, highlight energy, detail ----------------------

@pytest.fixture
def hdr_lf():
    """A (2, 3, 24, 32, 3) HDR light field over ~8 decades with texture, every sample positive."""
    rng = np.random.default_rng(11)
    yy, xx = np.mgrid[0:24, 0:32]
    base = 10.0 ** (8 * xx / 31 - 4) * (1 + 0.4 * np.sin(yy / 2.0))
    data = base[None, None, :, :, None] * rng.uniform(0.7, 1.3, (2, 3, 24, 32, 3))
    return LightField(data=data.astype(np.float32))


def test_hdr_figures_identity(hdr_lf):
    from lfproc.metrics import hdr_figures

    out = hdr_figures(hdr_lf, hdr_lf)
    assert out["max_decade_stops"] == 0.0
    assert all(d["median_stops"] == 0.0 for d in out["stops_by_decade"])
    assert sum(d["samples"] for d in out["stops_by_decade"]) == 2 * 3 * 24 * 32
    assert out["zeros_above_floor"] == 0.0
    assert out["highlight_energy"] == 1.0
    assert out["detail_ratio"] == 0.0
    assert out["emitter_share"] == 0.0 and out["emitters_dominate"] is False
    # the decades are those of the reference luminance, ascending
    y = metric_luminance(hdr_lf.data.astype(np.float64))
    lo = [d["decade"][0] for d in out["stops_by_decade"]]
    assert lo == sorted(lo)
    assert lo[0] == pytest.approx(10.0 ** math.floor(math.log10(y.min())))
    assert out["stops_by_decade"][-1]["decade"][1] == pytest.approx(10.0 ** (math.floor(math.log10(y.max())) + 1))


def test_hdr_figures_report_the_samples_below_the_floor_apart(hdr_lf):
    """Known answer: a result one stop too bright at and below the floor (the reference's median luminance), exact
    above it: the decades above read 0 stops, those below 1 stop, and every positive sample is in one or the other;
    without a floor there is nothing below it."""
    from lfproc.metrics import hdr_figures

    y = metric_luminance(hdr_lf.data.astype(np.float64))
    floor = float(np.median(y))
    res = np.where((y <= floor)[..., None], 2.0 * hdr_lf.data, hdr_lf.data)
    out = hdr_figures(res, hdr_lf.data, noise_floor=floor)
    assert out["max_decade_stops"] == 0.0
    assert [d["median_stops"] for d in out["stops_below_floor"]] == pytest.approx([1.0] * len(out["stops_below_floor"]))
    assert sum(d["samples"] for d in out["stops_below_floor"]) == np.count_nonzero(y <= floor)
    assert out["samples_above_floor"] + np.count_nonzero(y <= floor) == y.size
    assert out["stops_below_floor"][-1]["decade"][0] <= floor < out["stops_below_floor"][-1]["decade"][1]
    assert hdr_figures(res, hdr_lf.data)["stops_below_floor"] == []


def test_hdr_figures_twice_as_bright(hdr_lf):
    from lfproc.metrics import hdr_figures

    out = hdr_figures(2.0 * hdr_lf.data, hdr_lf.data)  # arrays as well as light fields
    for d in out["stops_by_decade"]:
        assert d["median_stops"] == pytest.approx(1.0, abs=1e-6)
    assert out["max_decade_stops"] == pytest.approx(1.0, abs=1e-6)
    assert out["highlight_energy"] == pytest.approx(2.0, rel=1e-6)
    assert out["zeros_above_floor"] == 0.0
    assert 0 < out["detail_ratio"]


def test_hdr_figures_blurred_detail_ratio(hdr_lf):
    from scipy.ndimage import gaussian_filter, laplace

    from lfproc.metrics import hdr_figures

    blurred = gaussian_filter(hdr_lf.data.astype(np.float64), sigma=(0, 0, 1.0, 1.0, 0))
    out = hdr_figures(blurred, hdr_lf.data, peak_luminance=500.0)
    # the definition written out again: PU21 (published formula) of the luminance scaled by
    # 500 / max(reference), squared Laplacian of every view, summed
    factor = 500.0 / float(hdr_lf.data.max())
    p_res = reference_pu21(metric_luminance(blurred) * factor, "banding_glare")
    p_ref = reference_pu21(metric_luminance(hdr_lf.data.astype(np.float64)) * factor, "banding_glare")
    num = sum(np.sum(laplace(p_res[v, u] - p_ref[v, u]) ** 2) for v in range(2) for u in range(3))
    den = sum(np.sum(laplace(p_ref[v, u]) ** 2) for v in range(2) for u in range(3))
    assert 0.0 < out["detail_ratio"] < 1.0
    assert out["detail_ratio"] == pytest.approx(num / den, rel=1e-9)
    # a flat (mean) result recovers no detail at all: ratio ~1
    flat = np.broadcast_to(hdr_lf.data.mean(axis=(2, 3), keepdims=True), hdr_lf.shape)
    assert hdr_figures(flat, hdr_lf.data)["detail_ratio"] == pytest.approx(1.0, abs=0.05)


def test_hdr_figures_detail_off_highlights():
    """A light right and a grainy background: ``detail_ratio`` is small because the light holds most of the
    reference's fine detail; away from it the grain is counted (known answer: the definition written out with the
    published PU21 formula and a mask made by hand)."""
    from scipy.ndimage import laplace

    from lfproc.metrics import hdr_figures

    rng = np.random.default_rng(3)
    ref = np.broadcast_to(rng.uniform(0.5, 1.0, (1, 1, 20, 20, 1)), (1, 1, 20, 20, 3)).copy()
    ref[0, 0, 9:11, 9:11] = 1e4  # a light: 4 samples, the brightest 1 % of 400
    res = ref * rng.uniform(0.7, 1.3, (1, 1, 20, 20, 1))  # grain everywhere ...
    res[0, 0, 9:11, 9:11] = 1e4  # ... but on the light
    out = hdr_figures(res, ref)
    factor = 1000.0 / 1e4
    p_ref = reference_pu21(metric_luminance(ref)[0, 0] * factor, "banding_glare")
    le = laplace(reference_pu21(metric_luminance(res)[0, 0] * factor, "banding_glare") - p_ref) ** 2
    lr = laplace(p_ref) ** 2
    near = np.zeros((20, 20), bool)
    near[8:12, 9:11] = near[9:11, 8:12] = True  # the light and its cross of neighbours
    assert out["detail_ratio"] == pytest.approx(le.sum() / lr.sum(), rel=1e-9)
    assert out["detail_ratio_off_highlights"] == pytest.approx(le[~near].sum() / lr[~near].sum(), rel=1e-9)
    assert out["highlight_detail_share"] == pytest.approx(lr[near].sum() / lr.sum(), rel=1e-9)
    assert out["highlight_detail_share"] > 0.9 and out["detail_ratio"] < 0.1 < out["detail_ratio_off_highlights"]
    # restricted by a mask (the left half, without the light): the brightest 1 % of the kept samples (2 of 160)
    # and their neighbours are set aside
    half = np.zeros((20, 20), bool)
    half[:, :8] = True
    y = metric_luminance(ref)[0, 0]
    near = np.zeros((20, 20), bool)
    for i, j in np.argwhere(y >= np.sort(y[half])[-2] - 1e-12):
        if half[i, j]:
            near[max(i - 1, 0):i + 2, j] = near[i, max(j - 1, 0):j + 2] = True
    off = half & ~near
    masked = hdr_figures(res, ref, mask=half)
    assert masked["detail_ratio_off_highlights"] == pytest.approx(le[off].sum() / lr[off].sum(), rel=1e-9)


def test_hdr_figures_zeros_in_the_dark(hdr_lf):
    from lfproc.metrics import hdr_figures

    y = metric_luminance(hdr_lf.data.astype(np.float64))
    dark = y < np.percentile(y, 10)
    data = hdr_lf.data.copy()
    data[dark] = 0.0
    out = hdr_figures(data, hdr_lf.data)
    assert out["zeros_above_floor"] == np.count_nonzero(dark) / y.size
    assert math.isinf(out["stops_by_decade"][0]["median_stops"])  # the darkest decade: all zeros
    assert out["highlight_energy"] == 1.0  # the highlights are untouched
    # above a noise floor that leaves out the zeroed samples: no zeros, no error
    floor = float(y[dark].max())
    out = hdr_figures(data, hdr_lf.data, noise_floor=floor)
    assert out["zeros_above_floor"] == 0.0 and out["max_decade_stops"] == 0.0
    assert out["samples_above_floor"] == np.count_nonzero(y > floor)


def test_hdr_figures_counts_near_zeros_as_zeros(hdr_lf):
    # a result 1e-14 of the truth (46 stops under: black on any display) is a zero; 19 stops under is not
    from lfproc.metrics import ZERO_STOPS, hdr_figures

    y = metric_luminance(hdr_lf.data.astype(np.float64))
    dark = y < np.percentile(y, 10)
    data = hdr_lf.data.astype(np.float64)
    data[dark] *= 1e-14
    out = hdr_figures(data, hdr_lf.data)
    assert ZERO_STOPS == 20.0
    assert out["zeros_above_floor"] == np.count_nonzero(dark) / y.size
    data = hdr_lf.data.astype(np.float64)
    data[dark] *= 2.0 ** -19
    assert hdr_figures(data, hdr_lf.data)["zeros_above_floor"] == 0.0


def test_hdr_figures_mask_and_emitters(hdr_lf):
    from lfproc.metrics import hdr_figures

    data = hdr_lf.data.copy()
    data[:, :, :, :4] *= 8.0  # three stops off in the first four columns
    assert hdr_figures(data, hdr_lf)["max_decade_stops"] == pytest.approx(3.0, abs=1e-5)
    mask = np.ones((24, 32), dtype=bool)
    mask[:, :4] = False
    out = hdr_figures(data, hdr_lf, mask=mask)
    assert out["max_decade_stops"] == 0.0 and out["samples"] == 2 * 3 * 24 * 28
    full_mask = np.broadcast_to(mask, (2, 3, 24, 32))
    assert hdr_figures(data, hdr_lf, mask=full_mask)["samples"] == out["samples"]

    # a few emitters lost: they hold nearly all the PU21 error
    ref = hdr_lf.data.copy()
    ref[:, :, 3, 5] = 1e6
    res = hdr_lf.data.copy()
    res[:, :, 3, 5] = 1e3
    res *= np.float32(1.01)
    out = hdr_figures(res, ref)
    assert out["emitter_share"] > 0.6 and out["emitters_dominate"] is True
    assert out["highlight_energy"] < 0.1


def test_hdr_figures_bad_inputs(hdr_lf):
    from lfproc.metrics import hdr_figures

    with pytest.raises(ShapeError, match="same shape"):
        hdr_figures(hdr_lf.data[:, :, :10], hdr_lf.data)
    with pytest.raises(ShapeError, match="mask: expected shape"):
        hdr_figures(hdr_lf, hdr_lf, mask=np.ones((3, 3), dtype=bool))
    with pytest.raises(ShapeError, match="mask: expected a boolean"):
        hdr_figures(hdr_lf, hdr_lf, mask=np.ones((24, 32)))
    with pytest.raises(ShapeError, match="selects none"):
        hdr_figures(hdr_lf, hdr_lf, mask=np.zeros((24, 32), dtype=bool))
    with pytest.raises(InputError, match="noise_floor"):
        hdr_figures(hdr_lf, hdr_lf, noise_floor=-1.0)
    with pytest.raises(ShapeError, match="expected a light field or an array"):
        hdr_figures(np.ones((4, 5)), np.ones((4, 5)))


def test_evaluate_reports_hdr_figures_and_keeps_its_keys(bedroom):
    out = evaluate(_noisy(bedroom, 0.05, 1), bedroom)
    for key in ("pu21_psnr_db", "pu21_ssim", "pu2_psnr_db", "log_psnr_db", "linear_psnr_db",
                "mean_relative_error", "views", "scale_factor", "align", "gain"):
        assert key in out
    from lfproc.metrics import hdr_figures

    expected = hdr_figures(_noisy(bedroom, 0.05, 1), bedroom)
    for key in ("max_decade_stops", "zeros_above_floor", "highlight_energy", "detail_ratio", "emitter_share"):
        assert out[key] == pytest.approx(expected[key], rel=1e-12)
    assert out["stops_by_decade"] == expected["stops_by_decade"]
    assert out["masked"] is False and out["exclude_above"] is None


def test_evaluate_mask_and_exclude_above_restrict_every_figure():
    from lfproc.synth import synthesize

    ref = synthesize("layers", size=(32, 48), views=3, random_state=2)
    data = ref.data.copy()
    data[:, :, :, :16] *= 3.0  # wrong on the left third only
    res = ref.replace(data=data)
    full = evaluate(res, ref)
    assert full["pu21_psnr_db"] < 60 and full["max_decade_stops"] > 1
    mask = np.zeros((32, 48), dtype=bool)
    mask[:, 16:] = True
    out = evaluate(res, ref, mask=mask)
    for key in ("pu21_psnr_db", "pu2_psnr_db", "log_psnr_db", "linear_psnr_db"):
        assert out[key] == math.inf, key
    assert out["mean_relative_error"] == 0.0 and out["max_decade_stops"] == 0.0
    assert out["samples"] == 9 * 32 * 32 and out["masked"] is True
    assert out["scale_factor"] == full["scale_factor"]  # one scale, that of the whole reference
    # a mask cut inside the view: SSIM over the kept pixels is higher than over all
    assert out["pu21_ssim"] > full["pu21_ssim"]

    # emitters lost: excluded by luminance, the rest is scored alone
    y = metric_luminance(ref.data)
    bright = y > np.percentile(y, 99.5)
    data = ref.data.copy()
    data[bright] *= 0.25
    res = ref.replace(data=data)
    limit = float(y[~bright].max())
    out = evaluate(res, ref, exclude_above=limit)
    assert out["pu21_psnr_db"] == math.inf and out["highlight_energy"] == 1.0
    assert out["exclude_above"] == limit and out["samples"] == np.count_nonzero(~bright)
    assert evaluate(res, ref)["highlight_energy"] < 0.5

    with pytest.raises(ShapeError, match="mask: expected shape"):
        evaluate(res, ref, mask=np.ones((3, 3), bool))
    with pytest.raises(ShapeError, match="exclude_above=1e-09 left no sample"):
        evaluate(res, ref, exclude_above=1e-9)


def test_evaluate_mask_that_leaves_a_view_empty():
    from lfproc.synth import synthesize

    ref = synthesize("layers", size=(24, 32), views=3, random_state=3)
    res = _noisy(ref, 0.05, 2)
    keep = np.ones((3, 3, 24, 32), dtype=bool)
    keep[0, 0] = False  # view (0, 0) not scored at all
    out = evaluate(res, ref, mask=keep)
    first = out["views"][0]
    assert (first["v"], first["u"]) == (0, 0)
    for key in ("pu21_psnr_db", "pu21_ssim", "pu2_psnr_db", "log_psnr_db", "linear_psnr_db", "mean_relative_error"):
        assert math.isnan(first[key]), key
        assert out[key] == pytest.approx(np.mean([r[key] for r in out["views"][1:]]), rel=1e-12), key
    # the other views score as they do without a mask
    full = evaluate(res, ref)
    assert out["views"][4]["pu21_psnr_db"] == pytest.approx(full["views"][4]["pu21_psnr_db"], rel=1e-12)
    assert out["views"][4]["pu21_ssim"] == pytest.approx(full["views"][4]["pu21_ssim"], rel=1e-9)
