"""The sparse solvers' throughput against this machine's float32 GEMM rate, in one run.

Prints, in order:

1. the float32 GEMM rate (2048^3 SGEMM, best of 3), again at the end (a shared machine's
   load changes during the run: both figures bound the fractions);
2. Batch-OMP (:func:`lfproc.dictionary.batch_omp`) against scikit-learn's
   ``orthogonal_mp_gram`` on the same signals (n = 1200, K = 3240, 10 atoms, ``--signals``,
   default 10,000): both times include their Gram matrix (float32 for lfproc, float64 for
   scikit-learn, as benchmarks/batch_omp.py), the speed ratio and the share of equal supports;
3. Batch-OMP at the paper's size (n = 6075, K = 16402, 10 atoms, ``--paper-signals``, default
   3000): the Gram matrix's time separately, then signals/s of the coding and its ``D^T X``
   GEMM work as a fraction of the GEMM rate;
4. a reconstruction (ADMM, the defaults) of the top ``--rows`` rows of the Lytro-size capture
   of benchmarks/reconstruct.py (5 x 5 x 434 x 625, 2 shots, periodic mask): patches/s and its
   useful float32 work (two ``m x K`` products per patch and iteration, ``Phi D`` per phase and
   the final ``D a``) as a fraction of the GEMM rate;
5. the process's peak resident memory (``resource.getrusage``).

    python benchmarks/solvers.py                               # all (~5-10 min on 2 cores)
    python benchmarks/solvers.py --signals 2000 --rows 60      # a quicker look
    python benchmarks/solvers.py --skip sklearn,paper          # parts: sklearn, paper, reconstruct
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from batch_omp import problem  # noqa: E402
from reconstruct import gemm_rate  # noqa: E402


def peak_rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def omp_vs_sklearn(n_signals: int, sparsity: int) -> None:
    from sklearn.linear_model import orthogonal_mp_gram

    from lfproc.dictionary import batch_omp

    n, k = 1200, 3240
    d, x = problem(n, k, n_signals, sparsity)
    batch_omp(d, x[:, :50], sparsity)  # warm-up (imports, first BLAS calls)
    t0 = time.perf_counter()
    ours = batch_omp(d, x, sparsity)
    t_ours = time.perf_counter() - t0
    d64 = d.astype(np.float64)
    t0 = time.perf_counter()
    gram = d64.T @ d64
    ref = orthogonal_mp_gram(gram, d64.T @ x.astype(np.float64), n_nonzero_coefs=sparsity)
    t_ref = time.perf_counter() - t0
    same = ((ours != 0) == (ref != 0)).all(axis=0).mean()
    print(f"Batch-OMP vs scikit-learn orthogonal_mp_gram (n={n}, K={k}, N={n_signals}, {sparsity} atoms): "
          f"lfproc {t_ours:.2f} s ({n_signals / t_ours:.0f} signals/s), scikit-learn {t_ref:.1f} s "
          f"({n_signals / t_ref:.0f} signals/s): ratio {t_ref / t_ours:.1f}x; equal supports {100 * same:.2f} %",
          flush=True)


def omp_paper(n_signals: int, sparsity: int, rate: float) -> None:
    from lfproc.dictionary import batch_omp
    from lfproc.dictionary._omp import gram_matrix

    n, k = 6075, 16402
    rng = np.random.default_rng(0)
    d = rng.standard_normal((n, k), dtype=np.float32)
    d /= np.linalg.norm(d, axis=0)
    a = np.zeros((k, n_signals), dtype=np.float32)
    for i in range(n_signals):
        a[rng.choice(k, sparsity, replace=False), i] = rng.standard_normal(sparsity)
    x = d @ a
    del a
    t0 = time.perf_counter()
    gram = gram_matrix(d)
    t_gram = time.perf_counter() - t0
    batch_omp(d, x[:, :20], sparsity, gram=gram)  # warm-up
    t0 = time.perf_counter()
    batch_omp(d, x, sparsity, gram=gram)
    t_code = time.perf_counter() - t0
    gemm = 2.0 * n * k * n_signals
    print(f"Batch-OMP at the paper's size (n={n}, K={k}, N={n_signals}, {sparsity} atoms): Gram matrix {t_gram:.1f} s "
          f"(once per dictionary); coding {t_code:.2f} s = {n_signals / t_code:.0f} signals/s; its D^T X GEMM work "
          f"{gemm / t_code / 1e9:.1f} GFLOP/s = {100 * gemm / t_code / rate:.0f} % of the GEMM rate", flush=True)


def reconstruction(rows: int, threads: int | None, rate: float) -> None:
    from reconstruct import run_case

    args = SimpleNamespace(rows=rows, solver="admm", max_iter=None, tol=None, threads=threads, nonperiodic=False)
    print(f"Reconstruction (benchmarks/reconstruct.py's lytro case, top {rows} rows):", flush=True)
    run_case("lytro", args, rate)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--signals", type=int, default=10_000, help="signals of the scikit-learn comparison")
    ap.add_argument("--paper-signals", type=int, default=3000, help="signals at the paper's size")
    ap.add_argument("--sparsity", type=int, default=10)
    ap.add_argument("--rows", type=int, default=120, help="sensor rows of the reconstruction")
    ap.add_argument("--threads", type=int, default=None, help="reconstruction threads (default: the CPUs)")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: sklearn, paper, reconstruct")
    args = ap.parse_args()
    skip = {s.strip() for s in args.skip.split(",") if s.strip()}
    os.environ.setdefault("LFPROC_PROGRESS", "0")
    from threadpoolctl import threadpool_info

    blas = ", ".join(f"{i['internal_api']} {i.get('num_threads')} threads" for i in threadpool_info())
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"cores {os.cpu_count()}, BLAS: {blas}; load average at start {load:.2f}")
    rate = gemm_rate()
    print(f"float32 SGEMM rate (2048^3, best of 3): {rate / 1e9:.1f} GFLOP/s", flush=True)
    if "sklearn" not in skip:
        omp_vs_sklearn(args.signals, args.sparsity)
    if "paper" not in skip:
        omp_paper(args.paper_signals, args.sparsity, rate)
    if "reconstruct" not in skip:
        reconstruction(args.rows, args.threads, rate)
    rate2 = gemm_rate()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"float32 SGEMM rate at the end: {rate2 / 1e9:.1f} GFLOP/s; load average {load:.2f}")
    print(f"peak resident memory (max RSS) {peak_rss_gib():.2f} GiB")


if __name__ == "__main__":
    main()
