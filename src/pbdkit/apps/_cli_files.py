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
    from ..reproduction._probabilistic_ik import ReproductionResult
    from ..robots._robot import Robot
    from ..skill._skill import Skill

__all__ = [
    "REPRODUCTION_FORMAT",
    "REPRODUCTION_VERSION",
    "BagTiming",
    "bag_extras",
    "bag_timing",
    "load_demos",
    "reproduction_arrays",
]

#: The ``format`` and ``version`` of the file `pbdkit reproduce` writes (see its --out help).
#: Version 1 is the layout the command always wrote, now labelled; the keys of oriented
#: constraints (orientations, orientation_error_NAME) and task_error_NAME are optional within
#: it: a reader that looks keys up by name reads every file.
REPRODUCTION_FORMAT = "pbdkit-reproduction"
REPRODUCTION_VERSION = 1


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
    from ..data._bags import read_bag

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


def reproduction_arrays(res: ReproductionResult) -> tuple[dict[str, Any], str]:
    """The arrays of the file `reproduce` writes (its --out help lists them), and what to say
    of the timing ("" without the robot's limits)."""
    arrays = {
        "format": np.array(REPRODUCTION_FORMAT),
        "version": np.array(REPRODUCTION_VERSION, dtype=np.int64),
        "t": res.t,
        "joints": res.joints,
        "positions": res.positions,
        "gripper": res.gripper,
        "covariances": res.covariances,
    }
    arrays.update({f"influence_{k}": v for k, v in res.influence.items()})
    arrays.update({f"task_error_{k}": v for k, v in res.task_errors.items()})
    if res.orientations is not None:
        arrays["orientations"] = res.orientations
    arrays.update({f"orientation_error_{k}": v for k, v in res.orientation_errors.items()})
    timed = ""
    if res.times is not None and res.lead_in is not None:
        # Within the robot's motion limits: the timing (s), its derivatives, the lead-in.
        assert res.velocities is not None and res.accelerations is not None
        arrays.update(
            times=res.times,
            velocities=res.velocities,
            accelerations=res.accelerations,
            lead_in=res.lead_in,
        )
        lead = int(np.count_nonzero(res.lead_in))
        timed = (
            f", {lead} of them a lead-in from the start posture; {res.times[-1]:.2f} s within "
            f"the robot's limits, the skill's steps {res.stretch:.2f}x their demonstrated pace"
        )
    return arrays, timed


class BagTiming(NamedTuple):
    """What the trajectory bag of `reproduce` needs besides the joints."""

    t: np.ndarray
    """Times (s) of the samples (:meth:`pbdkit.Skill.times`)."""
    joint_names: list[str]
    """The skill's robot's joint names."""


def bag_extras(skill: Skill, res: ReproductionResult) -> dict[str, Any]:
    """The gripper, velocities and accelerations of the trajectory bag of `reproduce`."""
    return {
        "gripper": res.gripper if skill.has_gripper else None,
        # Velocities and accelerations of the timing (None without limits: positions only).
        "velocities": res.velocities,
        "accelerations": res.accelerations if res.velocities is not None else None,
    }


def bag_timing(skill: Skill, res: ReproductionResult, bag: Path) -> BagTiming:
    """Times (s, from :meth:`pbdkit.Skill.times`) and joint names (the skill's robot's) of the
    trajectory bag of `reproduce`, its whole content checked (nothing is written)."""
    from ..data._bags import _trajectory_messages

    names = [str(n) for n in skill.robot.joint_names]
    try:
        t = skill.times(res)
        _trajectory_messages(t, res.joints, names, **bag_extras(skill, res))
    except ValueError as exc:
        fail(f"--bag {bag}: {exc}")
    return BagTiming(t, names)
