"""Lytro Illum and F01 captures: decoding raw lenslet images into light fields (the decode stage).

* :func:`decode_capture`: a Lytro raw capture (``.lfr``/``.lfp``/``.raw``) into its central
  ``n x n`` views, with the white image of its camera (:mod:`lfproc.lytro.decode`);
* :func:`read_capture`, :class:`LytroCapture`, :func:`describe_lytro`: the raw image and
  metadata of a capture (:mod:`lfproc.lytro.capture`);
* :func:`extract_lfp`: the images, depth maps and metadata a Lytro file holds;
* :func:`build_white_db`, :func:`load_white_db`, :func:`estimate_grid`: white-image databases
  and lenslet grids from calibration data (:func:`read_caldata`);
* :func:`make_virtual_illum`: render a light field into Illum captures + calibration data;
* :func:`score_decode`: compare a decode with its ground truth.

The container, raw-packing and calibration-data helpers stay in their modules
(:mod:`~lfproc.lytro.container`, :mod:`~lfproc.lytro.raw`, :mod:`~lfproc.lytro.caldata`); their
former names here (``lfproc.lytro.read_lfp`` ...) still resolve.
"""

from . import caldata, container, raw
from . import capture as _capture
from .caldata import read_caldata
from .capture import LytroCapture, describe_lytro, read_capture
from .container import is_lfp, read_lfp
from .decode import DEMOSAIC_METHODS, decode_capture
from .extract import extract_lfp
from .grid import LensletGrid, estimate_grid
from .score import score_decode
from .virtual import make_virtual_illum
from .whites import build_white_db, load_white_db

__all__ = [
    "decode_capture", "DEMOSAIC_METHODS", "read_capture", "LytroCapture", "describe_lytro", "is_lfp", "read_lfp",
    "extract_lfp", "read_caldata", "build_white_db", "load_white_db", "estimate_grid", "LensletGrid",
    "make_virtual_illum", "score_decode",
]

_FORMER = (caldata, _capture, container, raw)  # where the names this package exported before live


def __getattr__(name):  # former exports (container, raw and calibration-data helpers)
    for module in _FORMER:
        if name in module.__all__:
            return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
