"""One K-SVD iteration at the paper's size: time, peak memory, estimate for 20 iterations.

The paper's preset: patches of 5 x 5 views x 9 x 9 pixels x RGB (n = 6075), K = 16402 atoms,
sparsity 10, 300,000 training patches (7.3 GB of float32). The patches come from lfproc's
synthetic scenes (the ``paper`` preset's training set) and are written to a ``.npy`` file
first (in a separate process), so the training process streams them from disk as it would in
a real run (explicit reads: the file is never resident in the process); its peak resident
memory (``ru_maxrss``) is what the training needs. Prints the load average and the process's CPU
share, the time per iteration split into coding, atom update and atom replacement, the peak
RSS and the estimate for 20 iterations (20 iterations plus the final coding). The training
checkpoints into ``WORK/checkpoint-N`` after every iteration; a rerun with the same arguments
resumes (and times only the iterations it runs).

    python benchmarks/ksvd_paper.py --work /tmp/ksvd-paper          # full size (7.3 GB of disk)
    python benchmarks/ksvd_paper.py --work /tmp/k --patches 30000   # a tenth, for a quick look
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def make_patches(path: Path, n_patches: int, seed: int) -> None:
    from lfproc.dictionary import PRESETS, training_patches
    from lfproc.dictionary._train import synthetic_lightfields

    p = PRESETS["paper"]
    lfs = list(synthetic_lightfields(p.synthetic_scenes, views=p.patch[:2], size=p.synthetic_size, random_state=seed))
    x, _ = training_patches(lfs, patch=p.patch, n_patches=n_patches, random_state=seed)
    del lfs
    np.save(path, x)


def train_one(path: Path, iterations: int, checkpoint: Path) -> dict:
    from lfproc.dictionary import PRESETS, _ksvd, ksvd

    p = PRESETS["paper"]
    phases = {"coding": 0.0, "update": 0.0, "replace": 0.0}
    for name, phase in (("_code_all", "coding"), ("_update_atoms", "update"), ("_clear_atoms", "replace")):
        inner = getattr(_ksvd, name)

        def timed(*a, _inner=inner, _phase=phase, **k):
            t0 = time.perf_counter()
            try:
                return _inner(*a, **k)
            finally:
                phases[_phase] += time.perf_counter() - t0

        setattr(_ksvd, name, timed)
    marks = []
    load0 = os.getloadavg()
    cpu0 = time.process_time()
    start = time.perf_counter()
    result = ksvd(path, p.atoms, p.sparsity, iterations, random_state=0, checkpoint=checkpoint,
                  callback=lambda it, err: marks.append((it, time.perf_counter() - start, err, dict(phases))))
    total = time.perf_counter() - start
    cpu = time.process_time() - cpu0
    if not marks:
        raise SystemExit(f"{checkpoint}: all {iterations} iterations were already done; remove it to time them again")
    per_iter = marks[-1][1] / len(marks)
    final_coding = total - marks[-1][1]
    last = marks[-1][3]
    return {"iterations_run": len(marks), "resumed_from": result.resumed_from, "seconds_total": round(total, 1),
            "seconds_per_iteration": round(per_iter, 1),
            "per_iteration": {k: round(v / len(marks), 1) for k, v in last.items()},
            "seconds_final_coding": round(final_coding, 1),
            "estimate_20_iterations_h": round((20 * per_iter + final_coding) / 3600, 2),
            "errors": result.errors, "final_error": result.final_error,
            "peak_rss_gib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2),
            "cpu_share_cores": round(cpu / total, 2), "load_before": [round(v, 2) for v in load0],
            "load_after": [round(v, 2) for v in os.getloadavg()]}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", type=Path, required=True, help="folder for the patch file")
    ap.add_argument("--patches", type=int, default=300_000)
    ap.add_argument("--iterations", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--_phase", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    path = args.work / f"paper-patches-{args.patches}-{args.seed}.npy"
    if args._phase == "make":
        make_patches(path, args.patches, args.seed)
        return
    if args._phase == "train":
        print(json.dumps(train_one(path, args.iterations, args.work / f"checkpoint-{args.patches}-{args.seed}")))
        return
    args.work.mkdir(parents=True, exist_ok=True)
    me = [sys.executable, __file__, "--work", str(args.work), "--patches", str(args.patches), "--seed", str(args.seed),
          "--iterations", str(args.iterations)]
    if not path.exists():
        t0 = time.perf_counter()
        subprocess.run(me + ["--_phase", "make"], check=True)
        print(f"patches: {args.patches} x 6075 float32 ({path.stat().st_size / 1e9:.1f} GB) in "
              f"{time.perf_counter() - t0:.0f} s")
    out = subprocess.run(me + ["--_phase", "train"], check=True, capture_output=True, text=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    ph = r["per_iteration"]
    print(f"K-SVD, n = 6075, K = 16402, T = 10, N = {args.patches}: {r['seconds_per_iteration']:.0f} s per iteration "
          f"(coding {ph['coding']:.0f} s, atom update {ph['update']:.0f} s, replacement {ph['replace']:.0f} s; "
          f"+{r['seconds_final_coding']:.0f} s final coding), peak RSS {r['peak_rss_gib']:.2f} GiB; "
          f"estimate for 20 iterations: {r['estimate_20_iterations_h']:.2f} h "
          f"(load {r['load_before'][0]:.2f} -> {r['load_after'][0]:.2f}, process used {r['cpu_share_cores']:.2f} cores)")
    print(json.dumps(r))


if __name__ == "__main__":
    main()
