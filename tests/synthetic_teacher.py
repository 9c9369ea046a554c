"""The synthetic teacher of the skill and controller tests: a glass reached on the Katana.

It rests, reaches the glass mid-motion and holds the hand on it (a grasp) with postures that
differ across demonstrations (the arm is redundant for a position), then leaves for an end
posture and rests; start and end postures are nearly the same in every demonstration. So the
task constraint is tight while grasping and the joint constraint is tight at the start and the
end. Shared by ``tests/conftest.py`` (the ``demos`` and ``skill`` fixtures) and the test modules
that build variants of it (other seeds, a coaster).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pbdkit.data._demonstration import Demonstration
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill

Float = NDArray[np.float64]

N_STEPS = 200
# Phases of the synthetic task (fractions of the duration): rest, approach, hold on the glass,
# leave, rest.
REST_END, REACH_END, HOLD_END, LEAVE_END = 0.1, 0.35, 0.55, 0.85
REACH_STEP = round(0.45 * (N_STEPS - 1))  # middle of the hold
Q_START = np.array([0.0, 1.2, -1.8, -1.4, 0.0])
Q_REACH = np.array([0.5, 0.8, -1.8, -1.0, 0.0])
Q_END = np.array([-0.6, 1.0, -1.5, -1.2, 0.0])
COASTER_OFFSET = np.array([0.0, 0.0, 0.08])  # the hand ends 8 cm above the coaster


def ik(robot: Robot, target: Float, preferred: Float, iters: int = 300) -> Float:
    """Damped least squares with a null-space pull toward ``preferred`` (test data only)."""
    q = preferred.copy()
    for _ in range(iters):
        x, jac = robot.fk_jacobian(q)
        jp = jac.T @ np.linalg.inv(jac @ jac.T + 1e-4 * np.eye(3))
        q = q + jp @ (target - x) + 0.1 * (np.eye(robot.n_joints) - jp @ jac) @ (preferred - q)
        q = np.clip(q, robot.lower, robot.upper)
    assert np.linalg.norm(robot.fk(q) - target) < 1e-3
    return q


def min_jerk(s: Float) -> Float:
    """The minimum-jerk profile from 0 to 1 over ``s`` in [0, 1]."""
    return np.asarray(10 * s**3 - 15 * s**4 + 6 * s**5)


def synthetic_demos(
    robot: Robot, rng: np.random.Generator, n_demos: int = 5, coaster: bool = False
) -> list[Demonstration]:
    """``n_demos`` demonstrations of the task (with a coaster to put the glass on if
    ``coaster``), irregularly sampled over 4-6 s; each draws from ``rng`` in turn."""
    glass_nominal = robot.fk(Q_REACH)
    demos = []
    for _ in range(n_demos):
        glass = glass_nominal + np.r_[rng.uniform(-0.06, 0.06, 2), 0.0]
        # Different elbow/wrist postures for the same hand position (redundancy).
        q_reach = ik(robot, glass, Q_REACH + np.r_[0.0, rng.normal(0.0, 0.25, 3), 0.0])
        q_start = Q_START + rng.normal(0.0, 0.02, 5)
        objects = {"glass": glass}
        if coaster:
            place = robot.fk(Q_END) + np.r_[rng.uniform(-0.06, 0.06, 2), 0.0]
            q_end = ik(robot, place, Q_END + np.r_[0.0, rng.normal(0.0, 0.2, 3), 0.0])
            objects["coaster"] = place - COASTER_OFFSET
        else:
            q_end = Q_END + rng.normal(0.0, 0.02, 5)
        n = int(rng.integers(300, 600))
        t = np.sort(rng.uniform(0.0, 1.0, n))
        t = np.unique(np.r_[0.0, t, 1.0]) * rng.uniform(4.0, 6.0)  # seconds, irregular
        s = (t / t[-1])[:, None]
        approach = q_start + (q_reach - q_start) * min_jerk(
            np.clip((s - REST_END) / (REACH_END - REST_END), 0, 1)
        )
        leave = q_reach + (q_end - q_reach) * min_jerk(
            np.clip((s - HOLD_END) / (LEAVE_END - HOLD_END), 0, 1)
        )
        q = np.where(s < REACH_END, approach, np.where(s < HOLD_END, q_reach, leave))
        gripper = (s[:, 0] > 0.45).astype(float)  # closes on the glass
        demos.append(Demonstration(t, q, objects, gripper))
    return demos


def unseen_glass(demos: list[Demonstration]) -> tuple[Float, float]:
    """A glass position no demonstration had, and its distance to their mean (m)."""
    mean = np.mean([d.objects["glass"] for d in demos], axis=0)
    new = mean + np.array([0.05, -0.07, 0.0])
    return new, float(np.linalg.norm(new - mean))


def bare_skill(skill: Skill) -> Skill:
    """``skill`` built by hand from its parts, without what it was learned from (its
    demonstrations, options and sample counts): as a skill file of version 1 or 2 loads."""
    return Skill(
        skill.robot,
        skill.gmms,
        n_steps=skill.n_steps,
        object_names=skill.object_names,
        has_gripper=skill.has_gripper,
        reach=skill.reach,
        duration=skill.duration,
        rotation_base=skill.rotation_base,
        aligned=skill.aligned_,
        calibration=skill.calibration_,
    )
