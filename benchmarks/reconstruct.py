"""Benchmark: joint reconstruction of a Lytro-size light field (time, memory, GEMM-rate fraction).

Usage::

    python benchmarks/reconstruct.py [--case lytro|paper|both] [--rows N] [--solver admm|fista|omp]
                                     [--nonperiodic] [--max-iter N] [--tol T] [--threads N] [--save FILE]

Cases (both from 2 shots, random ISO (100, 400, 800, 1600), medium noise, of a synthetic HDR
scene, ``lfproc.synth`` ``layers``, 5 x 5 x 434 x 625 x 3):

``lytro``
    the stand-in for the default dictionary: patch 5 x 5 views x 8 x 8 px x 3 colours
    (n = 4800), K = 2600 atoms (the shipped ``default`` dictionary when it exists, else a
    separable DCT dictionary of that size). Target: <= 2 minutes, <= 8 GB.
``paper``
    a paper-size dictionary: patch 9 x 9 px (n = 6075), K = 16402 random unit-norm atoms.
    Target: <= 15 minutes.

The mask is periodic (period 4; with stride 4 one shared operator per phase) unless
``--nonperiodic`` (the paper's mask: one operator per patch). ``--rows N`` reconstructs only
the top ``N`` sensor rows and extrapolates the time to the full sensor by the patch count
(said in the output).

Printed: wall time, patches/s, the peak traced memory (tracemalloc: numpy buffers included)
and the process's max RSS, the solver's useful float32 work (two ``m x K`` GEMM products per
patch and iteration, plus the per-phase/per-patch ``Phi D`` and the final ``D a``) as a
fraction of this machine's float32 GEMM rate measured in the same run (2048^3 SGEMM, best
of 3, at the start and again right after each case; the fraction is printed against the rate at the
start, the rate after the case and their mean): that fraction depends much less on how busy a shared
machine is than the wall time, but not at all only if the load stayed the same during the run. The
same per second of the process's CPU time (the reconstruction's and the SGEMM's, both measured with
``time.process_time``) depends still less on the load: a busy machine slows both through shared caches
and memory, but the share of the cores the process gets cancels.
PU21-PSNR against the ground truth is printed for the full-sensor runs. ``--save FILE`` writes the
reconstructed light field (``.npy``, float32; with ``--case both`` one file per case, the case's name
added) to compare the outputs of two versions of the code.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
import tracemalloc

import numpy as np


def _gemm_best(clock, n: int, repeat: int) -> float:
    """The best time, on ``clock``, of a float32 ``n x n`` GEMM over ``repeat`` runs."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal((n, n), dtype=np.float32)
    b = rng.standard_normal((n, n), dtype=np.float32)
    best = float("inf")
    for _ in range(repeat):
        t = clock()
        a @ b
        best = min(best, clock() - t)
    return best


def gemm_rate(n: int = 2048, repeat: int = 3) -> float:
    return 2 * n**3 / _gemm_best(time.perf_counter, n, repeat)


def gemm_cpu_rate(n: int = 2048, repeat: int = 3) -> float:
    """The same SGEMM's flops per second of this process's CPU time (all its threads): on a machine other jobs
    load, the wall-time rate falls with the share of the cores the process gets, this one much less."""
    return 2 * n**3 / max(_gemm_best(time.process_time, n, repeat), 1e-9)


def dictionary_for(case: str):
    from lfproc.dictionary import Dictionary, dct_dictionary, load_dictionary

    if case == "lytro":
        try:
            d = load_dictionary("default")
            return d, "shipped default"
        except Exception:  # noqa: BLE001 - not shipped yet: the stand-in
            return dct_dictionary((5, 5, 8, 8, 3), 2600, n_nonzero_coefs=10), "DCT stand-in (n=4800, K=2600)"
    rng = np.random.default_rng(0)
    patch = (5, 5, 9, 9, 3)
    n = int(np.prod(patch))
    atoms = rng.standard_normal((n, 16402), dtype=np.float32)
    atoms /= np.linalg.norm(atoms, axis=0)
    return Dictionary(atoms=atoms, patch=patch, sparsity=10, preset="random"), "random (n=6075, K=16402)"


def run_case(case: str, args, rate: float) -> None:
    from lfproc.camera.simulate import simulate_capture
    from lfproc.metrics import evaluate
    from lfproc.recon import reconstruct
    from lfproc.synth import synthesize

    dictionary, label = dictionary_for(case)
    size = (434, 625)
    truth = synthesize("layers", size=size, views=5, random_state=1)
    capture = simulate_capture(truth, profile="paper-medium", shots=2, mask_period=None if args.nonperiodic else 4,
                               random_state=1)
    full_patches = None
    if args.rows:
        from lfproc.recon import patch_count
        import dataclasses

        full_patches = patch_count(size, dictionary.patch_px, 4)
        r = args.rows
        mask = capture.mask
        if mask.period is None:
            mask = dataclasses.replace(mask, codes=np.ascontiguousarray(mask.codes[:, :, :, :r]))
        capture = dataclasses.replace(capture, dn=capture.dn[:, :r], iso=capture.iso[:, :r], mask=mask,
                                      bias_dn=None if capture.bias_dn is None else capture.bias_dn[:, :r])
    tracemalloc.start()
    cpu_rate = gemm_cpu_rate()
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    lf = reconstruct(capture, dictionary, solver=args.solver, max_iter=args.max_iter, tol=args.tol,
                     threads=args.threads, progress_bar=True)
    seconds = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rec = lf.attrs["reconstruction"]
    m = 2 * dictionary.patch_px**2
    n, k = dictionary.n, dictionary.n_atoms
    its = rec["iterations_mean"] * rec["patches"]
    per_iter = 4 * m * k if args.solver != "omp" else 2 * m * k
    setup_ops = rec["operators"] * 2 * m * 25 * k  # Phi_g D (gather form)
    final = rec["patches"] * 2 * n * k  # D a
    useful = its * per_iter + setup_ops + final
    achieved = useful / seconds
    print(f"[{case}] dictionary: {label}; mask: {'non-periodic' if args.nonperiodic else 'period 4'}; "
          f"solver {args.solver}; sensor rows {capture.size[0]} of {size[0]}")
    print(f"  patches {rec['patches']}, operators {rec['operators']}, iterations mean {rec['iterations_mean']:.1f} "
          f"(max {rec['iterations_max']}), tol {rec['tol']:.3g}, {rec['scheduler']}")
    if args.solver != "omp":
        print(f"  {1e6 * seconds / max(its, 1):.1f} us per patch-iteration (wall time, all threads)")
    print(f"  wall time {seconds:.1f} s ({rec['patches'] / seconds:.1f} patches/s)")
    if full_patches:
        print(f"  extrapolated to the full sensor ({full_patches} patches): {seconds * full_patches / rec['patches']:.0f} s")
    print(f"  peak traced memory {peak / 2**30:.2f} GiB; max RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")
    print(f"  useful float32 work {useful / 1e12:.2f} TFLOP at {achieved / 1e9:.1f} GFLOP/s = "
          f"{100 * achieved / rate:.0f} % of this machine's SGEMM rate")
    end_rate = gemm_rate()  # the load of a shared machine changes during a run: the fraction against both
    print(f"  SGEMM rate right after this case {end_rate / 1e9:.1f} GFLOP/s: {100 * achieved / end_rate:.0f} % of it, "
          f"{200 * achieved / (rate + end_rate):.0f} % of the mean of the two")
    cpu_rate = max(cpu_rate, gemm_cpu_rate())
    print(f"  CPU time {cpu:.1f} s ({cpu / seconds:.2f} cores on average): {useful / cpu / 1e9:.1f} GFLOP per CPU-second "
          f"= {100 * useful / cpu / cpu_rate:.0f} % of the SGEMM's {cpu_rate / 1e9:.1f} (the higher of before and after)")
    if getattr(args, "save", None):
        path = args.save if args.case != "both" else args.save.replace(".npy", "") + f"-{case}.npy"
        np.save(path, np.asarray(lf.data, dtype=np.float32))
        print(f"  saved the light field to {path}")
    if not args.rows:
        scores = evaluate(lf, truth)
        print(f"  PU21-PSNR {scores['pu21_psnr_db']:.2f} dB, PU21-SSIM {scores['pu21_ssim']:.4f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--case", choices=("lytro", "paper", "both"), default="lytro")
    parser.add_argument("--rows", type=int, default=None, help="reconstruct only the top N sensor rows")
    parser.add_argument("--solver", default="admm")
    parser.add_argument("--max-iter", type=int, default=None)
    parser.add_argument("--tol", type=float, default=None, help="paper: 3.0517578125e-05 (2^-15)")
    parser.add_argument("--threads", type=int, default=None, help="blocks solved at once (default: the CPUs)")
    parser.add_argument("--nonperiodic", action="store_true", help="the paper's non-periodic random mask")
    parser.add_argument("--save", default=None, help="write the reconstructed light field to this .npy file")
    args = parser.parse_args()
    os.environ.setdefault("LFPROC_PROGRESS", "1")
    rate = gemm_rate()
    print(f"float32 GEMM rate (2048^3, best of 3): {rate / 1e9:.1f} GFLOP/s")
    for case in (("lytro", "paper") if args.case == "both" else (args.case,)):
        run_case(case, args, rate)
    rate2 = gemm_rate()
    print(f"float32 GEMM rate at the end: {rate2 / 1e9:.1f} GFLOP/s")


if __name__ == "__main__":
    main()
