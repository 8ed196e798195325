"""Size limits of the library's functions (issue 21): at most 120 lines and 12 parameters each.

Measured on the source (an AST walk over ``lfproc/``, ``calib/`` and ``cli/``): a function's length is
``end_lineno - lineno + 1`` (its docstring included, its decorators not); its parameters are all of
them (``self``, ``*args`` and ``**kwargs`` count one each). A function with more settings takes an
option object (a frozen dataclass such as :class:`lfproc.camera.simulate.CaptureDesign`) and its
fields as ``**keywords`` (:func:`lfproc._shared.deprecate.resolve_options`); the ``__init__`` of a dataclass
is generated, so its fields are not parameters here, and a hand-written ``__init__`` of a dataclass
is exempt too. Nested functions count on their own and towards the function around them.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("lfproc", "calib", "cli")
MAX_LINES = 120
MAX_PARAMETERS = 12

#: Justified exceptions: (file name, qualified name) -> reason. The test fails when an exception is no
#: longer needed, so the list stays true.
EXCEPTIONS: dict[tuple[str, str], str] = {}


def _is_dataclass(node: ast.ClassDef) -> bool:
    for dec in node.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name == "dataclass":
            return True
    return False


@functools.lru_cache(maxsize=1)
def _functions():
    """``(path, qualified name, lines, parameters, exempt_parameters)`` of every function of the library."""
    out = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))

            def walk(node, prefix: str, in_dataclass: bool):
                for child in ast.iter_child_nodes(node):
                    if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                        a = child.args
                        n_params = (len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None)
                                    + (a.kwarg is not None))
                        exempt = in_dataclass and child.name == "__init__"
                        out.append((path, prefix + child.name, child.end_lineno - child.lineno + 1, n_params,
                                    exempt))
                        walk(child, f"{prefix}{child.name}.", False)
                    elif isinstance(child, ast.ClassDef):
                        walk(child, f"{prefix}{child.name}.", _is_dataclass(child))
                    else:
                        walk(child, prefix, in_dataclass)

            walk(tree, "", False)
    return tuple(out)


def test_the_walk_finds_the_library():
    names = {(p.name, q) for p, q, *_ in _functions()}
    assert ("_reconstruct.py", "reconstruct") in names and ("calibrate.py", "_calibrate_iso") in names
    assert len(names) > 500


def test_no_library_function_over_120_lines_or_12_parameters():
    too_long, too_many, used = [], [], set()
    for path, name, lines, params, exempt in _functions():
        key = (path.name, name)
        where = f"{path.relative_to(ROOT)}::{name}"
        if key in EXCEPTIONS:
            used.add(key)
            continue
        if lines > MAX_LINES:
            too_long.append(f"{where}: {lines} lines")
        if params > MAX_PARAMETERS and not exempt:
            too_many.append(f"{where}: {params} parameters")
    assert not too_long, (f"functions over {MAX_LINES} lines (split them into the steps they describe): "
                          + "; ".join(too_long))
    assert not too_many, (f"functions over {MAX_PARAMETERS} parameters (take an option object): "
                          + "; ".join(too_many))
    stale = []
    for key in set(EXCEPTIONS) - used:
        stale.append(f"{key} (not found)")
    for path, name, lines, params, _ in _functions():
        if (path.name, name) in EXCEPTIONS and lines <= MAX_LINES and params <= MAX_PARAMETERS:
            stale.append(f"{path.name}::{name} ({lines} lines, {params} parameters)")
    assert not stale, "exceptions no longer needed, remove them from EXCEPTIONS: " + "; ".join(stale)


def test_the_limits_see_a_long_function_and_a_wide_one(tmp_path):
    """The measure itself on known answers: a 121-line function, a 13-parameter one, an exempt dataclass."""
    body = "\n".join(f"    x{i} = {i}" for i in range(119))
    params = ", ".join(f"a{i}" for i in range(12))
    source = (f"def long():\n{body}\n    return x0\n\n\ndef wide({params}, *, b=1):\n    return b\n\n\n"
              "from dataclasses import dataclass\n\n\n@dataclass\nclass Opt:\n    def __init__(self, "
              + ", ".join(f"p{i}" for i in range(13)) + "):\n        pass\n")
    tree = ast.parse(source)
    funcs = {n.name: n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
    assert funcs["long"].end_lineno - funcs["long"].lineno + 1 == 121
    a = funcs["wide"].args
    assert len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) == 13
    cls = next(n for n in ast.walk(tree) if isinstance(n, ast.ClassDef))
    assert _is_dataclass(cls)
