"""Small helpers shared by every module: random state, progress bars, validation."""

from __future__ import annotations

import contextlib
import hashlib
import io
import math
import os
import sys
import tempfile
from pathlib import Path
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["check_random_state", "progress", "check_choice", "check_positive", "check_count", "max_workers",
           "to_jsonable", "file_sha256", "quiet"]


def check_random_state(random_state: Any = None) -> np.random.Generator:
    """Return a :class:`numpy.random.Generator` from a seed, a Generator or ``None``.

    Every stochastic function of lfproc takes ``random_state`` and passes it here,
    so a given integer seed always gives the same result.
    """
    if random_state is None or isinstance(random_state, (int, np.integer)):
        if random_state is not None and int(random_state) < 0:
            raise InputError(f"seed: expected a non-negative integer, got {random_state}")
        return np.random.default_rng(random_state)
    if isinstance(random_state, np.random.Generator):
        return random_state
    raise InputError(
        f"random_state: expected None, an int seed or a numpy Generator, got {type(random_state).__name__}"
    )


def progress(iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", disable: bool | None = None):
    """A tqdm progress bar on stderr, off when ``LFPROC_PROGRESS=0`` or not asked for.

    ``disable=None`` lets tqdm decide (it hides the bar when stderr is not a terminal).
    """
    from tqdm.auto import tqdm

    if os.environ.get("LFPROC_PROGRESS", "1") == "0":
        disable = True
    return tqdm(iterable, total=total, desc=desc, disable=disable, leave=False, dynamic_ncols=True)


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


def max_workers() -> int:
    """Most worker processes lfproc starts: four per CPU core, at most 256."""
    return max(1, min(256, 4 * (os.cpu_count() or 1)))


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays, paths and non-finite floats for ``json.dumps``."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, Path):
        return str(obj)
    return obj


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file, or of a folder: its files' relative names and contents, sorted."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_dir():
        for p in sorted(q for q in path.rglob("*") if q.is_file()):
            digest.update(str(p.relative_to(path)).encode())
            digest.update(b"\0")
            digest.update(bytes.fromhex(file_sha256(p)))
        return digest.hexdigest()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


@contextlib.contextmanager
def quiet():
    """Capture what the block prints on ``sys.stdout``/``sys.stderr`` *and* on the
    process's file descriptors 1 and 2 (where C libraries write); yields a list that is
    filled with the captured lines when the block ends.

    Other threads writing to fds 1/2 meanwhile are captured too (the block is short).
    """
    lines: list[str] = []
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    py_out = io.StringIO()
    try:
        tmp = tempfile.TemporaryFile()
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # pragma: no cover - no spare descriptors: run without capturing
        with contextlib.redirect_stdout(py_out), contextlib.redirect_stderr(py_out):
            yield lines
        lines.extend(py_out.getvalue().splitlines())
        return
    try:
        os.dup2(tmp.fileno(), 1)
        os.dup2(tmp.fileno(), 2)
        with contextlib.redirect_stdout(py_out), contextlib.redirect_stderr(py_out):
            yield lines
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])
        tmp.seek(0)
        captured = tmp.read(1 << 16).decode("utf-8", errors="replace")
        tmp.close()
        lines.extend(line.strip() for line in (py_out.getvalue() + "\n" + captured).splitlines() if line.strip())
