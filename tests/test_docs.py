"""README keeps up with the code: the sub-commands it lists and the environment variables the
test suite tells users to set."""

from __future__ import annotations

import re
from pathlib import Path

from lfproc.cli.main import COMMANDS

ROOT = Path(__file__).resolve().parents[1]


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
    readme = (ROOT / "README.md").read_text()
    assert "`centre()` and `view(v, u)` return" in readme and "lf.centre()[0, 0]" in readme


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
