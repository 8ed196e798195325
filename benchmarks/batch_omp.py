"""Batch-OMP against scikit-learn's ``orthogonal_mp_gram`` on the same problem, in one process.

Prints, for each size, the time of both on the same signals, signals per second, the speed
ratio and the share of signals whose supports agree. lfproc is timed before and after
scikit-learn's (much longer) run and the slower of the two is compared, so a change of load
on a shared machine cannot flatter the ratio. The dictionary is random (unit-norm
Gaussian atoms); signals are sparse combinations of 10 atoms plus noise at 20 dB SNR, so
the supports are meaningful.

Each solver's throughput is also given as a fraction of the machine's float32 GEMM rate,
measured in the same run (``D^T X`` for a block of the same signals, best of three): the
solver's signals per second times ``2 n K`` (the flops of the signal's correlations with the
atoms, the one product every OMP needs) over the GEMM's flops per second. 1.0 would be OMP at
the cost of its correlations alone; the rest is the greedy steps.

Both times include the Gram matrix ``D^T D`` (``2 n K^2`` flops: at the paper's size more
than the correlations of 10,000 signals; K-SVD computes it once per iteration for 300,000).

scikit-learn is skipped (``-``) above ``--max-sklearn-atoms`` atoms (it copies the ``K x K``
float64 Gram matrix for each signal: 2.2 GB at the paper's K = 16402).

    python benchmarks/batch_omp.py                       # n=1200, K=3240 and n=6075, K=16402 (paper); N=10000
    python benchmarks/batch_omp.py --sizes 1200x3240 --signals 10000
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np


def problem(n, k, n_signals, t, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((n, k)).astype(np.float32)
    d /= np.linalg.norm(d, axis=0)
    a = np.zeros((k, n_signals), dtype=np.float32)
    for i in range(n_signals):
        a[rng.choice(k, t, replace=False), i] = rng.standard_normal(t)
    x = d @ a
    noise = rng.standard_normal(x.shape).astype(np.float32)
    x += noise * (np.linalg.norm(x) / np.linalg.norm(noise) / 10)
    return d, x


def main():
    from sklearn.linear_model import orthogonal_mp_gram
    from threadpoolctl import threadpool_info

    from lfproc.dictionary import batch_omp

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1200x3240,6075x16402", help="comma-separated n x K")
    ap.add_argument("--signals", type=int, default=10000)
    ap.add_argument("--sparsity", type=int, default=10)
    ap.add_argument("--max-sklearn-atoms", type=int, default=8000)
    args = ap.parse_args()
    blas = [f"{i['internal_api']} {i.get('num_threads')} threads" for i in threadpool_info()]
    print(f"cores {os.cpu_count()}, BLAS: {', '.join(blas)}; load average {os.getloadavg()[0]:.2f}")
    print(f"{'n':>5} {'K':>6} {'N':>6}  {'lfproc s':>9} {'sklearn s':>9} {'lfproc sig/s':>12} {'sklearn sig/s':>13} "
          f"{'ratio':>6} {'same support':>12}  {'GEMM GFLOP/s':>12} {'lfproc/GEMM':>11} {'sklearn/GEMM':>12} "
          f"{'lfproc cores':>12}")
    for size in args.sizes.split(","):
        n, k = (int(v) for v in size.split("x"))
        d, x = problem(n, k, args.signals, args.sparsity)
        gemm = gemm_rate(d, x)
        c0, t0 = time.process_time(), time.perf_counter()
        ours = batch_omp(d, x, args.sparsity)
        t_ours = time.perf_counter() - t0
        cores = (time.process_time() - c0) / t_ours
        rate_ours = args.signals / t_ours
        flops = 2.0 * n * k  # per signal: its correlations with the atoms
        if k <= args.max_sklearn_atoms:
            d64 = d.astype(np.float64)
            t0 = time.perf_counter()
            gram = d64.T @ d64  # scikit-learn is given the Gram matrix and D^T X, as Batch-OMP computes them
            ref = orthogonal_mp_gram(gram, d64.T @ x.astype(np.float64), n_nonzero_coefs=args.sparsity)
            t_ref = time.perf_counter() - t0
            # lfproc again after scikit-learn's long run: the load may have changed meanwhile (a shared machine);
            # the slower of the two lfproc runs is the one compared (conservative)
            t0 = time.perf_counter()
            again = batch_omp(d, x, args.sparsity)
            t_again = time.perf_counter() - t0
            assert np.array_equal(again, ours)
            print(f"  (lfproc {t_ours:.2f} s before scikit-learn, {t_again:.2f} s after; "
                  f"load average now {os.getloadavg()[0]:.2f})")
            t_ours = max(t_ours, t_again)
            rate_ours = args.signals / t_ours
            same = ((ours != 0) == (ref != 0)).all(axis=0).mean()
            rate_ref = args.signals / t_ref
            ref_cols = (f"{t_ref:>9.1f} {rate_ours:>12.0f} {rate_ref:>13.0f} {t_ref / t_ours:>6.1f} {100 * same:>11.2f}%"
                        f"  {gemm / 1e9:>12.0f} {rate_ours * flops / gemm:>11.3f} {rate_ref * flops / gemm:>12.5f}")
        else:
            ref_cols = (f"{'-':>9} {rate_ours:>12.0f} {'-':>13} {'-':>6} {'-':>12}  {gemm / 1e9:>12.0f} "
                        f"{rate_ours * flops / gemm:>11.3f} {'-':>12}")
        print(f"{n:>5} {k:>6} {args.signals:>6}  {t_ours:>9.2f} {ref_cols} {cores:>12.2f}", flush=True)
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB; "
          f"load average {os.getloadavg()[0]:.2f}")


def gemm_rate(d, x, block=2048):
    """float32 GEMM flops per second on this machine now: ``D^T X`` for a block of the signals, best of three."""
    xb = np.ascontiguousarray(x[:, :block].T)  # signals as rows, as Batch-OMP multiplies them
    out = np.empty((xb.shape[0], d.shape[1]), dtype=np.float32)
    np.matmul(xb, d, out=out)  # warm-up
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        np.matmul(xb, d, out=out)
        best = min(best, time.perf_counter() - t0)
    return 2.0 * xb.shape[0] * d.shape[0] * d.shape[1] / best


if __name__ == "__main__":
    main()
