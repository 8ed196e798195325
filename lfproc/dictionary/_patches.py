"""Training patches from HDR light fields.

A patch is ``V x U`` views by ``P x P`` pixels by ``C`` colours, vectorised in C order of
``(V, U, P, P, C)`` (the order of :class:`lfproc.dictionary.Dictionary` atoms). Light fields
with more views than the patch contribute their central ``V x U`` views.

Selection rule (documented, seeded): candidate positions are drawn uniformly; a patch is
*empty* when its l2 norm is 0 (rejected) and *flat* when its coefficient of variation
(standard deviation over mean of all its samples) is below ``flat_cv`` = 0.02; flat patches
are kept with probability ``flat_keep`` = 0.1, so the few atoms that represent smooth
regions are still learned without flat patches dominating the training set.

Normalisation (``normalise="l2"``, lfproc's choice): every patch is divided by its l2 norm.
HDR patches span many orders of magnitude; without normalisation the brightest patches
(a lamp, the sun) dominate the squared error of K-SVD and the dictionary learns their
shapes only. The reconstruction is linear and per patch, so a scale-free dictionary loses
nothing: it solves each patch in linear radiance with its own scale. ``"none"`` keeps the
radiance (for comparison; ``benchmarks/dictionary_normalisation.py`` measures both).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._shared.random import check_random_state
from ..errors import InputError, MissingFileError, ShapeError
from ..lightfield import LightField
from ..io.lightfield_files import parse_view_name

__all__ = ["extract_patches", "training_patches", "collect_lightfields", "NORMALISATIONS"]

NORMALISATIONS = ("l2", "none")


def _check_patch(patch) -> tuple[int, int, int, int, int]:
    try:
        patch = tuple(int(p) for p in patch)
    except (TypeError, ValueError):
        raise InputError(f"patch: expected (V, U, P, P, C), got {patch!r}") from None
    if len(patch) != 5 or min(patch) < 1 or patch[2] != patch[3]:
        raise InputError(f"patch: expected 5 positive integers (V, U, P, P, C), got {list(patch)}")
    return patch


def _data(lf, patch, where: str = "light field") -> np.ndarray:
    """The central ``V x U`` views of a light field, checked against the patch."""
    data = lf.data if isinstance(lf, LightField) else np.asarray(lf)
    if data.ndim != 5:
        raise ShapeError(f"{where}: expected shape (V, U, H, W, C), got {data.shape}")
    v, u, p, _, c = patch
    nv, nu, h, w, nc = data.shape
    if nv < v or nu < u:
        raise ShapeError(f"{where}: has {nv} x {nu} views; the patch needs at least {v} x {u}")
    if nc != c:
        raise ShapeError(f"{where}: has {nc} colours; the patch needs {c}")
    if h < p or w < p:
        raise ShapeError(f"{where}: views of {h} x {w} pixels are smaller than the {p} x {p} patch")
    ov, ou = (nv - v) // 2, (nu - u) // 2
    return data[ov:ov + v, ou:ou + u]


def extract_patches(lf, patch, tops, lefts) -> np.ndarray:
    """Patches at ``(tops[i], lefts[i])``: ``(N, n)`` float32 (C order of ``(V, U, P, P, C)``)."""
    patch = _check_patch(patch)
    data = _data(lf, patch)
    p = patch[2]
    tops = np.asarray(tops, dtype=np.intp)
    lefts = np.asarray(lefts, dtype=np.intp)
    win = np.lib.stride_tricks.sliding_window_view(data, (p, p), axis=(2, 3))  # (V, U, H', W', C, P, P)
    out = win[:, :, tops, lefts]  # (V, U, N, C, P, P)
    return np.ascontiguousarray(out.transpose(2, 0, 1, 4, 5, 3), dtype=np.float32).reshape(len(tops), -1)


def _flat_or_empty(x: np.ndarray, flat_cv: float) -> tuple[np.ndarray, np.ndarray]:
    x64 = x.astype(np.float64)
    norm = np.sqrt((x64 * x64).sum(axis=1))
    mean = x64.mean(axis=1)
    std = x64.std(axis=1)
    empty = norm <= 0
    flat = ~empty & (std <= flat_cv * np.abs(mean))
    return empty, flat


def training_patches(
    lightfields: Sequence[Any],
    *,
    patch,
    n_patches: int,
    normalise: str = "l2",
    flat_cv: float = 0.02,
    flat_keep: float = 0.1,
    random_state=None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Random training patches from HDR light fields (see the module documentation).

    Parameters
    ----------
    lightfields : sequence of LightField or arrays (V, U, H, W, C)
    patch : (V, U, P, P, C)
    n_patches : int
        How many patches in all; spread over the light fields in proportion to their
        number of patch positions.
    normalise : {"l2", "none"}
    flat_cv, flat_keep : the flat-patch rule.
    random_state : int, Generator or None

    Returns
    -------
    patches : ndarray of shape (n_patches, n), float32
    info : dict
        ``per_source`` counts, ``rejected_empty``, ``rejected_flat``, ``kept_flat`` and the rule.

    Raises
    ------
    InputError
        No light fields, an unknown normalisation, a bad count, or too few usable patches.
    """
    patch = _check_patch(patch)
    if normalise not in NORMALISATIONS:
        raise InputError(f"normalise: expected one of {', '.join(NORMALISATIONS)}, got {normalise!r}")
    if isinstance(n_patches, bool) or int(n_patches) != n_patches or int(n_patches) < 1:
        raise InputError(f"patches: expected a positive integer, got {n_patches!r}")
    if not lightfields:
        raise InputError("training patches: expected at least one light field")
    rng = check_random_state(random_state)
    datas = [_data(lf, patch, where=getattr(lf, "source", None) or f"light field {i + 1}")
             for i, lf in enumerate(lightfields)]
    p = patch[2]
    positions = np.array([(d.shape[2] - p + 1) * (d.shape[3] - p + 1) for d in datas], dtype=np.float64)
    quota = np.floor(positions / positions.sum() * n_patches).astype(int)
    quota[np.argsort(-positions)[: n_patches - quota.sum()]] += 1
    out = np.empty((int(n_patches), math.prod(patch)), dtype=np.float32)
    filled = 0
    stats = {"rejected_empty": 0, "rejected_flat": 0, "kept_flat": 0}
    per_source = []
    for data, want in zip(datas, quota):
        got = 0
        h, w = data.shape[2:4]
        for _attempt in range(50):
            if got >= want:
                break
            m = max(64, int(2 * (want - got)))
            tops = rng.integers(0, h - p + 1, m)
            lefts = rng.integers(0, w - p + 1, m)
            cand = extract_patches(data, patch, tops, lefts)
            empty, flat = _flat_or_empty(cand, flat_cv)
            keep_flat = flat & (rng.random(m) < flat_keep)
            ok = ~empty & (~flat | keep_flat)
            stats["rejected_empty"] += int(empty.sum())
            stats["rejected_flat"] += int((flat & ~keep_flat).sum())
            cand = cand[ok][: want - got]
            stats["kept_flat"] += int(keep_flat[ok][: want - got].sum()) if cand.size else 0
            out[filled:filled + len(cand)] = cand
            filled += len(cand)
            got += len(cand)
        per_source.append(got)
    if filled < n_patches:
        raise InputError(f"training patches: found only {filled} usable patches of {n_patches} "
                         "(the light fields are too small, empty or flat)")
    if normalise == "l2":
        # in chunks: a float64 copy of the paper preset's 7.3 GB of patches would need 14.6 GB more
        for s in range(0, len(out), 8192):
            block = out[s:s + 8192]
            block /= np.linalg.norm(block.astype(np.float64), axis=1)[:, None].astype(np.float32)
    info = {"per_source": per_source, **stats, "normalise": normalise, "flat_cv": flat_cv, "flat_keep": flat_keep,
            "patch": list(patch)}
    return out, info


def collect_lightfields(sources: Sequence[str | os.PathLike]) -> list[Path]:
    """Light-field files from paths: files and view folders as they are; a data set built by
    ``lfproc dataset build`` (a folder with ``manifest.json``) contributes its scenes' ``hdr.exr``;
    any other folder its ``*.exr`` files."""
    found: list[Path] = []
    for src in sources:
        path = Path(src)
        if not path.exists():
            raise MissingFileError(f"{path}: no such light field, folder or data set")
        if path.is_file():
            found.append(path)
        elif (path / "manifest.json").is_file() and (path / "scenes").is_dir():
            found.extend(sorted((path / "scenes").glob("*/hdr.exr")))
        elif any(parse_view_name(f.stem) for f in path.iterdir() if f.is_file()):
            found.append(path)
        else:
            exrs = sorted(path.glob("*.exr"))
            if not exrs:
                raise InputError(f"{path}: no light fields in this folder (expected view_RR_CC files, *.exr files "
                                 "or a data set with manifest.json)")
            found.extend(exrs)
    return found
