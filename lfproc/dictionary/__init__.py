"""HDR light-field dictionaries (stage 5 of the pipeline, its first half).

* :class:`Dictionary`, :func:`load_dictionary`, :func:`save_dictionary`: the type and its
  versioned ``.npz`` files; ``load_dictionary("default")`` is the dictionary shipped in the package;
* :func:`batch_omp`: Batch-OMP sparse coding of many signals at once;
* :func:`dct_dictionary`: the separable 4-D DCT baseline.
"""

from ._dct import dct_dictionary
from ._files import (SHIPPED, Dictionary, dictionary_patch, is_dictionary_file, load_dictionary, save_dictionary,
                     shipped_path)
from ._ksvd import KsvdResult, TrainingSignals, ksvd
from ._omp import batch_omp, codes_to_dense, gram_matrix, omp_codes
from ._train import PRESETS, Preset, approximate, evaluate_dictionary, get_preset, synthetic_lightfields, train_dictionary
from ._preview import render_atoms
from ._patches import collect_lightfields, extract_patches, training_patches

__all__ = ["Dictionary", "load_dictionary", "save_dictionary", "shipped_path", "SHIPPED", "batch_omp", "omp_codes",
           "codes_to_dense", "gram_matrix", "dct_dictionary", "ksvd", "KsvdResult", "TrainingSignals",
           "training_patches", "extract_patches", "collect_lightfields", "PRESETS", "Preset", "get_preset", "train_dictionary",
           "evaluate_dictionary", "approximate", "synthetic_lightfields", "render_atoms", "is_dictionary_file",
           "dictionary_patch"]
