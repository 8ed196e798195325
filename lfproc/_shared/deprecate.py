"""Keyword renames and option objects: the two ways lfproc's signatures change without breaking callers.

:func:`renamed_keywords` keeps an old keyword name working for one release with a
:class:`DeprecationWarning` naming the new one (lfproc's vocabulary: ``random_state``, ``max_iter``,
``n_nonzero_coefs``, as scikit-learn). :func:`resolve_options` builds the option object of a function
that takes one (a frozen dataclass such as :class:`lfproc.camera.simulate.CaptureDesign`) from either
the object or its fields as keywords, never both.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

__all__ = ["REMOVED_IN", "renamed_keywords", "rename_keywords", "resolve_options"]

#: The release in which the deprecated keyword names stop working.
REMOVED_IN = "0.3"

_F = TypeVar("_F", bound=Callable[..., Any])
_O = TypeVar("_O")


def rename_keywords(func_name: str, kwargs: dict[str, Any], renames: Mapping[str, str], *,
                    stacklevel: int = 3) -> dict[str, Any]:
    """Move deprecated keywords of ``kwargs`` (in place) to their new names, with a DeprecationWarning each.

    ``renames`` maps old names to new ones. Giving both the old and the new name is a TypeError.
    """
    for old, new in renames.items():
        if old not in kwargs:
            continue
        if new in kwargs:
            raise TypeError(f"{func_name}() got both {old!r} and its new name {new!r}: pass only {new!r}")
        warnings.warn(f"{func_name}(): the keyword {old!r} is deprecated and will be removed in lfproc {REMOVED_IN}; "
                      f"use {new!r}", DeprecationWarning, stacklevel=stacklevel)
        kwargs[new] = kwargs.pop(old)
    return kwargs


def renamed_keywords(**renames: str) -> Callable[[_F], _F]:
    """Decorator: accept the old keyword names ``old="new"`` for one release, with a DeprecationWarning.

    The decorated function keeps its signature (``inspect.signature`` follows ``__wrapped__``).
    """
    def decorate(func: _F) -> _F:
        @functools.wraps(func)
        def wrapper(*args, **kwargs):
            if kwargs:
                rename_keywords(func.__name__, kwargs, renames)
            return func(*args, **kwargs)

        wrapper.__deprecated_keywords__ = dict(renames)  # type: ignore[attr-defined]
        return wrapper  # type: ignore[return-value]

    return decorate


def resolve_options(cls: type[_O], options: _O | None, keywords: dict[str, Any], *, func_name: str,
                    argument: str, renames: Mapping[str, str] | None = None, stacklevel: int = 4) -> _O:
    """The option object of a call: ``options`` as given, or ``cls(**keywords)``.

    ``keywords`` are the fields given as keywords (deprecated names in ``renames`` are moved to their
    new names with a DeprecationWarning). An unknown keyword is a TypeError, as Python's own; an
    option object together with field keywords is a TypeError naming the fields (one way per call).
    """
    if renames:
        rename_keywords(func_name, keywords, renames, stacklevel=stacklevel)
    fields = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(keywords) - fields)
    if unknown:
        raise TypeError(f"{func_name}() got an unexpected keyword argument {unknown[0]!r}")
    if options is None:
        return cls(**keywords)
    if not isinstance(options, cls):
        raise TypeError(f"{func_name}(): {argument} must be a {cls.__name__}, got {type(options).__name__}")
    if keywords:
        names = ", ".join(sorted(keywords))
        raise TypeError(f"{func_name}(): {names} given both in {argument} and as keywords: pass one "
                        f"(dataclasses.replace({argument}, {sorted(keywords)[0]}=...) changes a field)")
    return options


def former_module_names(implementation, package: str) -> Callable[[str], Any]:
    """A module ``__getattr__`` for a package that was a flat module: its former private names still resolve.

    ``lfproc.metrics`` (and synth, refocus, preview, dataset) were modules; as packages their public
    names are the ``__all__`` of the package, and any other name a caller of the former module used
    is looked up in ``implementation`` (the module that holds the code now).
    """

    def __getattr__(name: str) -> Any:
        try:
            return getattr(implementation, name)
        except AttributeError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None

    return __getattr__
