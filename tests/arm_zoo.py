"""The arm zoo: third-party URDFs no one here wrote, and a reach-grasp-return skill on each.

Shared by ``tests/test_zoo.py`` and ``benchmarks/bench_zoo.py``. The URDFs are vendored from
example-robot-data 6.0.0 without their meshes (``data/arms/LICENSES.md``). Per arm: the tip
frame, a home posture (the maker's "ready" pose, or near it) and the centre of the table where
the box is put, chosen where the arm reaches a 40 cm square (20 cm for the SO-100, whose reach
is about 35 cm).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pbdkit import Robot, Skill
from pbdkit.datasets import ReachGraspReturn, reach_grasp_return
from pbdkit.motion._limits import MotionLimits, with_defaults

ARMS_DIR = Path(__file__).parent / "data" / "arms"
NARROW, WIDE = 0.15, 0.40  # side of the square of placements (m): 5-20 cm and 20-56 cm apart


@dataclass(frozen=True)
class Arm:
    """One arm of the zoo."""

    name: str
    urdf: str  # file under data/arms
    tip: str
    home: tuple[float, ...]
    center: tuple[float, float, float]
    spreads: tuple[float, ...]  # the placement squares it reaches

    def robot(self) -> Robot:
        """The arm from its URDF, with explicit acceleration and jerk limits: pbdkit's defaults
        for an arm without them (a = v / 0.25 s, j = a / 0.1 s), given as a joint_limits file
        would, so that no DefaultLimitsWarning fires (issue 35)."""
        bare = Robot.from_urdf(ARMS_DIR / self.urdf, tip=self.tip)
        limits = with_defaults(MotionLimits.from_robot(bare, bare.n_joints), warn=False)
        names = bare.joint_names
        table = {
            name: {
                "has_acceleration_limits": True,
                "max_acceleration": float(limits.acceleration[i]),
                "has_jerk_limits": True,
                "max_jerk": float(limits.jerk[i]),
            }
            for i, name in enumerate(names)
        }
        return Robot.from_urdf(
            ARMS_DIR / self.urdf, tip=self.tip, joint_limits={"joint_limits": table}
        )

    def demos(self, robot: Robot, spread: float, seed: int) -> ReachGraspReturn:
        return reach_grasp_return(robot, self.center, self.home, spread=spread, seed=seed)


ARMS = {
    a.name: a
    for a in (
        Arm("ur5", "ur5.urdf", "tool0", (0, -1.57, 1.57, -1.57, -1.57, 0), (0.45, 0.1, 0.05),
            (NARROW, WIDE)),
        Arm("panda", "panda.urdf", "panda_hand_tcp", (0, -0.785, 0, -2.356, 0, 1.571, 0.785),
            (0.5, 0.0, 0.1), (NARROW, WIDE)),
        Arm("kinova-j2s6s200", "kinova_j2s6s200.urdf", "j2s6s200_end_effector",
            (4.71, 2.84, 0.8, 4.2, 1.45, 1.32), (-0.45, 0.25, 0.1), (NARROW, WIDE)),
        Arm("xarm7", "xarm7.urdf", "link_eef", (0, 0, 0, 1.0, 0, 1.0, 0), (0.42, 0.0, 0.05),
            (NARROW, WIDE)),
        Arm("so100", "so100.urdf", "gripper", (0, 1.0, -1.0, 0.5, 0), (0.0, -0.22, 0.05),
            (NARROW,)),
    )
}  # fmt: skip


def grasp_errors(skill: Skill, robot: Robot, data: ReachGraspReturn, boxes: NDArray[np.float64],
                 **reproduce: object) -> NDArray[np.float64]:  # fmt: skip
    """The fused hand's distance to the box at the first gripper close (m), per placement."""
    out = []
    for box in boxes:
        res = skill.reproduce({data.object_name: box}, **reproduce)  # type: ignore[arg-type]
        closing = res.gripper & ~res.lead_in
        i = int(np.argmax(closing))
        assert closing[i], "the reproduction never closes the gripper"
        out.append(float(np.linalg.norm(robot.fk(res.joints[i]) - box)))
    return np.array(out)
