"""Read-only arrays and mappings of the core types."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["is_frozen", "freeze", "frozen_array", "FrozenDict", "ReadOnlyState"]


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


class ReadOnlyState:
    """Mixin for the core types: unpickling and ``copy.deepcopy`` keep their arrays read-only.

    (Both rebuild an object from its ``__dict__`` without running the constructor, and the
    arrays they bring are new, writeable ones.)
    """

    def __setstate__(self, state):
        for name, value in state.items():
            object.__setattr__(self, name, frozen_array(value) if isinstance(value, np.ndarray) else value)
