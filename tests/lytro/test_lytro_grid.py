"""Hexagonal lenslet grid: model geometry and estimation from synthetic white images."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfproc.errors import CalibrationError, InputError, ShapeError
from lfproc.lytro.grid import F01_SPACING_PX, ILLUM_SPACING_PX, LensletGrid, estimate_grid
from lfproc.lytro.virtual import SENSOR_SIZES, expose_chunked, illum_grid, white_irradiance


def _white(grid: LensletGrid, *, seed: int, noise: bool = True) -> np.ndarray:
    irr = white_irradiance(grid, scale_e_per_s=0.85 * 4500 / 0.008)
    return expose_chunked(irr, exposure_s=0.008, iso=100, noise=noise, random_state=seed)


@pytest.mark.parametrize("seed, rotation", [(0, None), (1, None), (2, 1.1e-3), (3, -1.1e-3), (4, 0.0), (5, 0.02)])
def test_estimate_grid_recovers_known_grid(seed, rotation):
    truth = illum_grid(SENSOR_SIZES["small"], random_state=seed, rotation_rad=rotation, zoom_step=100 * seed)
    est = estimate_grid(_white(truth, seed=seed))
    assert abs(est.spacing_x_px - truth.spacing_x_px) < 0.01
    assert abs(est.spacing_y_px - truth.spacing_y_px) < 0.01
    assert abs(est.rotation_rad - truth.rotation_rad) < 1e-4
    assert truth.position_error_px(est) < 0.05
    # same origin lenslet and row parity: the lattices index the lenslets alike
    assert est.shape == truth.shape
    assert est.shift_parity == truth.shift_parity
    assert math.hypot(est.offset_x_px - truth.offset_x_px, est.offset_y_px - truth.offset_y_px) < 0.05


def test_estimate_grid_other_pitch_without_hint():
    # an F01-like pitch, found without an approximate spacing
    row = (F01_SPACING_PX * math.cos(-2e-3), F01_SPACING_PX * math.sin(-2e-3))
    truth = LensletGrid.from_lattice((5.3, 4.1), row, image_size=(400, 480), spacing_y_px=F01_SPACING_PX * math.sqrt(3) / 2)
    est = estimate_grid(_white(truth, seed=7), approx_spacing_px=None)
    assert abs(est.spacing_x_px - truth.spacing_x_px) < 0.01
    assert abs(est.rotation_rad - truth.rotation_rad) < 1e-4
    assert truth.position_error_px(est) < 0.05


def test_grid_geometry_round_trips():
    g = illum_grid((600, 800), random_state=3)
    c = g.centres()
    assert c.shape == g.shape + (2,)
    # neighbours along a row are spacing_x apart; rows spacing_y apart (in the grid frame)
    assert np.allclose(np.hypot(*(c[:, 1] - c[:, 0]).T), g.spacing_x_px)
    xp, yp = g.pixel_to_frame(c[..., 0], c[..., 1])
    assert np.allclose(np.diff(yp, axis=0), g.spacing_y_px)
    x, y = g.frame_to_pixel(xp, yp)
    assert np.allclose(x, c[..., 0]) and np.allclose(y, c[..., 1])
    # shifted rows sit half a spacing right of unshifted ones
    sh = g.shifted(np.arange(2))
    assert np.isclose(abs(xp[1, 0] - xp[0, 0]), 0.5 * g.spacing_x_px)
    assert sh.sum() == 1
    # nearest: lenslet centres map to themselves, with zero offset
    j, i, dx, dy = g.nearest(c[..., 0] + 0.3, c[..., 1] - 0.2)
    jj, ii = np.meshgrid(np.arange(g.shape[0]), np.arange(g.shape[1]), indexing="ij")
    assert (j == jj).all() and (i == ii).all()
    assert np.allclose(dx, 0.3 * math.cos(g.rotation_rad) - 0.2 * math.sin(g.rotation_rad))
    # dict round trip
    assert LensletGrid.from_dict(g.to_dict()) == g
    # every centre of an on-sensor lenslet lies inside the image
    inside = g.inside()
    assert inside.mean() > 0.9
    assert (c[inside][:, 0] >= 0).all() and (c[inside][:, 1] <= 599).all()


def test_grid_model_validation():
    good = illum_grid((600, 800), random_state=0).to_dict()
    with pytest.raises(InputError, match="missing field.*rotation_rad"):
        LensletGrid.from_dict({k: v for k, v in good.items() if k != "rotation_rad"})
    with pytest.raises(InputError, match="spacing_x_px: expected a finite spacing"):
        LensletGrid.from_dict(good | {"spacing_x_px": float("nan")})
    with pytest.raises(InputError, match="shift_parity: expected 0 or 1"):
        LensletGrid.from_dict(good | {"shift_parity": 2})
    with pytest.raises(InputError, match="expected a hexagonal grid"):
        LensletGrid.from_dict(good | {"kind": "square"})


def test_estimate_grid_bad_input():
    with pytest.raises(ShapeError, match="expected a 2-D"):
        estimate_grid(np.zeros((4, 200, 200)))
    with pytest.raises(CalibrationError, match="too small"):
        estimate_grid(np.random.default_rng(0).random((60, 60)))
    with pytest.raises(CalibrationError, match="flat"):
        estimate_grid(np.full((300, 300), 500.0))
    bad = np.ones((300, 300))
    bad[5, 5] = np.nan
    with pytest.raises(ShapeError, match="NaN or Inf"):
        estimate_grid(bad)
    # a square (not hexagonal) lattice of spots is refused
    yy, xx = np.mgrid[0:400, 0:400]
    square = np.cos(2 * np.pi * xx / ILLUM_SPACING_PX) + np.cos(2 * np.pi * yy / ILLUM_SPACING_PX) + 3
    with pytest.raises(CalibrationError, match="hexagonal"):
        estimate_grid(square)
