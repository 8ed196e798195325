"""`lfproc demo`: every stage runs, the report lists each with figures that make sense."""

import json

import pytest

from lfproc.cli.main import main
from lfproc.demo import STAGES


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "out"
    assert main(["demo", "-o", str(out)]) == 0
    return out


@pytest.mark.slow  # the whole demo (module fixture)
def test_report_lists_every_stage_with_figures(demo_dir):
    report = json.loads((demo_dir / "report.json").read_text())
    assert [row["stage"] for row in report["stages"]] == [name for name, _ in STAGES]
    markdown = (demo_dir / "report.md").read_text()
    for name, _ in STAGES:
        assert f"## {name}" in markdown
    for row in report["stages"]:
        assert row["figures"], row["stage"]
        for f in row["files"]:
            assert (demo_dir / f).is_file()


@pytest.mark.slow  # the whole demo (module fixture)
def test_stage_figures_are_right(demo_dir):
    stages = {row["stage"]: row["figures"] for row in json.loads((demo_dir / "report.json").read_text())["stages"]}
    assert stages["synthesize"]["dynamic_range_stops"] >= 16
    sanity = stages["metrics sanity"]
    assert sanity["relative_noise_0.01"]["pu21_psnr_db"] > sanity["relative_noise_0.05"]["pu21_psnr_db"]
    assert stages["white images"]["max_spacing_error_px"] < 0.01
    assert stages["white images"]["max_rotation_error_rad"] < 1e-4
    # lfproc.lytro.score: clipped truth left out, 99.9th-percentile peak (the sun does not inflate it)
    assert stages["decode"]["psnr_0ev_db"]["psnr_all_views_db"] >= 24  # 26.6 dB measured (96 x 96 scene)
    merge = stages["merge"]
    assert merge["pu21_psnr_db"] > merge["pu21_psnr_db_0ev_capture_alone"]  # the bracket adds range
    cal = stages["calibrate"]["worst_error_percent"]
    assert cal["gain_error_percent"] < 2 and cal["dark_current_error_percent"] < 5
    assert cal["full_well_error_percent"] < 2
    sim = stages["simulate"]
    assert sim["sampling_rate"] == "2.67 %"
    assert abs(sim["observation_relative_bias"]) < 0.01
    assert 0.9 < sim["observation_z_variance"] < 1.1
    # the 96 x 96 layers scene, 2 coded shots (a 96 px scene is mostly its sun and sky): measured
    # 2026-11-25, gmm (default; patches every 2 pixels: 45 x 45) 22.51 dB / 0.883, the shipped
    # dictionary 21.50 dB / 0.874
    rec = stages["reconstruct"]
    assert rec["method"] == "gmm" and rec["patches"] == 45 * 45
    assert rec["pu21_psnr_db"] > 21.5 and rec["pu21_ssim"] > 0.85, rec
    assert rec["dictionary_pu21_psnr_db"] > 20 and rec["dictionary_pu21_ssim"] > 0.8, rec
    assert rec["pu21_psnr_db"] > rec["dictionary_pu21_psnr_db"], rec


@pytest.mark.slow  # the whole demo (module fixture)
def test_existing_output_needs_force(demo_dir, capsys):
    assert main(["demo", "-o", str(demo_dir)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"lfproc demo -o {demo_dir} --force" in err[0]  # the command to re-run


@pytest.mark.slow  # the whole demo (module fixture)
def test_report_is_short_with_a_contact_sheet(demo_dir):
    """The report lists the raw calibration frames as one folder and shows a contact sheet of them,
    and every picture it embeds exists."""
    import re

    import cv2

    markdown = (demo_dir / "report.md").read_text()
    assert len(markdown) < 15000
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", markdown)
    assert "calibration/frames_contact_sheet.png" in pictures
    assert not any("/frames/" in p for p in pictures) and len(pictures) < 30
    for p in pictures:
        assert (demo_dir / p).is_file(), p
    assert re.search(r"calibration/simulated/frames/ \(288 PNG files\)", markdown)
    sheet = cv2.imread(str(demo_dir / "calibration/frames_contact_sheet.png"), cv2.IMREAD_GRAYSCALE)
    assert sheet is not None and sheet.shape[0] > 4 * 96  # a row per ISO (4 ISOs)
    report = json.loads((demo_dir / "report.json").read_text())
    calib = next(row for row in report["stages"] if row["stage"] == "calibrate")
    assert sum(f.startswith("calibration/simulated/frames/") for f in calib["files"]) == 288


def test_an_existing_folder_is_refused_before_any_stage_runs(tmp_path, capsys, monkeypatch):
    """The fast check of the demo's command line: an existing output is refused in one line naming the
    command with --force, before any stage runs, and the folder is left as it was."""
    import lfproc.demo as demo

    ran = []
    monkeypatch.setattr(demo, "STAGES", [(name, lambda ctx, name=name: ran.append(name)) for name, _ in STAGES])
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    assert main(["demo", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lfproc demo: error:") and f"lfproc demo -o {out} --force" in err[0]
    assert ran == [] and [p.name for p in out.iterdir()] == ["mine.txt"]
    assert (out / "mine.txt").read_text() == "keep"
