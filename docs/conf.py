"""Sphinx configuration: the markdown pages (myst-parser) and the API reference (autodoc +
numpydoc). Build from the repository root with

    python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# the source tree first, so that the pages describe this checkout even without an install
sys.path.insert(0, str(ROOT / "src"))
# importing cfbmarkov runs no heavy code: numba compiles a kernel on its first call, and
# autodoc only imports the modules

project = "cfbmarkov"
author = "the cfbmarkov authors"
copyright = "cfbmarkov authors, MIT licence"

try:
    from cfbmarkov import __version__ as release
except Exception:  # pragma: no cover - the API pages would fail anyway
    release = "unknown"
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinxarg.ext",  # the command-line reference (docs/cli.rst), from the argparse parser
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# docs/results/<run>/ hold reproductions' outputs (reports with figures left out): data,
# linked from docs/results/index.md, not pages of the guide
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "results/paper-*"]

# markdown: anchors for headings down to level 4 (docs/definitions.md#residence-time,
# docs/definitions.md#intervals); a link to a missing page, file or anchor is a warning,
# so an error under -W. $...$ maths
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath"]

# autodoc: members in source order, signatures without the type-hint clutter
autodoc_member_order = "bysource"
autodoc_typehints = "none"
autodoc_default_options = {"members": True, "show-inheritance": True}

# numpydoc: render the sections; no member tables (autodoc lists the members), and no
# validation beyond what a clean build needs
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

html_theme = "alabaster"
html_title = f"cfbmarkov {release}"

# inherited docstrings (e.g. concurrent.futures.Executor.submit) are not this project's text
autodoc_inherit_docstrings = False

# The docstrings are plain text that writes an absolute value as |x| (|u - v|, |ln e|),
# which reStructuredText would read as a substitution reference. Escape such bars outside
# literal text (``...`` and literal blocks), so that they print as written.
_BAR_PAIR = re.compile(r"(?<![\\|])\|(?=\S)([^|`\n]*?\S)\|(?!\|)")


def _escape_bars(line: str) -> str:
    parts = line.split("``")
    for k in range(0, len(parts), 2):       # even parts lie outside inline literals
        parts[k] = _BAR_PAIR.sub(r"\\|\1\\|", parts[k])
    return "``".join(parts)


def _plain_bars(app, what, name, obj, options, lines):
    literal_indent = None                   # indentation of the paragraph that opened "::"
    opens_literal = False
    for i, line in enumerate(lines):
        stripped = line.strip()
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None:
            if stripped and indent <= literal_indent:
                literal_indent = None
            else:
                continue
        if opens_literal and stripped:
            literal_indent, opens_literal = previous_indent, False
            if indent > literal_indent:
                continue
            literal_indent = None
        if stripped.endswith("::"):
            opens_literal, previous_indent = True, indent
        if re.match(r"\|\s|\+[-=]", stripped):   # line blocks and grid tables
            continue
        lines[i] = _escape_bars(line)


def setup(app):
    app.connect("autodoc-process-docstring", _plain_bars)
