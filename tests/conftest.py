"""Shared fixtures: the real data folder (skipped when absent) and a quiet environment."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("LFPROC_SHARED_DATA", ROOT.parent / "shared" / "data"))

os.environ.setdefault("LFPROC_PROGRESS", "0")
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` (or ``$LFPROC_SHARED_DATA``); tests using it skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real test data not found at {SHARED_DATA} (set LFPROC_SHARED_DATA)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def lytro_dir(shared_data) -> Path:
    """The real Lytro containers and metadata in ``shared_data / "lytro"``."""
    folder = shared_data / "lytro"
    if not folder.is_dir():
        pytest.skip(f"no Lytro data at {folder}")
    return folder


@pytest.fixture(scope="session")
def run_lfproc():
    """Run ``lfproc ARGS...`` in a fresh process; ``kill_at="point"`` (or ``"point#n"``) makes it
    SIGKILL itself at that point of lfproc.io._atomic (``LFPROC_TEST_KILL_AT``), and the run is
    checked to have died there. Returns the CompletedProcess (text output)."""
    import signal
    import subprocess
    import sys

    def run(*args, kill_at: str | None = None, timeout: float = 120):
        env = dict(os.environ, LFPROC_PROGRESS="0", MPLBACKEND="Agg")
        env.pop("LFPROC_TEST_KILL_AT", None)
        if kill_at:
            env["LFPROC_TEST_KILL_AT"] = kill_at
        proc = subprocess.run([sys.executable, "-m", "lfproc.cli.main", *map(str, args)], env=env,
                              capture_output=True, text=True, timeout=timeout)
        if kill_at:
            assert proc.returncode == -signal.SIGKILL, (
                f"expected a kill at {kill_at}, got exit {proc.returncode}: {proc.stderr[-2000:]}")
        return proc

    return run
