"""Reading and writing light fields and images (foundations).

* :func:`read_lightfield`, :func:`write_lightfield`: lfproc EXR files and folders of views;
* :func:`read_image`, :func:`write_image`: HDR and LDR images;
* :func:`srgb_encode`, :func:`srgb_decode`, :func:`exr_parts`, :func:`view_name`,
  :func:`parse_view_name`, :data:`IMAGE_SUFFIXES`.

Atomic outputs (the temporary-then-rename plumbing every writer uses) live in
:mod:`lfproc.io._atomic`; their former names here still resolve.
"""

from . import _atomic
from .images import IMAGE_SUFFIXES, exr_parts, read_image, srgb_decode, srgb_encode, write_image
from .lightfield_files import parse_view_name, read_lightfield, view_name, write_lightfield

__all__ = [
    "read_lightfield",
    "write_lightfield",
    "read_image",
    "write_image",
    "IMAGE_SUFFIXES",
    "exr_parts",
    "srgb_decode",
    "srgb_encode",
    "parse_view_name",
    "view_name",
]

_FORMER = ("atomic_dir", "atomic_file", "atomic_outputs", "check_output", "clean_stale")


def __getattr__(name):  # former exports: the atomic-output plumbing
    if name in _FORMER:
        return getattr(_atomic, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
