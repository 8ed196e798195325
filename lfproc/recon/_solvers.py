"""Batched sparse solvers for the per-patch weighted lasso (reconstruction.md section 3).

Every solver works on a batch of ``B`` patches at once, each the problem

``min_a  1/2 || diag(w_b) (A_b a - y_b) ||^2 + mu || a ||_1``

with ``A_b = Phi_b D`` (``m x K``). The patch matrices come as a :class:`SharedOperator`
(one ``A`` for the whole batch: patches of one phase of a periodic mask; the products are
GEMMs ``X @ A.T`` and ``R @ A`` over the batch) or a :class:`BatchOperator` (one ``A_b`` per
patch, batched matrix-vector products; non-periodic masks). States are ``(B, K)`` float32
row-major arrays, small systems are solved in float64.

Written by hand because no library solves many small weighted lasso problems that share
(or do not share) a sensing matrix in one batch: scikit-learn, skglm and celer solve one
problem at a time (reconstruction.md section 3.4).
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

__all__ = ["SharedOperator", "BatchOperator", "admm", "fista", "omp", "auto_rho", "SOLVERS"]

SOLVERS = ("admm", "fista", "omp")

_TINY = np.float32(1e-30)


class SharedOperator:
    """One patch matrix ``A`` (``m x K``) for every patch of a batch.

    Parameters
    ----------
    A : ndarray of shape (m, K), float32
    gram : ndarray of shape (m, m), optional
        ``A A^T`` (float64) if already computed (it is computed once per phase).
    """

    def __init__(self, A: np.ndarray, gram: np.ndarray | None = None):
        self.A = np.ascontiguousarray(A, dtype=np.float32)
        self.AT = np.ascontiguousarray(self.A.T)
        self._gram = gram
        self._sq = None

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


def _soft(x: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    """Soft threshold ``sign(x) max(|x| - kappa, 0)``, ``kappa`` per row (B, 1)."""
    return x - np.clip(x, -kappa, kappa)


def _rel_change(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    d = new - old
    num = np.einsum("bk,bk->b", d, d)
    den = np.einsum("bk,bk->b", new, new)
    return np.sqrt(num / np.maximum(den, _TINY))


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


def auto_rho(eigenvalues: np.ndarray) -> np.ndarray:
    """Initial ADMM penalty per patch: ``sqrt(l_min l_max)`` of ``B B^T`` (eigenvalues ``(B, m)``, ascending).

    The geometric mean of the extreme eigenvalues is the optimal penalty of ADMM on quadratic
    problems (Ghadimi et al., IEEE TAC 2015); ``l_min`` is taken over the measurements that
    have weight (zero rows give zero eigenvalues). :func:`admm` then adapts it (residual
    balancing).
    """
    top = np.maximum(eigenvalues[:, -1], 1e-30)
    low = np.where(eigenvalues > 1e-7 * top[:, None], eigenvalues, np.inf).min(axis=1)
    return np.sqrt(low * top)


#: Residual balancing of :func:`admm` (Boyd et al. 2011, section 3.4.1): every ``_BALANCE_EVERY``
#: iterations ``rho`` is doubled when the primal residual exceeds ``_BALANCE_RATIO`` times the
#: dual one, halved in the opposite case; the stopping test runs at the same iterations.
_BALANCE_EVERY = 5
_BALANCE_RATIO = 10.0


def admm(op, w: np.ndarray, y: np.ndarray, mu, *, max_iter: int, tol: float, rho=None,
         compact_fraction: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Scaled ADMM for the weighted lasso, Woodbury solve through one ``m x m`` eigendecomposition per patch.

    Splitting ``a = z``: ``a <- (B^T B + rho I)^-1 (B^T c + rho (z - u))`` with ``B = W A``,
    ``c = W y``, through ``(B^T B + rho I)^-1 q = (q - B^T (rho I + B B^T)^-1 B q) / rho``;
    ``B B^T = W (A A^T) W`` (with a shared ``A`` the Gram matrix ``A A^T`` is computed once per
    phase) is diagonalised once per patch, ``Q diag(l) Q^T``, so ``(rho I + B B^T)^-1`` is
    ``Q diag(1 / (rho + l)) Q^T`` for any ``rho`` and the penalty can adapt (residual balancing)
    at no cost. ``z <- soft(a + u, mu / rho)``; ``u <- u + a - z``. A patch stops when
    ``||z_k - z_{k-1}|| <= tol ||z_k||`` and ``||a_k - z_k|| <= tol ||z_k||``.

    Parameters
    ----------
    op : SharedOperator or BatchOperator
    w, y : ndarray of shape (B, m)
        Weights and measurements.
    mu : float or ndarray of shape (B,)
        l1 weight (per patch).
    max_iter : int
    tol : float
    rho : ndarray of shape (B,), optional
        Initial penalty per patch; default :func:`auto_rho`.

    Returns
    -------
    codes : ndarray of shape (B, K), float32 (the sparse iterate ``z``)
    iterations : ndarray of shape (B,), int32
    """
    w = np.asarray(w, dtype=np.float32)
    y = np.asarray(y, dtype=np.float32)
    b_n, m = w.shape
    k_n = op.shape[1]
    mu = np.broadcast_to(np.asarray(mu, dtype=np.float64).reshape(-1), (b_n,)).astype(np.float32)[:, None]
    btc = op.adj(w * w * y)  # B^T c, (B, K)
    g = op.gram()
    s = w[:, :, None].astype(np.float64) * g * w[:, None, :].astype(np.float64)
    with threadpool_limits(1):  # small LAPACK calls: 8x faster on one thread than on two (measured)
        ev, vec = np.linalg.eigh(s)
    ev = np.maximum(ev, 0.0)
    rho = auto_rho(ev) if rho is None else np.asarray(rho, dtype=np.float64).reshape(b_n)
    rho = rho.astype(np.float32)[:, None]
    q_t = np.ascontiguousarray(vec.transpose(0, 2, 1), dtype=np.float32)  # Q^T
    q_m = np.ascontiguousarray(vec, dtype=np.float32)
    ev = ev.astype(np.float32)
    inv = 1.0 / (rho + ev)
    p0 = op.fwd(btc)  # A B^T c
    h = btc / rho
    z = np.zeros((b_n, k_n), dtype=np.float32)
    u = np.zeros_like(z)
    act = _Active(b_n, k_n)
    pending = 0
    it = 0
    for it in range(1, max_iter + 1):
        v = z - u
        bq = w * (p0 + rho * op.fwd(v))
        # (rho I + B B^T)^-1 bq = Q diag(1 / (rho + l)) Q^T bq; einsum: numpy's stacked matmul of
        # matrix-vector products is ~30x slower here (measured, numpy 2 + OpenBLAS)
        r = np.einsum("bij,bj->bi", q_m, inv * np.einsum("bij,bj->bi", q_t, bq))
        a = h + v - op.adj(w * r / rho)
        x = a + u
        z_new = _soft(x, mu / rho)
        u = x - z_new
        if it % _BALANCE_EVERY and it != max_iter:  # residuals and stops every few iterations only
            z = z_new
            continue
        znorm = np.sqrt(np.einsum("bk,bk->b", z_new, z_new))
        dz = z_new - z
        change = np.sqrt(np.einsum("bk,bk->b", dz, dz))
        pr = a - z_new
        primal = np.sqrt(np.einsum("bk,bk->b", pr, pr))
        floor = np.maximum(znorm, _TINY)
        done = (change <= tol * floor) & (primal <= tol * floor)
        z = z_new
        pending += int(done.sum())
        if it == max_iter:
            break
        dual = rho[:, 0] * change
        up = primal > _BALANCE_RATIO * dual
        down = dual > _BALANCE_RATIO * primal
        if up.any() or down.any():
            factor = np.where(up, 2.0, np.where(down, 0.5, 1.0)).astype(np.float32)[:, None]
            rho = rho * factor
            u = u / factor
            inv = 1.0 / (rho + ev)
            h = btc / rho
        if pending and pending >= max(1, compact_fraction * len(act.rows)):
            keep = act.retire(done, z, it)
            pending = 0
            if not keep.all():
                if not keep.any():
                    return act.out, act.iters
                z, u, w, p0, h, btc, q_m, q_t, ev, inv, rho, mu = (
                    t[keep] for t in (z, u, w, p0, h, btc, q_m, q_t, ev, inv, rho, mu))
                op = op.subset(keep)
    act.retire(np.ones(len(act.rows), dtype=bool), z, it)
    return act.out, act.iters


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
    with threadpool_limits(1):
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


def omp(op, w: np.ndarray, y: np.ndarray, sparsity: int, *, tol2: np.ndarray | None = None
        ) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal matching pursuit on the weighted problem ``B = W A``, columns normalised for the selection.

    Each step picks the atom whose normalised column of ``B`` correlates most with the
    weighted residual, then refits all chosen atoms by weighted least squares (float64
    normal equations with a tiny ridge). A patch stops after ``sparsity`` atoms or when
    its squared weighted residual is at most ``tol2[b]`` (e.g. the number of usable
    measurements: a chi-square stop).

    Returns
    -------
    codes : ndarray of shape (B, K), float32
    atoms : ndarray of shape (B,), int32 (atoms used)
    """
    w = np.asarray(w, dtype=np.float32)
    y = np.asarray(y, dtype=np.float32)
    b_n, m = w.shape
    k_n = op.shape[1]
    t_n = int(min(sparsity, k_n, m))
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
    if tol2 is not None:
        active &= np.einsum("bm,bm->b", c, c) > tol2
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
        with threadpool_limits(1):
            sol = np.linalg.solve(gram, rhs)[:, :, 0]
        coef[active, :k + 1] = sol[active]
        used[active] = k + 1
        r = c - np.matmul(cols[:, :, :k + 1], coef[:, :k + 1, None])[:, :, 0]
        if tol2 is not None:
            active &= np.einsum("bm,bm->b", r, r) > tol2
    out = np.zeros((b_n, k_n), dtype=np.float32)
    for k in range(t_n):
        has = used > k
        out[rows[has], sel[has, k]] = coef[has, k]
    return out, used
