"""Teaching in simulation where the skill asks (private; :doc:`/active`): the wide ranges a
teacher may place the objects in, a demonstration at a given placement, and the placements no
teacher fixes.

- **The wide ranges** are the study's wide grids' (:func:`pbdkit.apps._study.grid_placements`):
  each moving object's range widened to twice its half-width on each side of its centre, in x, y
  and yaw; its height as demonstrated.
- **The placements no teacher fixes**: the wide grid's points where a skill learned from
  :data:`SPREAD_DEMOS` demonstrations spread over the wide ranges still fails (the glass stood
  on the shelf's edge falls before it is grasped). Success over the grid is measured without
  them, and they are listed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..data._demonstration import Demonstration
from ..robots import katana
from ..skill._skill import Skill
from ._task_skill import TaskSkill, constrained_objects
from ._tasks import PlacementRange, TaskSpec, yaw_pose
from ._teacher import teach_one

__all__ = [
    "SPREAD_DEMOS",
    "spread_placements",
    "task_skill",
    "teach_at",
    "wide_ranges",
]

Float = NDArray[np.float64]

#: Demonstrations spread over the wide ranges of the skill that finds the placements no teacher
#: fixes.
SPREAD_DEMOS = 20


def wide_ranges(spec: TaskSpec) -> dict[str, PlacementRange]:
    """Each moving object's range widened to twice its half-width on each side (x, y, yaw)."""
    out = {}
    for name in spec.tracked_objects:
        r = spec.ranges[name]
        c, h = r.center, 0.5 * (r.high - r.low)
        low, high = c - 2 * h, c + 2 * h
        yaw = None
        if r.yaw is not None:
            yc, yh = 0.5 * (r.yaw[0] + r.yaw[1]), 0.5 * (r.yaw[1] - r.yaw[0])
            yaw = (yc - 2 * yh, yc + 2 * yh)
        out[name] = PlacementRange(low, high, yaw)
    return out


def spread_placements(spec: TaskSpec, n: int, seed: int) -> list[dict[str, Float]]:
    """``n`` placements of every object spread over the wide ranges (a scrambled Halton
    sequence; fixed objects at their place)."""
    from scipy.stats import qmc

    wide = wide_ranges(spec)
    width = sum(3 + (r.yaw is not None) for r in wide.values())
    u = qmc.Halton(d=width, scramble=True, seed=seed).random(n)
    out = []
    for row in u:
        objects = spec.nominal_objects()
        at = 0
        for name, r in wide.items():
            p = r.low + row[at : at + 3] * (r.high - r.low)
            at += 3
            if r.yaw is None:
                objects[name] = p
            else:
                objects[name] = yaw_pose(p, r.yaw[0] + row[at] * (r.yaw[1] - r.yaw[0]))
                at += 1
        out.append(objects)
    return out


def teach_at(
    spec: TaskSpec, placements: Sequence[Mapping[str, Any]], seed: int
) -> list[Demonstration | None]:
    """The simulated teacher's demonstration at each placement (None where it cannot show the
    task there: no path within the arm's reach)."""
    rng = np.random.default_rng([seed, 39])
    robot = katana()
    out: list[Demonstration | None] = []
    for objects in placements:
        try:
            out.append(teach_one(spec, {k: np.asarray(v) for k, v in objects.items()}, rng, robot))
        except ValueError:
            out.append(None)
    return out


def task_skill(spec: TaskSpec, demos: list[Demonstration], skill: Skill | None = None) -> TaskSkill:
    """The task's skill of these demonstrations (learned as :func:`learn_task` learns it, or
    ``skill`` as given)."""
    if skill is None:
        names = constrained_objects(spec)
        skill = Skill.learn(demos, katana(), task_objects=names)
    return TaskSkill(task=spec, demos=demos, skill=skill, learn_seconds=0.0, teach_seconds=0.0)
