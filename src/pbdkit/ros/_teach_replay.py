"""The simulated teacher replayed in real time (:class:`TeacherReplay`, ``pbdkit ros sim --teach``):
what a recorder on the graph sees while a person guides the arm through a few demonstrations.

Take i (i = 0 .. takes - 1) puts the objects at placement i of ``pbdkit evaluate``'s stream
(:func:`placement_objects`) and the arm at the start of the teacher's demonstration
(:func:`pbdkit.sim._teacher.teach_one`, drawn from ``np.random.default_rng([seed, 3, i])``);
the arm rests :data:`REST_BEFORE` s, moves through the demonstration at its own pace, and rests
:data:`REST_AFTER` s before the next take. After the last take it rests where it ended.

On the Katana the teacher's demonstrations last 16-20 s whatever ``speed``: they are slowed to
keep every joint below 0.9 of its velocity limit
(:func:`~pbdkit.sim._teacher.trajectory_from_via_points`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .._validation import check_int, check_positive_float
from ..data._demonstration import Demonstration

if TYPE_CHECKING:  # the simulator (MuJoCo) is imported where a world is built
    from ..sim._tasks import TaskSpec

__all__ = ["REST_AFTER", "REST_BEFORE", "Take", "TeacherReplay", "placement_objects"]

Float = NDArray[np.float64]

#: Seconds at rest at a take's first posture, its objects in place, before the arm moves.
REST_BEFORE = 1.5
#: Seconds at rest at a take's last posture before the next take.
REST_AFTER = 2.5


def placement_objects(spec: TaskSpec, seed: int, index: int) -> dict[str, Float]:
    """Placement ``index`` of ``pbdkit evaluate --seed SEED``'s stream: its trial ``index``.

    ``evaluate`` draws its placements as ``spec.sample_objects(rng)``, ``trials`` times, from
    ``rng = np.random.default_rng([seed, 1])``; this is the draw number ``index`` (from 0).

    Parameters
    ----------
    spec : TaskSpec
        The task (:func:`pbdkit.sim.get_task`).
    seed, index : int
        >= 0.

    Returns
    -------
    objects : dict str -> ndarray, shape (3,) or (4, 4)
        Every object of the task.
    """
    seed = check_int(seed, "seed", minimum=0)
    index = check_int(index, "placement", minimum=0)
    rng = np.random.default_rng([seed, 1])
    objects = spec.sample_objects(rng)
    for _ in range(index):
        objects = spec.sample_objects(rng)
    return objects


@dataclass(frozen=True)
class Take:
    """One demonstration of the replay.

    Attributes
    ----------
    index : int
        From 0; the placement of ``evaluate``'s stream it uses.
    objects : dict str -> ndarray, shape (3,) or (4, 4)
        The placement.
    demo : Demonstration
        The teacher's (joints at 100 Hz, gripper 1 while closed).
    start : float
        World time (s) the take begins: objects placed, the arm at the demonstration's first
        posture.
    """

    index: int
    objects: dict[str, Float]
    demo: Demonstration
    start: float

    @property
    def motion_start(self) -> float:
        """World time (s) the arm starts to move."""
        return self.start + REST_BEFORE

    @property
    def motion_end(self) -> float:
        """World time (s) the demonstration ends."""
        return self.motion_start + float(self.demo.t[-1] - self.demo.t[0])

    @property
    def end(self) -> float:
        """World time (s) the take ends (the next one begins)."""
        return self.motion_end + REST_AFTER

    def command(self, t: float) -> tuple[Float, Float, bool]:
        """The servo targets at world time ``t``: joint angles (n,) and velocities (n,), the
        demonstration's joints interpolated linearly on its time stamps (the segment's slope as
        velocity), at rest before and after; and whether the gripper is closed (gripper > 0.5
        at the last sample at or before ``t``)."""
        demo = self.demo
        s = t - self.motion_start + float(demo.t[0])
        times, joints = demo.t, demo.joints
        gripper = np.zeros(len(times)) if demo.gripper is None else demo.gripper
        if s <= times[0]:
            return joints[0].copy(), np.zeros(joints.shape[1]), bool(gripper[0] > 0.5)
        if s >= times[-1]:
            return joints[-1].copy(), np.zeros(joints.shape[1]), bool(gripper[-1] > 0.5)
        k = int(np.searchsorted(times, s, side="right")) - 1
        h = float(times[k + 1] - times[k])
        slope = (joints[k + 1] - joints[k]) / h
        return joints[k] + slope * (s - times[k]), slope, bool(gripper[k] > 0.5)

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: the placement and the schedule (world seconds)."""
        gripper = self.demo.gripper
        closed = None if gripper is None or not np.any(gripper > 0.5) else gripper > 0.5
        grasp = None if closed is None else float(self.demo.t[int(np.argmax(closed))])
        return {
            "take": self.index,
            "placement": {k: np.asarray(v).tolist() for k, v in self.objects.items()},
            "start_s": self.start,
            "motion_start_s": self.motion_start,
            "motion_end_s": self.motion_end,
            "end_s": self.end,
            "grasp_s": None if grasp is None else self.motion_start + grasp - float(self.demo.t[0]),
        }


class TeacherReplay:
    """The schedule of ``takes`` demonstrations of the teacher (module docstring).

    Parameters
    ----------
    spec : TaskSpec
    seed : int
        The placements' stream (:func:`placement_objects`) and the teacher's
        (``default_rng([seed, 3, i])`` for take i).
    takes : int
        >= 1.
    speed : float
        The teacher's speed (:func:`pbdkit.sim._teacher.teach_one`), > 0.
    """

    def __init__(self, spec: TaskSpec, seed: int, takes: int, speed: float = 1.0) -> None:
        from ..robots import katana
        from ..sim._teacher import teach_one

        takes = check_int(takes, "takes", minimum=1)
        speed = check_positive_float(speed, "teach_speed")
        robot = katana()
        out: list[Take] = []
        start = 0.0
        for i in range(takes):
            objects = placement_objects(spec, seed, i)
            rng = np.random.default_rng([seed, 3, i])
            demo = teach_one(spec, objects, rng, robot, speed=speed)
            out.append(Take(i, objects, demo, start))
            start = out[-1].end
        self.takes: Sequence[Take] = tuple(out)

    @property
    def end(self) -> float:
        """World time (s) the last take ends (the replay is done)."""
        return self.takes[-1].end

    def take_at(self, t: float) -> int:
        """The index of the take in force at world time ``t`` (the last one after the end)."""
        for take in self.takes:
            if t < take.end:
                return take.index
        return self.takes[-1].index
