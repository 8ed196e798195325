"""lfproc: high-dynamic-range light fields from the camera to the reconstruction.

The light-field type is :class:`lfproc.LightField`; files are read and written with
:func:`lfproc.read_lightfield` and :func:`lfproc.write_lightfield`; every error lfproc
raises on purpose derives from :class:`lfproc.LfprocError`. The pipeline's main steps are
here too: :func:`lfproc.simulate_capture` (a coded multi-ISO capture of a light field),
:func:`lfproc.load_capture` (a capture file), :func:`lfproc.reconstruct` (the HDR light field
of a capture) and :func:`lfproc.evaluate` (HDR metrics against a reference).

Architecture: layers that import one way
----------------------------------------
lfproc is five layers. A module imports only from its own layer's package and from the
layers below it, never from a layer above, at module level or inside a function. Packages
within the stages layer are ordered too (a stage may use the stages listed below it). The
contract is ``[tool.importlinter]`` in ``pyproject.toml``, checked by
``tests/test_architecture.py`` (import-linter, plus an AST count of the few imports that sit
inside functions, each with a comment saying why).

5. **Applications** -- what a user runs: :mod:`lfproc.cli` (the ``lfproc`` command; the
   folder ``cli/``) above :mod:`lfproc.demo`, :mod:`lfproc.info` and :mod:`lfproc.bench`
   (independent of each other).

4. **Presentation** -- pictures of results: :mod:`lfproc.preview` (previews of light fields,
   captures and dictionaries, which it registers itself; tone mapping).

3. **Stages** -- the pipeline, one package each, top to bottom:

   - :mod:`lfproc.recon` (reconstruction of coded captures, the per-shot baselines);
   - :mod:`lfproc.camera` (simulated and imported coded captures);
   - :mod:`lfproc.dictionary` (learned HDR light-field dictionaries);
   - :mod:`lfproc.hdr` (merging exposure brackets; HDR data sets) and :mod:`lfproc.calib`
     (measuring camera profiles; the folder ``calib/``), independent of each other;
   - :mod:`lfproc.lytro` (decoding Lytro captures);
   - :mod:`lfproc.synth` (procedural scenes), :mod:`lfproc.metrics` (HDR metrics) and
     :mod:`lfproc.refocus`, independent of each other.

2. **Models** -- :mod:`lfproc.sensor`: the sensor's noise model and the camera profile type
   with the shipped profiles, which every stage uses.

1. **Foundations** -- :mod:`lfproc.io` (light-field and image files, atomic outputs) above
   :mod:`lfproc.lightfield` (the light-field type) above :mod:`lfproc._untrusted`
   (reading hostile files), :mod:`lfproc._shared` (helpers, one module per job),
   :mod:`lfproc.errors` (the exception and warning tree), :mod:`lfproc._layout` (old import
   paths of moved modules; the source-checkout layout) and :mod:`lfproc._version`.

Every package's ``__init__`` lists in ``__all__`` what users call; the implementation is in
its modules (``_private`` where only the package uses them). ``tests/test_api_surface.py``
pins every package's ``__all__``. A source checkout imports every module with
``PYTHONPATH=.`` (see :mod:`lfproc._layout`); modules that moved keep their old import paths.
"""

from . import _layout
from ._version import __version__
from .errors import LfprocError
from .io import read_image, read_lightfield, write_image, write_lightfield
from .lightfield import LightField

_layout.install()

__all__ = ["__version__", "LfprocError", "LightField", "read_image", "read_lightfield", "reconstruct", "reconstruct_gmm",
           "write_image",
           "write_lightfield", "simulate_capture", "load_capture", "evaluate"]

# imported on first use (the solvers, the simulator and the metrics are not needed by every command)
_LAZY = {"reconstruct": ".recon", "reconstruct_gmm": ".recon", "simulate_capture": ".camera", "load_capture": ".camera", "evaluate": ".metrics"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        # lazy on purpose: `import lfproc` stays light (the solvers, the simulator and the metrics on first use)
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'lfproc' has no attribute {name!r}")
