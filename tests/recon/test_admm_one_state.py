"""lfproc.recon's ADMM in its one-state form (``x = z + u``, ``A x`` carried in measurement space) against the
two-state form it replaced: the same iterates to float32 rounding, the same iteration counts."""

from __future__ import annotations

import numpy as np
import pytest

from lfproc.recon import _solvers
from lfproc.recon._solvers import (_ABS_TOL, _BALANCE_EVERY, _BALANCE_RATIO, _LSQ_THRESHOLD, _Active, _axpy,
                                   _sumsq, BatchOperator, SharedOperator, admm)


def _two_state_chunk(op, fac, w, y, mu, rho_rel, *, max_iter, tol, alpha, balance, compact_fraction):
    """The ADMM chunk as it was before the one-state form (commit 50304ab, verbatim but for the names)."""
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
    lsq_cols = np.flatnonzero(lsq[0])
    denom = w2 + rb
    z = np.zeros((k_n, b_n), dtype=np.float32)  # z / kappa
    u = np.zeros_like(z)  # u / kappa (scaled dual of a = z)
    v = np.empty_like(z)
    s = np.zeros((m, b_n), dtype=np.float32)  # the noiseless measurements A a
    d = np.zeros_like(s)  # scaled dual of s = A a
    alpha = np.float32(alpha)
    act = _Active(b_n, k_n)
    out_t = np.zeros((k_n, b_n), dtype=np.float32)
    pending = 0
    it = 0
    for it in range(1, max_iter + 1):
        check = it % _BALANCE_EVERY == 0 or it == max_iter
        np.subtract(z, u, out=v)  # v = z - u
        t = op.fwd_t(v)
        t *= unit  # A v
        e = fac.times(fac.N, (s - d) - t)  # the a step: a = v + A^T e
        a_m = t + fac.times(fac.G, e)  # A a
        if check:
            z_old, u_old, d_old, s_old = z.copy(), u.copy(), d, s
        # x = alpha a + (1 - alpha) z + u = v + (2 - alpha) u + alpha A^T e, built in v
        _axpy(u, v, 2 - alpha)
        op.adj_t_add((alpha / unit) * e, v)
        np.clip(v, -1.0, 1.0, out=u)  # u_new = x - soft(x, kappa) = clip(x, -kappa, kappa)
        if lsq_cols.size:
            u[:, lsq_cols] = 0.0  # threshold 0
        np.subtract(v, u, out=z)  # z_new = soft(x, kappa)
        ah = alpha * a_m + (1 - alpha) * s  # relaxed A a
        ah += d
        s = (w2y + rb * ah) / denom  # argmin 1/2 |w (s - y)|^2 + rho beta / 2 |s - ah|^2
        d = ah - s
        if not check:
            continue
        k_row = unit[0].astype(np.float64)
        np.subtract(z, z_old, out=z_old)
        change = k_row * np.sqrt(_sumsq(z_old))
        np.subtract(u, u_old, out=u_old)
        dd = d - d_old  # relaxed A a - s
        primal = np.sqrt(k_row**2 * _sumsq(u_old) + beta[0] * _sumsq(dd))
        # relative plus absolute (Boyd et al. 2011, section 3.3.1): a code near 0 stops too
        eps = tol * k_row * np.sqrt(_sumsq(z)) + atol
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
                f_unit = np.where(lsq, np.float32(1.0), f)  # a threshold-0 column keeps its units
                unit = unit / f_unit
                denom = w2 + rb
                z *= f_unit  # z / kappa with the new kappa; u / kappa is unchanged (0 with threshold 0)
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
            beta, rb, unit, lsq, atol = beta[:, keep], rb[:, keep], unit[:, keep], lsq[:, keep], atol[keep]
            lsq_cols = np.flatnonzero(lsq[0])
            v = np.empty_like(z)
            op = op.subset(keep)
            fac = fac.subset(keep)
    out_t[:, act.rows] = z * unit
    act.iters[act.rows] = it
    return np.ascontiguousarray(out_t.T), act.iters


def _problem(seed, m=64, k=256, b=40):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((m, k)).astype(np.float32)
    w = (0.5 + rng.random((b, m))).astype(np.float32)
    w[:5, :9] = 0  # unusable measurements
    code = np.where(rng.random((b, k)) < 0.03, rng.standard_normal((b, k)), 0.0)
    y = (code @ A.T.astype(np.float64) + 0.05 * rng.standard_normal((b, m))).astype(np.float32)
    y *= np.float32(10.0) ** rng.uniform(-3, 3, (b, 1)).astype(np.float32)  # HDR: patches of many scales
    lam = np.abs((w * w * y) @ A).max(axis=1)
    mu = (lam * rng.uniform(0.02, 0.5, b)).astype(np.float32)
    mu[3] = 0.0  # weighted least squares (a threshold-0 column)
    mu[4] = 2 * lam[4]  # an exact zero code
    return A, w, y, mu


@pytest.mark.parametrize("tol", [0.0, 1e-3])
@pytest.mark.parametrize("operator", ["shared", "batch"])
def test_one_state_admm_equals_the_two_state_form(monkeypatch, tol, operator):
    """Residual balancing (rho changes of the units), compaction (tol 1e-3: patches leave at different
    iterations), a threshold-0 column and a zero code: iteration counts equal, codes equal to float32 rounding:
    within 10x of how far the two-state form's codes move when the data move by one float32 ulp (the forms
    round differently at every iteration, not once; measured 2.5-5.5x in the median, 0.5-3x at the worst patch)."""
    A, w, y, mu = _problem(11)
    op = SharedOperator(A) if operator == "shared" else BatchOperator(np.stack([A] * len(w)))
    z_new, it_new = admm(op, w, y, mu, max_iter=200, tol=tol)
    monkeypatch.setattr(_solvers, "_admm_chunk", _two_state_chunk)
    z_old, it_old = admm(op, w, y, mu, max_iter=200, tol=tol)
    assert (it_new == it_old).all() and it_new[4] == 0 and (np.delete(it_new, 4) < 200).any() == (tol > 0)
    scale = np.abs(z_old).max(axis=1, keepdims=True) + 1e-30
    y_ulp = y * (1 + np.float32(2.0**-23) * np.random.default_rng(0).choice([-1, 1], y.shape)).astype(np.float32)
    z_ulp, _ = admm(op, w, y_ulp, mu, max_iter=200, tol=tol)
    rel = np.abs(z_new - z_old).max(axis=1) / scale[:, 0]  # per patch, relative to its largest coefficient
    rel_ulp = np.abs(z_ulp - z_old).max(axis=1) / scale[:, 0]
    assert rel.max() < max(10 * rel_ulp.max(), 1e-6), (rel.max(), rel_ulp.max())
    assert np.median(rel) < max(10 * np.median(rel_ulp), 1e-6), (np.median(rel), np.median(rel_ulp))
    assert not z_new[4].any()


def test_the_sparse_product_equals_the_dense_one():
    rng = np.random.default_rng(2)
    A = rng.standard_normal((32, 300)).astype(np.float32)
    Z = np.where(rng.random((300, 17)) < 0.02, rng.standard_normal((300, 17)), 0).astype(np.float32)
    Z[:, 3] = 0  # an empty column
    op = SharedOperator(A)
    np.testing.assert_allclose(op.fwd_t_sparse(Z), op.fwd_t(Z), rtol=1e-5, atol=1e-5 * np.abs(op.fwd_t(Z)).max())
    assert op.fwd_t_sparse(Z).flags.c_contiguous and op.fwd_t_sparse(Z).dtype == np.float32
