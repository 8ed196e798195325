"""Helpers shared by the sub-commands: JSON output, tables, common options."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from lfproc._shared.jsonable import to_jsonable
from lfproc.errors import InputError

__all__ = ["to_jsonable", "emit", "add_output", "add_json", "add_value_policies", "parse_floats", "parse_ints",
           "parse_size"]


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)) and len(value) <= 8 and all(not isinstance(x, (dict, list)) for x in value):
        return " x ".join(_fmt(x) for x in value) if all(isinstance(x, int) for x in value) else ", ".join(_fmt(x) for x in value)
    if isinstance(value, dict):
        return json.dumps(to_jsonable(value))
    return str(value)


def emit(result: dict[str, Any], *, as_json: bool, file=None) -> None:
    """Print ``result`` as one JSON object (``--json``) or as aligned ``key: value`` lines."""
    file = file or sys.stdout
    if as_json:
        print(json.dumps(to_jsonable(result)), file=file)
        return
    width = max((len(k) for k in result), default=0)
    for key, value in result.items():
        print(f"{key:<{width}}  {_fmt(value)}", file=file)


def add_json(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object to stdout")


def add_output(parser: argparse.ArgumentParser, *, required: bool = True, help: str = "output path") -> None:
    parser.add_argument("-o", "--output", required=required, type=Path, help=help)
    parser.add_argument("--force", action="store_true", help="overwrite an existing output")


def add_value_policies(parser: argparse.ArgumentParser, *, negative: str = "clip", nonfinite: str = "raise",
                       what: str = "input") -> None:
    """``--nonfinite raise|zero|clip`` and ``--negative clip|raise``: what to do with NaN/Inf and negative
    samples of the light fields a command reads (:func:`lfproc.lightfield.clean_nonfinite`)."""
    samples = f"{what} samples".strip()
    parser.add_argument("--nonfinite", choices=("raise", "zero", "clip"), default=nonfinite,
                        help=f"NaN/Inf {samples}: refuse (raise), set to 0 (zero), or NaN and -Inf to 0 and +Inf "
                             f"to the largest finite value (clip); default {nonfinite}")
    parser.add_argument("--negative", choices=("clip", "raise"), default=negative,
                        help=f"negative {samples} (lossy EXR compression leaves tiny ones): set to 0 (clip) or "
                             f"refuse (raise); default {negative}")


def parse_floats(text: str, *, option: str) -> list[float]:
    """``"1,2.5,3"`` -> ``[1.0, 2.5, 3.0]`` with an error naming the option."""
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{option}: expected comma-separated numbers, got {text!r}") from None


def parse_ints(text: str, *, option: str) -> list[int]:
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{option}: expected comma-separated integers, got {text!r}") from None


def parse_size(values: list[str], *, option: str, max_side: int = 1 << 16) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in values)
    except ValueError:
        raise InputError(f"{option}: expected two integers H W, got {' '.join(values)}") from None
    if h < 1 or w < 1 or h > max_side or w > max_side:
        raise InputError(f"{option}: expected sizes from 1 to {max_side}, got {h} {w}")
    return h, w
