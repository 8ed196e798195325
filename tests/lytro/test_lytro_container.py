"""Lytro containers and captures: the real files, write_lfr round trips read by imageio, bad input, lfproc info."""

from __future__ import annotations

import copy
import hashlib
import json
import struct

import numpy as np
import pytest

from lfproc.cli.main import main
from lfproc.errors import ChecksumError, InputError, LfpFormatError, MissingFileError, OutputExistsError, ShapeError
from lfproc.lytro.container import LFP_MAGIC, build_lfp, illum_metadata, sha1_ref, write_lfr
from lfproc.lytro import describe_lytro, read_capture, read_lfp
from lfproc.lytro.raw import pack_raw10, pack_raw12

REAL = {
    # name: (sections, content sections, toc position, embedded images)
    "illum_desktop_demo.LFP": (12, 11, "first", 11),
    "IMG_0001-stk.lfp": (14, 13, "first", 13),
    "IMG_0002-stk.lfp": (4, 3, "first", 3),
    "IMG_0002-dm.lfp": (3, 2, "first", 2),
}


def _capture_meta(h=8, w=16, **kw):
    kw = {"zoom_step": -297, "focus_step": 309, "exposure_s": 0.01, "iso": 200, "modulation_exposure_bias_ev": 0.269,
          "white_balance": {"r": 1.378859, "g": 1.0, "b": 1.148466},
          "ccm": [[2.2, -1.0, -0.2], [-0.5, 1.7, -0.2], [-0.6, -1.3, 2.9]], **kw}
    return illum_metadata(height=h, width=w, **kw)


def _raw(h=8, w=16, seed=0):
    return np.random.default_rng(seed).integers(0, 1024, (h, w), dtype=np.uint16)


# -- the real files ------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(REAL))
def test_real_containers_parse_with_every_hash_verified(lytro_dir, name):
    n_sections, n_content, toc_pos, n_images = REAL[name]
    c = read_lfp(lytro_dir / name)
    assert c.header_kind == "LFP" and c.sha1_verified is True
    assert len(c.sections) == n_sections
    assert sum(s.kind == "LFC" for s in c.sections) == n_content
    assert c.sections[0].kind == "LFM" and isinstance(c.toc, dict)  # toc first in these files
    for sec in c.sections:  # independent check of every hash
        assert sec.sha1 == "sha1-" + hashlib.sha1(sec.data).hexdigest()
    assert len(c.images()) == n_images
    d = describe_lytro(lytro_dir / name)
    assert (d["sections"], d["sha1_verified"], d["toc_position"], d["embedded_images"]) == (
        n_sections, True, toc_pos, n_images)


def test_real_illum_desktop_metadata(lytro_dir):
    c = read_lfp(lytro_dir / "illum_desktop_demo.LFP")
    meta = c.json("metadataRef")  # inline in the table of contents of desktop LFPs
    assert meta["camera"]["model"] == "ILLUM"
    assert c.json("privateMetadataRef")["camera"]["serialNumber"] == "45142500380"
    jpegs = [im for im in c.images() if im["representation"] == "jpeg"]
    assert len(jpegs) == 10 and all(c.by_sha1(im["sha1"]).data[:3] == b"\xff\xd8\xff" for im in jpegs)
    d = describe_lytro(lytro_dir / "illum_desktop_demo.LFP")
    assert d["kind"] == "lytro" and d["camera_model"] == "B01" and d["serial"] == "45142500380"
    assert (d["zoom_step"], d["focus_step"], d["iso"]) == (123, 814, 122.0)
    assert d["exposure_s"] == pytest.approx(0.03998677805066109)
    assert d["exposure_bias_ev"] == pytest.approx(0.2447252869606018)
    assert d["cfa_pattern"] == "GRBG" and d["black_level"]["gr"] == 64 and d["white_level"] == 1023
    assert d["ccm"][0][0] == pytest.approx(2.2448263168334961)
    assert d["white_balance"] == pytest.approx({"r": 1.0875036716461182, "g": 1.0, "b": 1.6269161701202393})
    assert d["has_raw"] is False and (d["width"], d["height"]) == (7728, 5368)
    with pytest.raises(LfpFormatError, match=r"illum_desktop_demo\.LFP: no raw lenslet image to decode"):
        read_capture(lytro_dir / "illum_desktop_demo.LFP")


def test_real_f01_stack_refers_to_absent_frame_sections(lytro_dir):
    c = read_lfp(lytro_dir / "IMG_0001-stk.lfp")
    assert c.ref("metadataRef") == "sha1-ce3f98f73890cc12958b89acb23f7974bec90610"
    assert not c.has("metadataRef")
    with pytest.raises(LfpFormatError, match=r"IMG_0001-stk\.lfp: missing section: .*metadataRef"):
        c.section("metadataRef")
    with pytest.raises(LfpFormatError, match="has no 'nonsenseRef'"):
        c.section("nonsenseRef")
    assert c.ref("depthLut") is None  # depthLut is a dict holding an imageRef, reached by its path:
    lut = c.section("picture.accelerationArray[0].vendorContent.depthLut.imageRef")
    assert lut.size == 20 * 20 * 4  # 20x20 float32 lambda table
    d = describe_lytro(lytro_dir / "IMG_0001-stk.lfp")
    assert d["camera_model"] is None and d["serial"] is None and d["iso"] is None
    assert d["frame_metadata"] == "referenced but absent"


@pytest.mark.parametrize("name", ["illum_desktop_demo.LFP", "IMG_0002-dm.lfp"])
def test_cli_info_json_on_real_files(lytro_dir, name, capsys):
    assert main(["info", str(lytro_dir / name), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("kind", "camera_model", "serial", "zoom_step", "focus_step", "exposure_s", "iso", "sections",
                "sha1_verified"):
        assert key in out
    assert out["kind"] == "lytro" and out["sha1_verified"] is True
    assert out["sections"] == REAL[name][0]
    if name.startswith("illum"):
        assert out["serial"] == "45142500380" and out["iso"] == 122
    else:
        assert out["iso"] is None and out["camera_model"] is None


def test_cli_info_plain_text(lytro_dir, capsys):
    assert main(["info", str(lytro_dir / "illum_desktop_demo.LFP")]) == 0
    text = capsys.readouterr().out
    assert "45142500380" in text and "lytro" in text


# -- write_lfr round trips -----------------------------------------------------------------
def test_write_lfr_round_trip(tmp_path):
    raw = _raw()
    path = write_lfr(tmp_path / "a.LFR", raw=raw, metadata=_capture_meta(), serial="B5143909630")
    c = read_lfp(path)
    assert len(c.sections) == 12 and c.sections[-1].kind == "LFM"  # Illum order: 11 content sections, then TOC
    assert c.section("imageRef").data == pack_raw10(raw)
    assert c.section("thumbnails[0].imageRef").data[:3] == b"\xff\xd8\xff"
    cap = read_capture(path)
    np.testing.assert_array_equal(cap.raw, raw)
    assert cap.raw.dtype == np.uint16
    assert (cap.camera_model, cap.serial, cap.cfa_pattern) == ("B01", "B5143909630", "GRBG")
    assert cap.black_level == {"r": 64.0, "gr": 64.0, "gb": 64.0, "b": 64.0} and cap.white_level == 1023.0
    assert (cap.zoom_step, cap.focus_step, cap.iso) == (-297, 309, 200.0)
    assert cap.exposure_s == pytest.approx(0.01) and cap.exposure_bias_ev == pytest.approx(0.269)
    assert cap.white_balance == pytest.approx({"r": 1.378859, "g": 1.0, "b": 1.148466})
    np.testing.assert_allclose(cap.ccm, [[2.2, -1.0, -0.2], [-0.5, 1.7, -0.2], [-0.6, -1.3, 2.9]])
    assert cap.geometry_hash == c.ref("geometryCorrectionRef") == sha1_ref(c.section("geometryCorrectionRef").data)
    np.testing.assert_array_equal(cap.black_level_2x2(), np.full((2, 2), 64.0))
    assert cap.sha1_verified is True


def test_write_lfr_links_geometry_and_hot_pixels(tmp_path):
    gct = b'{"kind": "geometryCorrection", "name": "MOD_0007"}'
    path = write_lfr(tmp_path / "b.lfr", raw=_raw(), metadata=_capture_meta(), geometry_correction=gct,
                     hot_pixels=[[3, 1], [15, 7]])
    c = read_lfp(path)
    assert read_capture(path).geometry_hash == sha1_ref(gct)
    hot = c.section("hotPixelRef").data
    assert struct.unpack("<I", hot[:4]) == (2,)
    np.testing.assert_array_equal(np.frombuffer(hot[4:], "<u2"), [3, 15, 1, 7])  # N x's then N y's
    hist = np.frombuffer(c.section("exposureHistogramRef").data, "<u4")
    assert hist.size == 1024 and hist.sum() == 8 * 16


def test_imageio_reads_what_write_lfr_writes(tmp_path, monkeypatch):
    """Independent reader: imageio's lytro-lfr returns raw / 1023 as float64 plus the metadata."""
    iio = pytest.importorskip("imageio.v2")
    lytro = pytest.importorskip("imageio.plugins.lytro")
    raw = _raw(24, 32, seed=5)
    meta = _capture_meta(24, 32)
    path = write_lfr(tmp_path / "c.lfr", raw=raw, metadata=meta, serial="B5152102610")
    monkeypatch.setattr(lytro, "LYTRO_ILLUM_IMAGE_SIZE", raw.shape)  # its sensor size is hard-coded
    im = iio.imread(path, format="lytro-lfr")
    assert im.dtype == np.float64 and im.shape == raw.shape
    assert float(im.max()) <= 1.0
    np.testing.assert_array_equal(np.rint(im * 1023.0).astype(np.uint16), raw)
    np.testing.assert_allclose(im, raw / 1023.0, rtol=0, atol=1e-12)
    assert im.meta["privateMetadata"]["camera"]["serialNumber"] == "B5152102610"
    theirs = im.meta["metadata"]
    assert theirs["devices"]["lens"]["zoomStep"] == -297 and theirs["devices"]["lens"]["focusStep"] == 309
    assert theirs["image"]["pixelFormat"]["black"]["gr"] == 64 and theirs["image"]["mosaic"]["upperLeftPixel"] == "gr"
    assert theirs == read_capture(path).metadata
    thumb = im.meta["thumbnail"]
    assert thumb["image"].shape == (thumb["height"], thumb["width"], 3)


def test_imageio_reads_an_f01_lfp_built_here(tmp_path, monkeypatch, lytro_dir):
    """F01 raw .lfp (table of contents first, 12-bit big-endian): lfproc and imageio agree."""
    iio = pytest.importorskip("imageio.v2")
    lytro = pytest.importorskip("imageio.plugins.lytro")
    path, raw, meta = _f01_lfp(tmp_path, lytro_dir)
    cap = read_capture(path)
    np.testing.assert_array_equal(cap.raw, raw)
    assert (cap.camera_model, cap.cfa_pattern, cap.serial) == ("F01", "BGGR", "A303134643")
    assert cap.black_level["b"] == 168 and cap.white_level == 4095
    assert (cap.iso, cap.zoom_step, cap.focus_step) == (200.0, 981, 582)
    assert cap.exposure_s == pytest.approx(0.01433531753718853)
    assert cap.exposure_bias_ev == pytest.approx(-1.1242823600769043)
    assert cap.white_balance == pytest.approx({"r": 1.0, "g": 1.1171875, "b": 1.72265625})
    assert cap.ccm[0, 0] == pytest.approx(3.1115827560424805)  # ccmRgbToSrgbArray
    assert cap.geometry_hash == "sha1-" + "ab" * 20
    monkeypatch.setattr(lytro, "LYTRO_F01_IMAGE_SIZE", raw.shape)
    im = iio.imread(path, format="lytro-lfp")
    np.testing.assert_array_equal(np.rint(im * 4095.0).astype(np.uint16), raw)
    assert im.meta["metadata"]["camera"]["model"] == "F01"


def _f01_lfp(tmp_path, lytro_dir, *, model="F01", packed=None, h=6, w=8):
    meta = json.loads((lytro_dir / "f01_IMG_0001__frame.json").read_text())
    meta["image"]["height"], meta["image"]["width"] = h, w
    meta["camera"]["model"] = model
    raw = np.random.default_rng(2).integers(0, 4096, (6, 8), dtype=np.uint16)
    packed = pack_raw12(raw) if packed is None else packed
    private = {"camera": {"serialNumber": "A303134643"}}
    mb, pb = json.dumps(meta).encode(), json.dumps(private).encode()
    toc = {"picture": {"frameArray": [{"frame": {"metadataRef": sha1_ref(mb), "privateMetadataRef": sha1_ref(pb),
                                                 "imageRef": sha1_ref(packed)}}],
                       "derivationArray": ["sha1-" + "AB" * 20]},
           "version": {"major": 1, "minor": 0}}
    path = tmp_path / "IMG_0001.lfp"
    path.write_bytes(build_lfp(toc, [packed, mb, pb], toc_first=True))
    return path, raw, meta


@pytest.mark.slow
def test_imageio_reads_full_size_lfr(tmp_path):
    """A full 7728 x 5368 Illum raw, without patching imageio (about 4 s, 1.2 GB)."""
    iio = pytest.importorskip("imageio.v2")
    raw = _raw(5368, 7728, seed=9)
    path = write_lfr(tmp_path / "full.LFR", raw=raw, metadata=illum_metadata(zoom_step=5, focus_step=6))
    assert path.stat().st_size > 51_854_880
    im = iio.imread(path, format="lytro-lfr")
    np.testing.assert_array_equal(np.rint(im * 1023.0).astype(np.uint16), raw)
    del im
    np.testing.assert_array_equal(read_capture(path).raw, raw)


def test_write_lfr_refuses_overwrite_and_bad_input(tmp_path):
    path = write_lfr(tmp_path / "d.lfr", raw=_raw(), metadata=_capture_meta())
    with pytest.raises(OutputExistsError, match=r"d\.lfr: output exists"):
        write_lfr(path, raw=_raw(), metadata=_capture_meta())
    write_lfr(path, raw=_raw(seed=1), metadata=_capture_meta(), force=True)
    np.testing.assert_array_equal(read_capture(path).raw, _raw(seed=1))
    with pytest.raises(ShapeError, match=r"image\.width = 16 does not match raw of shape \(8, 12\)"):
        write_lfr(tmp_path / "e.lfr", raw=_raw(8, 12), metadata=_capture_meta())
    with pytest.raises(ShapeError, match="0..1023"):
        write_lfr(tmp_path / "e.lfr", raw=_raw() + 1023, metadata=_capture_meta())
    bad = _capture_meta()
    bad["camera"]["model"] = "F01"
    with pytest.raises(InputError, match="camera.model is 'F01'"):
        write_lfr(tmp_path / "e.lfr", raw=_raw(), metadata=bad)
    assert not (tmp_path / "e.lfr").exists() and not list(tmp_path.glob(".lfproc-tmp-*"))


# -- bad input -----------------------------------------------------------------------------
@pytest.fixture
def good_lfr(tmp_path):
    return write_lfr(tmp_path / "good.lfr", raw=_raw(), metadata=_capture_meta())


def test_truncated_file(good_lfr, tmp_path):
    data = good_lfr.read_bytes()
    for n, where in ((len(data) // 2, "needs"), (10, "16"), (16 + 40, "cut off")):
        bad = tmp_path / f"trunc{n}.lfr"
        bad.write_bytes(data[:n])
        with pytest.raises(LfpFormatError, match=rf"trunc{n}\.lfr: truncated file.*{where}"):
            read_capture(bad)


def test_wrong_magic(good_lfr, tmp_path):
    bad = tmp_path / "magic.lfr"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n" + good_lfr.read_bytes()[8:])
    with pytest.raises(LfpFormatError, match=r"magic\.lfr: wrong magic"):
        read_lfp(bad)
    data = bytearray(good_lfr.read_bytes())
    data[16:20] = b"JUNK"
    bad.write_bytes(bytes(data))
    with pytest.raises(LfpFormatError, match=r"magic\.lfr: bad section magic at byte 16"):
        read_lfp(bad)


def test_sha1_mismatch_is_an_error_unless_opted_out(good_lfr, tmp_path):
    c = read_lfp(good_lfr)
    sec = c.section("imageRef")
    data = bytearray(good_lfr.read_bytes())
    data[sec.offset + 3] ^= 0x04  # flip one bit of the raw image
    bad = tmp_path / "flip.lfr"
    bad.write_bytes(bytes(data))
    with pytest.raises(ChecksumError, match=r"flip\.lfr: SHA-1 mismatch in section 2 \(LFC, 160 bytes\)"):
        read_capture(bad)
    cap = read_capture(bad, verify=False)
    assert cap.sha1_verified is False
    assert np.count_nonzero(cap.raw != _raw()) == 1
    assert read_lfp(bad, verify=False).sha1_verified is False


def test_missing_raw_section(tmp_path):
    meta = json.dumps(_capture_meta()).encode()
    toc = {"frames": [{"frame": {"metadataRef": sha1_ref(meta), "imageRef": sha1_ref(b"gone")}}]}
    bad = tmp_path / "noraw.lfr"
    bad.write_bytes(build_lfp(toc, [meta], toc_first=False))
    with pytest.raises(LfpFormatError, match=r"noraw\.lfr: no raw lenslet image to decode; the file holds frame "
                                             r"metadata"):
        read_capture(bad)


def test_wrong_raw_size(tmp_path):
    meta = _capture_meta()
    meta["image"]["width"] = 20  # metadata disagrees with the 8 x 16 raw section
    mb, packed = json.dumps(meta).encode(), pack_raw10(_raw())
    toc = {"frames": [{"frame": {"metadataRef": sha1_ref(mb), "imageRef": sha1_ref(packed)}}]}
    bad = tmp_path / "size.lfr"
    bad.write_bytes(build_lfp(toc, [mb, packed], toc_first=False))
    with pytest.raises(LfpFormatError, match=r"size\.lfr: wrong raw size: metadata says 20 x 8 at 10 bit = 200 "
                                             r"bytes, the raw section has 160"):
        read_capture(bad)


def test_unknown_camera_model(tmp_path, lytro_dir):
    path, _, _ = _f01_lfp(tmp_path, lytro_dir, model="X42")
    with pytest.raises(LfpFormatError, match=r"IMG_0001\.lfp: unknown camera model 'X42'"):
        read_capture(path)


def test_missing_file_and_cli_error_line(tmp_path, good_lfr, capsys):
    with pytest.raises(MissingFileError, match=r"nope\.lfr: no such file"):
        read_capture(tmp_path / "nope.lfr")
    bad = tmp_path / "cut.lfr"
    bad.write_bytes(good_lfr.read_bytes()[:300])
    assert main(["info", str(bad), "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lfproc info: error: ") and "cut.lfr: truncated file" in err and "\n" not in err


def test_cli_info_on_written_lfr(good_lfr, capsys):
    assert main(["info", str(good_lfr), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["kind"] == "lytro" and out["camera_model"] == "B01" and out["sections"] == 12
    assert out["sha1_verified"] is True and out["has_raw"] is True and out["toc_position"] == "last"
    assert (out["zoom_step"], out["focus_step"], out["iso"], out["width"], out["height"]) == (-297, 309, 200, 16, 8)
    assert out["raw_max_dn"] == int(_raw().max()) and out["embedded_images"] == 2


def test_magic_detection_without_suffix(good_lfr, tmp_path, capsys):
    other = tmp_path / "capture.bin"
    other.write_bytes(good_lfr.read_bytes())
    assert other.read_bytes()[:12] == LFP_MAGIC
    assert main(["info", str(other), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["kind"] == "lytro"


def test_section_lookup_prefers_the_frame_and_accepts_paths(good_lfr):
    c = read_lfp(good_lfr)
    frame_sha = c.toc["frames"][0]["frame"]["imageRef"]
    assert c.section("imageRef").sha1 == frame_sha
    assert c.section("frames[0].frame.imageRef").sha1 == frame_sha
    assert c.section(frame_sha.upper().replace("SHA1-", "sha1-")).sha1 == frame_sha
    assert c.section("imageRef").name == "imageRef" and c.section("imageRef").toc_path == "frames[0].frame.imageRef"
    assert c.json("privateMetadataRef")["camera"]["serialNumber"] == "B5000000000"
    toc_copy = copy.deepcopy(c.toc)
    assert "lfproc" in " ".join(toc_copy["generators"])  # files record the writer and its version
