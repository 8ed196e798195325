"""``lfproc demo [-o DIR]``: the whole pipeline on an embedded synthetic scene."""

from __future__ import annotations

import sys
from pathlib import Path


from ._common import add_json, emit
from lfproc.errors import OutputExistsError


def register(sub, common) -> None:
    p = sub.add_parser("demo", parents=[common], help="run every stage of lfproc on an embedded default scene",
                       description="Synthesise an HDR light field and run every stage lfproc has on it; write the "
                                   "results, previews and a Markdown report into DIR.")
    p.add_argument("-o", "--output", type=Path, default=Path("lfproc-demo"), help="output folder (default lfproc-demo)")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    add_json(p)
    p.set_defaults(run=run)


def run(args) -> int:
    # lfproc.demo loads every stage (scipy.linalg too): imported when the command runs, so `lfproc --help` starts fast
    from lfproc.demo import run_demo

    if args.output.exists() and not args.force:
        raise OutputExistsError(
            f"{args.output}: the output folder exists (an earlier demo?); run 'lfproc demo -o {args.output} --force' "
            "to replace it, or give another folder with -o DIR")

    def log(message: str) -> None:
        if not args.json:
            print(f"  {message}", file=sys.stderr, flush=True)

    report = run_demo(args.output, force=args.force, log=log)
    if args.json:
        emit({"output": str(args.output), "total_seconds": report["total_seconds"],
              "stages": {row["stage"]: row["figures"] for row in report["stages"]}}, as_json=True)
        return 0
    print(f"lfproc demo finished in {report['total_seconds']:.1f} s; everything is in {args.output}/")
    print(f"  report: {args.output / 'report.md'}")
    for row in report["stages"]:
        print(f"  {row['stage']:<16} {row['seconds']:6.1f} s  {len(row['files'])} files")
    return 0
