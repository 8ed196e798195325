"""Entry point of the ``lfproc`` command.

Expected errors (any :class:`lfproc.LfprocError`, and OS errors on files) print one line
``lfproc COMMAND: error: ...`` on stderr and exit with code 2; ``--debug`` shows the
traceback instead. lfproc's warnings (:class:`lfproc.errors.LfprocWarning`) print one line
``lfproc COMMAND: warning: ...`` each and do not change the exit code. Bad options are reported by argparse, also with code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings
from functools import partial

from lfproc._version import __version__
from lfproc.errors import LfprocError, LfprocWarning

# One module of lfproc.cli per sub-command, in the order `lfproc --help` lists them.
COMMANDS = (
    "demo",
    "info",
    "convert",
    "synth",
    "preview",
    "evaluate",
    "simulate",
    "capture",
    "reconstruct",
    "merge",
    "dataset",
    "virtual-illum",
    "whites",
    "decode",
    "extract",
    "calibrate",
    "profile",
    "dictionary",
)


def build_parser() -> argparse.ArgumentParser:
    # --debug is accepted before and after the sub-command; SUPPRESS keeps the
    # sub-parser from resetting a value given before it.
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks of errors")
    parser = argparse.ArgumentParser(
        prog="lfproc",
        description="High-dynamic-range light fields: decode, merge, calibrate, simulate, reconstruct, evaluate.",
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    parser.add_argument("--version", action="version", version=f"lfproc {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"lfproc.cli.{name.replace('-', '_')}").register(sub, common)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None, *, command: str, show) -> None:
    if issubclass(category, LfprocWarning):
        print(f"lfproc {command}: warning: {message}", file=sys.stderr)
    else:
        show(message, category, filename, lineno, file, line)


def main(argv: list[str] | None = None) -> int:
    """Run ``lfproc`` with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help/--version (0) or a bad option (2)
        return int(exc.code or 0)
    try:
        with warnings.catch_warnings():
            # lfproc's own warnings are shown as one line each (once per message), whatever the
            # interpreter's filters say; other warnings keep the usual handling
            warnings.simplefilter("default", LfprocWarning)
            warnings.showwarning = partial(_show_warning, command=args.command, show=warnings.showwarning)
            return int(args.run(args) or 0)
    except (LfprocError, OSError) as exc:
        if args.debug:
            raise
        if isinstance(exc, OSError) and not isinstance(exc, LfprocError):
            where = f"{exc.filename}: " if exc.filename else ""
            message = f"{where}{exc.strerror or exc}"
        else:
            message = str(exc)
        print(f"lfproc {args.command}: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lfproc {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
