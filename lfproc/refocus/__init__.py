"""Refocusing light fields by shift-and-sum over the views (a stage).

The implementation is :mod:`lfproc.refocus._refocus`; this package was the module ``lfproc.refocus``,
whose other (private) names are still found here.
"""

from .._shared.deprecate import former_module_names
from . import _refocus
from ._refocus import check_slopes, focal_stack, refocus

__all__ = [
    "refocus",
    "focal_stack",
    "check_slopes",
]


# names of the former flat module lfproc.refocus that are not public
__getattr__ = former_module_names(_refocus, __name__)
