"""Calibration from bias/dark/flat frames: round trip simulate-frames -> calibrate, bad input,
report and CLI."""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from lfproc.sensor import load_profile
from lfproc.calib.calibrate import calibrate, find_calibration_input
from lfproc.calib.frames import read_manifest
from lfproc.calib.report import write_report
from lfproc.calib.simulate_frames import expected_figures, simulate_frames
from lfproc.cli.main import main
from lfproc.errors import CalibrationError, FileFormatError, InputError, MissingFileError, ProfileError

ISOS = (100, 400, 1600)


def _test_profile():
    """paper-high with a 100 e-/s dark current (5 % measurable in a few seconds), PRNU and DSNU."""
    base = load_profile("paper-high")
    base = replace(base, isos={k: v for k, v in base.isos.items() if k in ISOS})
    base = base.with_noise(read_noise_e=2.8, dark_current_e_per_s=100.0, name="test-high")
    return replace(base, prnu=0.01, dsnu_e=1.0, fixed_pattern_seed=5)


@pytest.fixture(scope="module")
def profile():
    return _test_profile()


@pytest.fixture(scope="module")
def frames(tmp_path_factory, profile):
    out = tmp_path_factory.mktemp("calib") / "frames"
    return simulate_frames(profile, out, size=(128, 128), random_state=7)


@pytest.fixture(scope="module")
def result(frames):
    return calibrate(frames)


@pytest.mark.parametrize("iso", ISOS)
def test_round_trip_recovers_the_profile(result, profile, iso):
    want = expected_figures(profile, iso)
    got = result.figures[str(iso)]
    assert got["gain_dn_per_e"] == pytest.approx(want["gain_dn_per_e"], rel=0.02)
    assert got["read_noise_e"] == pytest.approx(want["read_noise_e"], rel=0.02)
    assert got["read_noise_dn"] == pytest.approx(want["read_noise_dn"], rel=0.02)
    assert got["dark_current_e_per_s"] == pytest.approx(want["dark_current_e_per_s"], rel=0.05)
    assert got["dark_current_var_e_per_s"] == pytest.approx(want["dark_current_e_per_s"], rel=0.05)
    # measured saturation capacity vs (saturation_dn - black) / gain (ADC clips first here)
    assert got["saturation_dn"] == want["saturation_dn"]
    assert got["full_well_e"] == pytest.approx(want["saturation_capacity_e"], rel=0.02)
    assert got["black_level_dn"] == pytest.approx(want["black_level_dn"], abs=0.05)
    assert got["dsnu_e"] == pytest.approx(profile.dsnu_e, rel=0.1)
    assert got["prnu"] == pytest.approx(profile.prnu, rel=0.1)
    assert got["hot_pixels"] == 0
    # the EMVA saturation capacity sits at the variance maximum, below the clip level
    assert got["saturation_capacity_emva_e"] < got["full_well_e"]
    assert got["channels_differ"] == []
    assert set(got["channels"]) == {"R", "Gr", "Gb", "B"}
    for ch in got["channels"].values():
        assert ch["gain_dn_per_e"] == pytest.approx(want["gain_dn_per_e"], rel=0.05)
    assert np.isfinite([v for v in got.values() if isinstance(v, float)]).all()


def test_profile_and_read_noise_split(result, profile):
    prof = result.profile
    assert prof.adc_bits == 12 and prof.white_level_dn == 4095 and prof.cfa_pattern == "RGGB"
    assert prof.iso_values == list(ISOS)
    assert prof.bias_frames[400].shape == (128, 128)
    assert float(prof.bias_frames[400].mean()) == pytest.approx(64, abs=0.1)
    assert prof.dark_current_e_per_s == pytest.approx(100, rel=0.05)
    # expose() with the measured profile saturates where the true sensor does
    for iso in ISOS:
        assert prof.saturation_dn(iso) == pytest.approx(profile.saturation_dn(iso), abs=1)
    m = result.read_noise_model
    assert m["sigma_pre_e"] == pytest.approx(2.8, rel=0.03)
    assert m["sigma_post_dn"] < 0.3
    assert list(result.unknown) == ["quantum_efficiency"]  # frames carry no photon counts
    assert "photon counts" in result.unknown["quantum_efficiency"]


def test_csv_and_json_manifests_agree(frames, result):
    # the folder simulate-frames wrote: calibrate finds its manifest.json
    assert find_calibration_input(frames.parent) == frames.with_name("manifest.json")
    other = calibrate(frames.parent)
    assert other.profile.name == "test-high-simulated" and other.source["input"].endswith("manifest.json")
    for iso in ISOS:
        assert other.figures[str(iso)]["gain_dn_per_e"] == result.figures[str(iso)]["gain_dn_per_e"]


def test_saved_profile_round_trip(result, tmp_path):
    from lfproc.sensor import save_profile

    path = save_profile(result.profile, tmp_path / "measured.json")
    back = load_profile(path)
    assert back.isos == result.profile.isos
    np.testing.assert_array_equal(back.bias_frames[100], result.profile.bias_frames[100])


def test_flat_field_and_bias_frames_match_the_sensor_maps(result, profile, tmp_path):
    """The measured maps against the simulated sensor's own (lfproc.camera.sensor.fixed_pattern): their
    errors have the standard deviation the calibration records."""
    from lfproc.sensor import save_profile
    from lfproc.sensor import fixed_pattern

    prof = result.profile
    gain, offset = fixed_pattern(profile, (128, 128))
    assert prof.flat_field.shape == (128, 128) and prof.flat_field.dtype == np.float32
    err = prof.flat_field - gain
    assert err.std() == pytest.approx(prof.flat_field_std, rel=0.1)
    assert prof.flat_field_std < 0.2 * profile.prnu  # the map resolves the 1 % PRNU
    assert abs(err.mean()) < 1e-3  # mean 1 per CFA position vs the sensor's mean over all pixels
    for r in (0, 1):
        for c in (0, 1):
            assert prof.flat_field[r::2, c::2].mean() == pytest.approx(1.0, abs=1e-6)
    assert [result.figures[str(i)]["flat_field_std"] for i in ISOS] == sorted(
        result.figures[str(i)]["flat_field_std"] for i in ISOS)  # fewer electrons at higher ISO
    for iso in ISOS:
        h = profile.isos[iso].gain_dn_per_e
        frame = prof.bias_frames[iso].astype(np.float64)
        dsnu_err = (frame - frame.mean()) / h - offset
        assert dsnu_err.std() == pytest.approx(prof.bias_frame_std_dn[iso] / h, rel=0.1)
    path = save_profile(prof, tmp_path / "measured.json")
    doc = json.loads(path.read_text())
    assert doc["flat_field_file"] == "measured.flat.npz" and doc["flat_field_std"] == prof.flat_field_std
    back = load_profile(path)
    np.testing.assert_array_equal(back.flat_field, prof.flat_field)
    assert back.flat_field_std == prof.flat_field_std and back.bias_frame_std_dn == prof.bias_frame_std_dn
    (tmp_path / "measured.flat.npz").unlink()
    with pytest.raises(ProfileError, match=r"measured.json: field 'flat_field_file': .*measured.flat.npz does not exist"):
        load_profile(path)


def test_measured_maps_make_t_unbiased_per_pixel(result, profile):
    """Captures of the true sensor, observed with its measured maps: per pixel, the mean of 100 draws is
    within the noise of the mean plus the maps' recorded uncertainty; without correction it is not."""
    from lfproc.sensor import calibrated_observation, expose, fixed_pattern_correction

    prof = result.profile
    # the true profile with the measured maps only, so that gain or dark-current errors stay out
    measured = replace(profile, source={"kind": "calibrated"}, fixed_pattern_seed=0, flat_field=prof.flat_field,
                       flat_field_std=prof.flat_field_std, bias_frames=prof.bias_frames,
                       bias_frame_std_dn=prof.bias_frame_std_dn)
    rng = np.random.default_rng(0)
    iso = rng.choice([100.0, 400.0, 1600.0], size=(128, 128))
    t = 0.01
    electrons = np.exp(rng.uniform(np.log(50), np.log(4000), size=iso.shape))
    E = np.where(iso == 1600, np.minimum(electrons, 1000), electrons) / t
    fp = fixed_pattern_correction(measured, iso.shape, iso)
    assert fp.gain_source == "flat_field" and fp.offset_source == "bias_frames (ISO 100, 400, 1600)"
    map_var = E**2 * fp.gain_var / fp.gain**2 + fp.offset_var_e2 / (t * fp.gain) ** 2
    draws = 100
    T = np.zeros(iso.shape)
    V = np.zeros(iso.shape)
    T_plain = np.zeros(iso.shape)
    for _ in range(draws):
        dn = expose(E, exposure_s=t, iso=iso, profile=profile, random_state=rng)
        kw = dict(exposure_s=t, iso=iso, variance_from="estimate", radiance_estimate=E)
        obs = calibrated_observation(dn, profile=measured, **kw)
        T += obs.radiance / draws
        V += obs.variance / draws
        T_plain += calibrated_observation(dn, profile=measured, correct_fixed_pattern=False, **kw).radiance / draws
    noise_var = V - map_var  # the part of the variance that averages down over draws
    z = (T - E) / np.sqrt(noise_var / draws + map_var)
    assert abs(z.mean()) < 4.5 / np.sqrt(z.size)
    assert z.var() == pytest.approx(1.0, abs=0.08)
    assert ((T_plain - E) / np.sqrt(noise_var / draws + map_var)).var() > 3


@pytest.mark.slow  # calibration report plots
def test_report(result, tmp_path):
    files = write_report(result, tmp_path / "rep")
    names = {f.name for f in files}
    assert {"photon_transfer.png", "dark_level.png", "dark_variance.png", "read_noise_vs_iso.png",
            "summary.md", "snr.png", "linearity.png", "prnu_dsnu_histograms.png"} <= names
    for f in files:
        assert f.stat().st_size > 0
    assert cv2.imread(str(tmp_path / "rep" / "photon_transfer.png")).shape[2] == 3
    md = (tmp_path / "rep" / "summary.md").read_text()
    # the table shows the measured figures, one column per ISO (the gains are near the true
    # 0.2048, 0.819 and 3.276 DN/e- of paper-high at ISO 100, 400 and 1600)
    row = next(line for line in md.splitlines() if line.startswith("| gain (DN/e-) |"))
    cells = [float(c) for c in row.strip("|").split("|")[1:]]
    np.testing.assert_allclose(cells, [result.figures[str(i)]["gain_dn_per_e"] for i in ISOS], rtol=1e-4)
    np.testing.assert_allclose(cells, [0.2048, 0.819, 3.276], rtol=0.02)
    sigma = float(md.split("sigma_pre = ")[1].split(" e-")[0])
    assert sigma == pytest.approx(result.read_noise_model["sigma_pre_e"], rel=1e-3)
    # figures.json holds the result's figures
    doc = json.loads((tmp_path / "rep" / "figures.json").read_text())
    assert doc["isos"]["400"]["gain_dn_per_e"] == result.figures["400"]["gain_dn_per_e"]


# -- bad input -------------------------------------------------------------------------------
def _rows(frames: Path):
    with open(frames) as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r["path"] = str(frames.parent / r["path"])
    return rows


def _manifest(tmp_path, rows, name="m.csv"):
    p = tmp_path / name
    with open(p, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return p


def _select(rows, iso, kinds=("bias", "dark", "flat")):
    return [r for r in rows if float(r["iso"]) == iso and r["kind"] in kinds]


def test_missing_iso_or_exposure_names_the_row(frames, tmp_path):
    rows = _select(_rows(frames), 100)
    rows[2] = dict(rows[2], iso="")
    with pytest.raises(InputError, match=r"m.csv line 4: missing ISO"):
        calibrate(_manifest(tmp_path, rows), frames_root=tmp_path.parent)
    rows = _select(_rows(frames), 100)
    rows[5] = dict(rows[5], exposure_s="fast")
    with pytest.raises(InputError, match=r"m.csv line 7: exposure_s: expected a number"):
        read_manifest(_manifest(tmp_path, rows), root=tmp_path.parent)
    bad = tmp_path / "nocol.csv"
    bad.write_text("path,kind\nx.png,bias\n")
    with pytest.raises(FileFormatError, match="lacks column.*iso"):
        read_manifest(bad)


def test_unreadable_and_missing_frames(frames, tmp_path):
    rows = _select(_rows(frames), 100)
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    rows[3] = dict(rows[3], path=str(broken))
    with pytest.raises(FileFormatError, match="broken.png: cannot read"):
        calibrate(_manifest(tmp_path, rows), frames_root=tmp_path.parent)
    rows[3] = dict(rows[3], path=str(tmp_path / "gone.png"))
    with pytest.raises(MissingFileError, match="gone.png"):
        calibrate(_manifest(tmp_path, rows), frames_root=tmp_path.parent)


def test_mixed_sizes_name_the_files(frames, tmp_path):
    rows = _select(_rows(frames), 100)
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((64, 64), 64, np.uint16))
    rows[1] = dict(rows[1], path=str(small))
    with pytest.raises(CalibrationError, match=r"mixed frames in ISO 100: .*small.png differs from .*iso100_.*png \(size 64x64 vs 128x128"):
        calibrate(_manifest(tmp_path, rows), frames_root=tmp_path.parent)


def test_single_bias_frame_records_unknown_read_noise(frames, profile, tmp_path):
    rows = _rows(frames)
    first_bias = next(r for r in rows if r["kind"] == "bias" and float(r["iso"]) == 400)
    rows = [r for r in rows if not (r["kind"] == "bias" and float(r["iso"]) == 400) or r is first_bias]
    # with dark pairs at several exposures the read noise is their intercept at t = 0
    res = calibrate(_manifest(tmp_path, rows), frames_root=tmp_path.parent)
    assert res.figures["400"]["read_noise_method"].startswith("intercept of the dark pair variance")
    assert res.figures["400"]["read_noise_dn"] == pytest.approx(2.8 * 0.819, rel=0.15)
    # without darks nothing gives a temporal pair at ISO 400
    rows = [r for r in rows if not (r["kind"] == "dark" and float(r["iso"]) == 400)]
    res = calibrate(_manifest(tmp_path, rows), frames_root=tmp_path.parent)
    f = res.figures["400"]
    assert f["read_noise_dn"] is None and f["read_noise_e"] is None and f["gain_dn_per_e"] is None
    assert "needs a pair of bias frames; ISO 400 has 1 bias frame" in res.unknown["isos.400.read_noise_dn"]
    assert "dark" in res.unknown["isos.400.dark_current_e_per_s"]
    assert res.profile.isos[400].read_noise_e is None
    # the other ISOs are unaffected: still measured, at the simulated profile's gain
    assert res.figures["100"]["gain_dn_per_e"] == pytest.approx(expected_figures(profile, 100)["gain_dn_per_e"],
                                                                rel=0.02)


def test_flats_without_pairs_record_unknown_gain(frames, tmp_path):
    rows = _rows(frames)
    seen = set()
    keep = []
    for r in rows:
        key = (r["iso"], r["kind"], r["exposure_s"])
        if r["kind"] == "flat" and float(r["iso"]) == 1600:
            if key in seen:
                continue
            seen.add(key)
        keep.append(r)
    res = calibrate(_manifest(tmp_path, keep), frames_root=tmp_path.parent)
    assert res.figures["1600"]["gain_dn_per_e"] is None
    assert "no frame pairs" in res.unknown["isos.1600.gain_dn_per_e"]


def test_all_saturated_flats(frames, tmp_path):
    rows = _rows(frames)
    saturated = [r for r in rows if r["kind"] != "flat" or float(r["iso"]) == 100
                 or float(r["exposure_s"]) > 0.0105]
    res = calibrate(_manifest(tmp_path, saturated), frames_root=tmp_path.parent)
    assert res.figures["400"]["gain_dn_per_e"] is None
    assert "all 8 flat frames at ISO 400 are saturated (clipped at 4095 DN)" == res.unknown["isos.400.gain_dn_per_e"]
    assert res.figures["400"]["read_noise_dn"] == pytest.approx(2.8 * 0.819, rel=0.03)
    only = [r for r in saturated if float(r["iso"]) == 400]
    with pytest.raises(CalibrationError, match="no system gain at any ISO.*saturated"):
        calibrate(_manifest(tmp_path, only, "only.csv"), frames_root=tmp_path.parent)


def test_no_overexposed_flats(frames, tmp_path):
    rows = [r for r in _select(_rows(frames), 100) if r["kind"] != "flat" or float(r["exposure_s"]) < 0.0095]
    with pytest.raises(CalibrationError, match="no saturation level.*no flat frame reaches saturation"):
        calibrate(_manifest(tmp_path, rows), frames_root=tmp_path.parent)


def test_hot_pixels_are_found_and_masked(tmp_path, profile):
    out = simulate_frames(profile, tmp_path / "f", size=(64, 64), random_state=3, isos=[400])
    rows = _rows(out)
    hot = [(5, 7), (40, 33), (20, 60)]
    for r in rows:
        if r["kind"] == "dark":
            img = cv2.imread(r["path"], cv2.IMREAD_UNCHANGED)
            for y, x in hot:
                img[y, x] = min(4095, int(img[y, x]) + int(600 * float(r["exposure_s"])))
            cv2.imwrite(r["path"], img)
    res = calibrate(out)
    assert res.figures["400"]["hot_pixels"] == 3
    assert sorted((int(y), int(x)) for y, x in zip(*np.nonzero(res.hot_pixels["400"]))) == sorted(hot)
    assert res.figures["400"]["dark_current_e_per_s"] == pytest.approx(100, rel=0.05)


# -- CLI ---------------------------------------------------------------------------------------
@pytest.mark.slow  # calibration with plots
def test_cli_calibrate_json(frames, result, tmp_path, capsys):
    out = tmp_path / "p.json"
    assert main(["calibrate", str(frames), "-o", str(out), "--json", "--report", str(tmp_path / "rep")]) == 0
    doc = json.loads(capsys.readouterr().out)
    for iso in ("100", "400", "1600"):  # the command reports what the library measures
        figs = doc["isos"][iso]
        for key in ("gain_dn_per_e", "read_noise_dn", "read_noise_e", "black_level_dn", "full_well_e",
                    "dark_current_e_per_s"):
            assert figs[key] == pytest.approx(result.figures[iso][key], rel=1e-12)
    assert load_profile(out).isos[400].gain_dn_per_e == pytest.approx(0.819, rel=0.02)
    assert (tmp_path / "p.bias.npz").is_file() and (tmp_path / "rep" / "summary.md").is_file()
    assert (tmp_path / "p.flat.npz").is_file() and load_profile(out).flat_field.shape == (128, 128)
    assert main(["profile", "show", str(out), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["flat_field"] == [128, 128] and 0 < shown["flat_field_std"] < 0.002
    assert sorted(shown["bias_frame_std_dn"]) == ["100", "1600", "400"]
    assert main(["calibrate", str(frames), "-o", str(out)]) == 2
    assert "output exists" in capsys.readouterr().err


def test_cli_simulate_frames(tmp_path, capsys):
    assert main(["calibrate", "simulate-frames", "--profile", "paper-medium", "-o", str(tmp_path / "s"),
                 "--size", "16", "24", "--seed", "2", "--iso", "200", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["format"] == "manifest" and doc["size"] == [16, 24]
    records, _ = read_manifest(tmp_path / "s" / "manifest.csv")
    assert {r.kind for r in records} == {"bias", "dark", "flat"}
    assert {r.iso for r in records} == {200.0}
    assert len({r.exposure_s for r in records if r.kind == "dark"}) >= 3
    img = cv2.imread(str(records[0].path), cv2.IMREAD_UNCHANGED)
    assert img.dtype == np.uint16 and img.shape == (16, 24)
    # the frames are the profile's sensor: paper-medium at ISO 200 has black level 64 DN and read
    # noise 2 e- x 0.4095 DN/e- = 0.819 DN, 0.868 DN with the rounding's 1/12 DN^2
    bias = [cv2.imread(str(r.path), cv2.IMREAD_UNCHANGED).astype(float) for r in records if r.kind == "bias"][:2]
    assert np.mean(bias) == pytest.approx(64, abs=0.15)
    assert np.std(bias[0] - bias[1]) / np.sqrt(2) == pytest.approx(np.sqrt(0.819**2 + 1 / 12), rel=0.12)
    params = json.loads((tmp_path / "s" / "simulation.json").read_text())
    assert params["seed"] == 2 and params["profile"] == "paper-medium" and "lfproc_version" in params
    assert main(["calibrate", "simulate-frames", "--profile", "paper-medium", "-o", str(tmp_path / "s")]) == 2
    assert "output exists" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, match",
    [
        (["calibrate", "simulate-frames", "-o", "X"], "--profile is required"),
        (["calibrate", "M", "-o", "p.json", "--seed", "3"], "--seed: only for 'lfproc calibrate simulate-frames'"),
        (["calibrate", "nothere.csv", "-o", "p.json"], "nothere.csv: no such file or folder; expected a frame manifest"),
        (["calibrate", ".", "-o", "p.json"], ".: a folder; expected a frame manifest (manifest.json or manifest.csv) "
                                             "or an EMVA 1288 descriptor"),
    ],
)
def test_cli_errors_one_line(argv, match, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lfproc calibrate: error:")
    assert match in err[0]


def test_cli_bad_frames_one_line(frames, tmp_path, capsys):
    rows = _select(_rows(frames), 100)
    rows[0] = dict(rows[0], exposure_s="")
    m = _manifest(tmp_path, rows)
    assert main(["calibrate", str(m), "-o", str(tmp_path / "p.json"), "--frames-root", str(tmp_path.parent)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "m.csv line 2: missing exposure_s" in err[0]
    only = [r for r in _select(_rows(frames), 400) if r["kind"] != "flat" or float(r["exposure_s"]) > 0.0105]
    assert main(["calibrate", str(_manifest(tmp_path, only, "sat.csv")), "-o", str(tmp_path / "p.json"),
                 "--frames-root", str(tmp_path.parent)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "saturated" in err[0]
    assert not (tmp_path / "p.json").exists()


def test_demo_contact_sheet_shares_one_scale(frames, tmp_path):
    """Issue 20, item 5: the demo's sheet of calibration frames uses one display scale for every
    tile (bias dark, flats brighter with exposure, saturated flats white, not black)."""
    from lfproc.demo import SHEET_CAPTION, SHEET_HEAD, SHEET_LABEL, SHEET_PAD, SHEET_TILE, _frames_contact_sheet

    sheet = cv2.imread(str(_frames_contact_sheet(frames, tmp_path / "sheet.png")), cv2.IMREAD_GRAYSCALE)
    rows = {(r["kind"], float(r["exposure_s"])) for r in _rows(frames) if float(r["iso"]) == ISOS[0]}
    order = {"bias": 0, "dark": 1, "flat": 2}
    columns = sorted({(r["kind"], float(r["exposure_s"])) for r in _rows(frames)}, key=lambda c: (order[c[0]], c[1]))
    y0 = SHEET_CAPTION + SHEET_LABEL + 2
    means = {}
    for j, col in enumerate(columns):
        if col in rows:
            x0 = SHEET_HEAD + j * (SHEET_TILE + SHEET_PAD) + 2
            means[col] = float(sheet[y0:y0 + SHEET_TILE - 4, x0:x0 + SHEET_TILE - 4].mean())
    flats = [m for (kind, _), m in sorted(means.items(), key=lambda kv: kv[0][1]) if kind == "flat"]
    assert means[("bias", min(t for k, t in means if k == "bias"))] < 60
    assert flats == sorted(flats) and flats[-1] > 250  # brighter with exposure; the saturated one white
