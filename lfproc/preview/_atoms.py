"""A picture of a dictionary's atoms (``lfproc preview DICT``); moved here from ``lfproc.dictionary._preview``."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..dictionary import Dictionary

__all__ = ["render_atoms"]


def render_atoms(dictionary: Dictionary, *, count: int = 32, zoom: int = 8, columns: int = 8, **_options) -> np.ndarray:
    """Centre view and horizontal EPI of the ``count`` most used atoms (by index without usage counts).

    Each cell shows the atom's centre view (``P x P`` pixels) above its horizontal
    epipolar-plane image at the centre pixel row (``U`` views by ``P`` pixels: slanted lines are
    parallax), both magnified ``zoom`` times; values are mapped per atom from ``-max|a|`` (black)
    through 0 (mid grey) to ``+max|a|`` (white), colour kept.

    Parameters
    ----------
    dictionary : Dictionary
    count : int, default 32
        Atoms shown (clipped to ``1..K``); the most used first when the dictionary has usage
        counts, else the first ``count``.
    zoom : int, default 8
        Magnification (screen pixels per atom sample).
    columns : int, default 8
        Cells per row.
    **_options
        Ignored (other preview options).

    Returns
    -------
    ndarray of shape (H, W, 3), uint8

    Raises
    ------
    InputError
        Not a Dictionary.
    """
    if not isinstance(dictionary, Dictionary):
        raise InputError(f"atoms preview: expected a Dictionary, got {type(dictionary).__name__}")
    count = max(1, min(int(count), dictionary.n_atoms))
    order = (np.argsort(-dictionary.usage, kind="stable") if dictionary.usage is not None
             else np.arange(dictionary.n_atoms))[:count]
    v, u, p, _, c = dictionary.patch
    atoms = dictionary.atom_patches()[order].astype(np.float64)  # (count, V, U, P, P, C)
    scale = np.abs(atoms).reshape(count, -1).max(axis=1)
    atoms = 0.5 + 0.5 * atoms / np.where(scale > 0, scale, 1)[:, None, None, None, None, None]
    if c == 1:
        atoms = np.repeat(atoms, 3, axis=-1)
    centre = atoms[:, v // 2, u // 2]  # (count, P, P, 3)
    epi = atoms[:, v // 2, :, p // 2]  # (count, U, P, 3)
    gap = max(2, zoom // 2)
    cell_h = (p + u) * zoom + gap
    cell_w = p * zoom
    columns = max(1, min(int(columns), count))
    rows = -(-count // columns)
    out = np.full((rows * (cell_h + gap) + gap, columns * (cell_w + gap) + gap, 3), 0.16)
    for i in range(count):
        r, q = divmod(i, columns)
        y0, x0 = gap + r * (cell_h + gap), gap + q * (cell_w + gap)
        out[y0:y0 + p * zoom, x0:x0 + cell_w] = np.kron(centre[i], np.ones((zoom, zoom, 1)))
        y1 = y0 + p * zoom + gap
        out[y1:y1 + u * zoom, x0:x0 + cell_w] = np.kron(epi[i], np.ones((zoom, zoom, 1)))
    return np.clip(np.rint(out * 255), 0, 255).astype(np.uint8)
