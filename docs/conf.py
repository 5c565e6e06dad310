"""Sphinx configuration of the sns_np documentation: the guides of docs/ (markdown, through
myst-parser) and an API reference generated from the numpydoc docstrings.

Build (warnings are errors): ``tox -e docs`` or
``python -m sphinx -W --keep-going -b html docs docs/_build/html``.
"""

import os
import re
import sys

sys.path.insert(0, os.path.abspath(".."))   # the source tree when the package is not installed

import sns_np  # noqa: E402

project = "sns_np"
author = "sns_np developers"
copyright = "sns_np developers, MIT licence"
release = sns_np.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]
templates_path = []

# autodoc: members in each module's __all__, in source order; signatures without type noise
autodoc_default_options = {"members": True, "member-order": "bysource", "show-inheritance": True}
autodoc_typehints = "none"
autodoc_class_signature = "mixed"
autodoc_preserve_defaults = True

# numpydoc: methods are documented by autodoc below each class (no autosummary tables), and
# the shapes-first parameter lines ("V : (n, 3) float array") are kept as written
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks = set()

# myst: the guides are plain markdown; heading anchors for links between them
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]



# ---------------------------------------------------------------------------------------------
# Plain-text formulas. Docstrings are written to read well in help() and in a terminal:
# ``|x|`` outside double backquotes is an absolute value there, not a reST substitution, and a
# numpydoc type line may continue a ``literal`` on the next line. Both are made reST-safe here
# (before numpydoc parses the docstring), so the source stays plain text.

def _escape_bars(line):
    parts = line.split("``")
    for i in range(0, len(parts), 2):       # outside inline literals
        parts[i] = re.sub(r"(?<!\\)\|", r"\\|", parts[i])
    return "``".join(parts)


def _plain_text_docstring(app, what, name, obj, options, lines):
    out, i = [], 0
    while i < len(lines):
        line = lines[i]
        # a literal left open at the end of a line is closed by joining the next line(s)
        while line.count("``") % 2 and i + 1 < len(lines) and lines[i + 1].strip():
            i += 1
            line = line.rstrip() + " " + lines[i].strip()
        if line.lstrip().startswith((">>>", "...")) or line.count("``") % 2:
            out.append(line)
        else:
            out.append(_escape_bars(line))
        i += 1
    lines[:] = out


def setup(app):
    app.connect("autodoc-process-docstring", _plain_text_docstring, priority=100)


html_theme = "alabaster"
html_title = f"sns_np {release}"
html_static_path = []
