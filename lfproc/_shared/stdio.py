"""Capturing what a block prints, on Python's streams and on file descriptors 1 and 2."""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile

__all__ = ["quiet"]


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
