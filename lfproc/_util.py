"""Small helpers shared by every module: random state, progress bars, validation."""

from __future__ import annotations

import contextlib
import hashlib
import io
import math
import os
import sys
import tempfile
import warnings
from pathlib import Path
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from .errors import SATURATION_WARNING_FRACTION, ConvergenceWarning, InputError, SaturationWarning

__all__ = [
    "check_random_state",
    "progress",
    "check_choice",
    "check_positive",
    "check_count",
    "max_workers",
    "to_jsonable",
    "file_sha256",
    "quiet",
    "zip_first_member",
    "freeze",
    "frozen_array",
    "is_frozen",
    "FrozenDict",
    "ReadOnlyState",
    "warn_saturation",
    "warn_convergence",
]


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


def progress(iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", disable: bool | None = None,
             unit: str = "it"):
    """A tqdm progress bar on stderr, off when ``LFPROC_PROGRESS=0`` or not asked for.

    ``disable=None`` lets tqdm decide (it hides the bar when stderr is not a terminal).
    ``unit`` names what is counted (the rate is shown as ``unit/s``, with the remaining time).
    """
    from tqdm.auto import tqdm

    if os.environ.get("LFPROC_PROGRESS", "1") == "0":
        disable = True
    return tqdm(iterable, total=total, desc=desc, disable=disable, leave=False, dynamic_ncols=True, unit=unit)


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


def warn_saturation(fraction: float, what: str, *, consequence: str, samples: str = "samples",
                    stacklevel: int = 3) -> bool:
    """Emit :class:`SaturationWarning` when ``fraction`` exceeds :data:`SATURATION_WARNING_FRACTION`.

    ``what`` names the data ("capture", "exposure bracket"...), ``consequence`` says what it
    means for the result. Returns whether a warning was emitted.
    """
    if not fraction > SATURATION_WARNING_FRACTION:
        return False
    warnings.warn(
        f"{what}: {100 * fraction:.1f} % of the {samples} are saturated (more than "
        f"{100 * SATURATION_WARNING_FRACTION:g} %); {consequence}",
        SaturationWarning,
        stacklevel=stacklevel,
    )
    return True


def warn_convergence(message: str, *, stacklevel: int = 3) -> None:
    """Emit :class:`ConvergenceWarning` (an iterative estimate stopped before its tolerance)."""
    warnings.warn(message, ConvergenceWarning, stacklevel=stacklevel)


# -- read-only arrays of the core types ---------------------------------------------------------
#
# Convention (LightField, Capture, MaskCode, ProjectionOperator, Observation, CameraProfile, and
# any new type that validates arrays): the constructor stores ``frozen_array(value, dtype=...)``.
# That array is read-only and nobody else can write to it by accident: the constructor reuses
# the caller's array only when it is already frozen all the way down (read-only, and so is every
# array it is a view of), or when the dtype conversion made a new array; otherwise it copies
# once. Producers that build a large array and hand it over call ``freeze(array)`` first, so the
# constructor takes it without a copy. Views of a frozen array (slices, crops) are frozen too,
# so derived objects share memory with their parent. Writing raises numpy's
# ``ValueError: assignment destination is read-only``; functions build new arrays instead.


def is_frozen(array: np.ndarray) -> bool:
    """True when ``array`` and every array it is a view of are read-only (and the memory is not a
    writable Python buffer), so no write can reach its values short of flipping a flag back."""
    a: Any = array
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return a is None or isinstance(a, bytes)


def freeze(array: np.ndarray) -> np.ndarray:
    """Mark an array the caller has just built (and will not write again) read-only, in place.

    Returns the array, so ``LightField(data=freeze(out))`` hands ``out`` over without a copy.
    """
    array.flags.writeable = False
    return array


def frozen_array(value: Any, *, dtype: Any = None) -> np.ndarray:
    """``value`` as a read-only ndarray (of ``dtype``) that no other reference can write to.

    No copy when ``value`` is already frozen (:func:`is_frozen`) or when converting it to
    ``dtype`` (or from a list) makes a new array; one copy otherwise. The caller's array,
    flags included, is never modified.
    """
    arr = np.asarray(value, dtype=dtype)
    if isinstance(value, np.ndarray):
        fresh = not np.may_share_memory(arr, value)
    else:
        fresh = isinstance(value, (list, tuple, int, float, bool, complex, np.generic)) and arr.flags.owndata
    if not fresh and not is_frozen(arr):
        arr = arr.copy()
    arr.flags.writeable = False
    return arr


class FrozenDict(dict):
    """A dict that refuses changes after construction (picklable; copy with ``dict(d)``)."""

    def _refuse(self, *args, **kwargs):
        raise TypeError(f"{type(self).__name__} is read-only; build a new mapping instead")

    __setitem__ = __delitem__ = _refuse
    clear = pop = popitem = setdefault = update = _refuse  # type: ignore[assignment]

    def __ior__(self, other):
        self._refuse()

    def __reduce__(self):
        return (type(self), (dict(self),))

    def __repr__(self) -> str:
        return f"FrozenDict({dict.__repr__(self)})"


#: Longest ``repr`` of one field that :func:`short_repr` shows as is.
SHORT_REPR_FIELD = 80


def short_value(value: Any, *, limit: int = SHORT_REPR_FIELD) -> str:
    """A short text for one field of a large object: arrays by shape and dtype, long
    sequences and mappings by length, anything else by its ``repr`` cut to ``limit`` characters."""
    if isinstance(value, np.ndarray):
        return f"<array {' x '.join(map(str, value.shape)) or 'scalar'} {value.dtype}>"
    if isinstance(value, (bytes, bytearray, memoryview)):
        return f"<{len(value)} bytes>"
    text = repr(value)
    if len(text) <= limit:
        return text
    if isinstance(value, dict):
        return f"<{len(value)} entries: {', '.join(map(str, list(value)[:6]))}{', ...' if len(value) > 6 else ''}>"
    if isinstance(value, (list, tuple)):
        return f"<{len(value)} items>"
    return text[: limit - 3] + "..."


def short_repr(cls):
    """Class decorator (after ``@dataclass``): ``repr``/``str`` show each field briefly
    (:func:`short_value`), never the contents of arrays. Fields declared with ``repr=False``
    are left out."""
    import dataclasses

    def __repr__(self) -> str:
        parts = [f"{f.name}={short_value(getattr(self, f.name))}" for f in dataclasses.fields(self) if f.repr]
        return f"{type(self).__name__}({', '.join(parts)})"

    cls.__repr__ = __repr__
    cls.__str__ = __repr__
    return cls


class ReadOnlyState:
    """Mixin for the core types: unpickling and ``copy.deepcopy`` keep their arrays read-only.

    (Both rebuild an object from its ``__dict__`` without running the constructor, and the
    arrays they bring are new, writeable ones.)
    """

    def __setstate__(self, state):
        for name, value in state.items():
            object.__setattr__(self, name, frozen_array(value) if isinstance(value, np.ndarray) else value)


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


def zip_first_member(path: str | os.PathLike) -> str | None:
    """Name of the first member of a ZIP archive (lfproc's .npz files start with their JSON
    header), or None when ``path`` is not a readable ZIP file."""
    import zipfile

    path = Path(path)
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as fh:
            if fh.read(4) != b"PK\x03\x04":
                return None
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            return infos[0].filename if infos else None
    except (OSError, zipfile.BadZipFile):
        return None


def realign(value):
    """``value`` with every array at a 16-byte boundary, as numpy allocates them (copies only those that are not).

    Arrays a Dask worker deserialises can sit at any byte offset (measured: offset 7, ``flags.aligned``
    False); numpy's matmul then bypasses BLAS and sums in another order, and the worker's output
    differed from this process's in the last bits (reconstruction: about 1 run in 8 for ADMM, 4 in
    10 for FISTA). Workers call it on what they receive, so their sums are this process's.
    """
    if isinstance(value, np.ndarray):
        return value.copy() if value.ctypes.data % 16 else value
    if isinstance(value, dict):
        return {k: realign(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(realign(v) for v in value)
    return value
