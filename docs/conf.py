"""Sphinx configuration of the fenicsmpm documentation (`make docs`: sphinx-build -W)."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "_ext"))
sys.path.insert(0, os.path.dirname(HERE))          # fenicsmpm itself, for autodoc

project = "fenicsmpm"
author = "the fenicsmpm developers"
copyright = "2026, the fenicsmpm developers"
release = version = "0.1.0"

extensions = ["sphinx.ext.autodoc", "myst_parser", "fenicsmpm_docs"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "results/*.json"]
myst_heading_anchors = 3
autodoc_member_order = "bysource"
autodoc_default_options = {"show-inheritance": True}
autoclass_content = "class"

try:                                                # Debian's python3-sphinx-rtd-theme
    import sphinx_rtd_theme  # noqa: F401
    html_theme = "sphinx_rtd_theme"
except ImportError:
    html_theme = "alabaster"
html_title = "fenicsmpm"
html_static_path = []
