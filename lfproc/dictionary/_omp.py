"""Batch-OMP: orthogonal matching pursuit for many signals at once.

Written by hand because no library does it at this size: scikit-learn's
``orthogonal_mp_gram`` loops over signals in Python and copies the ``K x K`` Gram matrix for
each of them, SPAMS's ``omp`` is order-recursive MP (a
different selection rule).

The algorithm is Batch-OMP of Rubinstein, Zibulevsky and Elad (2008): with the Gram matrix
``G = D^T D`` and the correlations ``alpha0 = D^T x`` of every signal computed once (one
float32 GEMM per chunk of signals), each step picks ``j = argmax |alpha|``, solves the
normal equations ``G[I, I] c = alpha0[I]`` on the support ``I`` and updates the correlations
``alpha = alpha0 - G[:, I] c`` without forming the residual. The Cholesky factor of
``G[I, I]`` grows by one row per step (``L w = G[I, j]``, new row ``(w, sqrt(G_jj - w.w))``),
so a step costs ``O(k^2)`` besides the ``O(k K)`` update of ``alpha``. An atom whose part
orthogonal to the support is below float32 precision (``G_jj - w.w <= 100 eps G_jj``) is
dependent and ends the signal, as does a residual at rounding level; finished signals leave
the batch. Here every step is vectorised over a chunk of signals: one row gather of ``G``
per signal and step, the triangular solves in float64, and one batched matrix-vector
product. These passes are memory-bound and run on one core each in NumPy, so a chunk's
signals are split into one block per core, coded in threads. The residual norm ``||x||^2 - c . alpha0[I]`` gives the error-constrained stop
(``tol``).

References
----------
.. [1] R. Rubinstein, M. Zibulevsky, M. Elad, "Efficient Implementation of the K-SVD
   Algorithm using Batch Orthogonal Matching Pursuit", Technion CS-2008-08, 2008.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .._shared.parallel import available_cpus
from ..errors import InputError, ShapeError

__all__ = ["batch_omp", "omp_codes", "codes_to_dense", "gram_matrix"]

#: Memory (bytes) of the per-chunk work arrays of :func:`omp_codes`.
CHUNK_BYTES = 192 * 2**20
#: A new atom whose part orthogonal to the support has squared norm below this fraction of its own is
#: dependent: about 100 times float32's rounding (the Gram matrix is float32); pairs of atoms at coherence
#: 0.99 (1 - 0.99^2 = 0.02) are well above it.
_DEPENDENT = 100 * float(np.finfo(np.float32).eps)


def _check_dictionary(D) -> np.ndarray:
    D = np.asarray(D)
    if D.ndim != 2 or D.shape[0] < 1 or D.shape[1] < 1:
        raise ShapeError(f"dictionary: expected a 2-D array (n, K), got shape {D.shape}")
    if not np.issubdtype(D.dtype, np.floating):
        raise InputError(f"dictionary: expected floating-point atoms, got {D.dtype}")
    if not np.isfinite(D).all():
        raise InputError("dictionary: NaN or infinite atoms")
    return D


def gram_matrix(D) -> np.ndarray:
    """``D^T D`` in float32, ``(K, K)``."""
    D = np.asarray(D, dtype=np.float32)
    return D.T @ D


def omp_codes(D, X_rows, n_nonzero_coefs: int, *, tol: float | None = None, gram=None,
              chunk_size: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sparse codes of the rows of ``X_rows`` (no input checks; see :func:`batch_omp`).

    Parameters
    ----------
    D : ndarray of shape (n, K), unit-norm columns
    X_rows : ndarray of shape (N, n)
        Signals as rows.
    n_nonzero_coefs : int
    tol : float, optional
        Stop a signal once its squared residual norm is at most ``tol``.
    gram : ndarray of shape (K, K), optional
        ``D^T D`` (float32), if already computed.
    chunk_size : int, optional
        Signals per chunk (default: as many as fit in :data:`CHUNK_BYTES`).

    Returns
    -------
    indices : ndarray of shape (N, T), int32
        Atoms used by each signal, in selection order; -1 where fewer than T were used.
    values : ndarray of shape (N, T), float32
        Their coefficients (0 where the index is -1).
    """
    D32 = np.asarray(D, dtype=np.float32)
    X_rows = np.asarray(X_rows)
    n, k_atoms = D32.shape
    big_n = X_rows.shape[0]
    t = int(n_nonzero_coefs)
    G = gram_matrix(D32) if gram is None else np.asarray(gram, dtype=np.float32)
    if chunk_size is None:
        chunk_size = max(16, CHUNK_BYTES // (4 * k_atoms * (t + 3)))
    indices = np.full((big_n, t), -1, dtype=np.int32)
    values = np.zeros((big_n, t), dtype=np.float32)
    rows = min(chunk_size, big_n)
    # work arrays reused by every chunk: fresh ones cost a page fault per 4 KiB on every chunk (measured:
    # a third of the time at n = 1200, K = 3240)
    work = (np.empty((t + 1, rows, k_atoms), dtype=np.float32), np.empty((rows, k_atoms), dtype=np.float32))
    for start in range(0, big_n, chunk_size):
        stop = min(start + chunk_size, big_n)
        idx, val = _omp_chunk(D32, G, X_rows[start:stop], t, tol, work)
        indices[start:stop] = idx
        values[start:stop] = val
    return indices, values


_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _pool(workers: int) -> ThreadPoolExecutor:
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL._max_workers < workers:
            _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="lfproc-omp")
        return _POOL


#: Fewest signals per thread of the step loop: below this, one thread (the per-step NumPy calls dominate).
_MIN_ROWS_PER_THREAD = 64


def _omp_chunk(D32, G, X, t, tol, work, threads=None):
    """Batch-OMP on one chunk of signals (rows of ``X``); see the module notes. ``work``: buffers
    ``(t + 1, B', K)`` and ``(B', K)`` float32 with ``B' >= B``.

    The correlations ``alpha0 = X D`` are one GEMM (multithreaded BLAS); the greedy steps, memory-bound
    NumPy passes over the chunk's Gram rows that run on one core each, are split into one block of rows per
    core, run in threads (NumPy releases the GIL). Every signal's result depends on its own row only, so it
    does not depend on the split."""
    b = X.shape[0]
    X32 = np.asarray(X, dtype=np.float32)
    gsub = work[0][:, :b]
    np.matmul(X32, D32, out=gsub[0])  # (B, K): the one GEMM of the chunk
    xnorm2 = np.einsum("ij,ij->i", X32, X32, dtype=np.float64)
    threads = available_cpus() if threads is None else threads
    parts = max(1, min(threads, b // _MIN_ROWS_PER_THREAD))
    if parts == 1:
        return _omp_steps(G, gsub, work[1][:b], xnorm2, t, tol)
    bounds = np.linspace(0, b, parts + 1).astype(int)
    futures = [_pool(parts).submit(_omp_steps, G, gsub[:, lo:hi], work[1][lo:hi], xnorm2[lo:hi], t, tol)
               for lo, hi in zip(bounds[:-1], bounds[1:])]
    results = [f.result() for f in futures]
    return np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results])


def _omp_steps(G, gsub, alpha_buf, xnorm2, t, tol):
    """The greedy steps for a block of signals whose correlations ``alpha0 = D^T x`` are in ``gsub[0]``.

    ``gsub[0]`` holds ``alpha0`` and ``gsub[1 + i]`` the Gram row of the ``i``-th selected atom,
    so ``alpha = alpha0 - G[:, I] c`` is one batched product with the coefficients ``(1, -c)``;
    ``alpha_buf`` (B, K) receives it."""
    b = gsub.shape[1]
    out_idx = np.full((b, t), -1, dtype=np.int32)
    out_val = np.zeros((b, t), dtype=np.float32)
    alpha0 = gsub[0]
    live = np.arange(b)  # rows still being coded; finished ones leave the batch
    keep = xnorm2 > (0.0 if tol is None else tol)
    if not keep.all():
        gsub = _compact(gsub, keep, 1)
        live, alpha0, xnorm2 = live[keep], gsub[0], xnorm2[keep]
    alpha = alpha0
    na = len(live)
    sel = np.zeros((na, t), dtype=np.intp)
    chol = np.zeros((na, t, t))  # L, G[I, I] = L L^T (float64), grown by one row per step
    a0_sel = np.zeros((na, t))  # alpha0[I]
    fwd = np.zeros((na, t))  # L^-1 alpha0[I], grown by one entry per step
    tiny = 1e-14 * np.maximum(xnorm2, np.finfo(np.float32).tiny)
    for k in range(t):
        if na == 0:
            break
        r = np.arange(na)
        j_hi, j_lo = alpha.argmax(axis=1), alpha.argmin(axis=1)  # argmax |alpha| without a temporary
        hi, lo = alpha[r, j_hi], alpha[r, j_lo]
        j = np.where(hi >= -lo, j_hi, j_lo)
        amax = np.where(hi >= -lo, hi, lo).astype(np.float64)
        ok = amax * amax > tiny  # a residual at rounding level: done
        gj = gsub[k + 1]
        np.take(G, j, axis=0, out=gj, mode="clip")  # rows G[j], (B, K), gathered in place (unbuffered)
        g_jj = gj[r, j].astype(np.float64)
        if k:
            # progressive Cholesky (O(k^2)): L w = G[I, j], new row (w, sqrt(G_jj - w.w))
            g_ij = gj[r[:, None], sel[:, :k]].astype(np.float64)
            w = np.empty((na, k))
            for i in range(k):
                w[:, i] = (g_ij[:, i] - np.einsum("bl,bl->b", chol[:, i, :i], w[:, :i])) / chol[:, i, i]
            schur = g_jj - np.einsum("bi,bi->b", w, w)
            ok &= schur > _DEPENDENT * g_jj  # dependent on the support at float32 precision: done
        if not ok.all():
            gsub = _compact(gsub, ok, k + 2)
            alpha0 = gsub[0]
            live, sel, chol, a0_sel, fwd, xnorm2, tiny, j, g_jj = (
                v[ok] for v in (live, sel, chol, a0_sel, fwd, xnorm2, tiny, j, g_jj))
            if k:
                w, schur = w[ok], schur[ok]
            na = len(live)
            if na == 0:
                break
            r = np.arange(na)
        if k:
            chol[:, k, :k] = w
            chol[:, k, k] = np.sqrt(schur)
        else:
            chol[:, 0, 0] = np.sqrt(g_jj)
        sel[:, k] = j
        a0_sel[:, k] = alpha0[r, j]
        # c = (L L^T)^-1 alpha0[I]: one new forward entry, then back substitution (O(k^2))
        fwd[:, k] = (a0_sel[:, k] - np.einsum("bl,bl->b", chol[:, k, :k], fwd[:, :k])) / chol[:, k, k]
        c = np.empty((na, k + 1))
        for i in range(k, -1, -1):
            c[:, i] = (fwd[:, i] - np.einsum("bl,bl->b", chol[:, i + 1:k + 1, i], c[:, i + 1:k + 1])) / chol[:, i, i]
        c_ext = np.empty((na, k + 2), dtype=np.float32)
        c_ext[:, 0] = 1.0
        c_ext[:, 1:] = -c
        alpha = np.einsum("bk,kbj->bj", c_ext, gsub[:k + 2], out=alpha_buf[:na])  # alpha0 - G[:, I] c, (B, K)
        alpha[r[:, None], sel[:, :k + 1]] = 0.0  # never pick an atom twice
        out_idx[live, :k + 1] = sel[:, :k + 1]
        out_val[live, :k + 1] = c
        if tol is not None:
            more = xnorm2 - np.einsum("bi,bi->b", c, a0_sel[:, :k + 1]) > tol
            if not more.all():
                gsub = _compact(gsub, more, k + 2)
                alpha0 = gsub[0]
                live, alpha, sel, chol, a0_sel, fwd, xnorm2, tiny = (
                    v[more] for v in (live, alpha, sel, chol, a0_sel, fwd, xnorm2, tiny))
                na = len(live)
    return out_idx, out_val


def _compact(gsub, keep, filled):
    """The signals ``keep`` (a mask over ``gsub``'s axis 1) moved to the front of ``gsub``, in place; returns the
    view of them. Only the ``filled`` leading slices hold data. (A fancy-indexed copy of the whole buffer,
    a fresh allocation each time some signals finish, took a quarter of the coding time at the paper's size.)"""
    kept = np.flatnonzero(keep)
    for dest, src in enumerate(kept.tolist()):
        if dest != src:  # dest < src: a forward copy never overwrites a row still to move
            gsub[:filled, dest] = gsub[:filled, src]
    return gsub[:, :len(kept)]


def codes_to_dense(indices: np.ndarray, values: np.ndarray, n_atoms: int) -> np.ndarray:
    """``(N, T)`` indices and values -> dense coefficients ``(K, N)`` float32."""
    n_signals = indices.shape[0]
    out = np.zeros((n_atoms, n_signals), dtype=np.float32)
    used = indices >= 0
    cols = np.broadcast_to(np.arange(n_signals)[:, None], indices.shape)
    out[indices[used], cols[used]] = values[used]
    return out


def batch_omp(D, X, n_nonzero_coefs: int, *, tol: float | None = None, gram=None,
              chunk_size: int | None = None) -> np.ndarray:
    """Sparse-code the columns of ``X`` over the dictionary ``D`` with Batch-OMP.

    Each column ``x`` gets at most ``n_nonzero_coefs`` atoms chosen greedily, with the
    coefficients the least-squares fit on the chosen atoms (orthogonal matching pursuit).
    All signals are processed together in chunks: float32 GEMMs for the correlations,
    float64 for the small normal equations.

    Parameters
    ----------
    D : ndarray of shape (n, K)
        Dictionary with unit-norm columns.
    X : ndarray of shape (n, N) or (n,)
        Signals as columns.
    n_nonzero_coefs : int
        Largest number of atoms per signal (1 .. min(n, K)).
    tol : float, optional
        Also stop a signal once its squared residual norm ``||x - D a||^2`` is at most ``tol``.
    gram : ndarray of shape (K, K), optional
        Precomputed ``D^T D``.
    chunk_size : int, optional
        Signals per chunk (bounds memory; default from :data:`CHUNK_BYTES`).

    Returns
    -------
    ndarray of shape (K, N) (or (K,) for one signal), float32
        The coefficients.

    Raises
    ------
    ShapeError, InputError
        Shapes that do not match, non-finite values, atoms that are not unit-norm, a
        sparsity out of range.

    Examples
    --------
    >>> import numpy as np
    >>> from lfproc.dictionary import batch_omp
    >>> rng = np.random.default_rng(0)
    >>> D = rng.standard_normal((64, 128))
    >>> D /= np.linalg.norm(D, axis=0)
    >>> a = np.zeros(128)
    >>> a[[3, 50, 99]] = [1.0, -2.0, 0.5]
    >>> coef = batch_omp(D, D @ a, 3)
    >>> coef.shape, np.flatnonzero(coef).tolist()
    ((128,), [3, 50, 99])
    >>> np.round(coef[[3, 50, 99]], 4).tolist()
    [1.0, -2.0, 0.5]
    >>> batch_omp(D, rng.standard_normal((64, 10)), 5).shape  # ten signals as columns
    (128, 10)
    """
    D = _check_dictionary(D)
    X = np.asarray(X)
    one = X.ndim == 1
    if one:
        X = X[:, None]
    if X.ndim != 2 or X.shape[0] != D.shape[0]:
        raise ShapeError(f"signals: expected shape ({D.shape[0]}, N) to match the dictionary, got {X.shape}")
    if not np.issubdtype(X.dtype, np.number) or not np.isfinite(X).all():
        raise InputError("signals: expected finite numbers")
    norms = np.linalg.norm(D.astype(np.float64), axis=0)
    if np.abs(norms - 1).max() > 1e-3:
        raise InputError(f"dictionary: expected unit-norm columns, found norms {norms.min():.4g}..{norms.max():.4g}")
    t = n_nonzero_coefs
    if isinstance(t, bool) or int(t) != t or not 1 <= int(t) <= min(D.shape):
        raise InputError(f"n_nonzero_coefs: expected an integer in 1..{min(D.shape)}, got {n_nonzero_coefs!r}")
    if tol is not None and not (np.isfinite(tol) and tol >= 0):
        raise InputError(f"tol: expected a non-negative number, got {tol!r}")
    if chunk_size is not None and int(chunk_size) < 1:
        raise InputError(f"chunk_size: expected a positive integer, got {chunk_size!r}")
    idx, val = omp_codes(D, X.T, int(t), tol=tol, gram=gram, chunk_size=chunk_size)
    out = codes_to_dense(idx, val, D.shape[1])
    return out[:, 0] if one else out
