"""Real calibrated captures: DNG files written from simulated sensor data, read back through rawpy
(LibRaw, an independent raw reader) by capture_from_raw and ``lfproc capture import``."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from lfproc.sensor import load_profile, save_profile
from lfproc.camera.capture import capture_from_raw, load_capture, observations, read_sensor_frame
from lfproc.camera.simulate import simulate_capture
from lfproc.cli.main import main
from lfproc.errors import LfprocWarning

H, W = 40, 48
ISOS = (100, 400, 800, 1600)


def _profile():
    # a sensor with a GRBG mosaic and a fixed pattern, so both must travel through the raw files
    base = load_profile("paper-medium")
    return replace(base, name="dng-sensor", cfa_pattern="GRBG", prnu=0.015, dsnu_e=2.0, fixed_pattern_seed=3)


def _lf(seed=0):
    rng = np.random.default_rng(seed)
    base = 0.02 + rng.random((1, 1, H, W, 3)).astype(np.float32) ** 3
    return np.broadcast_to(base, (5, 5, H, W, 3)).copy()


@pytest.fixture(scope="module")
def simulated():
    return simulate_capture(_lf(), profile=_profile(), iso_pattern_kind="row", isos=ISOS, shots=2, mask="random",
                            mask_period=4, exposure_s=0.004, relative_exposures=[1.0, 2.0], random_state=9)


@pytest.fixture(scope="module")
def files(simulated, tmp_path_factory, dng_writer):
    """The simulated shots as DNGs, the mask codes as .npy, the profile as JSON, the capture itself."""
    d = tmp_path_factory.mktemp("dng")
    profile = simulated.profile
    raws = [dng_writer(d / f"shot{s}.dng", simulated.dn[s], cfa_pattern=profile.cfa_pattern,
                       black_level=profile.black_level_dn, white_level=int(profile.white_level_dn),
                       exposure_s=simulated.exposures_s[s], iso=100)
            for s in range(simulated.shots)]
    np.save(d / "codes.npy", simulated.mask.codes)
    return {"dir": d, "raws": raws, "codes": d / "codes.npy", "profile": save_profile(profile, d / "sensor.json"),
            "capture": simulated.save(d / "sim.capture.npz")}


def _same_observations(a, b):
    oa, ob = observations(a), observations(b)
    for f in ("radiance", "variance", "weight", "saturated", "black_clipped"):
        np.testing.assert_array_equal(getattr(oa, f), getattr(ob, f))


def test_dng_frames_read_back_exactly(simulated, files):
    for s, path in enumerate(files["raws"]):
        dn, meta = read_sensor_frame(path)
        np.testing.assert_array_equal(dn, simulated.dn[s])
        assert meta["format"] == "raw" and meta["cfa_pattern"] == "GRBG"
        assert meta["black_level_dn"] == [64.0] * 4 and meta["white_level_dn"] == 4095.0


def test_capture_from_dng_equals_the_simulated_capture(simulated, files):
    cap = capture_from_raw(files["raws"], mask=simulated.mask, iso_layout=simulated.iso[0], profile=files["profile"],
                           exposures_s=simulated.exposures_s)
    np.testing.assert_array_equal(cap.dn, simulated.dn)
    assert cap.dn.dtype == np.uint16 and cap.cfa_pattern == simulated.cfa_pattern == "GRBG"
    assert cap.views == (5, 5) and cap.exposures_s == simulated.exposures_s
    assert cap.profile.black_level_dn == 64 and cap.profile.white_level_dn == 4095
    assert [f["black_level_dn"] for f in cap.parameters["frames"]] == [[64.0] * 4] * 2
    assert all(f["white_level_dn"] == 4095 for f in cap.parameters["frames"])
    _same_observations(cap, simulated)  # T, variance, weights: PRNU/DSNU corrected the same way
    lf = _lf()
    np.testing.assert_array_equal(cap.operator().forward(lf), simulated.operator().forward(lf))


def test_cli_import_then_info(simulated, files, tmp_path, capsys):
    out = tmp_path / "real.capture.npz"
    argv = ["capture", "import", *map(str, files["raws"]), "--mask", str(files["codes"]), "--mask-period", "4",
            "--iso-layout", "row", "--isos", "100,400,800,1600", "--profile", str(files["profile"]),
            "--exposures-s", "0.004,0.008", "-o", str(out), "--json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["shots"] == 2 and summary["size"] == [H, W] and summary["cfa_pattern"] == "GRBG"
    assert summary["raw_black_level_dn"] == [64.0] * 4 and summary["raw_white_level_dn"] == 4095.0
    assert summary["fixed_pattern"] == {"prnu": "simulated", "dsnu": "simulated"}
    back = load_capture(out)
    np.testing.assert_array_equal(back.dn, simulated.dn)
    np.testing.assert_array_equal(back.iso, simulated.iso)
    np.testing.assert_array_equal(back.mask.codes, simulated.mask.codes)
    assert back.iso_pattern == {"kind": "row", "isos": list(ISOS)}
    _same_observations(back, simulated)
    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["kind"] == "capture" and info["shots"] == 2 and info["cfa_pattern"] == "GRBG"
    assert info["exposures_s"] == [0.004, 0.008] and info["isos"] == list(ISOS)
    assert info["parameters"]["source"] == "raw" and len(info["parameters"]["frames"]) == 2
    assert info["saturated_fraction"] == pytest.approx(observations(simulated).saturated_fraction)
    # the existing output is kept without --force, replaced with it
    assert main(argv) == 2
    assert "output exists" in capsys.readouterr().err
    assert main(argv + ["--force"]) == 0


@pytest.mark.slow  # import and reconstruction
def test_dng_capture_imports_then_reconstructs(simulated, files, tmp_path, capsys):
    """DNG -> ``lfproc capture import`` -> ``lfproc reconstruct`` (both methods). Reference: the
    reconstruction of the simulated capture the DNGs were written from; the imported capture has
    no radiance scale, so its light field is in e-/s, the simulated one's times its radiance scale."""
    from lfproc.io import read_lightfield

    cap = tmp_path / "real.capture.npz"
    assert main(["capture", "import", *map(str, files["raws"]), "--mask", str(files["codes"]), "--mask-period", "4",
                 "--iso-layout", "row", "--isos", "100,400,800,1600", "--profile", str(files["profile"]),
                 "--exposures-s", "0.004,0.008", "-o", str(cap)]) == 0
    capsys.readouterr()
    real, sim = tmp_path / "real.exr", tmp_path / "sim.exr"
    assert main(["reconstruct", str(cap), "-o", str(tmp_path / "dict.exr"), "--method", "dictionary", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["dictionary"] == "default" and summary["solver"] == "admm" and summary["patches"] > 0
    assert main(["reconstruct", str(cap), "-o", str(real), "--json"]) == 0  # the default: gmm (periodic mask)
    summary = json.loads(capsys.readouterr().out)
    assert summary["method"] == "gmm" and summary["patches"] > 0
    assert main(["reconstruct", str(files["capture"]), "-o", str(sim)]) == 0
    a, b = read_lightfield(real), read_lightfield(sim)
    assert a.units == "e-/s" and a.shape == b.shape == (5, 5, H, W, 3)
    scale = simulated.radiance_scale
    np.testing.assert_allclose(a.data, b.data.astype(np.float64) * scale, rtol=1e-5, atol=1e-6 * scale * b.data.max())
    # (no quality check here: the scene is per-pixel white noise with half the rows saturated;
    # test_reconstruct.py and benchmarks/reconstruct_quality.py measure quality)


def test_cli_reuses_a_capture_files_mask_and_a_random_layout_by_seed(files, tmp_path, capsys, dng_writer):
    """The mask of an existing capture file (here a shifted one), the random ISO layout redrawn from its
    seed (the simulator draws it from the first of its streams, lfproc.camera.capture.capture_streams), one
    exposure for both shots."""
    sim = simulate_capture(_lf(), profile=_profile(), iso_pattern_kind="random", isos=ISOS, shots=2,
                           mask="shifted", mask_period=4, random_state=5)
    donor = sim.save(tmp_path / "donor.capture.npz")
    raws = [dng_writer(tmp_path / f"r{s}.dng", sim.dn[s], cfa_pattern="GRBG") for s in range(2)]
    out = tmp_path / "r.capture.npz"
    assert main(["capture", "import", *map(str, raws), "--mask", str(donor), "--iso-layout", "random",
                 "--isos", "100,400,800,1600", "--seed", "5", "--profile", str(files["profile"]),
                 "--exposures-s", "0.004", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "shots" in text and "GRBG" in text
    back = load_capture(out)
    np.testing.assert_array_equal(back.iso, sim.iso)
    assert (back.mask.kind, back.mask.period, back.mask.shift) == ("shifted", 4, 1)
    np.testing.assert_array_equal(back.mask.codes, sim.mask.codes)
    assert back.parameters["mask_source"] == str(donor)
    # the layout is recorded as the simulator records it, with the seed that redraws it
    assert back.iso_pattern == {**sim.iso_pattern, "seed": 5} == {"kind": "random", "isos": list(ISOS), "seed": 5}
    _same_observations(back, sim)


def test_a_raw_black_level_unlike_the_profiles_warns(simulated, files, tmp_path, dng_writer):
    raw = dng_writer(tmp_path / "b.dng", simulated.dn[0], cfa_pattern="GRBG", black_level=256)
    with pytest.warns(LfprocWarning, match=r"b.dng: black level 256 DN, but camera profile 'dng-sensor' has 64 DN"):
        capture_from_raw([raw], mask=replace(simulated.mask, codes=simulated.mask.codes[:1]), iso_layout=100,
                         profile=files["profile"], exposures_s=0.004)


# -- bad input: one line, exit code 2, no output --------------------------------------------------

@pytest.fixture
def bad_inputs(files, tmp_path, dng_writer):
    d = tmp_path
    wrong_size = dng_writer(d / "small.dng", np.full((H, W - 8), 100, np.uint16), cfa_pattern="GRBG")
    np.save(d / "flat_codes.npy", np.full((2, 4, 4), 0.5, np.float32))
    (d / "text.dng").write_text("not a raw file")
    with open(d / "huge_codes.npy", "wb") as fh:  # a header announcing 8 TB over 64 bytes of data
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": (10**6, 10**6)})
        fh.write(bytes(64))
    iso = np.full((40, 48), 400.0)
    iso[3, 5] = np.nan
    np.save(d / "nan_iso.npy", iso)
    iso[3, 5] = 123.0
    np.save(d / "odd_iso.npy", iso)
    return {"wrong_size": wrong_size, "bad_codes": d / "flat_codes.npy", "text": d / "text.dng",
            "huge_codes": d / "huge_codes.npy", "nan_iso": d / "nan_iso.npy", "odd_iso": d / "odd_iso.npy"}


def _argv(files, out, **change):
    opts = {"raws": [str(p) for p in files["raws"]], "--mask": str(files["codes"]), "--mask-period": "4",
            "--iso-layout": "row", "--isos": "100,400,800,1600", "--profile": str(files["profile"]),
            "--exposures-s": "0.004,0.008"}
    opts.update(change)
    argv = ["capture", "import", *opts.pop("raws")]
    for k, v in opts.items():
        if v is not None:
            argv += [k, v]
    return argv + ["-o", str(out)]


@pytest.mark.parametrize("case, change, message", [
    ("missing raw", lambda f, b: {"raws": [str(f["raws"][0]), str(f["dir"] / "nope.dng")]},
     r"nope.dng: no such sensor image"),
    ("raw of another size", lambda f, b: {"raws": [str(f["raws"][0]), str(b["wrong_size"])]},
     r"small.dng: sensor image of 40x40 pixels, but .*shot0.dng has 40x48"),
    ("not a raw file", lambda f, b: {"raws": [str(f["raws"][0]), str(b["text"])]},
     r"text.dng: not a raw file rawpy can read"),
    ("mask codes of the wrong shape", lambda f, b: {"--mask": str(b["bad_codes"])},
     r"flat_codes.npy: mask codes \(random\): expected 6 dimensions, got shape \(2, 4, 4\)"),
    ("mask codes announcing 8 TB", lambda f, b: {"--mask": str(b["huge_codes"])},
     r"huge_codes.npy: mask codes of shape \(1000000, 1000000\) \(float64\) needs 8000000000000 bytes, above the limit"),
    ("mask codes for another sensor", lambda f, b: {"--mask-period": None},
     r"codes.npy: random mask: codes cover \(4, 4\) pixels, the sensor is \(40, 48\)"),
    ("missing mask file", lambda f, b: {"--mask": str(f["dir"] / "none.npy")}, r"none.npy: no such mask code file"),
    ("unknown ISO layout", lambda f, b: {"--iso-layout": "zigzag"},
     r"--iso-layout: expected one of random, row, block, dual or an ISO map file; got 'zigzag'"),
    ("named layout without ISOs", lambda f, b: {"--isos": None}, r"--iso-layout row: --isos is required"),
    ("random layout without seed", lambda f, b: {"--iso-layout": "random"}, r"--iso-layout random: --seed is required"),
    ("ISO not in the profile", lambda f, b: {"--isos": "100,123"}, r"ISO 123 is not in camera profile 'dng-sensor'"),
    ("ISO map file with NaN", lambda f, b: {"--iso-layout": str(b["nan_iso"]), "--isos": None}, r"nan_iso.npy: ISO map with 1 NaN or Inf values; expected an ISO number per pixel"),
    ("ISO map file with an unknown ISO", lambda f, b: {"--iso-layout": str(b["odd_iso"]), "--isos": None},
     r"ISO 123 is not in camera profile 'dng-sensor'"),
    ("exposures count", lambda f, b: {"--exposures-s": "0.004,0.008,0.01"},
     r"--exposures-s: expected 1 or 2 exposure times \(one per RAW\), got 3"),
    ("bad exposure", lambda f, b: {"--exposures-s": "0.004,-1"}, r"exposures_s: expected positive finite seconds"),
    ("missing profile", lambda f, b: {"--profile": str(f["dir"] / "none.json")}, r"none.json: no such camera profile"),
])
def test_bad_input_one_line_exit_2_no_output(files, bad_inputs, tmp_path, capsys, case, change, message):
    out = tmp_path / "out.capture.npz"
    assert main(_argv(files, out, **change(files, bad_inputs))) == 2, case
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("lfproc capture: error: "), err
    assert __import__("re").search(message, err), err
    assert not out.exists() and not list(tmp_path.glob(".lfproc-tmp*"))


def test_output_exists_without_force(files, tmp_path, capsys):
    out = tmp_path / "exists.capture.npz"
    out.write_bytes(b"keep me")
    assert main(_argv(files, out)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "exists.capture.npz: output exists; pass --force" in err
    assert out.read_bytes() == b"keep me"


def test_calibrate_then_import_uses_the_measured_maps(files, tmp_path, capsys, dng_writer):
    """The whole real-camera chain on the command line: calibration frames of the sensor -> lfproc
    calibrate (flat field, bias frames) -> DNG shots -> lfproc capture import with the measured profile,
    whose observations are corrected with the measured maps."""
    from lfproc.sensor import calibrated_observation

    frames = tmp_path / "frames"
    assert main(["calibrate", "simulate-frames", "--profile", str(files["profile"]), "-o", str(frames), "--size",
                 str(H), str(W), "--iso", "100", "--iso", "400", "--seed", "2"]) == 0
    measured = tmp_path / "measured.json"
    assert main(["calibrate", str(frames / "manifest.csv"), "-o", str(measured), "--cfa", "GRBG"]) == 0
    assert (tmp_path / "measured.flat.npz").is_file() and (tmp_path / "measured.bias.npz").is_file()
    sim = simulate_capture(_lf(), profile=_profile(), iso_pattern_kind="row", isos=(100, 400), shots=2,
                           mask_period=4, random_state=3)
    raws = [dng_writer(tmp_path / f"m{s}.dng", sim.dn[s], cfa_pattern="GRBG") for s in range(2)]
    np.save(tmp_path / "codes.npy", sim.mask.codes)
    out = tmp_path / "m.capture.npz"
    capsys.readouterr()
    assert main(["capture", "import", *map(str, raws), "--mask", str(tmp_path / "codes.npy"), "--mask-period", "4",
                 "--iso-layout", "row", "--isos", "100,400", "--profile", str(measured), "--exposures-s",
                 str(sim.exposures_s[0]), "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["fixed_pattern"] == {"prnu": "flat_field", "dsnu": "bias_frames (ISO 100, 400)"}
    back = load_capture(out)
    prof = load_profile(measured)
    np.testing.assert_array_equal(back.profile.flat_field, prof.flat_field)
    obs = observations(back)
    for s in range(2):
        want = calibrated_observation(sim.dn[s], exposure_s=sim.exposures_s[s], iso=sim.iso[s], profile=prof)
        np.testing.assert_array_equal(obs.radiance[s], want.radiance)
        np.testing.assert_array_equal(obs.variance[s], want.variance)
        plain = calibrated_observation(sim.dn[s], exposure_s=sim.exposures_s[s], iso=sim.iso[s], profile=prof,
                                       correct_fixed_pattern=False)
        assert not np.array_equal(plain.radiance, want.radiance)
    # against the truth: the per-pixel scatter of T / (Phi L) shrinks by the removed PRNU (1.5 %)
    truth = sim.operator(dtype=np.float64).forward(_lf().astype(np.float64)) * sim.radiance_scale
    plain = observations(back, correct_fixed_pattern=False)
    ok = (obs.weight > 0) & (truth * np.array(sim.exposures_s)[:, None, None] > 500)
    spread, spread_plain = np.var(obs.radiance[ok] / truth[ok]), np.var(plain.radiance[ok] / truth[ok])
    assert spread < spread_plain - 0.5 * 0.015**2
