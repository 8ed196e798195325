"""HDR light-field dictionaries (stage 5 of the pipeline, its first half).

* :class:`Dictionary`, :func:`load_dictionary`, :func:`save_dictionary`: the type and its
  versioned ``.npz`` files; ``load_dictionary("default")`` is the dictionary shipped in the package;
* :func:`batch_omp`: Batch-OMP sparse coding of many signals at once;
* :func:`dct_dictionary`: the separable 4-D DCT baseline.
"""

from ._dct import dct_dictionary
from ._files import SHIPPED, Dictionary, load_dictionary, save_dictionary, shipped_path
from ._omp import batch_omp, codes_to_dense, gram_matrix, omp_codes

__all__ = ["Dictionary", "load_dictionary", "save_dictionary", "shipped_path", "SHIPPED", "batch_omp", "omp_codes",
           "codes_to_dense", "gram_matrix", "dct_dictionary"]
