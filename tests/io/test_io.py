"""Light-field and image files: round trips, real samples, refusals, atomic writes."""

import json
import os

import numpy as np
import pytest

from lfproc import LightField, read_lightfield, write_lightfield
from lfproc.errors import FileFormatError, InputError, MissingFileError, OutputExistsError, ShapeError
from lfproc.io._atomic import atomic_file
from lfproc.io import exr_parts, read_image, write_image


def random_lf(seed=0, shape=(3, 3, 12, 16, 3), **kw):
    rng = np.random.default_rng(seed)
    data = rng.lognormal(0, 3, size=shape).astype(np.float32)  # ~ 20 stops
    return LightField(data, **kw)


def test_exr_round_trip_is_bit_exact_with_metadata(tmp_path):
    rng = np.random.default_rng(1)
    lf = random_lf(
        variance=rng.uniform(0, 1, (3, 3, 12, 16, 3)),
        disparity=rng.normal(0, 1, (12, 16)),
        units="e-/s",
        exposure_s=0.004,
        iso=400,
        source="unit-test",
        attrs={"scene": "x", "seed": 3},
    )
    path = write_lightfield(lf, tmp_path / "lf.exr")
    back = read_lightfield(path)
    np.testing.assert_array_equal(back.data, lf.data)
    np.testing.assert_array_equal(back.variance, lf.variance)
    np.testing.assert_array_equal(back.disparity, lf.disparity)
    assert (back.units, back.exposure_s, back.iso, back.source) == ("e-/s", 0.004, 400, "unit-test")
    assert back.attrs == {"scene": "x", "seed": 3}
    parts = exr_parts(path)
    assert [p["name"] for p in parts][:2] == ["view_01_01", "view_01_02"] and len(parts) == 9


def test_exr_half_and_luminance_round_trip(tmp_path):
    lf = random_lf(shape=(1, 3, 5, 6, 1))
    back = read_lightfield(write_lightfield(lf, tmp_path / "y.exr", dtype="half"))
    assert back.channels == 1
    np.testing.assert_allclose(back.data, lf.data, rtol=1e-3)


def assert_rgbe_close(back, ref):
    """Radiance RGBE shares one exponent per pixel: error below 1/128 of the pixel's largest channel."""
    scale = ref.max(axis=-1, keepdims=True)
    assert np.all(np.abs(back - ref) <= scale / 128 + 1e-12)


@pytest.mark.parametrize("fmt, rtol", [("exr", 0), ("hdr", None), ("png16", 2e-4), ("tiff", 2e-4)])
def test_folder_round_trips(tmp_path, fmt, rtol):
    lf = random_lf(shape=(3, 3, 8, 9, 3))
    if fmt in ("png16", "tiff"):
        lf = lf.replace(data=np.clip(lf.data / lf.data.max() * 50, 0, 1))
    out = write_lightfield(lf, tmp_path / "views", folder_format=fmt)
    names = sorted(p.name for p in out.iterdir())
    assert "lightfield.json" in names and any(n.startswith("view_03_03.") for n in names)
    back = read_lightfield(out)
    assert back.views == (3, 3)
    if rtol == 0:
        np.testing.assert_array_equal(back.data, lf.data)
    elif rtol is None:
        assert_rgbe_close(back.data, lf.data)
    else:
        np.testing.assert_allclose(back.data, lf.data, rtol=rtol, atol=2e-4)


def test_overwrite_needs_force_and_writes_are_atomic(tmp_path):
    lf = random_lf()
    path = write_lightfield(lf, tmp_path / "a.exr")
    with pytest.raises(OutputExistsError, match="pass force=True to overwrite"):  # Python's name (CLI: --force)
        write_lightfield(lf, path)
    write_lightfield(lf.replace(source="second"), path, force=True)
    assert read_lightfield(path).source == "second"
    # a writer that fails leaves neither the output nor a temporary file
    with pytest.raises(RuntimeError):
        with atomic_file(tmp_path / "b.exr") as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("interrupted")
    assert sorted(os.listdir(tmp_path)) == ["a.exr"]
    folder = write_lightfield(lf, tmp_path / "views")
    with pytest.raises(OutputExistsError):
        write_lightfield(lf, folder)
    write_lightfield(lf.replace(source="again"), folder, force=True)
    assert json.loads((folder / "lightfield.json").read_text())["source"] == "again"
    assert sorted(os.listdir(tmp_path)) == ["a.exr", "views"]


def test_missing_and_wrong_inputs(tmp_path):
    with pytest.raises(MissingFileError, match="no such"):
        read_lightfield(tmp_path / "nope.exr")
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr at all")
    with pytest.raises(FileFormatError, match="OpenEXR"):
        read_lightfield(bad)
    txt = tmp_path / "notes.txt"
    txt.write_text("hello")
    with pytest.raises(FileFormatError, match="expected a folder"):
        read_lightfield(txt)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileFormatError, match="view_RR_CC"):
        read_lightfield(empty)
    with pytest.raises(InputError, match="suffix"):
        write_lightfield(random_lf(), tmp_path / "out.png")


def test_incomplete_or_mismatched_view_folder(tmp_path):
    lf = random_lf(shape=(2, 2, 4, 4, 3))
    folder = write_lightfield(lf, tmp_path / "v", folder_format="exr")
    (folder / "view_02_01.exr").unlink()
    with pytest.raises(FileFormatError, match="missing view_02_01"):
        read_lightfield(folder)
    write_image(folder / "view_02_01.exr", np.ones((5, 4, 3)))
    with pytest.raises(ShapeError, match="view size"):
        read_lightfield(folder)


def test_shared_png_views_decode_srgb(shared_data):
    lf = read_lightfield(shared_data / "lightfields/lowres_5x5/hci_bedroom")
    assert lf.views == (5, 5) and lf.size == (128, 128) and lf.saturation_level == 1.0
    raw, meta = read_image(shared_data / "lightfields/lowres_5x5/hci_bedroom/view_03_03.png", transfer="linear")
    assert meta["bit_depth"] == 8
    # sRGB decoding is below the identity in (0, 1)
    mid = (raw > 0.2) & (raw < 0.8)
    assert np.all(lf.centre()[mid] < raw[mid])


def _exr_first_part(path):
    """The first part's colour channels read with OpenEXR directly (R, G, B; else Y; else the one
    channel there is), float32, stacked on the last axis."""
    import OpenEXR

    ch = OpenEXR.File(str(path), separate_channels=True).parts[0].channels
    names = ["R", "G", "B"] if "R" in ch else (["Y"] if "Y" in ch else list(ch))
    return np.stack([ch[n].pixels.astype(np.float32) for n in names], axis=-1)


@pytest.mark.parametrize(
    "name, channels",
    [
        ("ScanLines_StillLife.exr", 3),
        ("ScanLines_Cannon.exr", 3),
        ("TestImages_WideFloatRange.exr", 1),
        ("MultiView_Fog.exr", 1),
        ("Beachball_multipart.0001.exr", 3),
    ],
)
def test_real_exr_samples_are_read(shared_data, name, channels):
    path = shared_data / "hdr" / name
    lf = read_lightfield(path)
    assert lf.views == (1, 1) and lf.channels == channels
    # the samples are the file's, channel for channel (negatives clipped to 0 by default)
    np.testing.assert_array_equal(lf.data[0, 0], np.maximum(_exr_first_part(path), 0))


def test_real_exr_structure_cases(shared_data):
    beach = shared_data / "hdr/Beachball_multipart.0001.exr"
    img, meta = read_image(beach)
    assert meta["part_name"] == "rgba_right" and img.shape == (876, 877, 3)
    img, meta = read_image(beach, part="rgba_left")
    assert meta["view"] == "left"
    with pytest.raises(InputError, match="no part named"):
        read_image(beach, part="nope")
    with pytest.raises(FileFormatError, match="R,G,B or Y"):
        read_image(beach, part="depth_left")
    fog = shared_data / "hdr/MultiView_Fog.exr"
    left, _ = read_image(fog)
    right, meta = read_image(fog, view="right")
    assert meta["channels_read"] == ["right.Y"] and not np.array_equal(left, right)
    wide, meta = read_image(shared_data / "hdr/TestImages_WideFloatRange.exr")
    assert wide.max() > 1e37 and meta["clipped_negative"] > 0


def test_nan_inf_sample_refused_or_cleaned(shared_data):
    path = shared_data / "hdr/TestImages_BrightRingsNanInf.exr"
    with pytest.raises(InputError, match="NaN .* Inf"):
        read_lightfield(path)
    lf = read_lightfield(path, nonfinite="zero")
    raw = _exr_first_part(path)
    bad = ~np.isfinite(raw)
    assert bad.sum() > 0 and (lf.data[0, 0][bad] == 0).all()  # NaN and Inf became 0, nothing else moved
    np.testing.assert_array_equal(lf.data[0, 0][~bad], np.maximum(raw[~bad], 0))
    clipped = read_lightfield(path, nonfinite="clip")  # +Inf -> the largest finite value instead
    posinf = np.isposinf(raw)
    assert posinf.any() and (clipped.data[0, 0][posinf] == raw[~bad].max()).all()


def test_dwab_environment_maps_clip_tiny_negatives(shared_data):
    img, meta = read_image(shared_data / "hdr_cc0/city.exr")
    assert img.min() >= 0 and img.max() > 1e4
    with pytest.raises(InputError, match="negative"):
        read_image(shared_data / "hdr_cc0/city.exr", negative="raise")


def test_radiance_hdr_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    img = rng.lognormal(0, 2, (6, 7, 3)).astype(np.float32)
    back, meta = read_image(write_image(tmp_path / "x.hdr", img))
    assert meta["transfer"] == "linear"
    assert_rgbe_close(back, img)


def test_outputs_get_the_usual_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        f = write_lightfield(random_lf(), tmp_path / "p.exr")
        d = write_lightfield(random_lf(), tmp_path / "pv")
    finally:
        os.umask(old)
    assert (f.stat().st_mode & 0o777) == 0o644
    assert (d.stat().st_mode & 0o777) == 0o755
