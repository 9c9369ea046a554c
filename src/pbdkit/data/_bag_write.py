"""ROS bags out: a reproduction as a ``JointTrajectory`` (:func:`write_trajectory_bag`,
checked first by :func:`check_trajectory_bag`) and a demonstration as a teaching session's bag
(:func:`write_demonstration_bag`).

Every argument is checked before anything is written (times below 2**31 s and increasing at
1 ns, ROS topic names, distinct); an existing path is refused, and the bag is written into a
temporary sibling directory and renamed onto it (``os.replace``). :doc:`/reproduction`,
"ROS bags".
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import quaternion_from_matrix
from .._validation import check_array, check_positive_float, short
from ..motion._limits import PAD_REST, MotionLimits, divided_differences, with_defaults
from ._demonstration import Demonstration
from ._placement import position_of, rotation_of
from ._ros import _NS, GRIPPER_THRESHOLD, JOINT_STATE_TYPE, TRAJECTORY_TYPE, _typestore

if TYPE_CHECKING:
    from rosbags.rosbag2 import Writer

__all__ = [
    "STORAGES",
    "check_trajectory_bag",
    "write_demonstration_bag",
    "write_trajectory_bag",
]

Float = NDArray[np.float64]
Storage = Literal["sqlite3", "mcap"]
STORAGES: tuple[Storage, ...] = ("sqlite3", "mcap")


def _check_new_path(path: str | os.PathLike[str], name: str = "path") -> Path:
    p = Path(path)
    if p.exists() or p.is_symlink():
        raise ValueError(
            f"{name} {p} exists; give a new path (a bag is a directory and is never overwritten)"
        )
    return p


def _check_storage(storage: object) -> Storage:
    if storage not in STORAGES:
        raise ValueError(f"storage must be one of {list(STORAGES)}, got {short(storage)}")
    return storage


def _check_names(names: object, n: int, what: str) -> list[str]:
    if isinstance(names, str) or not isinstance(names, Sequence):
        raise ValueError(f"{what} must be a list of {n} names, got {type(names).__name__}")
    out = list(names)
    if len(out) != n or not all(isinstance(x, str) and x for x in out):
        raise ValueError(f"{what} must be {n} non-empty strings, got {out}")
    if len(set(out)) != n:
        raise ValueError(f"{what} must be distinct, got {out}")
    return out


# A fully qualified ROS topic name, as bags store them: "/" then tokens of letters, digits
# and "_", none starting with a digit (ROS 2's rules, without substitutions).
_TOPIC_NAME = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+")
# builtin_interfaces Time and Duration hold int32 seconds: times must stay below this (s).
_MAX_ROS_SECONDS = 2**31
_TRAJECTORY_TOPIC = "/joint_trajectory"
_GRIPPER_TOPIC = "/gripper"


def _check_topics(topics: Mapping[str, object]) -> None:
    """Each topic (argument name -> value) a ROS topic name, all distinct: a topic has one
    message type."""
    seen: dict[str, str] = {}
    for name, topic in topics.items():
        if not isinstance(topic, str) or not _TOPIC_NAME.fullmatch(topic):
            raise ValueError(
                f"{name} must be a ROS topic name ('/' then names of letters, digits and _, "
                f"not starting with a digit, e.g. '/joint_trajectory'), got {short(topic)}"
            )
        if topic in seen:
            raise ValueError(
                f"{name} must differ from {seen[topic]} ({short(topic)}): a topic carries one "
                "message type"
            )
        seen[topic] = name


def _write_bag_atomic(path: Path, storage: Storage, fill: Callable[[Writer], None]) -> None:
    """Write a rosbag2 bag at the new ``path``: into a temporary sibling directory, then renamed.

    The bag is built at ``<tmp>/<path.name>`` (so its storage file is ``<path.name>.db3`` or
    ``.mcap``, as ``ros2 bag record`` names it), flushed to disk, and renamed onto ``path``;
    on any error the temporary directory is removed and ``path`` is not created.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    parent = Path(os.path.realpath(path.parent))
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent))
    try:
        inner = tmp / path.name
        with Writer(inner, version=9, storage_plugin=plugin) as writer:
            fill(writer)
        for item in inner.iterdir():
            fd = os.open(item, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        _check_new_path(path)  # created while writing: keep what is there
        os.replace(inner, parent / path.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _header(ns: int, frame_id: str = "") -> Any:
    ts = _typestore()
    time_cls = ts.types["builtin_interfaces/msg/Time"]
    header_cls = ts.types["std_msgs/msg/Header"]
    return header_cls(stamp=time_cls(sec=ns // _NS, nanosec=ns % _NS), frame_id=frame_id)


def write_trajectory_bag(
    path: str | os.PathLike[str],
    t: npt.ArrayLike,
    joints: npt.ArrayLike,
    joint_names: Sequence[str],
    gripper: npt.ArrayLike | None = None,
    *,
    velocities: npt.ArrayLike | None = None,
    accelerations: npt.ArrayLike | None = None,
    storage: Storage = "sqlite3",
    topic: str = _TRAJECTORY_TOPIC,
    gripper_topic: str = _GRIPPER_TOPIC,
    limits: MotionLimits | None = None,
) -> None:
    """Write a joint trajectory as a rosbag2 bag a ``ros2_control`` controller can replay.

    One ``trajectory_msgs/msg/JointTrajectory`` message on ``topic`` (recorded at log time 0,
    header stamp 0: "start on receipt"), one point per sample with its positions, its
    velocities and accelerations if given (else empty), and ``time_from_start`` = t; with a
    gripper, ``std_msgs/msg/Bool`` messages on ``gripper_topic`` (True = closed) at the first
    sample and at every change, recorded at their time t, so that ``ros2 bag play`` sends them
    in step with the trajectory.

    Parameters
    ----------
    path : str or path-like
        The bag to create (a directory); it must not exist. Written atomically.
    t : array-like, shape (T,)
        Time from the start of each point (s), >= 0, below ``2**31`` s (``time_from_start``
        holds int32 seconds) and strictly increasing to 1 ns (its resolution), e.g.
        ``skill.times(res)``.
    joints : array-like, shape (T, n)
        Joint positions (rad, or m), n >= 1, e.g. ``res.joints``.
    joint_names : sequence of str, length n
        The controller's joint names, e.g. ``robot.joint_names``.
    gripper : array-like, shape (T,), optional
        The gripper command (bool, or numbers: closed where > 0.5), e.g. ``res.gripper``.
    velocities, accelerations : array-like, shape (T, n), optional
        Joint velocities (rad/s) and accelerations (rad/s^2) at the points, written into each
        point's ``velocities`` and ``accelerations``. The joint trajectory controller
        interpolates between points with them: cubic splines with velocities, quintic with
        both; positions only: linear. They should come from the timing, e.g.
        ``res.velocities`` and ``res.accelerations`` (the derivatives of the timing: see
        :attr:`pbdkit.reproduction.ReproductionResult.velocities`), not from
        differences of the positions:
        those are not the derivatives of the timed motion (nor at rest at the ends), and the
        controller's splines through them would leave the planned, limited motion.
        ``accelerations`` need ``velocities`` (the controller uses both, or velocities alone).
        Without them the points carry positions only.
    storage : {"sqlite3", "mcap"}
        rosbag2 storage plugin.
    topic, gripper_topic : str
        Topic names, fully qualified (``"/name"``); with a gripper, two different topics.
    limits : MotionLimits, optional
        The arm's velocity, acceleration and jerk limits: the trajectory (from rest at its
        first point, to rest at its last) must be within them, checked as a drive checks its
        stream (divided differences at the points), e.g. ``MotionLimits.from_robot(robot, n)``.
        None: within the limits assumed for an arm that declares none, from the trajectory's
        own top speed per joint (acceleration v / 0.25 s, jerk that / 0.1 s:
        :func:`pbdkit.motion._limits.with_defaults`), which a jump from rest to speed
        exceeds by far.

    Raises
    ------
    ValueError
        An existing ``path``, or a shape, value or name that does not fit (named), or a
        trajectory beyond ``limits`` (the joint, the quantity and where). Every argument is
        checked before anything is written.
    """
    p = _check_new_path(path)
    plugin = _check_storage(storage)
    message, gripper_messages = _trajectory_messages(
        t,
        joints,
        joint_names,
        gripper,
        velocities=velocities,
        accelerations=accelerations,
        topic=topic,
        gripper_topic=gripper_topic,
        limits=limits,
    )
    ts = _typestore()

    def fill(writer: Writer) -> None:
        conn = writer.add_connection(topic, TRAJECTORY_TYPE, typestore=ts)
        writer.write(conn, 0, message)
        if gripper_messages:
            gconn = writer.add_connection(gripper_topic, "std_msgs/msg/Bool", typestore=ts)
            for ns, data in gripper_messages:
                writer.write(gconn, ns, data)

    _write_bag_atomic(p, plugin, fill)


def check_trajectory_bag(
    t: npt.ArrayLike,
    joints: npt.ArrayLike,
    joint_names: Sequence[str],
    gripper: npt.ArrayLike | None = None,
    *,
    velocities: npt.ArrayLike | None = None,
    accelerations: npt.ArrayLike | None = None,
    storage: Storage = "sqlite3",
    topic: str = _TRAJECTORY_TOPIC,
    gripper_topic: str = _GRIPPER_TOPIC,
    limits: MotionLimits | None = None,
) -> None:
    """Check what :func:`write_trajectory_bag` would write, writing nothing.

    Takes the arguments of :func:`write_trajectory_bag` but its ``path``, and raises exactly
    where it would (the path aside): so that a program that writes other files beside the bag
    (``pbdkit reproduce --out ... --bag ...``) can refuse the bag before it writes any of them.

    Raises
    ------
    ValueError
        A shape, value or name that does not fit (named), as :func:`write_trajectory_bag`.
    """
    _check_storage(storage)
    _trajectory_messages(
        t,
        joints,
        joint_names,
        gripper,
        velocities=velocities,
        accelerations=accelerations,
        topic=topic,
        gripper_topic=gripper_topic,
        limits=limits,
    )


def _check_motion(t: Float, q: Float, names: Sequence[str], limits: MotionLimits | None) -> None:
    """The trajectory within ``limits`` (or the limits assumed from its own top speeds), from
    rest to rest: else a ValueError that names the joint, the quantity and where."""
    if t.shape[0] < 2:
        return
    v, a, j = divided_differences(t, q, pad_rest=PAD_REST)
    assumed = limits is None
    if limits is None:
        top = np.abs(v).max(axis=0)
        unbounded = np.full(q.shape[1], np.inf)
        limits = with_defaults(
            MotionLimits._derived(np.where(top > 0, top, np.inf), unbounded, unbounded), warn=False
        )
    elif limits.n_joints != q.shape[1]:
        raise ValueError(
            f"limits are for {limits.n_joints} joints, the trajectory has {q.shape[1]}"
        )
    kinds = [("acceleration", a, limits.acceleration), ("jerk", j, limits.jerk)]
    if not assumed:
        kinds.insert(0, ("velocity", v, limits.velocity))
    for quantity, d, bound in kinds:
        ratio = np.abs(d) / bound
        k, joint = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        if ratio[k, joint] > 1.0 + 1e-6:
            where = float(t[min(max(int(k) - PAD_REST, 0), t.shape[0] - 1)])
            whose = "the limit assumed for an arm without one" if assumed else "the limit"
            raise ValueError(
                f"the trajectory exceeds {whose} on {short(names[int(joint)])}: {quantity} "
                f"{float(np.abs(d[k, joint])):.4g} against {float(bound[joint]):.4g} near "
                f"t = {where:.4g} s (from rest at the first point, to rest at the last); time "
                "it within the arm's limits (e.g. skill.times(res) of a reproduction within "
                "them) and pass limits= (MotionLimits.from_robot(robot, n)) to check it "
                "against them"
            )


def _trajectory_messages(
    t: npt.ArrayLike,
    joints: npt.ArrayLike,
    joint_names: Sequence[str],
    gripper: npt.ArrayLike | None,
    *,
    velocities: npt.ArrayLike | None,
    accelerations: npt.ArrayLike | None,
    topic: str = _TRAJECTORY_TOPIC,
    gripper_topic: str = _GRIPPER_TOPIC,
    limits: MotionLimits | None = None,
) -> tuple[memoryview, list[tuple[int, memoryview]]]:
    """The checked arguments of :func:`write_trajectory_bag` as its serialized messages: the
    JointTrajectory, and (log time ns, Bool) of the gripper's (:func:`check_trajectory_bag`
    builds them too, and writes nothing)."""
    _check_topics({"topic": topic, **({} if gripper is None else {"gripper_topic": gripper_topic})})
    t_ = check_array(t, "t", ndim=1, min_rows=1)
    if t_[0] < 0:
        raise ValueError(f"t must be >= 0 (time from start), got t[0]={short(float(t_[0]))}")
    if np.any(t_ >= _MAX_ROS_SECONDS):
        i = int(np.argmax(t_ >= _MAX_ROS_SECONDS))
        raise ValueError(
            f"t must be < {_MAX_ROS_SECONDS} s (2**31: time_from_start holds int32 seconds), "
            f"got t[{i}]={short(float(t_[i]))}"
        )
    ns = np.round(t_ * _NS).astype(np.int64)  # < 2**31 s: within int64 ns
    if np.any(np.diff(ns) <= 0):
        i = int(np.argmax(np.diff(ns) <= 0))
        a, b = float(t_[i]), float(t_[i + 1])
        if b > a:  # increasing, but not at the resolution of the stamps
            raise ValueError(
                f"t must increase by at least 1 ns (the resolution of time_from_start), got "
                f"t[{i}]={short(a)} and t[{i + 1}]={short(b)}, {b - a:.3g} s apart"
            )
        raise ValueError(
            f"t must increase strictly, got t[{i}]={short(a)} and t[{i + 1}]={short(b)}"
        )
    q = check_array(joints, "joints", shape=(t_.shape[0], None))
    if q.shape[1] == 0:
        raise ValueError(f"joints must have one column per joint, at least 1, got shape {q.shape}")
    names = _check_names(joint_names, q.shape[1], "joint_names")
    _check_motion(t_, q, names, limits)
    closed: NDArray[np.bool_] | None = None
    if gripper is not None:
        closed = check_array(gripper, "gripper", shape=(t_.shape[0],)) > GRIPPER_THRESHOLD
    if accelerations is not None and velocities is None:
        raise ValueError(
            "accelerations need velocities: the joint trajectory controller interpolates with "
            "both or with velocities alone; give velocities too (e.g. res.velocities)"
        )
    empty = np.zeros(0, dtype=np.float64)
    vel = None if velocities is None else check_array(velocities, "velocities", shape=q.shape)
    acc = (
        None
        if accelerations is None
        else check_array(accelerations, "accelerations", shape=q.shape)
    )

    ts = _typestore()
    duration_cls = ts.types["builtin_interfaces/msg/Duration"]
    point_cls = ts.types["trajectory_msgs/msg/JointTrajectoryPoint"]
    traj_cls = ts.types[TRAJECTORY_TYPE]
    bool_cls = ts.types["std_msgs/msg/Bool"]
    points = [
        point_cls(
            positions=q[i].copy(),
            velocities=empty if vel is None else vel[i].copy(),
            accelerations=empty if acc is None else acc[i].copy(),
            effort=empty,
            time_from_start=duration_cls(sec=int(ns[i]) // _NS, nanosec=int(ns[i]) % _NS),
        )
        for i in range(q.shape[0])
    ]
    msg = traj_cls(header=_header(0), joint_names=names, points=points)
    gripper_messages: list[tuple[int, memoryview]] = []
    if closed is not None:
        for i in np.r_[0, np.flatnonzero(np.diff(closed)) + 1]:
            data = ts.serialize_cdr(bool_cls(data=bool(closed[i])), "std_msgs/msg/Bool")
            gripper_messages.append((int(ns[i]), data))
    return ts.serialize_cdr(msg, TRAJECTORY_TYPE), gripper_messages


def write_demonstration_bag(
    path: str | os.PathLike[str],
    demo: Demonstration,
    joint_names: Sequence[str],
    *,
    storage: Storage = "sqlite3",
    joint_topic: str = "/joint_states",
    object_topics: Mapping[str, str | None] | None = None,
    object_rate: float = 30.0,
    gripper_topic: str | None = "/gripper",
    extra_joints: Mapping[str, float] | None = None,
    shuffle: np.random.Generator | None = None,
    start_time: float = 1_700_000_000.0,
    frame_id: str = "base_link",
) -> None:
    """Record a demonstration as a rosbag2 bag, as a real arm's teaching session would be.

    For recording simulated demonstrations, and for tests and examples: :func:`read_bag` of
    the result with the same topics gives the demonstration back (joints and object positions
    exactly, object orientations to 1e-9, times to 1 ns, the gripper at the 0.5 threshold),
    except that every object comes back as a pose: a ``PoseStamped`` has an orientation, the
    identity for an object given as a position. Header stamps and log times are equal:
    ``start_time`` + (t - t[0]).

    Parameters
    ----------
    path : str or path-like
        The bag to create (a directory); it must not exist. Written atomically.
    demo : Demonstration
        The demonstration.
    joint_names : sequence of str, length n
        Names of the demonstration's joints, in its column order (``robot.joint_names``).
    storage : {"sqlite3", "mcap"}
        rosbag2 storage plugin.
    joint_topic : str
        Topic of the ``sensor_msgs/msg/JointState`` messages, one per sample.
    object_topics : dict str -> str or None, optional
        Topic of each object's ``geometry_msgs/msg/PoseStamped`` messages (default
        ``"/{name}/pose"``; None: the object is not recorded): its position, and its
        orientation as a ROS quaternion (x, y, z, w), the identity for a position.
    object_rate : float
        Rate of the object messages (Hz), over the demonstration's duration.
    gripper_topic : str or None
        Topic of ``std_msgs/msg/Bool`` messages (closed where the gripper > 0.5), written at
        the first sample and at every change; None, or a demonstration without gripper: none.
    extra_joints : dict str -> float, optional
        Joints the arm does not have (e.g. ``{"finger": 0.02}``), published in every message
        with these positions, as drivers publish the gripper's fingers.
    shuffle : numpy.random.Generator, optional
        If given, each message lists its joints in a new random order drawn from it.
    start_time : float
        ROS time (s) of the first sample; the last must be below ``2**31`` s (ROS 2 stamps hold
        int32 seconds).
    frame_id : str
        ``header.frame_id`` of the object messages: the robot's base frame.

    Raises
    ------
    ValueError
        An existing ``path``, or an argument that does not fit (named).
    """
    p = _check_new_path(path)
    plugin = _check_storage(storage)
    if not isinstance(demo, Demonstration):
        raise ValueError(f"demo must be a Demonstration, got {type(demo).__name__}")
    names = _check_names(joint_names, demo.n_joints, "joint_names")
    extra = dict(extra_joints or {})
    clash = [k for k in extra if k in names]
    if clash:
        raise ValueError(f"extra_joints {clash} are joints of the demonstration; rename them")
    all_names = [*names, *extra]
    _check_names(all_names, len(all_names), "joint_names and extra_joints")
    rate = check_positive_float(object_rate, "object_rate")
    start = check_positive_float(start_time, "start_time", allow_zero=True)
    if start + demo.duration >= _MAX_ROS_SECONDS:
        raise ValueError(
            f"start_time + the demonstration's duration ({demo.duration:g} s) must be < "
            f"{_MAX_ROS_SECONDS} s (2**31: ROS 2 stamps hold int32 seconds), got "
            f"start_time={short(start_time)}"
        )
    t0 = round(start * _NS)
    topics: dict[str, str | None] = {n: f"/{n}/pose" for n in demo.object_names}
    if object_topics is not None:
        unknown = [k for k in object_topics if k not in demo.objects]
        if unknown:
            raise ValueError(
                f"object_topics: unknown object(s) {unknown}; the demonstration has "
                f"{list(demo.object_names)}"
            )
        topics.update(object_topics)
    _check_topics(
        {
            "joint_topic": joint_topic,
            **{f"object_topics[{short(n)}]": v for n, v in topics.items() if v is not None},
            **({} if gripper_topic is None else {"gripper_topic": gripper_topic}),
        }
    )

    ts = _typestore()
    js_cls = ts.types[JOINT_STATE_TYPE]
    pose_cls = ts.types["geometry_msgs/msg/PoseStamped"]
    pose_t = ts.types["geometry_msgs/msg/Pose"]
    point_t = ts.types["geometry_msgs/msg/Point"]
    quat_t = ts.types["geometry_msgs/msg/Quaternion"]
    bool_cls = ts.types["std_msgs/msg/Bool"]
    stamps = t0 + np.round((demo.t - demo.t[0]) * _NS).astype(np.int64)
    values = np.hstack([demo.joints, np.tile(np.array(list(extra.values())), (demo.n_steps, 1))])
    empty = np.zeros(0, dtype=np.float64)
    pose_stamps = t0 + np.round(np.arange(0.0, demo.duration + 1e-12, 1.0 / rate) * _NS).astype(
        np.int64
    )

    def fill(writer: Writer) -> None:
        conn = writer.add_connection(joint_topic, JOINT_STATE_TYPE, typestore=ts)
        for i, ns in enumerate(stamps):
            order = (
                np.arange(len(all_names))
                if shuffle is None
                else shuffle.permutation(len(all_names))
            )
            msg = js_cls(
                header=_header(int(ns)),
                name=[all_names[k] for k in order],
                position=values[i, order],
                velocity=empty,
                effort=empty,
            )
            writer.write(conn, int(ns), ts.serialize_cdr(msg, JOINT_STATE_TYPE))
        for name, topic in topics.items():
            if topic is None:
                continue
            oconn = writer.add_connection(topic, "geometry_msgs/msg/PoseStamped", typestore=ts)
            x, y, z = (float(v) for v in position_of(demo.objects[name]))
            rot = rotation_of(demo.objects[name])
            # pbdkit's quaternions are w first; a ROS Quaternion is (x, y, z, w).
            qw, qx, qy, qz = (
                (1.0, 0.0, 0.0, 0.0)
                if rot is None
                else (float(v) for v in quaternion_from_matrix(rot))
            )
            pose = pose_t(
                position=point_t(x=x, y=y, z=z), orientation=quat_t(x=qx, y=qy, z=qz, w=qw)
            )
            for ns in pose_stamps:
                msg = pose_cls(header=_header(int(ns), frame_id), pose=pose)
                writer.write(oconn, int(ns), ts.serialize_cdr(msg, "geometry_msgs/msg/PoseStamped"))
        if gripper_topic is not None and demo.gripper is not None:
            gconn = writer.add_connection(gripper_topic, "std_msgs/msg/Bool", typestore=ts)
            closed = demo.gripper > GRIPPER_THRESHOLD
            for i in np.r_[0, np.flatnonzero(np.diff(closed)) + 1]:
                data = ts.serialize_cdr(bool_cls(data=bool(closed[i])), "std_msgs/msg/Bool")
                writer.write(gconn, int(stamps[i]), data)

    _write_bag_atomic(p, plugin, fill)
