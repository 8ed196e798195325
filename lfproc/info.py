"""Describe any file lfproc understands: light fields, images, Lytro files, coded captures
and camera profiles.

:func:`describe` looks at the file and hands it to the describer of its kind; each
returns a JSON-serialisable dict whose first key is ``kind``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from .errors import FileFormatError, MissingFileError
from .io.images import exr_parts
from .io.lightfield_files import read_lightfield
from .lightfield import LightField
from .camera.capture import describe_capture, is_capture_file
from .lytro.capture import describe_lytro
from .lytro.container import is_lfp
from .sensor import describe_profile, is_profile_file, load_profile

__all__ = ["describe", "describe_lightfield"]


def describe_lightfield(lf: LightField) -> dict[str, Any]:
    """Figures of a light field: shape, value range, dynamic range, saturation, metadata.

    Parameters
    ----------
    lf : LightField

    Returns
    -------
    dict
        ``kind`` (``"image"`` for one view, else ``"lightfield"``), ``views``, ``size``,
        ``channels``, ``min``/``max``/``mean``, ``dynamic_range_stops``, ``saturated_fraction``,
        ``units``, ``colour_space``, ``exposure_s``, ``iso``, ``has_variance``,
        ``has_disparity``, ``source`` and ``attrs``.
    """
    data = lf.data
    kind = "image" if lf.views == (1, 1) else "lightfield"
    return {
        "kind": kind,
        "views": list(lf.views),
        "size": list(lf.size),
        "channels": lf.channels,
        "min": float(data.min()),
        "max": float(data.max()),
        "mean": float(data.mean(dtype=np.float64)),
        "dynamic_range_stops": lf.dynamic_range_stops(),
        "saturated_fraction": lf.saturated_fraction(),
        "units": lf.units,
        "colour_space": lf.colour_space,
        "exposure_s": lf.exposure_s,
        "iso": lf.iso,
        "has_variance": lf.variance is not None,
        "has_disparity": lf.disparity is not None,
        "source": lf.source,
        "attrs": dict(lf.attrs),
    }


def _is_lfp(path: Path) -> bool:
    return is_lfp(path)


def _describe_json(path: Path) -> dict[str, Any]:
    """A camera profile (``schema: lfproc.camera_profile``); any other JSON is named as such."""
    import json

    if is_profile_file(path):
        out = describe_profile(load_profile(path))
        out["path"] = str(path)
        return out
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise FileFormatError(f"{path}: not a JSON file ({exc})") from None
    schema = doc.get("schema") if isinstance(doc, dict) else None
    raise FileFormatError(
        f"{path}: a JSON file that lfproc info does not describe (schema {schema!r}); it describes camera profiles "
        f"(schema 'lfproc.camera_profile'), light fields, images, Lytro files and coded captures")


def describe(path: str | os.PathLike, **read_options) -> dict[str, Any]:
    """Describe the file or folder at ``path`` (see the module documentation).

    Parameters
    ----------
    path : str or path-like
        A Lytro file (``.lfr``, ``.lfp``, ``.raw``), a coded capture, a camera profile
        (``.json``), or a light field or image file or folder.
    **read_options
        Passed to :func:`lfproc.io.read_lightfield` for light fields and images.

    Returns
    -------
    dict
        JSON-serialisable figures whose first key is ``kind``; light fields as
        :func:`describe_lightfield` plus ``path`` (and ``exr_parts`` for EXR files).

    Raises
    ------
    MissingFileError
        No such file or folder.
    FileFormatError
        A file lfproc does not read (for example JSON that is not a camera profile).
    """
    path = Path(path)
    if not path.exists():
        raise MissingFileError(f"{path}: no such file or folder")
    if path.is_file() and (path.suffix.lower() in (".lfr", ".lfp", ".raw") or _is_lfp(path)):
        return describe_lytro(path)

    if is_capture_file(path):
        return describe_capture(path)
    if path.is_file() and path.suffix.lower() == ".json":
        return _describe_json(path)
    lf = read_lightfield(path, **read_options)
    out = describe_lightfield(lf)
    out["path"] = str(path)
    if path.is_file() and path.suffix.lower() == ".exr":
        out["exr_parts"] = len(exr_parts(path))
    return out
