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


def test_stage_figures_are_right(demo_dir):
    stages = {row["stage"]: row["figures"] for row in json.loads((demo_dir / "report.json").read_text())["stages"]}
    assert stages["synthesize"]["dynamic_range_stops"] >= 16
    sanity = stages["metrics sanity"]
    assert sanity["relative_noise_0.01"]["pu21_psnr_db"] > sanity["relative_noise_0.05"]["pu21_psnr_db"]
    assert stages["white images"]["max_spacing_error_px"] < 0.01
    assert stages["white images"]["max_rotation_error_rad"] < 1e-4
    assert stages["decode"]["psnr_0ev_db"] >= 35
    merge = stages["merge"]
    assert merge["pu21_psnr_db"] > merge["pu21_psnr_db_0ev_capture_alone"]  # the bracket adds range
    cal = stages["calibrate"]["worst_error_percent"]
    assert cal["gain_error_percent"] < 2 and cal["dark_current_error_percent"] < 5
    assert cal["full_well_error_percent"] < 2
    sim = stages["simulate"]
    assert sim["sampling_rate"] == "2.67 %"
    assert abs(sim["observation_relative_bias"]) < 0.01
    assert 0.9 < sim["observation_z_variance"] < 1.1


def test_existing_output_needs_force(demo_dir, capsys):
    assert main(["demo", "-o", str(demo_dir)]) == 2
    assert "--force" in capsys.readouterr().err
