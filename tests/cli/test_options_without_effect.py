"""Options accepted but without effect in the mode a command chose are refused (issue 20), outside
``lfproc merge`` (tests/hdr/test_merge.py): ``lfproc preview --exposure`` on a dictionary or a capture."""

from __future__ import annotations

from lfproc.camera.simulate import simulate_capture
from lfproc.cli.main import main
from lfproc.io import write_lightfield
from lfproc.synth import synthesize


def test_preview_exposure_refused_for_dictionaries_and_captures(tmp_path, capsys):
    out = tmp_path / "p.png"
    assert main(["preview", "default", "-o", str(out), "--exposure", "2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--exposure: applies to light-field previews; default is a dictionary" in err
    lf = synthesize("layers", size=(32, 32), views=5, random_state=1)
    path = simulate_capture(lf, profile="paper-medium", shots=1, mask_period=4, random_state=1).save(
        tmp_path / "a.capture.npz")
    assert main(["preview", str(path), "-o", str(out), "--exposure", "-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--exposure: applies to light-field previews" in err and "a coded capture" in err
    assert not out.exists()
    # where it applies it is accepted, and without it the other inputs still preview
    assert main(["preview", "default", "-o", str(out)]) == 0
    lf_path = write_lightfield(lf, tmp_path / "lf.exr")
    assert main(["preview", str(lf_path), "-o", str(tmp_path / "l.png"), "--exposure", "1"]) == 0
    capsys.readouterr()


def test_evaluate_force_without_error_map_is_refused(tmp_path, capsys):
    """--force only allows overwriting --error-map; alone it did nothing."""
    lf = synthesize("layers", size=(16, 16), views=3, random_state=1)
    path = write_lightfield(lf, tmp_path / "lf.exr")
    assert main(["evaluate", str(path), str(path), "--force"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--force: has no effect without --error-map" in err
    out = tmp_path / "map.png"
    assert main(["evaluate", str(path), str(path), "--error-map", str(out), "--json"]) == 0
    assert main(["evaluate", str(path), str(path), "--error-map", str(out), "--force", "--json"]) == 0
    capsys.readouterr()


def test_block_px_refused_unless_the_iso_pattern_is_block(tmp_path, capsys):
    """lfproc simulate --block-px and lfproc capture import --block-px only shape the block pattern."""
    lf_path = write_lightfield(synthesize("layers", size=(16, 16), views=5, random_state=1), tmp_path / "lf.exr")
    out = tmp_path / "c.npz"
    assert main(["simulate", str(lf_path), "-o", str(out), "--iso-pattern", "row", "--block-px", "4"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--block-px: has no effect with --iso-pattern row (block only)" in err
    assert not out.exists()
    assert main(["simulate", str(lf_path), "-o", str(out), "--iso-pattern", "block", "--block-px", "4",
                 "--seed", "1", "--json"]) == 0
    capsys.readouterr()
    assert main(["capture", "import", str(tmp_path / "a.dng"), "-o", str(tmp_path / "x.npz"), "--iso-layout", "row",
                 "--isos", "100,800", "--block-px", "4", "--mask", "random", "--exposures-s", "0.01",
                 "--profile", "paper-low"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--block-px: has no effect with --iso-layout row" in err
    # an ISO map file gives every pixel's ISO: --isos was ignored
    assert main(["capture", "import", str(tmp_path / "a.dng"), "-o", str(tmp_path / "x.npz"), "--iso-layout",
                 str(tmp_path / "isos.npy"), "--isos", "100,800", "--mask", "random", "--exposures-s", "0.01",
                 "--profile", "paper-low"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--isos: has no effect with an ISO map file" in err
