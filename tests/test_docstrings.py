"""The public API's docstrings: numpydoc sections, examples that run, references inside the repository.

Public names are the ``__all__`` of lfproc and of every package (the API-surface test lists them).
Every public function and class with parameters documents them in a numpydoc ``Parameters``
section; the ``Examples`` sections run here as doctests (scikit-learn's practice), and at least
:data:`MIN_EXAMPLES` public names have one; no docstring sends the reader to a design note that is
not in the repository.
"""

from __future__ import annotations

import doctest
import functools
import importlib
import inspect
import os
import re

import numpy as np
import pytest

PACKAGES = ("lfproc", "lfproc.io", "lfproc.sensor", "lfproc.lytro", "lfproc.hdr", "lfproc.calib", "lfproc.camera",
            "lfproc.dictionary", "lfproc.recon", "lfproc.metrics", "lfproc.synth", "lfproc.refocus", "lfproc.preview",
            "lfproc.dataset", "lfproc.bench")
MIN_EXAMPLES = 30
#: Design notes outside the repository (../shared/docs); docs/references.bib and the docs pages replace them.
OUTSIDE = re.compile(r"\b(method|reconstruction|hdr-and-calibration|lytro-format|representation|style)\.md\b")


def _public():
    """(qualified name, object) of every public function and class, once each."""
    seen, out = set(), []
    for pkg in PACKAGES:
        mod = importlib.import_module(pkg)
        for name in getattr(mod, "__all__", ()):
            obj = getattr(mod, name)
            if (inspect.isfunction(obj) or inspect.isclass(obj)) and id(obj) not in seen:
                seen.add(id(obj))
                out.append((f"{pkg}.{name}", obj))
    return out


def _has_parameters(obj) -> bool:
    target = obj.__init__ if inspect.isclass(obj) else obj
    try:
        sig = inspect.signature(target)
    except (TypeError, ValueError):
        return False
    return any(p.name not in ("self", "cls") for p in sig.parameters.values())


def _doc(obj) -> str:
    return inspect.getdoc(obj) or ""


def test_every_public_function_and_class_documents_its_parameters():
    missing = [name for name, obj in _public()
               if not (inspect.isclass(obj) and issubclass(obj, BaseException))  # exceptions take one message
               and _has_parameters(obj) and not re.search(r"^Parameters\n-{3,}", _doc(obj), re.M)]
    assert not missing, f"{len(missing)} public names without a numpydoc Parameters section: {missing}"


def test_no_docstring_points_outside_the_repository():
    bad = []
    for pkg in PACKAGES:
        mod = importlib.import_module(pkg)
        root = os.path.dirname(mod.__file__)
        for dirpath, _, files in os.walk(root):
            for f in files:
                if f.endswith(".py"):
                    with open(os.path.join(dirpath, f), encoding="utf-8") as fh:
                        text = fh.read()
                    bad += [f"{os.path.join(dirpath, f)}: {m.group(0)}" for m in OUTSIDE.finditer(text)]
    assert not bad, bad


@functools.lru_cache(maxsize=None)
def _examples():
    finder = doctest.DocTestFinder(exclude_empty=True)
    tests = {}
    for name, obj in _public():
        for t in finder.find(obj, name, globs={"np": np}):
            if t.examples:
                tests[t.name] = t
    return tests


def test_enough_public_names_have_examples():
    names = sorted(_examples())
    assert len(names) >= MIN_EXAMPLES, f"{len(names)} public names with Examples (want {MIN_EXAMPLES}): {names}"


#: Examples that take more than a few seconds, marked ``slow`` (tests/README.md), and why
SLOW_EXAMPLES = {"lfproc.reconstruct_gmm": "a reconstruction with its lights refit: about 40 s on 2 cores"}


def test_the_slow_examples_exist():
    assert set(SLOW_EXAMPLES) <= set(_examples()), set(SLOW_EXAMPLES) - set(_examples())


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_EXAMPLES else n
                                  for n in sorted(_examples())])
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # examples that write files write them here
    test = _examples()[name]
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test, out=lambda s: None)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, doctest_report(test)


def doctest_report(test) -> str:
    import io

    buf = io.StringIO()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test, out=buf.write)
    return buf.getvalue()
