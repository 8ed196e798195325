"""Capture files: round trip, schema errors, observations, real frames, info and preview."""

from __future__ import annotations

import json
import zipfile

import cv2
import numpy as np
import pytest

from lfproc.sensor import load_profile
from lfproc.camera.capture import (
    HEADER_NAME, Capture, capture_from_raw, describe_capture, is_capture_file, load_capture, observations,
)
from lfproc.preview import render_capture_preview
from lfproc.cli.main import main
from lfproc.errors import FileFormatError, InputError, OutputExistsError, ProfileError, ShapeError
from lfproc.camera.projection import MaskCode, make_mask
from lfproc.camera.simulate import simulate_capture


def _lf(h=32, w=32, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.random((1, 1, h, w, 3)).astype(np.float32) ** 4  # some dynamic range
    return np.broadcast_to(base, (5, 5, h, w, 3)).copy()


@pytest.fixture(scope="module")
def capture():
    return simulate_capture(_lf(), profile="paper-medium", iso_pattern_kind="row", shots=2, mask="shifted",
                            mask_period=4, random_state=11,
                            ground_truth={"path": "/x/lf.exr", "sha256": "0" * 64})


def test_round_trip_needs_no_seed(tmp_path, capture):
    path = capture.save(tmp_path / "a.capture.npz")
    assert is_capture_file(path) and not is_capture_file(tmp_path / "missing.npz")
    back = load_capture(path)
    np.testing.assert_array_equal(back.dn, capture.dn)
    assert back.dn.dtype == np.uint16
    np.testing.assert_array_equal(back.iso, capture.iso)
    np.testing.assert_array_equal(back.mask.codes, capture.mask.codes)
    assert back.mask.codes.shape == (2, 4, 4, 3)  # a periodic mask is stored as its tile
    assert (back.mask.kind, back.mask.period, back.mask.shift) == ("shifted", 4, 1)
    assert back.exposures_s == capture.exposures_s and back.gamma == capture.gamma
    assert back.cfa_pattern == "RGGB" and back.views == (5, 5)
    assert back.profile.to_json() == capture.profile.to_json()
    assert back.radiance_scale == capture.radiance_scale
    assert back.ground_truth == {"path": "/x/lf.exr", "sha256": "0" * 64}
    assert back.parameters["seed"] == 11
    lf = _lf()
    np.testing.assert_array_equal(back.operator().forward(lf), capture.operator().forward(lf))
    # self-describing: the header is plain JSON, first member of the archive; numpy can read the arrays
    with zipfile.ZipFile(path) as zf:
        assert zf.infolist()[0].filename == HEADER_NAME
        header = json.loads(zf.read(HEADER_NAME))
    assert header["schema"] == "lfproc.capture" and header["schema_version"] == 1
    assert header["lfproc_version"] and header["profile"]["name"] == "paper-medium"
    assert header["arrays"]["dn"] == {"shape": [2, 32, 32], "dtype": "uint16"}
    with np.load(path) as npz:
        np.testing.assert_array_equal(npz["dn"], capture.dn)
    assert header["arrays"]["mask"]["dtype"] == "uint8"  # levels k/255 are stored as 8-bit codes


def test_arbitrary_mask_codes_round_trip_as_float(tmp_path):
    codes = np.random.default_rng(0).random((1, 5, 5, 4, 4, 3)).astype(np.float32)
    cap = Capture(dn=np.full((1, 4, 4), 100, np.uint16), iso=100, exposures_s=0.01,
                  mask=MaskCode("random", codes), profile="paper-low")
    back = load_capture(cap.save(tmp_path / "f.capture.npz"))
    assert back.mask.codes.dtype == np.float32
    np.testing.assert_array_equal(back.mask.codes, codes)


def test_save_is_atomic_and_refuses_overwrite(tmp_path, capture):
    path = capture.save(tmp_path / "a.capture.npz")
    with pytest.raises(OutputExistsError, match="output exists"):
        capture.save(path)
    capture.save(path, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.capture.npz"]


def _rewrite(src, dst, *, header=None, drop=()):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            if info.filename in drop:
                continue
            data = zin.read(info.filename)
            if info.filename == HEADER_NAME and header is not None:
                data = json.dumps(header(json.loads(data))).encode()
            zout.writestr(info.filename, data)
    return dst


def test_load_errors_are_clear(tmp_path, capture):
    good = capture.save(tmp_path / "good.capture.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(FileFormatError, match="not an lfproc capture"):
        load_capture(tmp_path / "text.npz")
    bad = _rewrite(good, tmp_path / "v9.npz", header=lambda h: h | {"schema_version": 9})
    with pytest.raises(FileFormatError, match="'schema_version': expected 1, found 9"):
        load_capture(bad)
    bad = _rewrite(good, tmp_path / "nomask.npz", drop=("mask.npy",))
    with pytest.raises(FileFormatError, match="has no 'mask' array"):
        load_capture(bad)
    bad = _rewrite(good, tmp_path / "noexp.npz", header=lambda h: {k: v for k, v in h.items() if k != "exposures_s"})
    with pytest.raises(FileFormatError, match="missing field 'exposures_s'"):
        load_capture(bad)
    bad = _rewrite(good, tmp_path / "shape.npz",
                   header=lambda h: h | {"arrays": h["arrays"] | {"dn": {"shape": [1, 32, 32], "dtype": "uint16"}}})
    with pytest.raises(FileFormatError, match=r"field 'arrays.dn': expected shape \[2, 32, 32\] \(shots, height, "
                                              r"width\), found \[1, 32, 32\]"):
        load_capture(bad)
    bad = _rewrite(good, tmp_path / "prof.npz", header=lambda h: h | {"profile": h["profile"] | {"full_well_e": None}})
    with pytest.raises(ProfileError, match="missing field 'full_well_e'"):
        load_capture(bad)


def test_observations_and_weights(capture):
    obs = observations(capture)
    assert obs.radiance.shape == obs.weight.shape == obs.saturated.shape == (2, 32, 32)
    assert (obs.weight[obs.saturated] == 0).all() and (obs.weight[~obs.saturated & ~obs.black_clipped] > 0).all()
    # a hand-made capture with a saturated and a black-clipped pixel
    profile = load_profile("paper-low")
    dn = np.full((1, 4, 4), 500, np.uint16)
    dn[0, 0, 0] = 4095
    dn[0, 1, 1] = 0
    mask = make_mask("random", shots=1, views=(5, 5), size=(4, 4), random_state=0)
    cap = Capture(dn=dn, iso=400, exposures_s=0.01, mask=mask, profile=profile)
    obs = observations(cap)
    assert obs.saturated[0, 0, 0] and obs.black_clipped[0, 1, 1]
    assert obs.weight[0, 0, 0] == 0 and obs.weight[0, 1, 1] == 0
    h = profile.isos[400].gain_dn_per_e
    bias = 64 + h * 0.01 * profile.isos[400].dark_current_e_per_s
    assert obs.radiance[0, 2, 2] == pytest.approx((500 - bias) / (h * 0.01), rel=1e-6)
    assert obs.weight[0, 2, 2] == pytest.approx(1 / np.sqrt(obs.variance[0, 2, 2]), rel=1e-6)


def test_capture_validation():
    mask = make_mask("random", shots=1, views=(5, 5), size=(4, 4), random_state=0)
    dn = np.zeros((1, 4, 4), np.uint16)
    with pytest.raises(ProfileError, match="ISO 123 is not in camera profile"):
        Capture(dn=dn, iso=123, exposures_s=0.01, mask=mask, profile="paper-low")
    with pytest.raises(InputError, match="exposures_s: expected positive"):
        Capture(dn=dn, iso=100, exposures_s=0, mask=mask, profile="paper-low")
    with pytest.raises(ShapeError, match="codes for 1 shots, the capture has 2"):
        Capture(dn=np.zeros((2, 4, 4), np.uint16), iso=100, exposures_s=0.01, mask=mask, profile="paper-low")
    with pytest.raises(ShapeError, match="random mask: codes are for"):
        Capture(dn=dn, iso=100, exposures_s=0.01, mask=mask, profile="paper-low", views=(3, 3))


def test_capture_from_16bit_png_frames(tmp_path):
    rng = np.random.default_rng(0)
    frames = [rng.integers(64, 4000, size=(12, 16), dtype=np.uint16) for _ in range(2)]
    paths = []
    for i, frame in enumerate(frames):
        paths.append(tmp_path / f"shot{i}.png")
        assert cv2.imwrite(str(paths[-1]), frame)
    codes = make_mask("random", shots=2, views=(5, 5), size=(12, 16), period=4, random_state=3).codes
    np.save(tmp_path / "codes.npy", codes)
    cap = capture_from_raw(paths, mask={"kind": "random", "codes": tmp_path / "codes.npy", "period": 4},
                           iso_layout="row", isos=[100, 800], profile="paper-low", exposures_s=[0.004, 0.008])
    np.testing.assert_array_equal(cap.dn, np.stack(frames))
    np.testing.assert_array_equal(cap.iso[0, :, 0], [100, 100, 800, 800] * 3)
    assert cap.exposures_s == (0.004, 0.008) and cap.cfa_pattern == "RGGB"
    assert cap.parameters["frames"][0]["path"] == str(paths[0]) and len(cap.parameters["frames"][0]["sha256"]) == 64
    back = load_capture(cap.save(tmp_path / "real.capture.npz"))
    np.testing.assert_array_equal(back.dn, cap.dn)
    np.testing.assert_array_equal(back.mask.codes, codes)
    # an ISO map given as an array, one exposure for all shots
    cap2 = capture_from_raw(paths, mask=MaskCode("random", codes, period=4), iso_layout=np.full((12, 16), 400),
                            profile="paper-low", exposures_s=0.01)
    assert cap2.isos == [400.0] and cap2.exposures_s == (0.01, 0.01)
    cv2.imwrite(str(tmp_path / "eight.png"), np.zeros((12, 16), np.uint8))
    with pytest.raises(FileFormatError, match="expected a single-channel 16-bit sensor image"):
        capture_from_raw([tmp_path / "eight.png"], mask=MaskCode("random", codes[:1], period=4), iso_layout=100,
                         profile="paper-low", exposures_s=0.01)
    with pytest.raises(ShapeError, match="codes for 2 shots, the capture has 1"):
        capture_from_raw(paths[:1], mask=MaskCode("random", codes, period=4), iso_layout=100, profile="paper-low",
                         exposures_s=0.01)


def test_describe_and_info_json(tmp_path, capsys, capture):
    path = capture.save(tmp_path / "a.capture.npz")
    info = describe_capture(path)
    obs = observations(capture)
    assert info["kind"] == "capture" and info["shots"] == 2 and info["size"] == [32, 32]
    assert info["sampling_rate_percent"] == pytest.approx(200 / 75)
    assert info["saturated_fraction"] == pytest.approx(obs.saturated.mean())
    assert info["black_clipped_fraction"] == pytest.approx(obs.black_clipped.mean())
    assert info["isos"] == [100, 400, 800, 1600]
    assert main(["info", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("kind", "shots", "size", "sampling_rate_percent", "saturated_fraction", "black_clipped_fraction",
                "isos"):
        assert out[key] == info[key]


def _colour_count(image, rgb):
    return int(np.sum(np.abs(image.astype(int) - np.round(np.asarray(rgb) * 255).astype(int)).sum(-1) <= 3))


@pytest.mark.slow  # every preview kind of a capture
def test_preview(tmp_path, capsys, capture):
    import matplotlib

    image = render_capture_preview(capture, "capture")
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    assert image.shape[1] > image.shape[0]  # three panels side by side
    # the ISO map panel paints each of the four ISOs of the row pattern in its own viridis colour
    # (0.05 .. 0.95 of the map, lowest ISO darkest), in equal shares (whole Bayer rows each)
    iso_only = render_capture_preview(capture, "iso")
    assert iso_only.shape[1] < image.shape[1]
    cmap = matplotlib.colormaps["viridis"]
    counts = [_colour_count(iso_only, cmap(x)[:3]) for x in np.linspace(0.05, 0.95, 4)]
    assert min(counts) > 1000 and max(counts) < 1.5 * min(counts)
    assert _colour_count(render_capture_preview(capture, "sensor"), cmap(0.05)[:3]) == 0
    with pytest.raises(InputError, match="preview kind: expected one of capture, sensor, iso, mask"):
        render_capture_preview(capture, "epi")
    with pytest.raises(InputError, match="shot: expected 0..1, got 2"):
        render_capture_preview(capture, "sensor", shot=2)
    path = capture.save(tmp_path / "a.capture.npz")
    assert main(["preview", str(path), "-o", str(tmp_path / "p.png"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["kind"] == "capture" and out["isos"] == [100, 400, 800, 1600]
    written = cv2.cvtColor(cv2.imread(str(tmp_path / "p.png")), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(written, image)  # the file is the rendered picture
    assert list(written.shape[:2]) == out["size"]
    assert main(["preview", str(path), "-o", str(tmp_path / "m.png"), "--kind", "mask"]) == 0
    mask = cv2.cvtColor(cv2.imread(str(tmp_path / "m.png")), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(mask, render_capture_preview(load_capture(path), "mask"))
    capsys.readouterr()
    # a light-field kind on a capture: one line, exit 2, nothing written
    assert main(["preview", str(path), "-o", str(tmp_path / "s.png"), "--kind", "sheet"]) == 2
    assert "capture previews" in capsys.readouterr().err and not (tmp_path / "s.png").exists()


def test_describe_counts_a_hand_made_capture(tmp_path):
    dn = np.full((1, 4, 4), 500, np.uint16)
    dn[0, 0, 0] = 4095  # saturated (paper-low: 4095 at ISO 400)
    dn[0, 1, 1] = 0  # black-clipped
    dn[0, 2, 2] = 0
    mask = make_mask("random", shots=1, views=(5, 5), size=(4, 4), random_state=0)
    cap = Capture(dn=dn, iso=400, exposures_s=0.01, mask=mask, profile="paper-low")
    info = describe_capture(cap.save(tmp_path / "h.capture.npz"))
    assert info["saturated_fraction"] == 1 / 16 and info["black_clipped_fraction"] == 2 / 16
    assert info["per_iso"] == {"400": {"fraction": 1.0, "saturated_fraction": 1 / 16, "black_clipped_fraction": 2 / 16}}
    assert (info["dn_min"], info["dn_max"]) == (0, 4095) and info["sampling_rate_percent"] == pytest.approx(100 / 75)


# -- the photon-noise signal of the weights (variance_from="local") -------------------------------

def _flat_capture(level, *, noise=True, seed=5, size=64):
    lf = np.full((5, 5, size, size, 3), level, np.float32)
    return simulate_capture(lf, profile="paper-medium", iso_pattern_kind="random", shots=2, mask_period=4,
                            radiance_scale=1.0, noise=noise, random_state=seed)


def test_local_signal_leaves_the_measurement_out_and_knows_a_flat_scene():
    """Known answer: on a flat, noise-free scene every measurement is its total mask transmittance
    times the radiance, and so is its neighbours' estimate; the estimate of a pixel does not move
    when that pixel's own value does (leave-one-out), a same-colour neighbour's does."""
    from dataclasses import replace

    from lfproc.camera.capture import local_signal
    from lfproc.camera.projection import transmittance_map

    cap = _flat_capture(4000.0, noise=False)  # ~200 electrons: the codes' quantisation is ~1 %
    obs = observations(cap, warn_saturation=False)
    est = local_signal(cap, obs)
    r = transmittance_map(cap.mask, views=cap.views, cfa_pattern=cap.cfa_pattern, size=cap.size)
    inner = np.s_[:, 4:-4, 4:-4]
    np.testing.assert_allclose(obs.radiance[inner], (r * 4000.0)[inner], rtol=0.02)
    np.testing.assert_allclose(est[inner], (r * 4000.0)[inner], rtol=0.01)  # 8 neighbours average the quantisation
    bumped = obs.radiance.copy()
    bumped[0, 20, 20] *= 3
    est2 = local_signal(cap, replace(obs, radiance=bumped))
    # equal up to rounding (the filter's sums include the pixel, then subtract it); tripling it would move an
    # estimate that included it by about a quarter
    assert est2[0, 20, 20] == pytest.approx(est[0, 20, 20], rel=1e-12)
    assert est2[0, 22, 20] > est[0, 22, 20] * 1.1  # a same-colour neighbour's
    assert est2[0, 21, 20] == pytest.approx(est[0, 21, 20], rel=1e-12)  # another colour's


def test_local_variance_weights_are_unbiased_where_the_plug_in_is_low():
    """Statistics against the noise model: the inverse-variance weighted mean of the radiance of a flat
    scene at a few electrons per measurement is unbiased with the neighbours' signal in the variance
    (within 1 %; measured 0.996 of the truth), and low with the plug-in (each measurement's own value:
    Neyman's chi-square bias; measured 0.853)."""
    from lfproc.camera.projection import transmittance_map

    cap = _flat_capture(150.0)  # ~ 8 electrons per measurement
    r = transmittance_map(cap.mask, views=cap.views, cfa_pattern=cap.cfa_pattern, size=cap.size)
    means = {}
    for how in ("local", "measurement"):
        obs = observations(cap, warn_saturation=False, variance_from=how)
        w2 = obs.weight.astype(np.float64) ** 2 * r**2  # the weights of L = T / r
        means[how] = float((w2 * obs.radiance / r).sum() / w2.sum())
    electrons = float(np.median(observations(cap, warn_saturation=False).radiance)) * cap.exposures_s[0]
    assert 3 < electrons < 20, electrons
    assert abs(means["local"] / 150.0 - 1) < 0.01, means
    assert means["measurement"] / 150.0 < 0.95, means


def test_local_variance_refuses_an_estimate():
    with pytest.raises(InputError, match="variance_from='local' computes its own signal"):
        observations(_flat_capture(100.0), variance_from="local", radiance_estimate=np.ones((2, 64, 64)))
