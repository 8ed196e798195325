"""Compiled element-wise and small triangular kernels of the Gaussian-mixture reconstruction (:mod:`._gmm`).

Why compiled (numba, ``nogil``, as :mod:`._solvers`' ADMM steps): the reconstruction solves hundreds of thousands of
small systems (``m + 1 = 65`` for one 8 x 8 shot) on a thread pool. Around numpy's batched Cholesky factorisation,
which releases the GIL, the work was many passes of numpy over ``(B, m, m)`` arrays and scipy's batched triangular
solve, which loops over the batch in Python and holds the GIL. A py-spy profile of the default command-line path
(``benchmarks/cli_default.py``: one shot of city-interior at Lytro size, 120 CPU seconds on 2 threads) put 10 s in
forming the systems, 7 s in the triangular solves and 19 s in the refinement's truncated means
(``scipy.special.log_ndtr`` on masked copies). Each kernel here is one pass over its data; the factorisation itself
stays numpy's (LAPACK's ``dpotrf``). Back to back (docs/benchmarks.md, stop 45): the default path 62.5-65.8 s before,
42.2-46.2 s after; a two-shot reconstruction at Lytro size 16 % faster.

The formation gives numpy's numbers bit for bit; the back-substitution and the truncated mean differ from scipy's by
rounding (the latter is more exact far below 0, where the former formula lost up to all its digits to cancellation:
tests/recon/test_batched.py). The lights refit (:mod:`._lights`) can turn such rounding into a different fit of a
window whose hypotheses have near-equal evidence (one of four default-path captures, 52.10 -> 52.22 dB).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["whitened_system", "back_substitute", "truncated_mean"]


def whitened_system(kmat: np.ndarray, w: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``[[W K W + I, r], [r^T, r^T r + 1]]`` per patch, ``(B, m + 1, m + 1)`` (``kmat``: ``(m, m)`` shared by the
    batch or ``(B, m, m)``; ``w``, ``r``: ``(B, m)``); the same numbers as numpy's ``K * w_i * w_j + 1``."""
    b_n, m = w.shape
    c = np.empty((b_n, m + 1, m + 1))
    k = np.ascontiguousarray(kmat, np.float64)
    _whitened(k if k.ndim == 3 else k[None], k.ndim == 3, np.ascontiguousarray(w, np.float64),
              np.ascontiguousarray(r, np.float64), (r * r).sum(axis=1), c)
    return c


@numba.njit(nogil=True, cache=True)
def _whitened(k3, per_patch, w, r, rr, c):  # pragma: no cover - compiled (tests compare it with numpy)
    b_n, m = w.shape
    for b in range(b_n):
        k = k3[b] if per_patch else k3[0]
        cb = c[b]
        wb = w[b]
        for i in range(m):
            wi = wb[i]
            ci = cb[i]
            ki = k[i]
            for j in range(m):
                ci[j] = ki[j] * wi * wb[j]
            ci[i] += 1.0
            ci[m] = r[b, i]
            cb[m, i] = r[b, i]
        cb[m, m] = rr[b] + 1.0


def back_substitute(chol: np.ndarray) -> np.ndarray:
    """``alpha = L^-T z`` per patch from the Cholesky factor ``[[L, 0], [z^T, d]]`` of :func:`whitened_system`,
    ``(B, m)``."""
    b_n, m1 = chol.shape[:2]
    out = np.empty((b_n, m1 - 1))
    _back(chol, out)
    return out


@numba.njit(nogil=True, cache=True)
def _back(chol, out):  # pragma: no cover - compiled (tests compare it with scipy.linalg.solve_triangular)
    b_n, m = out.shape
    for b in range(b_n):
        for i in range(m - 1, -1, -1):
            s = chol[b, m, i]
            for k in range(i + 1, m):
                s -= chol[b, k, i] * out[b, k]
            out[b, i] = s / chol[b, i, i]


def truncated_mean(x: np.ndarray, std) -> np.ndarray:
    """``E[X | X > 0]`` for ``X ~ N(x, std^2)`` (``max(x, 0)`` where ``std`` is 0), any shapes ``std`` broadcasts
    to ``x``'s."""
    x = np.ascontiguousarray(x, np.float64)
    out = np.empty(x.shape)
    x2 = x.reshape((-1, x.shape[-1]) if x.ndim else (1, 1))
    std = np.asarray(std, np.float64)
    per_row = std.ndim == x.ndim and std.ndim >= 1 and std.shape[-1] == 1 and std.size * x.shape[-1] == x.size
    std2 = (np.ascontiguousarray(std).reshape(-1, 1) if per_row  # one std a row (the refinement's patches)
            else np.ascontiguousarray(np.broadcast_to(std, x.shape)).reshape(x2.shape))
    _truncated(x2, std2, out.reshape(x2.shape))
    return out


@numba.njit(nogil=True, cache=True)
def _inverse_mills(a):  # pragma: no cover - compiled (tests compare truncated_mean with scipy and asymptotics)
    """``phi(a) / Phi(a)``: ``sqrt(2 / pi) exp(-a^2 / 2) / erfc(-a / sqrt 2)`` above -30; below, where both would
    underflow, ``1 / R(-a)`` with Mills' ratio as its continued fraction ``R(t) = 1 / (t + 1 / (t + 2 / (t + 3 /
    ...)))`` (Abramowitz and Stegun 26.2.14), 40 terms: exact to rounding for ``t >= 30``."""
    if a > -30.0:
        return 0.7978845608028654 * math.exp(-0.5 * a * a) / math.erfc(-0.7071067811865476 * a)
    t = -a
    f = t
    for k in range(40, 0, -1):
        f = t + k / f
    return f


@numba.njit(nogil=True, cache=True)
def _truncated(x, std, out):  # pragma: no cover - compiled (tests compare truncated_mean with scipy)
    """``x``, ``out``: ``(R, C)``; ``std``: ``(R, C)`` or ``(R, 1)``. From 9 standard deviations above 0 the
    correction ``std phi(a) / Phi(a)`` is below 1.2e-19 of ``x``, under half its last bit: ``x`` itself, not
    computed."""
    r_n, c_n = x.shape
    per_row = std.shape[1] == 1
    for i in range(r_n):
        xi, oi, si = x[i], out[i], std[i]
        for j in range(c_n):
            v = xi[j]
            s = si[0] if per_row else si[j]
            if s > 0.0:
                oi[j] = v + s * _inverse_mills(v / s) if v < 9.0 * s else v
            else:
                oi[j] = max(v, 0.0)
