"""Sphinx configuration of rimcl's documentation (build: see docs/README.md)."""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

import rimcl  # noqa: E402

project = "rimcl"
author = "the rimcl authors"
copyright = "the rimcl authors, MIT licence"
release = version = rimcl.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_click",
    "rimcl_docs",  # docs/_ext: the scene-key tables, the public API list, figure names
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_generated", "README.md"]
templates_path = ["_templates"]

# Markdown pages: $...$ maths, ::: fences, definition lists, anchors for ## headings
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 3

# The API is generated from the package: autosummary walks rimcl recursively, so a module
# that is added, moved or renamed appears (or disappears) without editing these pages.
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_typehints = "none"  # the numpydoc Parameters sections carry types and units
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks = set()
# cross-references in docstrings ("array of float", "RimclError") are prose, not links
nitpicky = False
numpydoc_xref_param_type = False

html_theme = "furo"
html_title = f"rimcl {release}"
html_static_path = ["_static"]
# no build date: the same sources give the same pages
html_last_updated_fmt = None
