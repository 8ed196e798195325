"""K-SVD dictionary learning (approximate atom update), streaming, checkpointed, seeded.

Written by hand: no maintained Python K-SVD exists (the PyPI ``ksvd`` package uses
scikit-learn's OMP, which copies the Gram matrix per signal, and drops negative
coefficients).

Each iteration:

1. sparse coding of every training signal with Batch-OMP (:func:`lfproc.dictionary.omp_codes`),
   in chunks, optionally on a Dask cluster (``scheduler=``), and the residual
   ``E = X - D Gamma`` (signals as rows, float32);
2. the approximate K-SVD update of Rubinstein et al. (2008) for every atom ``j`` in a random
   order, written on the residual so no product with the whole dictionary is needed: for
   the signals ``I`` that use ``j`` with coefficients ``g``, ``d = E_I^T g + d_j (g . g)`` (that is
   ``X_I^T g - D Gamma_I g + d_j (g . g)``), normalised, ``g <- E_I d + g (d_j . d)``, then
   ``E_I <- E_I + g_old d_j^T - g d^T``, reading ``E_I`` in bounded chunks;
3. atoms used by no signal, used by fewer than ``min_usage`` signals, or too close to
   another atom (``|<d_i, d_j>| > max_coherence``) are replaced by the training signals with
   the largest residual among all of them, skipping a signal within ``max_coherence`` of an
   atom (KSVD-box's ``cleardict``).

Memory: the training signals can be a ``.npy`` file read in chunks; what stays in memory is
the residual (``N x n`` float32), the dictionary, its Gram matrix and the codes. The atom
update reads the residual rows of an atom's users in chunks of 32 MiB and never copies
``E_I`` (the previous update did, with two outer-product temporaries of the same size: the
peak of 10.3 GB measured at the paper's size, README). For the paper's preset (300,000 x 6075)
the residual alone is 7.3 GB.

Checkpoints: after every finished iteration the dictionary, the iteration count, the random
generator's state and the error history are written (atomically) to ``checkpoint``; a run
given the same checkpoint, data and parameters resumes after the last finished iteration
and ends with the same dictionary as an uninterrupted run.

References
----------
.. [1] M. Aharon, M. Elad, A. Bruckstein, "K-SVD: An Algorithm for Designing Overcomplete
   Dictionaries for Sparse Representation", IEEE TSP 54(11), 2006. doi:10.1109/TSP.2006.881199
.. [2] R. Rubinstein, M. Zibulevsky, M. Elad, "Efficient Implementation of the K-SVD
   Algorithm using Batch Orthogonal Matching Pursuit", Technion CS-2008-08, 2008.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._shared.deprecate import renamed_keywords
from .._shared.deps import require
from .._shared.random import check_random_state
from .._shared.progress import progress
from .._shared.parallel import realign
from .._shared.reprs import short_repr
from ..errors import FileFormatError, InputError, ShapeError
from ..io._atomic import atomic_file
from ._omp import gram_matrix, omp_codes

__all__ = ["ksvd", "KsvdResult", "TrainingSignals"]

CHECKPOINT_NAME = "ksvd-checkpoint.npz"


class TrainingSignals:
    """Training signals as rows ``(N, n)`` float32: an array in memory or a ``.npy`` file read in chunks."""

    def __init__(self, source):
        if isinstance(source, TrainingSignals):
            self.array, self.path, self.shape = source.array, source.path, source.shape
            return
        if isinstance(source, (str, os.PathLike)):
            self.path = Path(source)
            try:
                mm = np.load(self.path, mmap_mode="r", allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise FileFormatError(f"{self.path}: not a readable .npy array of training signals ({exc})") from None
            if mm.ndim != 2 or mm.dtype != np.float32:
                raise FileFormatError(f"{self.path}: expected a 2-D float32 array (N, n), found {mm.dtype} {mm.shape}")
            self.shape = mm.shape
            self.array = None
            del mm
        else:
            array = np.asarray(source)
            if array.ndim != 2:
                raise ShapeError(f"training signals: expected shape (N, n), got {array.shape}")
            if not np.issubdtype(array.dtype, np.floating):
                raise InputError(f"training signals: expected floating-point values, got {array.dtype}")
            self.array = np.ascontiguousarray(array, dtype=np.float32)
            self.path = None
            self.shape = self.array.shape

    def rows(self, start: int, stop: int) -> np.ndarray:
        if self.array is not None:
            return self.array[start:stop]
        mm = np.load(self.path, mmap_mode="r", allow_pickle=False)
        out = np.array(mm[start:stop], dtype=np.float32)
        del mm
        return out

    def fingerprint(self) -> str:
        """A hash of the shape and a sample of rows (identifies the data for checkpoints)."""
        h = hashlib.sha256(json.dumps(list(self.shape)).encode())
        n = self.shape[0]
        for i in sorted({0, n // 3, n // 2, n - 1}):
            h.update(self.rows(i, i + 1).tobytes())
        return h.hexdigest()[:16]


@short_repr
@dataclass
class KsvdResult:
    """What :func:`ksvd` returns.

    Parameters
    ----------
    atoms : ndarray of shape (n, K), float32
        The learned dictionary, unit-norm columns.
    errors : list of float
        Relative squared error ``||X - D G||^2 / ||X||^2`` after each iteration's coding.
    final_error : float
        The same for the returned dictionary.
    usage : ndarray of shape (K,)
        Number of training signals using each atom (final coding).
    iterations : int
        Iterations run.
    replaced : list of int, default []
        Atoms replaced (unused or duplicated) in each iteration.
    seconds : float, default 0.0
        Wall-clock time of the run.
    resumed_from : int, default 0
        Iteration of the checkpoint the run resumed from (0: a fresh start).
    """

    atoms: np.ndarray  #: (n, K) float32, unit-norm columns
    errors: list[float]  #: relative squared error ||X - D G||^2 / ||X||^2 after each iteration's coding
    final_error: float  #: the same for the returned dictionary
    usage: np.ndarray  #: (K,) signals using each atom (final coding)
    iterations: int
    replaced: list[int] = field(default_factory=list)  #: atoms replaced in each iteration
    seconds: float = 0.0
    resumed_from: int = 0


def _code_chunk(atoms, gram, rows, sparsity):
    atoms, gram, rows = realign((atoms, gram, rows))  # in a Dask worker: the in-process sums (lfproc._util.realign)
    return omp_codes(atoms, rows, sparsity, gram=gram)


def _code_all(signals: TrainingSignals, atoms: np.ndarray, sparsity: int, chunk: int, client, bar_desc: str):
    """Codes (N, T) and the residual E (N, n) of every signal; also ||X||^2."""
    n_sig, n = signals.shape
    gram = gram_matrix(atoms)
    idx = np.empty((n_sig, sparsity), dtype=np.int32)
    val = np.empty((n_sig, sparsity), dtype=np.float32)
    resid = np.empty((n_sig, n), dtype=np.float32)
    x_norm2 = 0.0
    starts = list(range(0, n_sig, chunk))
    atoms_t = np.ascontiguousarray(atoms.T)  # (K, n): one atom per row
    pending: dict[int, Any] = {}
    if client is not None:
        # a window of chunks in flight, so the signals are never all in memory at once
        d_f, g_f = client.scatter([atoms, gram], broadcast=True)
        window = 2 * max(1, len(client.scheduler_info().get("workers", {})))
        upcoming = iter(starts)

        def submit_next():
            s0 = next(upcoming, None)
            if s0 is not None:
                pending[s0] = client.submit(_code_chunk, d_f, g_f, signals.rows(s0, min(s0 + chunk, n_sig)), sparsity,
                                            pure=False)

        for _ in range(window):
            submit_next()
    for s in progress(starts, desc=bar_desc):
        e = min(s + chunk, n_sig)
        x = signals.rows(s, e)
        if client is None:
            i, v = omp_codes(atoms, x, sparsity, gram=gram)
        else:
            i, v = pending.pop(s).result()
            submit_next()
        idx[s:e], val[s:e] = i, v
        r = resid[s:e]
        r[...] = x
        for t in range(sparsity):  # subtract D Gamma, one selection slot at a time (bounded memory)
            used = i[:, t] >= 0
            r[used] -= v[used, t, None] * atoms_t[i[used, t]]
        x_norm2 += float(np.einsum("ij,ij->", x, x, dtype=np.float64))
    return idx, val, resid, x_norm2, gram


def _atom_users(idx: np.ndarray, n_atoms: int) -> tuple[np.ndarray, np.ndarray]:
    flat = idx.ravel()
    order = np.argsort(flat, kind="stable")
    counts = np.bincount(flat[flat >= 0], minlength=n_atoms)
    n_unused_slots = int((flat < 0).sum())
    order = order[n_unused_slots:]  # the -1 slots sort first
    bounds = np.concatenate([[0], np.cumsum(counts)])
    return order, bounds


#: Bytes of residual rows gathered at once by the atom update (:func:`_update_atoms`).
_UPDATE_CHUNK_BYTES = 32 * 2**20


def _update_atoms(atoms_t, idx, val, resid, rng, sparsity) -> list[int]:
    """The approximate K-SVD update of every atom (in place on atoms_t, val, resid); returns unused atoms.

    For atom ``j``, its users ``I`` and their coefficients ``g`` (Rubinstein et al. 2008; KSVD-box's
    ``optimize_atom``): ``d = E_I^T g + d_j (g . g)`` (``E_I^T g = X_I^T g - D Gamma_I g``: the residual without
    atom ``j`` times ``g``), ``d /= ||d||``, ``g <- E_I d + g (d_j . d)``, ``E_I <- E_I + g_old d_j^T - g d^T``.
    The residual rows of ``I`` are read in bounded chunks (two passes): ``E_I`` is never copied whole
    (a popular atom's ``E_I`` and its outer-product temporaries were gigabytes at the paper's size).
    """
    n_atoms, n = atoms_t.shape
    order, bounds = _atom_users(idx, n_atoms)
    val_flat = val.reshape(-1)
    step = max(1, _UPDATE_CHUNK_BYTES // (4 * n))
    unused = []
    for j in rng.permutation(n_atoms):
        pos = order[bounds[j]:bounds[j + 1]]
        if pos.size == 0:
            unused.append(int(j))
            continue
        sig = pos // sparsity
        g = val_flat[pos]
        dj = atoms_t[j].copy()
        d = dj * np.float32(np.dot(g, g))
        for s0 in range(0, len(sig), step):  # d = E_I^T g + d_j (g . g)
            d += resid[sig[s0:s0 + step]].T @ g[s0:s0 + step]
        nd = float(np.linalg.norm(d.astype(np.float64)))
        if not nd > 0:
            unused.append(int(j))
            continue
        d /= np.float32(nd)
        djd = np.float32(np.dot(dj, d))
        g_new = np.empty_like(g)
        pair = np.stack([dj, d])  # (2, n)
        for s0 in range(0, len(sig), step):  # g = E_I d + g (d_j . d); E_I <- E_I + g_old d_j^T - g d^T
            rows = sig[s0:s0 + step]
            part = resid[rows]
            gc = g[s0:s0 + step]
            gn = part @ d + gc * djd
            part += np.stack([gc, -gn], axis=1) @ pair
            resid[rows] = part
            g_new[s0:s0 + step] = gn
        atoms_t[j] = d
        val_flat[pos] = g_new
    return unused


def _clear_atoms(atoms_t, signals: TrainingSignals, resid, idx, unused, *, min_usage, max_coherence):
    """Replace unused, rarely used and near-duplicate atoms with the worst-represented signals (KSVD-box's ``cleardict``).

    The candidates are all training signals in decreasing order of their residual energy; a candidate
    whose normalised signal has ``|<x, d_i>| > max_coherence`` with an atom that stays (or one already put in)
    is skipped, so the replacements are neither duplicates of each other nor of the dictionary.
    """
    n_atoms, n = atoms_t.shape
    usage = np.bincount(idx[idx >= 0], minlength=n_atoms)
    replace = set(unused) | set(np.flatnonzero(usage < min_usage).tolist())
    # near-duplicates: of each close pair (a < b), replace b; the Gram matrix in row blocks (bounded memory)
    block = max(1, (64 * 2**20) // (4 * n_atoms))
    for r0 in range(0, n_atoms, block):
        g = atoms_t[r0:r0 + block] @ atoms_t.T
        a, b = np.nonzero(np.abs(g) > max_coherence)
        replace |= {int(j) for j in b[b > a + r0]}
    if not replace:
        return []
    n_sig = resid.shape[0]
    step = max(1, _UPDATE_CHUNK_BYTES // (4 * n))
    err = np.concatenate([np.einsum("ij,ij->i", resid[s0:s0 + step], resid[s0:s0 + step], dtype=np.float64)
                          for s0 in range(0, n_sig, step)])
    worst = np.argsort(-err, kind="stable")
    worst = worst[err[worst] > 0]
    todo = sorted(replace)
    staying = np.ones(n_atoms, dtype=bool)
    staying[todo] = False
    accepted: list[np.ndarray] = []  # normalised signals put in, in order
    done = []
    # candidates in blocks: their coherence with the staying atoms, with the signals already put in and with
    # each other are GEMMs (one pass over the dictionary per block; a product per candidate read it whole)
    limit = min(len(worst), 2 * len(todo) + 64)
    block = 1024
    for c0 in range(0, limit, block):
        if len(done) == len(todo):
            break
        cand = worst[c0:min(c0 + block, limit)]
        x = np.stack([signals.rows(int(i), int(i) + 1)[0] for i in cand]).astype(np.float64)
        nx = np.linalg.norm(x, axis=1)
        good = nx > 0
        x = (x[good] / nx[good, None]).astype(np.float32)
        if not len(x):
            continue
        coh = np.zeros(len(x), dtype=np.float32)
        for r0 in range(0, n_atoms, 4096):
            rows = np.flatnonzero(staying[r0:r0 + 4096]) + r0
            if rows.size:
                coh = np.maximum(coh, np.abs(atoms_t[rows] @ x.T).max(axis=0))
        if accepted:
            coh = np.maximum(coh, np.abs(np.stack(accepted) @ x.T).max(axis=0))
        mutual = np.abs(x @ x.T)
        taken: list[int] = []
        for i in range(len(x)):
            if len(done) == len(todo):
                break
            if coh[i] > max_coherence or (taken and mutual[i, taken].max() > max_coherence):
                continue  # (nearly) an atom already
            j = todo[len(done)]
            atoms_t[j] = x[i]
            taken.append(i)
            accepted.append(x[i])
            done.append(j)
    return done


def _init_atoms(signals: TrainingSignals, n_atoms: int, rng) -> np.ndarray:
    n_sig, n = signals.shape
    chosen = np.sort(rng.choice(n_sig, size=n_atoms, replace=False))
    atoms_t = np.stack([signals.rows(int(i), int(i) + 1)[0] for i in chosen]).astype(np.float64)
    norms = np.linalg.norm(atoms_t, axis=1)
    bad = ~(norms > 0)
    if bad.any():  # an all-zero training signal: a random atom instead
        atoms_t[bad] = rng.standard_normal((int(bad.sum()), n))
        norms = np.linalg.norm(atoms_t, axis=1)
    return (atoms_t / norms[:, None]).astype(np.float32)


def _save_checkpoint(path: Path, atoms_t, iteration, rng, errors, replaced, params) -> None:
    state = json.dumps(rng.bit_generator.state)
    with atomic_file(path, force=True) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, atoms_t=atoms_t, iteration=np.int64(iteration), rng_state=np.array(state),
                     errors=np.asarray(errors, dtype=np.float64), replaced=np.asarray(replaced, dtype=np.int64),
                     params=np.array(json.dumps(params, sort_keys=True)))


def _load_checkpoint(path: Path, params, rng):
    try:
        with np.load(path, allow_pickle=False) as z:
            saved = json.loads(str(z["params"]))
            if saved != params:
                diff = sorted(k for k in set(saved) | set(params) if saved.get(k) != params.get(k))
                raise InputError(f"{path}: checkpoint of another training run (differs in {', '.join(diff)}); "
                                 "use another --checkpoint folder or remove it")
            atoms_t = np.array(z["atoms_t"], dtype=np.float32)
            iteration = int(z["iteration"])
            rng.bit_generator.state = json.loads(str(z["rng_state"]))
            errors = [float(e) for e in z["errors"]]
            replaced = [int(r) for r in z["replaced"]]
    except InputError:
        raise
    except (OSError, ValueError, KeyError) as exc:
        raise FileFormatError(f"{path}: unreadable K-SVD checkpoint ({exc})") from None
    return atoms_t, iteration, errors, replaced


@renamed_keywords(sparsity="n_nonzero_coefs", n_iter="max_iter")
def ksvd(
    signals,
    n_atoms: int,
    n_nonzero_coefs: int,
    max_iter: int,
    *,
    random_state=None,
    checkpoint: str | os.PathLike | None = None,
    scheduler: str | None = None,
    chunk_size: int = 2048,
    min_usage: int = 4,
    max_coherence: float = 0.99,
    callback: Callable[[int, float], None] | None = None,
) -> KsvdResult:
    """Learn a dictionary with K-SVD (see the module documentation).

    Parameters
    ----------
    signals : ndarray of shape (N, n), path of a .npy file, or TrainingSignals
        Training signals as rows (float32).
    n_atoms : int
        Number of atoms ``K`` (at most ``N``).
    n_nonzero_coefs : int
        Atoms per signal in the sparse-coding step (the keyword ``sparsity`` is deprecated).
    max_iter : int
        Iterations (all are run; the keyword ``n_iter`` is deprecated).
    random_state : int, Generator or None
        Seeds the initial atoms (``K`` distinct training signals) and the order of the atom
        updates (the replacement of atoms is deterministic: the worst-represented signals).
    checkpoint : path of a folder, optional
        Save after every iteration and resume from what is there.
    scheduler : str, optional
        Address of a Dask scheduler for the sparse-coding step (same result as in process).
    chunk_size : int
        Signals per sparse-coding chunk (and per Dask task).
    min_usage, max_coherence : the atom replacement rule.
    callback : callable(iteration, error), optional
        Called after every iteration (used by tests to interrupt a run).

    Returns
    -------
    KsvdResult

    Raises
    ------
    InputError
        Sizes out of range (more atoms than signals, a sparsity above ``min(n, K)``), or a
        checkpoint without an integer seed.
    """
    signals = TrainingSignals(signals)
    n_sig, n = signals.shape
    sparsity, n_iter = n_nonzero_coefs, max_iter
    for name, value, low in (("n_atoms", n_atoms, 1), ("n_nonzero_coefs", sparsity, 1), ("max_iter", n_iter, 0),
                             ("chunk_size", chunk_size, 1)):
        if isinstance(value, bool) or int(value) != value or int(value) < low:
            raise InputError(f"{name}: expected an integer >= {low}, got {value!r}")
    if n_atoms > n_sig:
        raise InputError(f"n_atoms: {n_atoms} atoms need at least as many training signals; got {n_sig}")
    if sparsity > min(n, n_atoms):
        raise InputError(f"n_nonzero_coefs: expected at most {min(n, n_atoms)} for {n_atoms} atoms of length {n}, got {sparsity}")
    seed_ok = random_state is None or isinstance(random_state, (int, np.integer))
    if checkpoint is not None and (random_state is None or not seed_ok):
        raise InputError("checkpoint: a resumable run needs an integer seed (random_state)")
    rng = check_random_state(random_state)
    params = {"n_atoms": int(n_atoms), "sparsity": int(sparsity), "n_iter": int(n_iter), "chunk_size": int(chunk_size),
              "min_usage": int(min_usage), "max_coherence": float(max_coherence),
              "seed": None if random_state is None else int(random_state) if seed_ok else "generator",
              "signals": [int(n_sig), int(n)], "fingerprint": signals.fingerprint()}
    ckpt = None
    if checkpoint is not None:
        ckpt_dir = Path(checkpoint)
        ckpt_dir.mkdir(parents=True, exist_ok=True)
        ckpt = ckpt_dir / CHECKPOINT_NAME
    start_time = time.perf_counter()
    errors: list[float] = []
    replaced: list[int] = []
    done = 0
    if ckpt is not None and ckpt.is_file():
        atoms_t, done, errors, replaced = _load_checkpoint(ckpt, params, rng)
        resumed_from = done
    else:
        atoms_t = _init_atoms(signals, int(n_atoms), rng)
        resumed_from = 0
    client = None
    if scheduler is not None:
        require("distributed", purpose="K-SVD on a Dask scheduler (--scheduler)")
        from distributed import Client

        client = Client(scheduler, set_as_default=False)
    try:
        for it in range(done, int(n_iter)):
            idx, val, resid, x_norm2, _ = _code_all(signals, atoms_t.T, int(sparsity), int(chunk_size), client,
                                                   f"K-SVD {it + 1}/{n_iter}: coding")
            err = float(np.einsum("ij,ij->", resid, resid, dtype=np.float64)) / max(x_norm2, 1e-300)
            errors.append(err)
            unused = _update_atoms(atoms_t, idx, val, resid, rng, int(sparsity))
            cleared = _clear_atoms(atoms_t, signals, resid, idx, unused, min_usage=int(min_usage),
                                   max_coherence=float(max_coherence))
            replaced.append(len(cleared))
            del idx, val, resid
            if ckpt is not None:
                _save_checkpoint(ckpt, atoms_t, it + 1, rng, errors, replaced, params)
            if callback is not None:
                callback(it + 1, err)
        idx, val, resid, x_norm2, _ = _code_all(signals, atoms_t.T, int(sparsity), int(chunk_size), client,
                                               "K-SVD: final coding")
    finally:
        if client is not None:
            client.close()
    final = float(np.einsum("ij,ij->", resid, resid, dtype=np.float64)) / max(x_norm2, 1e-300)
    usage = np.bincount(idx[idx >= 0], minlength=int(n_atoms))
    return KsvdResult(atoms=np.ascontiguousarray(atoms_t.T), errors=errors, final_error=final, usage=usage,
                      iterations=int(n_iter), replaced=replaced, seconds=time.perf_counter() - start_time,
                      resumed_from=resumed_from)
