"""Sniffing ZIP archives (lfproc's ``.npz`` files) without trusting them."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["zip_first_member"]


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
