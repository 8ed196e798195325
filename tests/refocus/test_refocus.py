"""Shift-and-sum refocusing (issue 20, item 8): known answers, focal stacks, the command."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage

from lfproc import LightField
from lfproc.cli.main import main
from lfproc.errors import InputError
from lfproc.io import read_image, write_lightfield
from lfproc.refocus import focal_stack, refocus


def _plane(d: float, *, views=5, size=40, smooth=False, seed=0):
    """A fronto-parallel plane of disparity ``d``: view (v, u) sees the centre view's pixel (y, x) at
    (y + d dv, x + d du) (LightField's convention). HDR texture spanning 13 stops."""
    rng = np.random.default_rng(seed)
    m = int(np.ceil(abs(d) * (views // 2))) + 4
    big = 2.0 ** rng.uniform(-6, 7, (size + 2 * m, size + 2 * m, 3))
    if smooth:
        big = ndimage.gaussian_filter(big, (2, 2, 0))
    c = views // 2
    data = np.empty((views, views, size, size, 3), np.float32)
    for v in range(views):
        for u in range(views):
            dv, du = v - c, u - c
            shifted = ndimage.shift(big, (d * dv, d * du, 0), order=3, mode="nearest") if smooth else \
                np.roll(big, (int(d * dv), int(d * du)), axis=(0, 1))
            data[v, u] = shifted[m:m + size, m:m + size]
    return LightField(data)


def test_refocus_at_the_plane_disparity_gives_the_centre_view():
    lf = _plane(2)
    before = lf.data.copy()
    image = refocus(lf, 2)
    assert image.shape == (40, 40, 3) and image.dtype == np.float32
    np.testing.assert_allclose(image, lf.centre(), rtol=1e-6)  # sharp: every view lines up (HDR kept)
    assert image.max() > 50  # linear HDR values, not clipped
    assert np.abs(refocus(lf, 0) - lf.centre()).mean() > 0.3 * lf.centre().mean()  # elsewhere: blurred
    np.testing.assert_array_equal(lf.data, before)  # the input is not changed


def test_refocus_finds_a_subpixel_disparity():
    lf = _plane(0.5, smooth=True)
    centre = lf.centre()[6:-6, 6:-6]
    slopes = np.round(np.arange(-1, 1.51, 0.25), 2)
    errors = [np.abs(img[6:-6, 6:-6] - centre).mean() / centre.mean() for img in focal_stack(lf, slopes)]
    assert slopes[int(np.argmin(errors))] == 0.5
    assert min(errors) < 0.01 and sorted(errors)[1] > 2 * min(errors)  # bilinear shifts: 0.4 % left


def test_focal_stack_and_bad_slopes():
    lf = _plane(1)
    stack = focal_stack(lf, [-1, 0, 1])
    assert stack.shape == (3, 40, 40, 3)
    np.testing.assert_array_equal(stack[2], refocus(lf, 1))
    single = LightField(lf.data[2:3, 2:3])
    np.testing.assert_array_equal(refocus(single, 3), single.centre())  # one view: itself
    for bad in (float("nan"), 50, "1"):
        with pytest.raises(InputError, match="slope"):
            refocus(lf, bad)
    with pytest.raises(InputError, match="LightField"):
        refocus(lf.data, 1)


def test_cli_refocus_one_slope_and_a_focal_stack(tmp_path, capsys):
    lf = _plane(2)
    src = write_lightfield(lf, tmp_path / "lf.exr")
    out = tmp_path / "near.exr"
    assert main(["refocus", str(src), "-o", str(out), "--slope", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["slopes"] == [2.0]
    np.testing.assert_allclose(read_image(out)[0], lf.centre(), rtol=1e-6)
    stack = tmp_path / "stack"
    assert main(["refocus", str(src), "-o", str(stack), "--slope", "-1", "0", "2"]) == 0
    index = json.loads((stack / "focal_stack.json").read_text())
    assert index["slopes"] == [-1.0, 0.0, 2.0] and len(index["files"]) == 3
    np.testing.assert_allclose(read_image(stack / index["files"][2])[0], lf.centre(), rtol=1e-6)


@pytest.mark.parametrize("args, match", [
    (["--slope", "1", "-o", "{tmp}/x.png"], "--output: one slope gives one linear HDR image: expected a .exr or .hdr"),
    (["--slope", "1", "0", "-o", "{tmp}/x.exr"], "--output: 2 slopes give a focal stack: expected a folder"),
    (["--slope", "x", "-o", "{tmp}/x.exr"], "--slope: expected comma-separated numbers, got 'x'"),
    (["--slope", "90", "-o", "{tmp}/x.exr"], "--slope: 90 pixels per view step shifts the outer views by 180"),
    (["--slope", "1", "-o", "{tmp}/lf.exr"], "output exists; pass --force"),
])
def test_cli_refocus_errors_one_line(tmp_path, capsys, args, match):
    src = write_lightfield(_plane(1), tmp_path / "lf.exr")
    before = sorted(p.name for p in tmp_path.iterdir())
    argv = ["refocus", str(src)] + [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and match in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
