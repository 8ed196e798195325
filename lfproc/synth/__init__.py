"""Procedural HDR light fields with exact disparity (a stage).

The implementation is :mod:`lfproc.synth._synth`; this package was the module ``lfproc.synth``,
whose other (private) names are still found here.
"""

from . import _synth
from ._synth import check_scene, Layer, render_layers, scene_layers, scene_names, SCENES, synthesize

__all__ = [
    "synthesize",
    "scene_layers",
    "render_layers",
    "Layer",
    "SCENES",
    "scene_names",
    "check_scene",
]


def __getattr__(name):  # names of the former flat module lfproc.synth that are not public
    try:
        return getattr(_synth, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
