"""Refocusing light fields by shift-and-sum over the views (a stage).

The implementation is :mod:`lfproc.refocus._refocus`; this package was the module ``lfproc.refocus``,
whose other (private) names are still found here.
"""

from . import _refocus
from ._refocus import check_slopes, focal_stack, refocus

__all__ = [
    "refocus",
    "focal_stack",
    "check_slopes",
]


def __getattr__(name):  # names of the former flat module lfproc.refocus that are not public
    try:
        return getattr(_refocus, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
