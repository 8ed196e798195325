"""Worker counts and the realignment of arrays a Dask worker receives."""

from __future__ import annotations

import os

import numpy as np

__all__ = ["max_workers", "realign"]


def max_workers() -> int:
    """Most worker processes lfproc starts: four per CPU core, at most 256."""
    return max(1, min(256, 4 * (os.cpu_count() or 1)))


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
