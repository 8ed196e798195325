"""Benchmark: the default command-line path at Lytro size, ``lfproc simulate`` then ``lfproc reconstruct``.

Usage::

    python benchmarks/cli_default.py [--scene city-interior] [--size 434 625] [--mask-period default|none]
                                     [--seed N] [--mask-transmittance uniform|binary|mixed]

The scene is one of :mod:`quality_scenes` (real HDR photographs as layers), written as an EXR
light field; then ``lfproc simulate LF -o CAP`` and ``lfproc reconstruct CAP -o OUT`` run as
separate processes with their defaults but ``--seed`` (the scene's seed of :mod:`quality_scenes` unless given:
without one, simulate draws its own, and city-interior's PU21-PSNR went from 51.3 to 42.6 dB between two runs, as
its lamp came back or did not) (``--mask-period none`` adds that option to simulate,
the non-periodic mask: reconstruct then chooses the dictionary method; ``--mask-transmittance`` adds that option,
the codes' levels: the default path's time with other codes, stop 48). Printed per command:
wall seconds and peak memory (the largest max RSS of the child processes so far,
``resource.getrusage(RUSAGE_CHILDREN)``),
with a float32 GEMM rate measured before and after as the reference for how busy the machine
was (times compare between runs only at similar rates); then ``lfproc evaluate`` of the result.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import quality_scenes  # noqa: E402
from reconstruct import gemm_rate  # noqa: E402


def _run(argv: list[str]) -> tuple[float, float, str]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "lfproc.cli.main", *argv], capture_output=True, text=True,
                          env={**os.environ, "LFPROC_PROGRESS": "0"})
    seconds = time.perf_counter() - t
    if done.returncode:
        raise SystemExit(f"{' '.join(argv)}: exit {done.returncode}: {done.stderr.strip()}")
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return seconds, max(rss, before) / 2**20, done.stdout


def main() -> None:
    from lfproc.camera.simulate import DEFAULT_MASK_TRANSMITTANCE, MASK_TRANSMITTANCES
    from lfproc.io import write_lightfield

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default="city-interior", choices=sorted(quality_scenes.SETS["all"]))
    parser.add_argument("--size", type=int, nargs=2, default=[434, 625], metavar=("H", "W"))
    parser.add_argument("--mask-period", default="default")
    parser.add_argument("--seed", type=int, default=None, help="simulate's seed (default: the scene's)")
    parser.add_argument("--mask-transmittance", choices=MASK_TRANSMITTANCES, default=None,
                        help="simulate's --mask-transmittance (default: simulate's default)")
    args = parser.parse_args()
    seed = quality_scenes.SETS["all"][args.scene][-1] if args.seed is None else args.seed
    warnings.simplefilter("ignore")
    rate = gemm_rate()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        lf = quality_scenes.make_scene(args.scene, tuple(args.size))
        write_lightfield(lf, tmp / "lf.exr")
        sim = ["simulate", str(tmp / "lf.exr"), "-o", str(tmp / "cap.npz"), "--seed", str(seed)]
        if args.mask_period != "default":
            sim += ["--mask-period", args.mask_period]
        if args.mask_transmittance is not None:
            sim += ["--mask-transmittance", args.mask_transmittance]
        s_sec, s_rss, _ = _run(sim)
        r_sec, r_rss, out = _run(["reconstruct", str(tmp / "cap.npz"), "-o", str(tmp / "out.exr"), "--json"])
        method = json.loads(out).get("method", "dictionary")
        _, _, ev = _run(["evaluate", str(tmp / "out.exr"), str(tmp / "lf.exr"), "--json"])
        ev = json.loads(ev)
    codes = args.mask_transmittance or f"{DEFAULT_MASK_TRANSMITTANCE} (default)"
    print(f"scene {args.scene}, 5x5 x {args.size[0]}x{args.size[1]}, mask {args.mask_period}, codes {codes}, "
          f"seed {seed}")
    print(f"float32 GEMM rate at the start: {rate / 1e9:.1f} GFLOP/s")
    print(f"lfproc simulate: {s_sec:.1f} s, peak {s_rss:.2f} GiB")
    print(f"lfproc reconstruct (method {method}): {r_sec:.1f} s, peak {r_rss:.2f} GiB")
    print(f"lfproc evaluate: PU21-PSNR {ev['pu21_psnr_db']:.2f} dB, PU21-SSIM {ev['pu21_ssim']:.3f}")
    print(f"float32 GEMM rate at the end: {gemm_rate() / 1e9:.1f} GFLOP/s")


if __name__ == "__main__":
    main()
