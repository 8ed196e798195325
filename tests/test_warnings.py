"""lfproc's warnings are emitted where they apply: SaturationWarning and ConvergenceWarning.

The suite runs with warnings as errors, so every test here that expects *no* warning would
fail if one were emitted.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from lfproc.camera.capture import Capture, observations
from lfproc.camera.projection import make_mask
from lfproc.sensor import expose
from lfproc.camera.simulate import capture_summary, simulate_capture
from lfproc.cli.main import main
from lfproc.errors import ConvergenceWarning, SaturationWarning
from lfproc.io import write_lightfield
from lfproc.hdr._merge import ML_TOLERANCE_STD
from lfproc.hdr import merge_debevec, merge_ml
from lfproc.synth import synthesize

TIMES = [0.01 * 2**k for k in range(5)]


@pytest.mark.parametrize("n_saturated, warns", [(10, False), (11, True)])
def test_capture_threshold_is_more_than_ten_percent(n_saturated, warns):
    """Known answer (README, "Warnings"): more than 10 % of the least sensitive pixels saturated warns.
    100 ISO-100 pixels, counted by hand: 10 saturated (10.0 %) is silent, 11 (11.0 %) warns; the
    message states the documented threshold. (This replaces a test that compared
    SATURATION_WARNING_FRACTION with its own literal.)"""
    dn = np.full((1, 20, 10), 1000, np.uint16)
    dn[0, :10].flat[:n_saturated] = 4095  # rows 0-9: ISO 100 (100 pixels); rows 10-19: ISO 400
    iso = np.repeat(np.array([100] * 10 + [400] * 10, np.float32)[:, None], 10, axis=1)
    mask = make_mask("random", shots=1, views=(1, 1), size=(20, 10), random_state=0)
    cap = Capture(dn=dn, iso=iso, exposures_s=0.01, mask=mask, profile="paper-low", views=(1, 1))
    assert cap.saturated_fraction(pixels="least-sensitive") == n_saturated / 100
    if warns:
        with pytest.warns(SaturationWarning, match=re.escape("11.0 % of the least sensitive pixels (ISO 100 at "
                                                             "0.01 s) are saturated (more than 10 %)")):
            observations(cap)
    else:
        observations(cap)  # warnings are errors in this suite: any warning fails here


# -- captures ---------------------------------------------------------------------------------

def _two_iso_capture(n_sat_100: int, n_sat_400: int) -> Capture:
    """A 4 x 10 shot: rows 0-1 at ISO 100 (the least sensitive pixels), rows 2-3 at ISO 400."""
    dn = np.full((1, 4, 10), 1000, np.uint16)
    dn[0, :2].flat[:n_sat_100] = 4095  # paper-low saturates at the ADC's 4095 at both ISOs
    dn[0, 2:].flat[:n_sat_400] = 4095
    iso = np.repeat(np.array([100, 100, 400, 400], np.float32)[:, None], 10, axis=1)
    mask = make_mask("random", shots=1, views=(1, 1), size=(4, 10), random_state=0)
    return Capture(dn=dn, iso=iso, exposures_s=0.01, mask=mask, profile="paper-low", views=(1, 1))


def test_capture_warns_when_its_least_sensitive_pixels_saturate():
    # 3 of the 20 ISO-100 pixels: 15 % > 10 %
    cap = _two_iso_capture(3, 0)
    assert cap.saturated_fraction(pixels="least-sensitive") == pytest.approx(3 / 20)
    assert cap.saturated_fraction() == pytest.approx(3 / 40)
    with pytest.warns(SaturationWarning, match=re.escape(
            "capture: 15.0 % of the least sensitive pixels (ISO 100 at 0.01 s) are saturated (more than 10 %)")):
        obs = observations(cap)
    assert obs.saturated.sum() == 3
    # every ISO-400 pixel saturated but only 2 of 20 ISO-100 ones (10 %, not more): the high ISO
    # clips in highlights by design, the radiance is still in the low-ISO pixels -> no warning
    cap = _two_iso_capture(2, 20)
    assert cap.saturated_fraction() == pytest.approx(22 / 40)
    obs = observations(cap)
    assert obs.saturated_fraction == pytest.approx(22 / 40)


def test_simulate_warns_once_and_the_summary_does_not_repeat_it(tmp_path, capsys):
    lf = synthesize("layers", size=(16, 16), views=(5, 5), random_state=0)  # the shipped dictionary's views
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cap = simulate_capture(lf, radiance_scale=1e9, random_state=0)  # far too bright
        summary = capture_summary(cap)
    assert [w.category for w in caught] == [SaturationWarning]
    assert "capture: 100.0 % of the least sensitive pixels (ISO 100 at 0.004 s)" in str(caught[0].message)
    assert summary["saturated_fraction"] == 1.0
    # the automatic radiance scale does not warn (warnings are errors in this suite)
    simulate_capture(lf, random_state=0)
    # the command prints one warning line and still succeeds
    write_lightfield(lf, tmp_path / "lf.exr")
    assert main(["simulate", str(tmp_path / "lf.exr"), "-o", str(tmp_path / "c.npz"), "--radiance-scale", "1e9", "--seed", "0",
                 "--json"]) == 0
    err = capsys.readouterr().err
    assert err.startswith("lfproc simulate: warning: capture: 100.0 % of the least sensitive pixels")
    assert err.count("\n") == 1 and (tmp_path / "c.npz").is_file()


# -- exposure brackets ----------------------------------------------------------------------------

@pytest.mark.parametrize("n_saturated, warns", [(10, False), (11, True)])
def test_bracket_warns_above_ten_percent_saturated_everywhere(n_saturated, warns):
    dn = np.full((3, 100), 300, np.uint16)  # illum: 10-bit, saturates at 1023
    dn[:, :n_saturated] = 1023
    times = [0.01, 0.02, 0.04]
    if warns:
        with pytest.warns(SaturationWarning, match=r"exposure bracket: 11.0 % of the samples \(in every exposure\)"):
            _, _, info = merge_ml(dn, exposures_s=times, isos=100, profile="illum")
        with pytest.warns(SaturationWarning, match="11.0 %"):
            merge_debevec(dn, exposures_s=times, white_level=1023, black_level=64)
    else:
        _, _, info = merge_ml(dn, exposures_s=times, isos=100, profile="illum")
        merge_debevec(dn, exposures_s=times, white_level=1023, black_level=64)
    assert info["saturated_everywhere_count"] == n_saturated


def _bracket():
    truth = synthesize("layers", size=(24, 24), views=(1, 1), random_state=2).data.astype(np.float64) * 1e4
    flat = truth.reshape(-1, truth.shape[-2] * truth.shape[-1])
    return np.stack([expose(flat, exposure_s=t, iso=100, profile="illum", random_state=k).reshape(truth.shape)
                     for k, t in enumerate(TIMES)])


def test_ml_merge_warns_when_its_fixed_point_has_not_converged():
    dn = _bracket()
    x0, _, _ = merge_ml(dn, exposures_s=TIMES, isos=100, profile="illum", max_iter=0)
    with pytest.warns(ConvergenceWarning, match=r"ML merge: the weights did not converge in 1 fixed-point") as rec:
        x1, v1, info1 = merge_ml(dn, exposures_s=TIMES, isos=100, profile="illum", max_iter=1)
    # the count in the message, recomputed from two runs: samples the one update moved by more
    # than ML_TOLERANCE_STD of their standard deviation
    usable = info1["n_used"] > 0
    moved = int(np.sum(usable & (np.abs(x1 - x0) > ML_TOLERANCE_STD * np.sqrt(v1))))
    assert moved > 0 and f"moved {moved} sample(s)" in str(rec[0].message)
    assert info1["converged"] is False
    # the default two updates converge (no warning: warnings are errors here), and 0 is not iterative
    x2, v2, info2 = merge_ml(dn, exposures_s=TIMES, isos=100, profile="illum")
    assert info2["converged"] is True
    step2 = np.abs(x2 - x1)[usable] / np.sqrt(v2[usable])  # what the second update moved
    assert 0.01 < step2.max() < 0.15  # well inside the tolerance (0.25 sd): 0.025 on this bracket
    assert merge_ml(dn, exposures_s=TIMES, isos=100, profile="illum", max_iter=0)[2]["converged"] is None


# -- Lytro grid -----------------------------------------------------------------------------------

def test_grid_estimate_warns_when_the_frequency_refinement_does_not_converge(monkeypatch):
    import lfproc.lytro.grid as grid
    from lfproc.lytro.virtual import SENSOR_SIZES, expose_chunked, illum_grid, white_irradiance

    truth = illum_grid(SENSOR_SIZES["small"], random_state=0)
    white = expose_chunked(white_irradiance(truth, scale_e_per_s=0.85 * 4500 / 0.008), exposure_s=0.008, iso=100,
                           noise=False, random_state=0)
    grid.estimate_grid(white)  # converges: no warning
    demodulate, calls = grid._demodulate, []

    def drifting(*args, **kwargs):  # a phase ramp that grows at every call: the refinement never settles
        z, gx, gy = demodulate(*args, **kwargs)
        calls.append(1)
        return z * np.exp(2j * np.pi * 2e-4 * len(calls) * gx), gx, gy

    monkeypatch.setattr(grid, "_demodulate", drifting)
    with pytest.warns(ConvergenceWarning, match="lenslet grid: the frequency refinement of 3 of 3 lattice directions "
                                                "did not converge in 6 iterations") as rec:
        grid.estimate_grid(white)
    assert len(rec) == 1  # one warning per estimate, not per direction
