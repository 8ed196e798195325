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
    conftest = (ROOT / "tests" / "conftest.py").read_text()
    names = set(re.findall(r"\b(LFPROC_[A-Z_]+)\b", conftest)) - {"LFPROC_PROGRESS"}
    assert "LFPROC_SHARED_DATA" in names
    readme = (ROOT / "README.md").read_text()
    for name in names:
        assert name in readme, f"README does not document {name}"
