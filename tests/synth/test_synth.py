"""Synthetic HDR light fields: ground truth, parallax, determinism, textures, errors, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lfproc.errors import InputError, MissingFileError, ShapeError
from lfproc.io import read_lightfield
from lfproc.lightfield import LightField
from lfproc.synth import SCENES, Layer, render_layers, scene_layers, synthesize

KINDS = list(SCENES)


def test_at_least_three_kinds():
    assert len(KINDS) >= 3
    assert {"layers", "lamps", "window", "checker"} <= set(KINDS)


@pytest.mark.parametrize("scene", KINDS)
def test_shape_metadata_and_sixteen_stops(scene):
    lf = synthesize(scene, size=(64, 80), views=5, baseline_px=1.0, random_state=5)
    assert lf.shape == (5, 5, 64, 80, 3)
    assert lf.units == "relative" and lf.colour_space == "linear-srgb"
    assert lf.disparity.shape == (64, 80)
    assert lf.source == f"synth:{scene}"
    assert lf.attrs["synth_scene"] == scene and lf.attrs["synth_seed"] == 5
    assert lf.attrs["synth_baseline_px"] == 1.0 and lf.attrs["synth_size"] == [64, 80]
    assert lf.attrs["lfproc_version"]
    # robust (0.1 / 99.9 percentiles) and extreme dynamic range of the positive luminance
    assert lf.dynamic_range_stops() >= 16
    lum = lf.luminance()
    assert (lum > 0).all()
    assert np.log2(lum.max() / lum.min()) >= 16
    assert lf.data.max() < 65504  # fits half-float EXR


@pytest.mark.parametrize("scene", KINDS)
def test_deterministic_per_seed(scene):
    a = synthesize(scene, size=(32, 32), views=3, random_state=11)
    b = synthesize(scene, size=(32, 32), views=3, random_state=11)
    c = synthesize(scene, size=(32, 32), views=3, random_state=12)
    np.testing.assert_array_equal(a.data, b.data)
    np.testing.assert_array_equal(a.disparity, b.disparity)
    assert not np.array_equal(a.data, c.data)


@pytest.mark.parametrize("scene", KINDS)
def test_baseline_zero_gives_identical_views(scene):
    lf = synthesize(scene, size=(32, 48), views=5, baseline_px=0.0, random_state=1)
    for v in range(5):
        for u in range(5):
            np.testing.assert_array_equal(lf.data[v, u], lf.centre())
    assert (lf.disparity == 0).all()


@pytest.mark.parametrize("scene", KINDS)
def test_centre_view_does_not_depend_on_views_or_baseline(scene):
    one = synthesize(scene, size=(40, 40), views=1, baseline_px=0.0, random_state=2)
    many = synthesize(scene, size=(40, 40), views=7, baseline_px=2.5, random_state=2)
    np.testing.assert_array_equal(one.centre(), many.centre())


@pytest.mark.parametrize("scene", KINDS)
def test_disparity_map_holds_layer_disparities(scene):
    b = 1.5
    lf = synthesize(scene, size=(64, 64), views=5, baseline_px=b, random_state=4)
    layer_d = lf.attrs["layer_disparities_px"]
    # layers are back to front, from -baseline to +baseline, in quarters of the baseline
    assert layer_d[0] == -b and layer_d[-1] == b
    assert all(np.isclose(d / b * 4, round(d / b * 4)) for d in layer_d)
    values = set(np.unique(lf.disparity).tolist())
    assert values <= set(layer_d)
    assert len(values) >= 3


def test_disparity_known_pixels_checker():
    b = 2.0
    layers = scene_layers("checker", size=(64, 64), views=5, baseline_px=b, random_state=0)
    lf = synthesize("checker", size=(64, 64), views=5, baseline_px=b, random_state=0)
    m = (layers[0].alpha.shape[0] - 64) // 2
    lamp = layers[-1].alpha[m:m + 64, m:m + 64]
    y, x = np.unravel_index(np.argmax(lamp), lamp.shape)
    assert lamp[y, x] == 1 and lf.disparity[y, x] == b  # the lamp is the front-most layer
    assert lf.disparity[0, 0] == -b  # only the background board covers the corner
    assert layers[-1].disparity_px == b and layers[0].disparity_px == -b


def _unoccluded(layers, dv, du, size):
    """Centre pixels fully covered by one layer k that no layer in front of k covers in the centre view
    or in view (dv, du) and that carry no highlight there (integer disparities: exact indexing)."""
    h, w = size
    m = (layers[0].alpha.shape[0] - h) // 2
    yy, xx = np.mgrid[0:h, 0:w]

    def sample(raster, sy, sx):  # raster value at centre pixel (y + sy, x + sx); NaN outside the raster
        ys, xs = yy + m + sy, xx + m + sx
        inside = (ys >= 0) & (ys < raster.shape[0]) & (xs >= 0) & (xs < raster.shape[1])
        out = raster[np.clip(ys, 0, raster.shape[0] - 1), np.clip(xs, 0, raster.shape[1] - 1)].astype(float)
        out[~inside] = np.nan
        return out

    mask = np.zeros((h, w), bool)
    for k, lay in enumerate(layers):
        own = sample(lay.alpha, 0, 0) == 1
        for front in layers[k + 1:]:
            shift = lay.disparity_px - front.disparity_px
            own &= sample(front.alpha, 0, 0) == 0
            own &= sample(front.alpha, int(dv * shift), int(du * shift)) == 0
        if lay.specular is not None:
            shift = lay.disparity_px - lay.specular_disparity_px
            spec = lay.specular.max(axis=2)
            own &= (sample(spec, 0, 0) == 0) & (sample(spec, int(dv * shift), int(du * shift)) == 0)
        mask |= own
    return mask


@pytest.mark.parametrize("scene", KINDS)
def test_parallax_warping_reproduces_centre(scene):
    # baseline 4 px: every layer disparity is an integer, so warping is exact (no interpolation)
    size, b = (96, 96), 4.0
    lf = synthesize(scene, size=size, views=5, baseline_px=b, random_state=3)
    layers = scene_layers(scene, size=size, views=5, baseline_px=b, random_state=3)
    d = lf.disparity.astype(int)
    assert (d == lf.disparity).all()
    yy, xx = np.mgrid[0:size[0], 0:size[1]]
    centre = lf.centre()
    for v, u in [(0, 0), (2, 4), (4, 1), (1, 2), (3, 3)]:
        dv, du = v - 2, u - 2
        ys, xs = yy + dv * d, xx + du * d  # where the centre pixel is seen in view (v, u)
        inside = (ys >= 0) & (ys < size[0]) & (xs >= 0) & (xs < size[1])
        ok = _unoccluded(layers, dv, du, size) & inside
        assert ok.mean() > 0.5, ok.mean()
        warped = lf.data[v, u][np.clip(ys, 0, size[0] - 1), np.clip(xs, 0, size[1] - 1)]
        np.testing.assert_allclose(warped[ok], centre[ok], rtol=1e-5)
        # the views really differ where the disparity is not zero
        moving = ok & (d != 0)
        assert moving.mean() > 0.1
        assert np.mean(~np.isclose(lf.data[v, u][moving], centre[moving], rtol=1e-3)) > 0.5


def test_subpixel_translation_and_sign_convention():
    # a linear ramp is reproduced exactly by bilinear interpolation: known answer for any disparity
    h, w, m, disp = 20, 24, 4, 0.37
    yy, xx = np.mgrid[-m:h + m, -m:w + m].astype(np.float32)
    ramp = np.stack([1 + 0.1 * xx + 1, 1 + 0.05 * yy + 1, np.full_like(xx, 2.0)], axis=2)
    layer = Layer(radiance=ramp, alpha=np.ones(xx.shape, np.float32), disparity_px=disp)
    data, disparity = render_layers([layer], size=(h, w), views=5)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    for v in range(5):
        for u in range(5):
            dv, du = v - 2, u - 2
            # view (v, u) shows the centre pixel (y, x) at (y + dv*d, x + du*d)
            np.testing.assert_allclose(data[v, u, :, :, 0], 2 + 0.1 * (x - du * disp), rtol=1e-5)
            np.testing.assert_allclose(data[v, u, :, :, 1], 2 + 0.05 * (y - dv * disp), rtol=1e-5)
    assert (disparity == np.float32(disp)).all()


def test_occlusion_is_exact():
    h, w, m = 16, 16, 6
    back = Layer(radiance=np.full((h + 2 * m, w + 2 * m, 3), 1.0, np.float32),
                 alpha=np.ones((h + 2 * m, w + 2 * m), np.float32), disparity_px=-2.0)
    alpha = np.zeros((h + 2 * m, w + 2 * m), np.float32)
    alpha[m + 6:m + 10, m + 6:m + 10] = 1  # a 4x4 opaque square at centre pixels 6..9
    front = Layer(radiance=np.full((h + 2 * m, w + 2 * m, 3), 100.0, np.float32), alpha=alpha, disparity_px=2.0)
    data, disparity = render_layers([back, front], size=(h, w), views=3)
    assert disparity[7, 7] == 2.0 and disparity[0, 0] == -2.0
    right = data[1, 2, :, :, 0]  # one view to the right: the square moves 2 px right
    np.testing.assert_array_equal(right[6:10, 8:12], 100.0)
    np.testing.assert_array_equal(right[6:10, 6:8], 1.0)
    down = data[2, 1, :, :, 0]  # one view down: 2 px down
    np.testing.assert_array_equal(down[8:12, 6:10], 100.0)


def test_specular_highlight_moves_with_its_own_disparity():
    lf = synthesize("layers", size=(96, 96), views=5, baseline_px=4.0, random_state=3)
    layers = scene_layers("layers", size=(96, 96), views=5, baseline_px=4.0, random_state=3)
    ball = next(L for L in layers if L.specular is not None)
    assert ball.specular_disparity_px != ball.disparity_px
    # the sun is brighter than the highlight: look near the highlight only
    m = (ball.alpha.shape[0] - 96) // 2
    spec = ball.specular[m:m + 96, m:m + 96].max(axis=2)
    hy, hx = np.unravel_index(np.argmax(spec), spec.shape)
    lum_c = lf.luminance()[2, 2]
    lum_r = lf.luminance()[2, 3]
    win = (slice(hy - 3, hy + 4), slice(hx - 3, hx + 8))
    yc, xc = np.unravel_index(np.argmax(lum_c[win]), lum_c[win].shape)
    yr, xr = np.unravel_index(np.argmax(lum_r[win]), lum_r[win].shape)
    assert (yr - yc, xr - xc) == (0, int(ball.specular_disparity_px))


def test_texture_from_array_known_answer():
    flat = np.full((10, 12, 3), 3.0, np.float32)
    lf = synthesize("checker", size=(64, 64), views=3, textures=[flat], random_state=0)
    # the background board (first textured surface) takes the texture, scaled to median 1,
    # times its level (2**-8) and its colour (1, 0.9, 0.6) normalised to mean 1
    expected = 2.0**-8 * np.array([1.0, 0.9, 0.6]) / np.mean([1.0, 0.9, 0.6])
    np.testing.assert_allclose(lf.centre()[0, 0], expected, rtol=1e-5)
    assert lf.attrs["synth_textures"] == ["array 0"]
    procedural = synthesize("checker", size=(64, 64), views=3, random_state=0)
    assert not np.allclose(procedural.centre()[0, 0], expected, rtol=1e-3)


def test_texture_grey_array_is_grey_rgb():
    """A 2-D texture is taken as grey: the same light field as its three-channel copy, and the
    textured surface follows the texture (a ramp, not the procedural pattern)."""
    grey = np.linspace(0.1, 1, 30 * 40, dtype=np.float32).reshape(30, 40)
    lf = synthesize("layers", size=(32, 32), views=3, textures=[grey], random_state=0)
    rgb = synthesize("layers", size=(32, 32), views=3, textures=[np.repeat(grey[..., None], 3, 2)], random_state=0)
    np.testing.assert_array_equal(lf.data, rgb.data)
    procedural = synthesize("layers", size=(32, 32), views=3, random_state=0)
    assert not np.allclose(lf.data, procedural.data)
    assert lf.dynamic_range_stops() >= 16


@pytest.fixture(params=["written", "real"])
def texture_file(request, tmp_path):
    """A texture file: a constant image lfproc writes here, or a real HDR image (shared data)."""
    if request.param == "written":
        from lfproc.io import write_image

        return write_image(tmp_path / "flat.exr", np.full((10, 12, 3), 3.0, np.float32))
    return request.getfixturevalue("shared_data") / "hdr" / "ScanLines_StillLife.exr"


def test_texture_from_file(texture_file):
    lf = synthesize("window", size=(48, 64), views=3, textures=[texture_file], random_state=0)
    procedural = synthesize("window", size=(48, 64), views=3, random_state=0)
    assert lf.attrs["synth_textures"] == [texture_file.name]
    assert not np.allclose(lf.data, procedural.data)
    assert lf.dynamic_range_stops() >= 16
    # the sky and sun (never textured) are the same
    assert np.array_equal(lf.disparity, procedural.disparity)
    if texture_file.name == "flat.exr":  # a file gives what the same array gives
        from lfproc.io import read_image

        same = synthesize("window", size=(48, 64), views=3, textures=[read_image(texture_file)[0]],
                          random_state=0)
        np.testing.assert_array_equal(lf.data, same.data)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"scene": "forest"}, InputError, "scene: expected one of layers, lamps, window, checker; got 'forest'"),
        ({"views": 4}, InputError, "views: expected odd numbers >= 1"),
        ({"views": 0}, InputError, "views: expected odd numbers >= 1"),
        ({"views": 2.5}, InputError, "views: expected an odd integer"),
        ({"size": (8, 64)}, InputError, "size: expected H and W of at least 16 pixels, got 8 x 64"),
        ({"size": (32,)}, InputError, "size: expected two integers"),
        ({"size": (32.5, 32)}, InputError, "size: expected two integers"),
        ({"baseline_px": -1}, InputError, "baseline: expected a finite number >= 0"),
        ({"baseline_px": float("nan")}, InputError, "baseline: expected a finite number >= 0"),
        ({"baseline_px": "wide"}, InputError, "baseline: expected a number"),
        ({"textures": ["/no/such/texture.exr"]}, MissingFileError, "texture /no/such/texture.exr: no such file"),
        ({"textures": [np.zeros((4, 4, 5))]}, ShapeError, r"texture 0: expected an image of shape"),
        ({"textures": [np.zeros((8, 8, 3))]}, InputError, "texture: the image has no positive pixels"),
        ({"random_state": -3}, InputError, "seed: expected a non-negative integer"),
    ],
)
def test_errors(kwargs, error, match):
    kwargs = {"size": (32, 32), "views": 3} | kwargs
    with pytest.raises(error, match=match):
        synthesize(**kwargs)


def test_render_layers_errors():
    layer = Layer(radiance=np.ones((20, 20, 3), np.float32), alpha=np.ones((20, 20), np.float32), disparity_px=3.0)
    with pytest.raises(ShapeError, match="margin of 2 pixels is too small"):
        render_layers([layer], size=(16, 16), views=5)
    with pytest.raises(InputError, match="at least one layer"):
        render_layers([], size=(16, 16), views=5)


def test_luminance_uses_the_published_rec709_weights():
    """ITU-R BT.709 luminance of the linear primaries (constants written out here, not imported)."""
    primaries = LightField(np.eye(3, dtype=np.float32)[None, None, None])
    np.testing.assert_allclose(primaries.luminance()[0, 0, 0], [0.2126, 0.7152, 0.0722], rtol=1e-6)
    lf = synthesize("lamps", size=(32, 32), views=1, random_state=0)
    assert lf.colour_space == "linear-srgb" and (lf.luminance() > 0).all()


def test_cli_writes_readable_file(tmp_path, capsys):
    from lfproc.cli.main import main

    out = tmp_path / "scene.exr"
    argv = ["synth", "-o", str(out), "--scene", "lamps", "--size", "32", "40", "--views", "3", "--baseline", "1.5",
            "--seed", "7", "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["views"] == [3, 3] and report["size"] == [32, 40] and report["disparity_range_px"] == [-1.5, 1.5]
    assert report["dynamic_range_stops"] >= 16
    back = read_lightfield(out)
    expected = synthesize("lamps", size=(32, 40), views=3, baseline_px=1.5, random_state=7)
    np.testing.assert_array_equal(back.data, expected.data)
    np.testing.assert_array_equal(back.disparity, expected.disparity)
    assert back.attrs["synth_seed"] == 7 and back.attrs["synth_scene"] == "lamps"
    # existing output without --force: one-line error, exit 2, file untouched
    before = out.read_bytes()
    assert main(argv) == 2
    assert "output exists" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main(argv[:-1] + ["--force", "--seed", "8"]) == 0
    assert out.read_bytes() != before


def test_cli_errors_and_help(tmp_path, capsys):
    from lfproc.cli.main import main

    out = tmp_path / "x.exr"
    assert main(["synth", "-o", str(out), "--scene", "forest"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lfproc synth: error: scene: expected one of layers, lamps" in err
    assert main(["synth", "-o", str(out), "--texture", str(tmp_path / "missing.png")]) == 2
    assert "missing.png: no such file" in capsys.readouterr().err
    assert main(["synth", "-o", str(out), "--size", "32", "x"]) == 2
    assert "--size: expected two integers" in capsys.readouterr().err
    assert not out.exists()
    assert main(["synth", "--help"]) == 0
    text = capsys.readouterr().out
    assert all(name in text for name in KINDS)
