"""The compiled kernels of the Gaussian-mixture reconstruction (lfproc.recon._batched) against numpy, scipy and
published asymptotics."""

import numpy as np
import pytest


@pytest.mark.parametrize("per_patch", [False, True])
def test_whitened_system_is_numpys_formation_bit_for_bit(per_patch):
    """Reference: the numpy formation it replaced, ``K * w_i * w_j`` plus the identity, bordered by ``r`` and
    ``r^T r + 1``; the same operations in the same order, so the same bits."""
    from lfproc.recon._batched import whitened_system

    rng = np.random.default_rng(0)
    b_n, m = 7, 12
    g = rng.normal(size=(b_n if per_patch else 1, m, m))
    kmat = g @ g.transpose(0, 2, 1)
    kmat = kmat if per_patch else kmat[0]
    w = rng.uniform(0, 2, (b_n, m))
    w[w < 0.4] = 0.0  # unusable measurements
    r = rng.normal(size=(b_n, m))
    want = np.empty((b_n, m + 1, m + 1))
    np.multiply(kmat if per_patch else kmat[None], w[:, :, None], out=want[:, :m, :m])
    want[:, :m, :m] *= w[:, None, :]
    want[:, m, :m] = want[:, :m, m] = r
    want[:, m, m] = (r * r).sum(axis=1)
    want.reshape(b_n, -1)[:, ::m + 2] += 1.0
    np.testing.assert_array_equal(whitened_system(kmat, w, r), want)


def test_back_substitution_is_scipys_triangular_solve():
    """``alpha = L^-T z`` from the bordered factor; reference: scipy.linalg.solve_triangular (trans='T')."""
    import scipy.linalg as sl

    from lfproc.recon._batched import back_substitute, whitened_system

    rng = np.random.default_rng(1)
    b_n, m = 5, 16
    g = rng.normal(size=(m, m))
    chol = np.linalg.cholesky(whitened_system(g @ g.T, rng.uniform(0.1, 2, (b_n, m)), rng.normal(size=(b_n, m))))
    want = np.stack([sl.solve_triangular(c[:m, :m], c[m, :m], lower=True, trans="T") for c in chol])
    np.testing.assert_allclose(back_substitute(chol), want, rtol=1e-12, atol=1e-14)


def test_truncated_mean_is_scipys_truncnorm_mean():
    """Reference: scipy.stats.truncnorm's mean, over the range the refinement meets (a = x / std from -30 to 9)."""
    from scipy.stats import truncnorm

    from lfproc.recon._batched import truncated_mean

    rng = np.random.default_rng(2)
    s = rng.uniform(0.01, 3.0, 400)
    x = rng.uniform(-30, 9, 400) * s
    np.testing.assert_allclose(truncated_mean(x, s), truncnorm.mean(-x / s, np.inf, loc=x, scale=s), rtol=1e-10)


@pytest.mark.parametrize("t", [35.0, 113.28, 1e4])
def test_far_below_zero_the_truncated_mean_follows_its_asymptotic_series(t):
    """Known answer: for ``x = -t std`` with t large, ``E[X | X > 0] = std / t (1 - 2 / t^2 + 10 / t^4 - 74 / t^6
    + 706 / t^8 - 8162 / t^10 + ...)``: ``t / (1 - u) - t`` with ``Q(t) / phi(t) = (1 - u) / t``, ``u = 1 / t^2 - 3 /
    t^4 + 15 / t^6 - ...`` (Mills' ratio's asymptotic series, Abramowitz and Stegun 26.2.12; the coefficients
    expanded in exact fractions). x cancels against std phi / Phi: the former log_ndtr formula was 3e-8 off at
    t = 113 and 61 % at t = 1e4."""
    from lfproc.recon._batched import truncated_mean

    std = 9.649
    terms = [1, -2, 10, -74, 706, -8162]
    want = std / t * sum(c / t ** (2 * i) for i, c in enumerate(terms))
    got = truncated_mean(np.array([-t * std]), std)[0]
    # the error: x's rounding (|x| 2^-53, the cancellation) and the series' next term (110410 / t^12)
    assert abs(got - want) <= 4 * t * std * 2.0**-53 + 110410 / t**12 * want, (got, want)


def test_truncated_mean_shapes_and_edges():
    """A per-row std and the same std given per sample agree bit for bit; from 9 std above 0 it is x itself; std 0
    is max(x, 0); a scalar x works."""
    from lfproc.recon._batched import truncated_mean

    rng = np.random.default_rng(3)
    x = rng.normal(0, 3, (6, 50))
    s = rng.uniform(0, 1, (6, 1))
    s[2] = 0.0
    got = truncated_mean(x, s)
    np.testing.assert_array_equal(got, truncated_mean(x, np.broadcast_to(s, x.shape).copy()))
    far = x >= 9 * s
    assert far[s[:, 0] > 0].any()
    np.testing.assert_array_equal(got[far & (s > 0)], x[far & (s > 0)])
    np.testing.assert_array_equal(got[2], np.maximum(x[2], 0.0))
    assert (got[s[:, 0] > 0] > 0).all()
    assert truncated_mean(np.float64(-1.0), 0.0) == 0.0 and truncated_mean(np.float64(2.0), 0.1) == 2.0
