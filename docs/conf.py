"""Sphinx configuration of the snn-antenna documentation site.

Build it offline with warnings as errors (``tests/test_docs.py`` does the same)::

    python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the checkout's package, also when not installed
sys.path.insert(0, str(Path(__file__).parent / "_ext"))

import snn_antenna  # noqa: E402  (after the path is set)

project = "snn-antenna"
author = "the snn-antenna authors"
copyright = "the snn-antenna authors"
version = release = snn_antenna.__version__

extensions = [
    "myst_parser",  # the Markdown pages (docs/*.md, the README's style)
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",  # one page per public module, generated at build time
    "sphinx.ext.napoleon",  # numpy-style docstrings
    "sphinx.ext.mathjax",
    "plain_docstrings",  # docs/_ext: docstrings are plain text, not reST
    "source_comments",  # docs/_ext: a field's or a constant's comment shown on its API page
    "sphinx_gallery.gen_gallery",  # docs/examples: run at build, with their figures
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "README.md", "results/*.md", "examples/GALLERY_HEADER.rst"]

myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 3  # links such as reference.md#your-files resolve

autosummary_generate = True  # api/generated/ is written by the build, never committed
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_mock_imports: list[str] = []
napoleon_numpy_docstring = True
napoleon_google_docstring = False

# Text in docstrings names the toolkit's objects in ``double back-quotes``; cross-references
# are resolved where they exist and plain text elsewhere (no nitpicky mode).
default_role = "literal"

# The gallery: every docs/examples/plot_*.py is run when the site is built (an example that
# fails fails the build), its output and figures are put on its page, and each page can be
# downloaded as a script or a notebook. Each API page lists the examples that use its module
# (the minigallery in _templates/autosummary/module.rst reads the backreferences).
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "gallery",              # generated at build time, never committed
    "filename_pattern": r"/plot_",
    "doc_module": ("snn_antenna",),
    "backreferences_dir": "gallery/backreferences",
    "abort_on_example_error": True,
    "download_all_examples": False,
    "write_computation_times": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "within_subsection_order": "FileNameSortKey",
}

html_theme = "pydata_sphinx_theme"
html_title = f"snn-antenna {release}"
html_static_path = ["_static"]
html_css_files = ["custom.css"]
templates_path = ["_templates"]
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "navbar_align": "left",
    "header_links_before_dropdown": 2,
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_show_sourcelink = False
# every guide and reference page sits at the top of the site, so the left column would only
# say "Section Navigation" over nothing: the page takes the width (the API keeps its tree)
html_sidebars = {
    page: []
    for page in [
        "index",
        "install",
        "tutorial",
        "troubleshooting",
        "developer",
        "results",
        "reference",
        "materials",
        "live",
        "contributing",
        "changelog",
        "guide/*",
    ]
}

# Short class names (``Parts``, ``Plan``) are defined by more than one study; a type named in a
# signature is linked where it is unique and left as text where two studies define it.
suppress_warnings = ["ref.python"]
html_last_updated_fmt = None
