"""README and the documentation keep up with the code: the sub-commands README lists, the
environment variables the test suite tells users to set, README's Python and command-line examples
(run in an empty folder), its links, the Python API tour, and the modules the API reference lists.

The documentation site itself is built with warnings as errors by ``.ci/run``
(``python -m sphinx -W -b html docs docs/_build/html``), which also executes the gallery."""

from __future__ import annotations

import ast
import importlib
import pkgutil
import re
import shlex
from pathlib import Path

import pytest

from lfproc.cli.main import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: README's test command: ``.ci/run`` runs it verbatim, so README must keep it as it is.
TEST_COMMAND = 'python -m pip install -e ".[test]" && python -m pytest -q'


def test_readme_names_every_command():
    readme = (ROOT / "README.md").read_text()
    missing = [c for c in COMMANDS if f"lfproc {c}" not in readme]
    assert not missing, f"README does not show: {', '.join(missing)}"


def test_readme_documents_the_environment_variables_the_suite_names():
    """The skip message of the real-data fixture names an environment variable: README must say what
    it is (a user reading 'set LFPROC_SHARED_DATA' finds it there)."""
    told = "".join(p.read_text() for p in (ROOT / "tests").glob("*.py"))
    names = set(re.findall(r"\bset (LFPROC_[A-Z_]+)\b", told))  # what skip messages tell users to set
    assert "LFPROC_SHARED_DATA" in names
    readme = (ROOT / "README.md").read_text()
    for name in names:
        assert name in readme, f"README does not document {name}"


def test_readme_python_examples_run_anywhere(tmp_path, monkeypatch):
    """Issue 20, item 6: README's Python examples run in any folder (no ``../shared`` needed)."""
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    assert blocks
    monkeypatch.chdir(tmp_path)
    for code in blocks:
        exec(compile(code, "README.md", "exec"), {"__name__": "readme_example"})


def test_centre_and_view_are_arrays_as_documented():
    from lfproc.synth import synthesize

    lf = synthesize("layers", size=(16, 16), views=3, random_state=0)
    assert lf.centre().shape == (16, 16, 3) and lf.centre()[0, 0].shape == (3,)
    assert (lf.view(1, 1) == lf.centre()).all() and (lf.central(1).data[0, 0] == lf.centre()).all()
    guide = (DOCS / "guide" / "lightfields.md").read_text()  # README's long version moved here (issue 22)
    assert "`centre()`, `view(v, u)` | **one view as a read-only `(H, W, C)` numpy array**" in guide
    assert "lf.centre()[0, 0]" in guide and "return new light fields" not in guide


def test_main_steps_are_documented_at_the_top_level():
    import lfproc
    from lfproc.camera.capture import load_capture
    from lfproc.camera.simulate import simulate_capture
    from lfproc.metrics import evaluate

    assert lfproc.simulate_capture is simulate_capture and lfproc.load_capture is load_capture
    assert lfproc.evaluate is evaluate
    for f in (simulate_capture, load_capture, evaluate, lfproc.reconstruct):
        doc = f.__doc__
        assert "Returns\n    -------" in doc and "Raises\n    ------" in doc or "Warns\n    -----" in doc, f.__name__
    assert "overlapping estimates are averaged" not in lfproc.reconstruct.__doc__  # the old solver's
    assert 'scale="universal"' in lfproc.reconstruct.__doc__.split("Parameters")[0]


# -- issue 22: a short README that runs, and a documentation site ----------------------------

def _readme() -> str:
    return (ROOT / "README.md").read_text()


def test_readme_is_short_and_keeps_the_quick_start():
    text = _readme()
    assert len(text.splitlines()) <= 150
    assert "\n## Quick start\n" in text
    quick = text.split("## Quick start", 1)[1].split("```", 2)[1]
    assert "python -m pip install . && lfproc demo -o lfproc-demo" in quick
    assert TEST_COMMAND in quick.splitlines()
    assert TEST_COMMAND in (ROOT / ".ci" / "run").read_text().splitlines()  # .ci/run runs it verbatim


@pytest.mark.slow  # six commands, a reconstruction among them (about 5 s); test_readme_links_exist is the fast check
def test_readme_cli_example_runs_anywhere(tmp_path, monkeypatch):
    """README's ``sh`` block: every line is an lfproc command that succeeds in an empty folder."""
    from lfproc.cli.main import main

    blocks = re.findall(r"```sh\n(.*?)```", _readme(), re.S)
    assert blocks
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("LFPROC_PROGRESS", "0")
    ran = 0
    for block in blocks:
        assert "../shared" not in block and "LFPROC_SHARED_DATA" not in block
        for line in block.splitlines():
            argv = shlex.split(line, comments=True)
            if not argv:
                continue
            assert argv[0] == "lfproc", line
            assert main(argv[1:]) == 0, line
            ran += 1
    assert ran >= 4
    assert (tmp_path / "recon.exr").exists() and (tmp_path / "err.png").exists()


def test_readme_links_exist():
    """Relative links of README point at files of the repository (they work on GitHub unbuilt)."""
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", _readme())
    local = [t for t in targets if not re.match(r"[a-z]+://", t)]
    assert len(local) >= 10
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README links to missing files: {missing}"


def test_readme_links_the_emva_calibration_section():
    text = _readme()
    anchor = "docs/guide/calibration.md#from-an-emva-1288-data-set-folder-or-descriptor"
    assert anchor in text
    guide = (DOCS / "guide" / "calibration.md").read_text()
    assert "## From an EMVA 1288 data set (folder or descriptor)" in guide  # the anchor's heading


@pytest.mark.slow  # the whole tour: a virtual Illum, a calibration, a dictionary (about 10 s)
def test_python_api_tour_runs(tmp_path, monkeypatch):
    """The Python blocks of docs/python-api.md run, in order, in an empty folder."""
    blocks = re.findall(r"```python\n(.*?)```", (DOCS / "python-api.md").read_text(), re.S)
    assert len(blocks) >= 2
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("LFPROC_PROGRESS", "0")
    namespace = {"__name__": "python_api_tour"}
    for code in blocks:
        exec(compile(code, "docs/python-api.md", "exec"), namespace)
    assert (tmp_path / "recon.exr").exists() and (tmp_path / "profile.json").exists()


def _api_modules() -> list[str]:
    """``API_MODULES`` of docs/conf.py, read without running conf.py."""
    tree = ast.parse((DOCS / "conf.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "API_MODULES" for t in node.targets):
            return [m for _, modules in ast.literal_eval(node.value) for m in modules]
    raise AssertionError("docs/conf.py has no API_MODULES")


def test_api_reference_lists_importable_public_modules():
    """Every module the API reference lists imports and exports what its ``__all__`` names, and every
    public top-level module or package of lfproc (``lfproc.X``) is listed, or some of its sub-modules
    are (``lfproc.camera`` has no ``__all__``; its modules are listed): a package that moves or
    appears must be added to API_MODULES in docs/conf.py (its sub-modules may be listed too)."""
    listed = _api_modules()
    assert len(listed) == len(set(listed))
    for name in listed:
        module = importlib.import_module(name)
        names = getattr(module, "__all__", None)
        assert names, f"{name} has no __all__"
        absent = [n for n in names if not hasattr(module, n)]
        assert not absent, f"{name}.__all__ names what it does not have: {absent}"
    import lfproc

    public = set()
    for info in pkgutil.iter_modules(lfproc.__path__, "lfproc."):
        if info.name.split(".")[1].startswith("_") or info.name == "lfproc.cli":
            continue
        public.add(info.name)
    unlisted = sorted(m for m in public if m not in listed and not any(x.startswith(m + ".") for x in listed))
    assert not unlisted, f"public modules missing from API_MODULES in docs/conf.py: {unlisted}"


def test_gallery_has_eight_examples_that_draw():
    examples = sorted((DOCS / "examples").glob("plot_*.py"))
    assert len(examples) >= 8
    for path in examples:
        text = path.read_text()
        assert "matplotlib.pyplot" in text and ("imshow(" in text or ".plot(" in text), path.name
        assert "../shared" not in text and "LFPROC_SHARED_DATA" not in text, path.name
