"""Entry point of the ``lfproc`` command.

Expected errors (any :class:`lfproc.LfprocError`, and OS errors on files) print one line
``lfproc COMMAND: error: ...`` on stderr and exit with code 2; ``--debug`` shows the
traceback instead. lfproc's warnings (:class:`lfproc.errors.LfprocWarning`) print one line
``lfproc COMMAND: warning: ...`` each after a successful command (not after an error) and do
not change the exit code. Bad options are reported by argparse, also with code 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings
from functools import partial

from lfproc._version import __version__
from lfproc.errors import LfprocError, LfprocWarning, cli_interface

# One module of lfproc.cli per sub-command, in the order `lfproc --help` lists them.
COMMANDS = (
    "demo",
    "info",
    "convert",
    "synth",
    "preview",
    "refocus",
    "evaluate",
    "simulate",
    "capture",
    "reconstruct",
    "bench",
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
        # the sub-command table above names the modules; each registers its own parser
        importlib.import_module(f"lfproc.cli.{name.replace('-', '_')}").register(sub, common)
    return parser


def _keep_warning(message, category, filename, lineno, file=None, line=None, *, kept: list, show) -> None:
    if issubclass(category, LfprocWarning):
        if str(message) not in kept:
            kept.append(str(message))
    else:
        show(message, category, filename, lineno, file, line)


def _silence_stdout() -> None:
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout without a file descriptor (tests, IDEs)
        pass


def main(argv: list[str] | None = None) -> int:
    """Run ``lfproc`` with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help/--version (0) or a bad option (2)
        return int(exc.code or 0)
    kept: list[str] = []
    try:
        with warnings.catch_warnings(), cli_interface():  # messages name --options, not arguments
            # lfproc's own warnings are kept (whatever the interpreter's filters say) and shown
            # as one line each once the command has succeeded: a failed command shows its one
            # error line only. Other warnings keep the usual handling.
            warnings.simplefilter("always", LfprocWarning)
            warnings.showwarning = partial(_keep_warning, kept=kept, show=warnings.showwarning)
            code = int(args.run(args) or 0)
        for message in kept:
            print(f"lfproc {args.command}: warning: {message}", file=sys.stderr)
        return code
    except BrokenPipeError:
        # the reader of our output went away (``lfproc ... | head``): stop quietly, as other
        # command-line tools do; stdout goes to devnull so the interpreter's final flush is quiet too
        _silence_stdout()
        return 1
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
