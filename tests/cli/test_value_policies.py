"""``--negative clip|raise`` and ``--nonfinite`` on the commands that read light fields (issue 20):
refocus, dataset build and bench, as the nine commands that had them (convert, merge, ...)."""

from __future__ import annotations

import numpy as np
import pytest

import lfproc
from lfproc.bench import run_bench
from lfproc.cli.main import main
from lfproc.dataset import build_dataset
from lfproc.errors import InputError
from lfproc.io import read_lightfield, write_lightfield
from lfproc.lightfield import LightField
from lfproc.synth import synthesize


def _err_line(capsys, command: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"lfproc {command}: error: "), err
    return err[0]


def _poke(path, value, *, part=0, channel="R", at=(1, 2)) -> None:
    """Set one sample of an EXR file (an lfproc light field's view part, or an image) to ``value``:
    a file with what LightField itself refuses (negatives from lossy DWAB compression, NaN)."""
    import OpenEXR

    f = OpenEXR.File(str(path), separate_channels=True)
    pixels = np.array(f.parts[part].channels[channel].pixels)
    pixels[at] = value
    f.parts[part].channels[channel].pixels = pixels
    f.write(str(path))


def _with_negative(lf: LightField, path, *, value=-1e-4) -> None:
    """``lf`` written to ``path`` with one tiny negative sample."""
    write_lightfield(lf, path)
    _poke(path, value)
    with pytest.raises(InputError, match="contains 1 negative values"):
        read_lightfield(path, negative="raise")


def test_refocus_negative_and_nonfinite(tmp_path, capsys):
    lf = synthesize("layers", size=(16, 16), views=3, random_state=1)
    src = tmp_path / "neg.exr"
    _with_negative(lf, src)
    out = tmp_path / "r.exr"
    assert main(["refocus", str(src), "-o", str(out), "--slope", "0", "--negative", "raise"]) == 2
    line = _err_line(capsys, "refocus")
    assert f"{src}: contains 1 negative values" in line and "--negative clip" in line
    assert not out.exists()
    assert main(["refocus", str(src), "-o", str(out), "--slope", "0", "--negative", "clip"]) == 0
    assert lfproc.read_image(out)[0].min() >= 0
    write_lightfield(lf, tmp_path / "nan.exr")
    _poke(tmp_path / "nan.exr", np.nan, channel="G", at=(0, 0))
    assert main(["refocus", str(tmp_path / "nan.exr"), "-o", str(tmp_path / "n.exr"), "--slope", "0"]) == 2
    assert "1 NaN" in _err_line(capsys, "refocus") and not (tmp_path / "n.exr").exists()
    assert main(["refocus", str(tmp_path / "nan.exr"), "-o", str(tmp_path / "n.exr"), "--slope", "0",
                 "--nonfinite", "zero"]) == 0


def _bracket_scene(folder, *, negative: bool):
    """A 2-exposure bracket of linear light-field EXRs clipping at 1; one tiny negative sample in the first."""
    folder.mkdir(parents=True)
    radiance = np.geomspace(0.05, 20, 12 * 12 * 3, dtype=np.float32).reshape(1, 1, 12, 12, 3)
    for i, t in enumerate([0.05, 0.5]):
        write_lightfield(LightField(data=np.minimum(radiance * t, 1), saturation_level=1.0), folder / f"shot_{i}.exr")
        if negative and i == 0:
            _poke(folder / f"shot_{i}.exr", -1e-4, at=(0, 0))
    (folder / "exposures.txt").write_text("shot_0.exr 1/20\nshot_1.exr 0.5\n")


def test_dataset_build_negative_and_nonfinite(tmp_path, capsys):
    """lfproc dataset build reads its scenes' EXRs with --negative (default clip, as lfproc merge) and
    --nonfinite; a refused scene is reported naming its file and the option, exit 2, no output for it."""
    scenes = tmp_path / "scenes"
    _bracket_scene(scenes / "neg", negative=True)
    out = tmp_path / "ds"
    args = ["dataset", "build", str(scenes), "-o", str(out), "--scheduler", "synchronous"]
    assert main(args + ["--negative", "raise"]) == 2
    err = capsys.readouterr().err
    (line,) = [x for x in err.splitlines() if "scene neg failed" in x]
    assert str(scenes / "neg" / "shot_0.exr") in line and "contains 1 negative values" in line
    assert "--negative clip" in line
    assert not (out / "scenes" / "neg").exists() and not (out / "done" / "neg.json").exists()
    assert main(args + ["--negative", "clip"]) == 0
    capsys.readouterr()
    assert read_lightfield(out / "scenes" / "neg" / "hdr.exr").data.min() >= 0
    with pytest.raises(InputError, match="negative: expected one of"):
        build_dataset(scenes, out, negative="drop")


@pytest.fixture(scope="module")
def bench_inputs(tmp_path_factory):
    from lfproc.dictionary import dct_dictionary, save_dictionary

    root = tmp_path_factory.mktemp("bench-values")
    lf = synthesize("layers", size=(16, 16), views=5, random_state=1)
    neg = root / "neg.exr"
    _with_negative(lf, neg)
    dictionary = root / "dct4.npz"
    save_dictionary(dct_dictionary((5, 5, 4, 4, 3), 100, n_nonzero_coefs=4), dictionary)
    return root, neg, dictionary


def test_bench_negative_refused_by_default_clipped_on_request(bench_inputs, tmp_path, capsys):
    """lfproc bench refuses a scene with negative samples (its truth: default raise, as lfproc simulate)
    in one line naming the file and --negative, before any folder is made; --negative clip reads it."""
    from lfproc.bench.cells import load_scene
    from lfproc.bench.run import _scenes
    from lfproc.bench.grid import PRESETS
    from lfproc.dictionary import load_dictionary

    root, neg, dictionary = bench_inputs
    out = tmp_path / "b"
    assert main(["bench", str(neg), "-o", str(out), "--dictionary", str(dictionary)]) == 2
    line = _err_line(capsys, "bench")
    assert f"{neg}: contains 1 negative values" in line and "--negative clip" in line
    assert not out.exists()
    # with --negative clip the scene is read: the run gets as far as the output folder (refused here
    # because it is not a bench folder, so no cell is computed by this fast test)
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "mine.txt").write_text("not a bench")
    assert main(["bench", str(neg), "-o", str(tmp_path / "taken"), "--dictionary", str(dictionary),
                 "--negative", "clip"]) == 2
    assert "not a bench folder" in _err_line(capsys, "bench")
    # the workers read the scene with the same policy
    (scene,) = _scenes([neg], PRESETS["quick"], load_dictionary(dictionary), {"nonfinite": "raise", "negative": "clip"})
    assert scene.negative == "clip" and load_scene(scene).data.min() == 0
    with pytest.raises(InputError, match="nonfinite: expected one of"):
        run_bench([neg], tmp_path / "lib", dictionary=dictionary, read_options={"nonfinite": "drop"})


def test_bench_cells_of_another_value_policy_are_not_reused(bench_inputs):
    """A non-default value policy is part of the cell identity; the default keeps today's ids."""
    from lfproc.bench.grid import Cell, cell_id

    cell = Cell("neg", "joint", "random", 2, (100, 400, 800, 1600), "low")
    base = {"scene_sha256": "x", "crop": None}
    assert cell_id(cell, base) != cell_id(cell, base | {"values": {"nonfinite": "raise", "negative": "clip"}})
