"""Atomic outputs: write to a temporary sibling, then rename.

An interrupted run leaves no half-written file behind (at worst a hidden
``.lfproc-tmp-*`` sibling), and an existing output is only replaced with ``force``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

from ..errors import InputError, OutputExistsError

__all__ = ["check_output", "atomic_file", "atomic_dir"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _publish_mode(path: Path, base: int) -> None:
    """mkstemp/mkdtemp create private (0600/0700) entries; give outputs the usual mode."""
    os.chmod(path, base & ~_umask())


def check_output(path: str | os.PathLike, *, force: bool = False) -> Path:
    """Fail early when ``path`` exists and ``force`` is false, or its folder is missing."""
    path = Path(path)
    if path.exists() and not force:
        raise OutputExistsError(f"{path}: output exists; pass force=True (--force) to overwrite it")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{path}: the output folder {parent} does not exist")
    return path


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, *, force: bool = False):
    """Yield a temporary path next to ``path`` (same suffix); rename it onto ``path`` on success.

    The suffix is kept because writers such as OpenCV choose the format from it.
    """
    path = check_output(path, force=force)
    fd, tmp = tempfile.mkstemp(prefix=f".lfproc-tmp-{path.stem}-", suffix=path.suffix, dir=path.parent or ".")
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        if not tmp.exists() or tmp.stat().st_size == 0:
            raise OSError(f"{path}: the writer produced no data")
        if path.exists() and not force:  # appeared while we were working
            raise OutputExistsError(f"{path}: output exists; pass force=True (--force) to overwrite it")
        _publish_mode(tmp, 0o666)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, *, force: bool = False):
    """Yield a temporary folder next to ``path``; move it to ``path`` on success.

    With ``force`` an existing folder is replaced as a whole (moved aside, then removed),
    so readers never see a mix of old and new files.
    """
    path = check_output(path, force=force)
    tmp = Path(tempfile.mkdtemp(prefix=f".lfproc-tmp-{path.name}-", dir=path.parent or "."))
    try:
        yield tmp
        old = None
        if path.exists():
            if not force:
                raise OutputExistsError(f"{path}: output exists; pass force=True (--force) to overwrite it")
            old = path.with_name(f".lfproc-old-{path.name}-{os.getpid()}")
            os.replace(path, old)
        _publish_mode(tmp, 0o777)
        os.replace(tmp, path)
        if old is not None:
            shutil.rmtree(old) if old.is_dir() else old.unlink()
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
