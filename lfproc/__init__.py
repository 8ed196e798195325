"""lfproc: high-dynamic-range light fields from the camera to the reconstruction.

The light-field type is :class:`lfproc.LightField`; files are read and written with
:func:`lfproc.read_lightfield` and :func:`lfproc.write_lightfield`; every error lfproc
raises on purpose derives from :class:`lfproc.LfprocError`.
"""

from ._version import __version__
from .errors import LfprocError
from .io import read_image, read_lightfield, write_image, write_lightfield
from .lightfield import LightField

__all__ = ["__version__", "LfprocError", "LightField", "read_image", "read_lightfield", "reconstruct", "write_image",
           "write_lightfield"]


def __getattr__(name):
    # lfproc.reconstruct is imported on first use: the solvers are not needed by every command
    if name == "reconstruct":
        from .recon import reconstruct

        return reconstruct
    raise AttributeError(f"module 'lfproc' has no attribute {name!r}")
