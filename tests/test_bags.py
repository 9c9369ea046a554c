"""ROS bags: teacher demonstrations recorded as bags read back exactly (both rosbag2 storages,
shuffled joint order, a finger joint, objects at 30 Hz); posed objects read back with their
orientation (ROS's x, y, z, w quaternions against scipy's); a skill learned from bags equals one
learned from the arrays; trajectory bags hold the reproduction (read with rosbags' own reader),
with the timing's velocities and accelerations when given; tf, PointStamped, TransformStamped
and fixed sources (positions and poses; orientations through rotated frames, their mean over
noise, invalid quaternions dropped); cuts; every bad input a clear error; the
`pbdkit learn BAG...` and `pbdkit reproduce --bag` commands."""

from __future__ import annotations

import os
import re
import struct
import tracemalloc
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from arms import KinematicOnly
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner, Result

from pbdkit import Demonstration, Robot, Skill, read_bag, write_trajectory_bag
from pbdkit.apps._cli import app
from pbdkit.data import check_trajectory_bag
from pbdkit.data._bag_write import write_demonstration_bag
from pbdkit.data._placement import is_pose, position_of, rotation_of
from pbdkit.motion._limits import MotionLimits
from pbdkit.robots import panda

TS = get_typestore(Stores.ROS2_HUMBLE)
T0 = 1_700_000_000 * 10**9  # ROS time of the first joint state in the hand-written bags (ns)
KATANA_JOINTS = ["pan", "lift1", "lift2", "lift3", "wrist_roll"]
STORAGES = ["sqlite3", "mcap"]
SOURCES = {"glass": "/glass/pose", "coaster": "/coaster/pose"}
N_STEPS = 100
MAX_K = 10


# ----------------------------------------------------------------------------- fixtures
# robot: the Katana of conftest.py.
@pytest.fixture(scope="module")
def demos(fast_demos: Callable[..., list[Demonstration]]) -> list[Demonstration]:
    return fast_demos("coaster", 3, seed=1)


@pytest.fixture(scope="module")
def bags(
    tmp_path_factory: pytest.TempPathFactory, demos: list[Demonstration], robot: Robot
) -> dict[str, list[Path]]:
    """Each teacher demonstration recorded in both storages, as a real arm's driver publishes:
    joints in a new order in every message, a finger joint the arm model does not have."""
    root = tmp_path_factory.mktemp("bags")
    out: dict[str, list[Path]] = {}
    for k, storage in enumerate(STORAGES):
        rng = np.random.default_rng(10 + k)
        out[storage] = []
        for i, d in enumerate(demos):
            path = root / f"{storage}_{i}"
            write_demonstration_bag(
                path,
                d,
                robot.joint_names,
                storage=storage,
                extra_joints={"finger_left": 0.02, "finger_right": 0.021},
                shuffle=rng,
            )
            out[storage].append(path)
    return out


@pytest.fixture(scope="module")
def skill(demos: list[Demonstration], robot: Robot) -> Skill:
    return Skill.learn(demos, robot, n_steps=N_STEPS, max_components=MAX_K)


def _raw(path: Path, topic: str) -> list[tuple[int, Any]]:
    """(log time, message) of a topic, read with rosbags' own reader."""
    with AnyReader([path], default_typestore=TS) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [
            (log, reader.deserialize(raw, c.msgtype))
            for c, log, raw in reader.messages(connections=conns)
        ]


def _stamp(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


def _positions(demo: Demonstration) -> Demonstration:
    """The demonstration with its objects' positions only (a PoseStamped gives a pose)."""
    objects = {k: position_of(v) for k, v in demo.objects.items()}
    return Demonstration(demo.t, demo.joints, objects, gripper=demo.gripper)


def _rotation(value: np.ndarray) -> np.ndarray:
    """The rotation of a placement that must be a pose."""
    rotation = rotation_of(value)
    assert rotation is not None, f"a position, not a pose: {value}"
    return rotation


# ----------------------------------------------------------------------------- hand-written bags
def _header(ns: int, frame: str = "") -> Any:
    time = TS.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return TS.types["std_msgs/msg/Header"](stamp=time, frame_id=frame)


def _joint_state(ns: int, names: Sequence[str], position: Sequence[float]) -> tuple[str, Any]:
    empty = np.zeros(0)
    msg = TS.types["sensor_msgs/msg/JointState"](
        header=_header(ns),
        name=list(names),
        position=np.asarray(position, dtype=np.float64),
        velocity=empty,
        effort=empty,
    )
    return "sensor_msgs/msg/JointState", msg


def _vector(name: str, v: Sequence[float]) -> Any:
    return TS.types[name](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _transform(ns: int, parent: str, child: str, trans: Sequence[float], quat: Any) -> Any:
    x, y, z, w = (float(c) for c in quat)
    tf = TS.types["geometry_msgs/msg/Transform"](
        translation=_vector("geometry_msgs/msg/Vector3", trans),
        rotation=TS.types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )
    return TS.types["geometry_msgs/msg/TransformStamped"](
        header=_header(ns, parent), child_frame_id=child, transform=tf
    )


def _tf_message(ns: int, parent: str, child: str, trans: Sequence[float], quat: Any) -> Any:
    return TS.types["tf2_msgs/msg/TFMessage"](
        transforms=[_transform(ns, parent, child, trans, quat)]
    )


def _tf_entry(
    topic: str, ns: int, parent: str, child: str, trans: Sequence[float], quat: Any
) -> tuple[str, str, int, Any]:
    """A TFMessage of one transform, logged at its stamp."""
    return (topic, "tf2_msgs/msg/TFMessage", ns, _tf_message(ns, parent, child, trans, quat))


def _write(path: Path, messages: list[tuple[str, str, int, Any]], storage: str = "sqlite3") -> Path:
    """A rosbag2 bag of (topic, msgtype, log time ns, message), written with rosbags directly."""
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        conns: dict[str, Any] = {}
        for topic, msgtype, ns, msg in sorted(messages, key=lambda m: m[2]):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=TS)
            writer.write(conns[topic], ns, TS.serialize_cdr(msg, msgtype))
    return path


def _arm_motion(n: int = 50, dt_ns: int = 20_000_000) -> list[tuple[str, str, int, Any]]:
    """n joint states of the Katana at 50 Hz, stamped from T0."""
    out = []
    for i in range(n):
        ns = T0 + i * dt_ns
        msgtype, msg = _joint_state(ns, KATANA_JOINTS, 0.01 * i + np.arange(5.0))
        out.append(("/joint_states", msgtype, ns, msg))
    return out


def _set_joint_state(
    msgs: list[tuple[str, str, int, Any]],
    k: int,
    *,
    names: Sequence[str] = KATANA_JOINTS,
    stamp: int | None = None,
    log: int | None = None,
) -> None:
    """Message k of :func:`_arm_motion` replaced by one naming ``names`` (positions zero),
    logged at ``log`` (default: as it was) and stamped ``stamp`` (default: its log time)."""
    topic, msgtype, ns, _ = msgs[k]
    log_ns = ns if log is None else log
    stamp_ns = log_ns if stamp is None else stamp
    msgs[k] = (topic, msgtype, log_ns, _joint_state(stamp_ns, names, [0.0] * len(names))[1])


# ----------------------------------------------------------------------------- round trip
@pytest.mark.parametrize("storage", STORAGES)
def test_teacher_demonstrations_read_back_exactly(
    bags: dict[str, list[Path]], demos: list[Demonstration], robot: Robot, storage: str
) -> None:
    for path, d in zip(bags[storage], demos, strict=True):
        back = read_bag(path, robot=robot, objects=SOURCES, gripper_topic="/gripper")
        np.testing.assert_array_equal(back.joints, d.joints)  # float64 in, float64 out
        np.testing.assert_allclose(back.t, d.t - d.t[0], rtol=0, atol=1e-6)
        assert back.t[0] == 0.0
        assert back.object_names == ("glass", "coaster")
        for name in SOURCES:
            # A PoseStamped gives a pose: the position exactly, the identity orientation that
            # was written for an object given as a position.
            np.testing.assert_array_equal(position_of(back.objects[name]), d.objects[name])
            np.testing.assert_allclose(_rotation(back.objects[name]), np.eye(3), atol=1e-12)
        assert d.gripper is not None and back.gripper is not None
        np.testing.assert_array_equal(back.gripper > 0.5, d.gripper > 0.5)
        assert 0 < np.count_nonzero(back.gripper) < back.n_steps  # it opens and closes


@pytest.mark.parametrize("storage", STORAGES)
def test_posed_objects_read_back_with_their_orientation(
    tmp_path: Path, demos: list[Demonstration], robot: Robot, storage: str
) -> None:
    # Objects given as (x, y, z, qw, qx, qy, qz) (w first), as a 4x4 and as a position: each
    # PoseStamped carries the orientation, read back to 1e-9; compared with scipy's rotations,
    # whose quaternions are (x, y, z, w) as ROS's.
    rng = np.random.default_rng(23)
    r_glass = Rotation.from_quat(rng.normal(size=4))  # uniform on SO(3)
    r_coaster = Rotation.from_quat(rng.normal(size=4))
    d = demos[0]
    x, y, z, w = r_glass.as_quat()
    coaster = np.eye(4)
    coaster[:3, :3], coaster[:3, 3] = r_coaster.as_matrix(), d.objects["coaster"]
    objects = {
        "glass": [*d.objects["glass"], w, x, y, z],
        "coaster": coaster,
        "basin": [0.3, -0.1, 0.0],
    }
    posed = Demonstration(d.t, d.joints, objects, gripper=d.gripper)
    path = tmp_path / "posed"
    write_demonstration_bag(path, posed, robot.joint_names, storage=storage)
    # In the bag: ROS's (x, y, z, w), which is scipy's order (q and -q: the same rotation).
    for name, rot in [("glass", r_glass), ("coaster", r_coaster)]:
        for _, msg in _raw(path, f"/{name}/pose"):
            q = msg.pose.orientation
            wire = np.array([q.x, q.y, q.z, q.w])
            sign = 1.0 if wire @ rot.as_quat() > 0 else -1.0
            np.testing.assert_allclose(sign * wire, rot.as_quat(), rtol=0, atol=1e-12)
    back = read_bag(path, robot=robot, objects={n: f"/{n}/pose" for n in objects})
    np.testing.assert_array_equal(back.joints, d.joints)
    for name, rot in [("glass", r_glass), ("coaster", r_coaster)]:
        np.testing.assert_array_equal(
            position_of(back.objects[name]), position_of(posed.objects[name])
        )
        np.testing.assert_allclose(_rotation(back.objects[name]), rot.as_matrix(), atol=1e-9)
    # A position is written with the identity orientation: it comes back as that pose.
    np.testing.assert_array_equal(position_of(back.objects["basin"]), [0.3, -0.1, 0.0])
    np.testing.assert_allclose(_rotation(back.objects["basin"]), np.eye(3), atol=1e-12)


def test_recorded_bags_are_what_a_real_driver_writes(
    bags: dict[str, list[Path]], demos: list[Demonstration]
) -> None:
    # The recordings exercise the reader: the joint order changes between messages, a finger
    # joint is there, the objects come at 30 Hz, and the storage is the one asked for.
    path = bags["mcap"][0]
    assert {p.name for p in path.iterdir()} == {"metadata.yaml", "mcap_0.mcap"}
    assert {p.name for p in bags["sqlite3"][0].iterdir()} == {"metadata.yaml", "sqlite3_0.db3"}
    joints = _raw(path, "/joint_states")
    orders = {tuple(m.name) for _, m in joints[:20]}
    assert len(orders) > 10
    assert all(set(o) == {*KATANA_JOINTS, "finger_left", "finger_right"} for o in orders)
    poses = _raw(path, "/glass/pose")
    stamps = np.array([_stamp(m) for _, m in poses])
    np.testing.assert_allclose(np.diff(stamps) * 1e-9, 1 / 30, atol=1e-9)
    assert len(poses) == int(demos[0].duration * 30) + 1
    assert _stamp(joints[0][1]) == T0 and joints[0][0] == T0


def test_skill_from_bags_equals_skill_from_arrays(
    bags: dict[str, list[Path]], robot: Robot, skill: Skill
) -> None:
    paths = [bags["sqlite3"][0], bags["mcap"][1], bags["sqlite3"][2]]  # both storages
    from_bags = [
        _positions(read_bag(p, robot=robot, objects=SOURCES, gripper_topic="/gripper"))
        for p in paths
    ]
    learned = Skill.learn(from_bags, robot, n_steps=N_STEPS, max_components=MAX_K)
    assert learned.n_components == skill.n_components
    a, b = learned.constraints(), skill.constraints()
    np.testing.assert_allclose(a.joint_mean, b.joint_mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.joint_cov, b.joint_cov, rtol=1e-7, atol=1e-15)
    assert a.gripper is not None and b.gripper is not None
    np.testing.assert_allclose(a.gripper, b.gripper, rtol=0, atol=1e-9)
    for name in SOURCES:
        np.testing.assert_allclose(a.task_mean[name], b.task_mean[name], rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.task_cov[name], b.task_cov[name], rtol=1e-7, atol=1e-15)
    objects = {"glass": [0.48, 0.2, 0.175], "coaster": [0.5, -0.15, 0.006]}
    ra, rb = learned.reproduce(objects), skill.reproduce(objects)
    np.testing.assert_allclose(ra.joints, rb.joints, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(ra.gripper, rb.gripper)


@pytest.mark.parametrize("storage", STORAGES)
def test_trajectory_bag_holds_the_reproduction(
    tmp_path: Path, skill: Skill, robot: Robot, storage: str
) -> None:
    res = skill.reproduce({"glass": [0.47, 0.18, 0.175], "coaster": [0.49, -0.17, 0.006]})
    times = skill.times(res)
    path = tmp_path / "trajectory"
    write_trajectory_bag(
        path,
        times,
        res.joints,
        robot.joint_names,
        gripper=res.gripper,
        storage=storage,
        limits=MotionLimits.from_robot(robot, 5),  # the Katana's, the reproduction's timing's
    )
    assert not list(tmp_path.glob(".*"))  # the temporary directory is gone
    with AnyReader([path], default_typestore=TS) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types == {
        "/joint_trajectory": "trajectory_msgs/msg/JointTrajectory",
        "/gripper": "std_msgs/msg/Bool",
    }
    ((log, msg),) = _raw(path, "/joint_trajectory")
    assert log == 0 and _stamp(msg) == 0  # stamp zero: the controller starts on receipt
    assert list(msg.joint_names) == robot.joint_names
    assert len(msg.points) == len(res.joints)  # the steps and the lead-in from q0
    positions = np.stack([p.positions for p in msg.points])
    np.testing.assert_array_equal(positions, res.joints)
    # Without velocities and accelerations the points carry positions only.
    assert all(len(p.velocities) == len(p.accelerations) == len(p.effort) == 0 for p in msg.points)
    tfs = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points])
    np.testing.assert_allclose(tfs, times, rtol=0, atol=1e-9)
    # The gripper: Bool messages at its changes, held between them, equal the reproduction's.
    grip = _raw(path, "/gripper")
    logs = np.array([log for log, _ in grip])
    closed = np.array([m.data for _, m in grip])
    held = closed[np.searchsorted(logs, np.round(times * 1e9), side="right") - 1]
    np.testing.assert_array_equal(held, res.gripper)
    assert 2 <= len(grip) < N_STEPS // 4


def _derivatives(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """The velocities and accelerations of a JointTrajectory's points, (T, n) each."""
    return (
        np.stack([p.velocities for p in msg.points]),
        np.stack([p.accelerations for p in msg.points]),
    )


@pytest.mark.parametrize("storage", STORAGES)
def test_trajectory_bag_carries_the_timing_velocities_and_accelerations(
    tmp_path: Path, skill: Skill, robot: Robot, storage: str
) -> None:
    res = skill.reproduce({"glass": [0.47, 0.18, 0.175], "coaster": [0.49, -0.17, 0.006]})
    assert res.velocities is not None and res.accelerations is not None  # the Katana's limits
    path = tmp_path / "trajectory"
    write_trajectory_bag(
        path,
        skill.times(res),
        res.joints,
        robot.joint_names,
        gripper=res.gripper,
        velocities=res.velocities,
        accelerations=res.accelerations,
        storage=storage,
        limits=MotionLimits.from_robot(robot, 5),
    )
    ((_, msg),) = _raw(path, "/joint_trajectory")
    vel, acc = _derivatives(msg)
    np.testing.assert_array_equal(vel, res.velocities)  # float64 in, float64 out: exact
    np.testing.assert_array_equal(acc, res.accelerations)
    np.testing.assert_array_equal(np.stack([p.positions for p in msg.points]), res.joints)
    assert all(len(p.effort) == 0 for p in msg.points)
    np.testing.assert_allclose(vel[[0, -1]], 0.0, rtol=0, atol=1e-12)  # at rest at both ends
    assert np.abs(vel).max() > 0.01 and np.abs(acc).max() > 0.01  # and moving in between


def test_trajectory_bag_with_velocities_alone(tmp_path: Path, robot: Robot) -> None:
    # Arbitrary values (not from a timing) round-trip bit for bit; accelerations stay empty.
    rng = np.random.default_rng(3)
    q, v = rng.normal(size=(4, 5)), rng.normal(size=(4, 5)) * 1e-7
    v[1, 2] = -0.0
    unlimited = MotionLimits.from_robot(robot, 5, velocity=None, acceleration=None, jerk=None)
    write_trajectory_bag(
        tmp_path / "v",
        [0.0, 0.1, 0.25, 0.5],
        q,
        robot.joint_names,
        velocities=v.tolist(),
        limits=unlimited,  # checked against none: written as given
    )
    ((_, msg),) = _raw(tmp_path / "v", "/joint_trajectory")
    np.testing.assert_array_equal(np.stack([p.velocities for p in msg.points]), v)
    assert np.signbit(msg.points[1].velocities[2])
    assert all(len(p.accelerations) == 0 for p in msg.points)


def test_trajectory_bag_refuses_a_jump(tmp_path: Path, skill: Skill, robot: Robot) -> None:
    # Issue 35: a URDF-only arm's reproduction went from rest to speed in one sample and was
    # written without a word. Without limits= the bag is checked against those an arm without
    # any is assumed to have (from the trajectory's own top speed); with them, against them.
    res = skill.reproduce({"glass": [0.47, 0.18, 0.175], "coaster": [0.49, -0.17, 0.006]})
    times = skill.times(res)
    katana = MotionLimits.from_robot(robot, 5)
    write_trajectory_bag(tmp_path / "ok", times, res.joints, robot.joint_names, limits=katana)
    # The same postures at one step per 10 ms: from rest to speed in one step.
    fast = 0.01 * np.arange(len(times))
    for limits in (None, katana):
        with pytest.raises(
            ValueError, match=r"exceeds the limit.* on '.*': (velocity|acceleration)"
        ):
            write_trajectory_bag(
                tmp_path / "jump", fast, res.joints, robot.joint_names, limits=limits
            )
        with pytest.raises(ValueError, match="exceeds"):
            check_trajectory_bag(fast, res.joints, robot.joint_names, limits=limits)
    assert not (tmp_path / "jump").exists()
    # A step from rest at the first point: refused without limits too.
    q = np.zeros((20, 5))
    q[10:, 1] = 0.1
    with pytest.raises(
        ValueError, match=r"assumed for an arm without one on 'lift1': acceleration"
    ):
        write_trajectory_bag(tmp_path / "step", 0.01 * np.arange(20), q, robot.joint_names)
    # Limits for another arm: refused, named.
    with pytest.raises(ValueError, match="limits are for 7 joints, the trajectory has 5"):
        check_trajectory_bag(
            times, res.joints, robot.joint_names, limits=MotionLimits.from_robot(panda(), 7)
        )


# ----------------------------------------------------------------------------- object sources
@pytest.mark.parametrize("storage", STORAGES)
def test_tf_frame_two_levels_with_rotation(tmp_path: Path, robot: Robot, storage: str) -> None:
    r_cam = Rotation.from_euler("zyx", [40.0, -25.0, 110.0], degrees=True)
    p_cam = np.array([0.1, -0.4, 0.9])
    r_glass = Rotation.from_euler("xyz", [10.0, 0.0, -30.0], degrees=True)
    p_glass = np.array([0.2, 0.05, 0.7])  # the glass seen by the camera
    msgs = _arm_motion()
    for k in range(31):  # 30 Hz over the first second (both ends), then the glass is carried
        ns = T0 + k * 33_333_333
        sign = -1.0 if k % 2 else 1.0  # q and -q: the same rotation
        msgs.append(_tf_entry("/tf", ns, "base_link", "camera", p_cam, sign * r_cam.as_quat()))
        msgs.append(_tf_entry("/tf", ns, "camera", "glass", p_glass, r_glass.as_quat()))
    late = T0 + 2 * 10**9
    msgs.append(_tf_entry("/tf", late, "camera", "glass", p_glass + 0.3, r_glass.as_quat()))
    msgs.append(_tf_entry("/tf", late, "base_link", "camera", p_cam, [0.0, 0.0, 0.0, 1.0]))
    path = _write(tmp_path / "tf", msgs, storage)
    back = read_bag(path, robot=robot, objects={"glass": "tf:glass"})
    expected = r_cam.apply(p_glass) + p_cam  # base <- camera <- glass
    np.testing.assert_allclose(position_of(back.objects["glass"]), expected, rtol=0, atol=1e-12)
    assert np.linalg.norm(expected - p_glass) > 0.1  # the rotation matters
    # The glass's orientation in the base frame: the camera's rotation, then the glass's in it.
    rotation = _rotation(back.objects["glass"])
    np.testing.assert_allclose(rotation, (r_cam * r_glass).as_matrix(), rtol=0, atol=1e-12)
    assert np.abs(rotation - r_glass.as_matrix()).max() > 0.5  # the camera's rotation matters


def test_tf_with_a_common_root_and_a_point_in_the_camera_frame(
    tmp_path: Path, robot: Robot
) -> None:
    # world -> base_link and world -> camera (static); the glass is a PointStamped in the
    # camera frame: expressed in the base frame through tf (tf2's lookup via the common root),
    # a position still; the mug a PoseStamped in the camera frame: a pose, its orientation
    # turned through tf as its position is.
    r_base = Rotation.from_euler("z", 90.0, degrees=True)
    p_base = np.array([1.0, 0.5, 0.0])
    r_cam = Rotation.from_euler("xz", [180.0, 20.0], degrees=True)
    p_cam = np.array([1.2, 0.1, 1.5])
    point = np.array([0.05, -0.1, 1.2])
    msgs = _arm_motion()
    static = TS.types["tf2_msgs/msg/TFMessage"](
        transforms=[
            _transform(0, "world", "base_link", p_base, r_base.as_quat()),
            _transform(0, "/world", "camera", p_cam, r_cam.as_quat()),  # ROS 1 style name
        ]
    )
    msgs.append(("/tf_static", "tf2_msgs/msg/TFMessage", T0, static))
    pt = TS.types["geometry_msgs/msg/PointStamped"](
        header=_header(T0 + 10**8, "camera"), point=_vector("geometry_msgs/msg/Point", point)
    )
    msgs.append(("/glass/point", "geometry_msgs/msg/PointStamped", T0 + 10**8, pt))
    r_mug = Rotation.from_euler("zyx", [-70.0, 35.0, 15.0], degrees=True)
    p_mug = np.array([-0.2, 0.15, 1.1])
    mug = _pose(T0 + 2 * 10**8, p_mug, "camera", r_mug.as_quat())
    msgs.append(("/mug/pose", "geometry_msgs/msg/PoseStamped", T0 + 2 * 10**8, mug))
    path = _write(tmp_path / "root", msgs)
    back = read_bag(
        path,
        robot=robot,
        objects={"glass": "/glass/point", "cam": "tf:camera", "mug": "/mug/pose"},
    )
    in_world = r_cam.apply(point) + p_cam
    expected = r_base.inv().apply(in_world - p_base)
    assert back.objects["glass"].shape == (3,)  # a PointStamped: a position
    np.testing.assert_allclose(back.objects["glass"], expected, rtol=0, atol=1e-12)
    assert is_pose(back.objects["cam"])
    np.testing.assert_allclose(
        position_of(back.objects["cam"]), r_base.inv().apply(p_cam - p_base), rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        _rotation(back.objects["cam"]), (r_base.inv() * r_cam).as_matrix(), rtol=0, atol=1e-12
    )
    # T_base_mug = T_world_base^-1 T_world_camera T_camera_mug, composed by scipy.
    np.testing.assert_allclose(
        position_of(back.objects["mug"]),
        r_base.inv().apply(r_cam.apply(p_mug) + p_cam - p_base),
        rtol=0,
        atol=1e-12,
    )
    np.testing.assert_allclose(
        _rotation(back.objects["mug"]),
        (r_base.inv() * r_cam * r_mug).as_matrix(),
        rtol=0,
        atol=1e-12,
    )


def test_tf_frame_not_joined_to_the_base_names_the_chains(tmp_path: Path, robot: Robot) -> None:
    msgs = _arm_motion()
    unit = [0.0, 0.0, 0.0, 1.0]
    msgs.append(_tf_entry("/tf", T0, "map", "camera", [0, 0, 1], unit))
    msgs.append(_tf_entry("/tf", T0 + 1, "camera", "glass", [0, 0, 1], unit))
    path = _write(tmp_path / "apart", msgs)
    with pytest.raises(ValueError, match=r"glass <- camera <- map and base_link end in different"):
        read_bag(path, robot=robot, objects={"glass": "tf:glass"})
    no_tf = _write(tmp_path / "no_tf", _arm_motion())
    with pytest.raises(ValueError, match=r"neither /tf nor /tf_static"):
        read_bag(no_tf, robot=robot, objects={"glass": "tf:glass"})


def test_point_and_transform_stamped_median_over_the_first_second(
    tmp_path: Path, robot: Robot
) -> None:
    rng = np.random.default_rng(7)
    truth = {"glass": np.array([0.45, 0.2, 0.175]), "coaster": np.array([0.5, -0.2, 0.006])}
    msgs = _arm_motion(n=150)  # 3 s of joint states
    first: dict[str, list[np.ndarray]] = {"glass": [], "coaster": []}
    for k in range(90):  # 30 Hz for 3 s; the first second counts
        ns = T0 + k * 33_333_333
        seen = {n: p + rng.normal(0.0, 0.002, 3) for n, p in truth.items()}
        if k == 5:
            seen["glass"] = seen["glass"] + 0.5  # a perception outlier
        if k > 30:
            seen = {n: p + 0.2 for n, p in seen.items()}  # the objects are moved
        else:
            for n in first:
                first[n].append(seen[n])
        point = TS.types["geometry_msgs/msg/PointStamped"](
            header=_header(ns, "base_link"),
            point=_vector("geometry_msgs/msg/Point", seen["glass"]),
        )
        msgs.append(("/glass/point", "geometry_msgs/msg/PointStamped", ns, point))
        tr = _transform(ns, "", "coaster", seen["coaster"], [0.0, 0.0, 0.0, 1.0])
        msgs.append(("/coaster/tf", "geometry_msgs/msg/TransformStamped", ns, tr))
    path = _write(tmp_path / "points", msgs, "mcap")
    back = read_bag(path, robot=robot, objects={"glass": "/glass/point", "coaster": "/coaster/tf"})
    assert len(first["glass"]) == 31  # stamps 0 .. 1 s, both ends kept
    assert back.objects["glass"].shape == (3,)  # a PointStamped: a position
    assert is_pose(back.objects["coaster"])  # a TransformStamped: a pose (identity here)
    np.testing.assert_allclose(_rotation(back.objects["coaster"]), np.eye(3), atol=1e-12)
    for name in truth:
        position = position_of(back.objects[name])
        np.testing.assert_array_equal(position, np.median(first[name], axis=0))
        assert np.linalg.norm(position - truth[name]) < 0.003  # outlier ignored


def _karcher_mean(rotations: Rotation) -> Rotation:
    """The Karcher mean of rotations with scipy's maps, in the right tangent space: a reference
    independent of pbdkit's (its fixed point is the same: the geodesic distance is
    bi-invariant)."""
    mean = rotations[0]
    for _ in range(100):
        step = (mean.inv() * rotations).as_rotvec().mean(axis=0)
        mean = mean * Rotation.from_rotvec(step)
        if np.linalg.norm(step) < 1e-14:
            break
    return mean


def test_a_noisy_orientation_stream_gives_its_mean(tmp_path: Path, robot: Robot) -> None:
    # A mug's PoseStamped and a tray's TransformStamped at 30 Hz, about 5 degrees of noise:
    # the Karcher mean of the first second's orientations, close to the truth. Quaternions come
    # with either sign and unnormalized; a zero or NaN one is dropped (its position counts).
    rng = np.random.default_rng(11)
    truth = Rotation.from_euler("zyx", [120.0, -40.0, 75.0], degrees=True)
    where = np.array([0.45, 0.2, 0.175])
    turn = Rotation.from_euler("z", 90.0, degrees=True)
    r_cam = Rotation.from_euler("xyz", [-100.0, 5.0, 30.0], degrees=True)
    msgs = _arm_motion(n=100)
    kept: list[Rotation] = []
    first: list[np.ndarray] = []
    for k in range(45):
        ns = T0 + k * 33_333_333
        seen = Rotation.from_rotvec(rng.normal(0.0, 0.05, 3)) * truth
        p = where + rng.normal(0.0, 0.001, 3)
        if k > 30:
            seen = turn * seen  # after the first second: the mug is turned, not counted
        quat = seen.as_quat()
        if k % 3 == 1:
            quat = -quat
        if k % 4 == 2:
            quat = 2.5 * quat
        if k == 7:
            quat = np.zeros(4)  # a tracker's "no orientation"
        if k == 8:
            quat = np.array([np.nan, 0.0, 0.0, 1.0])
        if k <= 30:
            first.append(p)
            if k not in (7, 8):
                kept.append(seen)
        msgs.append(("/mug/pose", "geometry_msgs/msg/PoseStamped", ns, _pose(ns, p, quat=quat)))
        tray = _transform(ns, "base_link", "tray", p, quat)
        msgs.append(("/tray/tf", "geometry_msgs/msg/TransformStamped", ns, tray))
        # tf: the same rule. The first sample's zero quaternion was the reference of the signs.
        cam = np.zeros(4) if k == 0 else (-1.0) ** k * r_cam.as_quat()
        msgs.append(_tf_entry("/tf", ns, "base_link", "camera", [0.1, 0.2, 0.3], cam))
    path = _write(tmp_path / "noisy", msgs)
    back = read_bag(
        path, robot=robot, objects={"mug": "/mug/pose", "tray": "/tray/tf", "cam": "tf:camera"}
    )
    assert len(kept) == 29 and len(first) == 31
    reference = _karcher_mean(Rotation.concatenate(kept))
    for name in ("mug", "tray"):
        rotation = _rotation(back.objects[name])
        np.testing.assert_allclose(rotation, reference.as_matrix(), rtol=0, atol=1e-9)
        error = (Rotation.from_matrix(rotation) * truth.inv()).magnitude()
        assert error < np.radians(2.0), np.degrees(error)
        np.testing.assert_array_equal(position_of(back.objects[name]), np.median(first, axis=0))
    np.testing.assert_allclose(_rotation(back.objects["cam"]), r_cam.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(position_of(back.objects["cam"]), [0.1, 0.2, 0.3], atol=1e-15)


def test_a_pose_without_any_orientation_is_refused(tmp_path: Path, robot: Robot) -> None:
    # Every quaternion of the first second zero or NaN: no orientation to keep. A valid one on
    # a message whose position is NaN does not count.
    msgs = _arm_motion(n=60)
    for k in range(31):
        ns = T0 + k * 33_333_333
        quat = np.zeros(4) if k % 2 else np.array([0.0, np.inf, 0.0, 1.0])
        msgs.append(
            (
                "/mug/pose",
                "geometry_msgs/msg/PoseStamped",
                ns,
                _pose(ns, [0.4, 0.1, 0.2], quat=quat),
            )
        )
        tray = _transform(ns, "base_link", "tray", [0.5, 0.0, 0.0], quat)
        msgs.append(("/tray/tf", "geometry_msgs/msg/TransformStamped", ns, tray))
    lost = _pose(T0 + 5_000_000, [np.nan] * 3)  # the identity orientation, no position
    msgs.append(("/mug/pose", "geometry_msgs/msg/PoseStamped", T0 + 5_000_000, lost))
    path = _write(tmp_path / "no_orientation", msgs)
    for name, topic, field in [
        ("mug", "/mug/pose", "pose.orientation"),
        ("tray", "/tray/tf", "transform.rotation"),
    ]:
        with pytest.raises(
            ValueError,
            match=rf"^{re.escape(str(path))}: objects\['{name}'\]: none of the 31 message\(s\) "
            rf"of '{topic}' with a finite position stamped within the first second of the "
            rf"demonstration holds an orientation: their quaternions \({re.escape(field)}: x, "
            r"y, z, w\) are all zero, NaN or infinite\. Give the pose as x,y,z,qw,qx,qy,qz "
            r"\(quaternion w first\), or choose start",
        ):
            read_bag(path, robot=robot, objects={name: topic})


def test_fixed_pose_sources(bags: dict[str, list[Path]], robot: Robot) -> None:
    # A fixed source may be a pose: (x, y, z, qw, qx, qy, qz), the quaternion w first, or 4x4.
    path = bags["sqlite3"][1]
    rot = Rotation.from_euler("xyz", [30.0, -60.0, 145.0], degrees=True)
    x, y, z, w = rot.as_quat()
    tray = np.eye(4)
    tray[:3, :3], tray[:3, 3] = rot.inv().as_matrix(), [0.5, -0.2, 0.0]
    back = read_bag(
        path,
        robot=robot,
        objects={"glass": [0.4, 0.1, 0.2, w, x, y, z], "tray": tray, "basin": (0.5, 0.0, 0.0)},
    )
    np.testing.assert_array_equal(position_of(back.objects["glass"]), [0.4, 0.1, 0.2])
    np.testing.assert_allclose(_rotation(back.objects["glass"]), rot.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(back.objects["tray"], tray, rtol=0, atol=1e-12)
    assert back.objects["basin"].shape == (3,)
    forms = r"a topic, 'tf:frame', a position \(3,\) or a pose \(4x4, or x, y, z, qw, qx, qy, qz"
    for objects, match in [
        (
            {"glass": [0.4, 0.1, 0.2, 0.0, 0.0, 0.0, 0.0]},
            r"objects\['glass'\]: the quaternion "
            r"\(qw, qx, qy, qz\) = \[0\.0, 0\.0, 0\.0, 0\.0\] has zero norm",
        ),
        (
            {"glass": [1.0, 2.0, 3.0, 4.0]},
            r"objects\['glass'\] must be a position \(3,\), a "
            r"4x4 transform or \(x, y, z, qw, qx, qy, qz\) \(quaternion w first\), got an array "
            r"of shape \(4,\)",
        ),
        (
            {"glass": np.diag([1.0, 1.0, -1.0, 1.0])},
            r"objects\['glass'\]: the rotation block "
            r"of a 4x4 transform must be a rotation matrix",
        ),
        ({"glass": [0.4, np.nan, 0.2]}, r"objects\['glass'\] must be finite"),
        ({"glass": ["0.4", "0.1", "0.2"]}, r"objects\['glass'\] must be an array of numbers"),
        ({"glass": "tf:"}, rf"objects\['glass'\] must be {forms}"),
        ([0.4, 0.1, 0.2], rf"objects must be a dict mapping object names to {forms}"),
    ]:
        with pytest.raises(ValueError, match=match):
            read_bag(path, robot=robot, objects=objects)  # type: ignore[arg-type]


def test_fixed_position_source_and_no_objects(bags: dict[str, list[Path]], robot: Robot) -> None:
    path = bags["sqlite3"][1]
    back = read_bag(
        path, robot=robot, objects={"glass": [0.4, 0.1, 0.2], "coaster": "/coaster/pose"}
    )
    np.testing.assert_array_equal(back.objects["glass"], [0.4, 0.1, 0.2])
    assert back.gripper is None  # no gripper_topic: no gripper signal
    bare = read_bag(path, robot=robot)
    assert bare.object_names == () and bare.n_steps == back.n_steps


def test_float64_gripper_is_held_between_messages(tmp_path: Path, robot: Robot) -> None:
    msgs = _arm_motion(n=50)  # joint states at T0 + 20 ms * i, logged at their stamps
    float_cls = TS.types["std_msgs/msg/Float64"]
    for i, value in [(5, 0.2), (10, 0.9), (30, 0.51), (40, 0.3)]:
        msgs.append(
            ("/gripper", "std_msgs/msg/Float64", T0 + i * 20_000_000, float_cls(data=value))
        )
    path = _write(tmp_path / "grip", msgs)
    back = read_bag(path, robot=robot, gripper_topic="/gripper")
    expected = np.zeros(50)
    expected[10:40] = 1.0  # open before the first message, closed where > 0.5
    np.testing.assert_array_equal(back.gripper, expected)


def test_start_and_end_cut_a_longer_bag(
    bags: dict[str, list[Path]], demos: list[Demonstration], robot: Robot
) -> None:
    d = demos[0]
    assert d.gripper is not None
    closes = float(d.t[int(np.argmax(d.gripper > 0.5))])
    start, end = closes + 0.5, closes + 4.0  # the gripper is closed at the cut: held from before
    back = read_bag(
        bags["mcap"][0],
        robot=robot,
        objects=SOURCES,
        gripper_topic="/gripper",
        start=start,
        end=end,
    )
    rel = d.t - d.t[0]
    keep = (np.round(rel * 1e9) >= round(start * 1e9)) & (np.round(rel * 1e9) <= round(end * 1e9))
    np.testing.assert_array_equal(back.joints, d.joints[keep])
    np.testing.assert_allclose(back.t, rel[keep] - rel[keep][0], rtol=0, atol=1e-6)
    assert back.t[0] == 0.0 and abs(back.duration - (end - start)) < 0.011
    assert back.gripper is not None
    np.testing.assert_array_equal(back.gripper > 0.5, d.gripper[keep] > 0.5)
    assert back.gripper[0] == 1.0
    for name in SOURCES:  # located in the first second after the cut
        np.testing.assert_array_equal(position_of(back.objects[name]), d.objects[name])


def _write_ros1(path: Path, positions: np.ndarray) -> Path:
    """A ROS 1 bag of joint states at 100 Hz from T0, each listing the joints reversed."""
    ts1 = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(path) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts1)
        for i, row in enumerate(positions):
            ns = T0 + i * 10**7
            stamp = ts1.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
            header = ts1.types["std_msgs/msg/Header"](seq=i, stamp=stamp, frame_id="")
            msg = ts1.types["sensor_msgs/msg/JointState"](
                header=header,
                name=KATANA_JOINTS[::-1],
                position=row[::-1].copy(),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
            writer.write(conn, ns, ts1.serialize_ros1(msg, "sensor_msgs/msg/JointState"))
    return path


def test_ros1_bag(tmp_path: Path, robot: Robot) -> None:
    positions = np.random.default_rng(2).normal(size=(20, 5))
    path = _write_ros1(tmp_path / "demo.bag", positions)
    back = read_bag(path, robot=robot)
    np.testing.assert_array_equal(back.joints, positions)
    np.testing.assert_allclose(back.t, np.arange(20) * 0.01, rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- bad input
def test_missing_topic_lists_the_topics(bags: dict[str, list[Path]], robot: Robot) -> None:
    path = bags["sqlite3"][0]
    with pytest.raises(
        ValueError, match=r"joint_topic: the bag .* has no topic '/arm/joints'"
    ) as e:
        read_bag(path, robot=robot, joint_topic="/arm/joints")
    assert "/joint_states (sensor_msgs/msg/JointState)" in str(e.value)
    assert "/glass/pose (geometry_msgs/msg/PoseStamped)" in str(e.value)
    with pytest.raises(ValueError, match=r"objects\['cup'\]: .* no topic '/cup/pose'"):
        read_bag(path, robot=robot, objects={"cup": "/cup/pose"})


def test_wrong_type_names_expected_and_actual(bags: dict[str, list[Path]], robot: Robot) -> None:
    path = bags["mcap"][0]
    with pytest.raises(
        ValueError,
        match=r"objects\['glass'\]: topic '/gripper' must be of type "
        r"geometry_msgs/msg/PoseStamped or .*TransformStamped, got std_msgs/msg/Bool",
    ):
        read_bag(path, robot=robot, objects={"glass": "/gripper"})
    with pytest.raises(ValueError, match=r"gripper_topic: .* got geometry_msgs/msg/PoseStamped"):
        read_bag(path, robot=robot, gripper_topic="/glass/pose")
    with pytest.raises(ValueError, match=r"must be of type sensor_msgs/msg/JointState, got std_m"):
        read_bag(path, robot=robot, joint_topic="/gripper")


def test_non_monotonic_stamps(tmp_path: Path, robot: Robot) -> None:
    msgs = _arm_motion(n=10)
    _set_joint_state(msgs, 6, stamp=T0 + 3 * 20_000_000)
    path = _write(tmp_path / "jump", msgs)
    with pytest.raises(
        ValueError,
        match=r"must increase strictly in recording order; message 6 is stamped "
        r"1700000000\.060000000 s, not after message 5 \(1700000000\.100000000 s\)",
    ):
        read_bag(path, robot=robot)


def test_missing_joint_is_named(tmp_path: Path, robot: Robot) -> None:
    msgs = _arm_motion(n=5)
    _set_joint_state(msgs, 3, names=["pan", "lift1", "lift2", "lift3", "finger"])
    path = _write(tmp_path / "no_roll", msgs)
    with pytest.raises(
        ValueError, match=r"joint\(s\) \['wrist_roll'\] of the robot missing from message 3 "
    ):
        read_bag(path, robot=robot)


def test_messages_of_another_driver_on_the_topic_are_skipped(tmp_path: Path, robot: Robot) -> None:
    # A gripper driver publishing its fingers on /joint_states too, at the same stamps.
    arm = _arm_motion(n=10)
    fingers = []
    for _, _, ns, _ in arm:
        msgtype, msg = _joint_state(ns, ["finger_a", "finger_b"], [0.01, 0.01])
        fingers.append(("/joint_states", msgtype, ns, msg))
    path = _write(tmp_path / "two_drivers", arm + fingers)
    back = read_bag(path, robot=robot)
    np.testing.assert_array_equal(back.joints, [0.01 * i + np.arange(5.0) for i in range(10)])
    only_fingers = _write(tmp_path / "fingers", fingers)
    with pytest.raises(
        ValueError,
        match=r"0 message\(s\) of '/joint_states' \(of 10\) name the robot's joints "
        r"\['pan', .*\], need at least 2; the messages name \['finger_a', 'finger_b'\]",
    ):
        read_bag(only_fingers, robot=robot)


def test_empty_cut_and_late_objects(bags: dict[str, list[Path]], robot: Robot) -> None:
    path = bags["sqlite3"][2]
    with pytest.raises(ValueError, match=r"start/end: 0 joint state\(s\) .* within \[100, end\]"):
        read_bag(path, robot=robot, start=100.0)
    with pytest.raises(ValueError, match=r"end must be > start"):
        read_bag(path, robot=robot, start=2.0, end=1.0)


def test_not_a_bag(tmp_path: Path, robot: Robot) -> None:
    with pytest.raises(FileNotFoundError, match="bag not found"):
        read_bag(tmp_path / "nothing", robot=robot)
    with pytest.raises(ValueError, match=r"without metadata\.yaml"):
        read_bag(tmp_path, robot=robot)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file")
    with pytest.raises(ValueError, match="not a readable ROS bag"):
        read_bag(junk, robot=robot)


def test_existing_output_is_refused_and_kept(
    tmp_path: Path, demos: list[Demonstration], robot: Robot
) -> None:
    target = tmp_path / "out"
    target.mkdir()
    (target / "keep.txt").write_text("user data")
    with pytest.raises(ValueError, match=r"path .*out exists; give a new path"):
        write_trajectory_bag(target, [0.0, 1.0], np.zeros((2, 5)), robot.joint_names)
    with pytest.raises(ValueError, match=r"path .*out exists"):
        write_demonstration_bag(target, demos[0], robot.joint_names)
    file = tmp_path / "file.db3"
    file.write_text("x")
    with pytest.raises(ValueError, match="exists"):
        write_trajectory_bag(file, [0.0, 1.0], np.zeros((2, 5)), robot.joint_names)
    assert (target / "keep.txt").read_text() == "user data" and file.read_text() == "x"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.db3", "out"]


def test_trajectory_arguments_are_checked(tmp_path: Path, robot: Robot) -> None:
    q = np.zeros((3, 5))
    with pytest.raises(ValueError, match=r"joint_names must be 5 non-empty strings"):
        write_trajectory_bag(tmp_path / "a", [0, 1, 2], q, robot.joint_names[:4])
    with pytest.raises(ValueError, match=r"t must increase strictly"):
        write_trajectory_bag(tmp_path / "a", [0, 1, 1], q, robot.joint_names)
    with pytest.raises(ValueError, match=r"joints must have shape \(3, \*\)"):
        write_trajectory_bag(tmp_path / "a", [0, 1, 2], q[:2], robot.joint_names)
    with pytest.raises(ValueError, match=r"storage must be one of \['sqlite3', 'mcap'\]"):
        write_trajectory_bag(tmp_path / "a", [0, 1, 2], q, robot.joint_names, storage="zip")  # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []


def test_trajectory_velocities_and_accelerations_are_checked(tmp_path: Path, robot: Robot) -> None:
    t, q, names = [0.0, 1.0, 2.0], np.zeros((3, 5)), robot.joint_names
    ok = np.zeros((3, 5))
    with pytest.raises(ValueError, match=r"velocities must have shape \(3, 5\), got \(2, 5\)"):
        write_trajectory_bag(tmp_path / "a", t, q, names, velocities=ok[:2])
    with pytest.raises(ValueError, match=r"velocities must have shape \(3, 5\), got \(3, 4\)"):
        write_trajectory_bag(tmp_path / "a", t, q, names, velocities=ok[:, :4])
    with pytest.raises(ValueError, match=r"velocities must have shape \(3, 5\), got \(15,\)"):
        write_trajectory_bag(tmp_path / "a", t, q, names, velocities=ok.ravel())
    with pytest.raises(
        ValueError, match=r"accelerations must have shape \(3, 5\), got \(3, 5, 1\)"
    ):
        write_trajectory_bag(
            tmp_path / "a", t, q, names, velocities=ok, accelerations=ok[..., None]
        )
    nan, inf = ok.copy(), ok.copy()
    nan[1, 3] = np.nan
    inf[0, 0] = -np.inf
    with pytest.raises(ValueError, match=r"velocities must be finite, got 1 NaN or infinite"):
        write_trajectory_bag(tmp_path / "a", t, q, names, velocities=nan)
    with pytest.raises(ValueError, match=r"accelerations must be finite, got 1 NaN or infinite"):
        write_trajectory_bag(tmp_path / "a", t, q, names, velocities=ok, accelerations=inf)
    with pytest.raises(ValueError, match=r"velocities must be an array of numbers"):
        write_trajectory_bag(tmp_path / "a", t, q, names, velocities="fast")
    with pytest.raises(ValueError, match=r"accelerations need velocities"):
        write_trajectory_bag(tmp_path / "a", t, q, names, accelerations=ok)
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_check_trajectory_bag_refuses_what_the_writer_refuses(tmp_path: Path, robot: Robot) -> None:
    t, q, names = [0.0, 1.0, 2.0], np.zeros((3, 5)), robot.joint_names
    grip = [0.0, 1.0, 1.0]
    cases: list[tuple[tuple[Any, ...], dict[str, Any], str]] = [
        ((t, q, names[:4]), {}, r"joint_names must be 5 non-empty strings"),
        (([0.0, 1.0, 1.0], q, names), {}, r"t must increase strictly"),
        (([0.0, 1.5e9, 3e9], q, names), {}, r"t must be < 2147483648 s .*int32 seconds"),
        ((t, q[:2], names), {}, r"joints must have shape \(3, \*\)"),
        ((t, q, names), {"accelerations": q}, r"accelerations need velocities"),
        ((t, q, names), {"velocities": q[:, :4]}, r"velocities must have shape \(3, 5\)"),
        ((t, q, names), {"storage": "zip"}, r"storage must be one of \['sqlite3', 'mcap'\]"),
        ((t, q, names, grip), {"gripper_topic": "grip"}, r"gripper_topic must be a ROS topic"),
    ]
    for args, kwargs, match in cases:
        with pytest.raises(ValueError, match=match):
            check_trajectory_bag(*args, **kwargs)
        with pytest.raises(ValueError, match=match):
            write_trajectory_bag(tmp_path / "bag", *args, **kwargs)
    assert list(tmp_path.iterdir()) == []  # neither wrote anything
    check_trajectory_bag(t, q, names, grip, velocities=q, accelerations=q, storage="mcap")
    assert list(tmp_path.iterdir()) == []
    write_trajectory_bag(tmp_path / "bag", t, q, names, grip, velocities=q, accelerations=q)
    assert [c for c, _ in _topics(tmp_path / "bag")] == ["/gripper", "/joint_trajectory"]


def test_read_bag_needs_the_names_and_base_of_the_arm(
    bags: dict[str, list[Path]], robot: Robot
) -> None:
    with pytest.raises(
        ValueError,
        match=r"robot must be a BagRobot \(joint_names, base; e\.g\. pbdkit\.robots\.katana\(\) "
        r".*\): KinematicOnly lacks base",
    ):
        read_bag(bags["sqlite3"][0], robot=KinematicOnly(robot))  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- the CLI
def _one_line_error(result: Result, *fragments: str) -> None:
    assert result.exit_code == 2, result.output
    text = result.output.strip()
    assert text.startswith("error: ") and "\n" not in text, text
    for fragment in fragments:
        assert fragment in text, text


def _as_points(src: Path, dst: Path, storage: str) -> Path:
    """The bag ``src`` with its PoseStamped messages on ``/NAME/pose`` rewritten as
    PointStamped on ``/NAME/point`` (same stamps, frames and positions): objects as positions,
    as the paper's skills have them (a PoseStamped gives a pose)."""
    point_cls, point_t = TS.types["geometry_msgs/msg/PointStamped"], "geometry_msgs/msg/Point"
    messages = []
    with AnyReader([src], default_typestore=TS) as reader:
        for conn, log, raw in reader.messages():
            topic, msgtype = conn.topic, conn.msgtype
            msg = reader.deserialize(raw, msgtype)
            if msgtype == "geometry_msgs/msg/PoseStamped":
                v = msg.pose.position
                msg = point_cls(
                    header=_header(_stamp(msg), str(msg.header.frame_id)),
                    point=_vector(point_t, [v.x, v.y, v.z]),
                )
                topic, msgtype = topic.replace("/pose", "/point"), point_t + "Stamped"
            messages.append((topic, msgtype, log, msg))
    return _write(dst, messages, storage)


def test_cli_learn_from_bags_and_reproduce_to_a_bag(
    tmp_path: Path, bags: dict[str, list[Path]], robot: Robot, skill: Skill
) -> None:
    runner = CliRunner()
    out = tmp_path / "skill.npz"
    # The objects as PointStamped: positions, as the skill of the arrays has them.
    paths = [
        str(_as_points(bags[storage][i], tmp_path / f"points_{i}", storage))
        for i, storage in enumerate(["mcap", "sqlite3", "mcap"])
    ]
    args = ["--object", "glass=/glass/point", "--object", "coaster=/coaster/point"]
    result = runner.invoke(
        app,
        [
            "learn",
            *paths,
            "--robot",
            "katana",
            "--joint-topic",
            "/joint_states",
            *args,
            "--gripper-topic",
            "/gripper",
            "--n-steps",
            str(N_STEPS),
            "--max-components",
            str(MAX_K),
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    learned = Skill.load(out)
    assert learned.n_components == skill.n_components
    np.testing.assert_allclose(
        learned.constraints().joint_mean, skill.constraints().joint_mean, rtol=0, atol=1e-9
    )

    traj = tmp_path / "trajectory"
    objects = {"glass": [0.47, 0.18, 0.175], "coaster": [0.49, -0.17, 0.006]}
    opts = [f"{k}={','.join(str(v) for v in p)}" for k, p in objects.items()]
    result = runner.invoke(
        app,
        [
            "reproduce",
            str(out),
            "--object",
            opts[0],
            "--object",
            opts[1],
            "--out",
            str(tmp_path / "repro.npz"),
            "--bag",
            str(traj),
        ],
    )
    assert result.exit_code == 0, result.output
    ((_, msg),) = _raw(traj, "/joint_trajectory")
    with np.load(tmp_path / "repro.npz") as data:
        np.testing.assert_array_equal(np.stack([p.positions for p in msg.points]), data["joints"])
    res = learned.reproduce(objects)  # the command's reproduction, here
    np.testing.assert_array_equal(np.stack([p.positions for p in msg.points]), res.joints)
    expected = learned.times(res)
    tfs = np.array([p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points])
    np.testing.assert_allclose(tfs, expected, rtol=0, atol=1e-9)
    # The points carry the timing's velocities and accelerations (positions only without one).
    if res.velocities is None:
        assert all(len(p.velocities) == len(p.accelerations) == 0 for p in msg.points)
    else:
        assert res.accelerations is not None
        vel, acc = _derivatives(msg)
        np.testing.assert_array_equal(vel, res.velocities)
        np.testing.assert_array_equal(acc, res.accelerations)
    assert list(msg.joint_names) == robot.joint_names
    assert [m.data for _, m in _raw(traj, "/gripper")] == [False, True, False]


def test_cli_learn_bag_errors_are_one_line(
    tmp_path: Path, bags: dict[str, list[Path]], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    bag = str(bags["sqlite3"][0])
    result = runner.invoke(app, ["learn", bag, bag, "--object", "glass=/nope"])
    _one_line_error(result, "objects['glass']", "has no topic '/nope'", "its topics: /coaster")
    result = runner.invoke(app, ["learn", bag, "--joint-topic", "/gripper"])
    _one_line_error(result, "must be of type sensor_msgs/msg/JointState, got std_msgs/msg/Bool")
    result = runner.invoke(
        app, ["learn", bag, "--object", "glass=/glass/pose", "--object", "glass=tf:g"]
    )
    _one_line_error(result, "--object glass is given twice")
    result = runner.invoke(app, ["learn", "demos.npz", "--object", "glass=/glass/pose"])
    _one_line_error(result, "--object apply to bags; demos.npz is an .npz file")
    (tmp_path / "notes.txt").write_text("")
    result = runner.invoke(app, ["learn", "notes.txt"])
    _one_line_error(result, "notes.txt: not an .npz file of demonstrations nor a ROS bag")
    result = runner.invoke(app, ["learn", "missing_bag"])
    _one_line_error(result, "bag not found: missing_bag")
    assert not (tmp_path / "skill.npz").exists()


def test_cli_object_sources_tf_and_fixed(
    tmp_path: Path, bags: dict[str, list[Path]], robot: Robot
) -> None:
    # --object NAME=x,y,z is a fixed position; NAME=tf:frame needs /tf in the bag.
    bag = str(bags["mcap"][1])
    out = tmp_path / "skill.npz"
    result = CliRunner().invoke(
        app,
        [
            "learn",
            bag,
            str(bags["mcap"][2]),
            "--object",
            "glass=0.45,0.2,0.175",
            "--n-steps",
            "20",
            "--max-components",
            "2",
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    assert Skill.load(out).object_names == ["glass"]
    result = CliRunner().invoke(app, ["learn", bag, "--object", "glass=tf:glass"])
    _one_line_error(result, "neither /tf nor /tf_static")


def test_cli_reproduce_refuses_an_existing_bag_before_any_work(tmp_path: Path) -> None:
    existing = tmp_path / "trajectory"
    existing.mkdir()
    result = CliRunner().invoke(
        app,
        [
            "reproduce",
            str(tmp_path / "no_skill.npz"),  # an error about it would mean work had started
            "--object",
            "glass=0.3,0,0.1",
            "--out",
            str(tmp_path / "repro.npz"),
            "--bag",
            str(existing),
        ],
    )
    _one_line_error(result, f"--bag {existing}: exists; give a new path")


# ----------------------------------------------------------------------------- hostile input
def _damaged(data: bytes, offset: int, fill: bytes) -> bytes:
    """``data`` with ``fill`` written over it at ``offset``, of the same length."""
    return (data[:offset] + fill + data[offset + len(fill) :])[: len(data)]


def _pose(
    ns: int,
    position: Sequence[float],
    frame: str = "base_link",
    quat: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
) -> Any:
    """A PoseStamped; ``quat`` in ROS's order (x, y, z, w), as scipy's ``as_quat``."""
    x, y, z, w = (float(c) for c in quat)
    pose = TS.types["geometry_msgs/msg/Pose"](
        position=_vector("geometry_msgs/msg/Point", position),
        orientation=TS.types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
    )
    return TS.types["geometry_msgs/msg/PoseStamped"](header=_header(ns, frame), pose=pose)


@pytest.mark.parametrize("whole_bag", [False, True])
def test_corrupted_mcap_is_a_clear_error(tmp_path: Path, robot: Robot, whole_bag: bool) -> None:
    # 4 KiB of 0xff in the middle of the storage file made the reader raise OverflowError.
    bag = _write(tmp_path / "arm", _arm_motion(200), "mcap")
    storage = bag / "arm.mcap"
    data = storage.read_bytes()
    storage.write_bytes(_damaged(data, len(data) // 2, b"\xff" * 4096))
    path = bag if whole_bag else storage
    with pytest.raises(
        ValueError,
        match=rf"^{re.escape(str(path))} is not a readable ROS bag: corrupt or truncated "
        r"\(OverflowError: ",
    ):
        read_bag(path, robot=robot)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap", "ros1"])
def test_damaged_bags_fail_with_a_value_error_naming_them(
    tmp_path: Path, robot: Robot, storage: str
) -> None:
    # Bytes overwritten anywhere: the bag reads, or a ValueError names it (never a KeyError,
    # AssertionError, OverflowError, UnicodeDecodeError, ... of the reader).
    if storage == "ros1":
        source = _write_ros1(tmp_path / "good.bag", np.zeros((300, 5)) + np.arange(300)[:, None])
    else:
        suffix = "mcap" if storage == "mcap" else "db3"
        source = _write(tmp_path / "good", _arm_motion(300), storage) / f"good.{suffix}"
    data = source.read_bytes()
    rng = np.random.default_rng(0)
    damaged = tmp_path / f"damaged{source.suffix}"
    unnamed: list[tuple[int, int, str]] = []
    for k in range(20):
        offset = int(rng.integers(0, len(data)))
        size = int(rng.choice([1, 8, 64, 4096]))
        fill = b"\xff" * size if k % 2 else rng.bytes(size)
        damaged.write_bytes(_damaged(data, offset, fill))
        try:
            read_bag(damaged, robot=robot)
        except ValueError as exc:
            if str(damaged) not in str(exc):
                unnamed.append((offset, size, str(exc)))
    assert unnamed == []


def test_start_and_end_beyond_any_ros_time(tmp_path: Path, robot: Robot) -> None:
    # start=1e300 s made an OverflowError (1e309 ns); end=1e300 keeps everything.
    path = _write(tmp_path / "arm", _arm_motion(20))
    with pytest.raises(
        ValueError,
        match=r"start/end: 0 joint state\(s\) of '/joint_states' within \[1e\+300, end\] s, "
        r"need at least 2; the joint states span \[0, 0\.380\] s",
    ):
        read_bag(path, robot=robot, start=1e300)
    whole = read_bag(path, robot=robot)
    np.testing.assert_array_equal(read_bag(path, robot=robot, end=1e300).joints, whole.joints)
    assert whole.n_steps == 20
    result = CliRunner().invoke(app, ["learn", str(path), str(path), "--start", "1e300"])
    _one_line_error(result, f"{path}: start/end: 0 joint state(s)", "[1e+300, end]")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")
def test_fifos_and_devices_are_refused(
    tmp_path: Path, robot: Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A FIFO named like a bag blocked the reader for ever; a link to /dev/zero fed it without end.
    for name in ["x.bag", "x.db3", "x.mcap"]:
        os.mkfifo(tmp_path / name)
        with pytest.raises(
            ValueError, match=rf"x\.{name[2:]} is a FIFO \(named pipe\), not a ROS bag \(give"
        ):
            read_bag(tmp_path / name, robot=robot)
    if Path("/dev/zero").exists():
        (tmp_path / "zero.bag").symlink_to("/dev/zero")
        with pytest.raises(ValueError, match=r"zero\.bag is a character device, not a ROS bag"):
            read_bag(tmp_path / "zero.bag", robot=robot)
    # A rosbag2 bag is a directory (still read); what it holds must be regular files.
    bag = _write(tmp_path / "arm", _arm_motion(10))
    assert read_bag(bag, robot=robot).n_steps == 10
    (bag / "arm.db3").unlink()
    os.mkfifo(bag / "arm.db3")
    with pytest.raises(
        ValueError,
        match=r"arm: arm\.db3 is a FIFO \(named pipe\); a rosbag2 bag holds regular files only",
    ):
        read_bag(bag, robot=robot)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, ["learn", "x.bag", "x.db3"])
    _one_line_error(result, "x.bag is a FIFO (named pipe), not a ROS bag")


def _long_bag(path: Path, n: int) -> Path:
    """n joint states at 1 kHz from T0, written fast: one message serialized, its stamp patched."""
    msgtype, msg = _joint_state(T0, KATANA_JOINTS, np.arange(5.0))
    raw = bytearray(TS.serialize_cdr(msg, msgtype))
    with Writer(path, version=9) as writer:
        conn = writer.add_connection("/joint_states", msgtype, typestore=TS)
        for i in range(n):
            ns = T0 + i * 1_000_000
            # CDR: 4 bytes of encapsulation, then header.stamp as int32 sec, uint32 nanosec.
            struct.pack_into("<iI", raw, 4, ns // 10**9, ns % 10**9)
            writer.write(conn, ns, bytes(raw))
    return path


def test_read_bag_reads_only_what_it_keeps(
    tmp_path: Path, robot: Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 20 s at 1 kHz, 2 s kept: every message was deserialized and held (1e6 messages: 37 s,
    # 2.1 GB). Now the messages outside the cut are skipped on their raw header stamps.
    path = _long_bag(tmp_path / "long", 20_000)
    deserialize = AnyReader.deserialize
    count = 0

    def counted(self: AnyReader, rawdata: bytes, typ: str) -> object:
        nonlocal count
        count += 1
        return deserialize(self, rawdata, typ)

    monkeypatch.setattr(AnyReader, "deserialize", counted)
    back = read_bag(path, robot=robot, start=10.0, end=12.0)
    assert back.n_steps == 2001
    np.testing.assert_allclose(back.t, np.arange(2001) * 1e-3, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.joints, np.tile(np.arange(5.0), (2001, 1)))
    assert count == 1 + 2001  # the first joint state (the cut's origin), then what is kept
    tracemalloc.start()
    try:
        read_bag(path, robot=robot, start=10.0, end=12.0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8e6, peak  # was about 37 MB: all 20,000 messages deserialized


def test_a_nan_pose_in_the_first_second_is_dropped(tmp_path: Path, robot: Robot) -> None:
    # The median is robust to a perception outlier; a NaN one rejected the whole bag.
    rng = np.random.default_rng(4)
    truth = np.array([0.45, 0.2, 0.175])
    msgs = _arm_motion(n=100)
    kept = []
    unit = [0.0, 0.0, 0.0, 1.0]
    for k in range(31):
        ns = T0 + k * 33_333_333
        p = truth + rng.normal(0.0, 0.002, 3)
        if k == 3:
            p[:] = np.nan
        elif k == 4:
            p[1] = np.inf
        else:
            kept.append(p)
        msgs.append(("/glass/pose", "geometry_msgs/msg/PoseStamped", ns, _pose(ns, p)))
        msgs.append(("/nan/pose", "geometry_msgs/msg/PoseStamped", ns, _pose(ns, [np.nan] * 3)))
        cam = [np.nan, 0.0, 0.0] if k == 5 else [0.1, 0.2, 0.3]  # tf: the same rule
        msgs.append(_tf_entry("/tf", ns, "base_link", "camera", cam, unit))
    path = _write(tmp_path / "nan", msgs)
    back = read_bag(path, robot=robot, objects={"glass": "/glass/pose", "cam": "tf:camera"})
    np.testing.assert_array_equal(position_of(back.objects["glass"]), np.median(kept, axis=0))
    np.testing.assert_allclose(position_of(back.objects["cam"]), [0.1, 0.2, 0.3], atol=1e-15)
    with pytest.raises(
        ValueError,
        match=r"objects\['glass'\]: the 31 message\(s\) of '/nan/pose' stamped within the first "
        r"second of the demonstration all hold NaN or infinite positions",
    ):
        read_bag(path, robot=robot, objects={"glass": "/nan/pose"})


def test_a_nan_gripper_is_refused(tmp_path: Path, robot: Robot) -> None:
    # NaN > 0.5 is False: a NaN gripper signal was read as "open".
    msgs = _arm_motion(n=50)
    float_cls = TS.types["std_msgs/msg/Float64"]
    for i, value in [(5, 0.9), (10, np.nan), (20, 0.1)]:
        msgs.append(
            ("/gripper", "std_msgs/msg/Float64", T0 + i * 20_000_000, float_cls(data=value))
        )
    path = _write(tmp_path / "grip", msgs)
    with pytest.raises(
        ValueError,
        match=rf"^{re.escape(str(path))}: gripper_topic: message 1 of '/gripper' holds nan; "
        r"the gripper signal must be finite \(closed where > 0\.5\)",
    ):
        read_bag(path, robot=robot, gripper_topic="/gripper")
    # Cut before the NaN: the messages that hold no kept sample are not read.
    back = read_bag(path, robot=robot, gripper_topic="/gripper", end=0.1)
    np.testing.assert_array_equal(back.gripper, [0.0] * 5 + [1.0])


def test_a_gap_in_the_joint_states_is_refused(tmp_path: Path, robot: Robot) -> None:
    # A 1e8 s gap in the stamps was accepted: a demonstration of three years.
    msgs = _arm_motion(n=20)
    gap = 10**8 * 10**9
    for k in range(10, 20):
        _set_joint_state(msgs, k, log=msgs[k][2] + gap)
    path = _write(tmp_path / "gap", msgs)
    with pytest.raises(
        ValueError,
        match=r"joint_topic: the joint states of '/joint_states' stop for 100000000\.020000000 s "
        r"after message 9 \(0\.180000000 s after the first joint state\); they must come at "
        r"least every 1 s",
    ):
        read_bag(path, robot=robot)
    assert read_bag(path, robot=robot, end=1.0).n_steps == 10  # cut off: read
    # A gap of exactly 1 s is accepted.
    msgs = _arm_motion(n=3)
    _set_joint_state(msgs, 2, log=msgs[2][2] + 980_000_000)
    assert read_bag(_write(tmp_path / "one_second", msgs), robot=robot).duration == 1.02


def test_errors_about_the_content_name_the_bag(tmp_path: Path, robot: Robot) -> None:
    msgs = _arm_motion(n=5)
    _set_joint_state(msgs, 3, names=["pan", "pan", *KATANA_JOINTS[1:]])
    path = _write(tmp_path / "twice", msgs)
    with pytest.raises(
        ValueError,
        match=rf"^{re.escape(str(path))}: joint_topic: message 3 of '/joint_states' "
        r"names a joint twice",
    ):
        read_bag(path, robot=robot)
    garbage = tmp_path / "garbage.bag"
    garbage.write_bytes(b"#ROSBAG V2.0\n" + b"\xff" * 4096)
    with pytest.raises(ValueError, match=rf"^{re.escape(str(garbage))} is not a readable ROS bag"):
        read_bag(garbage, robot=robot)


def test_trajectory_times_a_bag_cannot_hold(tmp_path: Path, robot: Robot) -> None:
    # 3e9 s gave a struct.error (int32 seconds); times up to 1e12 "must increase strictly".
    q, names = np.zeros((3, 5)), robot.joint_names
    with pytest.raises(
        ValueError,
        match=r"t must be < 2147483648 s \(2\*\*31: time_from_start holds int32 seconds\), got "
        r"t\[2\]=3000000000\.0",
    ):
        write_trajectory_bag(tmp_path / "a", [0.0, 1.5e9, 3e9], q, names)
    with pytest.raises(ValueError, match=r"t must be < 2147483648 s .*got t\[1\]=500000000000\.0"):
        write_trajectory_bag(tmp_path / "a", [0.0, 5e11, 1e12], q, names)
    with pytest.raises(
        ValueError,
        match=r"t must increase by at least 1 ns \(the resolution of time_from_start\), got "
        r"t\[1\]=1\.0 and t\[2\]=1\.0000000001, 1e-10 s apart",
    ):
        write_trajectory_bag(tmp_path / "a", [0.0, 1.0, 1.0 + 1e-10], q, names)
    demo = Demonstration(t=[0.0, 1.0], joints=np.zeros((2, 5)))
    with pytest.raises(ValueError, match=r"start_time \+ the demonstration's duration \(1 s\)"):
        write_demonstration_bag(tmp_path / "a", demo, names, start_time=1e12)
    assert list(tmp_path.iterdir()) == []
    write_trajectory_bag(tmp_path / "last", [0.0, 2.0**31 - 0.5], q[:2], names)
    ((_, msg),) = _raw(tmp_path / "last", "/joint_trajectory")
    assert (msg.points[1].time_from_start.sec, msg.points[1].time_from_start.nanosec) == (
        2**31 - 1,
        500_000_000,
    )


def test_trajectory_topics_and_joints_are_checked(tmp_path: Path, robot: Robot) -> None:
    t, q, names = [0.0, 1.0], np.zeros((2, 5)), robot.joint_names
    grip = [0.0, 1.0]
    with pytest.raises(ValueError, match=r"topic must be a ROS topic name \('/' then .*got ''"):
        write_trajectory_bag(tmp_path / "a", t, q, names, topic="")
    with pytest.raises(ValueError, match=r"gripper_topic must be a ROS topic name .*got 'grip'"):
        write_trajectory_bag(tmp_path / "a", t, q, names, grip, gripper_topic="grip")
    with pytest.raises(
        ValueError,
        match=r"gripper_topic must differ from topic \('/joint_trajectory'\): a topic carries "
        "one message type",
    ):
        write_trajectory_bag(tmp_path / "a", t, q, names, grip, gripper_topic="/joint_trajectory")
    with pytest.raises(
        ValueError, match=r"joints must have one column per joint, at least 1, got shape \(2, 0\)"
    ):
        write_trajectory_bag(tmp_path / "a", t, np.zeros((2, 0)), [])
    demo = Demonstration(t=[0.0, 1.0], joints=np.zeros((2, 5)), objects={"glass": [0, 0, 0]})
    with pytest.raises(ValueError, match=r"object_topics\['glass'\] must differ from joint_topic"):
        write_demonstration_bag(
            tmp_path / "a", demo, names, object_topics={"glass": "/joint_states"}
        )
    assert list(tmp_path.iterdir()) == []
    # Without a gripper, gripper_topic is not used.
    write_trajectory_bag(tmp_path / "b", t, q, names, topic="/arm/trajectory", gripper_topic="/x")
    assert [c for c, _ in _topics(tmp_path / "b")] == ["/arm/trajectory"]


def _topics(path: Path) -> list[tuple[str, str]]:
    with AnyReader([path], default_typestore=TS) as reader:
        return sorted((c.topic, c.msgtype) for c in reader.connections)


def test_cli_reproduce_checks_the_bag_before_writing_out(tmp_path: Path, skill: Skill) -> None:
    # A skill of 3e9 s wrote --out, then failed on the bag with a struct.error traceback.
    skill.save(tmp_path / "skill.npz")
    long = Skill.load(tmp_path / "skill.npz")
    long.duration = 3e9
    long.save(tmp_path / "long.npz")
    bag, out = tmp_path / "trajectory", tmp_path / "repro.npz"
    args = ["--object", "glass=0.47,0.18,0.175", "--object", "coaster=0.49,-0.17,0.006"]
    result = CliRunner().invoke(
        app, ["reproduce", str(tmp_path / "long.npz"), *args, "--out", str(out), "--bag", str(bag)]
    )
    _one_line_error(result, f"--bag {bag}: t must be < 2147483648 s", "int32 seconds")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.npz", "skill.npz"]
    # --out and --bag the same path: refused before anything is written.
    same = tmp_path / "same"
    result = CliRunner().invoke(
        app,
        ["reproduce", str(tmp_path / "skill.npz"), *args, "--out", str(same), "--bag", str(same)],
    )
    _one_line_error(result, f"--out {same}: is also --bag {same}; give each output its own path")
    assert not same.exists()
