"""``pbdkit suggest``: where to put the objects for the next demonstration
(:meth:`pbdkit.Skill.suggest`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer
from rich.table import Table

from .._io import write_json
from .._rotations import as_pose, yaw_of
from .._validation import short
from ._cli_output import console, fail, reports_errors

if TYPE_CHECKING:
    from ..skill._suggest import Suggestion

__all__ = [
    "SuggestingTeacher",
    "default_ranges",
    "parse_range",
    "placement_text",
    "ranges_from_options",
    "suggest_command",
]


def parse_range(text: str) -> tuple[str, tuple[float, float], tuple[float, float], Any]:
    """``NAME=x0:x1,y0:y1[,yaw0:yaw1]`` (m, rad) -> (name, x, y, yaw or None)."""
    name, sep, rest = text.partition("=")
    parts = rest.split(",")
    if not sep or not name or len(parts) not in (2, 3):
        fail(f"--range must be NAME=x0:x1,y0:y1[,yaw0:yaw1], got {short(text)}")
    pairs = []
    for part in parts:
        lo, colon, hi = part.partition(":")
        try:
            a, b = float(lo), float(hi)
        except ValueError:
            fail(f"--range {short(name)}: {short(part)} is not lo:hi (numbers)")
        if not colon or not (math.isfinite(a) and math.isfinite(b)) or a > b:
            fail(f"--range {short(name)}: {short(part)} must be lo:hi, finite, lo <= hi")
        pairs.append((a, b))
    return name, pairs[0], pairs[1], pairs[2] if len(parts) == 3 else None


def ranges_from_options(skill: Any, parsed: list[Any]) -> dict[str, dict[str, Any]]:
    """``suggest``'s ranges from parsed --range options (:func:`parse_range`), each object at
    the height it was demonstrated at."""
    spec: dict[str, dict[str, Any]] = {}
    for name, x, y, yaw in parsed:
        if name not in skill.object_names:
            fail(f"--range names {short(name)}, not an object of the skill {skill.object_names}")
        z = float(np.mean([as_pose(d.objects[name])[0][2] for d in skill.demonstrations_]))
        spec[name] = {"low": (x[0], y[0], z), "high": (x[1], y[1], z), "yaw": yaw}
    return spec


@reports_errors
def suggest_command(
    skill_path: Annotated[Path, typer.Argument(metavar="SKILL", help="Skill file (.npz).")],
    ranges: Annotated[
        list[str],
        typer.Option(
            "--range",
            help="NAME=x0:x1,y0:y1[,yaw0:yaw1]: where NAME may be put, in the robot's base "
            "frame (m, rad; its height: where it was demonstrated). Repeat per object; an "
            "object without a range stays where it was first demonstrated.",
        ),
    ],
    n: Annotated[int, typer.Option("--n", help="How many placements (1..100).")] = 1,
    json_path: Annotated[
        Path | None,
        typer.Option("--json", help="Also write the suggestions here (JSON)."),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seeds the candidate placements.")] = 0,
) -> None:
    """Where to put the objects for the next demonstration: the placements, inside the
    ranges, where a demonstration would lower the skill's uncertainty over them most (the
    skill must keep its demonstrations: a skill file of version 3)."""
    from ..skill._skill import Skill

    parsed = [parse_range(r) for r in ranges]
    skill = Skill.load(skill_path)
    if skill.demonstrations_ is None:
        fail(
            f"{skill_path} does not keep its demonstrations (a skill file of version 1 or 2): "
            "learn it again with pbdkit learn"
        )
    spec = ranges_from_options(skill, parsed)
    found = skill.suggest(spec, n=n, seed=seed)
    if not found:
        fail("no placement inside the ranges is within the arm's reach")
    table = Table(title=f"where to demonstrate next ({skill_path.name})")
    table.add_column("#")
    for name in skill.object_names:
        table.add_column(name)
    table.add_column("uncertainty")
    rows = []
    for i, s in enumerate(found, 1):
        cells = []
        row: dict[str, Any] = {"score": s.score, "objects": {}}
        for name in skill.object_names:
            coords, yaw = _where(s.objects[name])
            cells.append(coords if yaw is None else f"{coords}, yaw {yaw:.0f} deg")
            row["objects"][name] = np.asarray(s.objects[name]).tolist()
        table.add_row(str(i), *cells, f"{s.score:.2f}")
        rows.append(row)
    console.print(table)
    if json_path is not None:
        write_json(json_path, {"skill": str(skill_path), "suggestions": rows})
        console.print(f"wrote {json_path}")


def default_ranges(skill: Any) -> dict[str, dict[str, Any]]:
    """Each object of the skill where it may be put when no --range says: its demonstrated
    box (x, y; and yaw for a pose) widened to twice its half-width on each side, at least 5 cm
    (and 30 degrees) wide, at the height it was demonstrated at."""
    out: dict[str, dict[str, Any]] = {}
    for name in skill.object_names:
        poses = [as_pose(d.objects[name]) for d in skill.demonstrations_]
        p = np.array([position for position, _ in poses])
        low, high = p.min(axis=0), p.max(axis=0)
        centre, half = 0.5 * (low + high), np.maximum(0.5 * (high - low), 0.0125)
        half[2] = 0.0
        yaw = None
        if poses[0][1] is not None:
            yaws = np.unwrap([yaw_of(r) for _, r in poses if r is not None])
            yc, yh = 0.5 * (yaws.min() + yaws.max()), max(0.5 * np.ptp(yaws), math.radians(7.5))
            yaw = (float(yc - 2 * yh), float(yc + 2 * yh))
        out[name] = {"low": centre - 2 * half, "high": centre + 2 * half, "yaw": yaw}
    return out


def placement_text(objects: Mapping[str, Any], names: Sequence[str]) -> str:
    """One line: where each object goes (m; a pose's yaw in degrees)."""
    parts = []
    for name in names:
        coords, yaw = _where(objects[name])
        parts.append(f"{name} at ({coords}) m" + ("" if yaw is None else f", yaw {yaw:.0f} deg"))
    return "; ".join(parts)


def _where(value: Any) -> tuple[str, float | None]:
    """An object's position as text (m), and a pose's yaw (degrees; None for a position)."""
    v = np.asarray(value)
    posed = v.shape == (4, 4)
    coords = ", ".join(f"{x:.3f}" for x in (v[:3, 3] if posed else v))
    return coords, (math.degrees(yaw_of(v)) if posed else None)


class SuggestingTeacher:
    """``pbdkit ros record --suggest SKILL``: before each take, where to put the objects (the
    skill's first suggestion inside ``ranges``); after each, the skill updated with the take
    and written back to ``path`` (atomically), so that the next suggestion knows it."""

    def __init__(self, path: Path, ranges: dict[str, dict[str, Any]] | None = None) -> None:
        from ..skill._skill import Skill

        self.path = path
        self.skill = Skill.load(path)
        if self.skill.demonstrations_ is None:
            fail(
                f"{path} does not keep its demonstrations (a skill file of version 1 or 2): "
                "learn it again with pbdkit learn"
            )
        self.taught = self.skill.demonstrations_[0]
        self.ranges = default_ranges(self.skill) if ranges is None else ranges

    @property
    def posed(self) -> list[str]:
        """The objects its demonstrations hold as poses: the takes must hold them so too."""
        from ..data._placement import is_pose

        return [k for k in self.taught.object_names if is_pose(self.taught.objects[k])]

    def check_takes(self, joint_names: list[str], sources: dict[str, Any], gripper: bool) -> None:
        """Refuse, in one line (exit 2), takes that :meth:`pbdkit.Skill.update` would refuse
        after the first one: of another arm (``joint_names``, the robot's), of other objects
        (``sources``: --object NAME=SOURCE), fixed coordinates of a position for an object
        it holds as a pose or the other way round, a gripper (``gripper``: --gripper-joint)
        where it has none or none where it has one."""
        skill, path = self.skill, self.path
        if list(skill.robot.joint_names) != list(joint_names):
            fail(
                f"--suggest {path} is a skill of the joints {list(skill.robot.joint_names)}, "
                f"not of --robot's {list(joint_names)}"
            )
        if set(self.taught.object_names) != set(sources):
            fail(
                f"--suggest {path}'s demonstrations have objects "
                f"{list(self.taught.object_names)}; record them (--object NAME=SOURCE for each)"
            )
        if skill.has_gripper != gripper:
            with_, fix = (
                ("with", "give --gripper-joint NAME:OPEN:CLOSED")
                if skill.has_gripper
                else ("without", "leave out --gripper-joint")
            )
            fail(f"--suggest {path} was learned {with_} a gripper: {fix}")
        posed = self.posed
        for name, source in sources.items():
            if not isinstance(source, str) and (np.size(source) == 7) != (name in posed):
                kind, give = (
                    ("pose", "x,y,z,qw,qx,qy,qz") if name in posed else ("position", "x,y,z")
                )
                fail(f"--object {name}: {path}'s demonstrations hold it as a {kind}: give {give}")

    def suggest(self) -> list[Suggestion]:
        """The next take's placement (a list of one, or none where nothing inside the ranges
        is within reach)."""
        return self.skill.suggest(self.ranges, n=1)

    def next_text(self, found: list[Suggestion] | None = None) -> str:
        """Where the next take's objects go (``found``: :meth:`suggest`'s, made here if
        None)."""
        found = self.suggest() if found is None else found
        if not found:
            return "no placement inside the ranges is within reach: place the objects yourself"
        where = placement_text(found[0].objects, self.skill.object_names)
        return f"put {where} (uncertainty {found[0].score:.2f})"

    def took(self, demo: Any) -> str:
        """Learn a take at once and save the skill; what to say."""
        self.skill = self.skill.update(demo)
        self.skill.save(self.path)
        n = len(self.skill.demonstrations_ or [])
        return f"{self.path} updated: learned from {n} demonstrations"
