"""Validation of option values at the public boundary: choices, positive numbers, counts."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["check_choice", "check_positive", "check_count"]


def check_choice(name: str, value: str, choices: Sequence[str]) -> str:
    """Validate a string option against its allowed values, listing them on error."""
    if value not in choices:
        raise InputError(f"{name}: expected one of {', '.join(map(str, choices))}; got {value!r}")
    return value


def check_positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    """Validate a finite positive (or non-negative) number."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    ok = np.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        raise InputError(f"{name}: expected a {'non-negative' if allow_zero else 'positive'} finite number, got {value!r}")
    return v


def check_count(name: str, value: Any, *, low: int = 1, high: int, why: str = "") -> int:
    """Validate an integer count (shots, workers, sizes...) in ``low..high`` before anything
    is allocated or started; the error names the option and the allowed range."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if not (isinstance(value, float) and math.isfinite(value) and value == int(value)):
            raise InputError(f"{name}: expected an integer from {low} to {high}, got {value!r}")
    value = int(value)
    if not low <= value <= high:
        raise InputError(f"{name}: expected an integer from {low} to {high}{f' ({why})' if why else ''}, got {value}")
    return value
