"""HDR light-field data sets from folders of exposure brackets (an application: it decodes
Lytro captures, merges brackets with :mod:`lfproc.hdr` and writes previews with
:mod:`lfproc.preview`).

The implementation is :mod:`lfproc.dataset._dataset`; this package was the module
``lfproc.dataset``, whose other (private) names are still found here.
"""

from .._shared.deprecate import former_module_names
from . import _dataset
from ._dataset import (EXPOSURE_FILES, MANIFEST_FIELDS, SCENE_OUTPUTS, Scene, build_dataset, find_scenes,
                       process_scene, read_exposure_file, read_manifest)

__all__ = ["Scene", "EXPOSURE_FILES", "read_exposure_file", "find_scenes", "process_scene", "build_dataset",
           "read_manifest", "SCENE_OUTPUTS", "MANIFEST_FIELDS"]


# names of the former flat module lfproc.dataset that are not public
__getattr__ = former_module_names(_dataset, __name__)
