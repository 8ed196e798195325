"""Lytro Illum and F01 captures: containers, raw images, calibration data, decoding."""

from .caldata import (WhiteFrame, geometry_correction_bytes, iter_caldata, read_caldata, white_metadata,
                      white_txt_document, write_caldata_tar)
from .capture import LytroCapture, cfa_from_mosaic, describe_lytro, normalise_camera_model, read_capture
from .container import (LFP_MAGIC, LfpContainer, LfpSection, build_lfp, illum_metadata, is_lfp, read_lfp, sha1_ref,
                        write_lfp, write_lfr)
from .raw import pack_raw10, pack_raw12, raw_byte_count, unpack_raw, unpack_raw10, unpack_raw12

__all__ = [
    "LFP_MAGIC", "LfpSection", "LfpContainer", "read_lfp", "is_lfp", "build_lfp", "write_lfp", "write_lfr",
    "illum_metadata", "sha1_ref",
    "unpack_raw", "unpack_raw10", "pack_raw10", "unpack_raw12", "pack_raw12", "raw_byte_count",
    "LytroCapture", "read_capture", "describe_lytro", "normalise_camera_model", "cfa_from_mosaic",
    "WhiteFrame", "read_caldata", "iter_caldata", "write_caldata_tar", "white_metadata", "white_txt_document",
    "geometry_correction_bytes",
]
