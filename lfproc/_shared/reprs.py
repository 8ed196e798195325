"""Short ``repr`` of large objects: arrays by shape and dtype, never their contents."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["SHORT_REPR_FIELD", "short_value", "short_repr"]


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
