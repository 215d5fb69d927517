"""Sphinx configuration of the morsuite documentation.

Build (warnings are errors, as in CI):

    python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

import os
import sys

sys.path.insert(0, os.path.abspath(".."))
sys.path.insert(0, os.path.abspath("_ext"))

import morsuite  # noqa: E402

project = "morsuite"
author = "the morsuite developers"
copyright = "2026, the morsuite developers"
version = release = morsuite.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
    "morsuite_api",
    "docstring_patches",
    "morsuite_tables",
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**.ipynb_checkpoints"]
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
myst_heading_anchors = 3

# tutorials are executed at build time; a failing cell fails the build
nb_execution_mode = "cache"
nb_execution_raise_on_error = True
nb_execution_timeout = 300

numpydoc_show_class_members = False
autodoc_member_order = "bysource"

html_theme = "pydata_sphinx_theme"
html_title = "morsuite"
html_theme_options = {"navigation_with_keys": False}
