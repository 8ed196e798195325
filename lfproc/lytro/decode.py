"""Decode a Lytro lenslet image into sub-aperture views.

Pipeline of :func:`decode_lenslet`, each step vectorised over the whole sensor:

1. **Levels**: ``(raw - black) / (white - black)`` for the capture and the white image.
2. **Hot pixels**: a pixel brighter than 1.25 times all eight same-colour neighbours
   (plus a margin), or listed by the caller, is replaced by the mean of its four axial
   same-colour neighbours; done on the capture and on the white image.
3. **Devignetting**: the white image's R and B pixels are divided by the white target's
   camera response (``devices.sensor.normalizedResponses``), so dividing by the white image
   removes the vignetting but keeps camera RGB.
4. **Demosaicing** of the devignetted mosaic (OpenCV's edge-aware demosaicing by default,
   Malvar-He-Cutler 2004 from ``colour_demosaicing`` on request).
5. **Slicing**: view ``(v, u)`` of lenslet ``(j, i)`` is the demosaiced image at the lenslet
   centre plus ``((u - c) * step, (v - c) * step)`` in the grid frame, ``step = spacing_x / 16``
   (bilinear).
6. **Hexagonal to square resampling**: every lenslet row is resampled along the row with a
   cubic B-spline (interpolating, prefiltered) onto columns ``spacing_y`` pixels apart, so
   spatial pixels are square; shifted and unshifted rows get the same interpolator, which keeps
   the alternating-row ("hex") artefacts of linear row interpolation away.
7. **Confidence**: the devignetted samples get a variance from the sensor noise model
   (Poisson + read noise + quantisation, divided by the white image squared); samples that
   are saturated (or next to saturated pixels), off the sensor or under a dark part of the
   white image get :data:`UNUSABLE_VARIANCE`.
8. **Unusable samples** get values interpolated from the usable samples of their view
   (OpenCV's Navier-Stokes inpainting, per view and colour; :func:`fill_unusable`), except
   those lying wholly on saturated pixels, which keep their saturation level (a lower bound:
   a clipped highlight stays bright). All keep :data:`UNUSABLE_VARIANCE`, so merges ignore
   them, but a viewer or a metric sees a plausible value instead of a hole. (The raw values
   of the others are no estimate: a sample beside a clipped highlight reads the highlight's
   saturation level through the pixels and views it shares with it.)

The output is linear camera RGB scaled so that 1.0 is as bright as the white image (the
decoder divides by it); ``colour="srgb"`` applies white balance, the colour matrix and the
exposure bias (still linear, Rec. 709 primaries).
"""

from __future__ import annotations

import math
import os
from typing import Any, Literal
from dataclasses import dataclass

import numpy as np

from .._shared.deprecate import resolve_options
from .._shared.validation import check_choice
from .._shared.frozen import freeze
from .._version import __version__
from ..errors import InputError, LfprocError, option_name, ShapeError
from ..lightfield import LightField
from .grid import LensletGrid
from .virtual import VIEW_STEP_DIVISOR, output_shape
from ..sensor import load_profile
from .capture import read_capture
from .whites import load_white_db, read_white_file, select_white

__all__ = [
    "decode_lenslet",
    "correct_hot_pixels",
    "demosaic",
    "hex_to_square",
    "apply_colour",
    "fill_unusable",
    "decode_capture",
    "UNUSABLE_VARIANCE",
    "DEMOSAIC_METHODS",
]

#: Variance given to samples that carry no information (saturated, off the sensor, dark).
UNUSABLE_VARIANCE = 1.0e6
DEMOSAIC_METHODS = ("opencv-ea", "malvar2004", "bilinear")
_CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")


def _check_pattern(pattern: str) -> str:
    return check_choice("cfa_pattern", str(pattern).upper(), _CFA_PATTERNS)


def _channel_map(pattern: str, shape: tuple[int, int]) -> np.ndarray:
    idx = {"R": 0, "G": 1, "B": 2}
    tile = np.array([[idx[pattern[0]], idx[pattern[1]]], [idx[pattern[2]], idx[pattern[3]]]], dtype=np.int8)
    h, w = shape
    return np.tile(tile, ((h + 1) // 2, (w + 1) // 2))[:h, :w]


def correct_hot_pixels(mosaic: np.ndarray, *, ratio: float = 1.25, margin: float = 0.1,
                       extra: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Replace isolated bright pixels of a Bayer mosaic.

    Parameters
    ----------
    mosaic : ndarray of shape (H, W), float32
        Level-normalised mosaic (0 black, 1 white level).
    ratio, margin : float
        A pixel is hot when ``value > ratio * max(same-colour neighbours) + margin``.
    extra : ndarray of shape (N, 2), optional
        Further hot pixels ``(x, y)`` (e.g. from ``HOTPIXEL.BIN``).

    Returns
    -------
    (corrected copy, number of pixels replaced)
    """
    import cv2

    m = np.ascontiguousarray(mosaic, dtype=np.float32)
    ring = np.zeros((5, 5), np.uint8)
    ring[::2, ::2] = 1
    ring[2, 2] = 0
    nb_max = cv2.dilate(m, ring, borderType=cv2.BORDER_REFLECT_101)
    hot = m > ratio * nb_max + margin
    if extra is not None and len(extra):
        e = np.asarray(extra, dtype=np.int64)
        ok = (e[:, 0] >= 0) & (e[:, 0] < m.shape[1]) & (e[:, 1] >= 0) & (e[:, 1] < m.shape[0])
        hot[e[ok, 1], e[ok, 0]] = True
    n = int(hot.sum())
    if not n:
        return m, 0
    cross = np.zeros((5, 5), np.float32)
    cross[0, 2] = cross[4, 2] = cross[2, 0] = cross[2, 4] = 0.25
    mean4 = cv2.filter2D(m, -1, cross, borderType=cv2.BORDER_REFLECT_101)
    out = m.copy()
    out[hot] = mean4[hot]
    return out, n


def demosaic(mosaic: np.ndarray, *, cfa_pattern: str = "GRBG", method: str = "opencv-ea") -> np.ndarray:
    """Demosaic a float mosaic ``(H, W)`` into linear RGB ``(H, W, 3)`` float32.

    ``method``: ``"opencv-ea"`` (OpenCV's edge-aware demosaicing, fast), ``"malvar2004"``
    (Malvar-He-Cutler gradient-corrected linear, ``colour_demosaicing``) or ``"bilinear"``
    (OpenCV). Values may exceed 1 (devignetted data); negatives are clipped to 0.
    """
    import cv2

    pattern = _check_pattern(cfa_pattern)
    check_choice("demosaic method", method, DEMOSAIC_METHODS)
    m = np.asarray(mosaic, dtype=np.float32)
    if m.ndim != 2:
        raise ShapeError(f"demosaic: expected an (H, W) mosaic, got shape {m.shape}")
    if method == "malvar2004":
        import warnings

        with warnings.catch_warnings():  # colour_demosaicing imports a deprecated scipy namespace
            warnings.simplefilter("ignore", DeprecationWarning)
            import colour_demosaicing

            rgb = colour_demosaicing.demosaicing_CFA_Bayer_Malvar2004(m, pattern).astype(np.float32)
        return np.maximum(rgb, 0.0, out=rgb)
    # OpenCV names the pattern by the 2x2 block starting at pixel (1, 1)
    code_name = pattern[3] + pattern[2]
    suffix = "_EA" if method == "opencv-ea" else ""
    code = getattr(cv2, f"COLOR_Bayer{code_name}2RGB{suffix}")
    scale = 8192.0  # 16-bit codes: values up to 8 with 1.2e-4 resolution
    q = np.clip(m * scale + 0.5, 0, 65535).astype(np.uint16)
    rgb = cv2.demosaicing(q, code).astype(np.float32)
    rgb *= 1.0 / scale
    return rgb


def _bspline_matrix(positions: np.ndarray, n: int):
    """Sparse ``(len(positions), n)`` matrix evaluating a cubic B-spline with coefficients on 0..n-1."""
    from scipy import sparse

    pos = np.clip(positions, 0, n - 1)
    i0 = np.floor(pos).astype(np.int64)
    t = pos - i0
    w = np.stack([(1 - t) ** 3 / 6, (3 * t ** 3 - 6 * t ** 2 + 4) / 6, (-3 * t ** 3 + 3 * t ** 2 + 3 * t + 1) / 6,
                  t ** 3 / 6], axis=1)
    cols = np.clip(i0[:, None] + np.arange(-1, 3)[None, :], 0, n - 1)
    rows = np.repeat(np.arange(len(pos)), 4)
    return sparse.csr_matrix((w.ravel(), (rows, cols.ravel())), shape=(len(pos), n))


def hex_to_square(samples: np.ndarray, grid: LensletGrid, *, method: Literal["spline", "linear"] = "spline"
                  ) -> np.ndarray:
    """Resample lenslet rows onto the square output grid.

    Parameters
    ----------
    samples : ndarray of shape (..., rows, cols, C)
        Values at the lenslets of ``grid`` (lattice order).
    grid : LensletGrid
    method : {"spline", "linear"}
        Cubic B-spline (interpolating) or linear interpolation along each row.

    Returns
    -------
    ndarray of shape (..., rows, out_cols, C), float32 (:func:`lfproc.lytro.virtual.output_shape`).
    """
    from scipy import ndimage, sparse

    check_choice("hex resampling method", method, ("spline", "linear"))
    s = np.asarray(samples, dtype=np.float32)
    rows, cols = s.shape[-3], s.shape[-2]
    out_rows, out_cols = output_shape(grid)
    if (rows, cols) != grid.shape:
        raise ShapeError(f"hex_to_square: samples have {rows} x {cols} lenslets, the grid has {grid.shape}")
    if method == "spline":
        coef = ndimage.spline_filter1d(s, order=3, axis=-2, mode="mirror", output=np.float32)
    else:
        coef = s
    k = np.arange(out_cols, dtype=np.float64) * grid.spacing_y_px / grid.spacing_x_px
    lead = s.shape[:-3]
    out = np.empty(lead + (out_rows, out_cols, s.shape[-1]), np.float32)
    for parity in (0, 1):
        rsel = np.nonzero(grid.shifted(np.arange(rows)) == parity)[0]
        if not len(rsel):
            continue
        pos = k - 0.5 * parity
        if method == "spline":
            mat = _bspline_matrix(pos, cols)
        else:
            p = np.clip(pos, 0, cols - 1)
            i0 = np.minimum(np.floor(p).astype(np.int64), cols - 2)
            t = p - i0
            mat = sparse.csr_matrix((np.concatenate([1 - t, t]),
                                     (np.tile(np.arange(out_cols), 2), np.concatenate([i0, i0 + 1]))),
                                    shape=(out_cols, cols))
        block = coef[..., rsel, :, :]                               # (..., r, cols, C)
        moved = np.moveaxis(block, -2, 0).reshape(cols, -1)         # (cols, ...*r*C)
        res = (mat @ moved).astype(np.float32).reshape((out_cols,) + lead + (len(rsel), s.shape[-1]))
        out[..., rsel, :, :] = np.moveaxis(res, 0, -2)
    return out


def _sample_views(image: np.ndarray, grid: LensletGrid, n_views: int, step: float) -> np.ndarray:
    """Bilinear samples of ``image`` (H, W[, C]) for each view at each lenslet: (n, n, rows, cols[, C])."""
    import cv2

    centres = grid.centres().astype(np.float64)
    c, s = math.cos(grid.rotation_rad), math.sin(grid.rotation_rad)
    half = n_views // 2
    out = None
    for v in range(n_views):
        for u in range(n_views):
            du, dv = (u - half) * step, (v - half) * step
            mx = (centres[..., 0] + c * du - s * dv).astype(np.float32)
            my = (centres[..., 1] + s * du + c * dv).astype(np.float32)
            res = cv2.remap(image, mx, my, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=0)
            if out is None:
                out = np.empty((n_views, n_views) + res.shape, np.float32)
            out[v, u] = res
    return out


def fill_unusable(data: np.ndarray, unusable: np.ndarray, *, keep: np.ndarray | None = None,
                  radius_px: float = 2.0) -> np.ndarray:
    """Values for the samples a decode could not measure, from the usable samples of each view.

    Parameters
    ----------
    data : ndarray of shape (V, U, H, W, C), float32
    unusable : ndarray of shape (V, U, H, W), bool
    keep : ndarray of shape (V, U, H, W), bool, optional
        Unusable samples that keep their own value (the decoder's: samples lying wholly on
        saturated pixels, whose value is the saturation level, a lower bound). They are not
        used to inpaint the others, so a clipped highlight does not bleed into its surround.
    radius_px : float
        Neighbourhood of OpenCV's Navier-Stokes inpainting (``cv2.INPAINT_NS``).

    Returns
    -------
    A new array; a view without any usable sample is all zero (except ``keep``).
    """
    import cv2

    data = np.asarray(data, dtype=np.float32)
    bad = np.asarray(unusable, dtype=bool)
    if bad.shape != data.shape[:4]:
        raise ShapeError(f"fill_unusable: mask {bad.shape} does not match the samples {data.shape[:4]}")
    out = data.copy()
    for v in range(data.shape[0]):
        for u in range(data.shape[1]):
            m = bad[v, u]
            if not m.any():
                continue
            if m.all():
                out[v, u] = 0.0
                continue
            mask = m.astype(np.uint8)
            for c in range(data.shape[4]):
                out[v, u, ..., c] = cv2.inpaint(np.ascontiguousarray(data[v, u, ..., c]), mask, radius_px,
                                                cv2.INPAINT_NS)
    if keep is not None:
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != bad.shape:
            raise ShapeError(f"fill_unusable: keep mask {keep.shape} does not match the samples {bad.shape}")
        out[keep] = data[keep]
    return np.maximum(out, 0.0, out=out)


@dataclass(frozen=True)
class LensletSensor:
    """The sensor figures :func:`decode_lenslet` needs: levels, CFA, the white target's response, known
    hot pixels and the noise figures at the capture's ISO (see its parameters).

    Parameters
    ----------
    black_level, white_level, cfa_pattern, white_responses, hot_pixels, gain_dn_per_e, read_noise_dn
        The keywords of :func:`decode_lenslet` of the same names (``black_level`` and
        ``white_level`` required, the others with the same defaults).
    """
    black_level: float
    white_level: float
    cfa_pattern: str = "GRBG"
    white_responses: Any = (1.0, 1.0, 1.0)
    hot_pixels: np.ndarray | None = None
    gain_dn_per_e: float | None = None
    read_noise_dn: float = 0.0


def decode_lenslet(raw: np.ndarray, white: np.ndarray, grid: LensletGrid, sensor: LensletSensor | None = None, *,
                   n_views: int = 5, demosaic_method: str = "opencv-ea",
                   hex_method: Literal["spline", "linear"] = "spline", white_threshold: float = 0.05,
                   fill: bool = True, **sensor_fields) -> dict[str, Any]:
    """Decode a raw lenslet image with its white image and lenslet grid.

    Parameters
    ----------
    raw, white : ndarray of shape (H, W)
        Raw counts (DN, black level included) of the capture and of its white image.
    grid : LensletGrid
        Grid of the white image (``grid.image_size`` must equal ``(H, W)``).
    sensor : LensletSensor, optional
        The sensor figures below (``black_level`` to ``read_noise_dn``, except the decoding options
        ``n_views``, ``demosaic_method``, ``hex_method``, ``white_threshold`` and ``fill``); or give them
        as keywords (``**sensor_fields``; ``black_level`` and ``white_level`` are required), not both.
    black_level, white_level : float
        Levels of both images (DN).
    cfa_pattern : str
        Row-major 2x2 Bayer pattern from the top-left pixel (Illum: ``"GRBG"``).
    white_responses : (r, g, b)
        Camera response of the white target (the white image's ``normalizedResponses``).
    n_views : int
        Odd number of views per side kept around the centre (1..15).
    hot_pixels : ndarray of shape (N, 2), optional
        Known hot pixels ``(x, y)``.
    demosaic_method : str
        See :func:`demosaic`.
    hex_method : {"spline", "linear"}
        See :func:`hex_to_square`.
    gain_dn_per_e, read_noise_dn : float, optional
        Sensor noise figures at the capture's ISO for the variance (None: variance from the
        white image only, as if the sensor had unit gain).
    white_threshold : float
        Samples where the (neutralised) white image is below this are unusable.
    fill : bool
        Give unusable samples values interpolated from the usable ones (:func:`fill_unusable`);
        False sets them to 0.

    Returns
    -------
    dict with ``data`` (n, n, rows, cols, 3) float32, ``variance`` (same shape), ``weight``
    (n, n, rows, cols) in [0, 1] (white-image transmission, 0 where unusable) and
    ``hot_pixels`` (count replaced in the capture and the white image).
    """
    sensor = resolve_options(LensletSensor, sensor, sensor_fields, func_name="decode_lenslet", argument="sensor")
    black_level, white_level, cfa_pattern = sensor.black_level, sensor.white_level, sensor.cfa_pattern
    white_responses, hot_pixels = sensor.white_responses, sensor.hot_pixels
    gain_dn_per_e, read_noise_dn = sensor.gain_dn_per_e, sensor.read_noise_dn
    raw = np.asarray(raw)
    white = np.asarray(white)
    if raw.ndim != 2 or white.shape != raw.shape:
        raise ShapeError(f"decode: raw {raw.shape} and white image {white.shape} must be 2-D arrays of the same "
                         "shape (use the white image of this camera)")
    if tuple(grid.image_size) != raw.shape:
        raise ShapeError(f"decode: the lenslet grid belongs to a {grid.image_size[1]} x {grid.image_size[0]} sensor, "
                         f"the raw image is {raw.shape[1]} x {raw.shape[0]}")
    if not (isinstance(n_views, (int, np.integer)) and n_views % 2 == 1 and 1 <= n_views <= VIEW_STEP_DIVISOR - 1):
        raise InputError(f"views: expected an odd number from 1 to {VIEW_STEP_DIVISOR - 1}, got {n_views}")
    if not white_level > black_level:
        raise InputError(f"levels: white level {white_level} must exceed black level {black_level}")
    pattern = _check_pattern(cfa_pattern)
    span = float(white_level - black_level)
    lin = (raw.astype(np.float32) - np.float32(black_level)) / np.float32(span)
    wht = (white.astype(np.float32) - np.float32(black_level)) / np.float32(span)
    saturated = raw >= white_level - 0.5
    lin, n_hot = correct_hot_pixels(lin, extra=hot_pixels)
    wht, n_hot_w = correct_hot_pixels(wht)
    resp = np.asarray(white_responses, dtype=np.float32)
    if resp.shape != (3,) or not np.all(resp > 0):
        raise InputError(f"white_responses: expected three positive numbers (r, g, b), got {white_responses}")
    wht /= resp[_channel_map(pattern, wht.shape)]
    usable = wht >= white_threshold
    devig = np.where(usable, lin / np.maximum(wht, white_threshold), 0.0).astype(np.float32)
    np.maximum(devig, 0.0, out=devig)
    rgb = demosaic(devig, cfa_pattern=pattern, method=demosaic_method)
    del devig
    step = grid.spacing_x_px / VIEW_STEP_DIVISOR
    samples = _sample_views(rgb, grid, n_views, step)
    del rgb
    # confidence: the white image and the unusable mask, sampled alike
    wsm = np.where(usable & ~saturated, np.minimum(wht, 1.5), 0.0).astype(np.float32)
    import cv2

    bad = cv2.dilate((~usable | saturated).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(np.float32)
    wsamp = _sample_views(wsm, grid, n_views, step)
    badsamp = _sample_views(bad, grid, n_views, step)
    data = hex_to_square(samples, grid, method=hex_method)
    wsq = hex_to_square(wsamp[..., None], grid, method="linear")[..., 0]
    badsq = hex_to_square(badsamp[..., None], grid, method="linear")[..., 0]
    # off-sensor lenslets: their centre outside the image
    inside = grid.inside(margin_px=step * (n_views // 2) + 1).astype(np.float32)
    insq = hex_to_square(np.broadcast_to(inside[None, None, :, :, None], (1, 1) + inside.shape + (1,)), grid,
                         method="linear")[0, 0, ..., 0]
    unusable = (badsq > 0) | (wsq < white_threshold) | (insq < 0.999)[None, None]
    np.maximum(data, 0.0, out=data)
    if fill:
        # samples lying wholly on saturated pixels keep their saturation level (a clipped highlight
        # stays bright); the others are inpainted from the usable samples only
        satsamp = _sample_views(saturated.astype(np.float32), grid, n_views, step)
        on_saturated = hex_to_square(satsamp[..., None], grid, method="linear")[..., 0] >= 1.0 - 1e-6
        del satsamp
        data = fill_unusable(data, unusable, keep=on_saturated & unusable)
    else:
        data[unusable] = 0.0
    g = 1.0 if gain_dn_per_e is None else float(gain_dn_per_e)
    # variance of (raw - black) / span in DN^2 / span^2, divided by the white image squared
    signal_dn = data * wsq[..., None] * span
    var = (g * signal_dn + float(read_noise_dn) ** 2 + 1.0 / 12.0) / (span ** 2) / np.maximum(wsq, white_threshold)[
        ..., None] ** 2
    var = var.astype(np.float32)
    var[unusable] = UNUSABLE_VARIANCE
    weight = np.where(unusable, 0.0, np.clip(wsq, 0.0, 1.0)).astype(np.float32)
    return {"data": data, "variance": var, "weight": weight, "hot_pixels": {"capture": n_hot, "white": n_hot_w}}


def apply_colour(rgb: np.ndarray, *, white_balance=(1.0, 1.0, 1.0), ccm=None, exposure_bias_ev: float = 0.0
                 ) -> np.ndarray:
    """Camera RGB to linear sRGB (Rec. 709 primaries): white balance, colour matrix, exposure bias.

    ``out = 2**exposure_bias_ev * (ccm @ (wb * rgb))`` per pixel (``ccm`` 3x3 row-major, rows
    summing to about 1, as Lytro's ``image.color.ccm``); negatives clipped to 0.
    """
    wb = np.asarray(white_balance, dtype=np.float32)
    a = np.eye(3, dtype=np.float32) if ccm is None else np.asarray(ccm, dtype=np.float32).reshape(3, 3)
    if wb.shape != (3,) or not np.all(np.isfinite(wb)) or not np.all(wb > 0):
        raise InputError(f"white balance: expected three positive gains (r, g, b), got {white_balance}")
    if not np.all(np.isfinite(a)):
        raise InputError("colour matrix: contains NaN or Inf")
    m = (a * wb[None, :]) * np.float32(2.0 ** float(exposure_bias_ev))
    out = np.asarray(rgb, dtype=np.float32) @ m.T
    return np.maximum(out, 0.0, out=out)


def _noise_figures(camera_model: str, iso: float | None) -> tuple[float | None, float]:
    """Gain (DN/e-) and read noise (DN) at ``iso`` from lfproc's camera profile, if it has them."""
    if camera_model != "B01" or iso is None:
        return None, 0.0

    try:
        figs = load_profile("illum").iso_figures(float(iso))
    except (LfprocError, KeyError, ValueError):
        return None, 0.0
    return float(figs.gain_dn_per_e), float(figs.read_noise_e) * float(figs.gain_dn_per_e)


def decode_capture(capture: str | os.PathLike, *, white_db: str | os.PathLike | None = None,
                   white: str | os.PathLike | None = None, n_views: int = 5,
                   colour: Literal["linear", "srgb"] = "linear", demosaic_method: str = "opencv-ea",
                   hex_method: Literal["spline", "linear"] = "spline", verify: bool = True,
                   fill: bool = True) -> LightField:
    """Decode a Lytro raw capture into its central ``n_views x n_views`` sub-aperture views.

    Parameters
    ----------
    capture : path
        Illum ``.LFR`` (or any capture :func:`lfproc.lytro.capture.read_capture` reads).
    white_db : path, optional
        White-image database (``lfproc whites``); the white image is selected by geometry
        hash, else serial and nearest zoom then focus step.
    white : path, optional
        Explicit white image (database ``.npz`` or ``MOD_xxxx.RAW``/``.TXT``); overrides the
        selection.
    n_views : int
        Odd number of views per side (default 5).
    colour : {"linear", "srgb"}
        ``"linear"``: camera RGB; ``"srgb"``: white balance, colour matrix and exposure bias
        applied (linear Rec. 709).
    demosaic_method, hex_method : str
        See :func:`demosaic` and :func:`hex_to_square`.
    verify : bool
        Verify container SHA-1s.
    fill : bool
        Unusable samples get values interpolated from the usable ones (default) or 0
        (see :func:`decode_lenslet`); either way their variance is :data:`UNUSABLE_VARIANCE`.

    Returns
    -------
    LightField
        ``units="relative"`` (1.0 = as bright as the white image), ``exposure_s``/``iso`` of
        the capture, per-sample ``variance`` (:data:`UNUSABLE_VARIANCE` where unusable), and
        ``attrs`` with the capture metadata, the white image used and why, the lenslet grid
        and the decoding options.

    Raises
    ------
    LfpFormatError
        The file holds no raw lenslet image (a processed focal stack or depth map: the message
        says what it holds; :func:`lfproc.lytro.extract.extract_lfp` writes it out).
    InputError
        Neither ``white_db`` nor ``white`` given, or a bad option.
    NoWhiteImageError
        No white image in the database matches the capture.
    ShapeError
        The white image's size differs from the capture's.
    """
    check_choice("colour", colour, ("linear", "srgb"))
    check_choice("demosaic method", demosaic_method, DEMOSAIC_METHODS)
    cap = read_capture(capture, verify=verify)  # first: a file without a raw image is named as such
    if white_db is None and white is None:
        raise InputError(f"decode: give a white-image database ({option_name('white_db=DB_DIR', '--white-db DB_DIR')}) "
                         f"or a white image ({option_name('white=FILE', '--white FILE')})")
    if white is not None:
        wraw, entry = read_white_file(white)
        how = "explicit file"
    else:
        db = load_white_db(white_db)
        entry, how = select_white(db, serial=cap.serial, zoom_step=cap.zoom_step, focus_step=cap.focus_step,
                                  geometry_hash=cap.geometry_hash, raw_shape=cap.raw.shape)
        wraw = entry.load_raw(db.path)
    if wraw.shape != cap.raw.shape:
        raise ShapeError(f"{capture}: wrong raw size for the white image {entry.name}: capture is "
                         f"{cap.raw.shape[1]} x {cap.raw.shape[0]}, white image {wraw.shape[1]} x {wraw.shape[0]}")
    black = float(cap.black_level.get("gr", next(iter(cap.black_level.values()))))
    gain, read_dn = _noise_figures(cap.camera_model, cap.iso)
    res = decode_lenslet(cap.raw, wraw, entry.grid, black_level=black, white_level=float(cap.white_level),
                         cfa_pattern=cap.cfa_pattern, white_responses=entry.responses, n_views=n_views,
                         demosaic_method=demosaic_method, hex_method=hex_method, gain_dn_per_e=gain,
                         read_noise_dn=read_dn, fill=fill)
    data, var = res["data"], res["variance"]
    colour_space = "camera-rgb"
    wb = (1.0, 1.0, 1.0)
    if cap.white_balance:
        wb = (float(cap.white_balance.get("r", 1.0)), float(cap.white_balance.get("g", 1.0)),
              float(cap.white_balance.get("b", 1.0)))
    if colour == "srgb":
        if cap.ccm is None:
            raise InputError(f"{capture}: --colour srgb needs the capture's colour matrix (image.color.ccm), "
                             "the file has none")
        bad = var >= UNUSABLE_VARIANCE
        m = (np.asarray(cap.ccm, dtype=np.float32).reshape(3, 3) * np.asarray(wb, np.float32)[None, :]
             * np.float32(2.0 ** cap.exposure_bias_ev))
        data = apply_colour(data, white_balance=wb, ccm=cap.ccm, exposure_bias_ev=cap.exposure_bias_ev)
        var = np.where(bad, UNUSABLE_VARIANCE, var @ (m ** 2).T).astype(np.float32)
        colour_space = "linear-srgb"
    w = res["weight"]
    attrs = {
        "decoder": "lfproc.lytro.decode",
        "lfproc_version": __version__,
        "lytro": {"camera_model": cap.camera_model, "serial": cap.serial, "zoom_step": cap.zoom_step,
                  "focus_step": cap.focus_step, "exposure_bias_ev": cap.exposure_bias_ev,
                  "white_balance": list(wb), "ccm": None if cap.ccm is None else np.asarray(cap.ccm).ravel().tolist(),
                  "geometry_hash": cap.geometry_hash},
        "white_image": {"name": entry.name, "selected_by": how, "serial": entry.serial,
                        "zoom_step": entry.zoom_step, "focus_step": entry.focus_step,
                        "geometry_hash": entry.geometry_hash},
        "grid": entry.grid.to_dict(),
        "decode": {"views": n_views, "colour": colour, "demosaic": demosaic_method, "hex_resampling": hex_method,
                   "view_step_px": entry.grid.spacing_x_px / VIEW_STEP_DIVISOR,
                   "unusable_variance": UNUSABLE_VARIANCE, "hot_pixels_replaced": res["hot_pixels"],
                   "unusable_values": "inpainted from usable samples (OpenCV Navier-Stokes)" if fill else "0",
                   "usable_fraction": float((w > 0).mean()), "mean_weight": float(w.mean())},
    }
    return LightField(data=freeze(data), variance=freeze(var), units="relative", colour_space=colour_space,
                      exposure_s=cap.exposure_s, iso=cap.iso, source=str(capture), attrs=attrs)
