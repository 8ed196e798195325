"""Optional third-party dependencies: import them when a function needs them, and say which
extra of lfproc installs them when they are missing (:class:`lfproc.errors.DependencyError`).

``pip install lfproc`` installs every extra's packages too (they are in the default
dependencies, so every stage works out of the box); the extras name the groups, so
``pip install "lfproc[parallel]"`` states what a feature needs and keeps working if the core
is ever slimmed down.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from ..errors import DependencyError

__all__ = ["EXTRAS", "require"]

#: Top-level module -> (distribution on PyPI, extra of lfproc that installs it).
EXTRAS = {
    "dask": ("dask[distributed]", "parallel"),
    "distributed": ("dask[distributed]", "parallel"),
    "matplotlib": ("matplotlib", "plot"),
    "rawpy": ("rawpy", "raw"),
    "colour": ("colour-science", "colour"),
    "colour_demosaicing": ("colour-demosaicing", "colour"),
}


def require(module: str, *, purpose: str) -> ModuleType:
    """Import ``module`` (e.g. ``"distributed"``) or raise :class:`DependencyError` naming the
    extra that installs it; ``purpose`` says what needed it ("a Dask cluster (--workers)")."""
    try:
        # a third-party module named by the caller (never an lfproc module): imported when needed
        return importlib.import_module(module)
    except ImportError:
        dist, extra = EXTRAS[module.split(".")[0]]
        raise DependencyError(f"{purpose} needs {dist}, which is not installed: "
                              f"pip install \"lfproc[{extra}]\" (or pip install {dist})") from None
