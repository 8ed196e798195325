"""Reading and writing light fields and images; atomic outputs."""

from ._atomic import atomic_dir, atomic_file, atomic_outputs, check_output, clean_stale
from .images import IMAGE_SUFFIXES, exr_parts, read_image, srgb_decode, srgb_encode, write_image
from .lightfield_files import parse_view_name, read_lightfield, view_name, write_lightfield

__all__ = [
    "atomic_dir",
    "atomic_file",
    "atomic_outputs",
    "check_output",
    "clean_stale",
    "IMAGE_SUFFIXES",
    "exr_parts",
    "read_image",
    "srgb_decode",
    "srgb_encode",
    "write_image",
    "parse_view_name",
    "read_lightfield",
    "view_name",
    "write_lightfield",
]
