"""Previews of coded captures: the sensor image, the ISO map and the mask (``lfproc preview CAPTURE``).

Moved here from :mod:`lfproc.camera.capture` (presentation renders the core types; the capture
type no longer registers its previews when imported).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from .._shared.validation import check_choice
from ..camera.capture import Capture, load_capture
from ..camera.iso import _num
from ..errors import InputError
from ..io._atomic import check_output
from ._preview import write_preview
from .._shared.deps import require

__all__ = ["PREVIEW_KINDS", "render_capture_preview", "write_capture_preview"]

PREVIEW_KINDS = ("capture", "sensor", "iso", "mask")


def _iso_colours(n: int) -> np.ndarray:
    import matplotlib

    cmap = matplotlib.colormaps["viridis"]
    return np.array([cmap(x)[:3] for x in (np.linspace(0.05, 0.95, n) if n > 1 else [0.5])])


def render_capture_preview(capture: Capture, kind: str = "capture", *, shot: int = 0, zoom: int = 32,
                           dpi: int = 100) -> np.ndarray:
    """A picture of a capture: the sensor image, the ISO map and the mask.

    Parameters
    ----------
    capture : Capture
    kind : {"capture", "sensor", "iso", "mask"}
        ``capture`` shows all three side by side (each with a zoomed top-left crop of
        ``zoom`` pixels so pixel-level patterns are visible); the others one of them.
        The sensor image has a colour bar in DN above the black level (gamma 2.2 scale),
        the mask one of its transmission (0 to 1; the hue is the pixel's CFA colour), the
        ISO map a legend of its ISOs.
    shot : int
        Which shot to show.
    zoom : int, default 32
        Side of the zoomed crop in pixels.
    dpi : int, default 100
        Resolution of the matplotlib figure (the picture's size in pixels scales with it).

    Returns
    -------
    ndarray of shape (H, W, 3), uint8

    Raises
    ------
    InputError
        An unknown kind or a shot out of range.
    """
    require("matplotlib", purpose="capture previews")
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    check_choice("preview kind", kind, PREVIEW_KINDS)
    if not 0 <= shot < capture.shots:
        raise InputError(f"shot: expected 0..{capture.shots - 1}, got {shot}")
    h, w = capture.size
    z = max(2, min(int(zoom), h, w))
    profile = capture.profile
    black = float(profile.black_level_dn)
    sensor_dn = np.maximum(capture.dn[shot].astype(np.float64) - black, 0)
    top = max(float(np.percentile(sensor_dn, 99.5)), 1.0)
    sensor = np.clip(sensor_dn / top, 0, 1) ** (1 / 2.2)
    isos = capture.isos
    colours = _iso_colours(len(isos))
    iso_index = np.searchsorted(np.asarray(isos), capture.iso[shot])
    iso_rgb = colours[iso_index]
    op = capture.operator()
    centre = (capture.views[0] // 2, capture.views[1] // 2)
    # the mask seen by the centre view at each pixel's CFA colour, tinted by that colour
    tint = np.eye(3)[op.cfa_index]
    mask_rgb = op.weights[shot, centre[0], centre[1]][..., None] * tint
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize, PowerNorm

    # colour bars: (mappable, label) of the values shown, drawn beside the full panel
    sensor_bar = (ScalarMappable(norm=PowerNorm(gamma=1 / 2.2, vmin=0, vmax=top), cmap="gray"),
                  "DN above black (clipped at the 99.5th percentile)")
    mask_bar = (ScalarMappable(norm=Normalize(vmin=0, vmax=1), cmap="gray"), "mask transmission (hue: CFA colour)")
    panels = []
    if kind in ("capture", "sensor"):
        panels.append((f"sensor, shot {shot + 1}/{capture.shots} (DN - black, gamma 2.2)", sensor, "gray", None,
                       sensor_bar))
    if kind in ("capture", "iso"):
        legend = [Patch(color=colours[i], label=f"ISO {_num(v)}") for i, v in enumerate(isos)]
        title = f"ISO map ({capture.iso_pattern.get('kind', 'given')})"
        panels.append((title, iso_rgb, None, legend, None))
    if kind in ("capture", "mask"):
        panels.append((f"mask, view {centre}, CFA {capture.cfa_pattern} ({capture.mask.kind})", mask_rgb, None, None,
                       mask_bar))
    fig = Figure(figsize=(4.2 * len(panels), 8.4), dpi=dpi)
    for i, (title, image, cmap, legend, bar) in enumerate(panels):
        ax = fig.add_subplot(2, len(panels), i + 1)
        ax.imshow(image, cmap=cmap, vmin=0, vmax=1, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.add_patch(matplotlib.patches.Rectangle((-0.5, -0.5), z, z, fill=False, color="red", lw=1))
        ax.set_xticks([])
        ax.set_yticks([])
        if bar is not None:
            cb = fig.colorbar(bar[0], ax=ax, fraction=0.046, pad=0.03)
            cb.set_label(bar[1], fontsize=8)
            cb.ax.tick_params(labelsize=7)
        ax2 = fig.add_subplot(2, len(panels), len(panels) + i + 1)
        ax2.imshow(image[:z, :z], cmap=cmap, vmin=0, vmax=1, interpolation="nearest")
        ax2.set_title(f"top-left {z} x {z} pixels", fontsize=9)
        ax2.set_xticks([])
        ax2.set_yticks([])
        if legend:
            ax2.legend(handles=legend, loc="upper center", bbox_to_anchor=(0.5, -0.02), ncol=min(4, len(legend)),
                       fontsize=8, frameon=False)
    fig.tight_layout()
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def write_capture_preview(capture, output: str | os.PathLike, *, kind: str = "capture", force: bool = False,
                          shot: int = 0) -> dict[str, Any]:
    """Write :func:`render_capture_preview` of a capture (object or file) to a PNG/JPEG/TIFF.

    Goes through :func:`lfproc.preview.write_preview` (the capture kinds are registered
    there).

    Parameters
    ----------
    capture : Capture or str or path-like
        A capture, or a capture file (read with :func:`lfproc.camera.load_capture`).
    output : str or path-like
        The picture to write (``.png``, ``.jpg``, ``.tif``).
    kind : {"capture", "sensor", "iso", "mask"}, default "capture"
        See :func:`render_capture_preview`.
    force : bool, default False
        Overwrite an existing ``output``.
    shot : int, default 0
        Which shot to show.

    Returns
    -------
    dict
        ``output`` (path), ``kind``, ``size`` ``[height, width]`` of the picture, ``shots``, ``isos``.

    Raises
    ------
    OutputExistsError
        ``output`` exists and ``force`` is false.
    InputError
        An unknown kind.

    Examples
    --------
    >>> import os
    >>> from lfproc.camera import simulate_capture
    >>> from lfproc.preview import write_capture_preview
    >>> from lfproc.synth import synthesize
    >>> capture = simulate_capture(synthesize("window", size=(24, 24), views=5, random_state=0),
    ...                            shots=2, mask_period=4, random_state=0)
    >>> summary = write_capture_preview(capture, "sensor.png", kind="sensor")
    >>> summary["output"], summary["shots"], summary["isos"], os.path.isfile("sensor.png")
    ('sensor.png', 2, [100, 400, 800, 1600], True)
    """
    check_choice("--kind (capture previews)", kind, PREVIEW_KINDS)
    check_output(output, force=force)
    if not isinstance(capture, Capture):
        capture = load_capture(capture)
    path = write_preview(capture, output, kind=kind, force=force, shot=shot)
    from PIL import Image

    with Image.open(path) as im:
        width, height = im.size
    return {"output": str(path), "kind": kind, "size": [height, width], "shots": capture.shots,
            "isos": [_num(v) for v in capture.isos]}
