"""The grid of patches every reconstruction and dictionary training uses (one definition)."""

from __future__ import annotations

import numpy as np

from ..errors import InputError, ShapeError

__all__ = ["patch_grid"]


def patch_grid(size: tuple[int, int], patch: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Top (or left) corners of patches of ``patch`` pixels every ``stride`` pixels covering ``size``.

    Per axis: ``0, stride, 2 stride, ...`` up to ``size - patch``, plus ``size - patch`` when the
    grid does not reach the border (so every pixel is covered).

    Returns
    -------
    tops, lefts : 1-D int arrays (the grid is their outer product)
    """
    patch, stride = int(patch), int(stride)
    if patch < 1 or stride < 1:
        raise InputError(f"patch grid: expected positive patch size and stride, got {patch} and {stride}")
    out = []
    for n in size:
        if n < patch:
            raise ShapeError(f"patch grid: patches of {patch} pixels do not fit a sensor of {tuple(size)} pixels")
        axis = np.arange(0, n - patch + 1, stride)
        if axis[-1] != n - patch:
            axis = np.append(axis, n - patch)
        out.append(axis.astype(np.intp))
    return out[0], out[1]
