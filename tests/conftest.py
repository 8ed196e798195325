"""Shared fixtures: the real data folder (skipped when absent) and a quiet environment."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("LFPROC_SHARED_DATA", ROOT.parent / "shared" / "data"))

os.environ.setdefault("LFPROC_PROGRESS", "0")
os.environ.setdefault("MPLBACKEND", "Agg")

# Hypothesis: the same examples on every run and machine (a failure reproduces, and no example
# database left by an earlier run changes what runs). Every @settings in the tests inherits this
# profile; the test files also say derandomize=True where they set their own settings.
settings.register_profile("lfproc", derandomize=True, database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("lfproc")


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


@pytest.fixture(scope="session")
def kill_when():
    """Run a command in its own process group and SIGKILL the whole group (the run and any Dask
    workers) as soon as ``ready()`` is true, or at ``timeout_s``; returns the exit code."""
    import signal
    import subprocess
    import time

    def run(cmd: list[str], ready, *, timeout_s: float = 120, env: dict | None = None, poll_s: float = 0.02) -> int:
        env = dict(os.environ, LFPROC_PROGRESS="0", MPLBACKEND="Agg", **(env or {}))
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                                env=env)
        try:
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline and proc.poll() is None and not ready():
                time.sleep(poll_s)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        return proc.returncode

    return run


# -- genuine raw files for the import tests ------------------------------------------------------

_CFA_CODES = {"R": 0, "G": 1, "B": 2}


def write_dng(path, dn, *, cfa_pattern: str = "RGGB", black_level: float = 64, white_level: int = 4095,
              exposure_s: float | None = None, iso: float | None = None) -> Path:
    """Write a Bayer mosaic (uint16 DN) as a minimal uncompressed DNG 1.4 that LibRaw (rawpy) reads.

    A test helper, not product code: tifffile writes the TIFF structure and the DNG tags (DNGVersion,
    CFARepeatPatternDim/CFAPattern, BlackLevel, WhiteLevel, an identity ColorMatrix1...).
    """
    import numpy as np
    import tifffile

    dn = np.ascontiguousarray(dn, dtype=np.uint16)
    tags = [
        (271, "s", 0, "lfproc", True),  # Make
        (272, "s", 0, "simulated sensor", True),  # Model
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, tuple(_CFA_CODES[c] for c in cfa_pattern), True),  # CFAPattern
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, "s", 0, "lfproc simulated sensor", True),  # UniqueCameraModel
        (50713, "H", 2, (1, 1), True),  # BlackLevelRepeatDim
        (50714, "2I", 1, (int(round(black_level * 1000)), 1000), True),  # BlackLevel (RATIONAL)
        (50717, "I", 1, (int(white_level),), True),  # WhiteLevel
        (50721, "2i", 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), True),  # ColorMatrix1 = I
        (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True),  # AsShotNeutral
        (50778, "H", 1, (21,), True),  # CalibrationIlluminant1 = D65
    ]
    if exposure_s is not None:
        tags.append((33434, "2I", 1, (int(round(exposure_s * 1e6)), 1_000_000), True))  # ExposureTime
    if iso is not None:
        tags.append((34855, "H", 1, (int(iso),), True))  # ISOSpeedRatings
    tifffile.imwrite(path, dn, photometric=32803, compression=None, planarconfig=1, subfiletype=0,
                     metadata=None, extratags=tags)
    return Path(path)


@pytest.fixture(scope="session")
def dng_writer():
    """:func:`write_dng` (skips when tifffile is missing)."""
    pytest.importorskip("tifffile")
    return write_dng
