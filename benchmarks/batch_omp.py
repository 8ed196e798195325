"""Batch-OMP against scikit-learn's ``orthogonal_mp_gram`` on the same problem, in one process.

Prints, for each size, the time of both on the same signals, signals per second, the speed
ratio and the share of signals whose supports agree. The dictionary is random (unit-norm
Gaussian atoms); signals are sparse combinations of 10 atoms plus noise at 20 dB SNR, so
the supports are meaningful.

    python benchmarks/batch_omp.py                       # n=1200, K=3240 and n=2700, K=5400; N=10000
    python benchmarks/batch_omp.py --sizes 1200x3240 --signals 10000
"""

from __future__ import annotations

import argparse
import os
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
    ap.add_argument("--sizes", default="1200x3240,2700x5400", help="comma-separated n x K")
    ap.add_argument("--signals", type=int, default=10000)
    ap.add_argument("--sparsity", type=int, default=10)
    args = ap.parse_args()
    blas = [f"{i['internal_api']} {i.get('num_threads')} threads" for i in threadpool_info()]
    print(f"cores {os.cpu_count()}, BLAS: {', '.join(blas)}")
    print(f"{'n':>5} {'K':>6} {'N':>6}  {'lfproc s':>9} {'sklearn s':>9} {'lfproc sig/s':>12} {'sklearn sig/s':>13} "
          f"{'ratio':>6} {'same support':>12}")
    for size in args.sizes.split(","):
        n, k = (int(v) for v in size.split("x"))
        d, x = problem(n, k, args.signals, args.sparsity)
        t0 = time.perf_counter()
        ours = batch_omp(d, x, args.sparsity)
        t_ours = time.perf_counter() - t0
        d64 = d.astype(np.float64)
        t0 = time.perf_counter()
        gram = d64.T @ d64  # scikit-learn is given the Gram matrix and D^T X, as Batch-OMP computes them
        ref = orthogonal_mp_gram(gram, d64.T @ x.astype(np.float64), n_nonzero_coefs=args.sparsity)
        t_ref = time.perf_counter() - t0
        same = ((ours != 0) == (ref != 0)).all(axis=0).mean()
        print(f"{n:>5} {k:>6} {args.signals:>6}  {t_ours:>9.2f} {t_ref:>9.1f} {args.signals / t_ours:>12.0f} "
              f"{args.signals / t_ref:>13.0f} {t_ref / t_ours:>6.1f} {100 * same:>11.2f}%", flush=True)


if __name__ == "__main__":
    main()
