"""``lfproc convert``: clipping warning, exposure and tone mapping, disparity kept, single images, dotted folders."""

from __future__ import annotations

import numpy as np
import pytest

from lfproc.cli.main import main
from lfproc.errors import SaturationWarning
from lfproc.io import read_lightfield, write_lightfield
from lfproc.synth import synthesize


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A synthetic HDR scene with its disparity (most samples above 1, as README's example)."""
    lf = synthesize("layers", size=(48, 64), views=3, random_state=1)
    path = tmp_path_factory.mktemp("scene") / "scene.exr"
    write_lightfield(lf, path)
    return lf, path


def test_clipping_is_reported(scene, tmp_path, capsys):
    """main wrote the 8/16-bit views silently with most samples clipped at 1."""
    lf, path = scene
    expected = float(np.mean(lf.data > 1))
    assert expected > 0.3
    assert main(["convert", str(path), str(tmp_path / "v"), "--format", "png16"]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lfproc convert: warning:" in err
    assert f"{expected:.1%} of the samples exceed 1" in err and "--tonemap" in err
    # the library warns with the project's warning class
    with pytest.warns(SaturationWarning, match="exceed 1"):
        write_lightfield(lf, tmp_path / "lib", folder_format="png")
    # float outputs do not clip: no warning
    assert main(["convert", str(path), str(tmp_path / "e"), "--format", "exr"]) == 0
    assert capsys.readouterr().err == ""


def test_exposure_and_tonemap(scene, tmp_path, capsys):
    lf, path = scene
    # exposure: the values are scaled by 2^EV before the 16-bit encoding
    assert main(["convert", str(path), str(tmp_path / "dark"), "--format", "png16", "--exposure-ev", "-8"]) == 0
    err = capsys.readouterr().err
    back = read_lightfield(tmp_path / "dark")
    scaled = lf.data / 256
    assert float(np.mean(scaled > 1)) == pytest.approx(float(np.mean(back.data >= 1 - 1e-4)), abs=1e-3)
    ok = (scaled > 0.01) & (scaled < 1)
    np.testing.assert_allclose(back.data[ok], scaled[ok], rtol=2e-3)
    assert back.attrs["display"]["exposure_ev"] == -8
    if float(np.mean(scaled > 1)) == 0:
        assert err == ""
    # tone mapping (OpenCV Reinhard on all views as one image): nothing clipped, order of luminance kept
    assert main(["convert", str(path), str(tmp_path / "tm.views"), "--format", "png16", "--tonemap", "reinhard"]) == 0
    assert "warning" not in capsys.readouterr().err
    tm = read_lightfield(tmp_path / "tm.views")
    assert tm.data.max() <= 1 and tm.data.max() > 0.5
    from scipy.stats import spearmanr

    for c in range(3):  # a global curve per channel: the order of the values is kept
        assert spearmanr(lf.data[..., c].ravel(), tm.data[..., c].ravel()).statistic > 0.99
    # every view tone mapped with the same statistics: the centre pixel of a static (zero-disparity)
    # layer reads the same in every view
    cv = lf.centre_index
    same = np.abs(lf.data - lf.data[cv][None, None]).max(axis=(0, 1, 4)) < 1e-6
    assert same.sum() > 50
    spread = np.abs(tm.data - tm.data[cv][None, None]).max(axis=(0, 1, 4))[same]
    assert spread.max() < 1e-3
    assert main(["convert", str(path), str(tmp_path / "x"), "--tonemap", "filmic"]) == 2
    assert "invalid choice" in capsys.readouterr().err


def test_disparity_kept_in_folders(scene, tmp_path):
    import cv2

    lf, path = scene
    assert lf.disparity is not None
    assert main(["convert", str(path), str(tmp_path / "out.views"), "--format", "png"]) in (0,)
    pfm = tmp_path / "out.views" / "disparity.pfm"
    assert pfm.exists()
    # an independent PFM reader (OpenCV) sees the same disparity
    np.testing.assert_array_equal(cv2.imread(str(pfm), cv2.IMREAD_UNCHANGED), lf.disparity)
    back = read_lightfield(tmp_path / "out.views")
    np.testing.assert_array_equal(back.disparity, lf.disparity)
    # and back to one EXR: the disparity channel again
    assert main(["convert", str(tmp_path / "out.views"), str(tmp_path / "again.exr")]) == 0
    np.testing.assert_array_equal(read_lightfield(tmp_path / "again.exr").disparity, lf.disparity)


def test_single_image_outputs(scene, tmp_path, capsys):
    lf, path = scene
    one = tmp_path / "centre.exr"
    write_lightfield(lf.central(1).replace(disparity=None), one)
    hdr = tmp_path / "centre.hdr"
    assert main(["convert", str(one), str(hdr)]) == 0
    back = read_lightfield(hdr)
    assert back.views == (1, 1)
    ref = lf.central(1).data
    # RGBE: 8-bit mantissas sharing the exponent of the pixel's largest channel
    assert (np.abs(back.data - ref) <= 0.008 * ref.max(axis=-1, keepdims=True) + 1e-6).all()
    assert main(["convert", str(one), str(tmp_path / "centre.png"), "--tonemap", "drago"]) == 0
    assert read_lightfield(tmp_path / "centre.png").shape == (1, 1, 48, 64, 3)
    assert main(["convert", str(one), str(tmp_path / "c2.exr")]) == 0
    # a 3x3 light field into one image: one clear line
    assert main(["convert", str(path), str(tmp_path / "all.hdr")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a single image holds one view, this light field has 3x3" in err
    assert not (tmp_path / "all.hdr").exists()


def test_negative_and_nonfinite_options(tmp_path, capsys):
    """--negative clip|raise (issue 20): clip by default as before, refused with --negative raise."""
    from lfproc.io import write_image

    img = np.full((8, 8, 3), 0.5, np.float32)
    img[1, 2, 0] = -0.01
    src = tmp_path / "neg.exr"
    write_image(src, img)
    out = tmp_path / "o.exr"
    assert main(["convert", str(src), str(out), "--negative", "raise"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{src}: contains 1 negative values" in err
    assert not out.exists()
    assert main(["convert", str(src), str(out)]) == 0
    assert read_lightfield(out).data.min() == 0
    img[3, 3, 2] = np.inf
    write_image(src, img, force=True)
    assert main(["convert", str(src), str(out), "--force"]) == 2
    assert "1 Inf" in capsys.readouterr().err
    assert main(["convert", str(src), str(out), "--force", "--nonfinite", "clip"]) == 0
    assert read_lightfield(out).data.max() == pytest.approx(0.5)
