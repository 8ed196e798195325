"""Presentation: previews of light fields, captures and dictionaries, tone mapping (a layer above the stages).

* :func:`render_preview`, :func:`write_preview`, :func:`preview_kinds`, :func:`register_preview`,
  :data:`PREVIEWS`: the registry of preview kinds and the light-field kinds (tone-mapped centre
  view, contact sheet, EPIs, histogram; :mod:`lfproc.preview._preview`);
* :func:`render_capture_preview`, :func:`write_capture_preview`: coded captures' sensor image,
  ISO map and mask (:mod:`lfproc.preview._capture`);
* :func:`render_atoms`: a dictionary's atoms (:mod:`lfproc.preview._atoms`);
* :func:`display_transform`, :data:`TONEMAPS`: exposure and tone mapping of light fields for
  8/16-bit outputs (:mod:`lfproc.preview._tonemap`, formerly ``lfproc.tonemap``).

The presentation layer registers the previews of the core types itself, here, when it is
imported: importing a capture or a dictionary no longer changes :data:`PREVIEWS`.
"""

from functools import partial

from .._shared.deprecate import former_module_names
from . import _preview
from ._atoms import render_atoms
from ._capture import PREVIEW_KINDS as CAPTURE_PREVIEW_KINDS
from ._capture import render_capture_preview, write_capture_preview
from ._preview import (PREVIEW_SUFFIXES, PREVIEWS, SHEET_MAX_PIXELS, epi_stretch, preview_kinds, register_preview,
                       reinhard_parameters, render_error_map, render_preview, sheet_tile_size, tonemap,
                       write_error_map, write_preview)
from ._tonemap import TONEMAPS, clipped_fraction, display_transform
from ..camera.capture import Capture
from ..dictionary._files import Dictionary

__all__ = [
    "render_preview", "write_preview", "preview_kinds", "register_preview", "PREVIEWS", "PREVIEW_SUFFIXES",
    "tonemap", "reinhard_parameters", "render_error_map", "write_error_map", "epi_stretch", "sheet_tile_size",
    "SHEET_MAX_PIXELS",
    "render_capture_preview", "write_capture_preview", "CAPTURE_PREVIEW_KINDS",
    "render_atoms",
    "display_transform", "TONEMAPS", "clipped_fraction",
]

_CAPTURE_KINDS = {
    "capture": "a coded capture's sensor image, ISO map and mask side by side",
    "sensor": "a coded capture's sensor image",
    "iso": "a coded capture's ISO map",
    "mask": "a coded capture's mask (centre view, CFA colour)",
}


def _register_core_types() -> None:
    """Add the preview kinds of captures and dictionaries (the light-field kinds are built in)."""
    for kind, text in _CAPTURE_KINDS.items():
        if kind not in PREVIEWS:
            register_preview(kind, partial(render_capture_preview, kind=kind), accepts=Capture, description=text)
    if "atoms" not in PREVIEWS:
        register_preview("atoms", render_atoms, accepts=Dictionary,
                         description="a dictionary's most used atoms: centre view above a horizontal EPI")


_register_core_types()


# names of the former flat module lfproc.preview that are not public
__getattr__ = former_module_names(_preview, __name__)
