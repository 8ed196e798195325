"""EMVA 1288: descriptor format and the linear-model evaluation on simulated data sets."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from lfproc.calib import load_profile
from lfproc.calib.calibrate import calibrate
from lfproc.calib.emva import (EmvaDescriptor, EmvaStep, evaluate_descriptor, format_descriptor, is_descriptor,
                               read_descriptor, saturation_index, write_descriptor)
from lfproc.calib.simulate_frames import expected_figures, simulate_frames
from lfproc.cli.main import main
from lfproc.errors import CalibrationError, FileFormatError, OutputExistsError, UnsafeFileError


@pytest.fixture(scope="module")
def emva_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("emva") / "set"
    return simulate_frames("paper-high", out, format="emva", size=(96, 96), seed=11)


def test_descriptor_parse(tmp_path):
    text = ("# EMVA data\nv 3.1\nn 12 4 3\nb 1000 12.5  # step\ni img\\a.png\ni img/b.png\n"
            "d 1000\ni img\\c.png\ni img\\d.png\n\nb 2e3 25\ni /abs/x.png\n")
    p = tmp_path / "desc.txt"
    p.write_text(text)
    assert is_descriptor(p)
    with pytest.raises(UnsafeFileError, match=r"line 12 .*'/abs/x.png' is an absolute path"):
        read_descriptor(p)  # images must lie in the descriptor's folder unless a root is named
    d = read_descriptor(p, root="/")
    assert (d.release, d.bits, d.width, d.height) == ("3.1", 12, 4, 3)
    assert [s.kind for s in d.steps] == ["bright", "dark", "bright"]
    assert d.steps[0].photons == 12.5 and d.steps[1].photons is None and d.steps[2].exposure_ns == 2000
    assert d.steps[0].images == (tmp_path / "img" / "a.png", tmp_path / "img" / "b.png")
    assert d.steps[2].images[0].as_posix() == "/abs/x.png"
    assert d.steps[0].exposure_s == pytest.approx(1e-6)
    # write and read back
    out = write_descriptor(d, tmp_path / "copy.txt")
    back = read_descriptor(out, root="/")
    assert back.steps == tuple(s.__class__(**{**s.__dict__, "line": b.line}) for s, b in zip(d.steps, back.steps))
    assert "i img/a.png" in out.read_text()
    with pytest.raises(OutputExistsError):
        write_descriptor(d, out)


@pytest.mark.parametrize(
    "text, match",
    [
        ("v 3\nn 12 4\n", r"line 2 .*expected 'n <bits> <width> <height>'"),
        ("v 3\nn 12 4 3\nb 100\n", r"line 3 .*expected 'b <exposure_ns> <photons>'"),
        ("v 3\nn 12 4 3\ni a.png\n", r"line 3 .*image line before any"),
        ("v 3\nn 12 4 3\nq 1\n", r"line 3 .*unknown item 'q'"),
        ("v 3\nb 1 2\ni a.png\n", r"no 'n <bits> <width> <height>' line"),
        ("v 3\nn 12 4 3\n", r"no 'b' or 'd' steps"),
        ("v 3\nn 12 4 3\nd -5\n", r"line 3 .*exposure must be"),
    ],
)
def test_descriptor_errors(tmp_path, text, match):
    p = tmp_path / "bad.txt"
    p.write_text(text)
    with pytest.raises(FileFormatError, match=match):
        read_descriptor(p)


def test_saturation_index_scans_from_the_top():
    s2 = np.array([1, 2, 9, 3, 4, 5, 6, 7, 8, 2, 1.0])  # an early noise peak (9) must not win
    assert saturation_index(s2) == 8
    assert saturation_index(np.arange(5.0)) == 4


def test_simulated_emva_set_layout(emva_set):
    d = read_descriptor(emva_set)
    bright_pairs = [s for s in d.steps if s.kind == "bright" and len(s.images) == 2]
    dark_pairs = [s for s in d.steps if s.kind == "dark" and len(s.images) == 2]
    stacks = [s for s in d.steps if len(s.images) == 50]
    assert len(bright_pairs) == len(dark_pairs) == 50
    assert sorted(s.kind for s in stacks) == ["bright", "dark"]
    assert (d.bits, d.width, d.height) == (12, 96, 96)
    img = cv2.imread(str(bright_pairs[-1].images[0]), cv2.IMREAD_UNCHANGED)
    assert img.dtype == np.uint16 and int(img.max()) == 4095  # the last steps are beyond saturation
    assert bright_pairs[0].photons < 0.01 * bright_pairs[-1].photons


def test_emva_evaluation_recovers_the_sensor(emva_set):
    want = expected_figures(load_profile("paper-high"), 100)
    _, data, fig, unknown = evaluate_descriptor(emva_set)
    assert fig["K"] == pytest.approx(want["gain_dn_per_e"], rel=0.02)
    assert fig["sigma_d"] == pytest.approx(want["read_noise_e"], rel=0.02)
    assert fig["u_e_sat"] == pytest.approx(want["saturation_capacity_e"], rel=0.05)
    assert fig["u_e_sat"] < want["saturation_capacity_e"]  # the variance maximum lies below the clip level
    assert fig["QE"] == pytest.approx(1.0, rel=0.02)  # lfproc's sensor has quantum efficiency 1
    assert fig["black_level_dn"] == pytest.approx(64, abs=0.05)
    assert fig["u_I_mean"] == pytest.approx(10.0, rel=0.1)
    assert fig["SNR_max"] == pytest.approx(np.sqrt(fig["u_e_sat"]))
    assert fig["DR"] == pytest.approx(fig["u_p_sat"] / fig["u_p_min"])
    assert fig["u_p_min"] == pytest.approx((fig["sigma_y_dark"] / fig["K"] + 0.5) / fig["QE"])
    assert abs(fig["LE_min"]) < 0.5 and abs(fig["LE_max"]) < 0.5
    assert fig["DSNU1288"] is None or fig["DSNU1288"] < 0.3  # the sensor has no DSNU


def test_emva_spatial_figures(tmp_path):
    from dataclasses import replace

    prof = replace(load_profile("paper-high"), prnu=0.01, dsnu_e=1.5, fixed_pattern_seed=2)
    path = simulate_frames(prof, tmp_path / "s", format="emva", size=(64, 64), seed=1)
    _, _, fig, unknown = evaluate_descriptor(path)
    assert fig["DSNU1288"] == pytest.approx(1.5, rel=0.1)
    assert fig["PRNU1288"] == pytest.approx(1.0, rel=0.1)  # percent
    assert fig["K"] == pytest.approx(0.20475, rel=0.02)


def test_calibrate_emva_to_profile(emva_set, tmp_path, capsys):
    res = calibrate(emva_set)
    f = res.figures["default"]
    assert f["gain_dn_per_e"] == pytest.approx(0.20475, rel=0.02)
    assert f["read_noise_e"] == pytest.approx(2.8, rel=0.02)
    assert res.profile.iso_values == [100] and "no ISO" in res.profile.unknown["iso"]
    assert res.profile.adc_bits == 12
    assert res.profile.isos[100].full_well_e == pytest.approx(f["emva1288"]["u_e_sat"])
    assert main(["calibrate", str(emva_set), "-o", str(tmp_path / "p.json"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    figs = doc["isos"]["default"]
    for key in ("gain_dn_per_e", "read_noise_dn", "read_noise_e", "black_level_dn", "full_well_e",
                "dark_current_e_per_s"):
        assert isinstance(figs[key], float)
    assert load_profile(tmp_path / "p.json").isos[100].gain_dn_per_e == pytest.approx(figs["gain_dn_per_e"])


def _tiny_set(tmp_path, images_per_step):
    rng = np.random.default_rng(0)
    steps = []
    for k, t in enumerate((1000, 2000, 3000)):
        for kind in ("bright", "dark"):
            paths = []
            for j in range(images_per_step):
                p = tmp_path / f"{kind}{k}_{j}.png"
                level = 100 + (400 * (k + 1) if kind == "bright" else 0)
                cv2.imwrite(str(p), rng.poisson(level, (8, 8)).astype(np.uint16))
                paths.append(p)
            steps.append(EmvaStep(kind, float(t), 100.0 * (k + 1) if kind == "bright" else None, tuple(paths)))
    d = EmvaDescriptor("3.1", 12, 8, 8, tuple(steps))
    path = tmp_path / "d.txt"
    path.write_text(format_descriptor(d, base=tmp_path))
    return path


def test_single_images_where_pairs_are_needed(tmp_path, capsys):
    path = _tiny_set(tmp_path, 1)
    with pytest.raises(CalibrationError, match="no bright step with an image pair"):
        evaluate_descriptor(path)
    assert main(["calibrate", str(path), "-o", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no bright step with an image pair" in err[0]


def test_unsaturated_data_record_unknown_saturation(tmp_path):
    _, data, fig, unknown = evaluate_descriptor(_tiny_set(tmp_path, 2))
    assert fig["u_e_sat"] is None and "do not reach saturation" in unknown["u_e_sat"]
    assert fig["K"] > 0 and np.isfinite(fig["sigma_d"])
    with pytest.raises(CalibrationError, match="no saturation level"):
        calibrate(tmp_path / "d.txt")


def test_wrong_frame_size_is_named(tmp_path):
    path = _tiny_set(tmp_path, 2)
    cv2.imwrite(str(tmp_path / "dark1_1.png"), np.zeros((4, 8), np.uint16))
    with pytest.raises(CalibrationError, match=r"dark1_1.png: frame is 4x8 pixels; the descriptor's 'n' line says 8x8"):
        evaluate_descriptor(path)
