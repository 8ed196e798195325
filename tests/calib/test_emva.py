"""EMVA 1288: descriptor format and the linear-model evaluation on simulated data sets."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from lfproc.sensor import load_profile
from lfproc.calib.calibrate import calibrate
from lfproc.calib.emva import (EmvaDescriptor, EmvaStep, evaluate_descriptor, format_descriptor, is_descriptor,
                               read_descriptor, saturation_index, write_descriptor)
from lfproc.calib.simulate_frames import expected_figures, simulate_frames
from lfproc.cli.main import main
from lfproc.errors import CalibrationError, FileFormatError, InputError, OutputExistsError, UnsafeFileError


@pytest.fixture(scope="module")
def emva_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("emva") / "set"
    return simulate_frames("paper-high", out, format="emva", size=(96, 96), random_state=11)


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
    assert abs(fig["LE_min"]) < 0.5 and abs(fig["LE_max"]) < 0.5
    assert fig["DSNU1288"] is None or fig["DSNU1288"] < 0.3  # the sensor has no DSNU


def test_emva_spatial_figures(tmp_path):
    from dataclasses import replace

    prof = replace(load_profile("paper-high"), prnu=0.01, dsnu_e=1.5, fixed_pattern_seed=2)
    path = simulate_frames(prof, tmp_path / "s", format="emva", size=(64, 64), random_state=1)
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
    # the profile's full well reaches the code where the over-exposed pairs pile up (the ADC
    # clip, 4095 DN); the EMVA saturation capacity at the variance maximum lies below it
    want = expected_figures(load_profile("paper-high"), 100)
    assert res.profile.isos[100].full_well_e == pytest.approx(want["saturation_capacity_e"], rel=0.015)
    assert f["saturation_capacity_emva_e"] == pytest.approx(f["emva1288"]["u_e_sat"])
    assert f["saturation_capacity_emva_e"] < res.profile.isos[100].full_well_e
    # the folder holding the descriptor is accepted as well
    assert main(["calibrate", str(emva_set.parent), "-o", str(tmp_path / "p.json"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    figs = doc["isos"]["default"]
    for key in ("gain_dn_per_e", "read_noise_dn", "read_noise_e", "black_level_dn", "full_well_e",
                "dark_current_e_per_s"):
        assert isinstance(figs[key], float)
    assert load_profile(tmp_path / "p.json").isos[100].gain_dn_per_e == pytest.approx(figs["gain_dn_per_e"])


def _designed_set(tmp_path):
    """A 4 x 4 pixel EMVA set whose statistics are exact by construction.

    Each pair is ``A = mu + delta s``, ``B = mu - delta s`` with ``s`` a +-1 checkerboard (zero
    mean), so the pair mean is ``mu`` and the EMVA temporal variance
    ``mean(((A - mu_A) - (B - mu_B))^2) / 2`` is exactly ``2 delta^2``. Designed sensor: dark
    level 100 DN with variance 8 DN^2; gain K = 0.5 DN/e- and responsivity R = 0.4 DN/photon
    (QE 0.8), i.e. ``2 delta^2 - 8 = 0.5 (mu - 100)`` and ``mu - 100 = 0.4 photons``; the
    variance peaks at the fourth step and falls at the fifth (saturation).
    """
    s = np.where(np.indices((4, 4)).sum(0) % 2 == 0, 1, -1)
    steps, k = [], 0

    def pair(kind, mu, delta, photons):
        nonlocal k
        paths = []
        for sign in (1, -1):
            k += 1
            p = tmp_path / f"{kind}{k}.png"
            cv2.imwrite(str(p), (mu + sign * delta * s).astype(np.uint16))
            paths.append(p)
        steps.append(EmvaStep(kind, 1000.0, photons, tuple(paths)))

    for mu, delta, photons in ((148, 4, 120), (228, 6, 320), (340, 8, 600), (484, 10, 960), (4000, 2, 2000)):
        pair("bright", mu, delta, photons)
        pair("dark", 100, 2, None)
    path = tmp_path / "designed.txt"
    path.write_text(format_descriptor(EmvaDescriptor("3.1", 12, 4, 4, tuple(steps)), base=tmp_path))
    return path


def test_photon_transfer_figures_of_a_designed_set_match_hand_computed_values(tmp_path):
    """EMVA 1288 figures worked out by hand from the designed statistics (see _designed_set)."""
    _, data, fig, unknown = evaluate_descriptor(_designed_set(tmp_path))
    np.testing.assert_allclose(data.u_y, [148, 228, 340, 484, 4000])
    np.testing.assert_allclose(data.s2_y, [32, 72, 128, 200, 8])
    assert fig["index_u_ysat"] == 3 and fig["fit_range"] == [0, 2]  # 70 % of 384 DN: the first three steps
    assert fig["K"] == pytest.approx(0.5, rel=1e-12)
    assert fig["R"] == pytest.approx(0.4, rel=1e-12)
    assert fig["QE"] == pytest.approx(0.8, rel=1e-12)
    assert fig["black_level_dn"] == pytest.approx(100.0)
    assert fig["sigma_y_dark"] == pytest.approx(2.8284271, rel=1e-7)  # sqrt(8)
    assert fig["sigma_d"] == pytest.approx(5.6273143, rel=1e-7)  # sqrt(8 - 1/12) / 0.5
    assert fig["u_p_sat"] == pytest.approx(960.0)
    assert fig["u_e_sat"] == pytest.approx(768.0)  # 0.8 x 960
    assert fig["u_e_min"] == pytest.approx(6.1568542, rel=1e-7)  # sqrt(8) / 0.5 + 1/2
    assert fig["u_p_min"] == pytest.approx(7.6960678, rel=1e-7)  # / 0.8
    assert fig["SNR_max"] == pytest.approx(27.712813, rel=1e-7)  # sqrt(768)
    assert fig["DR"] == pytest.approx(124.739026, rel=1e-7)  # 768 / 6.1568542
    assert fig["DR_dB"] == pytest.approx(41.920, abs=1e-3)
    assert fig["LE_min"] == pytest.approx(0.0, abs=1e-9) and fig["LE_max"] == pytest.approx(0.0, abs=1e-9)
    assert fig["u_I_mean"] is None and "1 exposure time" in unknown["u_I_mean"]


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
    # Poisson counts in DN behave like a sensor of gain 1 DN/e-: K ~ 1, and the dark Poisson(100)
    # noise gives sigma_d ~ sqrt(100 - 1/12) = 10 e- (8 x 8 pixels per pair: +-25 %)
    assert fig["K"] == pytest.approx(1.0, rel=0.25) and fig["sigma_d"] == pytest.approx(10.0, rel=0.25)
    with pytest.raises(CalibrationError, match="no saturation level"):
        calibrate(tmp_path / "d.txt")


def test_wrong_frame_size_is_named(tmp_path):
    path = _tiny_set(tmp_path, 2)
    cv2.imwrite(str(tmp_path / "dark1_1.png"), np.zeros((4, 8), np.uint16))
    with pytest.raises(CalibrationError, match=r"dark1_1.png: frame is 4x8 pixels; the descriptor's 'n' line says 8x8"):
        evaluate_descriptor(path)


@pytest.mark.slow  # calibration through CLI and report
def test_emva_figures_shown_and_consistent_everywhere(emva_set, tmp_path, capsys):
    """QE, sigma_y.dark and the saturation capacity appear in the calibrate output, the report
    summary and profile show, and the saturation code is the same number in all of them."""
    prof = tmp_path / "p.json"
    report = tmp_path / "report"
    assert main(["calibrate", str(emva_set), "-o", str(prof), "--report", str(report), "--json"]) == 0
    figs = json.loads(capsys.readouterr().out)["isos"]["default"]
    assert figs["quantum_efficiency"] == pytest.approx(1.0, rel=0.02)  # lfproc's sensor has QE 1
    assert figs["temporal_dark_noise_dn"] == pytest.approx(np.hypot(0.5733, np.sqrt(1 / 12)), rel=0.03)
    # the simulated sensor's saturation capacity (expected_figures), reached just below the clip level
    want_sat = expected_figures(load_profile("paper-high"), 100)["saturation_capacity_e"]
    assert figs["saturation_capacity_emva_e"] == pytest.approx(want_sat, rel=0.05)
    assert figs["saturation_capacity_emva_e"] < want_sat
    # the simulated set's brightest pairs clip at the 12-bit ADC code (test_simulated_emva_set_layout)
    assert figs["saturation_dn"] == 4095
    assert main(["profile", "show", str(prof), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["saturation_dn"]["100"] == figs["saturation_dn"]
    assert shown["source"]["emva1288"]["100"]["quantum_efficiency"] == pytest.approx(figs["quantum_efficiency"])
    summary = (report / "summary.md").read_text()
    qe_row = next(line for line in summary.splitlines() if line.startswith("| QE"))
    assert f"{figs['quantum_efficiency']:.5g}" in qe_row
    cap_row = next(line for line in summary.splitlines() if "mu_e.sat" in line)
    assert "unknown" not in cap_row and f"{figs['saturation_capacity_emva_e']:.5g}" in cap_row
    sat_row = next(line for line in summary.splitlines() if line.startswith("| saturation (DN)"))
    assert "| 4095 |" in sat_row
    # text outputs
    assert main(["calibrate", str(emva_set), "-o", str(prof), "--force"]) == 0
    text = capsys.readouterr().out
    assert "quantum_efficiency" in text and "temporal_dark_noise_dn" in text and "monochrome" in text
    assert main(["profile", "show", str(prof)]) == 0
    text = capsys.readouterr().out
    qe = next(line for line in text.splitlines() if line.startswith("quantum_efficiency"))
    assert f"{figs['quantum_efficiency']:.5g}" in qe
    sat = next(line for line in text.splitlines() if line.startswith("saturation_dn"))
    assert sat.split()[1] == "4095"


def test_emva_sensor_stays_monochrome(emva_set, tmp_path, capsys):
    res = calibrate(emva_set)
    assert res.profile.cfa_pattern == "mono" and res.profile.is_mono
    assert "cfa_pattern" not in res.profile.unknown
    from lfproc.sensor import save_profile

    save_profile(res.profile, tmp_path / "m.json")
    assert load_profile(tmp_path / "m.json").cfa_pattern == "mono"
    assert main(["profile", "show", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "RGGB" not in out and "mono" in out
    # a Bayer sensor measured per channel: --cfa says so
    assert calibrate(emva_set, cfa_pattern="GRBG").profile.cfa_pattern == "GRBG"
    # the coded-mask camera needs a Bayer sensor: one line naming the reason
    from lfproc.synth import synthesize

    lf = synthesize("layers", size=(16, 16), views=3, random_state=0)
    with pytest.raises(InputError, match="monochrome"):
        from lfproc.camera.simulate import simulate_capture

        simulate_capture(lf, profile=res.profile, isos=[100], random_state=0)


# -- the report of an EMVA 1288 data set (issue 20, item 5) ---------------------------------------

@pytest.mark.slow  # report plots
def test_emva_report_names_the_stored_iso_and_draws_the_emva_plots(emva_set, tmp_path):
    from PIL import Image

    from lfproc.calib.report import write_report

    res = calibrate(emva_set)
    assert res.iso_label("default") == "ISO 100" and res.figures["default"]["iso"] == 100
    names = [f.name for f in write_report(res, tmp_path / "rep")]
    assert {"snr.png", "linearity.png", "prnu_dsnu_histograms.png", "photon_transfer.png"} <= set(names)
    assert "read_noise_vs_iso.png" not in names  # one ISO: no empty read-noise plot
    md = (tmp_path / "rep" / "summary.md").read_text()
    assert "| figure | ISO 100 |" in md and "ISO default" not in md
    titles = [Image.open(tmp_path / "rep" / n).text["Title"] for n in names if n.endswith(".png")]
    assert len(set(titles)) == len(titles), titles  # one title per plot


@pytest.mark.slow  # report plots
def test_report_labels_stay_inside_the_pictures(emva_set, tmp_path):
    """Wide tick labels (a dark variance near 1e6 DN^2) used to push the y label out of the PNG."""
    from dataclasses import replace

    from PIL import Image

    from lfproc.calib.report import write_report

    res = calibrate(emva_set)
    c = dict(res.curves["default"])
    t = np.asarray(c["dark_var_exposure_s"], float)
    c["dark_var_dn2"] = (-12345.6 + 912345.6 * t / t.max()).tolist()
    c["read_var_dn2"] = -12345.6
    for f in write_report(replace(res, curves={"default": c}), tmp_path / "rep"):
        if f.suffix == ".png":
            grey = np.asarray(Image.open(f).convert("L"))
            border = np.concatenate([grey[:, 0], grey[:, -1], grey[0, :], grey[-1, :]])
            assert (border > 200).all(), f"{f.name}: something is cut off at the border"


def test_emva_data_give_per_pixel_bias_and_flat_maps(tmp_path):
    from dataclasses import replace

    from lfproc.sensor import save_profile
    from lfproc.sensor import fixed_pattern

    prof = replace(load_profile("paper-high"), prnu=0.01, dsnu_e=1.5, fixed_pattern_seed=2)
    res = calibrate(simulate_frames(prof, tmp_path / "s", format="emva", size=(64, 64), random_state=1))
    p = res.profile
    gain, offset = fixed_pattern(prof, (64, 64))
    assert p.flat_field.shape == (64, 64) and p.flat_field.mean() == pytest.approx(1.0, abs=1e-6)
    assert (p.flat_field - gain).std() == pytest.approx(p.flat_field_std, rel=0.15)
    h = prof.isos[100].gain_dn_per_e
    bias = p.bias_frames[100].astype(np.float64)
    assert ((bias - bias.mean()) / h - offset).std() == pytest.approx(p.bias_frame_std_dn[100] / h, rel=0.15)
    assert bias.mean() == pytest.approx(p.black_level_dn, abs=0.05)
    back = load_profile(save_profile(p, tmp_path / "emva.json"))
    np.testing.assert_array_equal(back.flat_field, p.flat_field)
    np.testing.assert_array_equal(back.bias_frames[100], p.bias_frames[100])


def test_saturation_mean_key_and_old_profiles(emva_set, tmp_path):
    from lfproc.sensor import save_profile

    res = calibrate(emva_set)
    f = res.figures["default"]
    assert "saturation_variance_max_dn" not in f
    assert f["saturation_mean_dn"] == pytest.approx(f["emva1288"]["u_y_sat"])  # EMVA mu_y.sat, a mean
    path = save_profile(res.profile, tmp_path / "p.json")
    doc = json.loads(path.read_text())
    assert "saturation_mean_dn" in doc["source"]["emva1288"]["100"]
    figs = doc["source"]["emva1288"]["100"]
    figs["saturation_variance_max_dn"] = figs.pop("saturation_mean_dn")  # as older lfproc wrote it
    path.write_text(json.dumps(doc))
    old = load_profile(path).source["emva1288"]["100"]
    assert old["saturation_mean_dn"] == pytest.approx(f["saturation_mean_dn"])
    assert "saturation_variance_max_dn" not in old
