"""A self-contained HTML report: text, tables and PNG figures embedded as base64.

The report has no external asset (no script, no stylesheet, no image file), so it can be mailed
or archived as one file. It is written atomically.

:func:`orientation_section` is the report's section on oriented constraints (issue 23): which
objects a skill learned with orientation, and each controller's distance and angle to what
they expect. A skill of positions only (the paper's tasks) has none, so its report is as it was.
"""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .._io import atomic_write_bytes

if TYPE_CHECKING:
    from ..reproduction._result import ReproductionResult
    from ..skill._skill import Skill

__all__ = [
    "Figure",
    "Section",
    "closest_approach",
    "orientation_section",
    "render_report",
    "write_report",
]

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


def closest_approach(result: ReproductionResult) -> dict[str, tuple[float, float | None]]:
    """Per object, how close a reproduction's hand came to where the object's constraint expects
    it: the smallest distance (mm) and, for an oriented object, the angle (degrees) between the
    hand's orientation and the one the constraint expects at that same sample (None for an
    object of a position-only constraint)."""
    out: dict[str, tuple[float, float | None]] = {}
    for name, err in result.task_errors.items():
        j = int(np.argmin(err))
        angle = result.orientation_errors.get(name)
        out[name] = (
            float(1000 * err[j]),
            None if angle is None else float(np.degrees(angle[j])),
        )
    return out


def orientation_section(
    skill: Skill,
    results: Mapping[str, ReproductionResult],
    *,
    anchor: str = "orientation",
) -> Section | None:
    """The report's section on a skill's oriented constraints, or None if it has none.

    Two tables: per object, what its constraint holds (the hand's position and orientation in
    the object's frame, or its position only) and how tight the constraint gets (the smallest
    spread over time: sqrt of the trace of the position covariance in mm, of the orientation
    covariance in degrees); per controller in ``results`` (name -> reproduction), the closest
    approach to each object (:func:`closest_approach`: mm, and degrees for an oriented one).

    A skill of positions only (:attr:`pbdkit.Skill.oriented` empty: the paper's tasks) gets
    None, so that its report is unchanged.
    """
    oriented = list(skill.oriented)
    if not oriented:
        return None
    c = skill.constraints()
    rows: list[list[object]] = []
    for name in skill.object_names:
        cov = c.task_cov[name]
        pos = 1000 * np.sqrt(np.trace(cov[:, :3, :3], axis1=1, axis2=2))
        if name in oriented:
            rot = np.degrees(np.sqrt(np.trace(cov[:, 3:, 3:], axis1=1, axis2=2)))
            what = "position and orientation, in the object's frame"
            rows.append([name, what, float(pos.min()), float(rot.min()), int(np.argmin(rot))])
        else:
            rows.append([name, "position relative to the object", float(pos.min()), "-", "-"])
    names = list(skill.object_names)
    header = ["controller"]
    for name in names:
        header.append(f"{name} (mm)")
        if name in oriented:
            header.append(f"{name} (deg)")
    errors: list[list[object]] = []
    for controller, res in results.items():
        approach = closest_approach(res)
        row: list[object] = [controller]
        for name in names:
            mm, deg = approach.get(name, (float("nan"), None))
            row.append(mm)
            if name in oriented:
                row.append("-" if deg is None else deg)
        errors.append(row)
    flat = [k for k in names if k not in oriented]
    paragraphs = [
        f"Learned with orientation: {', '.join(oriented)}. For each, the skill learned the "
        "hand's position in the object's frame, R^T (x - p), and its orientation relative to "
        "the object as a rotation vector r in the tangent space at the demonstrations' mean "
        "relative orientation M (R^T R_hand = exp([r]x) M: errors on the left, in the object's "
        "axes). Reproduction maps each constraint to the world with the object's new pose.",
        "Angles are the angle between the hand's orientation and the one the constraint "
        "expects, |log(R_hand R_target^T)|, in degrees; distances from the hand to where the "
        "constraint expects it, in mm, at the sample where the hand comes closest.",
    ]
    if flat:
        paragraphs.append(f"Position only: {', '.join(flat)}.")
    return Section(
        "Orientation: the hand's pose relative to the objects",
        paragraphs=paragraphs,
        tables={
            "Constraints per object (spread at its tightest: sqrt of the covariance trace)": (
                [
                    "object",
                    "constrains",
                    "position spread (mm)",
                    "orientation spread (deg)",
                    "tightest orientation at step",
                ],
                rows,
            ),
            "Closest approach per controller (mm; deg: the angle there)": (header, errors),
        },
        anchor=anchor,
    )
