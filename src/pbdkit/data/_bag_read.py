"""A demonstration from a ROS bag (:func:`read_bag`): joint states, object placements and
the gripper signal of one recording.

Time is the joint states' header stamps (integer nanoseconds, converted once as differences);
joints are reordered by each message's names; an object is placed from the messages of the
demonstration's first second (median position, Karcher mean orientation; through tf for
another frame); the gripper is held between messages (closed where > 0.5). ROS quaternions are
(x, y, z, w), w last; pbdkit's (qw, qx, qy, qz), w first. The message types, every convention
and what is refused: :doc:`/reproduction`, "ROS bags".
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import as_pose, mean_rotation, pose_matrix
from .._validation import check_array, check_positive_float, short
from ..robots._protocols import BagRobot, check_robot
from ._bag_stream import _PASSED_THROUGH, _Bag, _open_reader, _unreadable
from ._demonstration import Demonstration
from ._ros import (
    _NS,
    GRIPPER_THRESHOLD,
    GRIPPER_TYPES,
    JOINT_STATE_TYPE,
    OBJECT_TYPES,
    OBJECT_WINDOW_NS,
    POSE_TYPES,
    _frame,
    _is_rotation,
    _ros_rotation,
    _stamp_ns,
)
from ._tf import _TfTree

if TYPE_CHECKING:
    from rosbags.interfaces import Connection

__all__ = ["read_bag"]

Float = NDArray[np.float64]
TF_PREFIX = "tf:"
#: Consecutive joint states may be at most this far apart (ns): no data about the motion for
#: longer means a paused recording or a lost driver (a gap of 1e8 s was once accepted).
MAX_JOINT_GAP_NS = 1_000_000_000


def read_bag(
    path: str | os.PathLike[str],
    *,
    robot: BagRobot,
    joint_topic: str = "/joint_states",
    objects: Mapping[str, str | npt.ArrayLike] | None = None,
    gripper_topic: str | None = None,
    start: float | None = None,
    end: float | None = None,
) -> Demonstration:
    """One demonstration from a ROS bag (conventions: :doc:`/reproduction`, "ROS bags").

    Parameters
    ----------
    path : str or path-like
        A rosbag2 directory (sqlite3 or MCAP storage), a ``.db3`` or ``.mcap`` storage file,
        or a ROS 1 ``.bag``.
    robot : BagRobot
        The arm (e.g. a :class:`pbdkit.Robot`): its ``joint_names`` order the joints, its
        ``base`` (the URDF root link) is the frame of the object positions and poses.
    joint_topic : str
        Topic of ``sensor_msgs/msg/JointState`` messages (kinesthetic teaching).
    objects : dict str -> str or array-like, optional
        Where each object is, in the base frame:

        - a topic of ``geometry_msgs/msg/PoseStamped`` or ``TransformStamped``: a pose, the
          median position and the Karcher mean orientation of the messages of the first
          second (a ROS quaternion is (x, y, z, w), w last: read so);
        - a topic of ``geometry_msgs/msg/PointStamped``: a position, their median;
        - a tf frame written ``"tf:frame_name"``: its pose;
        - fixed: a position (3,) (m), a 4x4 transform, or (x, y, z, qw, qx, qy, qz) with the
          quaternion **w first** (pytransform3d's convention, not ROS's).

        Default: none (a joint-space skill).
    gripper_topic : str, optional
        Topic of ``std_msgs/msg/Bool`` or ``Float64`` (``Float32``) messages: closed where
        > 0.5, held between messages, open before the first. Default: no gripper signal.
    start, end : float, optional
        Seconds after the first joint-state stamp of the bag: keep the samples stamped within
        [start, end] (default: from the first, to the last). Only these are deserialized.

    Returns
    -------
    demo : Demonstration
        t (T,) seconds from the first kept stamp, joints (T, n) in ``robot.joint_names``
        order, the objects in the order given (a pose as its 4x4 transform, a position as
        (3,): :func:`pbdkit.data._placement.position_of` gives the position of either),
        gripper (T,) of 0.0 and 1.0 or None.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        A file that is not a bag (a FIFO, a device, a damaged file), a missing topic (the
        message lists the bag's topics), a topic of the wrong type (expected and actual
        types), stamps that do not increase or stop for more than 1 s, a robot joint missing
        from a message, fewer than 2 samples between ``start`` and ``end``, an object without
        a finite position (or, from a pose topic, without a finite non-zero quaternion) in
        the first second, a fixed source that is no position or pose, a NaN gripper value, or
        a frame that tf does not join to the base. An error about the bag's content starts
        with its path.
    """
    check_robot(robot, BagRobot)
    sources = _check_sources(objects)
    window = _check_window(start, end)
    p = Path(path)
    reader = _open_reader(p)
    try:
        reader.open()
    except _PASSED_THROUGH:
        raise
    except Exception as exc:
        raise _unreadable(p, exc) from exc
    try:
        return _read_demonstration(
            _Bag(reader, p),
            joint_names=[str(n) for n in robot.joint_names],
            base=_frame(str(robot.base)),
            joint_topic=joint_topic,
            sources=sources,
            gripper_topic=gripper_topic,
            window=window,
        )
    except ValueError as exc:
        # Every error about the bag's content names the bag (one of several given to learn).
        if str(p) in str(exc):
            raise
        raise ValueError(f"{p}: {exc}") from exc
    finally:
        with contextlib.suppress(Exception):
            reader.close()


_SOURCE_FORMS = (
    "a topic, 'tf:frame', a position (3,) or a pose (4x4, or x, y, z, qw, qx, qy, qz with the "
    "quaternion w first)"
)


def _check_sources(objects: object) -> dict[str, str | Float]:
    """Topics and tf frames as given; fixed sources as a position (3,) or a 4x4 pose."""
    if objects is None:
        return {}
    if not isinstance(objects, Mapping):
        raise ValueError(
            f"objects must be a dict mapping object names to {_SOURCE_FORMS}, got "
            f"{type(objects).__name__}"
        )
    out: dict[str, str | Float] = {}
    for name, source in objects.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"objects keys must be non-empty strings, got {short(name)}")
        what = f"objects[{short(name)}]"
        if isinstance(source, str):
            if not source or source == TF_PREFIX:
                raise ValueError(f"{what} must be {_SOURCE_FORMS}, got {short(source)}")
            out[name] = source
        else:
            # Numbers only (check_array refuses strings, dates, complex), then the forms.
            position, rotation = as_pose(check_array(source, what, finite=False), what)
            out[name] = position if rotation is None else pose_matrix(position, rotation)
    return out


class _Window(NamedTuple):
    """The cut of :func:`read_bag`: nanoseconds after the first joint state."""

    start_ns: int
    end_ns: int | None
    text: str  # "[start, end]" in seconds as given, for messages

    def keeps(self, rel: int) -> bool:
        """Whether a stamp ``rel`` ns after the first joint state is within the cut."""
        return rel >= self.start_ns and (self.end_ns is None or rel <= self.end_ns)


# ROS stamps hold 32-bit seconds (ROS 2: int32, ROS 1: uint32), so two stamps of a bag are
# less than 2**32 s apart: a cut bound beyond that keeps what 2**32 s keeps. Clamping keeps
# the bound's nanoseconds within int64 (``start=1e300`` would not be).
_MAX_SPAN_S = 2.0**32


def _check_window(start: float | None, end: float | None) -> _Window:
    s = 0.0 if start is None else check_positive_float(start, "start", allow_zero=True)
    e = None if end is None else check_positive_float(end, "end", allow_zero=True)
    if e is not None and e <= s:
        raise ValueError(f"end must be > start ({short(s)} s), got {short(e)}")
    text = f"[{s:g}, {'end' if e is None else f'{e:g}'}]"
    start_ns = round(min(s, _MAX_SPAN_S) * _NS)
    return _Window(start_ns, None if e is None else round(min(e, _MAX_SPAN_S) * _NS), text)


def _read_demonstration(
    bag: _Bag,
    *,
    joint_names: list[str],
    base: str,
    joint_topic: str,
    sources: Mapping[str, str | Float],
    gripper_topic: str | None,
    window: _Window,
) -> Demonstration:
    bag.check_topic(joint_topic, (JOINT_STATE_TYPE,), "joint_topic")
    # Check every topic before reading any message: a wrong name fails at once.
    for name, source in sources.items():
        if isinstance(source, str) and not source.startswith(TF_PREFIX):
            bag.check_topic(source, tuple(OBJECT_TYPES), f"objects[{short(name)}]")
    if gripper_topic is not None:
        bag.check_topic(gripper_topic, GRIPPER_TYPES, "gripper_topic")

    stamps, logs, joints = _joint_states(bag, joint_topic, joint_names, window)
    t0 = int(stamps[0])

    tf: _TfTree | None = None

    def tf_tree() -> _TfTree:
        nonlocal tf
        if tf is None:
            tf = _TfTree.from_bag(bag, t0)
        return tf

    placements: dict[str, Float] = {}  # positions (3,) and poses (4, 4)
    for name, source in sources.items():
        what = f"objects[{short(name)}]"
        if not isinstance(source, str):
            placements[name] = source
        elif source.startswith(TF_PREFIX):
            frame = _frame(source[len(TF_PREFIX) :])
            placements[name] = tf_tree().pose(frame, base, what)
        else:
            placements[name] = _object_placement(bag, source, t0, base, tf_tree, what)

    gripper = None if gripper_topic is None else _gripper(bag, gripper_topic, logs)
    return Demonstration(
        t=(stamps - t0).astype(np.float64) * 1e-9,
        joints=joints,
        objects=placements,
        gripper=gripper,
    )


def _joint_states(
    bag: _Bag, topic: str, joint_names: list[str], window: _Window
) -> tuple[NDArray[np.int64], NDArray[np.int64], Float]:
    """Header stamps (ns), log times (ns) and joints (T, n) in ``joint_names`` order of the
    joint states within the cut ``window``.

    A message naming none of the robot's joints comes from another driver sharing the topic
    (a gripper's fingers) and is skipped; one naming some of them only is an error. Once the
    first joint state (the origin of the cut) is found, a message stamped outside the cut is
    skipped on its raw header stamp, not deserialized: a long bag costs a few bytes per
    message outside what is kept, and memory for what is kept only.
    """
    wanted = set(joint_names)
    index: list[int] = []  # the message number of each kept sample, for error messages
    stamps: list[int] = []
    logs: list[int] = []
    rows: list[Float] = []
    order: dict[tuple[str, ...], NDArray[np.intp] | None] = {}  # per layout of names
    origin: int | None = None  # the first joint state's stamp: the cut counts from it
    n_messages = n_robot = n_skipped = 0
    last = 0  # the stamp of the last joint state seen, after the origin (ns)
    previous: tuple[int, int] | None = None  # (message number, stamp) of the arm's last read
    for i, (log, raw, conn) in enumerate(bag.raw(topic)):
        n_messages += 1
        if origin is not None:
            ns = bag.stamp(raw, conn)
            # Stamped before the origin: deserialized, to be refused below if it is the arm's.
            if ns is not None and ns >= origin and not window.keeps(ns - origin):
                n_skipped += 1
                last = ns - origin
                continue
        msg = bag.message(raw, conn)
        names = tuple(msg.name)
        if names not in order:
            order[names] = (
                _joint_order(names, joint_names, topic, i) if wanted & set(names) else None
            )
        idx = order[names]
        if idx is None:
            continue
        n_robot += 1
        stamp = _stamp_ns(msg.header.stamp)
        if previous is not None and stamp <= previous[1]:
            raise ValueError(
                f"joint_topic: the header stamps of {short(topic)} must increase strictly in "
                f"recording order; message {i} is stamped {_seconds(stamp)} s, not after "
                f"message {previous[0]} ({_seconds(previous[1])} s)"
            )
        previous = (i, stamp)
        if origin is None:
            origin = stamp
        last = stamp - origin
        if not window.keeps(last):
            continue
        position = np.asarray(msg.position, dtype=np.float64)
        if position.shape != (len(names),):
            raise ValueError(
                f"joint_topic: message {i} of {short(topic)} has {len(names)} names and "
                f"{position.shape[0]} positions; they must match"
            )
        rows.append(position[idx])
        stamps.append(stamp)
        logs.append(log)
        index.append(i)
    if origin is None or (n_robot < 2 and not n_skipped):
        seen = sorted({n for names in order for n in names})
        raise ValueError(
            f"joint_topic: {n_robot} message(s) of {short(topic)} (of {n_messages}) name the "
            f"robot's joints {joint_names}, need at least 2; the messages name {seen}"
        )
    if len(rows) < 2:
        raise ValueError(
            f"start/end: {len(rows)} joint state(s) of {short(topic)} within {window.text} s, "
            f"need at least 2; the joint states span [0, {last * 1e-9:.3f}] s"
        )
    stamps_ = np.array(stamps, dtype=np.int64)
    gaps = np.diff(stamps_)
    long = np.flatnonzero(gaps > MAX_JOINT_GAP_NS)
    if long.size:
        k = int(long[0]) + 1
        raise ValueError(
            f"joint_topic: the joint states of {short(topic)} stop for "
            f"{_seconds(int(gaps[k - 1]))} "
            f"s after message {index[k - 1]} ({_seconds(stamps[k - 1] - origin)} s after the "
            f"first joint state); they must come at least every {MAX_JOINT_GAP_NS * 1e-9:g} s "
            "(a longer gap is a paused recording or a lost driver: cut it off with start/end)"
        )
    return stamps_, np.array(logs, dtype=np.int64), np.stack(rows)


def _seconds(ns: int) -> str:
    """Integer nanoseconds as exact decimal seconds."""
    sign = "-" if ns < 0 else ""
    return f"{sign}{abs(ns) // _NS}.{abs(ns) % _NS:09d}"


def _joint_order(
    names: tuple[str, ...], joint_names: list[str], topic: str, i: int
) -> NDArray[np.intp]:
    if len(set(names)) != len(names):
        raise ValueError(f"joint_topic: message {i} of {short(topic)} names a joint twice: {names}")
    where = {n: k for k, n in enumerate(names)}
    missing = [n for n in joint_names if n not in where]
    if missing:
        raise ValueError(
            f"joint_topic: joint(s) {missing} of the robot missing from message {i} of "
            f"{short(topic)}, which names {list(names)}"
        )
    return np.array([where[n] for n in joint_names], dtype=np.intp)


def _placement_of(msg: Any, msgtype: str) -> tuple[Float, Float | None, str]:
    """(position (3,), ROS quaternion (x, y, z, w) or None for a point, frame) of an object
    message."""
    quaternion = None
    if msgtype == "geometry_msgs/msg/PoseStamped":
        v, r = msg.pose.position, msg.pose.orientation
        quaternion = np.array([r.x, r.y, r.z, r.w], dtype=np.float64)
    elif msgtype == "geometry_msgs/msg/PointStamped":
        v = msg.point
    else:
        v, r = msg.transform.translation, msg.transform.rotation
        quaternion = np.array([r.x, r.y, r.z, r.w], dtype=np.float64)
    position = np.array([v.x, v.y, v.z], dtype=np.float64)
    return position, quaternion, _frame(str(msg.header.frame_id))


def _object_placement(
    bag: _Bag,
    topic: str,
    t0: int,
    base: str,
    tf_tree: Callable[[], _TfTree],
    what: str,
) -> Float:
    """The object of a topic source in the base frame: a position (3,) (PointStamped), or a
    pose (4, 4) (PoseStamped, TransformStamped): the median of the finite positions of the
    messages of the first second and the Karcher mean of those messages' valid orientations."""
    msgtype = bag.check_topic(topic, tuple(OBJECT_TYPES), what)
    window: list[Float] = []
    finite: list[Float] = []
    rotations: list[Float] = []  # of the messages with a finite position
    frames: set[str] = set()
    n_messages = 0
    first = last = 0  # the earliest and latest stamps (ns), for the error message
    for _, raw, conn in bag.raw(topic):
        msg = None
        ns = bag.stamp(raw, conn)
        if ns is None:
            msg = bag.message(raw, conn)
            ns = _stamp_ns(msg.header.stamp)
        first, last = (ns, ns) if not n_messages else (min(first, ns), max(last, ns))
        n_messages += 1
        if not t0 <= ns <= t0 + OBJECT_WINDOW_NS:
            continue  # outside the first second: not deserialized
        pos, quaternion, frame = _placement_of(
            bag.message(raw, conn) if msg is None else msg, msgtype
        )
        window.append(pos)
        if np.all(np.isfinite(pos)):  # a NaN from perception is an outlier too: dropped
            finite.append(pos)
            frames.add(frame)
            if quaternion is not None and _is_rotation(quaternion):
                rotations.append(_ros_rotation(quaternion))
    if not window:
        span = (
            f"its {n_messages} messages are stamped from {_seconds(first - t0)} to "
            f"{_seconds(last - t0)} s"
            if n_messages
            else "it has no messages"
        )
        raise ValueError(
            f"{what}: no message of {short(topic)} stamped within the first second of the "
            f"demonstration ([0, 1] s after the first joint state); {span}. Give the position "
            "as x,y,z, or choose start"
        )
    if not finite:
        raise ValueError(
            f"{what}: the {len(window)} message(s) of {short(topic)} stamped within the first "
            "second of the demonstration all hold NaN or infinite positions. Give the position "
            "as x,y,z, or choose start"
        )
    if len(frames) > 1:
        raise ValueError(
            f"{what}: the messages of {short(topic)} are in several frames {sorted(frames)}"
        )
    if msgtype in POSE_TYPES and not rotations:
        raise ValueError(
            f"{what}: none of the {len(finite)} message(s) of {short(topic)} with a finite "
            "position "
            "stamped within the first second of the demonstration holds an orientation: their "
            f"quaternions ({POSE_TYPES[msgtype]}: x, y, z, w) are all zero, NaN or infinite. "
            "Give the pose as x,y,z,qw,qx,qy,qz (quaternion w first), or choose start"
        )
    position = np.asarray(np.median(np.stack(finite), axis=0), dtype=np.float64)
    rotation = mean_rotation(np.stack(rotations)) if rotations else None
    (frame,) = frames
    if frame not in ("", base):
        rot, trans = tf_tree().transform(
            frame, base, f"{what} (frame {short(frame)} of {short(topic)})"
        )
        position = np.asarray(rot @ position + trans, dtype=np.float64)
        rotation = None if rotation is None else rot @ rotation
    return position if rotation is None else pose_matrix(position, rotation)


def _gripper(bag: _Bag, topic: str, joint_logs: NDArray[np.int64]) -> Float:
    """The gripper signal held at each joint state's log time: 1.0 closed, 0.0 open.

    Only the messages that hold a kept sample are deserialized: the last one logged at or
    before the first kept joint state, and those up to the last (the bag is read in log
    order, so reading stops there).
    """
    first, last = int(joint_logs.min()), int(joint_logs.max())
    held: list[tuple[int, int, bytes, Connection]] = []  # (message number, log, raw, conn)
    for i, (log, raw, conn) in enumerate(bag.raw(topic)):
        if log > last:
            break
        if log <= first:
            held = []  # an earlier message is replaced by this one at the first sample
        held.append((i, log, raw, conn))
    logs = np.array([log for _, log, _, _ in held], dtype=np.int64)
    closed = np.zeros(len(held), dtype=np.float64)
    for k, (i, _, raw, conn) in enumerate(held):
        value = float(bag.message(raw, conn).data)
        if not np.isfinite(value):
            # NaN > 0.5 is False: it would read as "open" where the signal is unknown.
            raise ValueError(
                f"gripper_topic: message {i} of {short(topic)} holds {value}; the gripper signal "
                f"must be finite (closed where > {GRIPPER_THRESHOLD})"
            )
        closed[k] = value > GRIPPER_THRESHOLD
    idx = np.searchsorted(logs, joint_logs, side="right") - 1
    out = np.zeros(joint_logs.shape[0], dtype=np.float64)
    held_at = idx >= 0
    out[held_at] = closed[idx[held_at]]
    return out
