"""lfproc: high-dynamic-range light fields from the camera to the reconstruction.

The light-field type is :class:`lfproc.LightField`; files are read and written with
:func:`lfproc.read_lightfield` and :func:`lfproc.write_lightfield`; every error lfproc
raises on purpose derives from :class:`lfproc.LfprocError`. The pipeline's main steps are
here too: :func:`lfproc.simulate_capture` (a coded multi-ISO capture of a light field),
:func:`lfproc.load_capture` (a capture file), :func:`lfproc.reconstruct` (the HDR light field
of a capture) and :func:`lfproc.evaluate` (HDR metrics against a reference).
"""

from ._version import __version__
from .errors import LfprocError
from .io import read_image, read_lightfield, write_image, write_lightfield
from .lightfield import LightField

__all__ = ["__version__", "LfprocError", "LightField", "read_image", "read_lightfield", "reconstruct", "write_image",
           "write_lightfield", "simulate_capture", "load_capture", "evaluate"]

# imported on first use (the solvers, the simulator and the metrics are not needed by every command)
_LAZY = {"reconstruct": ".recon", "simulate_capture": ".camera.simulate", "load_capture": ".camera.capture",
         "evaluate": ".metrics"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'lfproc' has no attribute {name!r}")
