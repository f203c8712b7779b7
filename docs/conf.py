"""Sphinx configuration of the animegraph documentation site.

Build (warnings are errors, as in CI, tests/test_docs.py)::

    PYTHONPATH=$PWD sphinx-build -W --keep-going -b html docs docs/_build/html

Pages are Markdown (MyST), so that GitHub renders them too; the API reference comes from
the numpydoc docstrings, the command-line reference from the argument parser itself
(``docs/_ext/cli_reference.py``), the gallery from ``docs/examples/plot_*.py``
(sphinx-gallery; the examples run at build time on a tiny synthetic corpus).
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
# The project is imported from this checkout (an editable install may point elsewhere).
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE / "_ext"))

from animegraph import __version__  # noqa: E402

project = "animegraph"
author = "the animegraph authors"
copyright = "the animegraph authors; MIT licence"
version = release = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx.ext.mathjax",
    "sphinx_gallery.gen_gallery",
    "cli_reference",
    "internal_refs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# Only the site's own pages: build output, the gallery's sources (sphinx-gallery turns
# them into auto_examples/) and the results page that docs/results/ replaces.
exclude_patterns = ["_build", "examples", "results.md"]
templates_path = ["_templates"]

# Every reference to a page, heading or object of this project must resolve (an object
# the API reference leaves out must at least exist: docs/_ext/internal_refs.py); names of
# other libraries (numpy, pathlib, pyarrow ...) are left as plain text (no intersphinx:
# the build runs offline).
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(?!(animegraph|db|ingest)\b).*"),
]

# -- MyST ---------------------------------------------------------------------------
# linkify: bare URLs become links, as GitHub shows them.
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath", "linkify"]
# ``page.md#a-heading`` links resolve for headings down to ###.
myst_heading_anchors = 3
# "$ANIMEGRAPH_DB or $HOME" stays text: math needs no space inside its dollars.
myst_dmath_allow_space = False

# -- autodoc / autosummary / numpydoc -------------------------------------------------
autosummary_generate = True
autosummary_imported_members = False
autodoc_typehints = "none"  # numpydoc's Parameters section says the types
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "inherited-members": False, "undoc-members": False}
numpydoc_show_class_members = False  # the class template lists them
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# -- sphinx-gallery -------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": ["examples"],
    "gallery_dirs": ["auto_examples"],
    "filename_pattern": r"/plot_",
    # Helper modules of the examples (the shared tiny database) are not examples.
    "ignore_pattern": r"^_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "min_reported_time": 1,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
}

# -- HTML -----------------------------------------------------------------------------
html_theme = "furo"
html_title = f"animegraph {version}"
html_static_path: list[str] = []
html_show_sourcelink = False
