"""A self-contained HTML report: text, tables and PNG figures embedded as base64.

The report has no external asset (no script, no stylesheet, no image file), so it can be mailed
or archived as one file. It is written atomically.
"""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from .._io import atomic_write_bytes

__all__ = ["Figure", "Section", "render_report", "write_report"]

_STYLE = """
body { font-family: -apple-system, 'Segoe UI', Helvetica, Arial, sans-serif; max-width: 1150px;
       margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #bbb; }
table { border-collapse: collapse; margin: .8em 0; }
th, td { border: 1px solid #ccc; padding: .25em .7em; text-align: left; }
th { background: #f0f0f0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { color: #555; font-size: .92em; margin-top: .3em; }
.ok { color: #176b1e; font-weight: bold; } .fail { color: #a31515; font-weight: bold; }
"""


@dataclass(frozen=True)
class Figure:
    """A PNG image with its caption."""

    png: bytes
    caption: str
    alt: str = "figure"


@dataclass
class Section:
    """A report section: paragraphs, tables and figures, shown in that order.

    ``tables`` maps a table title to (header, rows); cells are converted with ``str`` (floats
    with 4 significant digits). ``html_paragraphs`` are trusted HTML written by pbdkit itself
    (e.g. a <video> tag); ``paragraphs`` are escaped.
    """

    title: str
    paragraphs: Sequence[str] = ()
    tables: Mapping[str, tuple[Sequence[str], Sequence[Sequence[object]]]] = field(
        default_factory=dict
    )
    figures: Sequence[Figure] = ()
    html_paragraphs: Sequence[str] = ()
    anchor: str | None = None


def _cell(value: object) -> tuple[str, bool]:
    if isinstance(value, bool):
        return ('<span class="ok">yes</span>' if value else '<span class="fail">no</span>'), False
    if isinstance(value, float):
        return f"{value:.4g}", True
    if isinstance(value, int):
        return str(value), True
    return html.escape(str(value)), False


def render_report(title: str, sections: Sequence[Section], *, intro: str = "") -> str:
    """The report as an HTML string."""
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title>",
        f"<style>{_STYLE}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
    ]
    if intro:
        out.append(f"<p>{html.escape(intro)}</p>")
    out.append("<nav><ul>")
    for i, sec in enumerate(sections):
        anchor = sec.anchor or f"s{i}"
        out.append(f'<li><a href="#{anchor}">{html.escape(sec.title)}</a></li>')
    out.append("</ul></nav>")
    for i, sec in enumerate(sections):
        anchor = sec.anchor or f"s{i}"
        out.append(f'<section id="{anchor}"><h2>{html.escape(sec.title)}</h2>')
        out.extend(f"<p>{html.escape(p)}</p>" for p in sec.paragraphs)
        out.extend(sec.html_paragraphs)
        for caption, (header, rows) in sec.tables.items():
            out.append(f"<table><caption>{html.escape(caption)}</caption><tr>")
            out.extend(f"<th>{html.escape(str(h))}</th>" for h in header)
            out.append("</tr>")
            for row in rows:
                out.append("<tr>")
                for value in row:
                    text, numeric = _cell(value)
                    out.append(f'<td class="num">{text}</td>' if numeric else f"<td>{text}</td>")
                out.append("</tr>")
            out.append("</table>")
        for fig in sec.figures:
            data = base64.b64encode(fig.png).decode("ascii")
            out.append(
                f'<figure><img alt="{html.escape(fig.alt)}" src="data:image/png;base64,{data}">'
                f"<figcaption>{html.escape(fig.caption)}</figcaption></figure>"
            )
        out.append("</section>")
    out.append("</body></html>")
    return "\n".join(out)


def write_report(
    path: str | os.PathLike[str], title: str, sections: Sequence[Section], *, intro: str = ""
) -> None:
    """Render the report and write it atomically to ``path``."""
    atomic_write_bytes(path, render_report(title, sections, intro=intro).encode("utf-8"))
