"""Separable 4-D DCT dictionaries: the analytic baseline the learned ones are compared with."""

from __future__ import annotations

import math

import numpy as np

from .._shared.deprecate import renamed_keywords
from ..errors import InputError
from ._files import Dictionary

__all__ = ["dct_dictionary"]

#: Orthonormal colour basis: luminance-like, then two opponent axes.
_COLOUR_BASIS = np.array([[1, 1, 1], [1, 0, -1], [1, -2, 1]], dtype=np.float64)
_COLOUR_BASIS /= np.linalg.norm(_COLOUR_BASIS, axis=1, keepdims=True)


def _dct_1d(size: int, atoms: int) -> np.ndarray:
    """``atoms`` cosines sampled on ``size`` points, unit norm: ``(size, atoms)`` (overcomplete when atoms > size)."""
    x = np.arange(size)
    k = np.arange(atoms)
    basis = np.cos(np.pi * (2 * x[:, None] + 1) * k[None, :] / (2 * atoms))
    return basis / np.linalg.norm(basis, axis=0, keepdims=True)


@renamed_keywords(sparsity="n_nonzero_coefs")
def dct_dictionary(patch: tuple[int, int, int, int, int], n_atoms: int | None = None, *,
                   n_nonzero_coefs: int = 10) -> Dictionary:
    """A separable DCT dictionary over views, pixels and colours with ``n_atoms`` atoms.

    Each of the four axes ``(V, U, P, P)`` gets ``a_i = ceil(size_i * r)`` cosines (``r`` the
    fourth root of the overcompleteness ``n_atoms / n``, at least 1), the colour axis an
    orthonormal luminance/opponent basis; atoms are Kronecker products of these, and the
    ``n_atoms`` of lowest total frequency (sum of the normalised frequencies, ties broken
    by colour then index) are kept. With ``n_atoms = n`` it is the orthonormal 4-D DCT-II.

    Parameters
    ----------
    patch : (V, U, P, P, C)
        Patch shape (C is 1 or 3).
    n_atoms : int, optional
        Number of atoms (default ``n``).
    n_nonzero_coefs : int
        Recorded sparsity (used by :func:`lfproc.dictionary.evaluate_dictionary`; the keyword
        ``sparsity`` is deprecated).

    Returns
    -------
    Dictionary
        ``preset="dct"``.

    Raises
    ------
    InputError
        A patch that is not ``(V, U, P, P, C)`` with C in (1, 3), or a number of atoms below 1
        or above the available frequency combinations.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.dictionary import dct_dictionary
    >>> d = dct_dictionary((5, 5, 4, 4, 3))  # complete: the orthonormal 4-D DCT
    >>> d.atoms.shape, d.patch, d.preset
    ((1200, 1200), (5, 5, 4, 4, 3), 'dct')
    >>> bool(np.allclose(d.atoms.T @ d.atoms, np.eye(1200), atol=1e-5))
    True
    >>> dct_dictionary((5, 5, 4, 4, 3), 2400).atoms.shape  # twice overcomplete
    (1200, 2400)
    """
    patch = tuple(int(p) for p in patch)
    if len(patch) != 5 or min(patch) < 1 or patch[4] not in (1, 3):
        raise InputError(f"dct patch: expected (V, U, P, P, C) with C in (1, 3), got {patch}")
    n = math.prod(patch)
    k = n if n_atoms is None else int(n_atoms)
    if k < 1:
        raise InputError(f"dct atoms: expected a positive number, got {n_atoms}")
    r = max(1.0, (k / n) ** 0.25)
    counts = [max(s, math.ceil(s * r)) if s > 1 else 1 for s in patch[:4]]
    bases = [_dct_1d(s, a) for s, a in zip(patch[:4], counts)]
    colour = np.eye(1) if patch[4] == 1 else _COLOUR_BASIS.T  # (C, C) columns are atoms
    # total normalised frequency of every (f_v, f_u, f_y, f_x, c) combination
    freq = np.zeros(tuple(counts) + (patch[4],))
    for axis, a in enumerate(counts):
        shape = [1] * 5
        shape[axis] = a
        freq = freq + (np.arange(a) / a).reshape(shape)
    order = np.lexsort((np.arange(freq.size), np.broadcast_to(np.arange(patch[4]), freq.shape).ravel(), freq.ravel()))
    if k > freq.size:
        raise InputError(f"dct atoms: at most {freq.size} for patch {list(patch)}, got {k}")
    chosen = np.unravel_index(order[:k], freq.shape)
    atoms = np.ones((k,) + patch)
    for axis, (basis, idx) in enumerate(zip(bases + [colour], chosen)):
        # basis[:, idx] has shape (size_axis, k): put it on the patch axis
        values = basis[:, idx].T  # (k, size_axis)
        shape = [k, 1, 1, 1, 1, 1]
        shape[axis + 1] = patch[axis]
        atoms = atoms * values.reshape(shape)
    atoms = atoms.reshape(k, n).T
    atoms /= np.linalg.norm(atoms, axis=0, keepdims=True)
    return Dictionary(atoms=atoms.astype(np.float32), patch=patch, sparsity=min(n_nonzero_coefs, k, n), preset="dct",
                      normalisation={"kind": "l2"}, provenance={"kind": "separable 4-D DCT", "counts": counts},
                      name=f"dct{list(patch)}x{k}")
