"""The report as a list of blocks (headings, paragraphs, lists, tables, figures) and its
rendering to Markdown and to self-contained HTML (PNGs embedded as base64 ``data:`` URIs,
inline CSS), written atomically."""

from __future__ import annotations

import base64
import html
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from cfbmarkov._atomic import atomic_path

FIGURES = "figures"
#: a link to a heading of the report in a paragraph, table cell or list item: [text](#anchor)
_LINK = re.compile(r"\[([^\]]+)\]\(#([a-z0-9-]+)\)")


def anchor(text: str) -> str:
    """The anchor of a heading, as Markdown renderers (GitHub, MyST) derive it.

    Parameters
    ----------
    text : str
        The heading's text.

    Returns
    -------
    str
        Lower case, punctuation dropped, spaces as hyphens, e.g. "Table 3 in detail" ->
        "table-3-in-detail".
    """
    kept = re.sub(r"[^\w\- ]", "", text.strip().lower())
    return kept.replace(" ", "-")


def link(text: str, heading: str) -> str:
    """A link to a heading of the report, written into a block's text.

    Parameters
    ----------
    text : str
        The link's text.
    heading : str
        The heading's text (:func:`anchor`).

    Returns
    -------
    str
        ``[text](#anchor)``: a Markdown link, and an ``<a href="#anchor">`` in the HTML.
    """
    return f"[{text}](#{anchor(heading)})"


def finite_or_none(value) -> float | None:
    """A value as a finite float, or None.

    Parameters
    ----------
    value : object
        Anything ``float()`` accepts.

    Returns
    -------
    float or None
        ``float(value)``; None when it cannot be converted or is not finite.
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None

@dataclass
class Heading:
    """A heading.

    Attributes
    ----------
    level : int
        2 or 3.
    text : str
        The heading text.
    """

    level: int
    text: str


@dataclass
class Para:
    """A paragraph.

    Attributes
    ----------
    text : str
        The paragraph text.
    css : str
        An HTML class, e.g. ``warn`` (empty: none).
    """

    text: str
    css: str = ""


@dataclass
class Bullets:
    """A bulleted list.

    Attributes
    ----------
    items : list of str
        The items.
    """

    items: list[str]


@dataclass
class Table:
    """A table with numbered notes below it.

    Attributes
    ----------
    header : list of str
        Column headings.
    rows : list of list of str
        The cells, row by row.
    notes : list of str
        Notes printed below the table, numbered from 1.
    """

    header: list[str]
    rows: list[list[str]]
    notes: list[str] = field(default_factory=list)


@dataclass
class FigureBlock:
    """A figure.

    Attributes
    ----------
    file : str
        PNG file name in ``figures/``.
    title : str
        Figure title.
    sentence : str
        Caption sentence.
    """

    file: str
    title: str
    sentence: str


def number_text(value, spec: str, unit: str = "") -> str:
    """A number as text, or "n/a" when it is not finite.

    Parameters
    ----------
    value : object
        The number (see :func:`finite_or_none`).
    spec : str
        Format specification, e.g. ``".3f"``.
    unit : str, optional
        Appended after the number, e.g. ``" s"``.

    Returns
    -------
    str
    """
    v = finite_or_none(value)
    return "n/a" if v is None else f"{v:{spec}}{unit}"


def interval_text(lo, hi, decimals: int = 3, sep: str = "–") -> str:
    """An interval's ends as text, with as many decimals as keep them apart.

    Parameters
    ----------
    lo, hi : object
        The ends (see :func:`finite_or_none`).
    decimals : int, optional
        The fewest decimals; more are taken (up to 12) while the two ends, where they
        differ, would print fewer than three steps of the last digit apart, so that an
        interval never collapses to "0.014-0.014" nor reads as "0.013-0.014"; the lower
        end rounded down and the upper up, so that the text holds every value the interval
        holds, with a digit more where that rounding widens it by more than
        :data:`WIDENED`.
    sep : str, optional
        Between the ends.

    Returns
    -------
    str
        "0.0138–0.0144", or "n/a" where an end is not finite.
    """
    a, b = finite_or_none(lo), finite_or_none(hi)
    if a is None or b is None:
        return "n/a"
    d = decimals
    # ends at least three steps of the last digit apart: "0.0133-0.0142", not "0.013-0.015"
    while d < 12 and a != b and abs(round(b * 10 ** d) - round(a * 10 ** d)) < 3:
        d += 1
    while True:
        # rounded outwards, so that the printed interval holds every value the stored one
        # holds; a digit more where that widens it by more than a quarter ("0.0509-0.0538"
        # for 0.05098-0.05374, not "0.050-0.054")
        scale = 10.0 ** d
        low, high = a * scale, b * scale
        low = math.floor(low + 1e-9 * abs(low)) / scale
        high = math.ceil(high - 1e-9 * abs(high)) / scale
        if d >= 12 or not b > a or high - low <= WIDENED * (b - a):
            return f"{low:.{d}f}{sep}{high:.{d}f}"
        d += 1


#: how much wider than the stored interval its printed ends may be (:func:`interval_text`)
WIDENED = 1.25


def duration_text(seconds) -> str:
    """A wall time in s, min or h (3 significant digits), or "n/a".

    Parameters
    ----------
    seconds : object
        The duration, s (see :func:`finite_or_none`).

    Returns
    -------
    str
        Seconds below 120 s, minutes below 2 h, else hours; "n/a" when not finite.
    """
    s = finite_or_none(seconds)
    if s is None:
        return "n/a"
    if s < 120:
        return f"{s:.3g} s"
    if s < 7200:
        return f"{s / 60:.3g} min"
    return f"{s / 3600:.3g} h"


def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def render_markdown(title: str, blocks) -> str:
    """The blocks as Markdown, figures linked as ``figures/NAME.png``.

    Parameters
    ----------
    title : str
        Document title (the level-1 heading).
    blocks : iterable
        :class:`Heading`, :class:`Para`, :class:`Bullets`, :class:`Table` and
        :class:`FigureBlock` objects.

    Returns
    -------
    str
        The Markdown text, ending in a newline.
    """
    out = [f"# {title}", ""]
    for b in blocks:
        if isinstance(b, Heading):
            out += ["#" * b.level + " " + b.text, ""]
        elif isinstance(b, Para):
            out += [b.text, ""]
        elif isinstance(b, Bullets):
            out += [f"- {item}" for item in b.items] + [""]
        elif isinstance(b, Table):
            out.append("| " + " | ".join(_md_cell(h) for h in b.header) + " |")
            out.append("|" + "|".join("---" for _ in b.header) + "|")
            out += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in b.rows]
            out.append("")
            if b.notes:
                out += [f"{k + 1}. {note}" for k, note in enumerate(b.notes)] + [""]
        elif isinstance(b, FigureBlock):
            out += [f"![{b.title}]({FIGURES}/{b.file})", "", f"**{b.title}.** {b.sentence}", ""]
    return "\n".join(out).rstrip() + "\n"


_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; color: #222;
       max-width: 1180px; margin: 2em auto; padding: 0 1.2em; line-height: 1.45; }
h1 { font-size: 1.7em; border-bottom: 2px solid #1f4e79; padding-bottom: .2em; }
h2 { font-size: 1.3em; margin-top: 2em; color: #1f4e79; border-bottom: 1px solid #ccd; }
h3 { font-size: 1.08em; margin-top: 1.4em; }
div.wide { overflow-x: auto; }
p.verdict { font-weight: bold; border-left: 4px solid #1f4e79; padding-left: .6em; }
table { border-collapse: collapse; margin: .8em 0; font-size: .88em; }
th, td { border: 1px solid #bbc; padding: .25em .55em; text-align: right; }
th { background: #eef2f7; text-align: center; }
td:first-child, td:nth-child(2) { text-align: left; }
tr:nth-child(even) td { background: #fafbfd; }
ol.notes { font-size: .85em; color: #444; }
figure { margin: 1em 0 1.6em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #e3e3e3; }
figcaption { font-size: .92em; margin-top: .3em; }
p.warn { color: #8a4b00; }
p.verdict { font-weight: 600; border-left: 4px solid #1f4e79; padding-left: .7em; }
"""


def render_html(title: str, blocks, figures_dir: Path) -> str:
    """The blocks as one self-contained HTML page.

    Figures are embedded as base64 ``data:`` URIs, styles inline.

    Parameters
    ----------
    title : str
        Document title.
    blocks : iterable
        :class:`Heading`, :class:`Para`, :class:`Bullets`, :class:`Table` and
        :class:`FigureBlock` objects.
    figures_dir : pathlib.Path
        Folder the figures' PNGs are read from.

    Returns
    -------
    str
        The HTML text.
    """
    def e(text) -> str:
        """Escaped text with its links to headings as anchors."""
        return _LINK.sub(r'<a href="#\2">\1</a>', html.escape(str(text)))

    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           f"<title>{html.escape(title)}</title>", f"<style>{_CSS}</style>", "</head>", "<body>",
           f"<h1>{e(title)}</h1>"]
    for b in blocks:
        if isinstance(b, Heading):
            out.append(f'<h{b.level} id="{anchor(b.text)}">{e(b.text)}</h{b.level}>')
        elif isinstance(b, Para):
            out.append(f'<p class="{b.css}">{e(b.text)}</p>' if b.css else f"<p>{e(b.text)}</p>")
        elif isinstance(b, Bullets):
            out.append("<ul>" + "".join(f"<li>{e(i)}</li>" for i in b.items) + "</ul>")
        elif isinstance(b, Table):
            out.append('<div class="wide"><table><thead><tr>' + "".join(f"<th>{e(h)}</th>" for h in b.header)
                       + "</tr></thead><tbody>")
            out += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in b.rows]
            out.append("</tbody></table></div>")
            if b.notes:
                out.append('<ol class="notes">' + "".join(f"<li>{e(n)}</li>" for n in b.notes)
                           + "</ol>")
        elif isinstance(b, FigureBlock):
            encoded = base64.b64encode((figures_dir / b.file).read_bytes()).decode("ascii")
            out.append(f'<figure><img src="data:image/png;base64,{encoded}" alt="{html.escape(b.title)}">'
                       f"<figcaption><b>{e(b.title)}.</b> {e(b.sentence)}</figcaption></figure>")
    out += ["</body>", "</html>", ""]
    return "\n".join(out)


def readable_mode() -> int:
    """File mode rw for everyone the umask allows (temporary files of atomic_path are 0600).

    Returns
    -------
    int
        ``0o666`` less the current umask.
    """
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def write_utf8(path: Path, text: str) -> None:
    """Write text to a file atomically, readable as the umask allows.

    Parameters
    ----------
    path : pathlib.Path
        The file.
    text : str
        Written as UTF-8.
    """
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
        os.chmod(tmp, readable_mode())


__all__ = ["FIGURES", "Bullets", "FigureBlock", "Heading", "Para", "Table", "anchor", "duration_text", "interval_text",
           "finite_or_none", "link", "number_text", "readable_mode", "render_html", "render_markdown",
           "write_utf8"]
