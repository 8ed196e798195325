"""Time and memory of the projection operator Phi on a 5 x 5 x 512 x 512 RGB light field.

Usage: python benchmarks/projection.py [--size 512] [--shots 1 2] [--repeat 3]

Prints, per mask kind and number of shots: operator build time, forward and adjoint time
(best of --repeat), the adjoint identity's relative error, the time of 1000 patch
matrices through ``patch_sparse`` (gather form) and the peak traced memory (tracemalloc) of building
the operator and of forward + adjoint (beyond the operator and the input).
"""

from __future__ import annotations

import argparse
import resource
import time
import tracemalloc

import numpy as np

from lfproc.camera.projection import build_operator, make_mask


def best(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--shots", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    n = args.size
    rng = np.random.default_rng(0)
    lf = rng.random((5, 5, n, n, 3), dtype=np.float32)
    print(f"light field 5 x 5 x {n} x {n} x 3 float32 ({lf.nbytes / 2**20:.0f} MiB)")
    for kind, period in (("random", None), ("shifted", None), ("random", 4)):
        for shots in args.shots:
            tracemalloc.start()
            t = time.perf_counter()
            mask = make_mask(kind, shots=shots, views=(5, 5), size=(n, n), period=period, random_state=1)
            op = build_operator(mask, views=(5, 5), size=(n, n))
            t_build = time.perf_counter() - t
            _, peak_build = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
            base, _ = tracemalloc.get_traced_memory()
            t_fwd, y = best(lambda: op.forward(lf), args.repeat)
            t_adj, x = best(lambda: op.adjoint(y), args.repeat)
            _, peak_apply = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            rel = abs(np.vdot(y.astype(np.float64), y) - np.vdot(lf.astype(np.float64), x)) / np.vdot(y, y)
            tops = rng.integers(0, n - 9, 1000)
            lefts = rng.integers(0, n - 9, 1000)
            t_patch, _ = best(lambda: op.patch_sparse(tops, lefts, 9), 1)
            print(f"{kind:8s} period={str(period):4s} shots={shots}: build {t_build:6.3f} s, forward {t_fwd:6.3f} s, "
                  f"adjoint {t_adj:6.3f} s, adjoint rel. err {rel:.1e}, 1000 patches (gather) {t_patch:6.3f} s, "
                  f"peak traced: build {peak_build / 2**20:4.0f} MiB, forward+adjoint {(peak_apply - base) / 2**20:4.0f} MiB "
                  f"(outputs of two repeats included)")
    print(f"max RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
