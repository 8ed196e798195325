"""Camera profiles: shipped files = defaults.py, schema errors name the field, round trip with
the bias sidecar, ``lfproc profile show``."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from lfproc.sensor import SHIPPED_PROFILES, load_profile, save_profile
from lfproc.calib.defaults import build_all
from lfproc.cli.main import main
from lfproc.errors import FileFormatError, MissingFileError, OutputExistsError, ProfileError


def _strip(doc):
    doc = dict(doc)
    doc.pop("lfproc_version", None)
    return doc


@pytest.mark.parametrize("name", SHIPPED_PROFILES)
def test_shipped_profiles_equal_what_defaults_build(name):
    built = build_all()[name]
    assert _strip(load_profile(name).to_json()) == _strip(built.to_json())


def test_round_trip_with_bias_sidecar(tmp_path):
    base = load_profile("paper-medium")
    rng = np.random.default_rng(3)
    bias = {100: (64 + rng.normal(0, 1, (8, 6))).astype(np.float32), 400: np.full((8, 6), 65.5, np.float32)}
    prof = replace(base, bias_frames=bias, unknown={"isos.100.prnu": "no flats"}, prnu=0.01, dsnu_e=0.5)
    path = save_profile(prof, tmp_path / "cam.json")
    doc = json.loads(path.read_text())
    assert doc["bias_frame_file"] == "cam.bias.npz"
    assert (tmp_path / "cam.bias.npz").is_file()
    back = load_profile(path)
    assert _strip(back.to_json()) == _strip(prof.to_json())
    assert sorted(back.bias_frames) == [100, 400]
    np.testing.assert_array_equal(back.bias_frames[100], bias[100])
    assert back.saturation_dn(400) == prof.saturation_dn(400)
    with pytest.raises(OutputExistsError, match="cam"):
        save_profile(prof, path)
    save_profile(prof, path, force=True)


def _write(tmp_path, doc, name="bad.json"):
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return p


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda d: d.update(schema="other"), "field 'schema'"),
        (lambda d: d.update(schema_version=99), "field 'schema_version'"),
        (lambda d: d.pop("adc_bits"), "missing field 'adc_bits'"),
        (lambda d: d["isos"]["100"].update(gain_dn_per_e="fast"), "isos.100.gain_dn_per_e"),
        (lambda d: d["isos"]["400"].update(read_noise_e=-1.0), "isos.400.read_noise_e"),
        (lambda d: d["isos"]["100"].update(colour="red"), "isos.100.*colour"),
        (lambda d: d["isos"].update({"fast": d["isos"]["100"]}), "'fast' is not an ISO"),
        (lambda d: d.update(cfa_pattern="RGBW"), "cfa_pattern"),
        (lambda d: d.update(black_level_dn=5000.0), "black_level_dn"),
        (lambda d: d.update(bias_frame_file="missing.npz"), "bias_frame_file"),
        (lambda d: d.update(flat_field_file="missing.npz"), r"field 'flat_field_file': .*missing.npz does not exist"),
        (lambda d: d.update(flat_field_file="notflat.npz"), r"field 'flat_field_file': .*notflat.npz is not a flat-field"),
        (lambda d: d.update(flat_field_file="negflat.npz"), r"flat_field: expected an \(H, W\) map of positive finite gains"),
        (lambda d: d.update(flat_field_std=-0.1), "field 'flat_field_std': expected a number >= 0"),
        (lambda d: d.update(bias_frame_std_dn={"fast": 1.0}), "field 'bias_frame_std_dn': keys must be ISO numbers"),
        (lambda d: d.update(bias_frame_std_dn={"100": "big"}), "field 'bias_frame_std_dn.100': expected a number"),
    ],
)
def test_load_errors_name_the_field(tmp_path, edit, match):
    np.savez(tmp_path / "notflat.npz", other=np.ones((2, 2)))
    np.savez(tmp_path / "negflat.npz", flat_field=-np.ones((2, 2)))
    doc = load_profile("paper-high").to_json()
    edit(doc)
    with pytest.raises(ProfileError, match=match):
        load_profile(_write(tmp_path, doc))


def test_load_errors_files(tmp_path):
    with pytest.raises(MissingFileError, match="no such camera profile"):
        load_profile(tmp_path / "nope.json")
    bad = tmp_path / "x.json"
    bad.write_text("{not json")
    with pytest.raises(FileFormatError, match="not a JSON camera profile"):
        load_profile(bad)


def test_cli_profile_show(tmp_path, capsys):
    assert main(["profile", "show", "paper-high", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["name"] == "paper-high"
    assert doc["isos"]["100"]["gain_dn_per_e"] == pytest.approx(0.20475)
    assert doc["saturation_dn"]["100"] == 4095
    assert main(["profile", "show", "illum"]) == 0
    out = capsys.readouterr().out
    assert "GRBG" in out and "gain_dn_per_e" in out and "3200" in out


def test_cli_profile_show_errors(tmp_path, capsys):
    assert main(["profile", "show", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lfproc profile: error:") and "missing.json" in err[0]
    doc = load_profile("paper-low").to_json()
    doc["isos"]["200"]["gain_dn_per_e"] = None
    doc["isos"]["200"]["full_well_e"] = "big"
    assert main(["profile", "show", str(_write(tmp_path, doc))]) == 2
    assert "isos.200.full_well_e" in capsys.readouterr().err


def test_cli_info_describes_a_profile(tmp_path, capsys):
    """`lfproc info PROFILE.json` (info --help names profiles) prints what `profile show` prints."""
    from lfproc.sensor import save_profile

    path = save_profile(load_profile("paper-high"), tmp_path / "p.json")
    assert main(["info", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["kind"] == "camera_profile" and doc["name"] == "paper-high"
    assert doc["saturation_dn"]["100"] == 4095 and doc["isos"]["100"]["gain_dn_per_e"] == pytest.approx(0.20475)
    assert main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert "camera_profile" in text and "gain_dn_per_e" in text and "0.20475" in text
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"schema": "something.else"}))
    assert main(["info", str(other)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "other.json" in err[0] and "camera profiles" in err[0]


def test_flat_field_sidecar_is_confined_and_checked_like_the_bias_sidecar(tmp_path):
    from lfproc.errors import UnsafeFileError

    outside = tmp_path / "elsewhere"
    outside.mkdir()
    np.savez(outside / "flat.npz", flat_field=np.ones((2, 2), np.float32))
    folder = tmp_path / "profile"
    folder.mkdir()
    doc = load_profile("paper-high").to_json()
    doc["flat_field_file"] = "../elsewhere/flat.npz"
    with pytest.raises(UnsafeFileError, match="'flat_field_file'.*leads outside"):
        load_profile(_write(folder, doc))
    np.savez(folder / "cube.npz", flat_field=np.ones((2, 2, 2), np.float32))
    doc["flat_field_file"] = "cube.npz"
    with pytest.raises(ProfileError, match="cube.npz is not a flat-field map.*expected a 2-D float array"):
        load_profile(_write(folder, doc))
    np.savez(folder / "good.npz", flat_field=np.full((2, 3), 0.5, np.float32))
    doc["flat_field_file"] = "good.npz"
    assert load_profile(_write(folder, doc)).flat_field.tolist() == [[0.5] * 3] * 2
