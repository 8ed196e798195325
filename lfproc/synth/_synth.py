"""Synthetic HDR light fields with exact ground truth.

A scene is a stack of fronto-parallel layers (back to front). Each layer is a raster of
linear RGB radiance with an alpha (coverage) map, drawn in the coordinates of the centre
view, and one disparity. The continuous scene is the bilinear interpolant of these rasters,
so every view is an *exact* sample of it: view ``(v, u)`` shows layer ``k`` translated by
``(dv * d_k, du * d_k)`` pixels (rows, columns), with ``(dv, du) = (v - cv, u - cu)`` the
offset of the view from the centre view ``(cv, cu) = (V // 2, U // 2)``. Layers are then
composited back to front with their (translated) alpha, so occlusion is exact.

Sign convention (the one of :class:`lfproc.LightField`): a surface of disparity ``d > 0``
moves **right** by ``d`` pixels per step of the angular column ``u`` and **down** by ``d``
pixels per step of the angular row ``v``: the centre-view pixel ``(y, x)`` of that surface
is seen at ``(y + dv * d, x + du * d)`` in view ``(v, u)``. Front layers have positive
disparity, back layers negative; the zero-disparity plane is in the middle of the scene.

Ground truth:

* ``LightField.data``: the radiance of every view (units ``"relative"``, linear sRGB).
* ``LightField.disparity``: for each centre-view pixel, the disparity of the front-most
  layer whose alpha there is at least 0.5 (pixels per view step).
* ``attrs["layer_disparities_px"]``: the disparity of every layer, back to front.

Specular highlights are view dependent: a highlight is the virtual image of an emitter in
a glossy object, so it moves with its own disparity (``Layer.specular_disparity_px``),
masked by the object that carries it. Pixels of a highlight therefore do not follow the
ground-truth disparity of their surface (as in a real scene); :func:`scene_layers` gives
the layers, hence where the highlights are.

Textures are procedural (hashed value noise at several scales down to one pixel, stripes,
checkers; a function of absolute centre-view coordinates, so the centre view does not
depend on the number of views or the baseline) or taken from image files
(``textures=[path, ...]``, read with :func:`lfproc.io.read_image`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._shared.random import check_random_state
from .._shared.frozen import freeze
from .._version import __version__
from ..errors import InputError, MissingFileError, ShapeError
from ..lightfield import REC709_LUMA, LightField, luminance
from .. import _untrusted as ut
from ..io import read_image

__all__ = ["synthesize", "scene_layers", "render_layers", "Layer", "SCENES", "scene_names", "check_scene"]


@dataclass(frozen=True, eq=False)
class Layer:
    """One fronto-parallel layer of a synthetic scene.

    Parameters
    ----------
    radiance : ndarray of shape (H + 2m, W + 2m, 3), float32
        Linear radiance in centre-view coordinates with a margin of ``m`` pixels on each
        side (raster pixel ``(i, j)`` is centre-view pixel ``(i - m, j - m)``).
    alpha : ndarray of shape (H + 2m, W + 2m), float32 in [0, 1]
        Coverage of the layer.
    disparity_px : float
        Disparity of the layer in pixels per view step (see the module documentation).
    specular : ndarray of shape (H + 2m, W + 2m, 3), optional
        Additive view-dependent radiance (a highlight), visible only where the layer is.
    specular_disparity_px : float
        Disparity of the highlight (its virtual image).
    name : str
        What the layer is (for reports).
    """

    radiance: np.ndarray
    alpha: np.ndarray
    disparity_px: float
    specular: np.ndarray | None = None
    specular_disparity_px: float = 0.0
    name: str = ""


# -- procedural textures -------------------------------------------------------------------

_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xC2B2AE3D27D4EB4F)
_M3 = np.uint64(0xBF58476D1CE4E5B9)
_M4 = np.uint64(0x94D049BB133111EB)
_OFFSET = 1 << 24  # keeps lattice indices positive before the cast to uint64


def _hash_uniform(iy: np.ndarray, ix: np.ndarray, key: int) -> np.ndarray:
    """Uniform values in [0, 1) from integer lattice coordinates (splitmix64 finaliser)."""
    z = (iy + _OFFSET).astype(np.uint64) * _M1 + (ix + _OFFSET).astype(np.uint64) * _M2 + np.uint64(key)
    z = (z ^ (z >> np.uint64(30))) * _M3
    z = (z ^ (z >> np.uint64(27))) * _M4
    z = z ^ (z >> np.uint64(31))
    return ((z >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))).astype(np.float32)


def _value_noise(yy: np.ndarray, xx: np.ndarray, cell_px: float, key: int) -> np.ndarray:
    """Value noise in [-1, 1] with lattice spacing ``cell_px`` (smoothstep interpolation)."""
    if cell_px <= 1.0:
        return 2 * _hash_uniform(yy.astype(np.int64), xx.astype(np.int64), key) - 1
    gy, gx = yy / cell_px, xx / cell_px
    y0, x0 = np.floor(gy), np.floor(gx)
    ty, tx = gy - y0, gx - x0
    ty, tx = ty * ty * (3 - 2 * ty), tx * tx * (3 - 2 * tx)
    y0, x0 = y0.astype(np.int64), x0.astype(np.int64)
    v00 = _hash_uniform(y0, x0, key)
    v01 = _hash_uniform(y0, x0 + 1, key)
    v10 = _hash_uniform(y0 + 1, x0, key)
    v11 = _hash_uniform(y0 + 1, x0 + 1, key)
    top = v00 + (v01 - v00) * tx
    bottom = v10 + (v11 - v10) * tx
    return (2 * (top + (bottom - top) * ty) - 1).astype(np.float32)


def _fractal_noise(yy, xx, key: int, *, largest_px: float) -> np.ndarray:
    """Sum of value noise from ``largest_px`` down to single pixels; roughly in [-1, 1]."""
    cells, weights = [], []
    cell, weight = float(largest_px), 1.0
    while cell > 1.5:
        cells.append(cell)
        weights.append(weight)
        cell, weight = cell / 3.0, weight * 0.7
    cells.append(1.0)  # pixel-level detail
    weights.append(weight)
    total = np.zeros(yy.shape, np.float32)
    for i, (c, w) in enumerate(zip(cells, weights)):
        total += np.float32(w) * _value_noise(yy, xx, c, key + 7919 * (i + 1))
    return total / np.float32(0.6 * math.sqrt(sum(w * w for w in weights)))


def _smooth_box(yy, xx, top, left, bottom, right) -> np.ndarray:
    """Anti-aliased coverage (1-pixel ramp) of the rectangle [top, bottom) x [left, right)."""
    cy = np.clip(np.minimum(yy + 0.5 - top, bottom - (yy - 0.5)), 0, 1)
    cx = np.clip(np.minimum(xx + 0.5 - left, right - (xx - 0.5)), 0, 1)
    return (cy * cx).astype(np.float32)


def _smooth_disc(yy, xx, cy, cx, ry, rx=None) -> np.ndarray:
    """Anti-aliased coverage of an ellipse (semi-axes ry, rx)."""
    rx = ry if rx is None else rx
    r = np.sqrt(((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2)
    return np.clip((1 - r) * min(ry, rx) + 0.5, 0, 1).astype(np.float32)


def _colour(rgb) -> np.ndarray:
    """An RGB colour scaled to unit luminance."""
    c = np.asarray(rgb, np.float64)
    return (c / float(c @ REC709_LUMA)).astype(np.float32)


# -- scene context ---------------------------------------------------------------------------

class _Context:
    """What a scene builder needs: grid, sizes, baseline, randomness and textures."""

    def __init__(self, size, margin, baseline_px, rng, textures):
        self.h, self.w = size
        self.s = min(size)
        self.m = margin
        self.b = baseline_px
        self.rng = rng
        coords = np.arange(-margin, self.h + margin, dtype=np.float32), np.arange(-margin, self.w + margin,
                                                                                     dtype=np.float32)
        self.yy, self.xx = np.meshgrid(*coords, indexing="ij")
        self._textures = list(textures)
        self._next_texture = 0
        # every random draw of a scene happens in a fixed order and number, whatever the size
        self.keys = [int(k) for k in rng.integers(0, 2**62, size=16)]

    def uniform(self, low, high):
        return float(self.rng.uniform(low, high))

    def surface(self, key_index: int, *, level: float, colour, contrast_stops: float, pattern: str = "noise",
                period_px: float = 6.0, use_file: bool = True) -> np.ndarray:
        """Radiance raster of a textured surface with median luminance near ``level``."""
        colour = _colour(colour)
        if use_file and self._textures:
            tex = self._textures[self._next_texture % len(self._textures)]
            self._next_texture += 1
            return (self._place_texture(tex) * np.float32(level) * colour / colour.mean()).astype(np.float32)
        key = self.keys[key_index]
        noise = _fractal_noise(self.yy, self.xx, key, largest_px=max(self.s / 4, 4))
        if pattern == "stripes":
            angle = (key % 1000) / 1000 * math.pi
            t = self.xx * math.cos(angle) + self.yy * math.sin(angle)
            base = np.tanh(3 * np.sin(2 * math.pi * t / period_px))
            n = 0.6 * base + 0.4 * noise
        elif pattern == "checker":
            c = max(2, int(round(period_px)))
            base = ((np.floor(self.yy / c) + np.floor(self.xx / c)) % 2) * 2 - 1
            n = 0.6 * base + 0.4 * noise
        else:
            n = noise
        mod = np.exp2(np.float32(contrast_stops / 2) * np.clip(n, -2, 2))
        return (mod[..., None] * np.float32(level) * colour).astype(np.float32)

    def _place_texture(self, tex: np.ndarray) -> np.ndarray:
        """Resize a texture to cover the centre view (aspect kept), mirror it into the margin,
        and scale it to median luminance 1."""
        import cv2

        th, tw = tex.shape[:2]
        scale = max(self.h / th, self.w / tw)
        nh, nw = max(self.h, int(math.ceil(th * scale))), max(self.w, int(math.ceil(tw * scale)))
        interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
        resized = cv2.resize(tex, (nw, nh), interpolation=interp)
        if resized.ndim == 2:
            resized = resized[..., None]
        top, left = (nh - self.h) // 2, (nw - self.w) // 2
        crop = resized[top:top + self.h, left:left + self.w]
        crop = np.repeat(crop, 3, axis=2) if crop.shape[2] == 1 else crop[..., :3]
        crop = np.maximum(crop, 0)
        lum = luminance(crop)
        positive = lum[lum > 0]
        median = float(np.median(positive)) if positive.size else 0.0
        if median <= 0:
            raise InputError("texture: the image has no positive pixels; expected a picture with some light in it")
        floor = median * 2.0**-12  # keep every sample positive (log-luminance statistics stay finite)
        crop = np.maximum(crop, floor) / np.float32(median)
        m = self.m
        return np.pad(crop, ((m, m), (m, m), (0, 0)), mode="symmetric").astype(np.float32)

    def layer(self, radiance, alpha, depth, *, name, specular=None, specular_depth=0.0) -> Layer:
        return Layer(radiance=radiance, alpha=np.asarray(alpha, np.float32), disparity_px=depth * self.b,
                     specular=specular, specular_disparity_px=specular_depth * self.b, name=name)

    def full(self) -> np.ndarray:
        return np.ones(self.yy.shape, np.float32)

    def highlight(self, cy, cx, radius, peak, colour) -> np.ndarray:
        """A Gaussian highlight (zero beyond 4 sigma, so its support is exact)."""
        r2 = ((self.yy - cy) ** 2 + (self.xx - cx) ** 2) / (radius * radius)
        spot = np.where(r2 < 16, np.exp(-0.5 * r2), 0).astype(np.float32)
        return (spot[..., None] * np.float32(peak) * _colour(colour)).astype(np.float32)


# Depths below are fractions of the baseline in multiples of 1/4, so that a baseline of 4
# pixels gives integer disparities (tests use this for exact, interpolation-free checks).

def _scene_layers(ctx: _Context) -> list[Layer]:
    """Daylight: sky with the sun, far hills, a building with a dark doorway, objects, a glossy ball."""
    h, w, s, yy, xx = ctx.h, ctx.w, ctx.s, ctx.yy, ctx.xx
    horizon = ctx.uniform(0.35, 0.5) * h
    sun_y, sun_x = ctx.uniform(0.08, 0.2) * h, ctx.uniform(0.15, 0.85) * w
    sky = ctx.surface(0, level=2.0**4, colour=(0.55, 0.75, 1.0), contrast_stops=1.0, use_file=False)
    sky *= np.exp2(-1.5 * np.clip(yy / h, 0, 1))[..., None]  # brighter towards the zenith
    sun_r = max(1.5, 0.035 * s)
    sun = _smooth_disc(yy, xx, sun_y, sun_x, sun_r)
    sky = sky * (1 - sun[..., None]) + sun[..., None] * np.float32(2.0**14) * _colour((1.0, 0.95, 0.85))
    layers = [ctx.layer(sky, ctx.full(), -1.0, name="sky and sun")]

    ridge = horizon + 0.06 * h * _value_noise(yy * 0 + 0, xx, max(4.0, w / 6), ctx.keys[1])
    hills = np.clip(yy - ridge + 0.5, 0, 1)
    hills_rad = ctx.surface(2, level=2.0**1, colour=(0.45, 0.6, 0.3), contrast_stops=3.0)
    layers.append(ctx.layer(hills_rad, hills, -0.5, name="hills"))

    bx0, bx1 = ctx.uniform(0.05, 0.3) * w, ctx.uniform(0.55, 0.75) * w
    by0 = ctx.uniform(0.25, 0.4) * h
    building = _smooth_box(yy, xx, by0, bx0, 1.2 * h, bx1)
    wall = ctx.surface(3, level=2.0**0, colour=(0.9, 0.8, 0.7), contrast_stops=2.0, pattern="stripes",
                       period_px=ctx.uniform(4, 9))
    door = _smooth_box(yy, xx, by0 + 0.35 * (h - by0), bx0 + 0.2 * (bx1 - bx0), 1.2 * h, bx0 + 0.5 * (bx1 - bx0))
    shadow = ctx.surface(4, level=2.0**-9, colour=(0.6, 0.7, 1.0), contrast_stops=2.0, use_file=False)
    wall = wall * (1 - door[..., None]) + shadow * door[..., None]
    layers.append(ctx.layer(wall, building, 0.0, name="building with doorway"))

    cy, cx = ctx.uniform(0.6, 0.75) * h, ctx.uniform(0.6, 0.85) * w
    crate = _smooth_box(yy, xx, cy - 0.12 * s, cx - 0.12 * s, cy + 0.12 * s, cx + 0.12 * s)
    crate_rad = ctx.surface(5, level=2.0**-1, colour=(0.8, 0.5, 0.3), contrast_stops=3.0, pattern="checker",
                            period_px=ctx.uniform(3, 7))
    layers.append(ctx.layer(crate_rad, crate, 0.5, name="checkered crate"))

    by, bxc, br = ctx.uniform(0.55, 0.7) * h, ctx.uniform(0.15, 0.4) * w, 0.11 * s
    ball = _smooth_disc(yy, xx, by, bxc, br)
    nz = np.sqrt(np.clip(1 - ((yy - by) ** 2 + (xx - bxc) ** 2) / br**2, 0, 1))
    light = np.array([-0.5, 0.3, 0.81])  # towards the sun: up, right, towards the camera
    shade = np.clip(light[0] * (yy - by) / br + light[1] * (xx - bxc) / br + light[2] * nz, 0, 1)
    ball_rad = ctx.surface(6, level=2.0**-1, colour=(0.9, 0.2, 0.15), contrast_stops=1.0, use_file=False)
    ball_rad = ball_rad * (0.1 + 0.9 * shade)[..., None].astype(np.float32)
    spec = ctx.highlight(by - 0.35 * br, bxc + 0.25 * br, max(0.8, 0.08 * br), 2.0**12, (1.0, 0.95, 0.85))
    layers.append(ctx.layer(ball_rad, ball, 0.75, name="glossy ball", specular=spec, specular_depth=0.5))

    # foreground: dark foliage in the shade along the bottom-left, the deepest shadows of the scene
    edge = 0.82 * h + 0.08 * h * _value_noise(yy * 0, xx, max(3.0, w / 10), ctx.keys[7])
    fg = np.clip(yy - edge + 0.5, 0, 1) * np.clip((0.55 * w - xx) / 4 + 0.5, 0, 1)
    fg_rad = ctx.surface(8, level=2.0**-8, colour=(0.3, 0.5, 0.25), contrast_stops=3.0)
    layers.append(ctx.layer(fg_rad, fg.astype(np.float32), 1.0, name="foliage in shade"))
    return layers


def _scene_lamps(ctx: _Context) -> list[Layer]:
    """Night: dark sky with moon and stars, a facade with lit windows, street lamps, a glossy car, a fence."""
    h, w, s, yy, xx = ctx.h, ctx.w, ctx.s, ctx.yy, ctx.xx
    sky = ctx.surface(0, level=2.0**-10, colour=(0.3, 0.35, 0.6), contrast_stops=1.5, use_file=False)
    stars = (_hash_uniform(yy.astype(np.int64), xx.astype(np.int64), ctx.keys[1]) > 0.997).astype(np.float32)
    sky = sky + stars[..., None] * np.float32(2.0**2)
    moon = _smooth_disc(yy, xx, ctx.uniform(0.08, 0.18) * h, ctx.uniform(0.6, 0.9) * w, max(1.5, 0.04 * s))
    sky = sky * (1 - moon[..., None]) + moon[..., None] * np.float32(2.0**5) * _colour((1.0, 1.0, 0.95))
    layers = [ctx.layer(sky, ctx.full(), -1.0, name="night sky, moon and stars")]

    roof = ctx.uniform(0.25, 0.4) * h
    facade = _smooth_box(yy, xx, roof, 0.05 * w, 1.2 * h, 0.7 * w)
    facade_rad = ctx.surface(2, level=2.0**-9, colour=(0.7, 0.6, 0.5), contrast_stops=3.0)
    pitch_y, pitch_x = max(4.0, 0.1 * h), max(4.0, 0.1 * w)
    fy, fx = (yy - roof) / pitch_y, (xx - 0.05 * w) / pitch_x
    in_cell = ((fy % 1) > 0.3) & ((fy % 1) < 0.8) & ((fx % 1) > 0.25) & ((fx % 1) < 0.75)
    lit = _hash_uniform(np.floor(fy).astype(np.int64), np.floor(fx).astype(np.int64), ctx.keys[3]) < 0.45
    win = (in_cell & lit & (yy > roof + 1)).astype(np.float32)
    window_rad = ctx.surface(4, level=2.0**2, colour=(1.0, 0.8, 0.5), contrast_stops=1.0, use_file=False)
    facade_rad = facade_rad * (1 - win[..., None]) + window_rad * win[..., None]
    layers.append(ctx.layer(facade_rad, facade, -0.5, name="facade with lit windows"))

    lamps_alpha = np.zeros(yy.shape, np.float32)
    lamps_rad = np.zeros(yy.shape + (3,), np.float32)
    post_rad = ctx.surface(5, level=2.0**-8, colour=(0.5, 0.5, 0.5), contrast_stops=1.0, use_file=False)
    head_colour = _colour((1.0, 0.65, 0.3))
    for i in range(3):
        lx = (0.2 + 0.3 * i + ctx.uniform(-0.06, 0.06)) * w
        ly = ctx.uniform(0.3, 0.45) * h
        post = _smooth_box(yy, xx, ly, lx - max(0.8, 0.012 * w), 1.2 * h, lx + max(0.8, 0.012 * w))
        head = _smooth_disc(yy, xx, ly, lx, max(1.5, 0.035 * s))
        lamps_rad = lamps_rad * (1 - post[..., None]) + post_rad * post[..., None]
        lamps_rad = lamps_rad * (1 - head[..., None]) + head[..., None] * np.float32(2.0**11) * head_colour
        lamps_alpha = np.maximum(np.maximum(lamps_alpha, post), head)
    layers.append(ctx.layer(lamps_rad, lamps_alpha, 0.0, name="street lamps"))

    cy, cx = ctx.uniform(0.72, 0.8) * h, ctx.uniform(0.35, 0.65) * w
    car = _smooth_disc(yy, xx, cy, cx, 0.12 * s, 0.25 * s) * (yy < cy + 0.08 * s)
    car_rad = ctx.surface(6, level=2.0**-6, colour=(0.2, 0.3, 0.8), contrast_stops=2.0, pattern="stripes",
                          period_px=ctx.uniform(3, 6))
    spec = ctx.highlight(cy - 0.06 * s, cx + ctx.uniform(-0.1, 0.1) * s, max(0.8, 0.012 * s), 2.0**9,
                         (1.0, 0.7, 0.4))
    layers.append(ctx.layer(car_rad, car.astype(np.float32), 0.5, name="glossy car", specular=spec,
                            specular_depth=0.25))

    # foreground fence: thin vertical bars with a high spatial frequency
    period = max(4.0, 0.05 * w)
    phase = ctx.uniform(0, period)
    bar = np.clip(np.minimum((xx - phase) % period, period - (xx - phase) % period) - 0.2 * period + 0.5, 0, 1)
    rail = _smooth_box(yy, xx, 0.8 * h, -ctx.m - 1, 0.84 * h, w + ctx.m + 1)
    fence = np.maximum((1 - bar) * (yy > 0.72 * h), rail).astype(np.float32)
    fence_rad = ctx.surface(8, level=2.0**-8, colour=(0.6, 0.55, 0.5), contrast_stops=2.0)
    layers.append(ctx.layer(fence_rad, fence, 1.0, name="fence"))
    return layers


def _scene_window(ctx: _Context) -> list[Layer]:
    """Interior: dim room, a bright window with sky and sun, mullions, a table, a glossy vase, a plant."""
    h, w, s, yy, xx = ctx.h, ctx.w, ctx.s, ctx.yy, ctx.xx
    outside = ctx.surface(0, level=2.0**8, colour=(0.6, 0.75, 1.0), contrast_stops=2.0, use_file=False)
    land = np.clip(yy - ctx.uniform(0.4, 0.5) * h + 0.5, 0, 1)[..., None]
    ground = ctx.surface(1, level=2.0**6, colour=(0.5, 0.6, 0.35), contrast_stops=3.0)
    outside = outside * (1 - land) + ground * land
    wy0, wx0 = ctx.uniform(0.12, 0.2) * h, ctx.uniform(0.2, 0.4) * w
    wy1, wx1 = wy0 + 0.45 * h, wx0 + 0.4 * w
    sun = _smooth_disc(yy, xx, wy0 + 0.2 * (wy1 - wy0), wx0 + ctx.uniform(0.3, 0.7) * (wx1 - wx0),
                       max(1.5, 0.03 * s))
    outside = outside * (1 - sun[..., None]) + sun[..., None] * np.float32(2.0**14) * _colour((1.0, 0.95, 0.85))
    layers = [ctx.layer(outside, ctx.full(), -1.0, name="outside: sky, sun, landscape")]

    opening = _smooth_box(yy, xx, wy0, wx0, wy1, wx1)
    wall = ctx.surface(2, level=2.0**-5, colour=(0.9, 0.85, 0.7), contrast_stops=2.0, pattern="stripes",
                       period_px=ctx.uniform(4, 8))
    dist = np.hypot((yy - (wy0 + wy1) / 2) / h, (xx - (wx0 + wx1) / 2) / w)
    wall = wall * np.exp2(-6 * dist)[..., None].astype(np.float32)  # darker away from the window
    layers.append(ctx.layer(wall, 1 - opening, -0.5, name="wall with window opening"))

    t = max(1.0, 0.015 * s)
    my, mx = (wy0 + wy1) / 2, (wx0 + wx1) / 2
    mullions = np.maximum(_smooth_box(yy, xx, wy0, mx - t, wy1, mx + t), _smooth_box(yy, xx, my - t, wx0, my + t, wx1))
    frame_rad = ctx.surface(3, level=2.0**-4, colour=(0.9, 0.9, 0.9), contrast_stops=1.0, use_file=False)
    layers.append(ctx.layer(frame_rad, mullions, -0.25, name="window mullions"))

    ty = ctx.uniform(0.65, 0.72) * h
    table = _smooth_box(yy, xx, ty, 0.1 * w, 1.2 * h, 0.9 * w)
    table_rad = ctx.surface(4, level=2.0**-3, colour=(0.7, 0.45, 0.25), contrast_stops=3.0, pattern="stripes",
                            period_px=ctx.uniform(3, 6))
    table_rad = table_rad * np.exp2(-4 * np.clip((yy - ty) / h, 0, 1))[..., None].astype(np.float32)
    layers.append(ctx.layer(table_rad, table, 0.25, name="table"))

    vy, vx, vr = ty - 0.12 * s, ctx.uniform(0.45, 0.75) * w, 0.08 * s
    vase = _smooth_disc(yy, xx, vy, vx, 0.14 * s, vr)
    vase_rad = ctx.surface(5, level=2.0**-4, colour=(0.3, 0.5, 0.8), contrast_stops=2.0, pattern="checker",
                           period_px=ctx.uniform(2, 5))
    spec = ctx.highlight(vy - 0.05 * s, vx - 0.3 * vr, max(0.8, 0.1 * vr), 2.0**10, (0.95, 0.97, 1.0))
    layers.append(ctx.layer(vase_rad, vase, 0.5, name="glossy vase", specular=spec, specular_depth=0.25))

    leaves = np.zeros(yy.shape, np.float32)
    for i in range(5):
        ly, lx = ctx.uniform(0.55, 0.95) * h, ctx.uniform(0.0, 0.22) * w
        leaves = np.maximum(leaves, _smooth_disc(yy, xx, ly, lx, 0.05 * s, 0.11 * s))
    plant_rad = ctx.surface(6, level=2.0**-9, colour=(0.25, 0.5, 0.2), contrast_stops=3.0)
    layers.append(ctx.layer(plant_rad, leaves, 1.0, name="plant in shade"))
    return layers


def _scene_checker(ctx: _Context) -> list[Layer]:
    """Test chart: checkerboards at five depths, each a few stops brighter, and a lamp in front."""
    h, w, s, yy, xx = ctx.h, ctx.w, ctx.s, ctx.yy, ctx.xx
    layers = []
    specs = [  # (depth, level, cell px, half size as a fraction of the frame)
        (-1.0, 2.0**-8, 8, None),
        (-0.5, 2.0**-3, 6, 0.36),
        (0.0, 2.0**1, 5, 0.26),
        (0.5, 2.0**5, 4, 0.16),
    ]
    for i, (depth, level, cell, half) in enumerate(specs):
        rad = ctx.surface(i, level=level, colour=(1.0, 0.9 - 0.1 * i, 0.6 + 0.1 * i), contrast_stops=5.0,
                          pattern="checker", period_px=max(2, round(cell * s / 128)))
        if half is None:
            alpha = ctx.full()
        else:
            cy, cx = ctx.uniform(0.4, 0.6) * h, ctx.uniform(0.4, 0.6) * w
            alpha = _smooth_box(yy, xx, cy - half * s, cx - half * s, cy + half * s, cx + half * s)
        layers.append(ctx.layer(rad, alpha, depth, name=f"checkerboard {i}"))
    lamp = _smooth_disc(yy, xx, ctx.uniform(0.15, 0.3) * h, ctx.uniform(0.15, 0.85) * w, max(1.5, 0.04 * s))
    lamp_rad = np.broadcast_to(np.float32(2.0**12) * _colour((1.0, 0.9, 0.7)), yy.shape + (3,)).astype(np.float32)
    layers.append(ctx.layer(lamp_rad, lamp, 1.0, name="lamp"))
    return layers


#: Scene kinds: name -> (builder, one-line description).
SCENES: dict[str, tuple[Callable[[_Context], list[Layer]], str]] = {
    "layers": (_scene_layers, "daylight: sky with the sun, hills, a building with a dark doorway, a checkered "
                              "crate, a glossy ball, foliage in deep shade"),
    "lamps": (_scene_lamps, "night: dark sky with moon and stars, a facade with lit windows, three street lamps, "
                            "a glossy car, a fence in front"),
    "window": (_scene_window, "interior: dim room, a bright window with sky and sun behind mullions, a table, a "
                              "glossy vase, a plant in shade"),
    "checker": (_scene_checker, "test chart: checkerboards at five depths, 4-5 stops apart, and a lamp in front"),
}


def scene_names() -> list[str]:
    """Names of the scene kinds :func:`synthesize` knows."""
    return list(SCENES)


# -- validation ---------------------------------------------------------------------------------

def _check_views(views) -> tuple[int, int]:
    try:
        pair = (views, views) if isinstance(views, (int, np.integer)) else tuple(views)
    except TypeError:
        pair = ()
    if len(pair) != 2 or not all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in pair):
        raise InputError(f"views: expected an odd integer >= 1 or a pair of them, got {views!r}")
    if not all(n >= 1 and n % 2 == 1 for n in pair):
        raise InputError(f"views: expected odd numbers >= 1 (so there is a centre view), got {views!r}")
    return int(pair[0]), int(pair[1])


def _check_size(size) -> tuple[int, int]:
    try:
        h, w = size
        ok = all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in (h, w))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"size: expected two integers (H, W), got {size!r}")
    if h < 16 or w < 16:
        raise InputError(f"size: expected H and W of at least 16 pixels, got {h} x {w}")
    if h * w > 2**26:
        raise InputError(f"size: expected at most 2**26 pixels per view, got {h} x {w}")
    return int(h), int(w)


def _check_baseline(baseline_px) -> float:
    try:
        b = float(baseline_px)
    except (TypeError, ValueError):
        raise InputError(f"baseline: expected a number of pixels per view step, got {baseline_px!r}") from None
    if not (math.isfinite(b) and b >= 0):
        raise InputError(f"baseline: expected a finite number >= 0 (pixels per view step), got {baseline_px!r}")
    return b


def _load_textures(textures) -> tuple[list[np.ndarray], list[str]]:
    if textures is None:
        return [], []
    if isinstance(textures, (str, os.PathLike, np.ndarray)):
        textures = [textures]
    arrays, names = [], []
    for i, tex in enumerate(textures):
        if isinstance(tex, np.ndarray):
            arr = np.asarray(tex, dtype=np.float32)
            if arr.ndim == 2:
                arr = arr[..., None]
            if arr.ndim != 3 or arr.shape[2] not in (1, 3, 4) or min(arr.shape[:2]) < 2:
                raise ShapeError(f"texture {i}: expected an image of shape (H, W[, 1|3|4]), got {tex.shape}")
            if not np.isfinite(arr).all():
                raise InputError(f"texture {i}: contains NaN or Inf values")
            arrays.append(arr[..., :3])
            names.append(f"array {i}")
            continue
        path = Path(tex)
        if not path.exists():
            raise MissingFileError(f"texture {path}: no such file")
        image, _ = read_image(path, nonfinite="zero", negative="clip")
        arrays.append(image)
        names.append(path.name)
    return arrays, names


# -- rendering ----------------------------------------------------------------------------------

def _margin(views: tuple[int, int], baseline_px: float) -> int:
    """Raster margin covering the largest translation (plus one pixel for bilinear support)."""
    reach = max(views[0] // 2, views[1] // 2) * baseline_px
    return int(math.ceil(reach)) + 2


def _translate(raster: np.ndarray, oy: float, ox: float, h: int, w: int) -> np.ndarray:
    """``out[y, x] = raster(y + oy, x + ox)`` for a constant offset, bilinear (exact at integer offsets)."""
    iy, ix = math.floor(oy), math.floor(ox)
    fy, fx = oy - iy, ox - ix
    out = raster[iy:iy + h, ix:ix + w] * np.float32((1 - fy) * (1 - fx))
    if fx:
        out += raster[iy:iy + h, ix + 1:ix + 1 + w] * np.float32((1 - fy) * fx)
    if fy:
        out += raster[iy + 1:iy + 1 + h, ix:ix + w] * np.float32(fy * (1 - fx))
    if fx and fy:
        out += raster[iy + 1:iy + 1 + h, ix + 1:ix + 1 + w] * np.float32(fy * fx)
    return out


def render_layers(layers: Sequence[Layer], *, size: tuple[int, int], views: int | tuple[int, int] = 5
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Render layers (back to front) into every view.

    Parameters
    ----------
    layers : sequence of Layer
        Back to front, rasters with a common margin ``m`` (``H + 2m`` by ``W + 2m``).
    size : (H, W)
        Size of a view in pixels.
    views : int or (V, U)
        Odd numbers of angular rows and columns.

    Returns
    -------
    data : ndarray of shape (V, U, H, W, 3), float32
        Radiance of every view: view ``(v, u)`` samples each layer at
        ``(y - dv * d, x - du * d)``, then composites it over the layers behind.
    disparity : ndarray of shape (H, W), float32
        Disparity of the front-most layer with alpha >= 0.5 at each centre-view pixel.
    """
    h, w = _check_size(size)
    nv, nu = _check_views(views)
    if not layers:
        raise InputError("layers: expected at least one layer")
    hr, wr = layers[0].alpha.shape
    m = (hr - h) // 2
    if hr != h + 2 * m or wr != w + 2 * m or m < 0:
        raise ShapeError(f"layers: rasters of shape {hr} x {wr} do not fit views of {h} x {w} with an even margin")
    reach = max(nv // 2, nu // 2) * max(max(abs(L.disparity_px), abs(L.specular_disparity_px)) for L in layers)
    if reach + 1 > m:
        raise ShapeError(f"layers: margin of {m} pixels is too small for translations up to {reach:.3g} pixels")
    premult = []
    for L in layers:
        if L.alpha.shape != (hr, wr) or L.radiance.shape != (hr, wr, 3):
            raise ShapeError(f"layer {L.name!r}: expected radiance ({hr}, {wr}, 3) and alpha ({hr}, {wr})")
        premult.append(np.concatenate([L.radiance * L.alpha[..., None], L.alpha[..., None]], axis=2))
    cv, cu = nv // 2, nu // 2
    data = np.empty((nv, nu, h, w, 3), np.float32)
    for v in range(nv):
        for u in range(nu):
            dv, du = v - cv, u - cu
            out = np.zeros((h, w, 3), np.float32)
            for L, p in zip(layers, premult):
                q = _translate(p, m - dv * L.disparity_px, m - du * L.disparity_px, h, w)
                a = q[..., 3:]
                out *= 1 - a
                out += q[..., :3]
                if L.specular is not None:
                    out += _translate(L.specular, m - dv * L.specular_disparity_px,
                                      m - du * L.specular_disparity_px, h, w) * a
            np.maximum(out, 0, out=out)  # rounding can leave -1e-8 where alpha is 1
            data[v, u] = out
    disparity = np.zeros((h, w), np.float32)
    for L in layers:
        disparity[L.alpha[m:m + h, m:m + w] >= 0.5] = L.disparity_px
    return data, disparity


def scene_layers(scene: str = "layers", *, size: tuple[int, int] = (256, 256), views: int | tuple[int, int] = 5,
                 baseline_px: float = 1.0, textures: Sequence[Any] | None = None, random_state=None) -> list[Layer]:
    """The layers of a synthetic scene, back to front (what :func:`synthesize` renders).

    Parameters
    ----------
    scene : {"layers", "lamps", "window", "checker"}
        Scene kind.
    size : (H, W)
        Size of each view in pixels (each at least 16).
    views : int or (V, U)
        Odd number of angular rows and columns; with ``baseline_px`` it sets the layers'
        margin.
    baseline_px : float
        Largest absolute disparity, pixels per view step (>= 0).
    textures : sequence of paths or arrays, optional
        Images used instead of procedural textures (see :func:`synthesize`).
    random_state : None, int or numpy Generator
        Seed of the layout and textures (the same as :func:`synthesize`'s gives its layers).

    Returns
    -------
    list of Layer
        Back to front; each with its radiance and alpha rasters (centre-view coordinates plus
        a margin), disparity, optional highlight and name.

    Raises
    ------
    InputError
        Unknown scene, bad size, views or baseline.

    Examples
    --------
    >>> from lfproc.synth import scene_layers
    >>> layers = scene_layers("layers", size=(32, 32), random_state=0)
    >>> [layer.disparity_px for layer in layers]
    [-1.0, -0.5, 0.0, 0.5, 0.75, 1.0]
    >>> layers[0].radiance.shape, layers[0].alpha.shape        # 32 + 2 * 4 margin pixels
    ((40, 40, 3), (40, 40))
    """
    builder = _builder(scene)
    h, w = _check_size(size)
    nviews = _check_views(views)
    b = _check_baseline(baseline_px)
    arrays, _ = _load_textures(textures)
    ctx = _Context((h, w), _margin(nviews, b), b, check_random_state(random_state), arrays)
    return builder(ctx)


def check_scene(scene: str) -> str:
    """Validate a scene name; the error lists the valid ones.

    Parameters
    ----------
    scene : str
        A scene name.

    Returns
    -------
    str
        ``scene``, when it is one of :data:`SCENES`.

    Raises
    ------
    InputError
        Any other name.

    Examples
    --------
    >>> from lfproc.synth import check_scene
    >>> check_scene("lamps")
    'lamps'
    >>> check_scene("sunset")
    Traceback (most recent call last):
    ...
    lfproc.errors.InputError: scene: expected one of layers, lamps, window, checker; got 'sunset'
    """
    if scene not in SCENES:
        raise InputError(f"scene: expected one of {', '.join(SCENES)}; got {scene!r}")
    return scene


def _builder(scene: str):
    return SCENES[check_scene(scene)][0]


def synthesize(scene: str = "layers", *, size: tuple[int, int] = (256, 256), views: int | tuple[int, int] = 5,
               baseline_px: float = 1.0, textures: Sequence[Any] | None = None, random_state=None) -> LightField:
    """A synthetic HDR light field with exact ground truth.

    Parameters
    ----------
    scene : {"layers", "lamps", "window", "checker"}
        Scene kind (see :data:`SCENES`).
    size : (H, W)
        Size of each view in pixels (each at least 16).
    views : int or (V, U)
        Odd number of angular rows and columns (5 gives 5 x 5 views).
    baseline_px : float
        Largest absolute disparity in the scene, in pixels per view step (>= 0). Layers
        have disparities ``baseline_px`` times fixed fractions in [-1, 1] (multiples of
        1/4): front layers positive, back layers negative. 0 gives identical views.
    textures : sequence of paths or arrays, optional
        Images (read with :func:`lfproc.io.read_image`) used instead of procedural
        textures on the scene's textured surfaces, in turn; each is resized to cover the
        view (aspect kept, centre crop) and scaled to the surface's median luminance.
    random_state : None, int or numpy Generator
        Seed of the scene layout and textures; the same seed gives the same light field.
        The centre view does not depend on ``views`` or ``baseline_px``.

    Returns
    -------
    LightField
        ``data`` of shape (V, U, H, W, 3), units ``"relative"``, colour space
        ``"linear-srgb"``, ``disparity`` of the centre view (pixels per view step;
        positive: a point moves right as ``u`` increases and down as ``v`` increases),
        ``source="synth:<scene>"`` and ``attrs`` with the scene, seed, baseline, size,
        views, layer disparities and lfproc version.

    Raises
    ------
    InputError
        Unknown scene, bad size, views or baseline; unusable texture.
    MissingFileError
        A texture file does not exist.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.synth import synthesize
    >>> lf = synthesize("lamps", size=(64, 64), views=3, random_state=0)
    >>> lf.shape, lf.units, lf.source
    ((3, 3, 64, 64, 3), 'relative', 'synth:lamps')
    >>> bool(lf.dynamic_range_stops() > 16)
    True
    >>> lf5 = synthesize("layers", size=(32, 32), views=5, random_state=0)
    >>> lf5.attrs["layer_disparities_px"], lf5.disparity.shape
    ([-1.0, -0.5, 0.0, 0.5, 0.75, 1.0], (32, 32))
    >>> lf3 = synthesize("layers", size=(32, 32), views=3, random_state=0)
    >>> bool(np.array_equal(lf3.centre(), lf5.centre()))    # the centre view does not depend on the views
    True
    """
    _builder(scene)
    h, w = _check_size(size)
    nviews = _check_views(views)
    b = _check_baseline(baseline_px)

    ut.check_nbytes((*nviews, h, w, 3), np.float32, error=InputError,
                    what=f"size x views: a light field of {nviews[0]} x {nviews[1]} views of {h} x {w} pixels")
    arrays, names = _load_textures(textures)
    ctx = _Context((h, w), _margin(nviews, b), b, check_random_state(random_state), arrays)
    layers = SCENES[scene][0](ctx)
    data, disparity = render_layers(layers, size=(h, w), views=nviews)
    seed = int(random_state) if isinstance(random_state, (int, np.integer)) else None
    attrs = {
        "synth_scene": scene,
        "synth_seed": seed,
        "synth_baseline_px": b,
        "synth_size": [h, w],
        "synth_views": list(nviews),
        "synth_textures": names,
        "layer_names": [L.name for L in layers],
        "layer_disparities_px": [L.disparity_px for L in layers],
        "disparity_convention": "pixels per view step; view (v,u) shows centre pixel (y,x) of a surface of "
                                "disparity d at (y + (v-cv)*d, x + (u-cu)*d)",
        "lfproc_version": __version__,
    }
    return LightField(data=freeze(data), disparity=freeze(disparity), units="relative", colour_space="linear-srgb",
                      source=f"synth:{scene}", attrs=attrs)
