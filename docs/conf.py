"""Sphinx configuration of the thinfilm-mi documentation (``make docs``).

Lean on purpose: the test suite builds this site with ``-W`` (tests/cross/test_readme_commands.py
runs ``make docs``), so no intersphinx (no network) and no autosummary stub pages. The
notebooks (``docs/notebooks`` is a link to ``notebooks/``) are rendered by myst-nb from the
outputs stored in them (``scripts/store_notebook_outputs.py``), never executed here.
"""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

from thinfilm_plugins import RST_PROLOG  # noqa: E402

from thinfilm_mi.version import __version__  # noqa: E402

project = "thinfilm-mi"
author = "the thinfilm-mi authors"
copyright = "the thinfilm-mi authors, BSD-3-Clause"
release = version = __version__

extensions = [
    "myst_nb",                  # Markdown pages (MyST) and the notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",      # the numpy-style "Parameters" sections of the docstrings
    "sphinx.ext.mathjax",
    "thinfilm_plugins",
    "thinfilm_generated",       # {generated} NAME: a benchmark's tables, docs/_generated/NAME.md
    "thinfilm_policy",          # {policy}: prose whose numbers are tabulate.policy's constants
]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "_generated"]   # _generated: benchmark tables, shown by {generated}
root_doc = "index"
rst_prolog = RST_PROLOG
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
nb_execution_mode = "off"       # the stored outputs; `make docs` never runs a notebook
nb_merge_streams = True

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented"
napoleon_google_docstring = False
autodoc_default_options = {"members": True, "undoc-members": False}

html_theme = "furo"
html_title = f"thinfilm-mi {release}"
html_static_path = ["_static"]
html_css_files = ["plugins.css"]
html_copy_source = False
html_show_sourcelink = False
