"""Benchmark: ML and Debevec merge of 5 exposures of a full Illum-size 5x5 light field.

Usage: ``python benchmarks/merge.py [--threads N] [--repeat R] [--views V] [--size H W]``

Input: 5 exposures (1 EV apart) of a (5, 5, 434, 625, 3) light field as uint16 sensor
codes from the sensor model (illum profile, ISO 100): a synthetic HDR scene through
:func:`lfproc.camera.sensor.expose`. Prints the best wall time of ``merge_ml`` (2 iterations, with
variance) and ``merge_debevec`` (linear response), the peak traced Python memory during the
merge (tracemalloc, numpy buffers included), the process's max RSS and the ML quality
(mean relative error and variance calibration) against the known truth. Target: ML <= 3 s on
2 cores.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
import tracemalloc

import numpy as np


def make_bracket(views: int, size: tuple[int, int], seed: int = 0):
    from lfproc.sensor import expose
    from lfproc.synth import synthesize

    lf = synthesize("lamps", size=size, views=views, random_state=seed)
    truth = lf.data.astype(np.float64) * 2e5
    flat = truth.reshape(-1, truth.shape[-2] * truth.shape[-1])
    times = [0.01 * 2**k for k in range(5)]
    dn = np.stack([expose(flat, exposure_s=t, iso=100, profile="illum", random_state=seed + k).reshape(truth.shape)
                   for k, t in enumerate(times)])
    return truth.astype(np.float32), dn, times


def timed(fn, repeat: int):
    best = float("inf")
    out = None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return best, peak, out


def main(argv=None) -> int:
    from lfproc.hdr import merge_debevec, merge_ml

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--threads", type=int, default=2, help="threads of the merge (default 2)")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--views", type=int, default=5)
    p.add_argument("--size", type=int, nargs=2, default=(434, 625), metavar=("H", "W"))
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    truth, dn, times = make_bracket(args.views, tuple(args.size))
    print(f"bracket: 5 x {dn.shape[1:]} uint16 ({dn.nbytes / 2**20:.0f} MiB), made in {time.perf_counter() - t0:.1f} s;"
          f" cpus {os.cpu_count()}, threads {args.threads}")
    t_ml, peak_ml, (x, var, info) = timed(
        lambda: merge_ml(dn, exposures_s=times, isos=100, profile="illum", n_threads=args.threads), args.repeat)
    valid = ~info["saturated_everywhere"]
    rel = (x[valid] - truth[valid]) / truth[valid]
    z = (x[valid] - truth[valid]) / np.sqrt(var[valid])
    print(f"merge_ml     : {t_ml:.2f} s (best of {args.repeat}), peak traced {peak_ml / 2**20:.0f} MiB; "
          f"mean rel err {rel.mean():+.2e}, mean |rel err| {np.abs(rel).mean():.4f}, var(z) {z.var():.3f}, "
          f"saturated everywhere {100 * info['saturated_everywhere_fraction']:.2f} %")
    t_deb, peak_deb, (r, dinfo) = timed(
        lambda: merge_debevec(dn, exposures_s=times, white_level=1023, black_level=64, n_threads=args.threads),
        args.repeat)
    est = r * (1023 - 64) / 0.22733333333333333
    rel_d = (est[valid] - truth[valid]) / truth[valid]
    print(f"merge_debevec: {t_deb:.2f} s (best of {args.repeat}), peak traced {peak_deb / 2**20:.0f} MiB; "
          f"mean rel err {rel_d.mean():+.2e}, mean |rel err| {np.abs(rel_d).mean():.4f}")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"max RSS of the process (bracket + truth + outputs): {rss:.0f} MiB")
    print(f"target ML <= 3 s: {'met' if t_ml <= 3 else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
