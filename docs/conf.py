"""Sphinx configuration of lfproc's documentation (build: ``sphinx-build -W docs docs/_build/html``)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
os.environ.setdefault("LFPROC_PROGRESS", "0")  # no progress bars in the gallery's output
os.environ.setdefault("MPLBACKEND", "Agg")

import lfproc  # noqa: E402

project = "lfproc"
author = "the lfproc authors"
copyright = "2026, the lfproc authors"
version = release = lfproc.__version__

# -- The public modules: the API reference lists each one's ``__all__`` -------------------
# The ONE place to edit when packages move (one page per module, grouped by pipeline stage).
API_MODULES = [
    ("Core: light fields, files, errors, test scenes",
     ["lfproc", "lfproc.lightfield", "lfproc.io", "lfproc.errors", "lfproc.synth", "lfproc.info"]),
    ("1. Lytro decoding", ["lfproc.lytro", "lfproc.lytro.decode", "lfproc.lytro.whites", "lfproc.lytro.virtual",
                           "lfproc.lytro.extract", "lfproc.lytro.score"]),
    ("2. HDR merging and data sets", ["lfproc.hdr", "lfproc.dataset"]),
    ("3. The sensor model, camera profiles and calibration",
     ["lfproc.sensor", "lfproc.calib", "lfproc.calib.emva", "lfproc.calib.frames", "lfproc.calib.report"]),
    ("4. The coded multi-ISO camera",
     ["lfproc.camera", "lfproc.camera.simulate", "lfproc.camera.capture", "lfproc.camera.projection",
      "lfproc.camera.iso"]),
    ("5. Dictionaries and reconstruction", ["lfproc.dictionary", "lfproc.recon"]),
    ("6. Evaluation and pictures", ["lfproc.metrics", "lfproc.preview", "lfproc.refocus"]),
    ("7. Bench and demo", ["lfproc.bench", "lfproc.demo"]),
]
lfproc_api_modules = API_MODULES
# the generated API pages (written by lfproc_docs at config-inited) are listed explicitly: with
# ``True`` autosummary would only see the pages a cached build environment already knew
API_PAGES = [f"api/{module}.rst" for _, modules in API_MODULES for module in modules]

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "sphinxcontrib.bibtex",
    "myst_parser",
    "lfproc_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "bench-quick/*.md", "examples/README.txt", "**.ipynb_checkpoints",
                    "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip", "auto_examples/*.md5",
                    "auto_examples/*.json"]
templates_path = ["_templates"]

# -- autodoc / autosummary / numpydoc --------------------------------------------------------
autosummary_generate = API_PAGES
autosummary_imported_members = True
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"  # numpydoc sections carry the types; signatures stay short
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# -- MyST (the user guide is Markdown, like the README it came from) ------------------------
myst_enable_extensions = ["dollarmath", "deflist"]
myst_heading_anchors = 3

# -- bibliography ----------------------------------------------------------------------------
bibtex_bibfiles = ["references.bib"]
bibtex_default_style = "plain"
bibtex_reference_style = "author_year"

# -- gallery ---------------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "min_reported_time": 1,
    "show_memory": False,
    "abort_on_example_error": True,
}

# -- HTML ------------------------------------------------------------------------------------
try:
    import pydata_sphinx_theme  # noqa: F401

    html_theme = "pydata_sphinx_theme"
    html_theme_options = {"navigation_depth": 2, "show_toc_level": 2}
except ImportError:  # pragma: no cover
    html_theme = "alabaster"
smartquotes = False  # "--option" must stay two hyphens (the CLI reference and the guide quote options)
html_title = f"lfproc {release}"
html_static_path: list[str] = []
# numpydoc turns a module docstring's "References" section into citations that its text does not
# cite ([1]_): harmless, and the docstrings move to the bibliography in a later step
suppress_warnings = ["config.cache", "ref.citation"]
