"""Virtual Illum camera: files a Lytro reader accepts, consistent metadata, truth and grids."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lfproc import LightField, read_lightfield
from lfproc.cli.main import main
from lfproc.errors import InputError, OutputExistsError, ShapeError
from lfproc.io import write_lightfield
from lfproc.lytro.caldata import read_caldata
from lfproc.lytro.capture import read_capture
from lfproc.lytro.grid import LensletGrid
from lfproc.lytro.virtual import (SENSOR_SIZES, WHITE_STEPS, illum_grid, make_virtual_illum, output_shape,
                                  render_irradiance, vignetting)
from lfproc.synth import synthesize


@pytest.fixture(scope="module")
def virtual(tmp_path_factory):
    root = tmp_path_factory.mktemp("virtual")
    lf = synthesize("layers", size=(48, 64), views=5, baseline_px=0.5, random_state=2)
    write_lightfield(lf, root / "lf.exr")
    out = root / "cam"
    rc = main(["virtual-illum", str(root / "lf.exr"), "-o", str(out), "--sensor", "small", "--exposures-ev", "-1,0",
               "--seed", "4", "--json"])
    assert rc == 0
    return out, json.loads((out / "truth.json").read_text())


def test_outputs_and_truth(virtual):
    out, info = virtual
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(["IMG_0001.LFR", "IMG_0002.LFR", f"caldata-{info['serial']}.tar", "truth.exr",
                            "truth.json"])
    assert info["sensor_size"] == list(SENSOR_SIZES["small"])
    assert [c["exposure_ev"] for c in info["captures"]] == [-1.0, 0.0]
    assert info["truth_capture"] == "IMG_0002.LFR"
    # the longer exposure gets twice the signal: the truth factors differ by 2
    f = [c["truth_factor"] for c in info["captures"]]
    assert f[1] == pytest.approx(2 * f[0])
    truth = read_lightfield(out / "truth.exr")
    grid = LensletGrid.from_dict(info["grid"])
    assert truth.views == (5, 5) and truth.size == output_shape(grid)
    assert truth.exposure_s == pytest.approx(0.01) and truth.iso == 100
    assert truth.attrs["virtual_illum"]["serial"] == info["serial"]
    assert info["lfproc_version"]
    # what a perfect decoder returns: the input views (already at the decoder's 48 x 64 output
    # size, so not resampled) times the 0 EV capture's signal over the white image's
    lf = read_lightfield(out.parent / "lf.exr")
    assert truth.size == lf.size
    np.testing.assert_allclose(truth.data, lf.data * np.float32(f[1]), rtol=1e-6)


def test_captures_read_back_with_realistic_metadata(virtual):
    out, info = virtual
    cap = read_capture(out / "IMG_0001.LFR")
    assert cap.camera_model == "B01" and cap.serial == info["serial"]
    assert cap.raw.shape == tuple(SENSOR_SIZES["small"]) and cap.raw.dtype == np.uint16
    assert cap.cfa_pattern == "GRBG" and cap.black_level["gr"] == 64 and cap.white_level == 1023
    assert (cap.zoom_step, cap.focus_step) == WHITE_STEPS[2]
    assert cap.exposure_s == pytest.approx(0.005) and cap.iso == 100
    assert cap.ccm is not None and np.allclose(cap.ccm.sum(axis=1), 1.0, atol=0.01)
    assert cap.white_balance["b"] > 1.5 and cap.exposure_bias_ev == pytest.approx(0.2447, abs=1e-3)
    assert 60 <= int(cap.raw.min()) and int(cap.raw.max()) <= 1023
    # the capture points at its white image through the geometry-correction hash
    frames = read_caldata(out / info["caldata"])
    assert [f.is_dark for f in frames] == [False] * len(WHITE_STEPS) + [True]
    match = [f.name for f in frames if f.geometry_hash == cap.geometry_hash]
    assert match == [info["capture_white"]]
    assert [(f.zoom_step, f.focus_step) for f in frames[:-1]] == list(WHITE_STEPS)
    dark = frames[-1].raw.astype(float)
    assert abs(np.median(dark) - 64) <= 1
    # white images: bright micro-image centres, dark gaps
    w = frames[2].raw
    assert np.percentile(w, 99) > 700 and np.percentile(w, 5) < 120


def test_imageio_reads_the_virtual_capture(virtual, monkeypatch):
    iio = pytest.importorskip("imageio.v2")
    lytro = pytest.importorskip("imageio.plugins.lytro")
    out, info = virtual
    cap = read_capture(out / "IMG_0002.LFR")
    monkeypatch.setattr(lytro, "LYTRO_ILLUM_IMAGE_SIZE", cap.raw.shape)  # its sensor size is hard-coded
    im = iio.imread(out / "IMG_0002.LFR", format="lytro-lfr")
    np.testing.assert_array_equal(np.rint(im * 1023.0).astype(np.uint16), cap.raw)
    assert im.meta["privateMetadata"]["camera"]["serialNumber"] == info["serial"]
    assert im.meta["metadata"]["devices"]["lens"]["zoomStep"] == WHITE_STEPS[2][0]


def test_forward_model_is_consistent():
    g = illum_grid((240, 320), random_state=1)
    rows, cols = output_shape(g)
    flat = np.full((3, 3, rows, cols, 3), 0.5, np.float32)
    irr = render_irradiance(flat, g, scale_e_per_s=1000.0)
    vig = vignetting(g)
    # a uniform light field gives 0.5 * scale * transmission on every pixel
    np.testing.assert_allclose(irr, 500.0 * vig, rtol=1e-5, atol=1e-3)
    # each micro image is a disk of radius 0.46 x pitch with a 1.5-px soft edge: light reaches
    # the share pi (0.46 s + 0.75)^2 / (s * s sqrt(3)/2) of a hexagonal cell (95 %), nothing
    # between the disks, and about all of it at the centre of the central lenslets
    s = g.spacing_x_px
    assert g.spacing_y_px == pytest.approx(s * np.sqrt(3) / 2, rel=1e-3)
    assert (vig > 0).mean() == pytest.approx(np.pi * (0.46 * s + 0.75) ** 2 / (s * g.spacing_y_px), rel=0.03)
    assert vig.min() == 0.0
    h, w = vig.shape
    assert vig[h // 2 - 10:h // 2 + 10, w // 2 - 10:w // 2 + 10].max() > 0.99
    # the zoom step spreads the micro images
    assert illum_grid((240, 320), random_state=1, zoom_step=300).spacing_x_px > g.spacing_x_px


def test_bad_input(tmp_path, virtual, capsys):
    lf = LightField(data=np.ones((3, 3, 8, 8, 1), np.float32))
    with pytest.raises(ShapeError, match="RGB light field"):
        make_virtual_illum(lf, tmp_path / "a", sensor="small")
    rgb = LightField(data=np.ones((3, 3, 8, 8, 3), np.float32))
    with pytest.raises(InputError, match="sensor: expected one of full, small"):
        make_virtual_illum(rgb, tmp_path / "b", sensor="medium")
    with pytest.raises(InputError, match="exposures-ev"):
        make_virtual_illum(rgb, tmp_path / "c", sensor="small", exposures_ev=[])
    out, _ = virtual
    with pytest.raises(OutputExistsError):
        make_virtual_illum(rgb, out, sensor="small")
    rc = main(["virtual-illum", str(tmp_path / "missing.exr"), "-o", str(tmp_path / "d"), "--sensor", "small"])
    assert rc == 2
    assert "virtual-illum: error" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
