"""Former grab-bag of helpers, now split into :mod:`lfproc._shared` (one module per job).

Kept so that old imports keep working; lfproc itself imports from :mod:`lfproc._shared`.
"""

from ._shared.random import check_random_state  # noqa: F401
from ._shared.progress import progress  # noqa: F401
from ._shared.validation import check_choice, check_positive, check_count  # noqa: F401
from ._shared.parallel import max_workers, realign  # noqa: F401
from ._shared.jsonable import to_jsonable  # noqa: F401
from ._shared.hashing import file_sha256  # noqa: F401
from ._shared.warn import warn_saturation, warn_convergence  # noqa: F401
from ._shared.frozen import is_frozen, freeze, frozen_array, FrozenDict, ReadOnlyState  # noqa: F401
from ._shared.reprs import SHORT_REPR_FIELD, short_value, short_repr  # noqa: F401
from ._shared.stdio import quiet  # noqa: F401
from ._shared.zipfiles import zip_first_member  # noqa: F401

__all__ = ["check_random_state", "progress", "check_choice", "check_positive", "check_count", "max_workers", "realign", "to_jsonable", "file_sha256", "warn_saturation", "warn_convergence", "is_frozen", "freeze", "frozen_array", "FrozenDict", "ReadOnlyState", "quiet", "zip_first_member"]
