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
