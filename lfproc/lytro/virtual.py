"""A virtual Lytro Illum: render a light field through a hexagonal microlens array.

The forward model (the decoder of :mod:`lfproc.lytro.decode` inverts it):

* **Geometry.** A :class:`~lfproc.lytro.grid.LensletGrid` of micro-image centres (Illum pitch
  14.29 px, rows ``sqrt(3)/2`` of that apart, a small rotation and offset; the spacing grows
  slightly with the zoom step, as the exit pupil moves). Each sensor pixel belongs to its
  nearest lenslet.
* **Sampling.** Lenslet ``(j, i)`` sees the scene at one spatial position: output pixel row
  ``j``, column ``(i + shifted(j) / 2) * spacing_x / spacing_y`` of the decoder's square
  output grid (:func:`output_shape`). A pixel at offset ``d`` (grid frame) from the lenslet
  centre sees the angular position ``d / view_step_px`` (view index offset from the centre
  view); the light field is interpolated linearly between views (and held constant beyond
  the outer views) and with a cubic spline in space.
* **Vignetting.** Each micro image is the image of the main-lens aperture: a disk of radius
  ``aperture_radius_px`` with a soft edge and a mild fall-off, times a radial main-lens
  vignetting over the sensor.
* **Sensor.** Bayer GRBG on the camera-RGB light field (values are camera RGB), then
  :func:`lfproc.camera.sensor.expose` with the ``illum`` profile (black 64, white 1023, 10 bit,
  Poisson and read noise, full well), plus a few hot pixels fixed per camera.
* **White images** are the same optics looking at a uniform white target whose camera
  response is the sensor's ``normalizedResponses`` (R and B about 0.75 of G).

Scale: the decoder divides by the white image (levels normalised, colour neutralised), so
its output for a capture is ``truth * capture_signal / white_signal`` where both signals are
electrons per unit light-field value; :func:`render_capture` returns that factor so the
truth written by ``lfproc virtual-illum`` is exactly what a perfect decoder returns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._shared.deprecate import renamed_keywords
from .._shared.validation import check_positive
from .._shared.random import check_random_state
from .._shared.progress import progress
from ..errors import InputError, ShapeError
from .grid import ILLUM_SPACING_PX, LensletGrid
from .._version import __version__
from ..io import write_lightfield
from ..io._atomic import atomic_dir
from ..lightfield import LightField
from ..sensor import expose, load_profile
from .caldata import geometry_correction_bytes, white_metadata, write_caldata_tar
from .container import illum_metadata, sha1_ref, write_lfr

__all__ = [
    "SENSOR_SIZES",
    "Optics",
    "illum_grid",
    "output_shape",
    "lenslet_spatial_positions",
    "vignetting",
    "render_irradiance",
    "white_irradiance",
    "hot_pixel_list",
    "expose_chunked",
    "NORMALIZED_RESPONSES",
    "VIEW_STEP_DIVISOR",
    "make_virtual_illum",
    "WHITE_STEPS",
]

#: Sensor sizes ``(H, W)``: the real Illum sensor and a central crop for fast tests.
SENSOR_SIZES = {"full": (5368, 7728), "small": (600, 800)}
#: Camera-RGB response of the sensor to the white target (R, G, B), as in real Illum metadata.
NORMALIZED_RESPONSES = (0.7437664270401001, 1.0, 0.7596521377563477)
#: Views are ``spacing_x / VIEW_STEP_DIVISOR`` pixels apart (Dansereau's toolbox: 16 -> 15 x 15 views).
VIEW_STEP_DIVISOR = 16


@dataclass(frozen=True)
class Optics:
    """Optical parameters of the virtual camera besides the lenslet grid.

    Parameters
    ----------
    aperture_radius_frac : float
        Radius of a micro image (the main-lens aperture seen by a lenslet) as a fraction of the
        lenslet spacing.
    edge_width_px : float
        Width of the soft edge of a micro image, pixels.
    microlens_falloff : float
        Relative drop of transmission from a micro-image centre to its edge.
    main_lens_vignetting : float
        Relative drop of transmission from the sensor centre to its corners.
    """

    aperture_radius_frac: float = 0.46
    edge_width_px: float = 1.5
    microlens_falloff: float = 0.2
    main_lens_vignetting: float = 0.3

    def to_dict(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in ("aperture_radius_frac", "edge_width_px", "microlens_falloff",
                                                     "main_lens_vignetting")}


def illum_grid(shape: tuple[int, int], *, zoom_step: int = 0, focus_step: int = 0, random_state=None,
               rotation_rad: float | None = None) -> LensletGrid:
    """A plausible Illum lenslet grid for a sensor of ``shape`` (H, W).

    The seed fixes the microlens array: spacing 14.29 px, rows ``sqrt(3)/2 * 1.0003`` of that
    apart (Lytro's ``scaleFactor.y``), a rotation of 0.4-1.2 mrad of random sign and a
    sub-pixel offset kept away from the lattice-frame boundaries. The micro-image centres
    then spread about the sensor centre by ``1 + 1e-5 * zoom_step + 1e-6 * focus_step`` (the
    exit pupil moves with zoom and focus), so every zoom/focus step has its own grid.
    """
    rng = check_random_state(random_state)
    h, w = (int(v) for v in shape)
    sx0 = ILLUM_SPACING_PX
    sy0 = sx0 * math.sqrt(3) / 2 * 1.0003
    if rotation_rad is None:
        rotation_rad = float(rng.choice([-1, 1]) * rng.uniform(4e-4, 1.2e-3))
    fx = rng.uniform(0.15, 0.35)
    fy = rng.uniform(0.35, 0.65)
    # a lattice point at fraction (fx, fy) of the first cell of the grid frame, whose
    # origin is the top-left corner of the image's bounding box in that frame
    c, s = math.cos(rotation_rad), math.sin(rotation_rad)
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=float)
    qx = (c * corners[:, 0] + s * corners[:, 1]).min() + fx * sx0
    qy = (-s * corners[:, 0] + c * corners[:, 1]).min() + fy * sy0
    k = 1.0 + 1e-5 * zoom_step + 1e-6 * focus_step
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    origin = (cx + k * (c * qx - s * qy - cx), cy + k * (s * qx + c * qy - cy))
    row = (k * sx0 * c, k * sx0 * s)
    return LensletGrid.from_lattice(origin, row, image_size=(h, w), spacing_y_px=k * sy0)


def output_shape(grid: LensletGrid) -> tuple[int, int]:
    """``(rows, cols)`` of the decoder's square spatial output grid for ``grid``.

    One output row per lenslet row; columns ``spacing_y`` pixels apart (square pixels), so
    ``floor((lenslets per row - 1) * spacing_x / spacing_y) + 1`` of them.
    """
    rows, cols = grid.shape
    return rows, int(math.floor((cols - 1) * grid.spacing_x_px / grid.spacing_y_px)) + 1


def lenslet_spatial_positions(grid: LensletGrid) -> tuple[np.ndarray, np.ndarray]:
    """Output-grid coordinates ``(row, col)`` (float, ``(rows, cols)`` arrays) of every lenslet."""
    rows, cols = grid.shape
    j, i = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    k = (i + 0.5 * grid.shifted(j)) * grid.spacing_x_px / grid.spacing_y_px
    return j.astype(np.float64), k


def _microimage(r: np.ndarray, radius: float, optics: Optics) -> np.ndarray:
    edge = np.clip((radius - r) / optics.edge_width_px + 0.5, 0.0, 1.0)
    edge = edge * edge * (3 - 2 * edge)  # smoothstep
    return edge * (1.0 - optics.microlens_falloff * np.minimum(r / radius, 1.0) ** 2)


def vignetting(grid: LensletGrid, *, optics: Optics = Optics(), rows: slice | None = None) -> np.ndarray:
    """Transmission (0..1) of every sensor pixel: micro-image profile times main-lens vignetting.

    ``rows`` selects a band of sensor rows (default: all); returns float32 ``(h, W)``.
    """
    h, w = grid.image_size
    rows = rows or slice(0, h)
    y = np.arange(h, dtype=np.float64)[rows]
    x = np.arange(w, dtype=np.float64)
    xx, yy = np.meshgrid(x, y)
    _, _, dx, dy = grid.nearest(xx, yy)
    radius = optics.aperture_radius_frac * grid.spacing_x_px
    micro = _microimage(np.hypot(dx, dy), radius, optics)
    rho2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2)
    main = 1.0 - optics.main_lens_vignetting * rho2
    return (micro * main).astype(np.float32)


def _cfa_channels(pattern: str, rows: slice, width: int) -> np.ndarray:
    """Channel index (0 R, 1 G, 2 B) of each pixel of a row band for a 2x2 pattern like "GRBG"."""
    idx = {"R": 0, "G": 1, "B": 2}
    tile = np.array([[idx[pattern[0]], idx[pattern[1]]], [idx[pattern[2]], idx[pattern[3]]]])
    y = np.arange(rows.start, rows.stop)
    x = np.arange(width)
    return tile[(y % 2)[:, None], (x % 2)[None, :]]


def _spatial_samples(views: np.ndarray, grid: LensletGrid) -> np.ndarray:
    """The light field at every lenslet's spatial position: ``(V, U, rows, cols, C)`` float32."""
    from scipy import ndimage

    nv, nu, h, w, nc = views.shape
    r, k = lenslet_spatial_positions(grid)
    out = np.empty((nv, nu) + r.shape + (nc,), np.float32)
    coords = np.stack([r, k])
    for v in range(nv):
        for u in range(nu):
            for c in range(nc):
                coef = ndimage.spline_filter(views[v, u, :, :, c].astype(np.float64), order=3, mode="mirror")
                out[v, u, :, :, c] = ndimage.map_coordinates(coef, coords, order=3, mode="mirror", prefilter=False)
    return np.maximum(out, 0.0)


def render_irradiance(views: np.ndarray, grid: LensletGrid, *, scale_e_per_s: float, optics: Optics = Optics(),
                      cfa_pattern: str = "GRBG", view_step_px: float | None = None,
                      chunk_rows: int = 256) -> np.ndarray:
    """Irradiance (electrons/s) on the sensor from a light field on the decoder's output grid.

    Parameters
    ----------
    views : ndarray of shape (V, U, rows, cols, 3)
        Camera-RGB light field on the output grid of ``grid`` (:func:`output_shape`); larger
        arrays are used as far as the grid reaches, smaller ones are extended at the edges.
    grid : LensletGrid
    scale_e_per_s : float
        Electrons per second for a light-field value of 1 at full transmission.
    optics : Optics
    cfa_pattern : str
        Row-major 2x2 Bayer pattern from the top-left pixel.
    view_step_px : float, optional
        Distance between views in pixels (default ``spacing_x / 16``).

    Returns
    -------
    ndarray of shape (H, W), float32
    """
    views = np.asarray(views, dtype=np.float32)
    if views.ndim != 5 or views.shape[-1] != 3:
        raise ShapeError(f"virtual camera: expected a light field (V, U, H, W, 3), got shape {views.shape}")
    check_positive("scale_e_per_s", scale_e_per_s)
    nv, nu = views.shape[:2]
    step = grid.spacing_x_px / VIEW_STEP_DIVISOR if view_step_px is None else check_positive("view_step_px",
                                                                                             view_step_px)
    samples = _spatial_samples(views, grid)  # (V, U, rows, cols, 3)
    rows_n, cols_n = samples.shape[2:4]
    h, w = grid.image_size
    out = np.empty((h, w), np.float32)
    cv, cu = (nv - 1) / 2.0, (nu - 1) / 2.0
    flat = samples.reshape(nv * nu, rows_n * cols_n * 3)
    for r0 in range(0, h, chunk_rows):
        band = slice(r0, min(r0 + chunk_rows, h))
        yy, xx = np.meshgrid(np.arange(band.start, band.stop, dtype=np.float64), np.arange(w, dtype=np.float64),
                             indexing="ij")
        j, i, dx, dy = grid.nearest(xx, yy)
        j = np.clip(j, 0, rows_n - 1)
        i = np.clip(i, 0, cols_n - 1)
        ch = _cfa_channels(cfa_pattern, band, w)
        base = (j * cols_n + i) * 3 + ch
        au = np.clip(dx / step + cu, 0, nu - 1)
        av = np.clip(dy / step + cv, 0, nv - 1)
        u0 = np.minimum(np.floor(au).astype(np.int64), max(nu - 2, 0))
        v0 = np.minimum(np.floor(av).astype(np.int64), max(nv - 2, 0))
        fu, fv = au - u0, av - v0
        u1, v1 = np.minimum(u0 + 1, nu - 1), np.minimum(v0 + 1, nv - 1)
        val = ((1 - fv) * ((1 - fu) * flat[v0 * nu + u0, base] + fu * flat[v0 * nu + u1, base])
               + fv * ((1 - fu) * flat[v1 * nu + u0, base] + fu * flat[v1 * nu + u1, base]))
        vig = vignetting(grid, optics=optics, rows=band)
        out[band] = val * vig * scale_e_per_s
    return out


def white_irradiance(grid: LensletGrid, *, scale_e_per_s: float, optics: Optics = Optics(),
                     cfa_pattern: str = "GRBG", responses=NORMALIZED_RESPONSES, chunk_rows: int = 512) -> np.ndarray:
    """Irradiance (electrons/s) of a white image: vignetting times the white target's camera response."""
    check_positive("scale_e_per_s", scale_e_per_s)
    h, w = grid.image_size
    resp = np.asarray(responses, dtype=np.float32)
    out = np.empty((h, w), np.float32)
    for r0 in range(0, h, chunk_rows):
        band = slice(r0, min(r0 + chunk_rows, h))
        out[band] = vignetting(grid, optics=optics, rows=band) * resp[_cfa_channels(cfa_pattern, band, w)] \
            * scale_e_per_s
    return out


def hot_pixel_list(shape: tuple[int, int], serial: str, *, fraction: float = 2e-5) -> np.ndarray:
    """Hot pixels of a virtual camera: ``(N, 2)`` int ``(x, y)``, fixed by its serial number."""
    h, w = shape
    seed = int.from_bytes(str(serial).encode()[-8:].rjust(8, b"\0"), "little") % (2 ** 32)
    rng = np.random.default_rng(seed)
    n = max(1, int(round(fraction * h * w)))
    flat = rng.choice(h * w, size=n, replace=False)
    return np.stack([flat % w, flat // w], axis=1).astype(np.int64)


def expose_chunked(irradiance_e_per_s: np.ndarray, *, exposure_s: float, iso: float, profile="illum",
                   hot_pixels: np.ndarray | None = None, hot_pixel_dn: float = 500.0, noise: bool = True,
                   random_state=None, chunk_rows: int = 512) -> np.ndarray:
    """:func:`lfproc.camera.sensor.expose` in bands of rows (bounded memory), plus hot pixels.

    Hot pixels add ``hot_pixel_dn`` (clipped at the white level) to the exposed counts.
    Returns uint16 DN ``(H, W)``.
    """
    prof = load_profile(profile)
    rng = check_random_state(random_state)
    e = np.asarray(irradiance_e_per_s)
    if e.ndim != 2:
        raise ShapeError(f"irradiance: expected an (H, W) sensor image, got shape {e.shape}")
    out = np.empty(e.shape, np.uint16)
    for r0 in range(0, e.shape[0], chunk_rows):
        band = slice(r0, min(r0 + chunk_rows, e.shape[0]))
        out[band] = expose(e[band], exposure_s=exposure_s, iso=iso, profile=prof, noise=noise, random_state=rng)
    if hot_pixels is not None and len(hot_pixels):
        hp = np.asarray(hot_pixels)
        vals = out[hp[:, 1], hp[:, 0]].astype(np.float64) + hot_pixel_dn
        out[hp[:, 1], hp[:, 0]] = np.minimum(vals, prof.white_level_dn).astype(np.uint16)
    return out


# -- the whole virtual camera: LFR captures, pairing tar, truth --------------------------

#: Zoom/focus steps of the virtual camera's white images; the captures use the third one.
WHITE_STEPS = ((-300, 300), (0, 300), (0, 800), (300, 800))
CAPTURE_WHITE = 2
#: Colour data of a real Illum capture (illum_desktop_demo.LFP): CCM, white balance, bias.
ILLUM_CCM = (2.244826316833496, -0.9087038040161133, -0.33612245321273804, -0.5600823760032654,
             1.7229819297790527, -0.16289949417114258, -0.5868203043937683, -1.3248286247253418, 2.911648750305176)
ILLUM_WB = {"r": 1.0875036716461182, "gr": 1.0, "gb": 1.0, "b": 1.6269161701202393}
ILLUM_MODULATION_BIAS_EV = 0.2447252869606018


def _fit_views(lf_data: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Crop the views to the aspect of ``shape`` (centred) and resize them to ``shape``."""
    import cv2

    nv, nu, h, w, c = lf_data.shape
    th, tw = shape
    if h * tw > w * th:  # too tall
        ch = max(1, int(round(w * th / tw)))
        top = (h - ch) // 2
        lf_data = lf_data[:, :, top:top + ch]
    else:
        cw = max(1, int(round(h * tw / th)))
        left = (w - cw) // 2
        lf_data = lf_data[:, :, :, left:left + cw]
    h, w = lf_data.shape[2:4]
    interp = cv2.INTER_AREA if (h >= th and w >= tw) else cv2.INTER_CUBIC
    out = np.empty((nv, nu, th, tw, c), np.float32)
    for v in range(nv):
        for u in range(nu):
            out[v, u] = cv2.resize(np.ascontiguousarray(lf_data[v, u]), (tw, th), interpolation=interp).reshape(
                th, tw, c)
    return np.maximum(out, 0.0)


@dataclass(frozen=True)
class _Camera:
    """What every frame of one virtual Illum shares: sensor size, ISO, serial, hot pixels, white balance
    responses, optics, the white images' exposure and scale, and the noise generator."""
    shape: tuple[int, int]
    iso: float
    serial: str
    hot: Any
    nr: dict
    optics: Optics
    white_exposure_s: float
    white_scale: float
    rng: Any


def _write_calibration(tmp, cam: _Camera, grids) -> tuple[str, bytes, list[dict]]:
    """The camera's calibration data in ``tmp``: a white image at every :data:`WHITE_STEPS` plus a dark frame,
    in ``caldata-<serial>.tar``. Returns the tar's name, the capture white's geometry correction and the white
    images' records."""
    from types import SimpleNamespace

    shape, iso, hot = cam.shape, cam.iso, cam.hot
    frames = []
    white_info = []
    for k, ((z, f), g) in enumerate(progress(list(zip(WHITE_STEPS, grids)), desc="virtual Illum: white images")):
        irr = white_irradiance(g, scale_e_per_s=cam.white_scale, optics=cam.optics)
        raw = expose_chunked(irr, exposure_s=cam.white_exposure_s, iso=iso, hot_pixels=hot, random_state=cam.rng)
        del irr
        meta = white_metadata(height=shape[0], width=shape[1], zoom_step=z, focus_step=f,
                              exposure_s=cam.white_exposure_s, iso=iso, mla_rotation_rad=g.rotation_rad,
                              extra={"devices": {"sensor": {"normalizedResponses": [cam.nr]}}})
        name = f"MOD_{k:04d}"
        frames.append(SimpleNamespace(raw=raw, metadata=meta, name=name, is_dark=False))
        white_info.append({"name": name, "zoom_step": z, "focus_step": f, "grid": g.to_dict(),
                           "geometry_hash": sha1_ref(geometry_correction_bytes(meta, name))})
    dark_meta = white_metadata(height=shape[0], width=shape[1], zoom_step=0, focus_step=0,
                               exposure_s=cam.white_exposure_s, iso=iso,
                               mla_rotation_rad=grids[CAPTURE_WHITE].rotation_rad)
    dark = expose_chunked(np.zeros(shape, np.float32), exposure_s=cam.white_exposure_s, iso=iso, hot_pixels=hot,
                          random_state=cam.rng)
    frames.append(SimpleNamespace(raw=dark, metadata=dark_meta, name=f"MOD_{len(WHITE_STEPS):04d}",
                                  is_dark=True))
    tar_name = f"caldata-{cam.serial}.tar"
    write_caldata_tar(tmp / tar_name, frames, serial=cam.serial, hot_pixels=hot)
    cap_white = frames[CAPTURE_WHITE]
    return tar_name, geometry_correction_bytes(cap_white.metadata, cap_white.name), white_info


def _write_captures(tmp, cam: _Camera, views, cap_grid, evs, *, scale: float, base_exposure_s: float,
                    gct: bytes, white_level: float) -> list[dict]:
    """One ``IMG_000n.LFR`` per exposure offset in ``evs`` (EV) in ``tmp``; returns their records."""
    irr0 = render_irradiance(views, cap_grid, scale_e_per_s=scale, optics=cam.optics)
    captures = []
    z, f = WHITE_STEPS[CAPTURE_WHITE]
    for n, ev in enumerate(progress(evs, desc="virtual Illum: captures")):
        t = base_exposure_s * 2.0 ** ev
        raw = expose_chunked(irr0, exposure_s=t, iso=cam.iso, hot_pixels=cam.hot, random_state=cam.rng)
        meta = illum_metadata(height=cam.shape[0], width=cam.shape[1], zoom_step=z, focus_step=f, exposure_s=t,
                              iso=cam.iso, modulation_exposure_bias_ev=ILLUM_MODULATION_BIAS_EV,
                              white_balance=ILLUM_WB, ccm=ILLUM_CCM, mla_rotation_rad=cap_grid.rotation_rad,
                              extra={"devices": {"sensor": {"normalizedResponses": [cam.nr]}},
                                     "settings": {"exposure": {"compensation": ev}}})
        fname = f"IMG_{n + 1:04d}.LFR"
        write_lfr(tmp / fname, raw=raw, metadata=meta, serial=cam.serial, geometry_correction=gct,
                  hot_pixels=cam.hot)
        captures.append({"file": fname, "exposure_ev": ev, "exposure_s": t, "iso": cam.iso,
                         "saturated_fraction": float((raw >= white_level).mean()),
                         "truth_factor": scale * t / (cam.white_scale * cam.white_exposure_s)})
        del raw
    return captures


def _check_virtual_inputs(lf, sensor, exposures_ev, random_state, base_exposure_s) -> list[float]:
    """Validate :func:`make_virtual_illum`'s arguments; returns the exposure offsets (EV)."""
    if not isinstance(lf, LightField):
        raise InputError(f"virtual camera: expected a LightField, got {type(lf).__name__}")
    if lf.channels != 3:
        raise ShapeError(f"virtual camera: expected an RGB light field (3 channels), got {lf.channels}")
    if sensor not in SENSOR_SIZES:
        raise InputError(f"sensor: expected one of {', '.join(SENSOR_SIZES)}; got {sensor!r}")
    evs = [float(e) for e in exposures_ev]
    if not evs or not all(math.isfinite(e) and abs(e) <= 10 for e in evs):
        raise InputError(f"exposures-ev: expected one or more values within +-10 EV, got {exposures_ev}")
    if not isinstance(random_state, (int, np.integer)) or random_state < 0:
        raise InputError(f"random_state: expected a non-negative integer, got {random_state!r}")
    check_positive("base_exposure_s", base_exposure_s)
    return evs


@renamed_keywords(seed="random_state")
def make_virtual_illum(lf, out_dir, *, sensor: str = "small", exposures_ev=(-2, -1, 0, 1, 2), random_state: int = 0,
                       base_exposure_s: float = 0.01, iso: float = 100, force: bool = False) -> dict[str, Any]:
    """Render a light field with the virtual Illum into ``out_dir``.

    Writes ``IMG_0001.LFR``... (one per exposure), ``caldata-<serial>.tar`` (white images at
    :data:`WHITE_STEPS` plus a dark frame, hot-pixel list), ``truth.exr`` (the central 5x5
    views a perfect decoder returns for the 0 EV capture, or the first one) and
    ``truth.json`` (grids, exposures and scale factors, seed, lfproc version).

    Parameters
    ----------
    lf : LightField
        RGB light field (any number of views; odd counts put a view at the centre); its
        values are taken as camera RGB.
    out_dir : path
        Output folder (written atomically; see ``force``).
    sensor : {"full", "small"}
        7728 x 5368 (the real sensor) or a 800 x 600 crop.
    exposures_ev : sequence of float
        Exposure offsets in EV from ``base_exposure_s``.
    random_state : int
        Fixes the camera (serial, grid, hot pixels) and the noise (recorded as ``"seed"``; the
        keyword ``seed`` is deprecated).
    base_exposure_s, iso : float
        Exposure of the 0 EV capture and the ISO of all captures.
    force : bool
        Replace an existing ``out_dir``.

    Returns
    -------
    dict : the content of ``truth.json``.
    """
    import json

    evs = _check_virtual_inputs(lf, sensor, exposures_ev, random_state, base_exposure_s)
    seed = random_state
    profile = load_profile("illum")
    iso_figs = profile.iso_figures(iso)  # validates the ISO
    full_well = float(profile.full_well_e)
    shape = SENSOR_SIZES[sensor]
    rng = np.random.default_rng(seed)
    serial = f"B51{int(rng.integers(10 ** 7, 10 ** 8)):08d}"
    grid_seed = int(rng.integers(2 ** 31))
    white_exposure_s = 0.008
    cam = _Camera(shape=shape, iso=iso, serial=serial, hot=hot_pixel_list(shape, serial),
                  nr={"r": NORMALIZED_RESPONSES[0], "gr": 1.0, "gb": 1.0, "b": NORMALIZED_RESPONSES[2], "cct": 5100},
                  optics=Optics(), white_exposure_s=white_exposure_s,
                  white_scale=0.85 * full_well / white_exposure_s, rng=rng)

    grids = [illum_grid(shape, zoom_step=z, focus_step=f, random_state=grid_seed) for z, f in WHITE_STEPS]
    cap_grid = grids[CAPTURE_WHITE]
    out_rows, out_cols = output_shape(cap_grid)
    views = _fit_views(lf.data, (out_rows, out_cols))
    p_hi = float(np.percentile(views, 99.5)) or 1.0
    scale = 0.7 * full_well / (base_exposure_s * p_hi)

    with atomic_dir(out_dir, force=force) as tmp:
        tar_name, gct, white_info = _write_calibration(tmp, cam, grids)
        captures = _write_captures(tmp, cam, views, cap_grid, evs, scale=scale, base_exposure_s=base_exposure_s,
                                   gct=gct, white_level=profile.white_level_dn)
        ref = min(range(len(evs)), key=lambda i: abs(evs[i]))
        nv, nu = views.shape[:2]
        n_keep = min(5, nv, nu)
        v0, u0 = (nv - n_keep) // 2, (nu - n_keep) // 2
        truth_views = views[v0:v0 + n_keep, u0:u0 + n_keep] * np.float32(captures[ref]["truth_factor"])
        info = {
            "generator": "lfproc virtual-illum", "lfproc_version": __version__, "seed": int(seed), "sensor": sensor,
            "sensor_size": list(shape), "serial": serial, "caldata": tar_name, "captures": captures,
            "truth_capture": captures[ref]["file"], "truth_views": n_keep,
            "grid": cap_grid.to_dict(), "white_images": white_info, "capture_white": white_info[CAPTURE_WHITE]["name"],
            "optics": cam.optics.to_dict(), "view_step_px": cap_grid.spacing_x_px / VIEW_STEP_DIVISOR,
            "irradiance_scale_e_per_s": scale, "white_scale_e_per_s": cam.white_scale,
            "white_exposure_s": white_exposure_s, "hot_pixels": int(len(cam.hot)), "source": lf.source,
            "gain_dn_per_e": iso_figs.gain_dn_per_e,
        }
        truth = LightField(data=truth_views, units="relative", colour_space="camera-rgb",
                           exposure_s=captures[ref]["exposure_s"], iso=iso, source=f"virtual-illum:{lf.source}",
                           attrs={"virtual_illum": info})
        write_lightfield(truth, tmp / "truth.exr")
        (tmp / "truth.json").write_text(json.dumps(info, indent=2))
    return info
