"""Where lfproc's modules live: old import paths of moved modules, and the source checkout.

Two import hooks, installed by :mod:`lfproc` when it is imported (foundations layer: this
module imports nothing of lfproc):

* **Moved modules keep their old paths.** :data:`MOVED` maps an old module path to the module
  that now holds its code; ``import lfproc.merge`` (or ``from lfproc.merge import merge_ml``)
  gives the very module object ``lfproc.hdr._merge``, so attributes, monkeypatching and pickles
  behave as before. lfproc's own code imports the new paths only (a test checks). No
  DeprecationWarning is raised yet: the test suite turns warnings into errors and code written
  against the old paths is still being merged; flip :data:`WARN_MOVED` to start deprecating.
* **A source checkout imports every module with ``PYTHONPATH=.``.** The design card keeps
  ``calib/`` and ``cli/`` at the top level of the repository, and ``pip install`` maps them to
  ``lfproc.calib`` and ``lfproc.cli`` (``package-dir`` in pyproject.toml). Without an install,
  :class:`_CheckoutFinder` does the same mapping: when ``lfproc/`` sits in a checkout (a
  ``pyproject.toml`` beside it naming the project ``lfproc``) and no other finder knows
  ``lfproc.calib``/``lfproc.cli``, they are loaded from ``<checkout>/calib`` and
  ``<checkout>/cli``. The finder is consulted last, so an installed or editable lfproc wins.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings
from pathlib import Path

__all__ = ["MOVED", "TOP_LEVEL", "install"]

#: Old module path -> the module that holds its code now (issue 21's layering).
MOVED = {
    "lfproc.camera.sensor": "lfproc.sensor._model",
    "lfproc.calib.profile": "lfproc.sensor._profile",
    "lfproc.merge": "lfproc.hdr._merge",
    "lfproc.bracket": "lfproc.hdr._bracket",
    "lfproc.tonemap": "lfproc.preview._tonemap",
    "lfproc.dictionary._preview": "lfproc.preview._atoms",
    "lfproc.bench.baselines": "lfproc.recon._per_shot",
}

#: Packages of lfproc whose source lives at the top level of the repository.
TOP_LEVEL = {"lfproc.calib": "calib", "lfproc.cli": "cli"}

#: Raise a DeprecationWarning when an old path in :data:`MOVED` is imported.
WARN_MOVED = False

_CHECKOUT = Path(__file__).resolve().parent.parent


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Resolves the old paths of :data:`MOVED` to the modules that replaced them."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        if WARN_MOVED:
            warnings.warn(f"{spec.name} moved to {MOVED[spec.name]}; import it from there",
                          DeprecationWarning, stacklevel=4)
        # the old path is an alias: the new module, imported on the first import of the old path
        return importlib.import_module(MOVED[spec.name])

    def exec_module(self, module):
        pass  # the module is the new one, already executed


def _is_checkout(root: Path) -> bool:
    try:
        text = (root / "pyproject.toml").read_text(encoding="utf-8")
    except OSError:
        return False
    return 'name = "lfproc"' in text


class _CheckoutFinder(importlib.abc.MetaPathFinder):
    """``lfproc.calib``/``lfproc.cli`` from ``calib/``/``cli/`` of a source checkout."""

    def find_spec(self, fullname, path=None, target=None):
        folder = TOP_LEVEL.get(fullname)
        if folder is None:
            return None
        init = _CHECKOUT / folder / "__init__.py"
        if not init.is_file() or not _is_checkout(_CHECKOUT):
            return None
        return importlib.util.spec_from_file_location(fullname, init,
                                                      submodule_search_locations=[str(init.parent)])


def install() -> None:
    """Put both finders on :data:`sys.meta_path` (once)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())
    if not any(isinstance(f, _CheckoutFinder) for f in sys.meta_path):
        sys.meta_path.append(_CheckoutFinder())
