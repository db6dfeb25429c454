"""Sphinx configuration of the fpe-harvester site.

Build (warnings are errors): ``python -m sphinx -W --keep-going -b html docs docs/_build/html``.
"""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path[:0] = [str(ROOT), str(DOCS / "_ext")]

project = "fpe-harvester"
author = "the fpe-harvester developers"
copyright = "2026, " + author  # noqa: A001  (Sphinx's name)

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.intersphinx",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "apipages",
    "benchtables",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "_cache", "examples", "**/*.ipynb"]
templates_path = ["_templates"]
bench_data_dir = str(ROOT / "validation" / "data")

# API reference: autosummary stubs from the pages apipages writes, numpydoc docstrings
autosummary_generate = True
autosummary_imported_members = True
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()

myst_enable_extensions = ["colon_fence"]
myst_heading_anchors = 3

intersphinx_mapping: dict[str, tuple[str, None]] = {}

# gallery: the shipped scenes, run on committed caches of their points (docs/_cache)
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "gallery",
    "filename_pattern": r"/scene_",
    "image_scrapers": ("scenegallery.scene_scraper",),  # by name: the config stays picklable
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "line_numbers": False,
    "plot_gallery": "True",
}

html_theme = "pydata_sphinx_theme"
html_title = "fpe-harvester"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "header_links_before_dropdown": 5,
    "secondary_sidebar_items": ["page-toc"],
}
html_sidebars = {"index": [], "getting-started": [], "model": [], "methods": [], "benchmarks": []}
html_static_path: list[str] = []
html_show_sourcelink = False
