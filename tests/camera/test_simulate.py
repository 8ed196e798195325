"""The capture simulator: ISO patterns, baselines, noise statistics, CLI and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lfproc.sensor import load_profile
from lfproc.camera.capture import load_capture, observations
from lfproc.cli.main import main
from lfproc.errors import FileFormatError, InputError, ProfileError
from lfproc.io import write_image, write_lightfield
from lfproc.lightfield import LightField
from lfproc.camera.simulate import (
    BRACKETING_EXPOSURES,
    ISO_PATTERNS,
    auto_radiance_scale,
    iso_pattern,
    simulate_capture,
)

ISOS = (100, 400, 800, 1600)


def _lf(h=32, w=32, seed=0):
    rng = np.random.default_rng(seed)
    base = 0.01 + rng.random((1, 1, h, w, 3)).astype(np.float32) ** 4
    return np.broadcast_to(base, (5, 5, h, w, 3)).copy()


# -- ISO patterns -----------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["row", "block", "dual"])
def test_structured_patterns_keep_bayer_quads_on_one_iso(kind):
    m = iso_pattern(kind, size=(16, 24), isos=ISOS)
    quads = m.reshape(8, 2, 12, 2)
    assert (quads == quads[:, :1, :, :1]).all()


def test_iso_pattern_layouts(tmp_path):
    row = iso_pattern("row", size=(10, 4), isos=ISOS)
    np.testing.assert_array_equal(row[:, 0], [100, 100, 400, 400, 800, 800, 1600, 1600, 100, 100])
    assert (row == row[:, :1]).all()
    dual = iso_pattern("dual", size=(8, 3), isos=ISOS)
    np.testing.assert_array_equal(dual[:, 0], [100, 100, 1600, 1600] * 2)
    block = iso_pattern("block", size=(8, 8), isos=ISOS, block_px=2)
    np.testing.assert_array_equal(block[::2, ::2], [[100, 400, 100, 400], [800, 1600, 800, 1600]] * 2)
    # default blocks of 8 pixels (DEFAULT_BLOCK_PX): an 8 x 8 patch on the block grid sees one ISO
    wide = iso_pattern("block", size=(16, 16), isos=ISOS)
    np.testing.assert_array_equal(wide[::8, ::8], [[100, 400], [800, 1600]])
    assert (wide[:8, :8] == 100).all() and len(np.unique(wide[4:12, 4:12])) == 4
    rnd = iso_pattern("random", size=(200, 200), isos=ISOS, random_state=0)
    values, counts = np.unique(rnd, return_counts=True)
    np.testing.assert_array_equal(values, ISOS)
    assert np.allclose(counts / rnd.size, 0.25, atol=0.01)
    np.testing.assert_array_equal(rnd, iso_pattern("random", size=(200, 200), isos=ISOS, random_state=0))
    np.save(tmp_path / "iso.npy", block)
    np.testing.assert_array_equal(iso_pattern(tmp_path / "iso.npy", size=(8, 8)), block)
    with pytest.raises(InputError, match="iso pattern: expected one of random, row, block, dual or a file"):
        iso_pattern("zigzag", size=(8, 8))
    with pytest.raises(InputError, match="block size: expected an even number"):
        iso_pattern("block", size=(8, 8), block_px=3)
    with pytest.raises(Exception, match=r"ISO map of shape \(8, 8\); expected the sensor size \(4, 4\)"):
        iso_pattern(tmp_path / "iso.npy", size=(4, 4))
    np.save(tmp_path / "zero.npy", np.where(block == 800, 0, block))
    with pytest.raises(FileFormatError, match=r"zero.npy: ISO map with values <= 0 \(smallest 0\); expected positive"):
        iso_pattern(tmp_path / "zero.npy", size=(8, 8))


# -- simulation, baselines, scale -----------------------------------------------------------------

@pytest.mark.parametrize("kind", ISO_PATTERNS)
def test_simulated_capture_uses_the_pattern_in_every_shot(kind):
    cap = simulate_capture(_lf(), iso_pattern_kind=kind, shots=2, random_state=1)
    assert cap.dn.shape == (2, 32, 32) and cap.dn.dtype == np.uint16
    np.testing.assert_array_equal(cap.iso[0], cap.iso[1])
    assert not np.array_equal(cap.mask.codes[0], cap.mask.codes[1])  # each shot its own code
    assert cap.iso_pattern["kind"] == kind
    assert set(cap.isos) == ({100.0, 1600.0} if kind == "dual" else set(map(float, ISOS)))


def test_seed_reproduces_and_none_records_a_seed():
    a = simulate_capture(_lf(), shots=2, random_state=5)
    b = simulate_capture(_lf(), shots=2, random_state=5)
    np.testing.assert_array_equal(a.dn, b.dn)
    c = simulate_capture(_lf(), shots=2)
    d = simulate_capture(_lf(), shots=2, random_state=c.parameters["seed"])
    np.testing.assert_array_equal(c.dn, d.dn)


def test_baselines():
    ind = simulate_capture(_lf(), baseline="individual-iso", isos=ISOS, random_state=0)
    assert ind.shots == 4
    for s, iso in enumerate(ISOS):
        assert (ind.iso[s] == iso).all()
    for n, rel in BRACKETING_EXPOSURES.items():
        br = simulate_capture(_lf(), baseline="bracketing", shots=n, exposure_s=0.004, random_state=0)
        assert br.exposures_s == pytest.approx([0.004 * r for r in rel]) and br.isos == [100.0]
    assert BRACKETING_EXPOSURES == {2: (0.5, 8.0), 3: (0.5, 2.0, 8.0), 4: (0.5, 2.0, 4.0, 8.0)}
    with pytest.raises(InputError, match="bracketing baseline takes 2, 3 or 4 shots, got 5"):
        simulate_capture(_lf(), baseline="bracketing", shots=5)
    with pytest.raises(InputError, match="baseline: expected one of individual-iso, bracketing"):
        simulate_capture(_lf(), baseline="hdr-cnn")


def test_auto_radiance_scale_saturates_the_lowest_iso():
    lf = _lf()
    profile = load_profile("paper-medium")
    scale = auto_radiance_scale(lf, profile=profile, iso=100, exposure_s=0.004)
    # ISO 100: the ADC saturates first, at (4095 - 64) / h electrons
    e_sat = (4095 - 64) / profile.isos[100].gain_dn_per_e
    assert scale * 0.004 * 0.5 * lf.sum(axis=(0, 1)).max() == pytest.approx(e_sat)
    cap = simulate_capture(lf, profile=profile, random_state=0)
    assert cap.radiance_scale == pytest.approx(scale)
    # noiseless, ISO 100 only: pixels whose mask transmits more than the mean 0.5 saturate, few others
    cap = simulate_capture(lf, profile=profile, iso_pattern_kind="row", isos=[100], noise=False, random_state=0)
    expected_e = cap.operator(dtype=np.float64).forward(lf.astype(np.float64)) * scale * 0.004
    obs = observations(cap)
    np.testing.assert_array_equal(obs.saturated, expected_e >= e_sat - 0.5 / profile.isos[100].gain_dn_per_e)
    with pytest.raises(InputError, match="all samples are zero"):
        auto_radiance_scale(np.zeros((5, 5, 4, 4, 3)), profile=profile, iso=100, exposure_s=0.004)


@pytest.mark.filterwarnings("ignore::lfproc.errors.SaturationWarning")  # the long exposures saturate on purpose
def test_exposure_time_acts_as_in_a_camera(tmp_path, capsys):
    """The automatic scale belongs to the scene (reference exposure 4 ms), not to the shot: on main it was
    recomputed from --exposure-s, so 0.1 ms and 1 s saturated the same share of pixels."""
    import json

    from lfproc.cli.main import main
    from lfproc.io import write_lightfield
    from lfproc.lightfield import LightField

    lf = _lf()
    profile = load_profile("paper-low")
    caps = {t: simulate_capture(lf, profile=profile, iso_pattern_kind="row", isos=[100], exposure_s=t, noise=False,
                                random_state=0) for t in (0.001, 0.004, 0.016)}
    scales = {cap.radiance_scale for cap in caps.values()}
    assert len(scales) == 1  # one scene, one scale
    assert all(cap.parameters["reference_exposure_s"] == 0.004 for cap in caps.values())
    sat = {t: float(observations(cap).saturated.mean()) for t, cap in caps.items()}
    assert sat[0.001] < sat[0.004] < sat[0.016]
    assert sat[0.016] > 4 * sat[0.004] and sat[0.001] < 0.5 * sat[0.004]
    # proportionally more signal: codes above black scale with time where nothing clips
    black = profile.black_level_dn
    a = caps[0.001].dn.astype(np.float64) - black
    b = caps[0.004].dn.astype(np.float64) - black
    ok = (caps[0.004].dn < profile.saturation_dn(100) - 1) & (a > 20)
    assert ok.sum() > 100
    assert np.median(b[ok] / a[ok]) == pytest.approx(4.0, rel=0.02)
    # the command line: --exposure-s changes the saturated share
    path = tmp_path / "lf.exr"
    write_lightfield(LightField(data=lf), path)
    fractions = []
    for t in ("0.0001", "1"):
        out = tmp_path / f"c{t}.capture.npz"
        assert main(["simulate", str(path), "-o", str(out), "--exposure-s", t, "--seed", "1", "--json"]) == 0
        fractions.append(json.loads(capsys.readouterr().out)["saturated_fraction"])
    assert fractions[0] < 0.01 and fractions[1] > 0.9


# -- statistics ---------------------------------------------------------------------------------

def _light(kind: str) -> np.ndarray:
    h = w = 96
    if kind == "constant":
        return np.ones((5, 5, h, w, 3), np.float32)
    ramp = 0.02 + np.linspace(0, 1, w, dtype=np.float32)
    return np.broadcast_to(ramp[None, None, None, :, None], (5, 5, h, w, 3)).copy()


@pytest.mark.parametrize("gamma", [1.0, 2.2])
@pytest.mark.parametrize("kind", ["constant", "ramp"])
@pytest.mark.parametrize("level", ["none", "low", "medium", "high"])
def test_radiance_estimate_is_unbiased_with_the_predicted_variance(level, kind, gamma):
    """Every pixel is a sample: 4 shots of 96 x 96 give about 9000 samples per ISO.

    The ramp drives ISO 1600 into saturation; statistics use pixels whose expected code is
    at least 6 standard deviations inside the sensor's range (clipped distributions are
    neither unbiased nor of the model's variance: that is what weight 0 is for).
    """
    profile = load_profile(f"paper-{level}")
    lf = _light(kind)
    t = 0.004
    # electrons at the mean mask (12.5 of 25 views): 300 (constant) or up to 1530 (ramp)
    scale = (300 if kind == "constant" else 1500) / (t * 12.5)
    cap = simulate_capture(lf, profile=profile, iso_pattern_kind="random", shots=4, exposure_s=t, gamma=gamma,
                           radiance_scale=scale, random_state=7)
    truth = cap.operator(dtype=np.float64).forward(lf.astype(np.float64)) * scale
    pred = observations(cap, variance_from="estimate", radiance_estimate=truth)
    plug_in = observations(cap)
    z = (pred.radiance - truth) / np.sqrt(pred.variance)
    assert (pred.weight[pred.saturated] == 0).all() and (plug_in.weight[plug_in.saturated] == 0).all()
    for iso in ISOS:
        h = profile.isos[iso].gain_dn_per_e
        mean_dn = h * t * truth
        sd_dn = h * t * np.sqrt(pred.variance)
        inside = (cap.iso == iso) & (mean_dn - 6 * sd_dn > 0) & (mean_dn + 6 * sd_dn < profile.saturation_dn(iso) - 64)
        n = int(inside.sum())
        assert n > 4000, (iso, n)
        zi = z[inside]
        assert abs(zi.mean()) < 4.5 / np.sqrt(n), (iso, zi.mean())  # unbiased
        assert zi.var() == pytest.approx(1.0, rel=0.10), iso  # variance as predicted
        # the plug-in variance (from T itself) predicts the same on average
        assert plug_in.variance[inside].mean() == pytest.approx(pred.variance[inside].mean(), rel=0.10)
        assert not plug_in.saturated[inside].any()
    if kind == "ramp":
        sat = cap.iso == 1600
        assert pred.saturated[sat].mean() > 0.1  # the ramp saturates ISO 1600 ...
        assert (pred.weight[sat & pred.saturated] == 0).all()  # ... at weight zero
        assert not pred.saturated[cap.iso == 100].any()


# -- bad input --------------------------------------------------------------------------------------

def test_bad_input_is_refused_by_the_library(tmp_path):
    with pytest.raises(ProfileError, match="ISO 123 is not in camera profile 'paper-low'; it has ISO 100, 200"):
        simulate_capture(_lf(), isos=[100, 123])
    with pytest.raises(InputError, match="exposure_s: expected a positive finite number, got -1"):
        simulate_capture(_lf(), exposure_s=-1)
    bad = _lf()
    bad[0, 0, 1, 1, 0] = np.nan
    with pytest.raises(InputError, match="light field: contains 1 NaN"):
        simulate_capture(bad)
    bad[0, 0, 1, 1, 0] = -1
    with pytest.raises(InputError, match="light field: contains 1 negative values"):
        simulate_capture(bad)
    with pytest.raises(InputError, match="shots: expected an integer >= 1, got 0"):
        simulate_capture(_lf(), shots=0)
    with pytest.raises(InputError, match="a Bayer sensor needs 3 colour channels"):
        simulate_capture(_lf()[..., :1])
    doc = load_profile("paper-low").to_json()
    doc["isos"]["400"]["read_noise_e"] = None
    doc["isos"]["400"]["read_noise_dn"] = None
    (tmp_path / "p.json").write_text(json.dumps(doc))
    with pytest.raises(ProfileError, match="ISO 400 has no read_noise_e"):
        simulate_capture(_lf(), profile=tmp_path / "p.json")


# -- command line ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def lf_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("lf") / "lf.exr"
    write_lightfield(LightField(_lf(24, 20)), path)
    return path


def test_cli_simulate_prints_the_sampling_rate(tmp_path, capsys, lf_file):
    out = tmp_path / "one.capture.npz"
    assert main(["simulate", str(lf_file), "-o", str(out), "--seed", "3", "--iso-pattern", "row"]) == 0
    text = capsys.readouterr().out
    assert "1.33 %" in text and "saturated_fraction" in text and "black_clipped_fraction" in text
    assert main(["simulate", str(lf_file), "-o", str(tmp_path / "two.capture.npz"), "--shots", "2", "--noise",
                 "high", "--mask", "shifted", "--mask-period", "4", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["sampling_rate"] == "2.67 %" and summary["sampling_rate_percent"] == pytest.approx(200 / 75)
    assert summary["shots"] == 2 and summary["profile"] == "paper-high" and summary["size"] == [24, 20]
    cap = load_capture(tmp_path / "two.capture.npz")
    assert cap.ground_truth["path"] == str(lf_file.resolve()) and len(cap.ground_truth["sha256"]) == 64
    assert cap.mask.period == 4 and cap.parameters["seed"] == summary["seed"]
    assert main(["simulate", str(lf_file), "-o", str(tmp_path / "br.capture.npz"), "--baseline", "bracketing",
                 "--shots", "3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["exposures_s"] == pytest.approx([0.002, 0.008, 0.032])
    assert main(["simulate", str(lf_file), "-o", str(tmp_path / "k.capture.npz"), "--radiance-scale", "1000",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["radiance_scale"] == 1000


def test_same_seed_gives_byte_identical_capture_files(tmp_path, capsys, lf_file, monkeypatch):
    import time
    import zipfile

    from lfproc._shared.hashing import file_sha256

    args = ["simulate", str(lf_file), "--seed", "7", "--shots", "2", "--iso-pattern", "random"]
    assert main([*args, "-o", str(tmp_path / "a.capture.npz")]) == 0
    real = time.time
    monkeypatch.setattr(time, "time", lambda: real() + 86400 + 3)  # a later day: ZIP stamps would differ
    assert main([*args, "-o", str(tmp_path / "b.capture.npz")]) == 0
    assert main([*args[:3], "8", *args[4:], "-o", str(tmp_path / "c.capture.npz")]) == 0
    capsys.readouterr()
    sha = {name: file_sha256(tmp_path / f"{name}.capture.npz") for name in "abc"}
    assert sha["a"] == sha["b"] and sha["a"] != sha["c"]
    with zipfile.ZipFile(tmp_path / "b.capture.npz") as zf:
        assert {info.date_time for info in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}


def _nan_image(tmp_path, value):
    image = np.ones((8, 8, 3), np.float32)
    image[2, 3, 1] = value
    return write_image(tmp_path / f"bad{value}.exr", image)


@pytest.mark.parametrize("args, message", [
    (["--isos", "100,123"], "ISO 123 is not in camera profile"),
    (["--exposure-s", "0"], "exposure_s: expected a positive finite number"),
    (["--shots", "0"], "--shots: expected an integer from 1 to 256, got 0"),
    (["--shots", "1000000"], "--shots: expected an integer from 1 to 256, got 1000000"),
    (["--iso-pattern", "zigzag"], "iso pattern: expected one of random, row, block, dual or a file"),
    (["--isos", "100,x"], "--isos: expected comma-separated numbers"),
    (["--profile", "nowhere.json"], "no such camera profile file"),
])
def test_cli_errors_are_one_line(tmp_path, capsys, lf_file, args, message):
    assert main(["simulate", str(lf_file), "-o", str(tmp_path / "x.capture.npz"), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lfproc simulate: error: ") and message in err and "\n" not in err
    assert not (tmp_path / "x.capture.npz").exists()


def test_cli_refuses_bad_light_fields_and_existing_outputs(tmp_path, capsys, lf_file):
    for value, message in ((np.nan, "NaN"), (-2.0, "negative")):
        path = _nan_image(tmp_path, value)
        assert main(["simulate", str(path), "-o", str(tmp_path / "x.capture.npz")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("lfproc simulate: error: ") and message in err and "\n" not in err
    doc = load_profile("paper-low").to_json()
    doc["isos"]["100"]["gain_dn_per_e"] = None
    (tmp_path / "nogain.json").write_text(json.dumps(doc))
    assert main(["simulate", str(lf_file), "-o", str(tmp_path / "x.capture.npz"), "--profile",
                 str(tmp_path / "nogain.json")]) == 2
    assert "ISO 100 has no gain_dn_per_e" in capsys.readouterr().err
    out = tmp_path / "y.capture.npz"
    assert main(["simulate", str(lf_file), "-o", str(out)]) == 0
    capsys.readouterr()
    assert main(["simulate", str(lf_file), "-o", str(out)]) == 2
    assert "output exists" in capsys.readouterr().err
    assert main(["simulate", str(lf_file), "-o", str(out), "--force"]) == 0


# -- issue 20 item 3: --negative and --nonfinite on the command line --------------------------------------------

def test_cli_simulate_negative_clip_real_hdr_photograph(shared_data, tmp_path, capsys):
    """ScanLines_Desk.exr holds 10,794 tiny negatives (lossy compression): refused by default with advice
    naming the option, simulated with --negative clip (the advice named an option no command had)."""
    path = shared_data / "hdr" / "ScanLines_Desk.exr"
    if not path.exists():
        pytest.skip(f"{path} not found")
    out = tmp_path / "desk.capture.npz"
    assert main(["simulate", str(path), "-o", str(out), "--seed", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "10794 negative values" in err and "--negative clip" in err, err
    assert not out.exists()
    assert main(["simulate", str(path), "-o", str(out), "--seed", "1", "--negative", "clip", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["size"] == [874, 644] and out.exists()


def test_cli_simulate_nonfinite_policies(tmp_path, capsys):
    img = np.full((16, 16, 3), 0.5, np.float32)
    img[2, 3, 1] = np.nan
    img[4, 5, 0] = -0.25
    src = tmp_path / "bad.exr"
    write_image(src, img)
    out = tmp_path / "c.capture.npz"
    assert main(["simulate", str(src), "-o", str(out), "--negative", "clip"]) == 2
    assert "1 NaN" in capsys.readouterr().err
    assert main(["simulate", str(src), "-o", str(out), "--nonfinite", "zero"]) == 2
    assert "1 negative values" in capsys.readouterr().err
    assert not out.exists()
    assert main(["simulate", str(src), "-o", str(out), "--nonfinite", "zero", "--negative", "clip", "--json"]) == 0
    capsys.readouterr()
    assert out.exists()


@pytest.mark.parametrize("command", [["simulate"], ["convert"], ["evaluate"], ["preview"], ["info"], ["merge"],
                                     ["virtual-illum"], ["dictionary", "train"], ["dictionary", "eval"]])
def test_every_command_reading_light_fields_has_the_value_policies(command, capsys):
    assert main([*command, "--help"]) == 0
    text = capsys.readouterr().out
    assert "--negative {clip,raise}" in text and "--nonfinite {raise,zero,clip}" in text, command
# -- views against the dictionary (issue 20, item 7) --------------------------------------------

def test_simulate_warns_when_the_views_do_not_fit_the_shipped_dictionary():
    from lfproc.errors import ViewCountWarning

    lf3 = _lf(16, 16)[1:4, 1:4]
    with pytest.warns(ViewCountWarning) as record:
        capture = simulate_capture(lf3, profile="paper-low", random_state=0, dictionary="default")
    message = str(record[0].message)
    assert "3 x 3 views" in message and "shipped dictionary 'default' has 5 x 5 views" in message
    assert "--" not in message  # Python names the function, not the command's options
    assert capture.views == (3, 3)  # still made
    simulate_capture(_lf(16, 16), profile="paper-low", random_state=0, dictionary="default")  # 5 x 5: no warning
    simulate_capture(lf3, profile="paper-low", random_state=0)  # Python's default: no check


def test_cli_simulate_of_3x3_views_warns_in_one_line(tmp_path, capsys):
    path = tmp_path / "lf3.exr"
    write_lightfield(LightField(_lf(16, 16)[1:4, 1:4]), path)
    out = tmp_path / "c.capture.npz"
    assert main(["simulate", str(path), "-o", str(out), "--seed", "1"]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("lfproc simulate: warning: ")
    assert "3 x 3 views" in err and "'default' has 5 x 5 views" in err and "lfproc dictionary train" in err
    assert out.is_file()
    from lfproc.dictionary import dct_dictionary, save_dictionary

    mine = save_dictionary(dct_dictionary((3, 3, 4, 4, 3), 40), tmp_path / "d33.npz")
    assert main(["simulate", str(path), "-o", str(tmp_path / "c2.capture.npz"), "--seed", "1",
                 "--dictionary", str(mine)]) == 0
    assert capsys.readouterr().err == ""  # the dictionary it is meant for fits: no warning


# -- the default mask tile (issue 23: a default that reconstructs fast) -----------------------------------------

def test_random_masks_are_tiled_by_default_and_none_turns_it_off(tmp_path, capsys):
    from lfproc.camera.simulate import DEFAULT_MASK_PERIOD

    lf = _lf(16, 16)
    assert simulate_capture(lf, profile="paper-low", random_state=0).mask.period == DEFAULT_MASK_PERIOD == 4
    assert simulate_capture(lf, profile="paper-low", random_state=0, mask_period=None).mask.period is None
    assert simulate_capture(lf, profile="paper-low", random_state=0, mask="shifted").mask.period is None
    with pytest.raises(InputError, match="mask_period: expected a period in pixels, None or 'default'"):
        simulate_capture(lf, profile="paper-low", random_state=0, mask_period="four")
    path = tmp_path / "lf.exr"
    write_lightfield(LightField(lf), path)
    for option, period in ((None, 4), ("none", None), ("8", 8)):
        out = tmp_path / f"c{option}.capture.npz"
        extra = [] if option is None else ["--mask-period", option]
        assert main(["simulate", str(path), "-o", str(out), "--seed", "1", *extra]) == 0
        capsys.readouterr()
        assert load_capture(out).mask.period == period
    assert main(["simulate", str(path), "-o", str(tmp_path / "x.capture.npz"), "--mask-period", "four"]) == 2
    err = capsys.readouterr().err
    assert "--mask-period" in err and "'four'" in err


def test_one_seed_gives_the_same_mask_and_noise_whatever_the_iso_layout():
    """Paired designs (lfproc.camera.capture.capture_streams): at one seed the random and block layouts get the same
    mask codes and the same noise draws, so a pixel both layouts give the same ISO has the same code in both."""
    a = simulate_capture(_lf(), shots=2, iso_pattern_kind="random", isos=ISOS, random_state=7)
    b = simulate_capture(_lf(), shots=2, iso_pattern_kind="block", isos=ISOS, block_px=2, random_state=7)
    np.testing.assert_array_equal(a.mask.codes, b.mask.codes)
    same = a.iso == b.iso
    assert 0.1 < same.mean() < 0.5  # a quarter of the pixels, by chance
    np.testing.assert_array_equal(a.dn[same], b.dn[same])
    assert (a.dn[~same] != b.dn[~same]).mean() > 0.5  # another ISO: another code
    c = simulate_capture(_lf(), shots=2, iso_pattern_kind="random", isos=ISOS, random_state=8)
    assert not np.array_equal(a.mask.codes, c.mask.codes)


# -- binary mask transmittances (stop 30) ----------------------------------------------------------------------

def test_binary_masks_draw_zero_or_one_and_uniform_ones_are_unchanged(tmp_path, capsys):
    """make_mask(transmittance=...): the binary code is 0 or 1 with mean 1/2 (a statistic: 6000 codes, 5 standard
    errors) and variance 1/4; the uniform one is still rng.integers(0, 256) / 255 from the same seed (known answer:
    captures made before stop 30 are remade bit for bit); the capture records the choice and its file keeps the codes;
    a bad choice is one line, from the library and from the command line (exit code 2)."""
    from lfproc.camera import make_mask

    binary = make_mask(shots=2, views=(5, 5), size=(8, 8), period=4, random_state=3, transmittance="binary").codes
    assert set(np.unique(binary).tolist()) == {0.0, 1.0}
    assert abs(binary.mean() - 0.5) < 5 * 0.5 / np.sqrt(binary.size) and binary.size == 2400
    uniform = make_mask(shots=2, views=(5, 5), size=(8, 8), period=4, random_state=3).codes
    expected = np.random.default_rng(3).integers(0, 256, (2, 5, 5, 4, 4, 3), dtype=np.uint8) / np.float32(255)
    np.testing.assert_array_equal(uniform, expected.astype(np.float32))
    big = make_mask(shots=4, views=(5, 5), size=(8, 8), period=8, random_state=0, transmittance="binary").codes
    assert abs(big.var() - 0.25) < 0.01 and abs(make_mask(shots=4, views=(5, 5), size=(8, 8), period=8,
                                                           random_state=0).codes.var() - 1 / 12) < 0.01

    lf = _lf(16, 16)
    cap = simulate_capture(lf, profile="paper-low", random_state=0, mask_transmittance="binary")
    assert cap.parameters["mask_transmittance"] == "binary"
    back = load_capture(cap.save(tmp_path / "b.capture.npz"))
    np.testing.assert_array_equal(back.mask.codes, cap.mask.codes)
    with pytest.raises(InputError, match="mask_transmittance: expected one of"):
        simulate_capture(lf, profile="paper-low", random_state=0, mask_transmittance="grey")
    path = tmp_path / "lf.exr"
    write_lightfield(LightField(lf), path)
    out = tmp_path / "c.capture.npz"
    assert main(["simulate", str(path), "-o", str(out), "--seed", "1", "--mask-transmittance", "binary"]) == 0
    capsys.readouterr()
    assert load_capture(out).parameters["mask_transmittance"] == "binary"
    assert main(["simulate", str(path), "-o", str(tmp_path / "x.capture.npz"), "--mask-transmittance", "grey"]) == 2
    assert "argument --mask-transmittance: invalid choice: 'grey'" in capsys.readouterr().err
    assert not (tmp_path / "x.capture.npz").exists()


def test_a_binary_mask_tells_neighbouring_pixels_apart_better_at_disparity_one():
    """Why binary (module notes of lfproc.camera.projection.make_mask): at disparity 1 a pixel's coded sum mixes its
    5 x 5 neighbours; only the code's deviation from its mean tells them apart. A centre view of pixel-level
    checkerboard (the finest detail) sheared to disparity 1 gives coded sums whose spread, relative to the sums of a
    flat view of the same mean, is about sqrt(3) times larger with binary codes (std 1/2 against 1/sqrt(12)); measured
    over 4 shots of 32 x 32 pixels 1.66 times (mixed codes 1.60), bounds 1.5 .. 2.1 (a statistic that fails if the
    codes' variance is not used)."""
    from lfproc.camera import build_operator, make_mask

    yy, xx = np.mgrid[0:32, 0:32]
    checker = np.repeat(((yy + xx) % 2).astype(float)[..., None], 3, axis=2)
    views = np.empty((5, 5, 32, 32, 3))
    for v in range(5):
        for u in range(5):
            views[v, u] = np.roll(checker, (v - 2, u - 2), axis=(0, 1))  # disparity 1 (wrapped: no edge)
    flat = np.full_like(views, 0.5)
    spread = {}
    for t in ("uniform", "binary"):
        mask = make_mask(shots=4, views=(5, 5), size=(32, 32), period=None, random_state=7, transmittance=t)
        op = build_operator(mask, views=(5, 5), size=(32, 32), cfa_pattern="RGGB", dtype=np.float64)
        spread[t] = np.std(op.forward(views) - op.forward(flat)) / np.mean(op.forward(flat))
    assert 1.5 < spread["binary"] / spread["uniform"] < 2.1


def test_mixed_masks_draw_open_closed_and_small_codes_in_their_shares():
    """make_mask(transmittance="mixed"): codes 1, 0 and small levels (k / 255, k < 64) in the shares MIXED_SHARES
    (0.475 / 0.325 / 0.2; statistics over 48,000 codes, 5 standard errors each), mean 1/2 within 0.01 (the same light
    as the other distributions), variance 0.23 (uniform codes 1/12: the detail a coded sum resolves)."""
    from lfproc.camera import make_mask
    from lfproc.camera.projection import MIXED_SHARES

    codes = make_mask(shots=4, views=(5, 5), size=(40, 40), period=20, random_state=5, transmittance="mixed").codes
    n = codes.size
    assert n == 4 * 25 * 400 * 3
    small = (codes > 0) & (codes < 1)
    assert codes[small].max() <= 63 / 255 + 1e-6
    for share, got in zip(MIXED_SHARES, ((codes == 1).mean(), (codes == 0).mean(), small.mean())):
        assert abs(got - share) < 5 * np.sqrt(share * (1 - share) / n), (share, got)
    assert abs(codes.mean() - 0.5) < 0.01 and abs(codes.var() - 0.23) < 0.01


def test_the_default_mask_is_mixed_from_the_library_and_the_command_line(tmp_path, capsys):
    """Stop 49 made mixed codes the default (module notes "Mask transmittances"): a capture made without
    ``mask_transmittance`` records "mixed" and its codes are those of ``make_mask(transmittance="mixed")`` from the
    mask's stream of the same seed (known answer: the same codes, bit for bit), with 1, 0 and small levels among
    them; ``lfproc simulate`` without the option records the same, and ``--mask-transmittance uniform`` still gives the
    paper's codes."""
    from lfproc.camera.simulate import DEFAULT_MASK_TRANSMITTANCE

    assert DEFAULT_MASK_TRANSMITTANCE == "mixed"
    lf = _lf(16, 16)
    default = simulate_capture(lf, profile="paper-low", shots=2, random_state=4)
    mixed = simulate_capture(lf, profile="paper-low", shots=2, random_state=4, mask_transmittance="mixed")
    uniform = simulate_capture(lf, profile="paper-low", shots=2, random_state=4, mask_transmittance="uniform")
    assert default.parameters["mask_transmittance"] == "mixed"
    np.testing.assert_array_equal(default.mask.codes, mixed.mask.codes)
    np.testing.assert_array_equal(default.dn, mixed.dn)
    codes = default.mask.codes
    assert (codes == 1).any() and (codes == 0).any() and ((codes > 0) & (codes <= 63 / 255 + 1e-6)).any()
    assert not ((codes > 63 / 255 + 1e-6) & (codes < 1)).any()  # no mid levels: not uniform codes
    assert ((uniform.mask.codes > 0.3) & (uniform.mask.codes < 0.7)).any()

    path = tmp_path / "lf.exr"
    write_lightfield(LightField(lf), path)
    assert main(["simulate", str(path), "-o", str(tmp_path / "d.capture.npz"), "--seed", "1"]) == 0
    assert main(["simulate", str(path), "-o", str(tmp_path / "u.capture.npz"), "--seed", "1",
                 "--mask-transmittance", "uniform"]) == 0
    capsys.readouterr()
    assert load_capture(tmp_path / "d.capture.npz").parameters["mask_transmittance"] == "mixed"
    assert load_capture(tmp_path / "u.capture.npz").parameters["mask_transmittance"] == "uniform"
