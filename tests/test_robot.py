"""Tests of pbdkit.robots (_robot, _urdf, _chain, _ik) and pbdkit.robots._kinematics."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
import yaml
from arms import KinematicOnly
from numpy.typing import NDArray

from pbdkit import robots
from pbdkit._rotations import log_map
from pbdkit.robots._ik import damped_least_squares, ik
from pbdkit.robots._kinematics import damped_pinv, damping_schedule, nullspace_projector
from pbdkit.robots._robot import Robot
from pbdkit.robots._urdf import _rpy_from_matrix, urdf_from_dh

PI = math.pi

# ------------------------------------------------------------------------------------------
# helpers: an independent forward kinematics from URDF numbers (homogeneous transforms)
# ------------------------------------------------------------------------------------------


def rot_x(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)


def rot_y(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=float)


def rot_z(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=float)


def origin(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> NDArray[np.float64]:
    """URDF <origin>: translation, then R = Rz(yaw) Ry(pitch) Rx(roll)."""
    t = np.eye(4)
    t[:3, :3] = rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])
    t[:3, 3] = xyz
    return t


def rz4(q: float) -> NDArray[np.float64]:
    t = np.eye(4)
    t[:3, :3] = rot_z(q)
    return t


# design.md: the Katana 6M180 chain, all joints about local z, then the fixed tool frame
KATANA_ORIGINS = [
    ((0, 0, 0.2015), (0, 0, 0)),
    ((0, 0, 0), (PI / 2, 0, 0)),
    ((0.19, 0, 0), (0, 0, 0)),
    ((0.139, 0, 0), (PI, 0, 0)),
    ((0.1523, 0, 0), (PI / 2, 0, -PI / 2)),
]
KATANA_TOOL = ((0, 0, -0.1505), (0, PI / 2, 0))
KATANA_LOWER = [-3.025528, -0.135228, -2.221804, -2.033309, -2.993240]
KATANA_UPPER = [2.891097, 2.168572, 2.054223, 1.876133, 2.870985]


def katana_fk_reference(q: NDArray[np.float64]) -> NDArray[np.float64]:
    t = np.eye(4)
    for (xyz, rpy), qi in zip(KATANA_ORIGINS, q, strict=True):
        t = t @ origin(xyz, rpy) @ rz4(qi)
    t = t @ origin(*KATANA_TOOL)
    return t[:3, 3]


def random_q(robot: Robot, rng: np.random.Generator, m: int | None = None) -> NDArray[np.float64]:
    size = robot.n_joints if m is None else (m, robot.n_joints)
    return rng.uniform(robot.lower, robot.upper, size=size)


def fd_jacobian(robot: Robot, q: NDArray[np.float64], h: float) -> NDArray[np.float64]:
    cols = []
    for i in range(robot.n_joints):
        dq = np.zeros(robot.n_joints)
        dq[i] = h
        cols.append((robot.fk(q + dq) - robot.fk(q - dq)) / (2 * h))
    return np.stack(cols, axis=1)


# A hand-written Panda URDF (franka_description's joint origins), to compare with the DH path.
PANDA_ORIGINS = [
    ((0, 0, 0.333), (0, 0, 0)),
    ((0, 0, 0), (-PI / 2, 0, 0)),
    ((0, -0.316, 0), (PI / 2, 0, 0)),
    ((0.0825, 0, 0), (PI / 2, 0, 0)),
    ((-0.0825, 0.384, 0), (-PI / 2, 0, 0)),
    ((0, 0, 0), (PI / 2, 0, 0)),
    ((0.088, 0, 0), (PI / 2, 0, 0)),
]


def chain_urdf(
    origins: Sequence[tuple[tuple[float, ...], tuple[float, ...]]],
    tip_xyz: tuple[float, float, float],
    types: list[str] | None = None,
    visual: str = "",
) -> str:
    types = types or ["revolute"] * len(origins)
    links = "".join(f'<link name="l{i}">{visual}</link>' for i in range(len(origins) + 1))
    joints = ""
    for i, ((xyz, rpy), jt) in enumerate(zip(origins, types, strict=True)):
        joints += (
            f'<joint name="j{i + 1}" type="{jt}"><parent link="l{i}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{" ".join(map(repr, xyz))}" rpy="{" ".join(map(repr, rpy))}"/>'
            '<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
    tip = (
        f'<link name="tip"/><joint name="tip_joint" type="fixed"><parent link="l{len(origins)}"/>'
        f'<child link="tip"/><origin xyz="{" ".join(map(repr, tip_xyz))}"/></joint>'
    )
    return f'<?xml version="1.0"?><robot name="chain">{links}{joints}{tip}</robot>'


@pytest.fixture(scope="module")
def katana() -> Robot:
    return robots.katana()


@pytest.fixture(scope="module")
def panda() -> Robot:
    return robots.panda()


# ------------------------------------------------------------------------------------------
# the Katana model
# ------------------------------------------------------------------------------------------


def test_katana_model_matches_design(katana: Robot) -> None:
    assert katana.n_joints == 5
    assert katana.joint_names == ["pan", "lift1", "lift2", "lift3", "wrist_roll"]
    assert katana.tip == "tool"
    assert katana.base == "base_link"
    np.testing.assert_allclose(katana.lower, KATANA_LOWER, rtol=0, atol=1e-12)
    np.testing.assert_allclose(katana.upper, KATANA_UPPER, rtol=0, atol=1e-12)
    np.testing.assert_allclose(katana.velocity_limit, 1.19, rtol=0, atol=1e-12)
    assert katana.revolute.all()


def test_katana_limits_from_the_shipped_yaml(katana: Robot) -> None:
    # The maker publishes no acceleration or jerk limits: conservative ones, the same on every
    # joint; the velocity stays the URDF's (the YAML does not repeat it).
    assert robots.katana_joint_limits_path().is_file()
    declared = yaml.safe_load(robots.katana_joint_limits_path().read_text())["joint_limits"]
    assert list(declared) == katana.joint_names
    assert not any("has_velocity_limits" in entry for entry in declared.values())
    np.testing.assert_array_equal(katana.velocity_limit, np.full(5, 1.19))
    np.testing.assert_array_equal(katana.acceleration_limit, np.full(5, 6.0))
    np.testing.assert_array_equal(katana.jerk_limit, np.full(5, 60.0))


def test_katana_fk_equals_independent_transforms(katana: Robot) -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = random_q(katana, rng)
        np.testing.assert_allclose(katana.fk(q), katana_fk_reference(q), rtol=0, atol=1e-12)
    q_batch = random_q(katana, rng, 200)
    ref = np.array([katana_fk_reference(q) for q in q_batch])
    np.testing.assert_allclose(katana.fk(q_batch), ref, rtol=0, atol=1e-12)


def test_katana_stretched_reach(katana: Robot) -> None:
    # all zero: the arm is stretched along x at the shoulder height
    np.testing.assert_allclose(
        katana.fk(np.zeros(5)), [0.19 + 0.139 + 0.1523 + 0.1505, 0, 0.2015], rtol=0, atol=1e-12
    )


def test_katana_wrist_roll_column_is_zero(katana: Robot) -> None:
    rng = np.random.default_rng(1)
    q_batch = random_q(katana, rng, 100)
    jac = katana.jacobian(q_batch)
    np.testing.assert_allclose(jac[:, :, 4], 0.0, rtol=0, atol=1e-15)
    for q in q_batch[:10]:
        np.testing.assert_allclose(katana.jacobian(q)[:, 4], 0.0, rtol=0, atol=1e-15)
        # and rolling does not move the tool point
        q2 = q.copy()
        q2[4] = -q[4]
        np.testing.assert_allclose(katana.fk(q2), katana.fk(q), rtol=0, atol=1e-15)


def test_katana_default_tip_is_last_link() -> None:
    robot = Robot.from_urdf(robots.katana_urdf_path())
    assert robot.tip == "tool"
    assert robot.urdf == robots.katana_urdf_path().read_text(encoding="utf-8")


def test_katana_urdf_loads_in_mujoco(katana: Robot) -> None:
    mujoco = pytest.importorskip("mujoco")
    model = mujoco.MjModel.from_xml_path(str(robots.katana_urdf_path()))
    data = mujoco.MjData(model)
    assert [model.joint(i).name for i in range(model.njnt)] == katana.joint_names
    assert 3.0 <= float(model.body_mass.sum()) <= 5.0
    np.testing.assert_allclose(model.jnt_range, np.c_[katana.lower, katana.upper], atol=1e-12)
    assert np.all(model.body_inertia[2:7] > 0)
    rng = np.random.default_rng(2)
    tool = model.body("tool").id
    for q in random_q(katana, rng, 20):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        np.testing.assert_allclose(data.xpos[tool], katana.fk(q), rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------------
# Jacobians, batches, the two evaluation paths
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["katana", "panda"])
def test_jacobian_equals_finite_differences(name: str) -> None:
    robot = robots.load(name)
    rng = np.random.default_rng(3)
    # central differences: truncation ~h^2 = 1e-12, rounding ~1e-16 / h = 1e-10
    for q in random_q(robot, rng, 30):
        np.testing.assert_allclose(
            robot.jacobian(q), fd_jacobian(robot, q, 1e-6), rtol=0, atol=1e-8
        )


@pytest.mark.parametrize("name", ["katana", "panda"])
def test_batch_equals_single(name: str) -> None:
    robot = robots.load(name)
    rng = np.random.default_rng(4)
    q_batch = random_q(robot, rng, 300)
    x_b, j_b = robot.fk_jacobian(q_batch)
    assert x_b.shape == (300, 3)
    assert j_b.shape == (300, 3, robot.n_joints)
    x_s = np.array([robot.fk(q) for q in q_batch])
    j_s = np.array([robot.jacobian(q) for q in q_batch])
    np.testing.assert_allclose(x_b, x_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(j_b, j_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(robot.fk(q_batch), x_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(robot.jacobian(q_batch), j_s, rtol=0, atol=1e-12)
    x1, j1 = robot.fk_jacobian(q_batch[0])
    np.testing.assert_allclose(x1, x_s[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(j1, j_s[0], rtol=0, atol=1e-15)
    # a batch of one and an empty batch
    np.testing.assert_allclose(robot.fk(q_batch[:1]), x_s[:1], rtol=0, atol=1e-12)
    assert robot.jacobian(np.empty((0, robot.n_joints))).shape == (0, 3, robot.n_joints)


def test_accepts_lists_and_returns_new_arrays(katana: Robot) -> None:
    q = [0.1, 0.2, 0.3, 0.4, 0.5]
    x, jac = katana.fk_jacobian(q)
    np.testing.assert_allclose(x, katana.fk(np.array(q)), rtol=0, atol=1e-15)
    x[:] = 0.0
    jac[:] = 0.0
    np.testing.assert_allclose(katana.fk(q), katana_fk_reference(np.array(q)), atol=1e-12)


def test_prismatic_joints() -> None:
    # R P R: a planar-ish arm with a telescopic middle joint
    table = [[0.0, 0.0, 0.3, 0.0], [0.2, PI / 2, 0.1, 0.0], [0.0, -PI / 2, 0.25, 0.3]]
    robot = Robot.from_dh(
        table, "RPR", lower=[-3, 0.0, -3], upper=[3, 0.4, 3], tip_offset=(0.1, 0, 0)
    )
    assert robot.revolute.tolist() == [True, False, True]
    rng = np.random.default_rng(5)
    q_batch = random_q(robot, rng, 50)
    x_b, j_b = robot.fk_jacobian(q_batch)
    for q, x, jac in zip(q_batch, x_b, j_b, strict=True):
        np.testing.assert_allclose(robot.fk(q), x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(robot.jacobian(q), jac, rtol=0, atol=1e-12)
        np.testing.assert_allclose(jac, fd_jacobian(robot, q, 1e-6), rtol=0, atol=1e-8)


# ------------------------------------------------------------------------------------------
# DH tables
# ------------------------------------------------------------------------------------------


def test_panda_dh_equals_handwritten_urdf(panda: Robot) -> None:
    urdf = Robot.from_urdf(chain_urdf(PANDA_ORIGINS, (0, 0, 0.107)), tip="tip")
    rng = np.random.default_rng(6)
    q_batch = rng.uniform(-3, 3, size=(100, 7))
    np.testing.assert_allclose(panda.fk(q_batch), urdf.fk(q_batch), rtol=0, atol=1e-12)
    np.testing.assert_allclose(panda.jacobian(q_batch), urdf.jacobian(q_batch), rtol=0, atol=1e-12)
    # published zero-configuration flange position of the Panda
    np.testing.assert_allclose(panda.fk(np.zeros(7)), [0.088, 0, 0.926], rtol=0, atol=1e-12)


def test_panda_factory(panda: Robot) -> None:
    assert panda.n_joints == 7
    assert panda.tip == "flange"
    assert panda.joint_names[0] == "panda_joint1"
    np.testing.assert_allclose(panda.upper[3], -0.0698, rtol=0, atol=0)
    np.testing.assert_allclose(panda.effort_limit[[0, 6]], [87.0, 12.0], rtol=0, atol=0)


def test_panda_has_frankas_published_limits(panda: Robot) -> None:
    # Franka, "Robot and interface specifications", limits for Panda.
    np.testing.assert_array_equal(
        panda.velocity_limit, [2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]
    )
    np.testing.assert_array_equal(panda.acceleration_limit, [15, 7.5, 10, 12.5, 15, 20, 20])
    np.testing.assert_array_equal(panda.jerk_limit, [7500, 3750, 5000, 6250, 7500, 10000, 10000])
    # ... read from the shipped YAML, not from the generated URDF (which has no velocity)
    assert robots.panda_joint_limits_path().name == "panda_joint_limits.yaml"
    without = Robot.from_urdf(panda.urdf, tip="flange")
    assert np.isinf(without.velocity_limit).all() and np.isinf(without.jerk_limit).all()


def test_limit_arrays_are_float64_and_read_only(panda: Robot) -> None:
    for name in ("lower", "upper", "velocity_limit", "acceleration_limit", "jerk_limit"):
        arr = getattr(panda, name)
        assert arr.dtype == np.float64 and arr.shape == (7,), name
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 1.0


def test_a_urdf_velocity_of_zero_means_no_limit() -> None:
    urdf = chain_urdf(KATANA_ORIGINS[:3], (0.1, 0, 0)).replace('velocity="1"', 'velocity="0"', 1)
    robot = Robot.from_urdf(urdf, tip="tip")
    np.testing.assert_array_equal(robot.velocity_limit, [np.inf, 1.0, 1.0])
    # no YAML: no acceleration or jerk limit anywhere
    np.testing.assert_array_equal(robot.acceleration_limit, np.full(3, np.inf))
    np.testing.assert_array_equal(robot.jerk_limit, np.full(3, np.inf))
    # a continuous joint without <limit> gets velocity 0 in the URDF: no limit either
    text = (
        '<robot name="c"><link name="a"/><link name="b"/>'
        '<joint name="spin" type="continuous"><parent link="a"/><child link="b"/>'
        '<axis xyz="0 0 1"/></joint></robot>'
    )
    np.testing.assert_array_equal(Robot.from_urdf(text).velocity_limit, [np.inf])


def test_from_dh_acceleration_and_jerk() -> None:
    table = [[0, 0, 0.1, 0], [0.2, 0, 0, 0]]
    robot = Robot.from_dh(table, velocity=[1.0, 0.0], acceleration=3.0, jerk=[30.0, np.inf])
    np.testing.assert_array_equal(robot.velocity_limit, [1.0, np.inf])
    np.testing.assert_array_equal(robot.acceleration_limit, [3.0, 3.0])
    np.testing.assert_array_equal(robot.jerk_limit, [30.0, np.inf])
    plain = Robot.from_dh(table)
    assert np.isinf(plain.velocity_limit).all() and np.isinf(plain.acceleration_limit).all()
    with pytest.raises(ValueError, match=r"acceleration\[1\] must be > 0 \(rad/s\^2; inf for no "):
        Robot.from_dh(table, acceleration=[1.0, 0.0])
    with pytest.raises(ValueError, match=r"jerk\[0\] must be > 0 .* got nan"):
        Robot.from_dh(table, jerk=np.nan)
    with pytest.raises(ValueError, match=r"jerk must have shape \(2,\) \(one value per joint\)"):
        Robot.from_dh(table, jerk=[1.0, 2.0, 3.0])


@pytest.mark.parametrize("convention", ["modified", "standard"])
def test_planar_two_link_dh(convention: str) -> None:
    l1, l2 = 0.4, 0.3
    if convention == "modified":
        table = [[0, 0, 0, 0], [l1, 0, 0, 0]]
        tip = (l2, 0.0, 0.0)
    else:
        table = [[l1, 0, 0, 0], [l2, 0, 0, 0]]
        tip = (0.0, 0.0, 0.0)
    robot = Robot.from_dh(table, tip_offset=tip, convention=convention)  # type: ignore[arg-type]
    rng = np.random.default_rng(7)
    for q1, q2 in rng.uniform(-3, 3, size=(20, 2)):
        expected = [
            l1 * math.cos(q1) + l2 * math.cos(q1 + q2),
            l1 * math.sin(q1) + l2 * math.sin(q1 + q2),
            0,
        ]
        np.testing.assert_allclose(robot.fk([q1, q2]), expected, rtol=0, atol=1e-12)


def test_standard_and_modified_dh_agree_on_katana_like_arm() -> None:
    # one arm written in both conventions: z0 up, shoulder, two links, a tool on the last axis
    std = [[0, PI / 2, 0.2015, 0], [0.19, 0, 0, 0], [0.139, 0, 0, 0]]
    mod = [[0, 0, 0.2015, 0], [0, PI / 2, 0, 0], [0.19, 0, 0, 0]]
    a = Robot.from_dh(std, convention="standard")
    b = Robot.from_dh(mod, convention="modified", tip_offset=(0.139, 0, 0))
    rng = np.random.default_rng(8)
    q_batch = rng.uniform(-3, 3, size=(50, 3))
    np.testing.assert_allclose(a.fk(q_batch), b.fk(q_batch), rtol=0, atol=1e-12)


def test_dh_tip_offset_as_transform() -> None:
    offset = np.eye(4)
    offset[:3, :3] = rot_z(0.3) @ rot_y(PI / 2)
    offset[:3, 3] = [0.1, 0.2, 0.3]
    a = Robot.from_dh([[0, 0, 0.1, 0], [0.2, PI / 2, 0, 0]], tip_offset=offset)
    b = Robot.from_dh([[0, 0, 0.1, 0], [0.2, PI / 2, 0, 0]], tip_offset=[0.1, 0.2, 0.3])
    q = np.array([0.4, -0.7])
    np.testing.assert_allclose(a.fk(q), b.fk(q), rtol=0, atol=1e-15)


def test_random_dh_robots_batch_single_and_finite_differences() -> None:
    # random chains of revolute and prismatic joints in both conventions exercise the numpy chain
    rng = np.random.default_rng(13)
    for k in range(12):
        n = int(rng.integers(1, 8))
        table = np.c_[
            rng.uniform(-0.3, 0.3, n),
            rng.choice([0.0, PI / 2, -PI / 2, PI, 0.7], n),
            rng.uniform(-0.3, 0.3, n),
            rng.uniform(-PI, PI, n),
        ]
        types = "".join(rng.choice(["R", "P"], n, p=[0.7, 0.3]))
        robot = Robot.from_dh(
            table,
            types,
            lower=np.where(np.array(list(types)) == "R", -PI, -0.2),
            upper=np.where(np.array(list(types)) == "R", PI, 0.4),
            tip_offset=rng.uniform(-0.2, 0.2, 3),
            convention="modified" if k % 2 else "standard",
        )
        assert robot.n_joints == n
        q_batch = random_q(robot, rng, 20)
        x_b, j_b = robot.fk_jacobian(q_batch)
        for q, x, jac in zip(q_batch, x_b, j_b, strict=True):
            np.testing.assert_allclose(robot.fk(q), x, rtol=0, atol=1e-12)
            np.testing.assert_allclose(robot.jacobian(q), jac, rtol=0, atol=1e-12)
            np.testing.assert_allclose(jac, fd_jacobian(robot, q, 1e-6), rtol=0, atol=1e-8)


def test_katana_urdf_is_simulation_ready() -> None:
    root = ET.parse(robots.katana_urdf_path()).getroot()
    links = {link.get("name"): link for link in root.findall("link")}
    assert root.find(".//mesh") is None  # primitives only
    for name in ["base_link", "pan_link", "upper_arm", "forearm", "wrist", "gripper"]:
        link = links[name]
        assert link.find("visual/geometry") is not None
        assert link.find("collision/geometry") is not None
        mass = link.find("inertial/mass")
        assert mass is not None
        assert float(mass.get("value", "0")) > 0
    masses = [float(m.get("value", "0")) for m in root.iter("mass")]
    assert 3.5 <= sum(masses) <= 5.0
    for joint in root.findall("joint[@type='revolute']"):
        limit = joint.find("limit")
        assert limit is not None
        assert float(limit.get("velocity", "0")) == pytest.approx(1.19, abs=1e-12)
        assert float(limit.get("effort", "0")) > 0
    tool = root.find("joint[@name='tool_joint']/origin")
    assert tool is not None
    assert tool.get("xyz") == "0 0 -0.1505"


def test_rpy_round_trip_including_gimbal_lock() -> None:
    rng = np.random.default_rng(9)
    angles = [*rng.uniform(-PI, PI, size=(50, 3)).tolist()]
    angles += [[0.3, PI / 2, 0.0], [0.3, -PI / 2, 0.2], [PI / 2, PI / 2, PI / 2], [-PI, 0, PI]]
    for r, p, y in angles:
        mat = rot_z(y) @ rot_y(p) @ rot_x(r)
        r2, p2, y2 = _rpy_from_matrix(mat)
        np.testing.assert_allclose(rot_z(y2) @ rot_y(p2) @ rot_x(r2), mat, rtol=0, atol=1e-14)


def test_urdf_from_dh_is_loadable_text() -> None:
    text = urdf_from_dh([[0, 0, 0.3, 0]], name="one", joint_names=["spin"], tip="end")
    assert text.startswith("<?xml")
    robot = Robot.from_urdf(text)
    assert robot.joint_names == ["spin"]
    assert robot.tip == "end"
    np.testing.assert_allclose(robot.lower, [-PI], rtol=0, atol=0)


# ------------------------------------------------------------------------------------------
# URDF loading: files, meshes, trees, joint types
# ------------------------------------------------------------------------------------------


def test_missing_mesh_files_still_load(tmp_path: Path) -> None:
    visual = (
        '<visual><geometry><mesh filename="package://nowhere/meshes/part.stl"/></geometry></visual>'
        '<collision><geometry><mesh filename="/does/not/exist.dae"/></geometry></collision>'
    )
    text = chain_urdf(PANDA_ORIGINS[:3], (0, 0, 0.1), visual=visual)
    path = tmp_path / "arm.urdf"
    path.write_text(text, encoding="utf-8")
    for source in (text, path, str(path)):
        robot = Robot.from_urdf(source)
        assert robot.n_joints == 3
        assert robot.urdf == text


def test_branching_tree_locks_other_branches() -> None:
    # l0 -> j1 -> l1 -> {j2 -> l2 -> tip (fixed), k2 -> m2 -> k3 -> m3}
    branch = (
        '<link name="m2"/><link name="m3"/>'
        '<joint name="k2" type="revolute"><parent link="l1"/><child link="m2"/>'
        '<origin xyz="0 0.5 0"/><axis xyz="1 0 0"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        '<joint name="k3" type="prismatic"><parent link="m2"/><child link="m3"/>'
        '<axis xyz="0 1 0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>'
    )
    chain = chain_urdf(PANDA_ORIGINS[:2], (0.1, 0, 0.2))
    tree = chain.replace("</robot>", branch + "</robot>")
    robot = Robot.from_urdf(tree, tip="tip")
    ref = Robot.from_urdf(chain)
    assert robot.joint_names == ["j1", "j2"]
    rng = np.random.default_rng(10)
    q_batch = rng.uniform(-3, 3, size=(20, 2))
    np.testing.assert_allclose(robot.fk(q_batch), ref.fk(q_batch), rtol=0, atol=1e-15)
    other = Robot.from_urdf(tree, tip="m3")
    assert other.joint_names == ["j1", "k2", "k3"]
    assert other.revolute.tolist() == [True, True, False]
    for q in random_q(other, rng, 10):
        np.testing.assert_allclose(other.jacobian(q), fd_jacobian(other, q, 1e-6), atol=1e-8)
    with pytest.raises(ValueError, match=r"tip is None but the URDF tree branches.*'tip'.*'m3'"):
        Robot.from_urdf(tree)


def test_tip_may_be_a_joint_frame(katana: Robot) -> None:
    robot = Robot.from_urdf(robots.katana_urdf_path(), tip="lift3")
    assert robot.joint_names == ["pan", "lift1", "lift2", "lift3"]
    q = np.array([0.2, 0.4, -0.3, 0.9])
    wrist_centre = katana.fk([*q.tolist(), 0.0])  # not the same point: just a sanity check
    assert np.linalg.norm(robot.fk(q) - wrist_centre) > 0.1


def test_unaligned_axes() -> None:
    text = chain_urdf(PANDA_ORIGINS[:4], (0.05, 0.02, 0.1), types=["revolute", "prismatic"] * 2)
    for i, axis in enumerate(["1 1 0", "0.3 -0.5 0.8", "0 -2 0", "-1 0 0"]):
        text = text.replace('<axis xyz="0 0 1"/>', f'<axis xyz="{axis}"/>', 1)
        assert f'axis xyz="{axis}"' in text, i
    robot = Robot.from_urdf(text)
    assert robot.revolute.tolist() == [True, False, True, False]
    rng = np.random.default_rng(14)
    q_batch = random_q(robot, rng, 20)
    x_b, j_b = robot.fk_jacobian(q_batch)
    for q, x, jac in zip(q_batch, x_b, j_b, strict=True):
        np.testing.assert_allclose(robot.fk(q), x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(robot.jacobian(q), jac, rtol=0, atol=1e-12)
        np.testing.assert_allclose(jac, fd_jacobian(robot, q, 1e-6), rtol=0, atol=1e-8)
    # the axis is normalized: the prismatic joint along "0.3 -0.5 0.8" moves 1 m per metre
    np.testing.assert_allclose(np.linalg.norm(j_b[:, :, 1], axis=1), 1.0, rtol=0, atol=1e-12)


def test_continuous_joint_becomes_revolute() -> None:
    text = (
        '<robot name="c"><link name="a"/><link name="b"/><link name="t"/>'
        '<joint name="spin" type="continuous"><parent link="a"/><child link="b"/>'
        '<axis xyz="0 0 1"/></joint>'
        '<joint name="f" type="fixed"><parent link="b"/><child link="t"/><origin xyz="0.5 0 0"/>'
        "</joint></robot>"
    )
    robot = Robot.from_urdf(text)
    assert robot.n_joints == 1
    np.testing.assert_allclose([robot.lower[0], robot.upper[0]], [-PI, PI], rtol=0, atol=0)
    assert 'type="revolute"' in robot.urdf
    np.testing.assert_allclose(robot.fk([PI / 2]), [0, 0.5, 0], rtol=0, atol=1e-15)
    # one joint: the Jacobian is still (3, 1), (M, 3, 1)
    np.testing.assert_allclose(robot.jacobian([PI / 2]), [[-0.5], [0.0], [0.0]], atol=1e-15)
    np.testing.assert_allclose(robot.jacobian([[PI / 2]]), [[[-0.5], [0.0], [0.0]]], atol=1e-15)


# ------------------------------------------------------------------------------------------
# bad input
# ------------------------------------------------------------------------------------------


def test_bad_urdf_sources(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"path_or_xml is not valid XML"):
        Robot.from_urdf("<robot name='x'><link name='a'></robot>")
    with pytest.raises(ValueError, match=r"URDF file '.*nope\.urdf' does not exist"):
        Robot.from_urdf(tmp_path / "nope.urdf")
    with pytest.raises(ValueError, match=r"URDF file 'nope\.urdf' does not exist"):
        Robot.from_urdf("nope.urdf")
    with pytest.raises(ValueError, match=r"URDF file '.*' is a directory"):
        Robot.from_urdf(tmp_path)
    with pytest.raises(ValueError, match=r"<robot> root element, got <sdf>"):
        Robot.from_urdf("<sdf version='1.6'/>")
    with pytest.raises(ValueError, match=r"path_or_xml must be a path .* got int"):
        Robot.from_urdf(3)  # type: ignore[arg-type]


def test_binary_urdf_file_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "arm.urdf"
    path.write_bytes(b"<robot name='x'>\xff\xfe\x00\x81</robot>")
    with pytest.raises(ValueError, match=r"'.*arm\.urdf' is not a UTF-8 text URDF"):
        Robot.from_urdf(path)
    with pytest.raises(ValueError, match=r"'.*arm\.urdf' is not a UTF-8 text URDF"):
        Robot.from_urdf(str(path))


def _with_mimic(text: str, joint: str, follows: str) -> str:
    return text.replace(
        f'<joint name="{joint}" type="revolute">',
        f'<joint name="{joint}" type="revolute"><mimic joint="{follows}" multiplier="1"/>',
    )


def test_mimic_joint_on_the_chain_is_refused() -> None:
    text = chain_urdf(PANDA_ORIGINS[:3], (0, 0, 0.1))
    with pytest.raises(
        ValueError,
        match=r"joint 'j3' is a <mimic> joint \(it follows 'j2'\).*remove the <mimic> tag.*"
        r"type=\"fixed\"",
    ):
        Robot.from_urdf(_with_mimic(text, "j3", "j2"))


def test_mimic_joint_off_the_chain_is_locked_like_any_other() -> None:
    # A gripper finger that mimics another one does not move the tip: it is locked.
    branch = (
        '<link name="f1"/><link name="f2"/>'
        '<joint name="finger1" type="prismatic"><parent link="l2"/><child link="f1"/>'
        '<axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>'
        '<joint name="finger2" type="prismatic"><parent link="l2"/><child link="f2"/>'
        '<mimic joint="finger1"/>'
        '<axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>'
    )
    text = chain_urdf(PANDA_ORIGINS[:2], (0, 0, 0.1)).replace("</robot>", branch + "</robot>")
    robot = Robot.from_urdf(text, tip="tip")
    assert robot.joint_names == ["j1", "j2"]
    with pytest.raises(ValueError, match=r"joint 'finger2' is a <mimic> joint"):
        Robot.from_urdf(text, tip="f2")


def test_from_dh_escapes_names_in_the_xml() -> None:
    evil = 'x"/><joint name="evil" type="revolute"><parent link="link0"/><child link="tip"/>'
    robot = Robot.from_dh(
        [[0, 0, 0.1, 0], [0.2, 0, 0, 0]],
        name=evil,
        joint_names=['a"b', "c<d>&e"],
        tip="t'ip",
    )
    assert robot.name == evil
    assert robot.joint_names == ['a"b', "c<d>&e"]
    assert robot.tip == "t'ip"
    np.testing.assert_allclose(robot.fk([0.0, 0.0]), [0.2, 0.0, 0.1], atol=1e-12)


def test_malformed_trees() -> None:
    with pytest.raises(ValueError, match=r"the URDF has no <link>"):
        Robot.from_urdf('<robot name="x"></robot>')
    with pytest.raises(ValueError, match=r"exactly one root link, got 2: \['a', 'b'\]"):
        Robot.from_urdf('<robot name="x"><link name="a"/><link name="b"/></robot>')
    text = chain_urdf(PANDA_ORIGINS[:2], (0, 0, 0.1))
    with pytest.raises(ValueError, match=r"joint 'j2' has child link 'zz', which is not a <link>"):
        Robot.from_urdf(text.replace('<child link="l2"/>', '<child link="zz"/>'))
    with pytest.raises(ValueError, match=r"joint 'j1' has axis xyz='0 0 0'; give 3 finite numbers"):
        Robot.from_urdf(text.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1))
    flipped = text.replace('lower="-3" upper="3"', 'lower="1" upper="-1"', 1)
    with pytest.raises(ValueError, match=r"lower <= upper, got lower=\[1\.0, -3\.0\]"):
        Robot.from_urdf(flipped)


def test_tip_errors() -> None:
    with pytest.raises(
        ValueError, match=r"tip frame 'hand' does not exist.*available frames.*'tool'"
    ):
        Robot.from_urdf(robots.katana_urdf_path(), tip="hand")
    with pytest.raises(ValueError, match=r"tip frame 'base_link' is not moved by any joint"):
        Robot.from_urdf(robots.katana_urdf_path(), tip="base_link")


def test_unsupported_joints() -> None:
    text = chain_urdf(PANDA_ORIGINS[:2], (0, 0, 0.1))
    with pytest.raises(ValueError, match=r"joint 'j2' has type 'planar'"):
        Robot.from_urdf(text.replace('name="j2" type="revolute"', 'name="j2" type="planar"'))
    no_limit = text.replace(
        '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>', "</joint>"
    )
    with pytest.raises(ValueError, match=r"revolute joint 'j1' has no <limit>"):
        Robot.from_urdf(no_limit)


def test_bad_joint_values(katana: Robot) -> None:
    with pytest.raises(ValueError, match=r"q must have shape \(5,\) .*'pan'.*got \(4,\)"):
        katana.fk(np.zeros(4))
    with pytest.raises(ValueError, match=r"q must have shape \(M, 5\) .*got \(2, 6\)"):
        katana.jacobian(np.zeros((2, 6)))
    with pytest.raises(ValueError, match=r"q must be 1-D or 2-D, got 3-D"):
        katana.fk(np.zeros((2, 2, 5)))
    with pytest.raises(ValueError, match=r"q must be finite, got 1 NaN"):
        katana.fk_jacobian(np.array([0.0, np.nan, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r"q must be finite, got 1 NaN"):
        katana.fk([[0.0, 0.0, np.inf, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"q must be an array of numbers"):
        katana.fk("abc")


def test_check_joints_limits(katana: Robot) -> None:
    q = np.zeros(5)
    q[2] = 2.5
    with pytest.raises(
        ValueError,
        match=r"q0\[2\] \(joint 'lift2'\) must be within \[-2\.2218, 2\.05422\], got 2\.5",
    ):
        katana.check_joints(q, name="q0", enforce_limits=True)
    np.testing.assert_array_equal(katana.check_joints(q, name="q0"), q)
    batch = np.zeros((3, 5))
    batch[1, 1] = -1.0
    with pytest.raises(ValueError, match=r"Q\[1, 1\] \(joint 'lift1'\)"):
        katana.check_joints(batch, name="Q", enforce_limits=True)
    assert katana.within_limits(np.zeros(5)) is True
    assert katana.within_limits(q) is False
    assert katana.within_limits(q, tol=0.5) is True
    np.testing.assert_array_equal(katana.within_limits(batch), [True, False, True])
    clipped = katana.clip(batch)
    np.testing.assert_allclose(clipped[1, 1], katana.lower[1], rtol=0, atol=0)
    assert katana.within_limits(katana.clip(q)) is True


def test_robots_registry() -> None:
    assert robots.available() == ["katana", "panda"]
    assert robots.load("katana").n_joints == 5
    with pytest.raises(ValueError, match=r"name must be one of \['katana', 'panda'\], got 'ur5'"):
        robots.load("ur5")


def test_dh_bad_input() -> None:
    with pytest.raises(ValueError, match=r"table must have shape \(n, 4\).*got \(2, 3\)"):
        urdf_from_dh(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"joint_types must give 2 entries"):
        urdf_from_dh(np.zeros((2, 4)), "RX")
    with pytest.raises(ValueError, match=r"lower and upper are required when a joint is prismatic"):
        urdf_from_dh(np.zeros((2, 4)), "RP")
    with pytest.raises(ValueError, match=r"convention must be 'modified' or 'standard'"):
        urdf_from_dh(np.zeros((2, 4)), convention="craig")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"tip_offset must have shape \(3,\) or \(4, 4\)"):
        urdf_from_dh(np.zeros((2, 4)), tip_offset=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"lower must have shape \(2,\)"):
        urdf_from_dh(np.zeros((2, 4)), lower=[0.0, 0.0, 0.0])


def test_dh_scalar_limits_apply_to_every_joint() -> None:
    # documented "shape (n,) or scalar": a scalar used to be refused as shape (1,)
    robot = Robot.from_dh(np.zeros((3, 4)), lower=-1.0, upper=2.0, velocity=1.5, effort=4.0)
    np.testing.assert_array_equal(robot.lower, np.full(3, -1.0))
    np.testing.assert_array_equal(robot.upper, np.full(3, 2.0))
    np.testing.assert_array_equal(robot.velocity_limit, np.full(3, 1.5))
    np.testing.assert_array_equal(robot.effort_limit, np.full(3, 4.0))


# ------------------------------------------------------------------------------------------
# damped pseudo-inverse and null space
# ------------------------------------------------------------------------------------------


def far_from_singular(robot: Robot, rng: np.random.Generator, m: int) -> NDArray[np.float64]:
    q_batch = random_q(robot, rng, 4 * m)
    sigma_min = np.linalg.svd(robot.jacobian(q_batch), compute_uv=False)[:, -1]
    return q_batch[sigma_min > 0.1][:m]


@pytest.mark.parametrize("name", ["katana", "panda"])
def test_damped_pinv_equals_pinv_far_from_singularities(name: str) -> None:
    robot = robots.load(name)
    rng = np.random.default_rng(11)
    jac = robot.jacobian(far_from_singular(robot, rng, 50))
    expected = np.linalg.pinv(jac)
    np.testing.assert_allclose(damped_pinv(jac), expected, rtol=0, atol=1e-12)
    for j, e in zip(jac, expected, strict=True):
        jp = damped_pinv(j)
        np.testing.assert_allclose(jp, e, rtol=0, atol=1e-12)
        np.testing.assert_allclose(j @ jp, np.eye(3), rtol=0, atol=1e-12)
        null = nullspace_projector(j, jp)
        np.testing.assert_allclose(j @ null, 0.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(null @ null, null, rtol=0, atol=1e-12)  # a projector
    np.testing.assert_allclose(nullspace_projector(jac) @ expected, 0.0, rtol=0, atol=1e-12)


def test_damped_pinv_bounded_at_singularity(katana: Robot) -> None:
    # q = 0: the Katana is fully stretched, sigma_min = 0
    j0 = katana.jacobian(np.zeros(5))
    assert np.linalg.svd(j0, compute_uv=False)[-1] < 1e-12
    eps, lambda_max = 0.03, 0.05
    jp = damped_pinv(j0, eps=eps, lambda_max=lambda_max)
    assert np.all(np.isfinite(jp))
    # lambda_max >= eps: every gain sigma / (sigma^2 + lambda^2) is at most 1 / eps
    assert np.linalg.norm(jp, 2) <= 1.0 / eps
    # approaching the singularity along lift2: bounded all the way, continuous at eps
    norms = []
    for q2 in np.geomspace(1e-8, 0.5, 60):
        jac = katana.jacobian([0.0, 0.3, q2, 0.0, 0.0])
        jp = damped_pinv(jac, eps=eps, lambda_max=lambda_max)
        assert np.all(np.isfinite(jp))
        norms.append(np.linalg.norm(jp, 2))
    assert max(norms) <= 1.0 / eps + 1e-9
    # the undamped pseudo-inverse blows up there
    assert np.linalg.norm(np.linalg.pinv(katana.jacobian([0.0, 0.3, 1e-8, 0.0, 0.0])), 2) > 1e6


def test_damped_pinv_formula_and_batches() -> None:
    rng = np.random.default_rng(12)
    jac = rng.normal(size=(4, 3, 6))
    lam = 0.3
    expected = np.array([j.T @ np.linalg.inv(j @ j.T + lam**2 * np.eye(3)) for j in jac])
    np.testing.assert_allclose(damped_pinv(jac, damping=lam), expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(
        damped_pinv(jac[0], damping=lam), expected[0], rtol=1e-12, atol=1e-14
    )
    # single (closed-form 3x3 path) == batch (eigh path), also near singularities
    katana = robots.katana()
    j_batch = katana.jacobian(random_q(katana, rng, 500))
    single = np.array([damped_pinv(j) for j in j_batch])
    np.testing.assert_allclose(single, damped_pinv(j_batch), rtol=0, atol=1e-8)
    # tall and other shapes: undamped equals np.linalg.pinv
    for shape in [(5, 3), (2, 4), (6, 7), (1, 1), (2, 3, 3)]:
        a = rng.normal(size=shape)
        np.testing.assert_allclose(damped_pinv(a, eps=0.0), np.linalg.pinv(a), atol=1e-10)
    # an all-zero Jacobian without damping: the pseudo-inverse is zero, not NaN
    np.testing.assert_array_equal(damped_pinv(np.zeros((3, 5)), damping=0.0), np.zeros((5, 3)))


def test_damping_schedule() -> None:
    lam2 = damping_schedule([0.0, 0.015, 0.03, 0.5], eps=0.03, lambda_max=0.05)
    np.testing.assert_allclose(lam2, [0.0025, 0.0025 * 0.75, 0.0, 0.0], rtol=1e-14, atol=0)


def test_pinv_bad_input() -> None:
    with pytest.raises(ValueError, match=r"J must have shape \(\.\.\., m, n\)"):
        damped_pinv(np.zeros(3))
    with pytest.raises(ValueError, match=r"J must be finite"):
        damped_pinv(np.full((3, 4), np.nan))
    with pytest.raises(ValueError, match=r"eps must be finite and >= 0, got -1"):
        damped_pinv(np.ones((3, 4)), eps=-1.0)
    with pytest.raises(ValueError, match=r"J_pinv must have shape \(4, 3\), got \(3, 4\)"):
        nullspace_projector(np.ones((3, 4)), np.ones((3, 4)))


def test_a_pickled_robot_computes_what_the_original_does() -> None:
    # Worker processes (pbdkit evaluate --workers) receive the skill's robot pickled.
    import pickle

    from pbdkit.robots import katana, panda

    rng = np.random.default_rng(11)
    for robot in (katana(), panda()):
        copy = pickle.loads(pickle.dumps(robot))
        assert copy.joint_names == robot.joint_names and copy.tip == robot.tip
        assert copy.urdf == robot.urdf
        for name in ("lower", "upper", "velocity_limit", "acceleration_limit", "jerk_limit"):
            np.testing.assert_array_equal(getattr(copy, name), getattr(robot, name))
        for q in rng.uniform(robot.lower, robot.upper, (5, robot.n_joints)):
            x, jac = robot.fk_jacobian_unchecked(q)
            x2, jac2 = copy.fk_jacobian_unchecked(q)
            assert np.array_equal(x, x2) and np.array_equal(jac, jac2)
            assert np.array_equal(robot.fk(q), copy.fk(q))


# ------------------------------------------------------------------------------------------
# inverse kinematics (Robot.ik, pbdkit.robots._ik)
# ------------------------------------------------------------------------------------------


def pose_residual(robot: Robot, q: NDArray[np.float64], tf: NDArray[np.float64]) -> float:
    """Norm of [position error (m); rotation vector of R* R^T (rad)]: what ik's tol bounds."""
    reached = robot.fk_pose(q)
    rot_err = log_map(tf[:3, :3] @ reached[:3, :3].T)
    return float(np.linalg.norm(np.r_[tf[:3, 3] - reached[:3, 3], rot_err]))


def regular_postures(robot: Robot, rng: np.random.Generator, m: int) -> NDArray[np.float64]:
    """``m`` random postures 0.2 inside the limits where the 6-D Jacobian is well conditioned
    (its smallest singular value above 0.05): targets a local IK reaches in few steps."""
    q_batch = rng.uniform(robot.lower + 0.2, robot.upper - 0.2, size=(8 * m, robot.n_joints))
    sigma_min = np.linalg.svd(robot.jacobian6(q_batch), compute_uv=False)[:, -1]
    out = q_batch[sigma_min > 0.05][:m]
    assert out.shape[0] == m
    return out


def nearby_start(
    robot: Robot, q: NDArray[np.float64], rng: np.random.Generator
) -> NDArray[np.float64]:
    """A start posture 0.3 rad (sd per joint) from ``q``, within the limits."""
    return np.clip(q + rng.normal(0.0, 0.3, robot.n_joints), robot.lower, robot.upper)


@pytest.mark.parametrize("name", ["katana", "panda"])
@pytest.mark.parametrize("with_orientation", [False, True])
def test_ik_reaches_targets_from_random_postures(name: str, with_orientation: bool) -> None:
    robot = robots.load(name)
    rng = np.random.default_rng(11)
    # Reachable targets: the poses of random postures.
    for q_true in regular_postures(robot, rng, 20):
        tf = robot.fk_pose(q_true)
        q0 = nearby_start(robot, q_true, rng)
        rot = tf[:3, :3] if with_orientation else None
        q = robot.ik(tf[:3, 3], q0, orientation=rot)
        assert q.shape == (robot.n_joints,)
        assert np.all(q >= robot.lower) and np.all(q <= robot.upper)
        if with_orientation:
            assert pose_residual(robot, q, tf) < 1e-4
        else:
            assert np.linalg.norm(robot.fk(q) - tf[:3, 3]) < 1e-4


def test_ik_default_start_is_the_middle_of_the_limits_and_tol_is_kept(panda: Robot) -> None:
    rng = np.random.default_rng(12)
    middle = 0.5 * (panda.lower + panda.upper)
    for q_true in regular_postures(panda, rng, 10):
        x = panda.fk(q_true)
        q = panda.ik(x, tol=1e-9)
        assert np.linalg.norm(panda.fk(q) - x) < 1e-9
        np.testing.assert_array_equal(panda.ik(x, middle, tol=1e-9), q)


def test_ik_accepts_a_kinematic_model_that_is_not_a_robot(katana: Robot) -> None:
    arm = KinematicOnly(katana)
    rng = np.random.default_rng(13)
    q_true = rng.uniform(katana.lower + 0.2, katana.upper - 0.2)
    q0 = nearby_start(katana, q_true, rng)
    q = ik(arm, katana.fk(q_true), q0)  # type: ignore[arg-type]
    np.testing.assert_array_equal(q, katana.ik(katana.fk(q_true), q0))
    with pytest.raises(ValueError, match=r"robot must be a PoseKinematicModel.*lacks fk_pose"):
        ik(arm, katana.fk(q_true), q0, orientation=np.eye(3))  # type: ignore[arg-type]


def test_ik_refuses_unreachable_targets_naming_the_residual(katana: Robot) -> None:
    with pytest.raises(
        ValueError,
        match=r"ik did not converge to the position \[2\.0, 0\.0, 0\.2\]: residual 1\.\d+ "
        r">= tol=0\.0001 after max_iter=200 iterations",
    ):
        katana.ik([2.0, 0.0, 0.2])
    # A reachable position with an orientation the 5 joints cannot give it.
    tf = katana.fk_pose(np.array([0.1, 1.0, -1.0, 0.5, 0.2]))
    with pytest.raises(ValueError, match=r"to the pose .*residual 0\.\d+ >= tol=1e-06 after "):
        katana.ik(tf[:3, 3], orientation=rot_z(0.7) @ tf[:3, :3], tol=1e-6, max_iter=50)


def test_ik_bad_input(katana: Robot) -> None:
    x = katana.fk(np.zeros(5))
    cases: list[tuple[dict[str, object], str]] = [
        ({"target": [0.1, 0.2]}, r"target must have shape \(3,\), got \(2,\)"),
        ({"target": [0.1, np.nan, 0.2]}, "target must be finite"),
        ({"target": [True, False, True]}, "target must be an array of numbers"),
        ({"q0": np.zeros(4)}, r"q0 must have shape \(5,\), got \(4,\)"),
        ({"q0": [0.0, 0.0, np.inf, 0.0, 0.0]}, "q0 must be finite"),
        (
            {"q0": [0.0, -1.0, 0.0, 0.0, 0.0]},
            r"q0\[1\] \(joint 'lift1'\) must be within the joint limits \[-0\.135228, 2\.16857\]"
            r", got -1",
        ),
        ({"orientation": np.eye(2)}, r"orientation must be a rotation matrix \(3, 3\)"),
        ({"orientation": 2.0 * np.eye(3)}, "orientation.*must be a rotation matrix"),
        ({"orientation": np.diag([1.0, 1.0, -1.0])}, "orientation.*determinant"),
        ({"tol": 0.0}, "tol must be finite and > 0, got 0.0"),
        ({"tol": np.nan}, "tol must be finite and > 0"),
        ({"max_iter": 0}, "max_iter must be >= 1, got 0"),
        ({"max_iter": 2.5}, "max_iter must be an integer, got 2.5"),
    ]
    for kwargs, pattern in cases:
        args: dict[str, object] = {"target": x, **kwargs}
        with pytest.raises(ValueError, match=pattern):
            katana.ik(**args)  # type: ignore[arg-type]


def test_damped_least_squares_bounds_the_step_and_reports_the_last_evaluated_error(
    katana: Robot,
) -> None:
    q_true = np.array([0.5, 1.0, -1.2, 0.3, 0.1])
    q0 = q_true + 0.1
    x = katana.fk(q_true)
    common = {"lower": katana.lower, "upper": katana.upper, "tol": 1e-9, "damping": 1e-2}
    q1, err = damped_least_squares(katana, x, q0, max_iter=1, max_step=0.05, **common)
    assert np.linalg.norm(q1 - q0) == pytest.approx(0.05, rel=1e-12)
    assert err == pytest.approx(np.linalg.norm(x - katana.fk(q0)), rel=0, abs=0)
    # Constant rows (the teacher's tool pitch) are met with the position.
    pitch = np.array([[0.0, 1.0, 1.0, -1.0, 0.0]])
    q, err = damped_least_squares(
        katana, x, q0, max_iter=200, rows=pitch, row_targets=(-0.3,), **common
    )
    assert err < 1e-9
    assert float(pitch[0] @ q) == pytest.approx(-0.3, abs=1e-9)
    np.testing.assert_allclose(katana.fk(q), x, rtol=0, atol=1e-9)
