"""The files of a bench folder: its scenes (cropped light fields, cached per process) and its
cell files. Used by :mod:`lfproc.bench.run` (which writes them) and :mod:`lfproc.bench.report`
(which reads them), so neither imports the other.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..io import read_lightfield

__all__ = ["BenchScene", "load_scene", "read_cells", "read_centre"]

_SCENE_CACHE: dict[tuple, Any] = {}


@dataclass(frozen=True)
class BenchScene:
    """A scene of the bench: its name (file stem), path, SHA-256 and the crop used."""

    name: str
    path: str
    sha256: str
    crop: tuple[int, int, int, int] | None  # top, left, height, width
    views: tuple[int, int]
    size: tuple[int, int]
    nonfinite: str = "raise"  # value policies the scene is read with (lfproc bench --nonfinite, --negative)
    negative: str = "raise"


def load_scene(scene: BenchScene):
    """The scene's light field, cropped (cached per process: workers read each scene once)."""
    key = (scene.path, scene.sha256, scene.crop, scene.nonfinite, scene.negative)
    if key not in _SCENE_CACHE:
        lf = read_lightfield(scene.path, nonfinite=scene.nonfinite, negative=scene.negative)
        if scene.crop is not None:
            lf = lf.crop(*scene.crop)
        _SCENE_CACHE.clear()  # one scene per worker at a time bounds the memory
        _SCENE_CACHE[key] = lf
    return _SCENE_CACHE[key]


def _cell_path(cells_dir: Path, cid: str) -> Path:
    return cells_dir / f"{cid}.npz"


def read_cells(paths: list[Path]) -> list[dict[str, Any]]:
    """The rows of cell files (skipping any that cannot be read: they are recomputed)."""
    rows = []
    for path in paths:
        try:
            with np.load(path, allow_pickle=False) as z:
                rows.append(json.loads(str(z["row"])))
        except (OSError, ValueError, KeyError):
            continue
    return rows


def read_centre(bench_dir: str | os.PathLike, cid: str) -> np.ndarray:
    """The reconstructed centre view stored with a cell."""
    with np.load(_cell_path(Path(bench_dir) / "cells", cid), allow_pickle=False) as z:
        return np.array(z["centre"])
