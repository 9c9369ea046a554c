"""The files the ``pbdkit`` command reads and writes: demonstrations (an .npz archive or ROS
bags, ``learn``) and a reproduction (an .npz archive and its trajectory bag, ``reproduce``).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ._cli_output import fail

if TYPE_CHECKING:
    from ..data._demonstration import Demonstration
    from ..reproduction._result import ReproductionResult
    from ..robots._robot import Robot
    from ..skill._skill import Skill

__all__ = [
    "BagTiming",
    "bag_extras",
    "bag_timing",
    "load_demos",
    "timing_text",
]


def load_demos(
    paths: list[Path],
    arm: Robot,
    sources: dict[str, str | np.ndarray],
    joint_topic: str | None,
    gripper_topic: str | None,
    start: float | None,
    end: float | None,
) -> list[Demonstration]:
    """The demonstrations of `learn`: an .npz file's, or one per bag (errors name the bag)."""
    if len(paths) == 1 and paths[0].suffix == ".npz":
        from ..data._demonstration import load_demonstrations

        return load_demonstrations(paths[0])
    from ..data._bag_read import read_bag

    items = []
    for path in paths:
        try:
            items.append(
                read_bag(
                    path,
                    robot=arm,
                    joint_topic=joint_topic or "/joint_states",
                    objects=sources,
                    gripper_topic=gripper_topic,
                    start=start,
                    end=end,
                )
            )
        except ValueError as exc:
            text = str(exc)
            raise ValueError(text if str(path) in text else f"{path}: {text}") from exc
    return items


def timing_text(res: ReproductionResult) -> str:
    """What to say of a reproduction's timing ("" without the robot's limits)."""
    if res.times is None or res.lead_in is None:
        return ""
    lead = int(np.count_nonzero(res.lead_in))
    return (
        f", {lead} of them a lead-in from the start posture; {res.times[-1]:.2f} s within "
        f"the robot's limits, the skill's steps {res.stretch:.2f}x their demonstrated pace"
    )


class BagTiming(NamedTuple):
    """What the trajectory bag of `reproduce` needs besides the joints."""

    t: np.ndarray
    """Times (s) of the samples (:meth:`pbdkit.Skill.times`)."""
    joint_names: list[str]
    """The skill's robot's joint names."""


def bag_extras(skill: Skill, res: ReproductionResult) -> dict[str, Any]:
    """The gripper, velocities and accelerations of the trajectory bag of `reproduce`."""
    from ..motion._limits import MotionLimits, with_defaults

    declared = MotionLimits.from_robot(skill.robot, skill.n_joints)
    return {
        "gripper": res.gripper if skill.has_gripper else None,
        # Velocities and accelerations of the timing (None without limits: positions only).
        "velocities": res.velocities,
        "accelerations": res.accelerations if res.velocities is not None else None,
        # Checked against the limits it was timed within (none declared: the bag's check
        # refuses a jump).
        "limits": with_defaults(declared, warn=False) if declared.any else None,
    }


def bag_timing(skill: Skill, res: ReproductionResult, bag: Path) -> BagTiming:
    """Times (s, from :meth:`pbdkit.Skill.times`) and joint names (the skill's robot's) of the
    trajectory bag of `reproduce`, its whole content checked (nothing is written)."""
    from ..data import check_trajectory_bag

    names = [str(n) for n in skill.robot.joint_names]
    try:
        t = skill.times(res)
        check_trajectory_bag(t, res.joints, names, **bag_extras(skill, res))
    except ValueError as exc:
        fail(f"--bag {bag}: {exc}")
    return BagTiming(t, names)
