"""Sphinx configuration of the dftc-mujoco documentation site.

Why this stack: the package's docstrings are already reStructuredText with Sphinx roles
(:func:, :class:, :mod:), so ``sphinx.ext.autodoc`` reads them as they are; the pages are
Markdown through MyST (myst-parser), and the tutorials are MyST text notebooks executed at
build time by myst-nb, so every figure and number they show comes from a real run of the
simulator. Gymnasium and PettingZoo document themselves with the same stack (Sphinx, furo,
MyST and executed pages).

Build (from the repository's root; the ``docs`` extra installs the tools):

    python -m sphinx -W --keep-going -n -b html docs docs/_build/html

``-W`` turns every warning (a broken link, an unknown reference, a notebook cell that
raised) into a failure; ``tests/test_docs.py`` runs that command.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the package, also when it is not installed
os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco is imported by autodoc or a tutorial

import dftc_mujoco  # noqa: E402

project = "dftc-mujoco"
author = "the dftc-mujoco authors"
copyright = "the dftc-mujoco authors, MIT licence"
release = dftc_mujoco.__version__
version = release

extensions = [
    "myst_nb",  # MyST Markdown pages and executed MyST notebooks (includes myst_parser)
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
]

source_suffix = {".md": "myst-nb", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "**/.ipynb_checkpoints", "jupyter_execute"]
root_doc = "index"

# MyST: $...$ maths, definition lists, ```{directive} fences; heading anchors for links
myst_enable_extensions = ["dollarmath", "deflist", "colon_fence"]
myst_heading_anchors = 3

# myst-nb: run every tutorial at build time, and fail the build when a cell raises
nb_execution_mode = "force"
nb_execution_raise_on_error = True
nb_execution_timeout = 180
nb_execution_show_tb = True
nb_merge_streams = True

# autodoc: members in source order, no private members
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "undoc-members": False}
autodoc_typehints = "description"
autodoc_typehints_format = "short"

# nitpicky mode (-n, as tests/test_docs.py builds): every cross-reference must resolve.
# Type hints in the public signatures name classes that have no page here: numpy's,
# MuJoCo's, dm_control's and the standard library's, and the package's internal classes
# (the graph, the scenario's parts, the blocks' compiled records, ...), which change as the
# code does; those class references are not checked. Every other reference — a :func:,
# :meth:, :attr:, :mod: or :exc: role in a docstring, a {doc} link in a page — must
# resolve, except the few internal names below that the public docstrings mention.
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|mujoco|collections|typing|pathlib|os|tomllib)(\..*)?"),
    (r"py:.*", r"(dm_env|dm_control)(\..*)?"),
    (r"py:class", r"dftc_mujoco\..*"),
    (r"py:class", r"[A-Z]\w*"),  # a class named bare in a type hint
    (r"py:exc", r"ScenarioError"),
    (r"py:(func|attr|mod)", r"(apply_overrides|dropped_faults|load|allowed|radio|seat)"),
]

html_theme = "furo"
html_title = f"dftc-mujoco {release}"
html_static_path: list[str] = []
