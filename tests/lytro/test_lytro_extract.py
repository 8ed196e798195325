"""Lytro files without a raw image: decode says what they hold; lfproc extract writes it (real files)."""

from __future__ import annotations

import hashlib
import json

import cv2
import numpy as np
import pytest

from lfproc.cli.main import main
from lfproc.io import read_image
from lfproc.lytro.container import read_lfp, write_lfr
from lfproc.lytro.extract import contents_summary, extract_lfp, lfp_contents


def _sha1(data: bytes) -> str:
    return "sha1-" + hashlib.sha1(data).hexdigest()


@pytest.mark.parametrize("name, holds", [
    ("IMG_0001-stk.lfp", "12 focus-stack JPEGs (1080 x 1080), a 20 x 20 depth lookup table"),
    ("IMG_0002-dm.lfp", "a 330 x 330 depth map, a 330 x 330 confidence map"),
    ("illum_desktop_demo.LFP", "10 focus-stack JPEGs (704 x 480), a 88 x 60 depth map, frame metadata"),
])
def test_decode_says_first_that_there_is_no_raw_image(lytro_dir, name, holds, tmp_path, capsys):
    # no --white-db: the missing raw image is what decode reports, not the missing database
    assert main(["decode", str(lytro_dir / name), "-o", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no raw lenslet image to decode" in err[0] and holds in err[0]
    assert f"lfproc extract {lytro_dir / name} -o DIR" in err[0]
    assert contents_summary(lfp_contents(read_lfp(lytro_dir / name))).startswith(holds)
    assert main(["info", str(lytro_dir / name), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["holds"].startswith(holds)


def test_extract_f01_focal_stack(lytro_dir, tmp_path, capsys):
    src = lytro_dir / "IMG_0001-stk.lfp"
    out = tmp_path / "stk"
    assert main(["extract", str(src), "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["raw_lenslet_image"] is False and summary["missing_sections"] == 3  # frame sections absent
    index = json.loads((out / "extracted.json").read_text())
    toc = json.loads((out / "table_of_contents.json").read_text())
    stack = toc["picture"]["accelerationArray"][0]["vendorContent"]["imageArray"]
    jpgs = [f for f in index["files"] if f["kind"] == "focus_stack"]
    assert len(jpgs) == len(stack) == 12
    for f, entry in zip(jpgs, stack):
        data = (out / f["file"]).read_bytes()
        assert _sha1(data) == entry["imageRef"]  # the embedded bytes, unchanged (independent hashlib)
        assert f["params"]["lambda"] == pytest.approx(entry["lambda"])
        img = cv2.imread(str(out / f["file"]))
        assert img.shape == (1080, 1080, 3)
    lut = read_image(out / "depth_lut.exr", negative="keep")[0][..., 0]
    raw = read_lfp(src).section("picture.accelerationArray[0].vendorContent.depthLut.imageRef").data
    np.testing.assert_array_equal(lut, np.frombuffer(raw, "<f4").reshape(20, 20))
    # lambda values: the table spans the refocus range of the stack
    lambdas = [e["lambda"] for e in stack]
    assert min(lambdas) - 1 < lut.min() < lut.max() < max(lambdas) + 1
    assert cv2.imread(str(out / "depth_lut.png")).ndim == 3  # colour-mapped preview with a colour bar


def test_extract_f01_depth_map_and_illum_desktop(lytro_dir, tmp_path):
    doc = extract_lfp(lytro_dir / "IMG_0002-dm.lfp", tmp_path / "dm")
    vendor = json.loads((tmp_path / "dm" / "table_of_contents.json").read_text())["picture"][
        "accelerationArray"][0]["vendorContent"]
    depth = read_image(tmp_path / "dm" / "depth_map.exr", negative="keep")[0][..., 0]
    conf = read_image(tmp_path / "dm" / "confidence_map.exr", negative="keep")[0][..., 0]
    assert depth.shape == conf.shape == (vendor["height"], vendor["width"])
    assert vendor["minLambda"] <= depth.min() < depth.max() <= vendor["maxLambda"]  # the file's own range
    assert 0 <= conf.min() and conf.max() <= 1
    assert not doc["raw_lenslet_image"]
    doc = extract_lfp(lytro_dir / "illum_desktop_demo.LFP", tmp_path / "illum")
    acc = json.loads((tmp_path / "illum" / "table_of_contents.json").read_text())["views"][0]["accelerations"][0]
    depth = read_image(tmp_path / "illum" / "depth_map.exr", negative="keep")[0][..., 0]
    assert depth.shape == (acc["depthMap"]["height"], acc["depthMap"]["width"]) == (60, 88)
    assert acc["depthMap"]["minLambda"] <= depth.min() < depth.max() <= acc["depthMap"]["maxLambda"]
    jpgs = [f for f in doc["files"] if f["kind"] == "focus_stack"]
    assert [f["params"]["focus"] for f in jpgs] == [e["focus"] for e in acc["perImage"]]
    assert all(f["shape"] == [480, 704] for f in jpgs)
    meta = json.loads((tmp_path / "illum" / "metadata.json").read_text())
    assert meta["image"]["width"] == 7728 and meta["image"]["iso"] == 122  # the inline frame metadata
    assert (tmp_path / "illum" / "private_metadata.json").is_file()


def test_extract_raw_capture_and_errors(tmp_path, capsys):
    from lfproc.lytro.container import illum_metadata

    raw = np.random.default_rng(0).integers(64, 1024, (8, 16), dtype=np.uint16)
    lfr = write_lfr(tmp_path / "a.LFR", raw=raw, metadata=illum_metadata(height=8, width=16), serial="B5143909630")
    doc = extract_lfp(lfr, tmp_path / "a")
    assert doc["raw_lenslet_image"] is True
    kinds = {f["kind"] for f in doc["files"]}
    assert {"raw_lenslet", "metadata", "table_of_contents"} <= kinds
    packed = (tmp_path / "a" / "raw_lenslet.bin").read_bytes()
    assert _sha1(packed) == read_lfp(lfr).frame()["imageRef"]
    # no overwrite without --force; one line; --force replaces
    assert main(["extract", str(lfr), "-o", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--force" in err[0]
    assert main(["extract", str(lfr), "-o", str(tmp_path / "a"), "--force"]) == 0
    capsys.readouterr()
    assert main(["extract", str(tmp_path / "none.lfp"), "-o", str(tmp_path / "b")]) == 2
    assert "none.lfp" in capsys.readouterr().err
    not_lfp = tmp_path / "x.lfp"
    not_lfp.write_bytes(b"hello")
    assert main(["extract", str(not_lfp), "-o", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "x.lfp" in err[0]
    assert not (tmp_path / "c").exists()


@pytest.mark.slow  # real F01 videos
def test_extract_writes_the_frames_of_f01_videos(lytro_dir, tmp_path):
    """Issue 20, item 8: the H.264 streams of an F01 focal stack are decoded into frames."""
    out = tmp_path / "stk"
    doc = extract_lfp(lytro_dir / "IMG_0002-stk.lfp", out)
    acc = json.loads((out / "table_of_contents.json").read_text())["picture"]["accelerationArray"]
    videos = [f for f in doc["files"] if f["kind"] == "video"]
    assert len(videos) == 2 and all((out / v["file"]).is_file() for v in videos)  # the streams, as stored
    frames = [f for f in doc["files"] if f["kind"] == "video_frame"]
    by_stream = {s: [f for f in frames if f["stream"] == s] for s in ("parallax", "refocus_stack")}
    assert [len(v) for v in by_stream.values()] == [37, 11]
    meta = {a["type"].rsplit(".", 1)[1]: a["vendorContent"]["blockOfImages"]["metadataArray"] for a in acc}
    assert [f["params"]["lambda"] for f in by_stream["refocus_stack"]] == pytest.approx(
        [m["lambda"] for m in meta["refocusStack"]])
    assert [f["params"]["x"] for f in by_stream["parallax"]] == pytest.approx(
        [m["coord"]["x"] for m in meta["edofParallax"]])
    for f in (by_stream["parallax"][0], by_stream["refocus_stack"][-1]):
        img = cv2.imread(str(out / f["file"]))
        assert img.shape == (1080, 1080, 3) and img.std() > 10  # a picture, not a blank frame
    assert by_stream["refocus_stack"][0]["file"] == "refocus_stack_frame_000_lambda-8.81.png"


def test_extract_depth_preview_is_colour_mapped_with_a_bar(lytro_dir, tmp_path):
    doc = extract_lfp(lytro_dir / "IMG_0002-dm.lfp", tmp_path / "dm")
    entry = next(f for f in doc["files"] if f["kind"] == "depth_map")
    assert entry["values"] == "depth: Lytro refocus lambda" and entry["min"] < 0 < entry["max"]
    img = cv2.imread(str(tmp_path / "dm" / entry["preview"]))
    assert img.shape[1] > img.shape[0]  # the map and, beside it, its colour bar
    b, g, r = (img[..., i].astype(int) for i in range(3))
    assert (np.abs(b - g) + np.abs(g - r) > 30).mean() > 0.3  # colours, not grey
