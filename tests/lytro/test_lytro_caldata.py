"""Lytro calibration data: real white-image metadata, pairing tars, MOD folders, data.C.N archives."""

from __future__ import annotations

import io
import json
import shutil
import tarfile

import numpy as np
import pytest

from lfproc.errors import InputError, LfpFormatError, MissingFileError, OutputExistsError
from lfproc.lytro.caldata import (
    WhiteFrame, geometry_correction_bytes, iter_caldata, white_metadata, white_txt_document, write_caldata_tar,
)
from lfproc.lytro.container import build_lfp, illum_metadata, sha1_ref, write_lfr
from lfproc.lytro.raw import pack_raw10, pack_raw12, raw_byte_count
from lfproc.lytro import read_caldata, read_capture

SERIAL = "B5152102610"


def _frames(h=8, w=16):
    rng = np.random.default_rng(7)
    out = []
    for i, (zoom, focus, dark) in enumerate([(-560, -20, False), (0, 100, False), (0, 100, True)]):
        level = (600, 900) if not dark else (60, 70)
        out.append(WhiteFrame(raw=rng.integers(*level, (h, w)).astype(np.uint16),
                              metadata=white_metadata(height=h, width=w, zoom_step=zoom, focus_step=focus,
                                                      exposure_s=0.01 * (i + 1)),
                              name=f"MOD_{i + 10:04d}", is_dark=dark))
    return out


def _sparse(path, size):
    with open(path, "wb") as fh:
        fh.truncate(size)
    return path


# -- real white-image metadata -------------------------------------------------------------
@pytest.mark.parametrize("txt, serial, zoom, focus, exposure, derivation", [
    ("illum_white_MOD_0015.TXT", "B5152102610", -560, -20, 0.008131949424743653,
     "sha1-52b44308e8cb5e129f64c48176aecfd992a73489"),
    ("illum_white_MOD_epfl.TXT", "B5143909630", -1040, -300, 0.0072242450714111329,
     "sha1-52b44308e8cb5e129f64c48176aecfd992a73489"),
])
def test_real_white_txt_in_a_mod_folder(lytro_dir, tmp_path, txt, serial, zoom, focus, exposure, derivation):
    shutil.copy(lytro_dir / txt, tmp_path / "MOD_0015.TXT")
    _sparse(tmp_path / "MOD_0015.RAW", raw_byte_count(5368, 7728, 10))
    (w,) = read_caldata(tmp_path, load_raw=False)
    assert w.raw is None and w.name == "MOD_0015"
    assert (w.camera_model, w.serial, w.zoom_step, w.focus_step) == ("B01", serial, zoom, focus)
    assert w.exposure_s == pytest.approx(exposure)
    assert w.is_dark is False  # com.lytro.tags: darkFrame false, modulationFrame true
    assert w.geometry_hash == derivation  # no .GCT here: derivationArray[0], lower case
    assert w.black_level == {"r": 64.0, "gr": 64.0, "gb": 64.0, "b": 64.0} and w.white_level == 1023.0
    assert w.cfa_pattern == "GRBG"
    assert w.metadata["devices"]["mla"]["tiling"] == "hexUniformRowMajor"
    # the same pair read as a capture (.RAW + .TXT): levels from image.rawDetails, ISO from devices.sensor
    cap = read_capture(tmp_path / "MOD_0015.RAW")
    assert cap.raw.shape == (5368, 7728) and cap.raw.dtype == np.uint16 and not cap.raw.any()
    assert (cap.camera_model, cap.serial, cap.iso, cap.cfa_pattern) == ("B01", serial, 100.0, "GRBG")
    assert cap.ccm[0, 0] == pytest.approx(2.482781171798706)  # image.color.ccmRgbToSrgbArray
    assert cap.sha1_verified is None


def test_real_mod_0015_is_single_line_json_with_trailing_text(lytro_dir, tmp_path):
    text = (lytro_dir / "illum_white_MOD_0015.TXT").read_text()
    (tmp_path / "MOD_0001.TXT").write_text(text + "\n\x00junk")  # tolerated, as PlenoptiCam does
    _sparse(tmp_path / "MOD_0001.RAW", raw_byte_count(5368, 7728, 10))
    (w,) = read_caldata(tmp_path / "MOD_0001.TXT", load_raw=False)
    assert w.zoom_step == -560


def test_real_f01_frame_json_with_raw(lytro_dir, tmp_path):
    shutil.copy(lytro_dir / "f01_IMG_0001__frame.json", tmp_path / "IMG_0001__frame.json")
    raw = np.random.default_rng(4).integers(0, 4096, (3280, 3280), dtype=np.uint16)
    (tmp_path / "IMG_0001__frame.raw").write_bytes(pack_raw12(raw))
    (tmp_path / "IMG_0001__private_metadata.json").write_text(json.dumps({"camera": {"serialNumber": "A000424242"}}))
    cap = read_capture(tmp_path / "IMG_0001__frame.raw")
    np.testing.assert_array_equal(cap.raw, raw)
    assert (cap.camera_model, cap.cfa_pattern, cap.serial) == ("F01", "BGGR", "A000424242")
    assert cap.black_level["gr"] == 168 and cap.white_level == 4095
    assert (cap.iso, cap.zoom_step, cap.focus_step) == (200.0, 981, 582)
    assert cap.exposure_s == pytest.approx(0.01433531753718853)
    np.testing.assert_array_equal(cap.black_level_2x2(), np.full((2, 2), 168.0))


# -- pairing-data tar ----------------------------------------------------------------------
def test_caldata_tar_round_trip(tmp_path):
    frames = _frames()
    path = write_caldata_tar(tmp_path / f"caldata-{SERIAL}.tar", frames, serial=SERIAL)
    with tarfile.open(path) as tar:
        names = tar.getnames()
        manifest = json.loads(tar.extractfile("unitdata/cal_file_manifest.json").read())
        txt = json.loads(tar.extractfile("unitdata/MOD_0010.TXT").read())
        assert len(tar.extractfile("unitdata/MOD_0010.RAW").read()) == raw_byte_count(8, 16, 10)
    for f in frames:
        assert {f"unitdata/{f.name}.{ext}" for ext in ("RAW", "TXT", "GCT")} <= set(names)
    assert {"unitdata/unit_info.json", "unitdata/HOTPIXEL.BIN", "unitdata/mla_calibration.json"} <= set(names)
    # the real TXT layout: master.picture.frameArray[0].frame.{metadata, privateMetadata}
    frame = txt["master"]["picture"]["frameArray"][0]
    assert frame["frame"]["metadata"]["camera"]["model"] == "B01"
    assert frame["frame"]["metadata"]["image"]["rawDetails"]["pixelFormat"]["black"]["gr"] == 64
    assert frame["frame"]["privateMetadata"]["camera"]["serialNumber"] == SERIAL
    assert frame["parameters"]["vendorContent"]["com.lytro.tags"] == {"darkFrame": False, "modulationFrame": True}
    got = read_caldata(path)
    assert [w.name for w in got] == ["MOD_0010", "MOD_0011", "MOD_0012"]
    for w, f in zip(got, frames):
        np.testing.assert_array_equal(w.raw, f.raw)
        assert (w.serial, w.camera_model, w.is_dark) == (SERIAL, "B01", f.is_dark)
        assert (w.zoom_step, w.focus_step) == (f.metadata["devices"]["lens"]["zoomStep"],
                                               f.metadata["devices"]["lens"]["focusStep"])
        gct_hash = next(e["hash"] for e in manifest["calibrationFiles"] if e["name"] == f"{w.name}.GCT")
        assert w.geometry_hash == gct_hash == sha1_ref(geometry_correction_bytes(f.metadata, w.name))
        assert w.source.endswith(f"unitdata/{w.name}.RAW")
    assert got[1].exposure_s == pytest.approx(0.02)
    light = [w for w in got if not w.is_dark]
    assert len(light) == 2


def test_capture_points_at_its_white_image_by_geometry_hash(tmp_path):
    frames = _frames()
    tar = write_caldata_tar(tmp_path / f"caldata-{SERIAL}.tar", frames, serial=SERIAL)
    gct = geometry_correction_bytes(frames[1].metadata, frames[1].name)
    lfr = write_lfr(tmp_path / "IMG_0001.LFR", raw=frames[1].raw, metadata=illum_metadata(height=8, width=16),
                    serial=SERIAL, geometry_correction=gct)
    cap = read_capture(lfr)
    match = [w.name for w in read_caldata(tar, load_raw=False) if w.geometry_hash == cap.geometry_hash]
    assert match == ["MOD_0011"] and cap.serial == SERIAL


def test_tar_with_serial_prefix_and_unit_info_override(tmp_path):
    path = write_caldata_tar(tmp_path / "pairing.tar", _frames()[:1], serial="45142500380", prefix="45142500380")
    (w,) = read_caldata(path)
    assert w.serial == "45142500380" and w.source.endswith("45142500380/MOD_0010.RAW")
    # unit_info.json wins over the TXT serial (Light Field Toolbox v0.5.1 rule)
    with tarfile.open(path) as tar:
        members = {m.name: tar.extractfile(m).read() for m in tar.getmembers()}
    members["45142500380/unit_info.json"] = json.dumps({"camera": {"serialNumber": "B0000000001"}}).encode()
    other = tmp_path / "caldata-B0000000001.tar"
    with tarfile.open(other, "w") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    assert read_caldata(other)[0].serial == "B0000000001"


def test_write_caldata_tar_refuses_bad_input(tmp_path):
    path = write_caldata_tar(tmp_path / "c.tar", _frames()[:1], serial=SERIAL)
    with pytest.raises(OutputExistsError, match=r"c\.tar: output exists"):
        write_caldata_tar(path, _frames()[:1], serial=SERIAL)
    write_caldata_tar(path, _frames()[:2], serial=SERIAL, force=True)
    assert len(read_caldata(path, load_raw=False)) == 2
    with pytest.raises(InputError, match="serial must be letters and digits"):
        write_caldata_tar(tmp_path / "d.tar", _frames(), serial="B5/../x")
    with pytest.raises(InputError, match="two frames are named MOD_0010"):
        write_caldata_tar(tmp_path / "d.tar", [_frames()[0], _frames()[0]], serial=SERIAL)
    with pytest.raises(InputError, match="no frames"):
        write_caldata_tar(tmp_path / "d.tar", [], serial=SERIAL)
    assert not (tmp_path / "d.tar").exists()


# -- folders and Lytro Desktop archives ----------------------------------------------------
def test_folder_of_mod_files_and_folder_of_tars(tmp_path):
    frames = _frames()
    (tmp_path / "tars").mkdir()
    tar = write_caldata_tar(tmp_path / "tars" / f"caldata-{SERIAL}.tar", frames, serial=SERIAL)
    assert [w.name for w in read_caldata(tmp_path / "tars", load_raw=False)] == ["MOD_0010", "MOD_0011", "MOD_0012"]
    folder = tmp_path / "mods"
    with tarfile.open(tar) as t:
        t.extractall(folder, filter="data")
    got = read_caldata(folder)
    assert [w.name for w in got] == ["MOD_0010", "MOD_0011", "MOD_0012"]
    np.testing.assert_array_equal(got[2].raw, frames[2].raw)
    assert got[0].serial == SERIAL and got[2].is_dark


def _f01_white_txt(lytro_dir, h, w, *, tags=True):
    meta = json.loads((lytro_dir / "f01_IMG_0001__frame.json").read_text())
    meta["image"]["height"], meta["image"]["width"] = h, w
    frame = {"frame": {"metadata": meta, "privateMetadata": {"camera": {"serialNumber": "A000424242"}}}}
    doc = {"master": {"picture": {"frameArray": [frame], "derivationArray": ["sha1-" + "CD" * 20]}}}
    return (json.dumps(doc) + "\r\n").encode()


def test_lytro_desktop_data_c_archives(lytro_dir, tmp_path):
    """Two data.C.N storage archives (F01 white images without tags: dark frames found by level)."""
    h, w = 4, 6
    rng = np.random.default_rng(8)
    dark = rng.integers(165, 172, (h, w)).astype(np.uint16)
    white = rng.integers(3000, 4000, (h, w)).astype(np.uint16)
    txt = _f01_white_txt(lytro_dir, h, w)
    files0 = {r"C:\T1CALIB\MOD_0000.TXT": txt, r"C:\T1CALIB\MOD_0000.RAW": pack_raw12(dark),
              r"C:\T1CALIB\MLACALIBRATION.TXT": b"{}"}
    files1 = {r"C:\T1CALIB\MOD_0002.TXT": txt.replace(b'"zoomStep": 981', b'"zoomStep": 900'),
              r"C:\T1CALIB\MOD_0002.RAW": pack_raw12(white)}
    for i, files in enumerate((files0, files1)):
        payloads = list(files.values())
        toc = {"files": [{"name": n, "dataRef": sha1_ref(d)} for n, d in files.items()]}
        if i == 0:
            toc["nextFile"] = "data.C.1"
        (tmp_path / f"data.C.{i}").write_bytes(build_lfp(toc, payloads))
    got = read_caldata(tmp_path / "data.C.0")
    assert [x.name for x in got] == ["MOD_0000", "MOD_0002"]
    assert [x.is_dark for x in got] == [True, False]
    assert [x.zoom_step for x in got] == [981, 900]
    assert {x.camera_model for x in got} == {"F01"} and got[0].serial == "A000424242"
    assert got[0].geometry_hash == "sha1-" + "cd" * 20  # derivationArray[0], as PlenoptiCam matches F01
    np.testing.assert_array_equal(got[1].raw, white)
    assert got[0].source.endswith("T1CALIB__MOD_0000.RAW")
    assert [x.name for x in read_caldata(tmp_path)] == ["MOD_0000", "MOD_0002"]  # the folder holding them


# -- bad input -----------------------------------------------------------------------------
def test_missing_raw_wrong_size_unknown_model_and_empty(tmp_path, lytro_dir):
    shutil.copy(lytro_dir / "illum_white_MOD_0015.TXT", tmp_path / "MOD_0015.TXT")
    with pytest.raises(MissingFileError, match=r"MOD_0015\.TXT has no matching raw image MOD_0015\.RAW"):
        read_caldata(tmp_path)
    _sparse(tmp_path / "MOD_0015.RAW", 1000)
    with pytest.raises(LfpFormatError, match=r"MOD_0015\.RAW: wrong raw size: MOD_0015\.TXT says 7728 x 5368 at "
                                             r"10 bit = 51854880 bytes, the file has 1000"):
        read_caldata(tmp_path, load_raw=False)
    doc = json.loads((lytro_dir / "illum_white_MOD_0015.TXT").read_text())
    doc["master"]["picture"]["frameArray"][0]["frame"]["metadata"]["camera"]["model"] = "Z9"
    (tmp_path / "MOD_0015.TXT").write_text(json.dumps(doc))
    with pytest.raises(LfpFormatError, match=r"MOD_0015\.TXT: unknown camera model 'Z9'"):
        read_caldata(tmp_path, load_raw=False)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(MissingFileError, match=r"empty: no white images"):
        read_caldata(empty)
    with pytest.raises(MissingFileError, match="no such file or folder"):
        list(iter_caldata(tmp_path / "absent.tar"))
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"0123")
    with pytest.raises(LfpFormatError, match=r"junk\.bin: not Lytro calibration data"):
        read_caldata(junk)


def test_truncated_tar_member_is_a_wrong_size(tmp_path):
    frames = _frames()[:1]
    meta = frames[0].metadata
    folder = tmp_path / "f"
    folder.mkdir()
    (folder / "MOD_0003.TXT").write_text(json.dumps(white_txt_document(meta, serial=SERIAL)))
    (folder / "MOD_0003.RAW").write_bytes(pack_raw10(frames[0].raw)[:-5])
    with pytest.raises(LfpFormatError, match=r"MOD_0003\.RAW: wrong raw size"):
        read_caldata(folder)
