"""The motion limits a skill's reproduction or controller runs within (private)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..motion._limits import LimitSpec, MotionLimits, defaults_where_declared

__all__ = ["run_limits", "skill_limits"]


def run_limits(
    robot: Any,
    n_joints: int,
    dt: float,
    velocity: LimitSpec,
    acceleration: LimitSpec,
    jerk: LimitSpec,
) -> tuple[float, MotionLimits | None]:
    """The step duration ``dt`` (s; NaN: unknown) and the limits of a run with these
    arguments of :meth:`pbdkit.Skill.reproduce` (None: none apply). An explicit limit needs
    a known step duration."""
    limits = MotionLimits.from_robot(
        robot, n_joints, velocity=velocity, acceleration=acceleration, jerk=jerk
    )
    if not np.isfinite(dt):
        explicit = [
            name
            for name, spec in (
                ("velocity_limit", velocity),
                ("acceleration_limit", acceleration),
                ("jerk_limit", jerk),
            )
            if spec is not None and not (isinstance(spec, str) and spec == "robot")
        ]
        if explicit:
            raise ValueError(
                f"{explicit[0]} is per second and needs the duration of a step; it is "
                "unknown (the skill has no known duration): pass None, or bound the steps "
                "in rad with max_step"
            )
        return dt, None
    if not limits.any:
        return dt, None
    return dt, defaults_where_declared(limits, robot.joint_names, velocity, acceleration, jerk)


def skill_limits(
    skill: Any, velocity: LimitSpec, acceleration: LimitSpec, jerk: LimitSpec
) -> tuple[float, MotionLimits | None]:
    """:func:`run_limits` of a skill (its robot, joints and step duration): the step duration
    and the limits its reproduction or controller runs within (None: none apply)."""
    return run_limits(skill.robot, skill.n_joints, skill.step_seconds, velocity, acceleration, jerk)
