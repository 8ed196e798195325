"""The layering of lfproc (the module docstring of :mod:`lfproc`) holds.

* the import-linter contract in pyproject.toml passes (run on a copy of the sources laid out as
  installed: ``lfproc/calib`` and ``lfproc/cli``);
* the same layers, checked from the code's own imports (module level and inside functions)
  without import-linter, so the contract holds where it is not installed;
* no package-level import cycle; at most 15 imports of lfproc's own modules inside functions,
  each with a comment saying why;
* a source checkout imports every module with ``PYTHONPATH=<repo>`` and no install;
* pyproject lists every package; moved modules keep their old import paths, and lfproc's own
  code uses the new ones; the presentation layer registers the previews.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

from lfproc import _layout

REPO = Path(__file__).resolve().parents[1]
# source folder -> package it is installed as
SOURCES = {"lfproc": "lfproc", "calib": "lfproc.calib", "cli": "lfproc.cli"}
MAX_FUNCTION_IMPORTS = 15


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))


def _modules() -> dict[str, tuple[Path, bool]]:
    """Every module of lfproc: name -> (file, is package)."""
    out = {}
    for folder, package in SOURCES.items():
        for path in sorted((REPO / folder).rglob("*.py")):
            rel = path.relative_to(REPO / folder).with_suffix("").parts
            is_pkg = rel[-1] == "__init__"
            parts = [package, *rel[:-1]] if is_pkg else [package, *rel]
            out[".".join(parts)] = (path, is_pkg)
    return out


def _imports(name: str, path: Path, is_pkg: bool):
    """(imported lfproc module or None for importlib, in a function?, line, comment) of a module."""
    source = path.read_text(encoding="utf-8")
    lines = source.splitlines()
    found = []

    def comment(node) -> str:
        here = lines[node.lineno - 1]
        above = lines[node.lineno - 2].strip() if node.lineno > 1 else ""
        return (here[here.index("#"):] if "#" in here else "") or (above if above.startswith("#") else "")

    def visit(node, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    if alias.name.split(".")[0] == "lfproc":
                        found.append((alias.name, in_function, child.lineno, comment(child)))
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[:len(base) - (child.level - 1)]
                    module = ".".join(base + ([child.module] if child.module else []))
                else:
                    module = child.module or ""
                if module.split(".")[0] == "lfproc":
                    for alias in child.names:
                        found.append((module, in_function, child.lineno, comment(child), alias.name))
            elif (in_function and isinstance(child, ast.Call)
                  and getattr(child.func, "attr", getattr(child.func, "id", None)) == "import_module"):
                found.append((None, True, child.lineno, comment(child)))
            visit(child, inner)

    visit(ast.parse(source), False)
    return found


def _edges() -> list[tuple[str, str, int]]:
    """(importer, imported module, line) for every static import of an lfproc module."""
    modules = _modules()
    edges = []
    for name, (path, is_pkg) in modules.items():
        for item in _imports(name, path, is_pkg):
            target = item[0]
            if target is None:
                continue
            if len(item) == 5 and f"{target}.{item[4]}" in modules:
                target = f"{target}.{item[4]}"  # `from package import module`
            edges.append((name, target, item[2]))
    return edges


def _layers() -> list[list[str]]:
    contract = _pyproject()["tool"]["importlinter"]["contracts"][0]
    assert contract["type"] == "layers" and contract["containers"] == ["lfproc"]
    return [[f"lfproc.{p.strip()}" for p in layer.split("|")] for layer in contract["layers"]]


def _child(module: str) -> str:
    """The child of the ``lfproc`` container a module belongs to (``lfproc.recon._gmm`` -> ``lfproc.recon``)."""
    return ".".join(module.split(".")[:2])


def test_layers_from_the_code_imports():
    """Every import (module level or inside a function) goes down the layers, or stays inside
    its package; siblings of one layer are independent."""
    position = {child: (i, child) for i, layer in enumerate(_layers()) for child in layer}
    children = {_child(m) for m in _modules() if m != "lfproc"}
    assert children <= set(position), f"not in any layer of the contract: {sorted(children - set(position))}"
    upward = []
    for importer, imported, line in _edges():
        a, b = _child(importer), _child(imported)
        if importer == "lfproc" or imported == "lfproc" or a == b:
            continue
        if position[b][0] <= position[a][0]:
            upward.append(f"{importer} (line {line}) -> {imported}")
    assert not upward, "imports against the layers:\n" + "\n".join(upward)


def test_import_linter_contract(tmp_path):
    """pyproject's [tool.importlinter] contract, run by import-linter on the installed layout."""
    pytest.importorskip("importlinter", reason="import-linter is in the test extra: pip install -e '.[test]'")
    stage = tmp_path / "src"
    ignore = shutil.ignore_patterns("__pycache__", "data", "profiles", "*.npz", "*.json")
    shutil.copytree(REPO / "lfproc", stage / "lfproc", ignore=ignore)
    shutil.copytree(REPO / "calib", stage / "lfproc" / "calib", ignore=ignore)
    shutil.copytree(REPO / "cli", stage / "lfproc" / "cli", ignore=ignore)
    shutil.copy(REPO / "pyproject.toml", stage / "pyproject.toml")
    code = ("import sys; from importlinter.cli import lint_imports; "
            "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True))")
    env = {**os.environ, "PYTHONPATH": str(stage)}
    run = subprocess.run([sys.executable, "-c", code], cwd=stage, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    assert "1 kept, 0 broken" in run.stdout


def test_no_package_cycle():
    graph: dict[str, set[str]] = {}
    for importer, imported, _ in _edges():
        a, b = _child(importer), _child(imported)
        if a != b and "lfproc" not in (importer, imported):
            graph.setdefault(a, set()).add(b)

    def reaches(start: str, goal: str, seen: set[str]) -> bool:
        for nxt in graph.get(start, ()):
            if nxt == goal or (nxt not in seen and (seen.add(nxt) or reaches(nxt, goal, seen))):
                return True
        return False

    cycles = sorted(p for p in graph if reaches(p, p, set()))
    assert not cycles, f"packages on an import cycle: {cycles}"


def test_function_level_imports_are_few_and_explained():
    found = []
    for name, (path, is_pkg) in _modules().items():
        for item in _imports(name, path, is_pkg):
            if item[1]:
                found.append((f"{path.relative_to(REPO)}:{item[2]}", item[3]))
    lines = sorted({where: why for where, why in found}.items())
    assert len(lines) <= MAX_FUNCTION_IMPORTS, f"{len(lines)} imports of lfproc inside functions: {lines}"
    unexplained = [where for where, why in lines if len(why.strip("# ")) < 10]
    assert not unexplained, f"imports inside functions without a comment saying why: {unexplained}"


def test_source_checkout_imports_every_module(tmp_path):
    """``PYTHONPATH=<repo>`` and no install: every module of lfproc, lfproc.calib and lfproc.cli imports."""
    script = textwrap.dedent(f"""
        import importlib, pkgutil, sys
        # no installed or editable lfproc: only the checkout on PYTHONPATH
        sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
        sys.path[:] = [p for p in sys.path if "__editable__" not in p]
        import lfproc, lfproc.calib, lfproc.cli
        repo = {str(REPO)!r}
        assert lfproc.__file__.startswith(repo), lfproc.__file__
        assert lfproc.calib.__file__.startswith(repo + "/calib"), lfproc.calib.__file__
        assert lfproc.cli.__file__.startswith(repo + "/cli"), lfproc.cli.__file__
        names = []
        for package in (lfproc, lfproc.calib, lfproc.cli):
            for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
                importlib.import_module(info.name)
                names.append(info.name)
        print(len(names))
    """)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(REPO)
    run = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-4000:]
    expected = sum(1 for m in _modules() if m not in ("lfproc", "lfproc.calib", "lfproc.cli"))
    assert int(run.stdout.split()[-1]) == expected


def test_pyproject_lists_every_package():
    setuptools = _pyproject()["tool"]["setuptools"]
    packages = {m for m, (_, is_pkg) in _modules().items() if is_pkg}
    assert set(setuptools["packages"]) == packages
    for package in packages:
        folder = {"lfproc.calib": "calib", "lfproc.cli": "cli"}.get(package, package.replace(".", "/"))
        assert setuptools["package-dir"][package] == folder
    for package, patterns in setuptools["package-data"].items():
        folder = REPO / setuptools["package-dir"][package]
        assert any(any(folder.glob(p)) for p in patterns), (package, patterns)  # the data is where it says


def test_moved_modules_keep_their_old_paths():
    import importlib

    for old, new in _layout.MOVED.items():
        assert importlib.import_module(old) is importlib.import_module(new), old
    import lfproc.bench
    import lfproc.calib
    import lfproc.dictionary
    import lfproc.io
    import lfproc.lytro
    import lfproc.recon
    from lfproc.camera.sensor import expose  # the old paths users have in their code
    from lfproc.calib.profile import CameraProfile
    from lfproc.merge import merge_ml
    from lfproc.tonemap import display_transform

    assert expose is importlib.import_module("lfproc.sensor").expose
    assert CameraProfile is lfproc.calib.CameraProfile
    assert merge_ml is importlib.import_module("lfproc.hdr").merge_ml
    assert display_transform is importlib.import_module("lfproc.preview").display_transform
    assert lfproc.lytro.read_lfp is lfproc.lytro.container.read_lfp
    assert lfproc.io.atomic_file is lfproc.io._atomic.atomic_file
    assert lfproc.dictionary.omp_codes is lfproc.dictionary._omp.omp_codes
    assert lfproc.bench.reconstruct_per_shot is lfproc.recon.reconstruct_per_shot
    with pytest.raises(AttributeError):
        lfproc.lytro.no_such_name  # noqa: B018
    # names that moved up to the presentation layer: still found, with a DeprecationWarning
    import lfproc.camera.capture
    import lfproc.preview

    with pytest.warns(DeprecationWarning, match="lfproc.preview"):
        assert lfproc.camera.capture.write_capture_preview is lfproc.preview.write_capture_preview
    with pytest.warns(DeprecationWarning, match="lfproc.preview"):
        assert lfproc.dictionary.render_atoms is lfproc.preview.render_atoms


def test_own_code_uses_the_new_paths():
    old = set(_layout.MOVED) | {"lfproc._util"}
    stale = [f"{importer} (line {line}) imports {imported}" for importer, imported, line in _edges()
             if imported in old and importer not in ("lfproc._util",)]
    assert not stale, stale


def test_presentation_registers_the_previews():
    """Importing a core type does not touch the preview registry; lfproc.preview registers them."""
    script = ("import sys, lfproc.camera, lfproc.dictionary; assert 'lfproc.preview' not in sys.modules, 'imported'; "
              "from lfproc.preview import PREVIEWS; print(' '.join(PREVIEWS))")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["centre", "sheet", "epi", "histogram", "capture", "sensor", "iso", "mask", "atoms"]


def test_missing_optional_dependency_names_its_extra(monkeypatch):
    from lfproc._shared.deps import EXTRAS, require
    from lfproc.errors import DependencyError

    extras = _pyproject()["project"]["optional-dependencies"]
    for module, (_, extra) in EXTRAS.items():
        assert extra in extras, module
    assert set(extras["all"][0].split("[")[1].rstrip("]").split(",")) == {e for _, e in EXTRAS.values()}
    monkeypatch.setitem(sys.modules, "rawpy", None)  # as if rawpy were not installed
    with pytest.raises(DependencyError, match=r"reading camera raw files needs rawpy.*lfproc\[raw\]"):
        require("rawpy", purpose="reading camera raw files")
    with pytest.raises(ImportError):  # DependencyError is an ImportError too
        require("rawpy", purpose="x")
