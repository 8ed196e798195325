"""Procedural HDR light fields with exact disparity (a stage).

The implementation is :mod:`lfproc.synth._synth`; this package was the module ``lfproc.synth``,
whose other (private) names are still found here.
"""

from .._shared.deprecate import former_module_names
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


# names of the former flat module lfproc.synth that are not public
__getattr__ = former_module_names(_synth, __name__)
