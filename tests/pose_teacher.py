"""A small pose teacher for tests: a Panda grasps a mug by its handle, the hand turning with
the mug (its yaw about the vertical), through start -> above the handle -> the handle -> lift.

Every posture comes from inverse kinematics on the full 6-D pose, so the hand's pose relative
to the mug at the grasp is the same in every demonstration: GRASP_LOCAL and the hand pointing
down, turned with the mug.
"""

from __future__ import annotations

import numpy as np

import pbdkit
from pbdkit._rotations import exp_map, log3

START = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])  # Panda "ready"
DOWN = np.diag([1.0, -1.0, -1.0])  # the hand's z axis pointing down
GRASP_LOCAL = np.array([0.09, 0.0, 0.05])  # the handle, in the mug's frame (m)
LIFT = 0.1  # m


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def mug_pose(yaw: float, x: float, y: float) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rot_z(yaw)
    out[:3, 3] = (x, y, 0.0)
    return out


def grasp_pose(mug: np.ndarray) -> np.ndarray:
    """The hand's pose at the grasp: over the handle, pointing down, turned with the mug."""
    out = np.eye(4)
    out[:3, :3] = mug[:3, :3] @ rot_z(np.pi / 2) @ DOWN
    out[:3, 3] = mug[:3, 3] + mug[:3, :3] @ GRASP_LOCAL
    return out


def ik(robot: pbdkit.Robot, target: np.ndarray, q: np.ndarray) -> np.ndarray:
    for _ in range(100):
        x, rot, jac = robot.fk_pose_jacobian_unchecked(q)
        err = np.r_[target[:3, 3] - x, log3(target[:3, :3] @ rot.T)]
        if np.linalg.norm(err) < 1e-10:
            break
        q = np.clip(
            q + jac.T @ np.linalg.solve(jac @ jac.T + 1e-8 * np.eye(6), err),
            robot.lower,
            robot.upper,
        )
    return q


def _smooth(n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def demonstration(
    robot: pbdkit.Robot, rng: np.random.Generator, yaw: float, n: int = 60
) -> tuple[pbdkit.Demonstration, np.ndarray]:
    """One demonstration for a mug at ``yaw`` (rad) and a random place; returns it and the
    mug's pose."""
    mug = mug_pose(yaw, rng.uniform(0.45, 0.55), rng.uniform(-0.1, 0.1))
    grasp = grasp_pose(mug)
    above = grasp.copy()
    above[2, 3] += 0.12
    q = START + rng.normal(0.0, 0.03, 7)
    x0, r0, _ = robot.fk_pose_jacobian_unchecked(q)
    turn = log3(above[:3, :3] @ r0.T)
    n1, n2 = n // 2, n // 4
    n3 = n - n1 - n2
    qs = [q]
    for s in _smooth(n1)[1:]:
        target = np.eye(4)
        target[:3, 3] = x0 + (above[:3, 3] - x0) * s
        target[:3, :3] = exp_map(turn * s) @ r0
        q = ik(robot, target, q)
        qs.append(q)
    for s in _smooth(n2 + 1)[1:]:
        target = above.copy()
        target[:3, 3] += (grasp[:3, 3] - above[:3, 3]) * s
        q = ik(robot, target, q)
        qs.append(q)
    for s in _smooth(n3 + 1)[1:]:
        target = grasp.copy()
        target[2, 3] += LIFT * s
        q = ik(robot, target, q)
        qs.append(q)
    joints = np.array(qs)
    t = np.linspace(0.0, rng.uniform(4.0, 5.0), joints.shape[0])
    closed = (np.arange(joints.shape[0]) >= n1 + n2 - 1).astype(float)
    return pbdkit.Demonstration(t, joints, {"mug": mug}, closed), mug


def demonstrations(
    robot: pbdkit.Robot, seed: int = 0, yaws_deg: tuple[float, ...] = (-80, -40, 0, 40, 80)
) -> list[pbdkit.Demonstration]:
    rng = np.random.default_rng(seed)
    return [demonstration(robot, rng, np.radians(y))[0] for y in yaws_deg]
