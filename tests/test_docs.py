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
