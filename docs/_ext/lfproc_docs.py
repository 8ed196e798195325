"""Sphinx helpers of lfproc's documentation.

* ``api_pages``: one page per public module of ``conf.API_MODULES``, listing every name of
  the module's ``__all__`` in an ``autosummary`` table (each name gets its own generated page).
  The list of modules is the only thing to edit when packages move.
* ``lfproc-cli`` directive: the command-line reference, generated from the argparse parser that
  ``lfproc`` itself uses (:func:`lfproc.cli.main.build_parser`): usage, description and every
  argument of every command and sub-command.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
from pathlib import Path

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

# -- API pages -------------------------------------------------------------------------------


def _title(text: str, char: str) -> list[str]:
    return [text, char * len(text), ""]


def api_page(module: str) -> str:
    """reST of one module's page: its docstring and an autosummary of its ``__all__``."""
    mod = importlib.import_module(module)
    names = list(getattr(mod, "__all__", []))
    if not names:
        raise RuntimeError(f"{module} has no __all__: the API reference is generated from it")
    lines = _title(f"``{module}``", "=")
    lines += [f".. automodule:: {module}", "   :no-members:", "", f".. currentmodule:: {module}", ""]
    lines += [".. autosummary::", "   :toctree: generated/", "   :nosignatures:", ""]
    lines += [f"   {name}" for name in names if not name.startswith("__")]
    lines.append("")
    return "\n".join(lines)


def write_api_pages(app, config) -> None:
    """Write ``api/<module>.rst`` for every module of ``API_MODULES`` and ``api/index.rst`` (at
    ``config-inited``: before Sphinx looks for source files and autosummary writes its stubs)."""
    groups = config.lfproc_api_modules
    out = Path(app.srcdir) / "api"
    out.mkdir(exist_ok=True)
    index = _title("API reference", "=")
    index += [
        "Generated from each public module's ``__all__`` (the list of modules is ``API_MODULES``",
        "in ``docs/conf.py``). Every name links to its own page with the full docstring.",
        "",
    ]
    for group, modules in groups:
        index += _title(group, "-")
        index += [".. toctree::", "   :maxdepth: 1", ""]
        index += [f"   {m}" for m in modules]
        index.append("")
        for module in modules:
            _write_if_changed(out / f"{module}.rst", api_page(module))
    _write_if_changed(out / "index.rst", "\n".join(index))


def _write_if_changed(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


# -- CLI reference ---------------------------------------------------------------------------

_RST_SPECIAL = re.compile(r"([\\`*|_\[\]<>])")


def _escape(text: str) -> str:
    return _RST_SPECIAL.sub(r"\\\1", " ".join(text.split()))


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _arguments(parser: argparse.ArgumentParser) -> list[str]:
    lines: list[str] = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.help == argparse.SUPPRESS:
            continue
        if action.option_strings:
            metavar = ""
            if action.nargs != 0:
                if isinstance(action.metavar, tuple):
                    metavar = " " + " ".join(action.metavar)
                else:
                    metavar = " " + (action.metavar or action.dest.upper())
            term = ", ".join(f"``{o}{metavar}``" for o in action.option_strings)
        else:
            term = f"``{action.metavar or action.dest}``"
        text = _escape(action.help or "")
        if action.choices and not isinstance(action, argparse._SubParsersAction):
            text += " (one of " + ", ".join(f"``{c}``" for c in action.choices) + ")"
        lines += [term, f"   {text or '(no description)'}", ""]
    return lines


def cli_rst(parser: argparse.ArgumentParser, name: str, level: int = 0) -> list[str]:
    chars = "-~^\""
    lines: list[str] = []
    if level:
        lines += [f".. _cli-{name.replace(' ', '-')}:", ""]
        lines += _title(f"``{name}``", chars[level - 1])
    usage = parser.format_usage().replace("usage: ", "", 1).rstrip()
    lines += ["::", ""] + ["   " + u for u in usage.splitlines()] + [""]
    if parser.description:
        lines += [_escape(parser.description), ""]
    args = _arguments(parser)
    if args:
        lines += ["**Arguments**", ""] + args
    subs = _subparsers(parser)
    for sub_name, sub in subs.items():
        lines += cli_rst(sub, f"{name} {sub_name}", level + 1)
    return lines


class LfprocCli(SphinxDirective):
    """``.. lfproc-cli::``: the whole ``lfproc`` command tree from its argparse parser."""

    has_content = False

    def run(self):
        from lfproc.cli.main import build_parser

        old = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = "90"  # argparse wraps usage lines at the terminal width: fix it
        try:
            text = cli_rst(build_parser(), "lfproc")
        finally:
            if old is None:
                del os.environ["COLUMNS"]
            else:
                os.environ["COLUMNS"] = old
        node = nodes.section()
        node.document = self.state.document
        nested_parse_with_titles(self.state, StringList(text, source="lfproc-cli"), node)
        return node.children


def _drop_type_docstring(app, what, name, obj, options, lines) -> None:
    """A constant without a doc comment would show its type's docstring (a numpy array: all of
    ``numpy.ndarray``'s, whose glossary terms then fail the build): drop it. A constant's own doc
    comment (``#:``) is kept."""
    if what not in ("data", "attribute") or not lines:
        return
    import inspect

    if inspect.isclass(obj) or inspect.isroutine(obj) or inspect.ismodule(obj):
        return
    inherited = getattr(obj, "__doc__", None)  # an instance's __doc__ is its type's
    if not inherited:
        return
    longest = max((line.strip() for line in lines), key=len)
    if longest and longest in inherited:
        lines.clear()


def setup(app):
    app.add_config_value("lfproc_api_modules", [], "env")
    app.connect("config-inited", write_api_pages)
    app.add_directive("lfproc-cli", LfprocCli)
    app.connect("autodoc-process-docstring", _drop_type_docstring, priority=400)  # before numpydoc
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
