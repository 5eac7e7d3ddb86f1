"""Sphinx configuration: the user guide (Markdown), the API reference from the numpydoc
docstrings, and the notebooks executed with their figures (myst-nb).

Build from the repository root with warnings as errors::

    pip install ".[docs]" && sphinx-build -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import shutil
from pathlib import Path

import implicitmesh

ROOT = Path(__file__).resolve().parents[1]

project = "implicitmesh"
author = "the implicitmesh developers"
release = version = implicitmesh.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_nb",
]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "**.ipynb_checkpoints"]
html_theme = "furo"
html_title = f"implicitmesh {release}"

autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]

# The notebooks live in notebooks/ (run by the test suite too); a copy beside the pages is
# executed here, so that the rendered pages carry their figures.
nb_execution_mode = "force"
nb_execution_timeout = 900
nb_execution_raise_on_error = True
_copy = Path(__file__).parent / "notebooks"
if _copy.exists():
    shutil.rmtree(_copy)
shutil.copytree(ROOT / "notebooks", _copy, ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
