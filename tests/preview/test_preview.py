"""Previews: Reinhard tone mapping, contact sheet, EPI, histogram, registry, files, CLI."""

from __future__ import annotations

import json

import re

import numpy as np
import pytest
from PIL import Image

from lfproc.errors import InputError, OutputExistsError, ShapeError
from lfproc.io import srgb_encode, write_lightfield
from lfproc.lightfield import LightField
from lfproc.preview import (
    PREVIEWS, epi_stretch, register_preview, reinhard_parameters, render_preview, tonemap, write_preview,
)
from lfproc.synth import synthesize


@pytest.fixture(scope="module")
def lf():
    return synthesize("layers", size=(48, 64), views=5, baseline_px=2.0, random_state=0)


# -- tone mapping ---------------------------------------------------------------------------------

def test_tonemap_is_monotonic_and_in_range():
    lum = np.exp2(np.linspace(-20, 20, 4001)).astype(np.float32)
    grey = np.repeat(lum[:, None], 3, axis=1)
    out = tonemap(grey)
    assert out.dtype == np.float32 and out.shape == grey.shape
    assert out.min() >= 0 and out.max() <= 1
    assert np.all(np.diff(out[:, 1]) >= 0)
    assert out[0, 1] < 0.01 and out[-1, 1] == 1.0


def test_tonemap_maps_log_average_to_documented_value():
    rng = np.random.default_rng(0)
    lum = np.exp2(rng.uniform(-10, 10, size=(64, 64))).astype(np.float32)
    image = lum[..., None] * np.array([1.0, 1.0, 1.0], np.float32)
    params = reinhard_parameters(image)
    log_avg = float(np.exp(np.mean(np.log(lum.astype(np.float64)))))
    assert params["log_average"] == pytest.approx(log_avg, rel=1e-5)
    assert params["scale"] == pytest.approx(0.18 / log_avg, rel=1e-5)
    white = params["white"]
    assert white == pytest.approx(np.percentile(lum, 99.9) * 0.18 / log_avg, rel=1e-5)
    probe = np.full((1, 1, 3), log_avg, np.float32)
    value = tonemap(probe, reference=image, encoding="linear")[0, 0, 1]
    expected = 0.18 * (1 + 0.18 / white**2) / (1 + 0.18)
    assert value == pytest.approx(expected, rel=1e-5)
    assert value == pytest.approx(0.1525, abs=1e-3)  # the value the docstring quotes
    # the sRGB output is the sRGB encoding of the linear one
    assert tonemap(probe, reference=image)[0, 0, 1] == pytest.approx(float(srgb_encode(np.float32(value))), rel=1e-5)
    # the white percentile maps to 1
    top = np.full((1, 1, 3), np.percentile(lum, 99.9), np.float32)
    assert tonemap(top, reference=image, encoding="linear")[0, 0, 1] == pytest.approx(1.0, rel=1e-5)


def test_tonemap_keeps_colour_ratios_and_exposure_brightens():
    image = np.array([[[0.2, 0.1, 0.05], [1.0, 1.0, 1.0], [4.0, 4.0, 4.0]]], np.float32)
    out = tonemap(image, encoding="linear")
    np.testing.assert_allclose(out[0, 0] / out[0, 0, 0], [1.0, 0.5, 0.25], rtol=1e-5)
    brighter = tonemap(image, encoding="linear", exposure_ev=1.0)
    assert brighter[0, 0, 1] > out[0, 0, 1]
    assert tonemap(np.zeros((2, 2, 3), np.float32)).max() == 0


def test_tonemap_errors():
    with pytest.raises(ShapeError, match="1 or 3 colour channels"):
        tonemap(np.ones((4, 4, 2)))
    with pytest.raises(InputError, match="key: expected a number in"):
        tonemap(np.ones((4, 4, 3)), key=1.5)
    with pytest.raises(InputError, match="white_percentile"):
        tonemap(np.ones((4, 4, 3)), white_percentile=0)
    with pytest.raises(InputError, match="encoding: expected srgb or linear"):
        tonemap(np.ones((4, 4, 3)), encoding="gamma")


# -- renderers -----------------------------------------------------------------------------------

def test_centre_preview(lf):
    img = render_preview(lf, "centre")
    assert img.dtype == np.uint8 and img.shape == (48, 64, 3)
    expected = np.round(tonemap(lf.centre()) * 255).astype(np.uint8)
    np.testing.assert_array_equal(img, expected)


def test_sheet_has_tiles_and_gaps_with_one_tone_curve():
    base = synthesize("checker", size=(32, 40), views=3, baseline_px=0.0, random_state=1).data.copy()
    base[0, 0] *= 4  # one view 2 stops brighter: with a common curve its tile is brighter
    lf = LightField(data=base)
    img = render_preview(lf, "sheet", labels=False)
    g = 2
    assert img.shape == (3 * 32 + 2 * g, 3 * 40 + 2 * g, 3)
    assert (img[32:32 + g] == 40).all() and (img[:, 40:40 + g] == 40).all()
    tiles = np.round(tonemap(lf.data) * 255).astype(np.uint8)
    np.testing.assert_array_equal(img[:32, :40], tiles[0, 0])
    np.testing.assert_array_equal(img[32 + g:64 + g, 40 + g:80 + g], tiles[1, 1])
    assert img[:32, :40].mean() > img[32 + g:64 + g, 40 + g:80 + g].mean() + 10


def test_epi_layout_and_slopes():
    # views that are the centre view translated by d * (u - cu): a bright dot draws a line of slope d
    h, w, d = 40, 48, 3
    data = np.full((5, 5, h, w, 3), 0.01, np.float32)
    for v in range(5):
        for u in range(5):
            data[v, u, 20 + d * (v - 2), 24 + d * (u - 2)] = (10.0, 0.0, 0.0)  # a red dot
    lf = LightField(data=data)
    s = epi_stretch(lf)
    g = 2
    img = render_preview(lf, "epi")
    assert img.shape == (h + g + 5 * s, w + g + 5 * s, 3)
    redness = img[..., 0].astype(int) - img[..., 1]
    horizontal = redness[h + g:, :w]  # rows: u (each s times), columns: x
    for u in range(5):
        assert np.argmax(horizontal[u * s + s // 2]) == 24 + d * (u - 2)
    vertical = redness[:h, w + g:]  # rows: y, columns: v (each s times)
    for v in range(5):
        assert np.argmax(vertical[:, v * s + s // 2]) == 20 + d * (v - 2)


def _grey_levels(levels, counts, zeros=0):
    """A 1 x 1 light field of grey pixels (luminance = value) at ``levels``, ``counts`` of each."""
    values = np.concatenate([np.repeat(np.float32(v), n) for v, n in zip(levels, counts)] + [np.zeros(zeros, np.float32)])
    return LightField(data=np.repeat(values.reshape(1, 1, 1, -1, 1), 3, axis=-1))


def test_histogram_figures_known_answer():
    from lfproc.preview._preview import _histogram_data

    data = _histogram_data(_grey_levels([1.0, 16.0], [30, 10], zeros=10))  # 0 and 4 stops
    np.testing.assert_allclose(data["edges"], np.linspace(0, 4, 33))  # whole stops, 8 bins a stop
    expected = np.zeros(32)
    expected[0], expected[-1] = 30 / 50, 10 / 50  # fractions of all samples, zeros included
    np.testing.assert_allclose(data["fractions"], expected)
    assert (data["p_lo"], data["p_hi"]) == (0.0, 4.0) and data["dynamic_range_stops"] == 4.0
    assert data["zero_fraction"] == pytest.approx(0.2) and data["saturated"] is None
    black = _histogram_data(LightField(data=np.zeros((1, 1, 8, 8, 3))))
    assert black["edges"] is None and black["zero_fraction"] == 1.0 and black["dynamic_range_stops"] == 0.0


def _bars(img):
    """Columns of the histogram's bars (its fill colour #4c72b0), grouped, and each group's height."""
    blue = np.abs(img.astype(int) - [76, 114, 176]).sum(-1) < 30
    cols = np.nonzero(blue.any(axis=0))[0]
    groups = np.split(cols, np.nonzero(np.diff(cols) > 1)[0] + 1) if cols.size else []
    return [(int(g.min()), int(blue[:, g].sum(axis=0).max())) for g in groups]


def test_histogram_preview_draws_the_bars_where_the_stops_are():
    # three levels 0, 2 and 4 stops: the middle bar is halfway (2 / 3.875 of the way from the
    # first bin's left edge at 0 to the last bin's at 3.875 stops) and, with twice the pixels,
    # taller than the two equal outer bars
    img = render_preview(_grey_levels([1.0, 4.0, 16.0], [10, 20, 10]), "histogram")
    assert img.shape == (500, 800, 3) and img.dtype == np.uint8
    (x0, h0), (x1, h1), (x2, h2) = _bars(img)
    assert abs(x1 - (x0 + (x2 - x0) * 2 / 3.875)) <= 1
    assert h0 == h2 and h1 > h0
    # a light field with no positive luminance still gives a picture, without bars
    black = render_preview(LightField(data=np.zeros((1, 1, 8, 8, 3))), "histogram")
    assert black.shape == (500, 800, 3) and _bars(black) == []


def test_render_preview_errors(lf):
    with pytest.raises(InputError, match=r"preview kind: expected one of centre, sheet, epi, histogram(, [a-z, ]+)?; got 'pie'"):
        render_preview(lf, "pie")
    with pytest.raises(InputError, match="expected a LightField, got ndarray"):
        render_preview(np.zeros((2, 2, 3)), "centre")


def test_registry_takes_new_input_kinds():
    class Capture:
        def __init__(self, image):
            self.image = image

    def sensor(capture, *, exposure_ev=0.0):
        return np.round(tonemap(capture.image[..., None], exposure_ev=exposure_ev) * 255).astype(np.uint8).repeat(3, 2)

    register_preview("test-sensor", sensor, accepts=Capture, description="sensor image")
    try:
        img = render_preview(Capture(np.ones((6, 7), np.float32)), "test-sensor")
        assert img.shape == (6, 7, 3)
        with pytest.raises(InputError, match="already registered"):
            register_preview("test-sensor", sensor, accepts=Capture)
        with pytest.raises(InputError, match="expected a Capture, got LightField"):
            render_preview(LightField(data=np.ones((1, 1, 4, 4, 3))), "test-sensor")
    finally:
        del PREVIEWS["test-sensor"]


# -- files and CLI -----------------------------------------------------------------------------

def test_write_preview_png_with_metadata(lf, tmp_path):
    path = write_preview(lf, tmp_path / "h.png", kind="histogram")
    assert path.stat().st_size > 1000
    with Image.open(path) as im:
        assert im.size == (800, 500)
        assert im.text["lfproc_preview"] == "histogram" and im.text["Software"].startswith("lfproc ")
    with pytest.raises(OutputExistsError, match="output exists"):
        write_preview(lf, path, kind="centre")
    write_preview(lf, path, kind="centre", force=True)
    with Image.open(path) as im:
        assert im.size == (64, 48)
        np.testing.assert_array_equal(np.asarray(im), render_preview(lf, "centre"))
    with pytest.raises(InputError, match=r"expected a preview file ending in \.png"):
        write_preview(lf, tmp_path / "x.exr")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.png"]  # no temporary files left


def test_cli_preview(lf, tmp_path, capsys):
    from lfproc.cli.main import main

    src = tmp_path / "lf.exr"
    write_lightfield(lf, src)
    out = tmp_path / "sheet.png"
    assert main(["preview", str(src), "-o", str(out), "--kind", "sheet", "--exposure", "1", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    g, band = 2, 10  # gaps; label bands of max(10, 64 // 10) pixels
    assert report["size"] == [5 * (band + 48) + 4 * g, 5 * 64 + 4 * g] and report["kind"] == "sheet"
    expected = render_preview(lf, "sheet", exposure_ev=1.0)
    with Image.open(out) as im:
        np.testing.assert_array_equal(np.asarray(im), expected)
    # existing output without --force
    before = out.read_bytes()
    assert main(["preview", str(src), "-o", str(out), "--kind", "centre"]) == 2
    err = capsys.readouterr().err
    assert "lfproc preview: error:" in err and "output exists" in err and err.count("\n") == 1
    assert out.read_bytes() == before
    # unknown kind
    assert main(["preview", str(src), "-o", str(tmp_path / "k.png"), "--kind", "pie"]) == 2
    # the registry lists the light-field kinds first, then those other modules add (capture kinds)
    assert re.search(r"--kind: expected one of centre, sheet, epi, histogram(, [a-z, ]+)?; got 'pie'",
                     capsys.readouterr().err)
    # missing input
    assert main(["preview", str(tmp_path / "nope.exr"), "-o", str(tmp_path / "n.png")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert not (tmp_path / "k.png").exists() and not (tmp_path / "n.png").exists()


@pytest.mark.parametrize("kind", ["centre", "epi",  # fast: two kinds; the sheet and histogram of a real folder slow
                                  pytest.param("sheet", marks=pytest.mark.slow),
                                  pytest.param("histogram", marks=pytest.mark.slow)])
def test_previews_of_real_light_field(shared_data, tmp_path, kind):
    """The command on a real folder of 8-bit views writes exactly what the renderer draws."""
    from lfproc.cli.main import main
    from lfproc.io import read_lightfield

    folder = shared_data / "lightfields" / "lowres_5x5" / "hci_bedroom"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    out = tmp_path / f"{kind}.png"
    assert main(["preview", str(folder), "-o", str(out), "--kind", kind]) == 0
    with Image.open(out) as im:
        np.testing.assert_array_equal(np.asarray(im), render_preview(read_lightfield(folder), kind))


# -- comparable pictures (issue 20, item 4) -------------------------------------------------------

def test_exposure_from_shows_a_result_and_its_truth_at_one_exposure(lf, tmp_path, capsys):
    dark = lf.replace(data=lf.data * np.float32(0.25))  # a result two stops too dark
    for kind in ("centre", "sheet", "epi"):
        own, truth = render_preview(dark, kind), render_preview(lf, kind)
        # each with its own curve, the two look alike: the error cannot be seen
        assert abs(own.astype(float).mean() - truth.astype(float).mean()) < 3, kind
        shared = render_preview(dark, kind, exposure_from=lf)
        assert shared.astype(float).mean() < truth.astype(float).mean() - 20, kind
        np.testing.assert_array_equal(render_preview(lf, kind, exposure_from=lf), truth)
    # the same curve as tonemap(..., reference=the truth's centre view)
    expected = np.round(tonemap(dark.centre(), reference=lf.centre()) * 255).astype(np.uint8)
    np.testing.assert_array_equal(render_preview(dark, "centre", exposure_from=lf), expected)
    with pytest.raises(InputError, match="exposure_from: expected a LightField"):
        render_preview(dark, "centre", exposure_from=np.ones((4, 4, 3)))

    from lfproc.cli.main import main

    res, ref = write_lightfield(dark, tmp_path / "res.exr"), write_lightfield(lf, tmp_path / "ref.exr")
    out = tmp_path / "res.png"
    assert main(["preview", str(res), "-o", str(out), "--exposure-from", str(ref), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["exposure_from"] == str(ref)
    from lfproc.io import read_lightfield

    with Image.open(out) as im:
        np.testing.assert_array_equal(np.asarray(im), render_preview(read_lightfield(res), "centre",
                                                                     exposure_from=read_lightfield(ref)))
    assert main(["preview", str(res), "-o", str(tmp_path / "n.png"), "--exposure-from", str(tmp_path / "no.exr")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--exposure-from" in err and "no.exr: no such file" in err
    assert not (tmp_path / "n.png").exists()


def test_exposure_from_refused_for_a_capture(tmp_path, capsys, lf):
    from lfproc.camera.simulate import simulate_capture
    from lfproc.cli.main import main

    cap = simulate_capture(lf.data[:, :, :32, :32], profile="paper-medium", shots=1, mask_period=4, random_state=1)
    path = cap.save(tmp_path / "a.capture.npz")
    ref = write_lightfield(lf, tmp_path / "ref.exr")
    assert main(["preview", str(path), "-o", str(tmp_path / "c.png"), "--exposure-from", str(ref)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--exposure-from: applies to light-field previews" in err
    assert not (tmp_path / "c.png").exists()


def test_histogram_figures_never_cover_the_peak():
    # the same two bars mirrored: the tallest one at the left, then at the right (where a legend
    # box used to sit); each is drawn to the same full height
    left = _bars(render_preview(_grey_levels([1.0, 16.0], [30, 10]), "histogram"))
    right = _bars(render_preview(_grey_levels([1.0, 16.0], [10, 30]), "histogram"))
    assert len(left) == len(right) == 2
    assert left[0][1] == right[1][1] and left[1][1] == right[0][1]
    assert right[1][1] > right[0][1]


def test_histogram_exposure_from_shares_the_stops_axis():
    from lfproc.preview._preview import _histogram_data, _stops_range

    narrow = _grey_levels([1.0, 4.0], [10, 10])  # 0 and 2 stops
    wide = _grey_levels([1 / 64, 1.0, 256.0], [10, 10, 10])  # -6, 0 and 8 stops
    assert _stops_range(wide) == (-6, 8)
    edges = _histogram_data(narrow, _stops_range(wide))["edges"]
    assert edges[0] == -6 and edges[-1] == 8
    # the bar at 0 stops is drawn at the same place in both pictures
    a = _bars(render_preview(narrow, "histogram", exposure_from=wide))
    b = _bars(render_preview(wide, "histogram", exposure_from=narrow))
    assert len(a) == 2 and len(b) == 3 and a[0][0] == b[1][0]
    assert _bars(render_preview(narrow, "histogram"))[0][0] < a[0][0] - 100  # alone, it spans the plot


def _dark_lf(views, h, w):
    return LightField(data=np.full((views, views, h, w, 3), 1e-4, np.float32))


def test_sheet_is_labelled_with_view_indices():
    lf = _dark_lf(3, 40, 60)
    img = render_preview(lf, "sheet")
    band, g = 10, 2  # max(10, 60 // 10), max(2, 40 // 64)
    assert img.shape == (3 * (band + 40) + 2 * g, 3 * 60 + 2 * g, 3)
    bands = [img[v * (band + 40 + g):v * (band + 40 + g) + band, u * (60 + g):u * (60 + g) + 60]
             for v in range(3) for u in range(3)]
    for b in bands:
        assert (b > 150).any()  # light text on the dark band
    # each label is different ("0,0", "0,1", ...), and the tiles themselves are untouched
    assert len({b.tobytes() for b in bands}) == 9
    plain = render_preview(lf, "sheet", labels=False)
    np.testing.assert_array_equal(img[band:band + 40, :60], plain[:40, :60])


def test_sheet_is_downscaled_to_its_pixel_budget():
    from lfproc.preview import SHEET_MAX_PIXELS, sheet_tile_size

    big = LightField(data=np.zeros((5, 5, 434, 625, 1), np.float32))  # Lytro size, as the 9.7 MB sheet
    th, tw = sheet_tile_size(big)
    assert 25 * th * tw <= SHEET_MAX_PIXELS and th * tw > 0.95 * SHEET_MAX_PIXELS / 25
    assert abs(tw / th - 625 / 434) < 0.01  # the aspect is kept
    assert sheet_tile_size(big, None) == (434, 625)
    assert sheet_tile_size(_dark_lf(3, 40, 60)) == (40, 60)  # small light fields keep full size
    with pytest.raises(InputError, match="max_pixels: expected a positive integer"):
        render_preview(big, "sheet", max_pixels=0)


@pytest.mark.slow  # renders a Lytro-size sheet
def test_a_lytro_size_sheet_is_rendered_at_the_budgeted_tile_size():
    from lfproc.preview import sheet_tile_size

    big = LightField(data=np.zeros((5, 5, 434, 625, 1), np.float32))
    th, tw = sheet_tile_size(big)
    img = render_preview(big, "sheet")
    assert img.shape[1] == 5 * tw + 4 * 2


@pytest.mark.slow  # a full-size real light field
def test_sheet_of_a_real_light_field_is_at_most_2_mb(shared_data, tmp_path):
    from lfproc.io import read_lightfield

    folder = shared_data / "lightfields" / "hci_antinous_5x5"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    lf = read_lightfield(folder)
    path = write_preview(lf, tmp_path / "sheet.png", kind="sheet")
    assert path.stat().st_size < 2_000_000
    full = write_preview(lf, tmp_path / "full.png", kind="sheet", max_pixels=None)
    assert full.stat().st_size > 3 * path.stat().st_size


def test_capture_preview_has_colour_bars(lf):
    from lfproc.preview import render_capture_preview
    from lfproc.camera.simulate import simulate_capture

    cap = simulate_capture(lf.data[:, :, :32, :32], profile="paper-medium", shots=1, mask_period=4, random_state=1)

    def gradient_columns(img):
        """Columns holding a grey ramp, white at the top to black at the bottom, in one run of at
        least 100 rows, each row no lighter than the one above: a colour bar (the pictures
        themselves are pixel noise, the other figures' columns are flat)."""
        found = []
        for c in range(img.shape[1]):
            col = img[:, c].astype(int)
            ok = (np.ptp(col, axis=-1) <= 2)[1:] & (np.diff(col[:, 0]) <= 0) & (np.diff(col[:, 0]) >= -6)
            start = 0
            for r in range(1, ok.size + 1):
                if r == ok.size or not ok[r]:
                    if r - start >= 100 and col[start, 0] - col[r, 0] >= 150:
                        found.append(c)
                        break
                    start = r + 1
        return found

    for kind in ("sensor", "mask"):
        assert gradient_columns(render_capture_preview(cap, kind)), kind
