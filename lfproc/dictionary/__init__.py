"""HDR light-field dictionaries (stage 5 of the pipeline, its first half).

* :class:`Dictionary`, :func:`load_dictionary`, :func:`save_dictionary`: the type and its
  versioned ``.npz`` files; ``load_dictionary("default")`` is the dictionary shipped in the package;
* :func:`train_dictionary`, :func:`evaluate_dictionary`, :func:`approximate`, presets
  (:data:`PRESETS`, :func:`get_preset`): training on light fields with K-SVD (:func:`ksvd`);
* :func:`batch_omp`: Batch-OMP sparse coding of many signals at once;
* :func:`dct_dictionary`: the separable 4-D DCT baseline;
* :func:`training_patches`: patches of light fields for training.

The picture of a dictionary's atoms is :func:`lfproc.preview.render_atoms` (presentation).
Former exports of internals (``omp_codes``, ``gram_matrix``...) still resolve here.
"""

from . import _files, _ksvd, _omp, _patches, _train
from ._dct import dct_dictionary
from ._files import SHIPPED, Dictionary, is_dictionary_file, load_dictionary, save_dictionary
from ._ksvd import KsvdResult, ksvd
from ._omp import batch_omp
from ._patches import training_patches
from ._train import PRESETS, Preset, TrainingSizes, approximate, evaluate_dictionary, get_preset, train_dictionary

__all__ = ["Dictionary", "load_dictionary", "save_dictionary", "is_dictionary_file", "SHIPPED", "batch_omp",
           "dct_dictionary", "ksvd", "KsvdResult", "training_patches", "PRESETS", "Preset", "get_preset",
           "train_dictionary", "TrainingSizes", "evaluate_dictionary", "approximate"]

#: former exports of this package -> the module that defines them
_FORMER = {"shipped_path": _files, "dictionary_patch": _files, "omp_codes": _omp, "codes_to_dense": _omp,
           "gram_matrix": _omp, "TrainingSignals": _ksvd, "extract_patches": _patches,
           "collect_lightfields": _patches, "synthetic_lightfields": _train}


def __getattr__(name):  # former exports of internals
    if name in _FORMER:
        return getattr(_FORMER[name], name)
    if name == "render_atoms":  # moved to the presentation layer
        import importlib
        import warnings

        warnings.warn("lfproc.dictionary.render_atoms moved to lfproc.preview; import it from there",
                      DeprecationWarning, stacklevel=2)
        # deprecated old path only: a stage must not import presentation, so it is looked up on use
        return importlib.import_module("lfproc.preview._atoms").render_atoms
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
