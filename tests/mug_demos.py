"""Demonstrations of a Panda grasping a mug by its handle, the mug at a random yaw: a small
subject with objects given as poses (issue 23), for the figure, report and command-line tests.

The teacher moves the hand, through damped least-squares inverse kinematics, above the handle
(turned with the mug), down to it, closes the gripper and lifts. Few steps per demonstration, so
that learning stays fast.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pbdkit.learning.demonstration import Demonstration
from pbdkit.prob.rotations import exp_map, log3
from pbdkit.robots import panda
from pbdkit.robots.model import Robot

Float = NDArray[np.float64]

START = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
DOWN = np.diag([1.0, -1.0, -1.0])  # the hand's z axis pointing down
GRASP_LOCAL = np.array([0.09, 0.0, 0.05])  # the handle, in the mug's frame
YAWS = np.radians([-80.0, -40.0, 0.0, 40.0, 80.0])


def rz(a: float) -> Float:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def mug_pose(yaw: float, position: Float) -> Float:
    pose = np.eye(4)
    pose[:3, :3] = rz(yaw)
    pose[:3, 3] = position
    return pose


def grasp_pose(mug: Float) -> Float:
    """Where the hand grasps the handle: turned with the mug, pointing down."""
    g = np.eye(4)
    g[:3, :3] = mug[:3, :3] @ rz(np.pi / 2) @ DOWN
    g[:3, 3] = mug[:3, 3] + mug[:3, :3] @ GRASP_LOCAL
    return g


def _ik(robot: Robot, target: Float, q: Float) -> Float:
    for _ in range(50):
        x, rot, jac = robot.fk_pose_jacobian_unchecked(q)
        e = np.r_[target[:3, 3] - x, log3(target[:3, :3] @ rot.T)]
        if np.linalg.norm(e) < 1e-9:
            break
        dq = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), e)
        q = np.clip(q + dq, robot.lower, robot.upper)
    return q


def _smooth(s: Float) -> Float:
    return 10 * s**3 - 15 * s**4 + 6 * s**5  # type: ignore[no-any-return]


def mug_demo(robot: Robot, rng: np.random.Generator, yaw: float, n: int = 40) -> Demonstration:
    """One demonstration of ``n`` samples for the mug at ``yaw`` (rad), placed at random."""
    mug = mug_pose(yaw, np.r_[rng.uniform(0.45, 0.55), rng.uniform(-0.1, 0.1), 0.0])
    g = grasp_pose(mug)
    pre = g.copy()
    pre[2, 3] += 0.12
    q = START + rng.normal(0.0, 0.03, 7)
    x0, rot0, _ = robot.fk_pose_jacobian_unchecked(q)
    r0 = log3(pre[:3, :3] @ rot0.T)
    n1, n2 = n // 2, n // 4
    n3 = n - n1 - n2
    targets = []
    for s in _smooth(np.linspace(0.0, 1.0, n1)[1:]):
        t = np.eye(4)
        t[:3, 3] = x0 + (pre[:3, 3] - x0) * s
        t[:3, :3] = exp_map(r0 * s) @ rot0
        targets.append(t)
    for s in _smooth(np.linspace(0.0, 1.0, n2)[1:]):
        t = pre.copy()
        t[:3, 3] = pre[:3, 3] + (g[:3, 3] - pre[:3, 3]) * s
        targets.append(t)
    for s in _smooth(np.linspace(0.0, 1.0, n3 + 1)[1:]):
        t = g.copy()
        t[2, 3] = g[2, 3] + 0.1 * s
        targets.append(t)
    qs = [q]
    for t in targets:
        q = _ik(robot, t, q)
        qs.append(q)
    joints = np.array(qs)
    grip = np.arange(len(joints)) >= n1 + n2 - 2
    return Demonstration(np.linspace(0.0, 0.04 * n, len(joints)), joints, {"mug": mug}, grip)


def mug_demos(seed: int = 0, n: int = 40) -> tuple[Robot, list[Demonstration]]:
    """The Panda and five demonstrations, the mug at yaws -80 .. 80 degrees."""
    robot = panda()
    rng = np.random.default_rng(seed)
    return robot, [mug_demo(robot, rng, float(y), n) for y in YAWS]
