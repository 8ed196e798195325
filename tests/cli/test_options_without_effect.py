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
