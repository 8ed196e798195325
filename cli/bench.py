"""``lfproc bench LF... -o BENCH_DIR``: the paper's experiments and baselines on HDR light fields."""

from __future__ import annotations

import sys
from pathlib import Path

from ._common import add_json, add_value_policies, emit
from lfproc.errors import InputError


def register(sub, common) -> None:
    p = sub.add_parser(
        "bench", parents=[common], help="run the paper's grid of acquisitions and baselines, with a report",
        description="Simulate, reconstruct and score every cell of the grid scenes x ISO pattern (random, row, "
                    "block, dual) x shots (1-3) x ISO set x noise level, plus the paper's baselines (individual ISO, "
                    "exposure bracketing merged per shot and solved jointly, dual ISO); write results.csv (one row "
                    "per cell), report.md (tables like the paper's Tables I-IV beside its numbers, the paper's "
                    "claims decided on these scenes) and plots into BENCH_DIR. Cells are cached in BENCH_DIR/cells: "
                    "a killed bench resumes where it stopped. Presets: quick (central 48 x 48 crop, 35 cells per "
                    "scene, minutes), paper (the full grid at full size).")
    p.add_argument("scenes", nargs="*", type=Path, metavar="LF", help="HDR light fields (files or view folders)")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="BENCH_DIR", help="bench folder")
    p.add_argument("--preset", default="quick", metavar="quick|paper", help="grid and scene size (default quick)")
    p.add_argument("--dictionary", default="default", metavar="default|FILE",
                   help="dictionary: the shipped 'default' or a dictionary .npz file")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="processes of the local Dask cluster (default: the CPU count)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="address of a running Dask scheduler, or 'synchronous' (this process)")
    p.add_argument("--method", default="auto", choices=("auto", "gmm", "dictionary"),
                   help="reconstruction method of every cell: auto (default) is gmm for a preset with a periodic mask "
                        "(quick), as lfproc reconstruct chooses, and dictionary otherwise (paper)")
    p.add_argument("--seed", type=int, default=0, help="bench seed; every cell's seed derives from it (default 0)")
    p.add_argument("--force", action="store_true",
                   help="recompute every cell (and use a folder that is not a bench folder)")
    add_value_policies(p, negative="raise", what="scene light-field")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    # lfproc.bench loads the reconstruction (scipy.linalg): imported when the command runs, so `lfproc --help` starts fast
    from lfproc.bench import get_preset, run_bench

    get_preset(args.preset)  # an unknown preset fails before anything is read
    if not args.scenes:
        raise InputError("LF: expected at least one light field, got none")
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers: expected a positive number, got {args.workers}")
    result = run_bench(args.scenes, args.output, preset=args.preset, dictionary=args.dictionary,
                       workers=args.workers, scheduler=args.scheduler, force=args.force, random_state=args.seed,
                       recon_options={"method": args.method},
                       read_options={"nonfinite": args.nonfinite, "negative": args.negative})
    failed = result["failed"]
    summary = {k: v for k, v in result.items() if k != "rows"}
    summary["failed"] = len(failed)
    summary["failures"] = failed
    emit(summary, as_json=args.json)
    if failed:
        for label, message in failed.items():
            print(f"lfproc bench: cell {label} failed: {message}", file=sys.stderr)
        print(f"lfproc bench: {len(failed)} job(s) failed; re-run to retry them", file=sys.stderr)
        return 2
    return 0
