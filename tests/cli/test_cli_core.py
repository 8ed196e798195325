"""The command line's shared behaviour: version, info, convert, error lines and exit codes."""

import json

import numpy as np
import pytest

from lfproc import LightField, __version__, read_lightfield, write_lightfield
from lfproc.cli.main import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_version(capsys):
    code, out, _ = run(capsys, "--version")
    assert code == 0 and out.strip() == f"lfproc {__version__}"


def test_info_json_on_written_lightfield(tmp_path, capsys):
    data = np.full((5, 5, 4, 6, 3), 2.0, dtype=np.float32)
    data[2, 2, 0, 0] = 512.0
    write_lightfield(LightField(data, exposure_s=0.01), tmp_path / "lf.exr")
    code, out, err = run(capsys, "info", str(tmp_path / "lf.exr"), "--json")
    assert code == 0 and err == ""
    info = json.loads(out)
    assert info["kind"] == "lightfield"
    assert info["views"] == [5, 5] and info["size"] == [4, 6] and info["channels"] == 3
    assert info["min"] == 2.0 and info["max"] == 512.0
    assert info["exposure_s"] == 0.01 and info["exr_parts"] == 25
    assert 0 < info["dynamic_range_stops"] <= 8.0


def test_info_on_shared_folder_and_single_image(shared_data, capsys):
    code, out, _ = run(capsys, "info", str(shared_data / "lightfields/lowres_5x5/stanford_tarot"), "--json")
    info = json.loads(out)
    assert code == 0 and info["kind"] == "lightfield" and info["views"] == [5, 5] and info["size"] == [128, 128]
    code, out, _ = run(capsys, "info", str(shared_data / "hdr/ScanLines_Desk.exr"), "--json")
    info = json.loads(out)
    assert code == 0 and info["kind"] == "image" and info["views"] == [1, 1] and info["size"] == [874, 644]
    assert info["dynamic_range_stops"] > 9
    code, out, _ = run(capsys, "info", str(shared_data / "hdr/ScanLines_Desk.exr"))
    assert code == 0 and "dynamic_range_stops" in out and "{" not in out.splitlines()[0]


@pytest.mark.parametrize(
    "make, expected",
    [
        (lambda p: p / "missing.exr", "no such file"),
        (lambda p: (p / "garbage.exr").write_bytes(b"\x00" * 10) and p / "garbage.exr", "not a readable OpenEXR"),
        (lambda p: (p / "notes.txt").write_text("x") and p / "notes.txt", "not a light field or image"),
    ],
)
def test_info_errors_are_one_line_exit_2(tmp_path, capsys, make, expected):
    path = make(tmp_path)
    code, out, err = run(capsys, "info", str(path))
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lfproc info: error: ") and expected in lines[0]
    assert str(path) in lines[0]


def test_debug_shows_the_traceback(tmp_path):
    from lfproc.errors import MissingFileError

    with pytest.raises(MissingFileError):
        main(["--debug", "info", str(tmp_path / "missing.exr")])
    with pytest.raises(MissingFileError):
        main(["info", str(tmp_path / "missing.exr"), "--debug"])


def test_bad_option_exits_2(capsys):
    code, _, err = run(capsys, "convert", "a", "b", "--format", "gif")
    assert code == 2 and "invalid choice" in err


@pytest.fixture(params=["written", "real"])
def png_views(request, tmp_path):
    """A folder of 8-bit sRGB PNG views: written here from a synthetic scene, or a real one (INRIA)."""
    if request.param == "real":
        return request.getfixturevalue("shared_data") / "lightfields/lowres_5x5/inria_hublais"
    from lfproc.synth import synthesize

    lf = synthesize("checker", size=(24, 32), views=5, random_state=3)
    lf = lf.replace(data=np.clip(lf.data / np.percentile(lf.data, 90), 0, 1))
    return write_lightfield(lf, tmp_path / "src_views", folder_format="png")


def test_convert_round_trip_and_force(png_views, tmp_path, capsys):
    src = png_views
    out = tmp_path / "hublais.exr"
    code, stdout, _ = run(capsys, "convert", str(src), str(out))
    assert code == 0 and "5x5 views" in stdout
    original = read_lightfield(src)
    np.testing.assert_array_equal(read_lightfield(out).data, original.data)
    code, _, err = run(capsys, "convert", str(src), str(out))
    assert code == 2 and "--force" in err
    code, _, _ = run(capsys, "convert", str(out), str(tmp_path / "views"), "--format", "png16")
    assert code == 0
    back = read_lightfield(tmp_path / "views")
    np.testing.assert_allclose(back.data, original.data, atol=1e-4)


def test_convert_wrong_shape_folder(tmp_path, capsys):
    folder = tmp_path / "v"
    write_lightfield(LightField(np.ones((2, 2, 3, 3, 3))), folder)
    from lfproc.io import write_image

    write_image(folder / "view_01_01.exr", np.ones((4, 3, 3)), force=True)
    code, _, err = run(capsys, "convert", str(folder), str(tmp_path / "o.exr"))
    assert code == 2 and "view size" in err and not (tmp_path / "o.exr").exists()


def test_a_closed_pipe_ends_quietly(tmp_path):
    """``lfproc info X | head -0``: the reader is gone before lfproc writes (a pipe whose read end
    is closed: every write fails with EPIPE). No traceback, no 'error: Broken pipe' line."""
    import os
    import subprocess
    import sys

    write_lightfield(LightField(np.ones((5, 5, 4, 6, 3), np.float32)), tmp_path / "lf.exr")
    r, w = os.pipe()
    os.close(r)
    try:
        proc = subprocess.run([sys.executable, "-c", "import sys; from lfproc.cli.main import main; "
                               f"sys.exit(main(['info', {str(tmp_path / 'lf.exr')!r}]))"],
                              stdout=w, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(w)
    assert proc.stderr == "" and proc.returncode == 1
