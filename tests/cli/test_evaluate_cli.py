"""``lfproc evaluate``: known answers, output formats, noise ordering, error paths.

Synthetic scenes (no shared data needed); the noise ordering also runs on a real light field
(HCI bedroom) when ``../shared/data`` is there.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lfproc.cli.main import main
from lfproc.io import read_lightfield, write_image, write_lightfield
from lfproc.metrics import evaluate, pu21_decode, pu21_encode
from lfproc.synth import synthesize

BEDROOM = "lightfields/lowres_5x5/hci_bedroom"


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A 5x5 synthetic HDR light field (written to EXR) and the light field read back."""
    path = tmp_path_factory.mktemp("eval") / "scene.exr"
    write_lightfield(synthesize("layers", size=(32, 40), views=5, random_state=1), path)
    return path, read_lightfield(path)


def _write_noisy(lf, sigma, seed, path):
    rng = np.random.default_rng(seed)
    data = np.clip(lf.data * (1 + sigma * rng.standard_normal(lf.shape, dtype=np.float32)), 0, None)
    return write_lightfield(lf.replace(data=data), path)


def _json(capsys, argv):
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1  # exactly one JSON object
    return json.loads(out)


def _grey(values):
    """Three equal channels: the PU21 luminance weights sum to 1, so Y equals the value."""
    return np.repeat(np.asarray(values, np.float32)[..., None], 3, axis=-1)


# -- known answers ----------------------------------------------------------------------------------

def test_known_pu21_psnr_of_a_known_pu_error(tmp_path, capsys):
    """A result whose PU21 values differ from the reference's by exactly +-d everywhere has
    PU21-PSNR = 20 log10(256 / d), whatever the image (the definition of pu21_metric.m)."""
    rng = np.random.default_rng(0)
    ref = rng.uniform(0.01, 1.0, (24, 32))  # scaled to 10 .. 1000 cd/m^2: inside PU21's range
    factor = 1000.0 / ref.max()
    d = 2.0
    sign = np.where((np.indices(ref.shape).sum(0) % 2) == 0, 1.0, -1.0)
    result = pu21_decode(pu21_encode(ref * factor) + sign * d) / factor
    write_image(tmp_path / "ref.exr", _grey(ref))
    write_image(tmp_path / "res.exr", _grey(result))
    out = _json(capsys, ["evaluate", str(tmp_path / "res.exr"), str(tmp_path / "ref.exr"), "--json"])
    assert out["pu21_psnr_db"] == pytest.approx(20 * math.log10(256 / d), abs=2e-3)  # 42.144 dB


def test_known_log_psnr_and_relative_error_of_a_scaled_image(tmp_path, capsys):
    """result = 1.02 x reference: every log10 luminance is off by log10(1.02), so log-PSNR =
    20 log10(log10(1000 / 0.005) / log10(1.02)) = 55.80 dB; the relative error is
    0.02 ref / (ref + 1e-3 max(ref)) on average (both computed here by hand)."""
    ref = np.random.default_rng(1).uniform(0.01, 1.0, (16, 20))
    write_image(tmp_path / "ref.exr", _grey(ref))
    write_image(tmp_path / "res.exr", _grey(ref * 1.02))
    out = _json(capsys, ["evaluate", str(tmp_path / "res.exr"), str(tmp_path / "ref.exr"), "--json"])
    assert out["log_psnr_db"] == pytest.approx(20 * math.log10(math.log10(1000 / 0.005) / math.log10(1.02)),
                                               abs=2e-3)
    ref32 = ref.astype(np.float32).astype(np.float64)
    res32 = (ref * 1.02).astype(np.float32).astype(np.float64)
    expected = np.mean(np.abs(res32 - ref32) / (ref32 + 1e-3 * ref32.max()))
    assert out["mean_relative_error"] == pytest.approx(expected, rel=1e-6)
    assert 0.0199 < out["mean_relative_error"] < 0.02  # just under 2 %: the regulariser
    assert len(out["views"]) == 1 and out["angular_shape"] == [1, 1]
    assert main(["evaluate", str(tmp_path / "res.exr"), str(tmp_path / "ref.exr")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[3].startswith("error by decade")  # header, columns, mean only, then the HDR figures


def test_identical_json_is_valid_with_inf(scene, capsys):
    path = str(scene[0])
    out = _json(capsys, ["evaluate", path, path, "--json"])
    assert out["pu21_psnr_db"] == "inf" and out["log_psnr_db"] == "inf" and out["pu2_psnr_db"] == "inf"
    assert out["pu21_ssim"] == 1.0 and out["mean_relative_error"] == 0.0
    assert len(out["views"]) == 25 and {"v", "u", "pu21_psnr_db", "pu21_ssim"} <= set(out["views"][0])
    assert out["peak_luminance_cd_m2"] == pytest.approx(1000.0)


# -- ordering and formats ------------------------------------------------------------------------------

@pytest.fixture(params=["synthetic", pytest.param("real", marks=pytest.mark.slow)])  # real: a full-size light field
def reference(request, scene):
    if request.param == "synthetic":
        return scene
    shared = request.getfixturevalue("shared_data")
    return shared / BEDROOM, read_lightfield(shared / BEDROOM)


def test_more_noise_lower_psnr_through_files(reference, tmp_path, capsys):
    ref_path, lf = reference
    figures = []
    for i, sigma in enumerate((0.01, 0.05, 0.2)):
        path = _write_noisy(lf, sigma, seed=10 + i, path=tmp_path / f"noisy{i}.exr")
        figures.append(_json(capsys, ["evaluate", str(path), str(ref_path), "--json", "--peak-luminance", "4000"]))
        # the command reports what the library computes on the same files
        lib = evaluate(read_lightfield(path), lf, peak_luminance=4000)
        assert figures[-1]["pu21_psnr_db"] == pytest.approx(lib["pu21_psnr_db"], rel=1e-12)
    for key in ("pu21_psnr_db", "pu21_ssim", "pu2_psnr_db", "log_psnr_db"):
        values = [f[key] for f in figures]
        assert values[0] > values[1] > values[2], (key, values)
    assert figures[0]["mean_relative_error"] < figures[1]["mean_relative_error"] < figures[2]["mean_relative_error"]
    assert figures[0]["peak_luminance_cd_m2"] == pytest.approx(4000.0)


def test_table_shows_the_json_figures(scene, tmp_path, capsys):
    ref_path, lf = scene
    path = _write_noisy(lf, 0.05, seed=1, path=tmp_path / "noisy.exr")
    doc = _json(capsys, ["evaluate", str(path), str(ref_path), "--json"])
    assert main(["evaluate", str(path), str(ref_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("5x5 views of 32x40, reference peak -> 1000 cd/m^2")
    assert "PU21-PSNR dB" in lines[1] and "PU21-SSIM" in lines[1]
    assert lines[2].split()[0] == "mean" and lines[3 + 25].startswith("error by decade")
    assert float(lines[2].split()[1]) == pytest.approx(doc["pu21_psnr_db"], abs=0.005)
    assert float(lines[2].split()[2]) == pytest.approx(doc["pu21_ssim"], abs=5e-5)
    first = doc["views"][0]
    assert lines[3].split()[:2] == [f"{first['v']},{first['u']}", f"{first['pu21_psnr_db']:.2f}"]


# -- errors -------------------------------------------------------------------------------------------

def _error(capsys, argv):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lfproc evaluate: error: ")
    return lines[0]


def test_shape_mismatch_is_one_line_error(scene, tmp_path, capsys):
    other = write_lightfield(synthesize("layers", size=(24, 40), views=5, random_state=1), tmp_path / "o.exr")
    line = _error(capsys, ["evaluate", str(scene[0]), str(other)])
    assert "result has 5x5 views of 32x40x3, reference 5x5 views of 24x40x3" in line


def test_view_count_mismatch(scene, tmp_path, capsys):
    path = write_lightfield(scene[1].central(3), tmp_path / "small.exr")
    line = _error(capsys, ["evaluate", str(path), str(scene[0])])
    assert "result has 3x3 views, reference 5x5" in line


def test_missing_file(scene, tmp_path, capsys):
    line = _error(capsys, ["evaluate", str(tmp_path / "nope.exr"), str(scene[0])])
    assert "nope.exr: no such file or folder" in line


def test_scale_mismatch_and_bad_peak(scene, tmp_path, capsys):
    ref_path, lf = scene
    bright = write_lightfield(lf.replace(data=lf.data * 100), tmp_path / "bright.exr")
    line = _error(capsys, ["evaluate", str(bright), str(ref_path)])
    assert f"differ by {math.log2(100):.2f} stops" in line and "--scale-tolerance-stops" in line
    black = write_lightfield(lf.replace(data=np.zeros(lf.shape, np.float32)), tmp_path / "black.exr")
    line = _error(capsys, ["evaluate", str(ref_path), str(black), "--scale-tolerance-stops", "100"])
    assert "all-black reference" in line
    line = _error(capsys, ["evaluate", str(bright), str(bright), "--peak-luminance", "0"])
    assert "peak_luminance: expected a positive finite number, got 0.0" in line


# -- units and exposures between stages (issue 14) --------------------------------------------------

def _pair(tmp_path):
    """A 'decode' (relative, 0.01 s, ISO 100) and a 'merge' of it: per second, exposure 1 s, 100x larger."""
    from lfproc.lightfield import LightField

    rng = np.random.default_rng(3)
    data = rng.uniform(0.01, 1.0, size=(3, 3, 24, 24, 3)).astype(np.float32)
    ref = LightField(data=data, units="relative", exposure_s=0.01, iso=100)
    noisy = data * (1 + 0.05 * rng.standard_normal(data.shape)).astype(np.float32)
    res = LightField(data=np.clip(noisy, 0, None) * 100, units="relative", exposure_s=1.0, iso=100)
    write_lightfield(ref, tmp_path / "truth.exr")
    write_lightfield(res, tmp_path / "hdr.exr")
    return ref, res


def test_exposure_mismatch_refused_or_aligned(tmp_path, capsys):
    """main scored a per-second merge against a 0.01 s capture with exit 0 (5.5 dB in README's pipeline)."""
    ref, res = _pair(tmp_path)
    a, b = str(tmp_path / "hdr.exr"), str(tmp_path / "truth.exr")
    assert main(["evaluate", a, b]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exposure 1 s at ISO 100 differs from the reference's 0.01 s" in err
    assert "--align exposure" in err
    by_exposure = _json(capsys, ["evaluate", a, b, "--align", "exposure", "--json"])
    assert by_exposure["align"] == "exposure" and by_exposure["gain"] == pytest.approx(0.01)
    by_gain = _json(capsys, ["evaluate", a, b, "--align", "gain", "--json"])
    assert by_gain["align"] == "gain" and by_gain["gain"] == pytest.approx(0.01, rel=0.01)  # fitted
    # aligned: the scores are those of the 5 % noise, not of a 100x scale error
    assert by_exposure["pu21_psnr_db"] > 25 and by_exposure["mean_relative_error"] < 0.06
    assert by_gain["pu21_psnr_db"] == pytest.approx(by_exposure["pu21_psnr_db"], abs=0.2)
    # linear PSNR beside PU21: its definition (peak = reference 99.9th percentile)
    aligned = res.data * 0.01
    peak = np.percentile(ref.data, 99.9)
    mse = np.mean((aligned.astype(np.float64) - ref.data) ** 2, axis=(2, 3, 4))
    assert by_exposure["linear_psnr_db"] == pytest.approx(float(np.mean(10 * np.log10(peak**2 / mse))), abs=1e-3)
    assert by_exposure["linear_psnr_peak"] == pytest.approx(peak)
    # the table says what was done
    assert main(["evaluate", a, b, "--align", "gain"]) == 0
    out = capsys.readouterr().out
    assert "align gain (result x0.0099" in out and "lin-PSNR dB" in out


def test_units_mismatch_needs_gain(tmp_path, capsys):
    from lfproc.lightfield import LightField

    ref, res = _pair(tmp_path)
    write_lightfield(LightField(data=res.data * 50, units="e-/s"), tmp_path / "e.exr")
    a, b = str(tmp_path / "e.exr"), str(tmp_path / "truth.exr")
    assert main(["evaluate", a, b]) == 2
    assert "result is in 'e-/s', reference in 'relative'" in capsys.readouterr().err
    assert main(["evaluate", a, b, "--align", "exposure"]) == 2
    assert "needs the same units" in capsys.readouterr().err
    doc = _json(capsys, ["evaluate", a, b, "--align", "gain", "--json"])
    assert doc["gain"] == pytest.approx(1 / 5000, rel=0.01) and doc["units"] == "relative"


def test_merge_output_carries_its_exposure(tmp_path):
    """A relative merge is a radiance per second: exposure_s = 1 (None on main)."""
    from lfproc.lightfield import LightField
    from lfproc.hdr import merge_lightfields

    rng = np.random.default_rng(0)
    scene = rng.uniform(0.05, 2.0, size=(1, 1, 16, 16, 3))
    lfs = [LightField(data=np.clip(scene * t * 10, 0, 1).astype(np.float32), units="relative", exposure_s=t,
                      iso=200, saturation_level=1.0, variance=np.full(scene.shape, 1e-6, np.float32))
           for t in (0.01, 0.02, 0.04)]
    merged, _ = merge_lightfields(lfs, method="ml")
    assert merged.units == "relative" and merged.exposure_s == 1.0 and merged.iso == 200
    np.testing.assert_allclose(merged.data, np.minimum(scene, 1 / 0.4) * 10, rtol=1e-3)
    path = tmp_path / "m.exr"
    write_lightfield(merged, path)
    assert read_lightfield(path).exposure_s == 1.0


# -- HDR figures, error map, mask (issue 20 item 4, issue 23) -------------------------------------------

def _lost_highlights(tmp_path):
    """A reference with a few emitters 10 stops above the scene, and a result that keeps the scene
    exactly but returns the emitters at 1/16 and zeros in a dark corner."""
    rng = np.random.default_rng(3)
    ref = rng.uniform(0.01, 1.0, (1, 1, 40, 48)).astype(np.float32)
    ref[0, 0, 5, 30:32] = 1000.0
    res = ref.copy()
    res[0, 0, 5, 30:32] = 1000.0 / 16
    ref[0, 0, 30:, :8] = 0.001  # a dark corner (80 samples) the result loses
    res[0, 0, 30:, :8] = 0.0
    from lfproc.lightfield import LightField

    ref_lf, res_lf = LightField(data=_grey(ref)), LightField(data=_grey(res))
    return (write_lightfield(res_lf, tmp_path / "res.exr"), write_lightfield(ref_lf, tmp_path / "ref.exr"),
            res_lf, ref_lf)


def test_table_prints_hdr_figures_and_says_when_emitters_dominate(tmp_path, capsys):
    res, ref, res_lf, ref_lf = _lost_highlights(tmp_path)
    doc = _json(capsys, ["evaluate", str(res), str(ref), "--json", "--scale-tolerance-stops", "10"])
    assert doc["zeros_above_floor"] == pytest.approx(80 / (40 * 48))
    assert doc["highlight_energy"] < 0.5 and doc["emitters_dominate"] is True
    assert {"decade", "median_stops", "samples"} <= set(doc["stops_by_decade"][0])
    assert doc["stops_by_decade"][0]["median_stops"] == "inf"  # the dark decade: all zeros
    # away from the emitters the error is the dark corner's; the table prints the JSON's figures
    off, share = doc["detail_ratio_off_highlights"], doc["highlight_detail_share"]
    assert 0 < off and 0 < share < 1
    assert main(["evaluate", str(res), str(ref), "--scale-tolerance-stops", "10"]) == 0
    out = capsys.readouterr().out
    assert f"away from the brightest 1 % {off:.3f} (they hold {100 * share:.0f} % of the reference's detail)" in out
    assert "error by decade of the reference luminance" in out
    assert "1e+03 .. 1e+04" in out and "1e-03 .. 1e-02" in out
    assert f"returned as 0 (or 20 stops under) above the floor: {100 * 80 / 1920:.3g} %" in out
    line = next(x for x in out.splitlines() if x.startswith("PU21 is dominated by a few emitters"))
    # the advice works: excluding above the suggested value scores the scene without the emitters
    value = line.split("--exclude-above ")[1].rstrip(")")
    doc = _json(capsys, ["evaluate", str(res), str(ref), "--json", "--exclude-above", value,
                         "--scale-tolerance-stops", "10", "--noise-floor", "0.002"])
    assert doc["pu21_psnr_db"] == "inf" and doc["max_decade_stops"] == 0.0 and doc["emitters_dominate"] is False
    assert doc["samples"] == 40 * 48 - 2 and doc["zeros_above_floor"] == 0.0


def test_the_samples_below_the_noise_floor_are_reported_apart(tmp_path, capsys):
    """The dark corner (80 samples at 0.001, returned as 0) under ``--noise-floor 0.002``: out of the worst decade and
    the zeros, in a line of its own (JSON: ``stops_below_floor``)."""
    res, ref, _, _ = _lost_highlights(tmp_path)
    args = ["evaluate", str(res), str(ref), "--scale-tolerance-stops", "10", "--noise-floor", "0.002"]
    doc = _json(capsys, [*args, "--json"])
    assert doc["zeros_above_floor"] == 0.0 and doc["samples_above_floor"] == 40 * 48 - 80
    (below,) = doc["stops_below_floor"]
    assert below["decade"] == pytest.approx([1e-3, 1e-2]) and below["samples"] == 80
    assert below["median_stops"] == "inf"
    assert main(args) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("below the noise floor"))
    assert "1e-03 .. 1e-02" in line and "(80 samples)" in line


def test_mask_files_restrict_every_figure(tmp_path, capsys):
    from PIL import Image

    res, ref, res_lf, ref_lf = _lost_highlights(tmp_path)
    keep = np.ones((40, 48), bool)
    keep[5, 30:32] = False
    keep[30:, :8] = False
    np.save(tmp_path / "keep.npy", keep)
    Image.fromarray((keep * 255).astype(np.uint8)).save(tmp_path / "keep.png")  # white = scored
    for name in ("keep.npy", "keep.png"):
        doc = _json(capsys, ["evaluate", str(res), str(ref), "--json", "--mask", str(tmp_path / name),
                             "--scale-tolerance-stops", "10"])
        assert doc["pu21_psnr_db"] == "inf" and doc["log_psnr_db"] == "inf" and doc["mean_relative_error"] == 0.0
        assert doc["samples"] == int(keep.sum()) and doc["max_decade_stops"] == 0.0 and doc["masked"] is True
        assert doc["mask"] == str(tmp_path / name)
    lib = evaluate(res_lf, ref_lf, mask=keep, scale_tolerance_stops=10)
    assert lib["pu21_ssim"] == pytest.approx(doc["pu21_ssim"], rel=1e-12)


def test_error_map_shows_stops_with_a_colour_bar(tmp_path, capsys):
    from PIL import Image

    from lfproc.lightfield import LightField

    rng = np.random.default_rng(4)
    ref = rng.uniform(0.1, 1.0, (3, 3, 40, 60)).astype(np.float32)
    res = ref.copy()
    res[:, :, :, :20] *= 4.0  # +2 stops on the left, -2 on the right, right in the middle
    res[:, :, :, 40:] /= 4.0
    write_lightfield(LightField(data=_grey(ref)), tmp_path / "ref.exr")
    write_lightfield(LightField(data=_grey(res)), tmp_path / "res.exr")
    out = tmp_path / "map.png"
    doc = _json(capsys, ["evaluate", str(tmp_path / "res.exr"), str(tmp_path / "ref.exr"), "--json",
                         "--error-map", str(out)])
    assert doc["error_map"] == str(out)
    img = np.asarray(Image.open(out).convert("RGB")).astype(int)
    redish = (img[..., 0] - img[..., 2]) > 50
    blueish = (img[..., 2] - img[..., 0]) > 50
    # the map: red (too bright) left, blue (too dark) right; the colour bar holds both hues stacked
    # vertically in one narrow column to the right of the map
    rows_r, cols_r = np.nonzero(redish)
    rows_b, cols_b = np.nonzero(blueish)
    assert np.median(cols_r) < np.median(cols_b)
    bar_cols = [c for c in range(img.shape[1]) if redish[:, c].any() and blueish[:, c].any()]
    assert bar_cols and min(bar_cols) > np.percentile(cols_b, 50)
    c = bar_cols[len(bar_cols) // 2]
    assert np.nonzero(redish[:, c])[0].mean() < np.nonzero(blueish[:, c])[0].mean()  # red on top
    # no overwrite without --force; with it, the map is rewritten
    before = out.read_bytes()
    line = _error(capsys, ["evaluate", str(tmp_path / "res.exr"), str(tmp_path / "ref.exr"), "--error-map", str(out)])
    assert "output exists" in line and out.read_bytes() == before
    assert main(["evaluate", str(tmp_path / "res.exr"), str(tmp_path / "ref.exr"), "--error-map", str(out),
                 "--force"]) == 0
    capsys.readouterr()


def test_error_map_values_are_log2_ratios():
    from lfproc.metrics import error_stops

    ref = _grey(np.full((2, 2, 4, 5), 2.0))
    res = ref.copy()
    res[1, 1, 0, 0] = 8.0
    res[1, 1, 0, 1] = 0.0
    ref[1, 1, 0, 2] = 0.0
    stops = error_stops(res, ref)  # the centre view (1, 1)
    assert stops[0, 0] == 2.0 and stops[0, 1] == -math.inf and math.isnan(stops[0, 2]) and stops[1, 1] == 0.0
    assert (error_stops(res, ref, view=(0, 0)) == 0).all()


def test_mask_and_error_map_errors(scene, tmp_path, capsys):
    path = str(scene[0])
    line = _error(capsys, ["evaluate", path, path, "--mask", str(tmp_path / "none.png")])
    assert "--mask" in line and "none.png: no such file" in line
    line = _error(capsys, ["evaluate", path, path, "--mask", str(tmp_path / "m.txt")])
    assert "--mask" in line and "expected a .png or .npy file" in line
    np.save(tmp_path / "wrong.npy", np.ones((3, 4), bool))
    line = _error(capsys, ["evaluate", path, path, "--mask", str(tmp_path / "wrong.npy")])
    assert "--mask" in line and "expected 32 x 40 (or 5 x 5 x 32 x 40)" in line and "found 3 x 4" in line
    np.save(tmp_path / "float.npy", np.full((32, 40), 0.5))
    line = _error(capsys, ["evaluate", path, path, "--mask", str(tmp_path / "float.npy")])
    assert "--mask" in line and "expected booleans or integers 0/1, found float64" in line
    (tmp_path / "bad.npy").write_bytes(b"not an array")
    line = _error(capsys, ["evaluate", path, path, "--mask", str(tmp_path / "bad.npy")])
    assert "--mask" in line and "not a valid .npy" in line
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    line = _error(capsys, ["evaluate", path, path, "--mask", str(tmp_path / "bad.png")])
    assert "bad.png" in line
    np.save(tmp_path / "none.npy", np.zeros((32, 40), bool))
    line = _error(capsys, ["evaluate", path, path, "--mask", str(tmp_path / "none.npy")])
    assert "no sample to evaluate" in line
    line = _error(capsys, ["evaluate", path, path, "--exclude-above", "-1"])
    assert "--exclude-above: expected a finite luminance >= 0, got -1" in line
    line = _error(capsys, ["evaluate", path, path, "--exclude-above", "0"])
    assert "--exclude-above 0: every reference sample is brighter" in line
    line = _error(capsys, ["evaluate", path, path, "--error-map", str(tmp_path / "map.exr")])
    assert "--error-map" in line and "expected a file ending in .png" in line
    line = _error(capsys, ["evaluate", path, path, "--error-map", str(tmp_path / "no" / "map.png")])
    assert "does not exist" in line
    # nothing half-written
    assert not any(p.name.startswith(("map", ".lfproc-tmp")) for p in tmp_path.rglob("*"))
