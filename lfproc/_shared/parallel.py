"""Worker counts, the Dask client of lfproc's parallel runs, and the realignment of arrays a worker receives."""

from __future__ import annotations

import ast
import contextlib
import functools
import multiprocessing
import os
import sys

import numpy as np

from ..errors import InputError
from .deps import require

__all__ = ["available_cpus", "max_workers", "realign", "dask_client", "can_start_processes"]


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the OS has one, else the CPU count), >= 1."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


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
    if isinstance(value, tuple) and hasattr(value, "_make"):  # a named tuple
        return value._make(realign(v) for v in value)
    if isinstance(value, (list, tuple)):
        return type(value)(realign(v) for v in value)
    return value


@contextlib.contextmanager
def dask_client(*, scheduler: str | None, workers: int | None, jobs: int):
    """A Dask client: of the running scheduler at ``scheduler``, or of a local cluster started for the block.

    The local cluster has ``workers`` processes (default: one per job, at most one per CPU), one
    thread each (lfproc's sums are made on one BLAS thread), no dashboard and only error logs; it
    is closed with the client when the block ends. Used by reconstruction, data sets and the bench.
    """
    import logging

    require("distributed", purpose="a local Dask cluster or a Dask scheduler (--workers/--scheduler)")
    from dask.distributed import Client, LocalCluster

    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        n = workers or min(max(jobs, 1), os.cpu_count() or 1)
        if n < 1:
            raise InputError(f"--workers: expected a positive number, got {workers}")
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.ERROR)
        client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def can_start_processes() -> bool:
    """Whether worker processes (``forkserver`` or ``spawn``) can start without running the caller's script again.

    Such a worker imports the main module (as ``__mp_main__``): a script runs again in every worker unless its code
    sits under ``if __name__ == "__main__":``. True for an interactive session or a notebook (no main file),
    ``python -m`` of a package's ``__main__`` (not imported), and a main script with that guard at its top level
    (the ``lfproc`` command, pytest, the benchmarks); False for a script without it, a main file that cannot be read,
    a frozen executable, or a daemonic process (a Dask worker: it may not have children), where lfproc keeps to
    threads.
    """
    main = sys.modules.get("__main__")
    if getattr(sys, "frozen", False) or multiprocessing.current_process().daemon:
        return False
    name = getattr(getattr(main, "__spec__", None), "name", None)
    if name is not None:
        return name == "__main__" or name.endswith(".__main__")
    path = getattr(main, "__file__", None)
    return True if path is None else _guarded(os.path.abspath(path))


@functools.lru_cache(maxsize=8)
def _guarded(path: str) -> bool:
    """Whether the Python file ``path`` has ``if __name__ == "__main__":`` at its top level."""
    try:
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read())
    except (OSError, SyntaxError, UnicodeDecodeError, ValueError):
        return False
    for node in tree.body:
        test = node.test if isinstance(node, ast.If) else None
        if isinstance(test, ast.Compare) and len(test.ops) == 1 and isinstance(test.ops[0], ast.Eq):
            sides = [test.left, test.comparators[0]]
            names = {s.id for s in sides if isinstance(s, ast.Name)}
            values = {s.value for s in sides if isinstance(s, ast.Constant)}
            if names == {"__name__"} and values == {"__main__"}:
                return True
    return False
