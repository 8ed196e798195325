"""K-SVD dictionary learning (approximate atom update), streaming, checkpointed, seeded.

Written by hand: no maintained Python K-SVD exists (the PyPI ``ksvd`` package uses
scikit-learn's OMP, which copies the Gram matrix per signal, and drops negative
coefficients).

Each iteration:

1. sparse coding of every training signal with Batch-OMP (:func:`lfproc.dictionary.omp_codes`),
   streaming the signals in chunks, optionally on a Dask cluster (``scheduler=``); the codes
   are kept compactly (``N x T`` indices and values), the residual energy is summed per chunk;
2. the approximate K-SVD update of Rubinstein et al. (2008) for every atom ``j`` in a random
   order, written without the residual: for the signals ``I`` that use ``j`` with coefficients
   ``g`` and the other atoms ``S`` they use, ``d = X_I^T g - D_S (Gamma_S g)``, normalised, then
   ``g <- X_I d - Gamma_S^T (D_S^T d)`` (the same as the update on the residual without atom ``j``);
3. atoms used by no signal, used by fewer than ``min_usage`` signals, or too close to
   another atom (``|<d_i, d_j>| > max_coherence``) are replaced by the training signals with
   the largest residual among all of them, skipping a signal within ``max_coherence`` of an
   atom (KSVD-box's ``cleardict``); the residual energies come from one more streaming pass.

Memory: the training signals can be a ``.npy`` file, read with explicit reads (chunks for the
coding, the rows of an atom's users for its update), so they are never resident as a whole.
What stays in memory is the dictionary (``K x n``), its Gram matrix (``K x K``, during the
coding), the codes (``N x T``) and buffers of bounded size. An earlier version kept the residual
``E = X - D Gamma`` (``N x n`` float32: 7.3 GB for the paper's 300,000 x 6075, peak 9.6 GiB).

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
from scipy.sparse import csr_array

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
    """Training signals as rows ``(N, n)`` float32: an array in memory or a ``.npy`` file read in chunks.

    A file is read with explicit reads (``os.preadv`` into the caller's buffers), never memory-mapped while
    training: mapped pages that were touched count in the process's resident memory, and the paper's
    300,000 patches are 7.3 GB."""

    def __init__(self, source):
        self._fd = None
        if isinstance(source, TrainingSignals):
            self.array, self.path, self.shape = source.array, source.path, source.shape
            self._offset = source._offset
            return
        self._offset = 0
        if isinstance(source, (str, os.PathLike)):
            self.path = Path(source)
            try:
                with open(self.path, "rb") as fh:
                    version = np.lib.format.read_magic(fh)
                    read_header = {(1, 0): np.lib.format.read_array_header_1_0,
                                   (2, 0): np.lib.format.read_array_header_2_0}.get(version)
                    if read_header is None:
                        raise ValueError(f".npy format version {version}")
                    shape, fortran, dtype = read_header(fh)
                    self._offset = fh.tell()
            except (OSError, ValueError) as exc:
                raise FileFormatError(f"{self.path}: not a readable .npy array of training signals ({exc})") from None
            if len(shape) != 2 or dtype != np.float32 or fortran:
                raise FileFormatError(f"{self.path}: expected a 2-D float32 array (N, n), found {dtype} {shape}"
                                      + (" in Fortran order" if fortran else ""))
            self.shape = tuple(int(v) for v in shape)
            if self.path.stat().st_size < self._offset + 4 * self.shape[0] * self.shape[1]:
                raise FileFormatError(f"{self.path}: truncated .npy array of training signals")
            self.array = None
        else:
            array = np.asarray(source)
            if array.ndim != 2:
                raise ShapeError(f"training signals: expected shape (N, n), got {array.shape}")
            if not np.issubdtype(array.dtype, np.floating):
                raise InputError(f"training signals: expected floating-point values, got {array.dtype}")
            self.array = np.ascontiguousarray(array, dtype=np.float32)
            self.path = None
            self.shape = self.array.shape

    def _file(self) -> int:
        if self._fd is None:
            self._fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_BINARY", 0))
        return self._fd

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown
            pass

    def _read(self, row: int, out: np.ndarray) -> None:
        """Rows ``row .. row + len(out)`` of the file into ``out`` (C-contiguous float32)."""
        view = memoryview(out.reshape(-1).view(np.uint8))
        pos, want = self._offset + 4 * row * self.shape[1], view.nbytes
        while want:
            got = os.preadv(self._file(), [view[view.nbytes - want:]], pos) if hasattr(os, "preadv") else None
            if got is None:  # no preadv (not POSIX): seek and read
                os.lseek(self._file(), pos, os.SEEK_SET)
                got = os.readv(self._file(), [view[view.nbytes - want:]])
            if got <= 0:
                raise FileFormatError(f"{self.path}: truncated .npy array of training signals")
            pos += got
            want -= got

    def rows(self, start: int, stop: int, out: np.ndarray | None = None) -> np.ndarray:
        """Rows ``start:stop`` (a copy for a file; into ``out`` if given)."""
        if self.array is not None and out is None:
            return self.array[start:stop]
        stop = min(stop, self.shape[0])
        if out is None:
            out = np.empty((max(0, stop - start), self.shape[1]), dtype=np.float32)
        else:
            out = out[:max(0, stop - start)]
        if self.array is not None:
            out[...] = self.array[start:stop]
        elif len(out):
            self._read(start, out)
        return out

    def take(self, rows: np.ndarray, out: np.ndarray) -> np.ndarray:
        """The rows ``rows`` (increasing) into ``out[:len(rows)]``; runs of consecutive rows are one read each."""
        out = out[:len(rows)]
        if self.array is not None:
            np.take(self.array, rows, axis=0, out=out, mode="clip")  # "clip": no hidden temporary copy
            return out
        if not len(rows):
            return out
        breaks = np.flatnonzero(np.diff(rows) != 1) + 1
        starts = np.concatenate([[0], breaks]).tolist()
        stops = np.concatenate([breaks, [len(rows)]]).tolist()
        first = rows[starts].tolist()
        for a, b, r in zip(starts, stops, first):
            self._read(r, out[a:b])
        return out

    def fingerprint(self) -> str:
        """A hash of the shape and a sample of rows (identifies the data for checkpoints)."""
        h = hashlib.sha256(json.dumps(list(self.shape)).encode())
        n = self.shape[0]
        for i in sorted({0, n // 3, n // 2, n - 1}):
            h.update(np.ascontiguousarray(self.rows(i, i + 1)).tobytes())
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


def _codes_matrix(idx: np.ndarray, val: np.ndarray, n_atoms: int):
    """Codes ``(B, T)`` as a CSR matrix ``(B, K)`` (unused slots: index 0, value 0)."""
    b, t = idx.shape
    return csr_array((val.reshape(-1), np.maximum(idx, 0).reshape(-1), np.arange(0, b * t + 1, t)), shape=(b, n_atoms))


def _residual_energy(x: np.ndarray, idx: np.ndarray, val: np.ndarray, atoms_t: np.ndarray) -> np.ndarray:
    """``||x_i - D c_i||^2`` of each row (float64); ``D c`` as one sparse-times-dense product (reads the used atoms)."""
    r = _codes_matrix(idx, val, atoms_t.shape[0]) @ atoms_t
    np.subtract(x, r, out=r)
    return np.einsum("ij,ij->i", r, r, dtype=np.float64)


def _code_all(signals: TrainingSignals, atoms_t: np.ndarray, sparsity: int, chunk: int, client, bar_desc: str):
    """Codes (N, T) of every signal, streaming the signals in chunks; also the total residual energy
    ``||X - D Gamma||^2`` and ``||X||^2``. Memory: the Gram matrix, the codes and one chunk (no residual)."""
    n_sig, n = signals.shape
    atoms = atoms_t.T  # (n, K), a view
    gram = gram_matrix(atoms)
    idx = np.empty((n_sig, sparsity), dtype=np.int32)
    val = np.empty((n_sig, sparsity), dtype=np.float32)
    x_norm2 = err2 = 0.0
    starts = list(range(0, n_sig, chunk))
    buf = np.empty((min(chunk, n_sig), n), dtype=np.float32) if signals.array is None else None
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
        if client is None:
            x = signals.rows(s, e, out=buf)
            i, v = omp_codes(atoms, x, sparsity, gram=gram)
        else:
            i, v = pending.pop(s).result()
            submit_next()
            x = signals.rows(s, e, out=buf)
        idx[s:e], val[s:e] = i, v
        err2 += float(_residual_energy(x, i, v, atoms_t).sum())
        x_norm2 += float(np.einsum("ij,ij->", x, x, dtype=np.float64))
    del gram
    return idx, val, err2, x_norm2


def _signal_errors(signals: TrainingSignals, atoms_t, idx, val, chunk: int) -> np.ndarray:
    """``||x_i - D c_i||^2`` of every signal (float64, ``N``), streaming the signals in chunks."""
    n_sig, n = signals.shape
    buf = np.empty((min(chunk, n_sig), n), dtype=np.float32) if signals.array is None else None
    out = np.empty(n_sig)
    for s in range(0, n_sig, chunk):
        e = min(s + chunk, n_sig)
        out[s:e] = _residual_energy(signals.rows(s, e, out=buf), idx[s:e], val[s:e], atoms_t)
    return out


def _atom_users(idx: np.ndarray, n_atoms: int) -> tuple[np.ndarray, np.ndarray]:
    flat = idx.ravel()
    order = np.argsort(flat, kind="stable")
    counts = np.bincount(flat[flat >= 0], minlength=n_atoms)
    n_unused_slots = int((flat < 0).sum())
    order = order[n_unused_slots:]  # the -1 slots sort first
    bounds = np.concatenate([[0], np.cumsum(counts)])
    return order, bounds


#: Bytes of training-signal rows gathered at once by the atom update (:func:`_update_atoms`).
_UPDATE_CHUNK_BYTES = 64 * 2**20
#: Atoms gathered at once by the atom update: a block that stays in cache for its product (gathering all of
#: ``D_S``, 40 MB for an average atom at the paper's size, then two products over it read it three times from
#: memory; measured 45 vs 50-100 ms per such atom, the larger figure with two BLAS threads under load).
_ATOM_BLOCK = 64


def _update_atoms(atoms_t, idx, val, signals: TrainingSignals, rng, sparsity) -> list[int]:
    """The approximate K-SVD update of every atom (in place on atoms_t and val); returns unused atoms.

    For atom ``j``, its users ``I``, their coefficients ``g`` and the other atoms ``S`` they use with
    coefficients ``Gamma_S`` (Rubinstein et al. 2008, written without the residual):
    ``d = X_I^T g - D_S (Gamma_S g)``, ``d /= ||d||``, ``g <- X_I d - Gamma_S^T (D_S^T d)``. This is the update on
    the residual without atom ``j`` (``d = E_I^T g + d_j (g . g)``, ``g <- E_I d + g (d_j . d)``), with the current
    atoms and coefficients, so atoms updated earlier in the sweep are seen by later ones. Memory: the rows
    ``X_I`` are gathered into a buffer of at most :data:`_UPDATE_CHUNK_BYTES` (an atom with more users than fit
    is done in chunks, reading them twice), the atoms ``D_S`` in blocks of :data:`_ATOM_BLOCK` (read twice).
    No ``N x n`` residual is kept (7.3 GB at the paper's size).
    """
    n_atoms, n = atoms_t.shape
    order, bounds = _atom_users(idx, n_atoms)
    val_flat = val.reshape(-1)
    step = max(1, _UPDATE_CHUNK_BYTES // (4 * n))
    most = int(np.diff(bounds).max(initial=0))  # users of the most popular atom
    xbuf = np.empty((min(step, most), n), dtype=np.float32)
    dbuf = np.empty((_ATOM_BLOCK, n), dtype=np.float32)
    unused = []
    for j in rng.permutation(n_atoms):
        pos = order[bounds[j]:bounds[j + 1]]
        if pos.size == 0:
            unused.append(int(j))
            continue
        sig = pos // sparsity  # increasing
        g = val_flat[pos]
        ci, cv = idx[sig], val[sig]  # (|I|, T): the users' codes
        other = (ci != j) & (ci >= 0)
        atoms_s, inv = np.unique(ci[other], return_inverse=True)
        h = np.bincount(inv, weights=(cv * g[:, None])[other].astype(np.float64), minlength=len(atoms_s))
        h = h.astype(np.float32)
        x_once = len(sig) <= step
        d = np.zeros(n, dtype=np.float32)
        for s0 in range(0, len(sig), step):  # X_I^T g
            x = signals.take(sig[s0:s0 + step], xbuf)
            d += g[s0:s0 + step] @ x
        for a0 in range(0, len(atoms_s), _ATOM_BLOCK):  # - D_S (Gamma_S g)
            part = atoms_s[a0:a0 + _ATOM_BLOCK]
            d -= h[a0:a0 + _ATOM_BLOCK] @ np.take(atoms_t, part, axis=0, out=dbuf[:len(part)], mode="clip")
        nd = float(np.linalg.norm(d.astype(np.float64)))
        if not nd > 0:
            unused.append(int(j))
            continue
        d /= np.float32(nd)
        p = np.empty(len(atoms_s), dtype=np.float32)  # D_S^T d
        for a0 in range(0, len(atoms_s), _ATOM_BLOCK):
            part = atoms_s[a0:a0 + _ATOM_BLOCK]
            p[a0:a0 + len(part)] = np.take(atoms_t, part, axis=0, out=dbuf[:len(part)], mode="clip") @ d
        q = np.zeros(cv.shape, dtype=np.float32)
        q[other] = cv[other] * p[inv]
        g_new = np.empty_like(g)
        for s0 in range(0, len(sig), step):  # X_I d - Gamma_S^T (D_S^T d)
            rows = sig[s0:s0 + step]
            x = xbuf[:len(rows)] if x_once else signals.take(rows, xbuf)
            g_new[s0:s0 + len(rows)] = x @ d
        g_new -= q.sum(axis=1)
        atoms_t[j] = d
        val_flat[pos] = g_new
    return unused


def _clear_atoms(atoms_t, signals: TrainingSignals, errors, idx, unused, *, min_usage, max_coherence):
    """Replace unused, rarely used and near-duplicate atoms with the worst-represented signals (KSVD-box's ``cleardict``).

    ``errors``: each signal's residual energy ``||x - D c||^2``, or a function returning them (called only if an
    atom is to be replaced). The candidates are all training signals in decreasing order of it; a candidate
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
    err = np.asarray(errors() if callable(errors) else errors, dtype=np.float64)
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
            idx, val, err2, x_norm2 = _code_all(signals, atoms_t, int(sparsity), int(chunk_size), client,
                                                f"K-SVD {it + 1}/{n_iter}: coding")
            err = err2 / max(x_norm2, 1e-300)
            errors.append(err)
            unused = _update_atoms(atoms_t, idx, val, signals, rng, int(sparsity))
            cleared = _clear_atoms(atoms_t, signals,
                                   lambda: _signal_errors(signals, atoms_t, idx, val, int(chunk_size)),
                                   idx, unused, min_usage=int(min_usage), max_coherence=float(max_coherence))
            replaced.append(len(cleared))
            del idx, val
            if ckpt is not None:
                _save_checkpoint(ckpt, atoms_t, it + 1, rng, errors, replaced, params)
            if callback is not None:
                callback(it + 1, err)
        idx, val, err2, x_norm2 = _code_all(signals, atoms_t, int(sparsity), int(chunk_size), client,
                                            "K-SVD: final coding")
    finally:
        if client is not None:
            client.close()
        signals.close()
    final = err2 / max(x_norm2, 1e-300)
    usage = np.bincount(idx[idx >= 0], minlength=int(n_atoms))
    return KsvdResult(atoms=np.ascontiguousarray(atoms_t.T), errors=errors, final_error=final, usage=usage,
                      iterations=int(n_iter), replaced=replaced, seconds=time.perf_counter() - start_time,
                      resumed_from=resumed_from)
