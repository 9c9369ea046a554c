"""Sphinx configuration: the API reference from the docstrings, and the README's walkthroughs.

Built offline with warnings as errors (``make docs``; ``make test`` runs it): no intersphinx, no
theme or font fetched (alabaster ships with Sphinx), no math renderer loaded from a CDN.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# Document the tree the docs sit in, whatever copy of pbdkit the environment has installed.
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))
# The simulator imports MuJoCo, which picks its rendering backend at import time; nothing is
# rendered here, and EGL (the default) needs no display.
os.environ.setdefault("MUJOCO_GL", "egl")

import pbdkit  # noqa: E402

project = "pbdkit"
author = "pbdkit contributors"
copyright = "pbdkit contributors"
release = version = pbdkit.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    # The walkthroughs are the README's sections, included rather than copied so that the two
    # cannot drift apart; the README is Markdown.
    "myst_parser",
    "pbdkit_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# Keep "--" as typed: the docstrings and the README name command-line options in plain text.
smartquotes_action = "qe"
exclude_patterns = ["_build"]

# --- autodoc: numpy docstrings, members in source order
# A module's __all__ is its API, documented or not (class members without a docstring are left
# to the class's "Attributes" section: pbdkit_docs).
autodoc_default_options = {
    "members": True,
    "undoc-members": True,
    "member-order": "bysource",
    "show-inheritance": True,
}
# The numpy docstrings give every parameter's type and shape; the annotations, expanded
# (npt.ArrayLike is a union of seven types), would bury the signatures, as in scikit-learn's.
autodoc_typehints = "none"
autodoc_preserve_defaults = True
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False

# Broken references to pbdkit's own objects fail the build; names outside pbdkit (numpy, the
# standard library) cannot be resolved offline, so they are left as text.
nitpicky = True
nitpick_ignore_regex = [("py:.*", r"(?!pbdkit\.).*")]
# Shapes in numpy docstrings ("shape (n_liquid, 3)") become references in typed fields, and a
# symbol that is also an attribute name in several classes would warn of an ambiguity.
suppress_warnings = ["ref.python"]

# --- MyST: anchors for the README's and benchmarks' headings, as GitHub makes them
myst_heading_anchors = 3

# --- HTML
html_theme = "alabaster"
html_title = f"pbdkit {release}"
html_static_path: list[str] = []
html_theme_options = {
    "description": "Probabilistic Programming by Demonstration",
    "fixed_sidebar": True,
    "page_width": "1100px",
    "sidebar_width": "240px",
}
html_sidebars = {"**": ["about.html", "navigation.html", "relations.html", "searchbox.html"]}
