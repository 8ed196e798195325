"""Training presets, the synthetic training set of the shipped dictionary, and evaluation.

Presets (:data:`PRESETS`):

``paper``
    The paper's dictionary: 5 x 5 views x 9 x 9 pixels x RGB (n = 6075), K = 16402 atoms
    (overcompleteness 2.7), sparsity 10, 20 iterations, 300,000 patches.
``default``
    The dictionary lfproc ships (``load_dictionary("default")``), chosen so that the
    float16 file stays under 25 MB and a full Lytro-size reconstruction takes minutes on
    2 cores: see README ("The shipped dictionary") for the measurements behind the choice.
``tiny``
    A small dictionary for tests (seconds to train).

The shipped default is trained on lfproc's own procedural scenes only
(:func:`synthetic_lightfields`: every :mod:`lfproc.synth` scene kind, a range of seeds and
baselines), so anyone can reproduce it bit for bit on the same machine and thread count with
``lfproc dictionary train --synthetic --preset default --seed 0 -o default.npz``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._shared.deprecate import renamed_keywords, resolve_options
from .._shared.validation import check_choice
from .._shared.progress import progress
from .._version import __version__
from ..errors import InputError, option_name
from ..lightfield import LightField
from ._dct import dct_dictionary
from ._files import Dictionary, load_dictionary
from ._ksvd import ksvd
from ._omp import gram_matrix, omp_codes
from ._patches import _data, extract_patches, training_patches
from .._shared.patches import patch_grid
from ..metrics import pu21_psnr
from ..synth import SCENES, synthesize

__all__ = ["Preset", "PRESETS", "TrainingSizes", "synthetic_lightfields", "train_dictionary", "evaluate_dictionary", "approximate"]


@dataclass(frozen=True)
class Preset:
    """Sizes of a training run (:data:`PRESETS`: ``tiny``, ``default``, ``paper``).

    Parameters
    ----------
    patch : tuple of 5 int
        Patch shape ``(V, U, P, P, C)``: views, pixels, colours.
    atoms : int
        Number of atoms ``K``.
    sparsity : int
        Atoms per training patch in the K-SVD coding step.
    iterations : int
        K-SVD iterations.
    patches : int
        Number of training patches drawn.
    synthetic_scenes : int, default 48
        Scenes of the synthetic training set (``--synthetic``).
    synthetic_size : tuple of 2 int, default (128, 128)
        View size ``(H, W)`` of the synthetic scenes.
    """

    patch: tuple[int, int, int, int, int]
    atoms: int
    sparsity: int
    iterations: int
    patches: int
    #: Synthetic training set (``--synthetic``): scenes and view size.
    synthetic_scenes: int = 48
    synthetic_size: tuple[int, int] = (128, 128)


PRESETS: dict[str, Preset] = {
    "tiny": Preset(patch=(5, 5, 4, 4, 3), atoms=1200, sparsity=6, iterations=4, patches=6000, synthetic_scenes=8,
                   synthetic_size=(64, 64)),
    "default": Preset(patch=(5, 5, 8, 8, 3), atoms=2560, sparsity=10, iterations=10, patches=32000,
                      synthetic_scenes=48, synthetic_size=(128, 128)),
    "paper": Preset(patch=(5, 5, 9, 9, 3), atoms=16402, sparsity=10, iterations=20, patches=300000,
                    synthetic_scenes=240, synthetic_size=(160, 160)),
}

@dataclass(frozen=True)
class TrainingSizes:
    """Overrides of a :class:`Preset`'s sizes in :func:`train_dictionary` (None: the preset's):
    patch ``(V, U, P, P, C)``, atoms, atoms per training patch, K-SVD iterations (all run), patches.

    Parameters
    ----------
    patch : tuple of 5 int, optional
        ``(V, U, P, P, C)`` of the atoms.
    atoms, n_nonzero_coefs, max_iter, patches : int, optional
        Atoms, atoms per training patch, K-SVD iterations and training patches.
    """

    patch: tuple[int, int, int, int, int] | None = None
    atoms: int | None = None
    n_nonzero_coefs: int | None = None
    max_iter: int | None = None
    patches: int | None = None


#: Baselines (largest |disparity|, pixels per view step) cycled through the synthetic scenes.
SYNTHETIC_BASELINES = (0.5, 1.0, 1.5, 2.0, 0.25, 3.0)


def get_preset(name: str) -> Preset:
    """The dictionary-training preset of this name.

    Parameters
    ----------
    name : {"tiny", "default", "paper"}

    Returns
    -------
    Preset

    Raises
    ------
    InputError
        An unknown name.

    Examples
    --------
    >>> from lfproc.dictionary import get_preset
    >>> p = get_preset("paper")
    >>> p.patch, p.atoms, p.sparsity
    ((5, 5, 9, 9, 3), 16402, 10)
    """
    check_choice("preset", name, tuple(PRESETS))
    return PRESETS[name]


@renamed_keywords(seed="random_state")
def synthetic_lightfields(n_scenes: int, *, views: tuple[int, int] = (5, 5), size: tuple[int, int] = (128, 128),
                          random_state: int = 0) -> Iterable[LightField]:
    """``n_scenes`` procedural HDR light fields: every scene kind in turn, seeds ``random_state * 1000 + i``,
    baselines cycled from :data:`SYNTHETIC_BASELINES` (the keyword ``seed`` is deprecated)."""
    kinds = sorted(SCENES)
    if views[0] != views[1]:
        raise InputError(f"synthetic light fields: expected square views, got {views}")
    for i in range(int(n_scenes)):
        yield synthesize(kinds[i % len(kinds)], size=size, views=views[0],
                         baseline_px=SYNTHETIC_BASELINES[(i // len(kinds)) % len(SYNTHETIC_BASELINES)],
                         random_state=int(random_state) * 1000 + i)


def _describe_sources(lightfields: Sequence[Any]) -> list[str]:
    return [getattr(lf, "source", None) or f"array {i}" for i, lf in enumerate(lightfields)]


@renamed_keywords(seed="random_state", sparsity="n_nonzero_coefs", iterations="max_iter")
def train_dictionary(
    lightfields: Sequence[Any] | None = None,
    *,
    preset: str = "default",
    sizes: TrainingSizes | None = None,
    synthetic: bool = False,
    normalise: str = "l2",
    random_state: int = 0,
    checkpoint=None,
    scheduler: str | None = None,
    command: str | None = None,
    sources: Sequence[str] | None = None,
    **size_overrides,
) -> Dictionary:
    """Train a dictionary with K-SVD on HDR light fields (see the module documentation).

    Parameters
    ----------
    lightfields : sequence of LightField, optional
        Training light fields (their central views as the patch needs).
    preset : {"tiny", "default", "paper"}
        Sizes; the keyword arguments below override them.
    synthetic : bool
        Add the preset's synthetic training set (:func:`synthetic_lightfields`).
    sizes : TrainingSizes, optional
        Overrides of the preset's sizes: ``patch``, ``atoms``, ``n_nonzero_coefs``, ``max_iter``,
        ``patches`` (None: the preset's). Give either ``sizes`` or these fields as keywords, not both.
    patch, atoms, n_nonzero_coefs, max_iter, patches : overrides of the preset (``**size_overrides``).
        ``n_nonzero_coefs``: atoms per training patch (the preset's ``sparsity``); ``max_iter``: K-SVD
        iterations (all are run; the preset's ``iterations``). The keywords ``sparsity`` and
        ``iterations`` are deprecated.
    normalise : {"l2", "none"}
        Patch normalisation (:mod:`lfproc.dictionary._patches`).
    random_state : int
        Seeds the synthetic scenes, the patch draw and K-SVD (recorded as ``"seed"``; the keyword
        ``seed`` is deprecated).
    checkpoint : folder, optional
        K-SVD checkpoints (a killed run resumes there).
    scheduler : str, optional
        Dask scheduler address for the sparse-coding step.
    command : str, optional
        The command line, recorded in the file.
    sources : sequence of str, optional
        Names of ``lightfields`` recorded in the file (default: each light field's ``source``).

    Returns
    -------
    Dictionary

    Raises
    ------
    InputError
        No light fields, a bad seed, or ``sources`` of another length.
    """
    p = get_preset(preset)
    sizes = resolve_options(TrainingSizes, sizes, size_overrides, func_name="train_dictionary", argument="sizes")
    patch = tuple(int(x) for x in (sizes.patch or p.patch))
    atoms = int(sizes.atoms or p.atoms)
    sparsity = int(sizes.n_nonzero_coefs or p.sparsity)
    iterations = int(p.iterations if sizes.max_iter is None else sizes.max_iter)
    n_patches = int(sizes.patches or p.patches)
    seed = random_state
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise InputError(f"random_state: expected a non-negative integer, got {seed!r}")
    lfs = list(lightfields or [])
    if sources is not None and len(sources) != len(lfs):
        raise InputError(f"sources: expected one name per light field ({len(lfs)}), got {len(sources)}")
    data_desc: dict[str, Any] = {"files": list(map(str, sources)) if sources is not None else _describe_sources(lfs)}
    if synthetic:
        lfs += list(progress(synthetic_lightfields(p.synthetic_scenes, views=patch[:2], size=p.synthetic_size,
                                                   random_state=seed), total=p.synthetic_scenes, desc="synthetic scenes"))
        data_desc["synthetic"] = {"scenes": p.synthetic_scenes, "size": list(p.synthetic_size), "seed": int(seed),
                                  "baselines_px": list(SYNTHETIC_BASELINES), "lfproc_version": __version__}
    if not lfs:
        raise InputError(f"training: no light fields (give files, or {option_name('synthetic=True', '--synthetic')})")
    x, info = training_patches(lfs, patch=patch, n_patches=n_patches, normalise=normalise, random_state=seed)
    del lfs
    result = ksvd(x, atoms, sparsity, iterations, random_state=seed, checkpoint=checkpoint, scheduler=scheduler)
    provenance = {
        "command": command,
        "data": data_desc,
        "seed": int(seed),
        "iterations": iterations,
        "training_patches": n_patches,
        "patch_selection": {k: info[k] for k in ("rejected_empty", "rejected_flat", "kept_flat", "flat_cv", "flat_keep")},
        "errors": [round(e, 8) for e in result.errors],
        "final_relative_error": round(result.final_error, 8),
        "replaced_atoms": result.replaced,
        "lfproc_version": __version__,  # no timings: the file depends only on the data, seed and sizes
    }
    return Dictionary(atoms=result.atoms, patch=patch, sparsity=sparsity, preset=preset,
                      normalisation={"kind": normalise}, provenance=provenance, usage=result.usage, name="trained")


@renamed_keywords(sparsity="n_nonzero_coefs")
def approximate(dictionary: Dictionary, lf, *, n_nonzero_coefs: int | None = None,
                stride: int | None = None) -> np.ndarray:
    """The sparse approximation of a light field: every patch on a grid (``stride``, default
    half the patch) normalised, coded with ``n_nonzero_coefs`` atoms (default: the dictionary's
    sparsity; the keyword ``sparsity`` is deprecated), rescaled; overlaps averaged.

    Parameters
    ----------
    dictionary : Dictionary, str or path-like
        Anything :func:`load_dictionary` accepts.
    lf : LightField or array_like of shape (V', U', H, W, C)
        At least the dictionary's views; its central ``V x U`` views are approximated.
    n_nonzero_coefs : int, optional
        Atoms per patch (Batch-OMP); default the dictionary's sparsity.
    stride : int, optional
        Patch step in pixels, ``1..P``; default ``P // 2``.

    Returns
    -------
    ndarray of shape (V, U, H, W, C), float32
        The approximation of the central ``V x U`` views.

    Raises
    ------
    InputError
        A stride out of range.
    ShapeError
        A light field smaller than the patch or of other colours.
    """
    d = load_dictionary(dictionary)
    t = int(n_nonzero_coefs or d.sparsity)
    v, u, p, _, c = d.patch
    data = lf.data if isinstance(lf, LightField) else np.asarray(lf)

    data = _data(data, d.patch, where=getattr(lf, "source", None) or "light field")
    stride = int(stride or max(1, p // 2))
    if stride < 1 or stride > p:
        raise InputError(f"stride: expected 1..{p} (the patch size), got {stride}")
    h, w = data.shape[2:4]

    tops, lefts = (a.ravel() for a in np.meshgrid(*patch_grid((h, w), p, stride), indexing="ij"))
    acc = np.zeros((v, u, h, w, c), dtype=np.float64)
    count = np.zeros((h, w), dtype=np.float64)
    gram = gram_matrix(d.atoms)
    chunk = 4096
    for s in range(0, len(tops), chunk):
        ty, tx = tops[s:s + chunk], lefts[s:s + chunk]
        x = extract_patches(data, d.patch, ty, tx)
        norms = np.linalg.norm(x.astype(np.float64), axis=1)
        scale = np.where(norms > 0, norms, 1.0).astype(np.float32)
        idx, val = omp_codes(d.atoms, x / scale[:, None], t, gram=gram)
        approx = np.zeros_like(x)
        atoms_t = d.atoms.T
        for k in range(t):
            used = idx[:, k] >= 0
            approx[used] += val[used, k, None] * atoms_t[idx[used, k]]
        approx *= scale[:, None]
        patches = approx.reshape(len(ty), v, u, p, p, c)
        for i, (y0, x0) in enumerate(zip(ty, tx)):
            acc[:, :, y0:y0 + p, x0:x0 + p] += patches[i]
            count[y0:y0 + p, x0:x0 + p] += 1
    return (acc / count[None, None, :, :, None]).astype(np.float32)


@renamed_keywords(sparsity="n_nonzero_coefs")
def evaluate_dictionary(dictionary, lightfields: Sequence[Any], *, n_nonzero_coefs: int | None = None,
                        stride: int | None = None, compare_dct: bool = True,
                        peak_luminance: float = 1000.0) -> dict[str, Any]:
    """Sparse-approximation quality of light fields with a dictionary, beside a DCT of the same size.

    Parameters
    ----------
    dictionary : Dictionary, name or path
    lightfields : sequence of LightField
    n_nonzero_coefs : int, optional
        Atoms per patch (default: the dictionary's sparsity; the keyword ``sparsity`` is deprecated).
    stride : int, optional (default: half the patch)
    compare_dct : bool
        Also score a separable 4-D DCT dictionary with the same number of atoms.
    peak_luminance : float
        Display peak the reference's maximum is mapped to for PU21 (``lfproc.metrics``).

    Returns
    -------
    dict
        ``relative_error`` (``||L_hat - L|| / ||L||``), ``pu21_psnr_db`` and, with
        ``compare_dct``, ``dct_relative_error`` and ``dct_pu21_psnr_db``: means over the
        light fields; ``lightfields``: the same per light field.

    Raises
    ------
    InputError
        No light fields, or ``n_nonzero_coefs`` out of range.
    """
    d = load_dictionary(dictionary)
    if not lightfields:
        raise InputError("evaluate: expected at least one light field")
    t = int(n_nonzero_coefs or d.sparsity)
    if not 1 <= t <= min(d.n, d.n_atoms):
        raise InputError(f"n_nonzero_coefs: expected 1..{min(d.n, d.n_atoms)}, got {n_nonzero_coefs}")
    dct = dct_dictionary(d.patch, d.n_atoms, n_nonzero_coefs=t) if compare_dct else None
    rows = []
    start = time.perf_counter()
    for i, lf in enumerate(lightfields):
        ref = _data(lf, d.patch, where=getattr(lf, "source", None) or f"light field {i + 1}").astype(np.float32)
        row: dict[str, Any] = {"source": getattr(lf, "source", None) or f"light field {i + 1}"}
        for prefix, dic in (("", d), ("dct_", dct)):
            if dic is None:
                continue
            approx = np.maximum(approximate(dic, ref, n_nonzero_coefs=t, stride=stride), 0)
            err = float(np.linalg.norm((approx - ref).astype(np.float64)) / max(np.linalg.norm(ref.astype(np.float64)),
                                                                                  1e-300))
            row[f"{prefix}relative_error"] = err
            row[f"{prefix}pu21_psnr_db"] = pu21_psnr(approx, ref, peak_luminance=peak_luminance, channel_axis=-1)
        rows.append(row)
    keys = [k for k in rows[0] if k != "source"]
    out: dict[str, Any] = {k: float(np.mean([r[k] for r in rows])) for k in keys}
    out.update({"dictionary": d.name, "atoms": d.n_atoms, "patch": list(d.patch), "sparsity": t,
                "stride": int(stride or max(1, d.patch[2] // 2)), "peak_luminance_cd_m2": peak_luminance,
                "seconds": round(time.perf_counter() - start, 2), "lightfields": rows})
    if compare_dct:
        out["gain_over_dct_db"] = out["pu21_psnr_db"] - out["dct_pu21_psnr_db"]
    return out


def preset_table() -> dict[str, dict[str, Any]]:
    """The presets as plain data (for ``--help`` and README)."""
    return {k: {**asdict(v), "n": math.prod(v.patch)} for k, v in PRESETS.items()}
