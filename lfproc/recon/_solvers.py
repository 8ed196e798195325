"""Batched sparse solvers for the per-patch weighted lasso.

ADMM in its scaled form follows Boyd, Parikh, Chu, Peleato and Eckstein, "Distributed optimization
and statistical learning via the alternating direction method of multipliers", Foundations and
Trends in Machine Learning 2011; FISTA is Beck and Teboulle, SIAM J. Imaging Sciences 2009.

Every solver works on a batch of ``B`` patches at once, each the problem

``min_a  1/2 || diag(w_b) (A_b a - y_b) ||^2 + mu || a ||_1``

with ``A_b = Phi_b D`` (``m x K``). The patch matrices come as a :class:`SharedOperator`
(one ``A`` for the whole batch: patches of one phase of a periodic mask; the products are
GEMMs ``X @ A.T`` and ``R @ A`` over the batch) or a :class:`BatchOperator` (one ``A_b`` per
patch, batched matrix-vector products; non-periodic masks). States are float32 (``(K, B)``
columns in :func:`admm`), small systems are factorised in float64.

Written by hand because no library solves many small weighted lasso problems that share
(or do not share) a sensing matrix in one batch: scikit-learn, skglm and celer solve one
problem at a time.

The solvers set no BLAS thread limit: threadpoolctl changes the BLAS library's state for the
whole process and is not thread-safe, so the caller sets it once (:func:`lfproc.recon.reconstruct`
runs every block on one BLAS thread).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["SharedOperator", "BatchOperator", "admm", "fista", "omp", "SOLVERS"]

SOLVERS = ("admm", "fista", "omp")

_TINY = np.float32(1e-30)


class SharedOperator:
    """One patch matrix ``A`` (``m x K``) for every patch of a batch.

    Parameters
    ----------
    A : ndarray of shape (m, K), float32
    gram : ndarray of shape (m, m), optional
        ``A A^T`` (float64) if already computed (it is computed once per phase).
    factor : optional
        The ADMM factor of ``A`` (:meth:`factor`) if already computed (:func:`lfproc.recon.reconstruct`
        builds one per phase for the whole reconstruction, not one per block).
    """

    def __init__(self, A: np.ndarray, gram: np.ndarray | None = None, factor: "_Factor | None" = None):
        self.A = np.ascontiguousarray(A, dtype=np.float32)
        self.AT = np.ascontiguousarray(self.A.T)
        self._gram = gram
        self._sq = None
        self._factor = factor

    @property
    def shape(self) -> tuple[int, int]:
        return self.A.shape

    def fwd(self, X: np.ndarray) -> np.ndarray:
        """``A x_b`` for every row: ``(B, K) -> (B, m)`` (one GEMM)."""
        return X @ self.A.T

    def adj(self, R: np.ndarray) -> np.ndarray:
        """``A^T r_b`` for every row: ``(B, m) -> (B, K)`` (one GEMM, ``(A^T R^T)^T``: 1.6x faster than ``R @ A``)."""
        return (self.AT @ R.T).T

    def gram(self) -> np.ndarray:
        """``A A^T`` in float64, ``(m, m)`` (broadcasts against a batch)."""
        if self._gram is None:
            A64 = self.A.astype(np.float64)
            self._gram = A64 @ A64.T
        return self._gram

    def colnorm2(self, w2: np.ndarray) -> np.ndarray:
        """Squared column norms of ``diag(w_b) A`` for every row: ``(B, K)``."""
        if self._sq is None:
            self._sq = self.A * self.A
        return w2.astype(np.float32) @ self._sq

    def columns(self, idx: np.ndarray) -> np.ndarray:
        """Columns ``A[:, idx[b]]``: ``(B, m, k)`` for ``idx`` of shape ``(B, k)``."""
        return np.moveaxis(self.A.T[idx], -1, 1)

    def subset(self, rows: np.ndarray) -> "SharedOperator":
        return self

    def factor(self) -> "_Factor":
        """The ADMM factor of :func:`admm` (computed once per operator, shared by every patch)."""
        if self._factor is None:
            self._factor = _Factor.build(self.gram())
        return self._factor

    def fwd_t(self, V: np.ndarray) -> np.ndarray:
        """``A v_b`` for every column: ``(K, B) -> (m, B)`` (one GEMM, the column layout of :func:`admm`)."""
        return self.A @ V

    def adj_t(self, E: np.ndarray, out: np.ndarray) -> None:
        """``out = A^T e_b`` for every column ``(m, B)`` of ``E``; ``out`` ``(K, B)`` C-contiguous float32 (one GEMM;
        numpy releases the GIL)."""
        np.matmul(self.AT, E, out=out)


class BatchOperator:
    """One patch matrix per patch: ``A`` of shape ``(B, m, K)`` (non-periodic masks)."""

    def __init__(self, A: np.ndarray):
        self.A = np.ascontiguousarray(A, dtype=np.float32)

    @property
    def shape(self) -> tuple[int, int]:
        return self.A.shape[1:]

    def fwd(self, X: np.ndarray) -> np.ndarray:
        return np.matmul(self.A, X[:, :, None])[:, :, 0]

    def adj(self, R: np.ndarray) -> np.ndarray:
        return np.matmul(R[:, None, :], self.A)[:, 0, :]

    def gram(self) -> np.ndarray:
        # (B, m, m) in float32 GEMMs, then float64: m^2 K per patch, the setup of a batch
        return np.matmul(self.A, self.A.transpose(0, 2, 1)).astype(np.float64)

    def colnorm2(self, w2: np.ndarray) -> np.ndarray:
        return np.einsum("bm,bmk->bk", w2.astype(np.float32), self.A * self.A)

    def columns(self, idx: np.ndarray) -> np.ndarray:
        return np.take_along_axis(self.A, idx[:, None, :], axis=2)

    def subset(self, rows: np.ndarray) -> "BatchOperator":
        return BatchOperator(self.A[rows])

    def factor(self) -> "_Factor":
        """One ADMM factor per patch (``m x m`` each: the setup of a batch, LAPACK on one thread)."""
        return _Factor.build(self.gram())

    def fwd_t(self, V: np.ndarray) -> np.ndarray:
        # stacked matmul (BLAS per patch): 15x faster than einsum("bmk,kb->mb") here (measured)
        return np.matmul(self.A, np.ascontiguousarray(V.T)[:, :, None])[:, :, 0].T

    def adj_t(self, E: np.ndarray, out: np.ndarray) -> None:
        out[...] = np.matmul(np.ascontiguousarray(E.T)[:, None, :], self.A)[:, 0, :].T


def _soft(x: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    """Soft threshold ``sign(x) max(|x| - kappa, 0)``, ``kappa`` per row (B, 1)."""
    return x - np.clip(x, -kappa, kappa)


def _rel_change(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    d = new - old
    num = _sumsq(d.T)
    den = _sumsq(new.T)
    return np.sqrt(num / np.maximum(den, 1e-300))


class _Active:
    """Rows still iterating; converged rows are written out and dropped (compaction)."""

    def __init__(self, n: int, k: int):
        self.rows = np.arange(n)
        self.out = np.zeros((n, k), dtype=np.float32)
        self.iters = np.zeros(n, dtype=np.int32)

    def retire(self, done: np.ndarray, state: np.ndarray, it: int) -> np.ndarray:
        """Store the rows ``done`` (a mask over active rows); return the mask of rows kept."""
        self.out[self.rows[done]] = state[done]
        self.iters[self.rows[done]] = it
        keep = ~done
        self.rows = self.rows[keep]
        return keep


#: Residual balancing of :func:`admm` (Boyd et al. 2011, section 3.4.1): every ``_BALANCE_EVERY``
#: iterations ``rho`` is doubled when the primal residual exceeds ``_BALANCE_RATIO`` times the
#: dual one, halved in the opposite case; the stopping test runs at the same iterations.
_BALANCE_EVERY = 5
_BALANCE_RATIO = 10.0


class _Factor:
    """What :func:`admm` needs of ``G = A A^T``: ``beta``, ``N = beta (I + beta G)^-1`` and ``G`` (float32).

    Shared (``G`` of shape ``(m, m)``: one per operator phase) or per patch (``(B, m, m)``).
    ``beta = m / trace(G)`` makes ``beta G`` of mean eigenvalue one, so the penalties of
    :func:`admm` are in units that do not depend on the dictionary's or the mask's scale.
    """

    def __init__(self, beta, n_mat, g_mat):
        self.beta, self.N, self.G = beta, n_mat, g_mat

    @classmethod
    def build(cls, gram: np.ndarray) -> "_Factor":
        gram = np.asarray(gram, dtype=np.float64)
        m = gram.shape[-1]
        beta = m / np.maximum(np.trace(gram, axis1=-2, axis2=-1), 1e-30)
        sys_ = np.asarray(beta)[..., None, None] * gram + np.eye(m)
        inv = np.linalg.inv(sys_)  # small LAPACK calls: reconstruct() runs them on one BLAS thread
        n_mat = (np.asarray(beta)[..., None, None] * inv).astype(np.float32)
        return cls(np.asarray(beta, dtype=np.float32), n_mat, gram.astype(np.float32))

    @property
    def shared(self) -> bool:
        return self.N.ndim == 2

    def beta_row(self, b_n: int) -> np.ndarray:
        return np.broadcast_to(self.beta.reshape(1, -1), (1, b_n)).astype(np.float32)

    def times(self, mat: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``mat_b x_b`` for every column ``x`` of shape ``(m, B)`` (``mat`` symmetric)."""
        if mat.ndim == 2:
            return mat @ x
        return np.einsum("bij,jb->ib", mat, x)

    def subset(self, keep: np.ndarray) -> "_Factor":
        if self.shared:
            return self
        return _Factor(self.beta[keep], self.N[keep], self.G[keep])


#: Over-relaxation of :func:`admm` (Boyd et al. 2011, section 3.4.3: 1.5-1.8 speeds convergence).
ADMM_ALPHA = 1.6
#: Penalty of :func:`admm` in its scale-free units (``rho beta``; measured, README).
ADMM_RHO = 1.0
#: Absolute tolerance of :func:`admm`, in units of ``tol`` times a patch's code scale (Boyd et al. 2011, 3.3.1).
_ABS_TOL = 1e-2
#: A soft threshold below this fraction of a patch's code scale is under float32's resolution: taken as 0.
_LSQ_THRESHOLD = 1e-7
#: Patches iterated together in :func:`admm` (the ``(K, B)`` state arrays' bytes). With the state touched once an
#: iteration (:func:`_z_u_step`) larger chunks pay: the Lytro-size benchmark (``benchmarks/reconstruct.py``, one
#: quiet run each, 2026-11-25) took 22.9 / 21.6 / 20.7 / 21.1 s with 4 / 8 / 16 / 32 MiB.
_ADMM_CHUNK_BYTES = 16 * 2**20


def admm(op, w: np.ndarray, y: np.ndarray, mu, *, max_iter: int, tol: float, rho=None, alpha: float = ADMM_ALPHA,
         balance: bool = True, compact_fraction: float = 0.1, chunk: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Scaled, over-relaxed ADMM for the weighted lasso with a factor shared by every patch of an operator.

    Splitting (Afonso, Bioucas-Dias and Figueiredo's SALSA form): ``s = A a`` (the noiseless
    measurements, penalty ``rho beta``) and ``z = a`` (the sparse code, penalty ``rho``), so that

    - the ``a`` step, ``argmin beta ||A a - p||^2 + ||a - v||^2``, is
      ``a = v + A^T N (p - A v)`` with ``N = beta (I + beta A A^T)^-1`` (Woodbury): it does not
      depend on the patch's weights nor on ``rho``, so one ``m x m`` factor serves every patch
      of an operator phase (no per-patch factorisation: the paper's splitting needs one
      ``m x m`` Cholesky per patch, which cost as much as ~70 iterations here) and the work
      is two GEMMs per iteration (``A v`` and ``A^T e``) plus ``m x m`` ones;
    - the ``s`` step (weighted data term) is element-wise in the ``m`` measurements and the
      ``z`` step is the soft threshold ``mu / rho``.

    Over-relaxation ``alpha`` (default 1.6) replaces ``a`` by ``alpha a + (1 - alpha) z_old``
    in the ``z``, ``s`` and dual steps. State arrays are kept as ``(K, B)`` columns, in units
    of each patch's threshold, and updated in place: besides the two ``m x K`` GEMMs and two ``m x m`` ones,
    one compiled pass over the ``(K, B)`` state per iteration (:func:`_z_u_step`, which also keeps the
    stopping rule's norms) and two over the ``(m, B)`` measurements (:func:`_scale_residual`,
    :func:`_s_d_step`), all releasing the GIL (numba, ``nogil``); patches run in
    chunks that keep them small. A patch stops when ``||z_k - z_{k-1}||`` and its primal residual
    are at most ``tol ||z_k|| + eps_abs`` (relative plus absolute, Boyd et al. 2011, section
    3.3.1; ``eps_abs`` is ``0.01 tol`` times the patch's code scale, ``||W y||`` over the rms norm
    of the columns of ``W A``), checked every 5 iterations; converged patches leave the batch.
    A patch whose optimal code is 0 (``||A^T W^2 y||_inf <= mu``) is not iterated (0 iterations).
    ``mu = 0`` (or a threshold below float32's resolution of the code) solves the weighted
    least-squares problem; started from 0 the iterates stay in the row space of ``A``, so with
    positive weights the answer is the minimum-norm solution.

    Parameters
    ----------
    op : SharedOperator or BatchOperator
    w, y : ndarray of shape (B, m)
        Weights and measurements.
    mu : float or ndarray of shape (B,)
        l1 weight (per patch).
    max_iter : int
    tol : float
    rho : float or ndarray of shape (B,), optional
        Penalty in units of ``1 / beta`` (:data:`ADMM_RHO` by default).
    alpha : float
        Over-relaxation (1: plain ADMM).
    chunk : int, optional
        Patches iterated together (default: state arrays of about 16 MiB).

    Returns
    -------
    codes : ndarray of shape (B, K), float32 (the sparse iterate ``z``)
    iterations : ndarray of shape (B,), int32
    """
    w = np.asarray(w, dtype=np.float32)
    y = np.asarray(y, dtype=np.float32)
    b_n, m = w.shape
    k_n = op.shape[1]
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float32).reshape(-1), (b_n,))
    rho = np.broadcast_to(np.asarray(ADMM_RHO if rho is None else rho, dtype=np.float32).reshape(-1), (b_n,))
    fac = op.factor()
    if chunk is None:  # the state arrays (and per-patch operators) of a chunk stay in the cache
        per_patch = 4 * k_n * 4 + (0 if fac.shared else 4 * m * k_n)
        chunk = max(4 if not fac.shared else 16, _ADMM_CHUNK_BYTES // per_patch)
    codes = np.zeros((b_n, k_n), dtype=np.float32)
    iters = np.zeros(b_n, dtype=np.int32)
    # the zero code is optimal exactly when ||A^T W^2 y||_inf <= mu (the lasso's optimality condition at 0):
    # such patches stop at once, with 0 iterations (with a large mu they ran to max_iter)
    todo = np.flatnonzero(~(np.abs(op.adj(w * w * y)).max(axis=1) <= mu))
    for start in range(0, len(todo), chunk):
        rows = todo[start:start + chunk]
        sub_op = op if fac.shared else op.subset(rows)
        sub_fac = fac if fac.shared else fac.subset(rows)
        codes[rows], iters[rows] = _admm_chunk(sub_op, sub_fac, w[rows], y[rows], mu[rows], rho[rows],
                                               max_iter=max_iter, tol=tol, alpha=alpha, balance=balance,
                                               compact_fraction=compact_fraction)
    return codes, iters


def _admm_chunk(op, fac, w, y, mu, rho_rel, *, max_iter, tol, alpha, balance, compact_fraction):
    """:func:`admm` on one chunk; the ``(K, B)`` state is kept in units of each patch's threshold ``kappa``.

    In those units the soft threshold is a clip at +-1 (0 in a threshold-0 column: ``lim``), ``kappa`` folds
    into the ``(m, B)`` side of the GEMMs, and a change of ``rho`` rescales ``z`` only.
    """
    b_n, m = w.shape
    k_n = op.shape[1]
    beta = fac.beta_row(b_n)  # (1, B)
    w2 = np.ascontiguousarray((w * w).T)  # (m, B)
    w2y = np.ascontiguousarray((w * w * y).T)
    rb = rho_rel.astype(np.float32)[None, :]  # rho beta: the penalty of s = A a
    kappa = (mu[None, :] * beta / rb).astype(np.float32)  # mu / rho, the soft threshold
    # the code scale of each patch: ||W y|| over the rms norm of the columns of W A (the size of a one-atom
    # fit); the absolute tolerance is a fraction of it
    diag_g = np.diagonal(fac.G, axis1=-2, axis2=-1).astype(np.float64)  # ||A_i||^2, (m,) or (B, m)
    col2 = (diag_g @ w2.astype(np.float64) if fac.shared else np.einsum("bm,mb->b", diag_g, w2)) / k_n
    ref = np.sqrt(np.einsum("mb,mb->b", w2y, y.T, dtype=np.float64) / np.maximum(col2, 1e-300))
    ref = np.where(ref > 0, ref, 1.0)[None, :]
    atol = (_ABS_TOL * tol * ref[0]).astype(np.float64)
    # the state is in units of kappa (below); a threshold under float32's resolution of the code (mu = 0
    # included: the weighted least-squares problem) has no units: those columns are in units of ref and
    # their threshold is 0, so no state overflows (mu = 0 gave inf norms and a wrong answer "converged")
    lsq = ~(kappa > _LSQ_THRESHOLD * ref)
    unit = np.where(lsq, ref, kappa).astype(np.float32)
    lim = np.where(lsq[0], np.float32(0), np.float32(1)).astype(np.float32)  # the clip's bound: 0 for threshold 0
    denom = w2 + rb
    z = np.zeros((k_n, b_n), dtype=np.float32)  # z / kappa
    u = np.zeros_like(z)  # u / kappa (scaled dual of a = z)
    v = np.zeros_like(z)  # z - u
    no_stats = np.zeros((3, 1))  # the stopping rule's norms (_z_u_step) are summed in check iterations only
    g = np.empty_like(z)  # alpha A^T e (adj_t)
    s = np.zeros((m, b_n), dtype=np.float32)  # the noiseless measurements A a
    d = np.zeros_like(s)  # scaled dual of s = A a
    r = np.empty_like(s)
    alpha = np.float32(alpha)
    one_minus_alpha = np.float32(1 - alpha)
    act = _Active(b_n, k_n)
    out_t = np.zeros((k_n, b_n), dtype=np.float32)
    pending = 0
    it = 0
    for it in range(1, max_iter + 1):
        check = it % _BALANCE_EVERY == 0 or it == max_iter
        t = op.fwd_t(v)  # v = z - u (kept by _z_u_step)
        _scale_residual(t, s, d, unit[0], r)  # t = A v, r = s - d - A v
        e = fac.times(fac.N, r)  # the a step: a = v + A^T e
        q = fac.times(fac.G, e)  # A a = A v + G e
        stats = np.zeros((3, z.shape[1])) if check else no_stats
        if check:
            d_old, s_old = d.copy(), s.copy()
        # x = alpha a + (1 - alpha) z + u = z + (1 - alpha) u + alpha A^T e; u_new = x - soft(x, kappa) =
        # clip(x, -kappa, kappa) (0 with threshold 0), z_new = soft(x, kappa): one compiled pass
        e *= alpha / unit
        op.adj_t(e, g)
        _z_u_step(z, u, g, lim, one_minus_alpha, v, stats, check)
        # the relaxed A a, alpha (A v + G e) + (1 - alpha) s, plus d; s = argmin 1/2 |w (s - y)|^2 + rho beta / 2
        # |s - (that)|^2 and the new d, in place
        _s_d_step(t, q, s, d, w2y, rb[0], denom, alpha)
        if not check:
            continue
        k_row = unit[0].astype(np.float64)
        change = k_row * np.sqrt(stats[0])  # ||z_k - z_{k-1}||
        dd = d - d_old  # relaxed A a - s
        primal = np.sqrt(k_row**2 * stats[1] + beta[0] * _sumsq(dd))
        # relative plus absolute (Boyd et al. 2011, section 3.3.1): a code near 0 stops too
        eps = tol * k_row * np.sqrt(stats[2]) + atol
        done = (change <= eps) & (primal <= eps)
        pending += int(done.sum())
        if it == max_iter:
            break
        if balance:  # residual balancing (Boyd et al. 2011, 3.4.1); the factor does not depend on rho
            ds = s - s_old
            dual = (rb[0] / beta[0]) * np.sqrt(change * change + beta[0] * _sumsq(ds))
            up = primal > _BALANCE_RATIO * dual
            down = dual > _BALANCE_RATIO * primal
            if up.any() or down.any():
                f = np.where(up, 2.0, np.where(down, 0.5, 1.0)).astype(np.float32)[None, :]
                rb = rb * f
                f_unit = np.where(lim == 0, np.float32(1.0), f)  # a threshold-0 column keeps its units
                unit = unit / f_unit
                denom = w2 + rb
                z *= f_unit  # z / kappa with the new kappa; u / kappa is unchanged (0 with threshold 0)
                np.subtract(z, u, out=v)
                d = d / f
        if pending and pending >= max(1, compact_fraction * len(act.rows)):
            out_t[:, act.rows[done]] = z[:, done] * unit[:, done]
            act.iters[act.rows[done]] = it
            keep = ~done
            act.rows = act.rows[keep]
            pending = 0
            if not keep.any():
                return out_t.T, act.iters
            z, u, s, d, w2, w2y, denom = (np.ascontiguousarray(x[:, keep]) for x in (z, u, s, d, w2, w2y, denom))
            r = np.empty_like(s)
            beta, rb, unit, atol, lim = beta[:, keep], rb[:, keep], unit[:, keep], atol[keep], lim[keep]
            v, g = z - u, np.empty_like(z)
            op = op.subset(keep)
            fac = fac.subset(keep)
    out_t[:, act.rows] = z * unit
    act.iters[act.rows] = it
    return np.ascontiguousarray(out_t.T), act.iters


def _sumsq(x: np.ndarray) -> np.ndarray:
    """Squared norms of the columns of ``x`` ``(n, B)`` in float64 (float32 sums, redone in float64 if one overflowed)."""
    out = np.einsum("kb,kb->b", x, x)
    if not np.isfinite(out).all():
        out = np.einsum("kb,kb->b", x, x, dtype=np.float64)
    return out.astype(np.float64)


@numba.njit(nogil=True, cache=True)
def _scale_residual(t, s, d, unit, r):  # pragma: no cover - compiled (tests compare it with numpy)
    """:func:`admm`'s ``t *= unit`` (``A v`` from the state in units of the threshold) and ``r = s - d - t``, one
    pass over ``(m, B)``."""
    m_n, b_n = t.shape
    for i in range(m_n):
        for j in range(b_n):
            x = t[i, j] * unit[j]
            t[i, j] = x
            r[i, j] = s[i, j] - d[i, j] - x


@numba.njit(nogil=True, cache=True)
def _s_d_step(t, q, s, d, w2y, rb, denom, alpha):  # pragma: no cover - compiled (tests compare it with numpy)
    """:func:`admm`'s ``s`` and dual steps in one pass over ``(m, B)``, in place: ``h = alpha (t + q) + (1 - alpha) s
    + d`` (the relaxed ``A a`` plus the dual), ``s = (w2y + rb h) / denom``, ``d = h - s``."""
    m_n, b_n = t.shape
    for i in range(m_n):
        for j in range(b_n):
            h = alpha * (t[i, j] + q[i, j]) + (1 - alpha) * s[i, j] + d[i, j]
            x = (w2y[i, j] + rb[j] * h) / denom[i, j]
            s[i, j] = x
            d[i, j] = h - x


@numba.njit(nogil=True, cache=True)
def _z_u_step(z, u, g, lim, a, v, stats, check):  # pragma: no cover - compiled (tests compare it with numpy)
    """The ``z`` and dual steps of :func:`admm` in one pass (units of the threshold), in place:
    ``x = z + a u + g`` (``a = 1 - alpha``, ``g = alpha A^T e``), ``u = clip(x, -lim, lim)``, ``z = x - u``, and
    ``v = z - u`` (the next iteration's GEMM input). With ``check``, adds per column to ``stats`` ``(3, B)``
    (float64) the squared norms of the change of ``z``, of the change of ``u`` and of the new ``z``: the stopping
    rule's, without copies of the old state.

    Why compiled: numpy needed seven passes over the ``(K, B)`` state for this (two multiply-adds, a clip, two
    subtractions, and two copies plus three norms every fifth iteration). ``lim`` ``(B,)``: 1, or 0 for a
    threshold-0 (least-squares) column. ``nogil``: the thread pool's blocks run it at once.
    """
    k_n, b_n = z.shape
    if check:
        for i in range(k_n):
            for j in range(b_n):
                z0 = z[i, j]
                u0 = u[i, j]
                x = z0 + a * u0 + g[i, j]
                c = min(max(x, -lim[j]), lim[j])
                zn = x - c
                u[i, j] = c
                z[i, j] = zn
                v[i, j] = zn - c
                dz, du, zf = float(zn) - float(z0), float(c) - float(u0), float(zn)  # float64: no overflow
                stats[0, j] += dz * dz
                stats[1, j] += du * du
                stats[2, j] += zf * zf
    else:
        for i in range(k_n):
            for j in range(b_n):
                x = z[i, j] + a * u[i, j] + g[i, j]
                c = min(max(x, -lim[j]), lim[j])
                u[i, j] = c
                z[i, j] = x - c
                v[i, j] = x - c - c


def fista(op, w: np.ndarray, y: np.ndarray, mu, *, max_iter: int, tol: float,
          compact_fraction: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """FISTA for the weighted lasso: step ``1/L``, ``L`` the largest eigenvalue of ``B B^T`` per patch.

    Same parameters and returns as :func:`admm` (no ``rho``).
    """
    w = np.asarray(w, dtype=np.float32)
    y = np.asarray(y, dtype=np.float32)
    b_n, m = w.shape
    k_n = op.shape[1]
    g = op.gram()
    s = w[:, :, None].astype(np.float64) * g * w[:, None, :].astype(np.float64)
    lip = np.linalg.eigvalsh(s)[:, -1]
    step = (1.0 / np.maximum(lip, 1e-30)).astype(np.float32)[:, None]
    kappa = np.broadcast_to(np.asarray(mu, dtype=np.float32), (b_n,))[:, None] * step
    w2 = w * w
    x = np.zeros((b_n, k_n), dtype=np.float32)
    yk = x
    t = 1.0
    act = _Active(b_n, k_n)
    pending = 0
    it = 0
    for it in range(1, max_iter + 1):
        grad = op.adj(w2 * (op.fwd(yk) - y))
        x_new = _soft(yk - step * grad, kappa)
        t_new = (1.0 + np.sqrt(1.0 + 4.0 * t * t)) / 2.0
        done = _rel_change(x_new, x) <= tol
        yk = x_new + np.float32((t - 1.0) / t_new) * (x_new - x)
        x, t = x_new, t_new
        pending += int(done.sum())
        if it == max_iter:
            break
        if pending and pending >= max(1, compact_fraction * len(act.rows)):
            keep = act.retire(done, x, it)
            pending = 0
            if not keep.all():
                if not keep.any():
                    return act.out, act.iters
                x, yk, w, w2, y, step, kappa = (v[keep] for v in (x, yk, w, w2, y, step, kappa))
                op = op.subset(keep)
    act.retire(np.ones(len(act.rows), dtype=bool), x, it)
    return act.out, act.iters


def omp(op, w: np.ndarray, y: np.ndarray, n_nonzero_coefs: int) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal matching pursuit on the weighted problem ``B = W A``, columns normalised for the selection.

    Each step picks the atom whose normalised column of ``B`` correlates most with the
    weighted residual, then refits all chosen atoms by weighted least squares (float64
    normal equations with a tiny ridge). A patch stops after ``n_nonzero_coefs`` atoms, or earlier
    when no atom correlates with its residual any more (an exact fit). There is no
    residual (chi-square) stop.

    Returns
    -------
    codes : ndarray of shape (B, K), float32
    atoms : ndarray of shape (B,), int32 (atoms used)
    """
    w = np.asarray(w, dtype=np.float32)
    y = np.asarray(y, dtype=np.float32)
    b_n, m = w.shape
    k_n = op.shape[1]
    t_n = int(min(n_nonzero_coefs, k_n, m))
    norms = np.sqrt(op.colnorm2(w * w))
    inv_norm = np.where(norms > 0, 1.0 / np.maximum(norms, _TINY), 0.0).astype(np.float32)
    c = (w * y).astype(np.float64)
    r = c.copy()
    rows = np.arange(b_n)
    sel = np.zeros((b_n, t_n), dtype=np.intp)
    cols = np.zeros((b_n, m, t_n), dtype=np.float64)  # chosen columns of B
    coef = np.zeros((b_n, t_n))
    used = np.zeros(b_n, dtype=np.int32)
    active = np.ones(b_n, dtype=bool)
    for k in range(t_n):
        if not active.any():
            break
        corr = np.abs(op.adj((w * r).astype(np.float32))) * inv_norm
        if k:
            corr[rows[:, None], sel[:, :k]] = -1.0  # never twice
        j = corr.argmax(axis=1)
        active &= corr[rows, j] > 0
        sel[:, k] = j
        cols[:, :, k] = w * op.columns(j[:, None])[:, :, 0]
        bk = cols[:, :, :k + 1]
        gram = np.matmul(bk.transpose(0, 2, 1), bk)
        ridge = 1e-10 * np.maximum(np.trace(gram, axis1=1, axis2=2), 1e-30) / (k + 1)
        gram[:, np.arange(k + 1), np.arange(k + 1)] += ridge[:, None]
        rhs = np.matmul(bk.transpose(0, 2, 1), c[:, :, None])
        sol = np.linalg.solve(gram, rhs)[:, :, 0]
        coef[active, :k + 1] = sol[active]
        used[active] = k + 1
        r = c - np.matmul(cols[:, :, :k + 1], coef[:, :k + 1, None])[:, :, 0]
    out = np.zeros((b_n, k_n), dtype=np.float32)
    for k in range(t_n):
        has = used > k
        out[rows[has], sel[has, k]] = coef[has, k]
    return out, used
