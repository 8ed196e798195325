"""Previews of HDR light fields: tone-mapped views, contact sheets, EPIs, histograms.

Tone mapping is the global photographic operator of Reinhard et al. (2002), applied to
luminance with colour ratios preserved, then sRGB encoding (:func:`lfproc.io.srgb_encode`).

Preview kinds live in a registry (:data:`PREVIEWS`): kind -> (type of input, renderer).
:func:`render_preview` checks the input type and dispatches, so previews of other inputs
(a sensor image, an ISO map, a mask...) are added with :func:`register_preview` without
touching the light-field ones.

References
----------
.. [1] E. Reinhard, M. Stark, P. Shirley, J. Ferwerda, "Photographic tone reproduction
   for digital images", ACM Transactions on Graphics 21(3), 267-276, 2002.
   https://doi.org/10.1145/566654.566575
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import InputError, ShapeError
from ..lightfield import LightField, luminance
from ..io import srgb_encode
from ..io._atomic import atomic_file, check_output
from ..metrics import error_stops
from .._shared.deps import require

__all__ = [
    "tonemap",
    "reinhard_parameters",
    "render_preview",
    "write_preview",
    "register_preview",
    "preview_kinds",
    "epi_stretch",
    "sheet_tile_size",
    "SHEET_MAX_PIXELS",
    "PREVIEWS",
    "PREVIEW_SUFFIXES",
    "render_error_map",
    "write_error_map",
]

PREVIEW_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")

#: Background grey (sRGB code) of gaps between tiles.
_GAP_GREY = 40


# -- tone mapping --------------------------------------------------------------------------------

def reinhard_parameters(image: np.ndarray, *, key: float = 0.18, white_percentile: float = 99.9,
                        exposure_ev: float = 0.0) -> dict[str, float]:
    """Statistics of the Reinhard global operator for ``image`` (linear, last axis colour).

    Parameters
    ----------
    image : ndarray
        Linear image or light field, colour on the last axis (RGB or one channel).
    key : float, default 0.18
        The grey the log-average luminance maps to, in (0, 1).
    white_percentile : float, default 99.9
        Percentile of the scaled luminance mapped to white, in (0, 100].
    exposure_ev : float, default 0.0
        Extra exposure in stops.

    Returns
    -------
    dict
        ``log_average`` (``exp(mean(log L))`` over the positive luminances ``L``),
        ``scale`` (``key * 2**exposure_ev / log_average``: scene luminance to the operator's
        ``L_s``) and ``white`` (``L_white``: the ``white_percentile`` of ``L_s``, mapped to 1).
        A black image gives ``{"log_average": 0.0, "scale": 0.0, "white": 1.0}``.

    Raises
    ------
    InputError
        ``key``, ``white_percentile`` or ``exposure_ev`` out of range.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.preview import reinhard_parameters
    >>> grey = np.full((4, 4, 3), 2.0, dtype=np.float32)  # luminance 2 everywhere
    >>> p = reinhard_parameters(grey)
    >>> round(p["log_average"], 6), round(p["scale"], 6), round(p["white"], 6)
    (2.0, 0.09, 0.18)
    """
    if not (0 < key < 1):
        raise InputError(f"key: expected a number in (0, 1) (0.18 is middle grey), got {key!r}")
    if not (0 < white_percentile <= 100):
        raise InputError(f"white_percentile: expected a number in (0, 100], got {white_percentile!r}")
    if not math.isfinite(exposure_ev):
        raise InputError(f"exposure: expected a finite number of EV, got {exposure_ev!r}")
    lum = _luminance_of(image).ravel()
    positive = lum[lum > 0]
    if positive.size == 0:
        return {"log_average": 0.0, "scale": 0.0, "white": 1.0}
    log_average = float(np.exp(np.mean(np.log(positive.astype(np.float64)))))
    scale = key * 2.0**exposure_ev / log_average
    white = float(np.percentile(positive, white_percentile)) * scale
    return {"log_average": log_average, "scale": scale, "white": max(white, 1e-6)}


def _luminance_of(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim == 0 or image.shape[-1] not in (1, 3):
        raise ShapeError(f"tonemap: expected linear values with 1 or 3 colour channels on the last axis, got shape "
                         f"{image.shape}")
    return luminance(image)


def tonemap(image: np.ndarray, *, key: float = 0.18, white_percentile: float = 99.9, exposure_ev: float = 0.0,
            reference: np.ndarray | None = None, encoding: str = "srgb") -> np.ndarray:
    """Tone-map linear HDR values to display values in [0, 1] (Reinhard et al. 2002, global).

    With ``L`` the luminance (Rec. 709) and ``L_avg`` its log-average over positive pixels,
    ``L_s = key * 2**exposure_ev * L / L_avg`` and (eq. 4 of [1]_)
    ``L_d = L_s * (1 + L_s / L_white**2) / (1 + L_s)``, with ``L_white`` the
    ``white_percentile`` of ``L_s`` (so that percentile maps to 1). Colours keep their ratios:
    ``rgb_d = rgb * L_d / L``, clipped to [0, 1]; then sRGB encoding.

    A pixel at the log-average luminance (with ``exposure_ev=0``) maps to the linear display
    value ``key * (1 + key / L_white**2) / (1 + key)`` (about 0.153 for ``key=0.18``).

    Parameters
    ----------
    image : ndarray of shape (..., C), C in {1, 3}
        Linear, non-negative values (any number of leading axes: a view, all views...).
    key : float
        Display value of the log-average (the "key" of the scene), in (0, 1).
    white_percentile : float
        Percentile of the luminance that maps to white.
    exposure_ev : float
        Extra exposure in stops (applied before the curve; the white point follows).
    reference : ndarray, optional
        Values the statistics come from (default: ``image``), so several images can share
        one tone curve.
    encoding : {"srgb", "linear"}
        Output encoding.

    Returns
    -------
    ndarray of the shape of ``image``, float32 in [0, 1].

    Raises
    ------
    InputError
        An unknown encoding, or ``key``/``white_percentile``/``exposure_ev`` out of range.

    Examples
    --------
    Three grey pixels a decade apart (log-average 1); the brightest is the white point:

    >>> import numpy as np
    >>> from lfproc.preview import tonemap
    >>> grey = np.array([0.1, 1.0, 10.0], dtype=np.float32)[:, None] * np.ones(3, dtype=np.float32)
    >>> np.round(tonemap(grey, white_percentile=100, encoding="linear")[:, 0].astype(float), 4).tolist()
    [0.0178, 0.161, 1.0]
    >>> np.round(tonemap(grey, white_percentile=100)[:, 0].astype(float), 4).tolist()  # sRGB-encoded
    [0.1418, 0.4379, 1.0]

    References
    ----------
    .. [1] E. Reinhard, M. Stark, P. Shirley, J. Ferwerda, "Photographic tone reproduction
       for digital images", ACM TOG 21(3), 2002. https://doi.org/10.1145/566654.566575
    """
    if encoding not in ("srgb", "linear"):
        raise InputError(f"encoding: expected srgb or linear; got {encoding!r}")
    image = np.asarray(image, dtype=np.float32)
    params = reinhard_parameters(image if reference is None else reference, key=key,
                                 white_percentile=white_percentile, exposure_ev=exposure_ev)
    lum = _luminance_of(image).astype(np.float64)
    ls = lum * params["scale"]
    ld = ls * (1 + ls / params["white"] ** 2) / (1 + ls)
    ratio = np.divide(ld, lum, out=np.zeros_like(lum), where=lum > 0)
    out = np.clip(image * ratio[..., None].astype(np.float32), 0, 1)
    return srgb_encode(out) if encoding == "srgb" else out.astype(np.float32)


def _to_uint8(display: np.ndarray) -> np.ndarray:
    """[0, 1] display values (any C in {1, 3}) to uint8 RGB."""
    rgb = np.repeat(display, 3, axis=-1) if display.shape[-1] == 1 else display
    return np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8)


# -- renderers -----------------------------------------------------------------------------------

def _gap(h: int, w: int) -> int:
    return max(2, min(h, w) // 64)


def _tone_source(lf: LightField, exposure_from: LightField | None) -> LightField:
    """The light field whose statistics set the tone curve: ``exposure_from`` when given."""
    if exposure_from is None:
        return lf
    if not isinstance(exposure_from, LightField):
        raise InputError(f"exposure_from: expected a LightField (the reference whose tone curve is shared), "
                         f"got {type(exposure_from).__name__}")
    return exposure_from


def _preview_centre(lf: LightField, *, exposure_ev: float = 0.0, exposure_from: LightField | None = None
                    ) -> np.ndarray:
    """The centre view, tone-mapped with its own statistics (or those of ``exposure_from``'s centre view)."""
    return _to_uint8(tonemap(lf.centre(), exposure_ev=exposure_ev, reference=_tone_source(lf, exposure_from).centre()))


#: Default pixel budget of a contact sheet's tiles (about 1.2 megapixels: a PNG of real views
#: of at most about 2 MB). Larger light fields are downscaled to fit.
SHEET_MAX_PIXELS = 1_200_000


def sheet_tile_size(lf: LightField, max_pixels: int | None = SHEET_MAX_PIXELS) -> tuple[int, int]:
    """Size (h, w) of one tile of the contact sheet: the view size, downscaled by one factor
    (at most 1) so that all ``V * U`` tiles hold at most ``max_pixels`` pixels (``None``: full size).

    Parameters
    ----------
    lf : LightField
    max_pixels : int or None, default SHEET_MAX_PIXELS
        Pixel budget of all tiles together.

    Returns
    -------
    tuple of 2 int
        ``(h, w)``, each at least 1.

    Raises
    ------
    InputError
        ``max_pixels`` is not a positive integer.
    """
    nv, nu = lf.views
    h, w = lf.size
    if max_pixels is None:
        return h, w
    if isinstance(max_pixels, bool) or not (isinstance(max_pixels, (int, np.integer)) and max_pixels > 0):
        raise InputError(f"max_pixels: expected a positive integer number of pixels, got {max_pixels!r}")
    scale = min(1.0, math.sqrt(max_pixels / (nv * nu * h * w)))
    return max(1, int(h * scale)), max(1, int(w * scale))


def _label_font(height: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=height)
    except (OSError, TypeError, ValueError, ImportError):  # no FreeType: the fixed bitmap font
        return ImageFont.load_default()


def _sheet_label_height(tile_w: int) -> int:
    return int(min(18, max(10, tile_w // 10)))


def _preview_sheet(lf: LightField, *, exposure_ev: float = 0.0, exposure_from: LightField | None = None,
                   max_pixels: int | None = SHEET_MAX_PIXELS, labels: bool = True) -> np.ndarray:
    """All V x U views as tiles, one tone curve, each under a label ``v,u`` (0-based view indices,
    as in ``lfproc evaluate``'s rows and :meth:`LightField.view`; file names ``view_RR_CC`` count from 01).

    Tiles are the views downscaled to :func:`sheet_tile_size` (``max_pixels`` in all), separated
    by gaps of ``max(2, min(h, w) // 64)`` pixels; with ``labels`` each tile has a band of
    ``min(18, max(10, w // 10))`` pixels above it holding its indices.
    """
    from PIL import Image, ImageDraw

    nv, nu = lf.views
    h, w = lf.size
    th, tw = sheet_tile_size(lf, max_pixels)
    g = _gap(th, tw)
    lb = _sheet_label_height(tw) if labels else 0
    tiles = _to_uint8(tonemap(lf.data, exposure_ev=exposure_ev, reference=_tone_source(lf, exposure_from).data))
    sheet = np.full((nv * (lb + th) + (nv - 1) * g, nu * tw + (nu - 1) * g, 3), _GAP_GREY, np.uint8)
    for v in range(nv):
        for u in range(nu):
            tile = tiles[v, u]
            if (th, tw) != (h, w):
                tile = np.asarray(Image.fromarray(tile).resize((tw, th), Image.Resampling.LANCZOS))
            top, left = v * (lb + th + g) + lb, u * (tw + g)
            sheet[top:top + th, left:left + tw] = tile
    if labels:
        pil = Image.fromarray(sheet)
        draw = ImageDraw.Draw(pil)
        font = _label_font(lb - 2)
        for v in range(nv):
            for u in range(nu):
                draw.text((u * (tw + g) + 2, v * (lb + th + g) + lb // 2), f"{v},{u}", fill=(225, 225, 225),
                          font=font, anchor="lm")
        sheet = np.asarray(pil).copy()
    return sheet


def epi_stretch(lf: LightField) -> int:
    """Rows (or columns) each view gets in an EPI preview: EPIs about a quarter of the view tall.

    Parameters
    ----------
    lf : LightField

    Returns
    -------
    int
        ``max(1, ceil(min(H, W) / (4 * max(V, U))))``.
    """
    h, w = lf.size
    return max(1, math.ceil(min(h, w) / (4 * max(lf.views))))


def _preview_epi(lf: LightField, *, exposure_ev: float = 0.0, row: int | None = None,
                 column: int | None = None, exposure_from: LightField | None = None) -> np.ndarray:
    """Centre view with the EPI lines marked, the horizontal EPI below it, the vertical EPI to its right.

    Each view is one row (column) of an EPI, repeated ``epi_stretch(lf)`` times so that the
    slopes (disparities) are visible; the tone curve is the centre view's
    (``exposure_from``'s centre view when given). Layout::

        [ centre view, row and column marked ] [gap] [ vertical EPI (H x V*s)   ]
        [ horizontal EPI (U*s x W)           ] [gap] [ empty                    ]
    """
    nv, nu = lf.views
    h, w = lf.size
    row = h // 2 if row is None else row
    column = w // 2 if column is None else column
    s = epi_stretch(lf)
    g = _gap(h, w)
    ref = _tone_source(lf, exposure_from).centre()
    centre = _to_uint8(tonemap(lf.centre(), exposure_ev=exposure_ev, reference=ref))
    ehor = _to_uint8(tonemap(lf.epi(axis="horizontal", index=row), exposure_ev=exposure_ev, reference=ref))
    ever = _to_uint8(tonemap(lf.epi(axis="vertical", index=column), exposure_ev=exposure_ev, reference=ref))
    ehor = np.repeat(ehor, s, axis=0)  # (U*s, W, 3)
    ever = np.repeat(np.transpose(ever, (1, 0, 2)), s, axis=1)  # (H, V*s, 3)
    marked = centre.copy()
    marker = np.array([255, 40, 40], np.uint8)
    dashes = (np.arange(max(h, w)) // 4) % 2 == 0  # dashed lines keep the content visible
    marked[row, dashes[:w]] = marker
    marked[dashes[:h], column] = marker
    out = np.full((h + g + nu * s, w + g + nv * s, 3), _GAP_GREY, np.uint8)
    out[:h, :w] = marked
    out[h + g:, :w] = ehor
    out[:h, w + g:] = ever
    return out


def _stops_range(lf: LightField) -> tuple[int, int] | None:
    lum = lf.luminance().ravel()
    positive = lum[lum > 0]
    if not positive.size:
        return None
    stops = np.log2(positive.astype(np.float64))
    return math.floor(stops.min()), math.ceil(stops.max())


def _histogram_data(lf: LightField, span: tuple[int, int] | None = None) -> dict[str, Any]:
    """What the histogram preview draws: bin ``edges`` (stops, whole stops at both ends, 8 bins
    a stop, 20 to 400 bins), ``fractions`` of all samples per bin, the 0.1/99.9 percentiles of
    log2 luminance, the dynamic range, the saturated and zero fractions. ``span`` (whole
    stops) widens the bins' range, so that two histograms share an axis."""
    lum = lf.luminance().ravel()
    positive = lum[lum > 0]
    out: dict[str, Any] = {"edges": None, "fractions": None, "p_lo": None, "p_hi": None,
                           "dynamic_range_stops": lf.dynamic_range_stops(), "saturated": lf.saturated_fraction(),
                           "zero_fraction": (lum.size - positive.size) / max(lum.size, 1)}
    if positive.size:
        stops = np.log2(positive.astype(np.float64))
        lo, hi = math.floor(stops.min()), math.ceil(stops.max())
        if span is not None:
            lo, hi = min(lo, span[0]), max(hi, span[1])
        hi = max(hi, lo + 1)
        bins = np.linspace(lo, hi, int(min(400, max(20, 8 * (hi - lo)))) + 1)
        counts, edges = np.histogram(stops, bins=bins)
        out["edges"], out["fractions"] = edges, counts / lum.size
        out["p_lo"], out["p_hi"] = (float(p) for p in np.percentile(stops, [0.1, 99.9]))
    return out


def _preview_histogram(lf: LightField, *, exposure_ev: float = 0.0, width_px: int = 800,
                       height_px: int = 500, exposure_from: LightField | None = None) -> np.ndarray:
    """Histogram of log2 luminance (all views), with the robust dynamic range and saturation.

    The figures are written under the plot, never over the bars. With ``exposure_from`` the
    stops axis spans both light fields, so the two histograms can be laid side by side.
    """
    require("matplotlib", purpose="histogram previews")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    span = None if exposure_from is None else _stops_range(_tone_source(lf, exposure_from))
    data = _histogram_data(lf, span)
    dpi = 100
    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    if data["edges"] is not None:
        edges = data["edges"]
        ax.stairs(data["fractions"], edges, fill=True, color="#4c72b0")
        ax.set_yscale("log")
        for p in (data["p_lo"], data["p_hi"]):
            ax.axvline(p, color="#c44e52", linestyle="--", linewidth=1)
        ax.axvspan(data["p_lo"], data["p_hi"], color="#c44e52", alpha=0.06)
        ax.set_xlim(edges[0] - 0.5, edges[-1] + 0.5)
    else:
        ax.text(0.5, 0.5, "no positive luminance", transform=ax.transAxes, ha="center")
    ax.set_xlabel("log2 luminance (stops)")
    ax.set_ylabel("fraction of pixels")
    sat = data["saturated"]
    sat_text = "unknown (no saturation level)" if sat is None else f"{100 * sat:.3g} %"
    text = (f"dynamic range (0.1-99.9 %): {data['dynamic_range_stops']:.1f} stops    "
            f"saturated: {sat_text}    zero pixels: {100 * data['zero_fraction']:.3g} %")
    # under the plot, outside the axes: never over the bars (the peak is often at the right)
    fig.text(0.5, 0.012, text, ha="center", va="bottom", fontsize=9,
             bbox={"facecolor": "white", "edgecolor": "#999999", "boxstyle": "round,pad=0.3"})
    nv, nu = lf.views
    h, w = lf.size
    title = f"{lf.source or 'light field'}: {nv}x{nu} views of {h}x{w}, units {lf.units}"
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


@dataclass(frozen=True)
class PreviewKind:
    """A preview: the input type it accepts, its renderer and a one-line description."""

    accepts: type
    render: Callable[..., np.ndarray]
    description: str


#: Preview kinds: name -> PreviewKind. Renderers take the input and keyword options and
#: return a uint8 RGB array (H, W, 3).
PREVIEWS: dict[str, PreviewKind] = {}


def register_preview(kind: str, render: Callable[..., np.ndarray], *, accepts: type = LightField,
                     description: str = "") -> None:
    """Add a preview kind (e.g. a capture's sensor image): ``render(obj, **options) -> uint8 (H, W, 3)``.

    Parameters
    ----------
    kind : str
        The new kind's name.
    render : callable
        ``render(obj, **options)`` returning a uint8 RGB array of shape ``(H, W, 3)``.
    accepts : type, default LightField
        The input type the kind renders.
    description : str, default ""
        One line for ``lfproc preview --help``.

    Raises
    ------
    InputError
        ``kind`` is already registered.
    """
    if kind in PREVIEWS:
        raise InputError(f"preview kind {kind!r} is already registered")
    PREVIEWS[kind] = PreviewKind(accepts=accepts, render=render, description=description)


register_preview("centre", _preview_centre, description="tone-mapped centre view")
register_preview("sheet", _preview_sheet, description="contact sheet of all views, labelled v,u, one tone curve")
register_preview("epi", _preview_epi, description="centre view with horizontal and vertical epipolar-plane images")
register_preview("histogram", _preview_histogram, description="histogram of log2 luminance with the dynamic range")


def preview_kinds(input_type: type | None = None) -> list[str]:
    """Preview kinds (those accepting inputs of ``input_type`` when given).

    Parameters
    ----------
    input_type : type, optional
        Keep the kinds whose renderer accepts this type (e.g. :class:`lfproc.LightField` or
        :class:`lfproc.camera.Capture`); None: every registered kind.

    Returns
    -------
    list of str
        Kinds in registration order.

    Examples
    --------
    >>> from lfproc import LightField
    >>> from lfproc.preview import preview_kinds
    >>> preview_kinds(LightField)
    ['centre', 'sheet', 'epi', 'histogram']
    """
    return [k for k, p in PREVIEWS.items() if input_type is None or issubclass(input_type, p.accepts)]


def render_preview(obj: Any, kind: str = "centre", **options) -> np.ndarray:
    """Render a preview as a uint8 RGB array of shape (H, W, 3).

    Parameters
    ----------
    obj : LightField (or the input type a registered kind accepts)
    kind : str
        ``"centre"`` (H x W), ``"sheet"`` (``V*(b+h) + (V-1)*g`` by ``U*w + (U-1)*g``: tiles of
        ``(h, w) = sheet_tile_size(lf)``, the views downscaled to ``max_pixels`` (default
        :data:`SHEET_MAX_PIXELS`; ``None`` keeps full size), label bands of
        ``b = min(18, max(10, w // 10))`` pixels (0 with ``labels=False``), gaps
        ``g = max(2, min(h, w) // 64)``), ``"epi"`` (``H + g + U*s`` by ``W + g + V*s``,
        ``s = epi_stretch(lf)``) or ``"histogram"`` (800 x 500 plot).
    **options
        Passed to the renderer: ``exposure_ev`` and ``exposure_from`` for all light-field
        kinds. ``exposure_from=reference`` (a LightField) takes the tone curve (log-average
        and white point) from the reference instead of ``obj``, so a result and its truth
        rendered with the same ``exposure_from`` are shown at one exposure (the histogram
        shares the reference's range of stops).

    Returns
    -------
    ndarray of shape (H, W, 3), uint8

    Raises
    ------
    InputError
        An unknown kind, or an input the kind does not accept.
    ShapeError
        A renderer that does not return uint8 ``(H, W, 3)``.

    Examples
    --------
    >>> from lfproc.preview import render_preview
    >>> from lfproc.synth import synthesize
    >>> lf = synthesize("lamps", size=(24, 32), views=3, random_state=0)
    >>> centre = render_preview(lf)  # the tone-mapped centre view
    >>> centre.shape, centre.dtype
    ((24, 32, 3), dtype('uint8'))
    """
    if kind not in PREVIEWS:
        raise InputError(f"preview kind: expected one of {', '.join(PREVIEWS)}; got {kind!r}")
    spec = PREVIEWS[kind]
    if not isinstance(obj, spec.accepts):
        raise InputError(f"preview kind {kind!r}: expected a {spec.accepts.__name__}, got {type(obj).__name__}")
    image = spec.render(obj, **options)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ShapeError(f"preview kind {kind!r}: renderer returned {image.dtype} {image.shape}, expected uint8 (H, W, 3)")
    return image


def _describe_option(value: Any) -> Any:
    if isinstance(value, LightField):
        return f"LightField({value.source})" if value.source else repr(value)
    return value


def write_preview(obj: Any, path: str | os.PathLike, *, kind: str = "centre", force: bool = False,
                  **options) -> Path:
    """Render a preview and write it atomically (PNG with lfproc version and kind in text chunks; JPEG, TIFF).

    Parameters
    ----------
    obj : LightField (or the input type a registered kind accepts)
    path : str or path-like
        The picture to write; the suffix picks the format (``.png``, ``.jpg``/``.jpeg``,
        ``.tif``/``.tiff``).
    kind : str, default "centre"
        A kind of :func:`preview_kinds` (see :func:`render_preview`).
    force : bool, default False
        Overwrite an existing ``path``.
    **options
        Passed to the renderer (:func:`render_preview`).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``force`` is false.
    InputError
        An unknown kind, an input the kind does not accept, or an unknown suffix.

    Examples
    --------
    >>> import os
    >>> from lfproc.synth import synthesize
    >>> from lfproc.preview import write_preview
    >>> lf = synthesize("lamps", size=(24, 24), views=3, random_state=0)
    >>> path = write_preview(lf, "centre.png")
    >>> path.name, os.path.getsize(path) > 0
    ('centre.png', True)
    >>> from PIL import Image
    >>> with Image.open(path) as im:
    ...     print(im.size, im.mode)  # (width, height) of the centre view
    (24, 24) RGB
    """
    text = {"lfproc_preview": kind,
            "lfproc_options": repr(sorted((k, _describe_option(v)) for k, v in options.items()))}
    if isinstance(obj, LightField) and obj.source:
        text["Source"] = obj.source
    return _write_picture(path, lambda: render_preview(obj, kind, **options), text, what="a preview", force=force)


def _write_picture(path, render, text: dict[str, str], *, what: str, force: bool) -> Path:
    """Check ``path``, render, and write atomically: PNG (with ``text`` and the lfproc version as text
    chunks), JPEG or TIFF by the suffix."""
    from PIL import Image
    from PIL.PngImagePlugin import PngInfo

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in PREVIEW_SUFFIXES:
        raise InputError(f"{path}: expected {what} file ending in {', '.join(PREVIEW_SUFFIXES)}")
    check_output(path, force=force)
    image = render()
    with atomic_file(path, force=force) as tmp:
        pil = Image.fromarray(image)
        if suffix == ".png":
            info = PngInfo()
            info.add_text("Software", f"lfproc {__version__}")
            for key, value in text.items():
                info.add_text(key, value)
            pil.save(tmp, format="PNG", pnginfo=info)
        elif suffix in (".jpg", ".jpeg"):
            pil.save(tmp, format="JPEG", quality=92)
        else:
            pil.save(tmp, format="TIFF")
    return path


# -- error maps -----------------------------------------------------------------------------------

#: Colours of the error map for samples without a colour-map value (RGB in [0, 1]).
ERROR_MAP_LOST = (0.0, 0.0, 0.0)  # the result is 0 where the reference is not
ERROR_MAP_EXCLUDED = (0.62, 0.62, 0.62)  # masked out, or the reference is 0


def _error_limit(stops: np.ndarray) -> float:
    """Half-range of the colour bar: the 99th percentile of |finite errors| rounded up to 0.25 stop,
    between 0.25 and 8 stops."""
    finite = np.abs(stops[np.isfinite(stops)])
    top = float(np.percentile(finite, 99)) if finite.size else 0.0
    return float(min(8.0, max(0.25, math.ceil(top * 4 - 1e-9) / 4)))


def render_error_map(result: Any, reference: Any, *, view: tuple[int, int] | None = None, mask: Any = None,
                     limit_stops: float | None = None, cmap: str = "RdBu_r", dpi: int = 100) -> np.ndarray:
    """A picture of the per-pixel error in stops of one view, with a colour bar.

    The error is :func:`lfproc.metrics.error_stops` (``log2`` of the result's over the
    reference's luminance): red too bright, blue too dark, white right, on a diverging
    colour map symmetric about 0 and clipped at ``+-limit_stops``. Black marks samples the
    result returns as 0 where the reference is not; grey, samples outside ``mask`` or with a
    reference luminance of 0.

    Parameters
    ----------
    result, reference : LightField or ndarray (H, W, C) / (V, U, H, W, C)
    view : (v, u), optional
        Default: the centre view.
    mask : array_like of bool, (H, W) or (V, U, H, W), optional
        Samples to show (the others are grey).
    limit_stops : float, optional
        Half-range of the colour bar in stops (default: the 99th percentile of the absolute
        error shown, rounded up to a quarter stop, from 0.25 to 8).
    cmap : str, default "RdBu_r"
        A diverging matplotlib colour map.
    dpi : int, default 100
        Resolution of the matplotlib figure.

    Returns
    -------
    ndarray (H', W', 3), uint8

    Raises
    ------
    ShapeError
        Light fields of other shapes, or a mask that is not boolean of shape (H, W) or (V, U, H, W).
    InputError
        A non-positive ``limit_stops``.
    """
    require("matplotlib", purpose="error maps")
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    stops = error_stops(result, reference, view=view)
    h, w = stops.shape
    shown = np.ones((h, w), dtype=bool)
    if mask is not None:
        m = np.asarray(mask)
        if m.dtype != bool:
            raise ShapeError(f"mask: expected a boolean array, got dtype {m.dtype}")
        if m.ndim == 4:
            nv, nu = m.shape[:2]
            v, u = (nv // 2, nu // 2) if view is None else view
            m = m[v, u]
        if m.shape != (h, w):
            raise ShapeError(f"mask: expected shape {(h, w)} or (V, U, {h}, {w}), got {np.asarray(mask).shape}")
        shown &= m
    visible = np.where(shown, stops, np.nan)
    if limit_stops is None:
        limit = _error_limit(visible)
    else:
        limit = float(limit_stops)
        if not (math.isfinite(limit) and limit > 0):
            raise InputError(f"limit_stops: expected a positive number of stops, got {limit_stops!r}")
    colours = matplotlib.colormaps[cmap]
    norm = Normalize(vmin=-limit, vmax=limit, clip=True)
    rgb = colours(norm(np.nan_to_num(visible, nan=0.0, neginf=-limit, posinf=limit)))[..., :3]
    lost = shown & np.isneginf(stops)
    rgb[lost] = ERROR_MAP_LOST
    rgb[~shown | np.isnan(stops)] = ERROR_MAP_EXCLUDED

    zoom = max(1.0, 420.0 / max(h, w))  # small views drawn larger, pixel for pixel
    fig = Figure(figsize=(w * zoom / dpi + 1.7, h * zoom / dpi + 1.1), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.imshow(rgb, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    finite = np.abs(visible[np.isfinite(visible)])
    median = float(np.median(finite)) if finite.size else math.nan
    where = "" if view is None else f" view {tuple(view)}"
    ax.set_title(f"error{where or ' (centre view)'}: median |error| {median:.3g} stops", fontsize=9)
    notes = []
    if lost.any():
        notes.append(f"black: result 0 ({100 * lost.sum() / shown.sum():.3g} %)")
    if (~shown | np.isnan(stops)).any():
        notes.append("grey: excluded or reference 0")
    if notes:
        ax.set_xlabel("; ".join(notes), fontsize=8)
    bar = fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=colours), ax=ax, extend="both",
                       fraction=0.05, pad=0.02)
    bar.set_label("log2(result / reference) luminance, stops", fontsize=8)
    bar.ax.tick_params(labelsize=8)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def write_error_map(result: Any, reference: Any, path: str | os.PathLike, *, force: bool = False,
                    **options) -> Path:
    """Write :func:`render_error_map` atomically to a PNG (or JPEG/TIFF); refuses an existing
    ``path`` unless ``force``. ``options`` go to :func:`render_error_map`.

    Parameters
    ----------
    result, reference : LightField
        The light fields compared (as :func:`render_error_map`).
    path : str or path-like
        The picture to write; the suffix picks the format.
    force : bool, default False
        Overwrite an existing ``path``.
    **options
        Passed to :func:`render_error_map`.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``force`` is false.
    """
    return _write_picture(path, lambda: render_error_map(result, reference, **options),
                          {"lfproc_preview": "error-map"}, what="an error-map", force=force)
