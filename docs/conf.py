"""Sphinx configuration of piezohyst's documentation site (``make docs``).

The site is built with warnings as errors (``sphinx-build -W``): a broken cross-reference, a
docstring section numpydoc cannot read, or a gallery example that raises fails the build.
The API reference is written at build time from the packages' own maps (``api_pages.py``), so
a public name added to an ``__all__`` gets its page without anyone editing this folder.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import api_pages  # noqa: E402  (the API reference's writer, beside this file)

import piezohyst  # noqa: E402

project = "piezohyst"
author = "piezohyst developers"
copyright = "2026, piezohyst developers"
release = piezohyst.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "sphinx_design",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
templates_path = ["_templates"]
exclude_patterns = ["_build", "api/generated/*.examples", "sg_execution_times.rst", "**.ipynb"]

# -- the existing guides, in Markdown (MyST) ----------------------------------------------
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
# the guides name files of the repository (benchmarks/..., README.md): links to GitHub
suppress_warnings = ["myst.header"]

# -- the API reference -----------------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": True, "inherited-members": False, "show-inheritance": True}
autodoc_typehints = "none"  # the numpydoc sections say the types, in words a reader uses
autodoc_member_order = "groupwise"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# -- the gallery -----------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": str(HERE.parent / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "remove_config_comments": True,
    "download_all_examples": False,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "min_reported_time": 1,
    "show_memory": False,
}

# -- the page ----------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"piezohyst {release}"
html_static_path = ["_static"]
html_favicon = "_static/favicon.svg"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "header_links_before_dropdown": 6,
    "secondary_sidebar_items": ["page-toc"],
}
html_show_sourcelink = False
html_context = {
    "default_mode": "auto"
}  # the reader's light or dark; unset, the theme logs an error
html_last_updated_fmt = None

os.environ.setdefault("MPLBACKEND", "Agg")


def setup(app):
    """Write the API reference's pages before Sphinx reads the sources."""
    api_pages.write(HERE / "api")
