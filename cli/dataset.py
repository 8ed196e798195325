"""``lfproc dataset build SCENES_DIR -o DATASET_DIR``: an HDR light-field data set from brackets."""

from __future__ import annotations

import sys
from pathlib import Path

from ._common import add_json, add_value_policies, emit
from lfproc._shared.parallel import max_workers
from lfproc._shared.validation import check_count
from lfproc.dataset import build_dataset


def register(sub, common) -> None:
    p = sub.add_parser(
        "dataset", parents=[common], help="build an HDR light-field data set from folders of brackets",
        description="Data-set tools. 'build': for every scene folder of SCENES_DIR (a bracket of captures, light "
                    "fields or images, optionally calibration data 'caldata*'), decode, merge, and write the HDR "
                    "light field, a preview, a dynamic-range histogram and a manifest row, in parallel with Dask. "
                    "Finished scenes are skipped on a new run; failed scenes are reported (exit code 2).")
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    b = actions.add_parser("build", parents=[common], help="process every scene folder",
                           description="Process every scene folder of SCENES_DIR into DATASET_DIR.")
    b.add_argument("scenes_dir", type=Path, metavar="SCENES_DIR", help="folder with one folder per scene")
    b.add_argument("-o", "--output", type=Path, required=True, metavar="DATASET_DIR", help="data-set folder")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running Dask scheduler (default: a local cluster; 'synchronous': in process)")
    b.add_argument("--workers", type=int, default=None, help="worker processes of the local cluster")
    b.add_argument("--method", choices=("ml", "debevec"), default=None, help="merging estimator (see lfproc merge)")
    b.add_argument("--profile", default=None, help="camera profile name or JSON file")
    add_value_policies(b, what="light-field (EXR) input")
    add_json(b)
    b.set_defaults(run=run)


def run(args) -> int:
    if args.workers is not None:
        import os

        check_count("--workers", args.workers, high=max_workers(),
                    why=f"at most 4 per CPU core; this machine has {os.cpu_count() or 1}")
    report = build_dataset(args.scenes_dir, args.output, method=args.method, profile=args.profile,
                           scheduler=args.scheduler, workers=args.workers, nonfinite=args.nonfinite,
                           negative=args.negative)
    failed = report["failed"]
    result = {
        "dataset": str(args.output),
        "scenes": report["scenes"],
        "processed": len(report["processed"]),
        "skipped": len(report["skipped"]),
        "failed": len(failed),
        "failures": failed,
        "manifest": report["manifest"],
    }
    emit(result, as_json=args.json)
    processed = set(report["processed"])
    for row in report["rows"]:
        if row["scene"] in processed:
            for message in row.get("warnings", []):
                print(f"lfproc dataset: scene {row['scene']}: warning: {message}", file=sys.stderr)
    if failed:
        for name, message in failed.items():
            print(f"lfproc dataset: scene {name} failed: {message}", file=sys.stderr)
        print(f"lfproc dataset: {len(failed)} of {report['scenes']} scenes failed "
              f"({len(report['processed'])} processed, {len(report['skipped'])} skipped)", file=sys.stderr)
        return 2
    return 0
