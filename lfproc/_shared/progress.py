"""Progress bars on stderr (tqdm), off with ``LFPROC_PROGRESS=0``."""

from __future__ import annotations

import os
from collections.abc import Iterable

__all__ = ["progress"]


def progress(iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", disable: bool | None = None,
             unit: str = "it"):
    """A tqdm progress bar on stderr, off when ``LFPROC_PROGRESS=0`` or not asked for.

    ``disable=None`` lets tqdm decide (it hides the bar when stderr is not a terminal).
    ``unit`` names what is counted (the rate is shown as ``unit/s``, with the remaining time).
    """
    from tqdm.auto import tqdm

    if os.environ.get("LFPROC_PROGRESS", "1") == "0":
        disable = True
    return tqdm(iterable, total=total, desc=desc, disable=disable, leave=False, dynamic_ncols=True, unit=unit)
