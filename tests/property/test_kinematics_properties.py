"""Property tests: every arm's analytic kinematics against central finite differences.

For each arm of the zoo (third-party URDFs, ``tests/arm_zoo.py``) and the shipped Katana and
Panda, at postures drawn within the joint limits: ``fk_jacobian`` is the derivative of ``fk``,
``jacobian6`` that of ``fk_pose`` (angular rows: the rotation's), ``fk_jacobian_axes_unchecked``
gives the same position and Jacobian with the joints' world axes (and so the second derivatives
of ``fk``), and the batch path equals the single one.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
import pytest
from arm_zoo import ARMS
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from pbdkit import Robot, robots
from pbdkit._rotations import log_map

Float = NDArray[np.float64]

ARM_NAMES = [*ARMS, "katana", "panda"]
# Central differences with step h: truncation ~h^2 (1e-12 at h = 1e-6), rounding ~1e-16 / h.
H = 1e-6
ATOL = 1e-8
# Second derivatives from differences of the Jacobian: a larger step, a looser tolerance.
H2 = 1e-5
ATOL2 = 1e-7
SETTINGS = settings(max_examples=15, deadline=None, derandomize=True)


@functools.cache
def arm(name: str) -> Robot:
    """The robot of a zoo arm or a shipped one, loaded once per session."""
    if name in ARMS:
        return ARMS[name].robot()
    return robots.load(name)


def fractions(m: int = 1) -> st.SearchStrategy[list[float]]:
    """Positions within the limits as fractions of each joint's range (8 values per posture,
    enough for any arm here; the first n are used)."""
    unit = st.floats(0.0, 1.0, allow_nan=False, allow_infinity=False)
    return st.lists(unit, min_size=8 * m, max_size=8 * m)


def postures(robot: Robot, u: list[float], m: int | None = None) -> Float:
    """Posture (n,) or batch (m, n) from fractions: lower + u (upper - lower)."""
    n = robot.n_joints
    rows = 1 if m is None else m
    frac = np.array(u, dtype=np.float64).reshape(rows, 8)[:, :n]
    q = robot.lower + frac * (robot.upper - robot.lower)
    return q[0] if m is None else q


def central(f: Callable[[Float], Float], q: Float, h: float) -> list[tuple[Float, Float]]:
    """(f(q + h e_i), f(q - h e_i)) for each joint i."""
    out = []
    for i in range(q.shape[0]):
        step = np.zeros_like(q)
        step[i] = h
        out.append((f(q + step), f(q - step)))
    return out


@pytest.mark.parametrize("name", ARM_NAMES)
@SETTINGS
@given(u=fractions())
def test_position_jacobian_is_the_derivative_of_fk(name: str, u: list[float]) -> None:
    robot = arm(name)
    q = postures(robot, u)
    x, jac = robot.fk_jacobian(q)
    np.testing.assert_array_equal(x, robot.fk(q))
    fd = np.stack([(a - b) / (2 * H) for a, b in central(robot.fk, q, H)], axis=1)
    np.testing.assert_allclose(jac, fd, rtol=0, atol=ATOL)


@pytest.mark.parametrize("name", ARM_NAMES)
@SETTINGS
@given(u=fractions())
def test_jacobian6_is_the_derivative_of_the_pose(name: str, u: list[float]) -> None:
    robot = arm(name)
    q = postures(robot, u)
    j6 = robot.jacobian6(q)
    assert j6.shape == (6, robot.n_joints)
    pairs = central(robot.fk_pose, q, H)
    linear = np.stack([(a[:3, 3] - b[:3, 3]) / (2 * H) for a, b in pairs], axis=1)
    # R(q + h e_i) R(q - h e_i)^T = exp(2 h [omega_i]x) + O(h^3): omega_i in the base frame.
    angular = np.stack([log_map(a[:3, :3] @ b[:3, :3].T) / (2 * H) for a, b in pairs], axis=1)
    np.testing.assert_allclose(j6[:3], linear, rtol=0, atol=ATOL)
    np.testing.assert_allclose(j6[3:], angular, rtol=0, atol=ATOL)
    np.testing.assert_allclose(j6[:3], robot.jacobian(q), rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", ARM_NAMES)
@SETTINGS
@given(u=fractions())
def test_axes_fast_path_gives_the_second_derivatives_of_fk(name: str, u: list[float]) -> None:
    robot = arm(name)
    q = postures(robot, u)
    x, jac, axes = robot.fk_jacobian_axes_unchecked(q)
    x_ref, jac_ref = robot.fk_jacobian(q)
    np.testing.assert_array_equal(x, x_ref)
    np.testing.assert_array_equal(jac, jac_ref)
    # The axes are the angular rows of the 6-D Jacobian (zero for a prismatic joint) ...
    np.testing.assert_allclose(axes, robot.jacobian6(q)[3:].T, rtol=0, atol=1e-15)
    assert np.all(axes[~robot.revolute] == 0.0)
    # ... and give d^2 x / (d theta_a d theta_b) = omega_min(a,b) x J_max(a,b) (serial chain).
    pairs = central(lambda p: robot.fk_jacobian(p)[1], q, H2)
    for a, (plus, minus) in enumerate(pairs):
        fd = (plus - minus) / (2 * H2)  # column b: d J_b / d theta_a
        for b in range(robot.n_joints):
            lo, hi = min(a, b), max(a, b)
            np.testing.assert_allclose(fd[:, b], np.cross(axes[lo], jac[:, hi]), atol=ATOL2)


@pytest.mark.parametrize("name", ARM_NAMES)
@SETTINGS
@given(u=fractions(m=4))
def test_batch_path_equals_the_single_path(name: str, u: list[float]) -> None:
    robot = arm(name)
    batch = postures(robot, u, m=4)
    x_b, j_b = robot.fk_jacobian(batch)
    poses_b, j6_b = robot.fk_pose(batch), robot.jacobian6(batch)
    np.testing.assert_allclose(robot.fk(batch), x_b, rtol=0, atol=1e-15)
    for k, q in enumerate(batch):
        x, jac = robot.fk_jacobian(q)
        np.testing.assert_allclose(x_b[k], x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(j_b[k], jac, rtol=0, atol=1e-12)
        np.testing.assert_allclose(poses_b[k], robot.fk_pose(q), rtol=0, atol=1e-12)
        np.testing.assert_allclose(j6_b[k], robot.jacobian6(q), rtol=0, atol=1e-12)
