"""HDR merging: exposure brackets of light fields or images into one HDR light field (a stage).

* :func:`merge_lightfields`, :func:`merge_ml`, :func:`merge_debevec`, :func:`merge_ml_codes8`,
  :func:`recover_response`, :func:`hat_weight`: the merges (:mod:`lfproc.hdr._merge`);
* :func:`read_bracket`, :func:`merge_files`, :func:`read_exif_exposure`, :func:`camera_response`,
  :func:`simulate_ldr_bracket`, :func:`write_response`: brackets on disk, camera responses
  (:mod:`lfproc.hdr._bracket`).

Data sets of HDR light fields built from folders of brackets are :mod:`lfproc.dataset` (an
application: it decodes, merges and writes previews). Formerly the flat modules
``lfproc.merge`` and ``lfproc.bracket``; those paths still work (they are these modules).
"""

from ._bracket import (BRACKET_SUFFIXES, CAMERA_RESPONSES, camera_response, merge_files, read_bracket,
                       read_exif_exposure, simulate_ldr_bracket, write_response)
from ._merge import (MERGE_METHODS, hat_weight, merge_debevec, merge_lightfields, merge_ml, merge_ml_codes8,
                     merge_with_variances, recover_response)

__all__ = [
    "MERGE_METHODS", "merge_lightfields", "merge_ml", "merge_debevec", "merge_ml_codes8", "merge_with_variances",
    "recover_response", "hat_weight",
    "BRACKET_SUFFIXES", "read_bracket", "merge_files", "read_exif_exposure", "CAMERA_RESPONSES", "camera_response",
    "simulate_ldr_bracket", "write_response",
]
