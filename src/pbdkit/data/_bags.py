"""ROS bags: demonstrations from recordings of a real arm, trajectories back to ROS 2.

People who teach a real arm record a bag: the joint states of kinesthetic teaching, the object
poses their perception publishes, the gripper state. :func:`read_bag` turns one such recording
into a :class:`pbdkit.Demonstration`; :func:`write_trajectory_bag` writes a reproduction as a
``trajectory_msgs/msg/JointTrajectory`` that a ``ros2_control`` joint trajectory controller can
replay; :func:`write_demonstration_bag` records a :class:`~pbdkit.Demonstration` as a bag (for
simulated demonstrations, tests and examples). The `rosbags` library does the reading and
writing: no ROS installation is needed.

Formats
-------
Read: whatever :class:`rosbags.highlevel.AnyReader` reads: a rosbag2 bag (a directory holding
``metadata.yaml``, sqlite3 or MCAP storage), a single rosbag2 storage file (``.db3``, ``.mcap``),
or a ROS 1 ``.bag``. The message definitions stored in the bag are used; a bag without them is
read with ROS 2 Humble's. Written: rosbag2 bags (format version 9), sqlite3 (default) or MCAP
storage, message definitions included.

=================  ===============================================  ================================
what               message type                                     fields used
=================  ===============================================  ================================
joint states       ``sensor_msgs/msg/JointState``                   header.stamp, name, position
object (topic)     ``geometry_msgs/msg/PoseStamped``                pose.position, pose.orientation
                   ``geometry_msgs/msg/TransformStamped``           transform.translation, .rotation
                   ``geometry_msgs/msg/PointStamped``               point (a position only)
object (tf)        ``tf2_msgs/msg/TFMessage`` on ``/tf``,           every transform
                   ``/tf_static``
gripper            ``std_msgs/msg/Bool``, ``Float64``, ``Float32``  data (closed where > 0.5)
trajectory out     ``trajectory_msgs/msg/JointTrajectory``          joint_names, points
=================  ===============================================  ================================

An object read from a ``PoseStamped``, a ``TransformStamped`` or tf is a pose (its orientation
is kept); one read from a ``PointStamped`` is a position.

Conventions
-----------
- ROS time is sec + nanosec * 1e-9. Stamps are kept as integer nanoseconds and converted once,
  as differences, so the 1.7e9 s of an epoch stamp cost no precision.
- Time of a demonstration: the joint states' ``header.stamp``. ``start`` and ``end`` are
  seconds after the first joint-state stamp of the bag; the samples stamped within
  [first + start, first + end] are kept, and the time origin (t = 0) is the first of them: the
  first joint-state stamp at or after ``start``. The stamps must increase strictly in
  recording order, and consecutive kept samples be at most 1 s apart
  (``MAX_JOINT_GAP_NS``): a longer gap is a paused recording or a lost driver, and a
  demonstration has no data about the motion there (cut it off with ``start``/``end``).
- Bags are streamed: messages are read one at a time and memory holds what is kept. A
  message outside the cut is skipped on its header stamp, read from its raw bytes, and is
  not deserialized (nor checked); a joint state stamped before the first is an error.
- Joint positions are reordered to ``robot.joint_names`` by each message's ``name`` field
  (drivers publish in any order, and the order may change between messages); joints the robot
  does not have (gripper fingers) are ignored, and so are messages that name none of the
  robot's joints (another driver publishing on the same topic). A message that names some of
  them but not all is an error.
- Objects are placed in the robot's base frame (``robot.base``, the URDF root link), constant
  during a demonstration (as in the paper); see :mod:`pbdkit.data._placement`. A
  ``PoseStamped``, ``TransformStamped`` or ``"tf:frame"`` source gives a pose, kept as its 4x4
  transform [[R, p], [0, 0, 0, 1]] (the orientation as well as the position); a
  ``PointStamped`` source gives a position (3,); a fixed source is what it is: a position
  (3,), a 4x4 transform or (x, y, z, qw, qx, qy, qz).
- Quaternions: a ROS message holds (x, y, z, w), **w last**; pbdkit's own are (qw, qx, qy,
  qz), **w first** (pytransform3d's convention), as in a fixed source (x, y, z, qw, qx, qy,
  qz). A message's quaternion is normalized; a zero or non-finite one is dropped.
- A topic source gives the component-wise median of the positions of its messages stamped
  within the demonstration's first second, [t0, t0 + 1 s]: before the hand moves anything, and
  robust to a perception outlier; for a pose, the orientation is the Karcher mean
  (:func:`pbdkit._rotations.mean_rotation`) of the orientations of the same messages
  (not robust to a gross outlier as the median is: a flip of 180 degrees in one of N messages
  turns the mean by about 180/N degrees). Non-finite positions (a NaN from a tracker that lost
  the object) are outliers too: dropped before the median, an error only if no finite one
  remains (tf transforms likewise). A message counts for the orientation if its position is
  finite and its quaternion is finite and not zero; an error if no message does. A message in
  another frame than the base (its ``header.frame_id``, neither empty nor ``robot.base``) is
  expressed in the base frame through tf, as a ``"tf:frame"`` source is: position and
  orientation.
- tf: the transforms of ``/tf`` stamped within the first second and every transform of
  ``/tf_static``. Each parent -> child link is estimated from its transforms (median
  translation; the sign-aligned mean of the finite, non-zero quaternions, normalized) and a
  frame's pose in the base frame composes the links from the base down to it through their
  parents (tf2's lookup: the base may itself hang below a common root, such as ``world``). If
  the base is not reached, the error names both chains up to where they stop.
- The gripper messages carry no header: they are placed by their recording (log) time against
  the joint states' log times and held between messages (zero-order hold); before the first
  message the gripper is open (0). A NaN or infinite gripper value among the messages that
  hold a kept sample is an error (NaN > 0.5 would read as open).

Bad input
---------
Every problem raises before anything is returned or written: :class:`FileNotFoundError` for a
bag that does not exist, :class:`ValueError` otherwise, naming the argument and the expected
and actual value: a topic not in the bag (the message lists the bag's topics and types), a topic
of another type (expected and actual types), non-monotonic stamps (the two messages and their
stamps), a gap in them, a robot joint missing from a message (named), an empty cut, an object
without a finite position or (for a pose) without a valid orientation in the first second, an
object frame that tf does not join to the base. An error about a bag's content starts with the bag's
path. A FIFO, a device or a socket (or a bag directory holding one) is refused before it is
opened: reading one blocks, or never ends. A damaged file makes the reader fail in many ways
(OverflowError, KeyError, AssertionError, ...): all are a ValueError naming the bag.

Writers check every argument before they write anything: times within what ROS's int32
seconds hold (below ``2**31`` s) and increasing at its 1 ns resolution, topics that are ROS names
and distinct, at least one joint. They refuse an existing path (a bag is a directory: nothing
is overwritten or deleted) and write atomically: the bag is written into a temporary sibling
directory and renamed onto the target (``os.replace``), so a reader never sees half a bag.
"""

from __future__ import annotations

import contextlib
import functools
import os
import re
import shutil
import stat
import struct
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import (
    as_pose,
    matrix_from_quaternion,
    mean_rotation,
    pose_matrix,
    quaternion_from_matrix,
)
from .._validation import check_array, check_positive_float
from ._demonstration import Demonstration
from ._placement import position_of, rotation_of

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection
    from rosbags.rosbag2 import Writer
    from rosbags.typesys.store import Typestore

    from ..robots._robot import Robot

__all__ = [
    "GRIPPER_TYPES",
    "JOINT_STATE_TYPE",
    "OBJECT_TYPES",
    "POSE_TYPES",
    "STORAGES",
    "TF_TOPICS",
    "TRAJECTORY_TYPE",
    "read_bag",
    "write_demonstration_bag",
    "write_trajectory_bag",
]

Float = NDArray[np.float64]
Storage = Literal["sqlite3", "mcap"]

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
#: Message types of an object topic, and where each holds the position.
OBJECT_TYPES: Mapping[str, str] = {
    "geometry_msgs/msg/PoseStamped": "pose.position",
    "geometry_msgs/msg/PointStamped": "point",
    "geometry_msgs/msg/TransformStamped": "transform.translation",
}
#: The object types that give a pose, and where each holds the orientation: a
#: ``geometry_msgs/msg/Quaternion``, (x, y, z, w) with w **last** (ROS's order).
POSE_TYPES: Mapping[str, str] = {
    "geometry_msgs/msg/PoseStamped": "pose.orientation",
    "geometry_msgs/msg/TransformStamped": "transform.rotation",
}
#: A message's quaternion of a smaller norm is no rotation (a tracker's "unknown"): dropped.
MIN_QUATERNION_NORM = 1e-9
GRIPPER_TYPES = ("std_msgs/msg/Bool", "std_msgs/msg/Float64", "std_msgs/msg/Float32")
TF_TYPE = "tf2_msgs/msg/TFMessage"
TF_TOPICS = ("/tf", "/tf_static")
TRAJECTORY_TYPE = "trajectory_msgs/msg/JointTrajectory"
STORAGES: tuple[Storage, ...] = ("sqlite3", "mcap")
TF_PREFIX = "tf:"
#: Objects are located from the messages of the demonstration's first second.
OBJECT_WINDOW_NS = 1_000_000_000
#: Consecutive joint states may be at most this far apart (ns): no data about the motion for
#: longer means a paused recording or a lost driver (a gap of 1e8 s was once accepted).
MAX_JOINT_GAP_NS = 1_000_000_000
#: A gripper signal above this is closed.
GRIPPER_THRESHOLD = 0.5
_NS = 1_000_000_000


@functools.cache
def _typestore() -> Typestore:
    """ROS 2 Humble's message types (built once: it takes ~0.1 s)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _stamp_ns(stamp: Any) -> int:
    """A builtin_interfaces Time (sec, nanosec) as integer nanoseconds."""
    return int(stamp.sec) * _NS + int(stamp.nanosec)


def _frame(name: str) -> str:
    """A tf frame id as tf2 keys it: without a leading slash (ROS 1 bags often have one)."""
    return name.lstrip("/")


# ============================================================================ reading
class _Bag:
    """An open bag: its topics, and the messages of one topic, streamed.

    Messages are read one at a time (nothing holds a whole topic), and deserialized only
    where needed: the header stamp of a message that begins with a ``std_msgs/Header`` is
    read from its raw bytes (:meth:`stamp`), so that the messages outside a cut cost a
    few bytes each. Any failure of the reader on the bag's content (a corrupted or
    truncated file makes it raise OverflowError, KeyError, AssertionError, ...) becomes
    a ValueError naming the bag.
    """

    def __init__(self, reader: AnyReader, path: Path) -> None:
        self.reader = reader
        self.path = path
        self.topics = {name: info.msgtype for name, info in reader.topics.items()}
        # Connection id -> whether its raw header stamp equals the deserialized one (checked
        # on its first message: a bag's own message definitions could differ from Humble's).
        self._raw_stamps: dict[int, bool] = {}

    def listing(self) -> str:
        """The bag's topics and types, for error messages."""
        if not self.topics:
            return "the bag has no topics"
        items = ", ".join(f"{t} ({m or 'several types'})" for t, m in sorted(self.topics.items()))
        return f"its topics: {items}"

    def check_topic(self, topic: str, expected: Sequence[str], what: str) -> str:
        """The message type of ``topic``, or a ValueError naming what was expected."""
        if topic not in self.topics:
            raise ValueError(
                f"{what}: the bag {self.path} has no topic {topic!r}; {self.listing()}"
            )
        actual = self.topics[topic]
        if actual is None or actual not in expected:
            want = " or ".join(expected)
            got = actual or "several types"
            raise ValueError(f"{what}: topic {topic!r} must be of type {want}, got {got}")
        return actual

    def unreadable(self, exc: BaseException) -> ValueError:
        """The error for a reader that failed on the bag's content."""
        return _unreadable(self.path, exc)

    def raw(self, topic: str) -> Iterator[tuple[int, bytes, Connection]]:
        """(log time ns, raw message, connection) of each message of ``topic``, in recording
        order (log time), not deserialized."""
        conns: list[Connection] = [c for c in self.reader.connections if c.topic == topic]
        if not conns:  # the reader would read every topic
            return
        items = self.reader.messages(connections=conns)
        while True:
            try:
                conn, log, raw = next(items)
            except StopIteration:
                return
            except _PASSED_THROUGH:
                raise
            except Exception as exc:
                raise self.unreadable(exc) from exc
            yield int(log), raw, conn

    def message(self, raw: bytes, conn: Connection) -> Any:
        """A raw message, deserialized."""
        try:
            msg = self.reader.deserialize(raw, conn.msgtype)
        except _PASSED_THROUGH:
            raise
        except Exception as exc:
            raise self.unreadable(exc) from exc
        if conn.id not in self._raw_stamps:
            header = getattr(msg, "header", None)
            stamp = getattr(header, "stamp", None)
            self._raw_stamps[conn.id] = stamp is not None and _raw_stamp(
                raw, ros2=self.reader.is2
            ) == _stamp_ns(stamp)
        return msg

    def stamp(self, raw: bytes, conn: Connection) -> int | None:
        """The header stamp (ns) of a raw message, without deserializing it; None where it
        cannot be read so (the connection's first message, which :meth:`message` checks, or
        a type without a leading header): deserialize it then."""
        if not self._raw_stamps.get(conn.id, False):
            return None
        return _raw_stamp(raw, ros2=self.reader.is2)

    def messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        """(log time ns, message) of each message of ``topic``, deserialized one at a time."""
        for log, raw, conn in self.raw(topic):
            yield log, self.message(raw, conn)


# Errors a reader raises that are not about the bag's content: passed on as they are.
_PASSED_THROUGH = (PermissionError, FileNotFoundError)


def _raw_stamp(raw: bytes, *, ros2: bool) -> int | None:
    """The header stamp (ns) of a serialized message that begins with a std_msgs/Header.

    CDR (ROS 2): a 4-byte encapsulation header (its 2nd byte 1: little-endian, 0: big),
    then stamp.sec int32 and stamp.nanosec uint32. ROS 1: seq uint32, then stamp.secs and
    stamp.nsecs uint32, little-endian.
    """
    if len(raw) < 12:
        return None
    if ros2:
        order = "<" if raw[1] == 1 else ">"
        sec, nanosec = struct.unpack_from(f"{order}iI", raw, 4)
    else:
        sec, nanosec = struct.unpack_from("<II", raw, 4)
    return int(sec) * _NS + int(nanosec)


def _unreadable(path: Path, exc: BaseException) -> ValueError:
    """A ValueError naming the bag a reader failed on (its own error, or any other)."""
    reader_errors = _reader_errors()
    text = " ".join(str(exc).split())
    if not isinstance(exc, reader_errors):
        text = f"corrupt or truncated ({type(exc).__name__}: {text})"
    return ValueError(f"{path} is not a readable ROS bag: {text}")


def _file_kind(mode: int) -> str | None:
    """What a file that is neither a directory nor a regular file is (None for those)."""
    kinds = (
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    )
    if stat.S_ISDIR(mode) or stat.S_ISREG(mode):
        return None
    return next((text for test, text in kinds if test(mode)), "not a regular file")


def _check_bag_path(path: Path) -> None:
    """Refuse what cannot be a bag before the reader opens it: a FIFO blocks the reader for
    ever and a device (/dev/zero) feeds it without end. A rosbag2 bag is a directory holding
    metadata.yaml and its storage files: those must be regular files too. Symbolic links
    are followed (what they point to is what is read)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise FileNotFoundError(f"bag not found: {path}") from None
    kind = _file_kind(mode)
    if kind is not None:
        raise ValueError(
            f"{path} is {kind}, not a ROS bag (give a rosbag2 directory, a .db3 or .mcap "
            "storage file, or a ROS 1 .bag file)"
        )
    if not stat.S_ISDIR(mode):
        return
    if not (path / "metadata.yaml").exists():
        raise ValueError(
            f"{path} is a directory without metadata.yaml: not a rosbag2 bag (give the bag's "
            "directory, a .db3 or .mcap storage file, or a ROS 1 .bag file)"
        )
    for item in sorted(path.iterdir()):
        try:
            kind = _file_kind(item.stat().st_mode)
        except FileNotFoundError:  # a dangling link: the reader says if it needs it
            continue
        if kind is not None:
            raise ValueError(
                f"{path}: {item.name} is {kind}; a rosbag2 bag holds regular files only"
            )


def _open_reader(path: Path) -> AnyReader:
    from rosbags.highlevel import AnyReader

    _check_bag_path(path)
    try:
        return AnyReader([path], default_typestore=_typestore())
    except _PASSED_THROUGH:
        raise
    except Exception as exc:
        raise _unreadable(path, exc) from exc


def _reader_errors() -> tuple[type[Exception], ...]:
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error

    return (AnyReaderError, Reader1Error, Reader2Error)


def read_bag(
    path: str | os.PathLike[str],
    *,
    robot: Robot,
    joint_topic: str = "/joint_states",
    objects: Mapping[str, str | npt.ArrayLike] | None = None,
    gripper_topic: str | None = None,
    start: float | None = None,
    end: float | None = None,
) -> Demonstration:
    """One demonstration from a ROS bag (see the module docstring for the conventions).

    Parameters
    ----------
    path : str or path-like
        A rosbag2 directory (sqlite3 or MCAP storage), a ``.db3`` or ``.mcap`` storage file,
        or a ROS 1 ``.bag``.
    robot : Robot
        The arm: its ``joint_names`` order the joints, its ``base`` (the URDF root link) is
        the frame of the object positions and poses.
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
    joint_names = getattr(robot, "joint_names", None)
    base = getattr(robot, "base", None)
    if not isinstance(joint_names, list) or not isinstance(base, str):
        raise ValueError(
            "robot must be a pbdkit.Robot (with joint_names and base), e.g. "
            f"pbdkit.robots.katana(), got {type(robot).__name__}"
        )
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
            joint_names=[str(n) for n in joint_names],
            base=_frame(base),
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
            raise ValueError(f"objects keys must be non-empty strings, got {name!r}")
        what = f"objects[{name!r}]"
        if isinstance(source, str):
            if not source or source == TF_PREFIX:
                raise ValueError(f"{what} must be {_SOURCE_FORMS}, got {source!r}")
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
        raise ValueError(f"end must be > start ({s!r} s), got {e!r}")
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
            bag.check_topic(source, tuple(OBJECT_TYPES), f"objects[{name!r}]")
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
        what = f"objects[{name!r}]"
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
                f"joint_topic: the header stamps of {topic!r} must increase strictly in "
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
                f"joint_topic: message {i} of {topic!r} has {len(names)} names and "
                f"{position.shape[0]} positions; they must match"
            )
        rows.append(position[idx])
        stamps.append(stamp)
        logs.append(log)
        index.append(i)
    if origin is None or (n_robot < 2 and not n_skipped):
        seen = sorted({n for names in order for n in names})
        raise ValueError(
            f"joint_topic: {n_robot} message(s) of {topic!r} (of {n_messages}) name the "
            f"robot's joints {joint_names}, need at least 2; the messages name {seen}"
        )
    if len(rows) < 2:
        raise ValueError(
            f"start/end: {len(rows)} joint state(s) of {topic!r} within {window.text} s, "
            f"need at least 2; the joint states span [0, {last * 1e-9:.3f}] s"
        )
    stamps_ = np.array(stamps, dtype=np.int64)
    gaps = np.diff(stamps_)
    long = np.flatnonzero(gaps > MAX_JOINT_GAP_NS)
    if long.size:
        k = int(long[0]) + 1
        raise ValueError(
            f"joint_topic: the joint states of {topic!r} stop for {_seconds(int(gaps[k - 1]))} "
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
        raise ValueError(f"joint_topic: message {i} of {topic!r} names a joint twice: {names}")
    where = {n: k for k, n in enumerate(names)}
    missing = [n for n in joint_names if n not in where]
    if missing:
        raise ValueError(
            f"joint_topic: joint(s) {missing} of the robot missing from message {i} of "
            f"{topic!r}, which names {list(names)}"
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


def _is_rotation(quaternion: Float) -> bool:
    """Whether a message's quaternion is a rotation: finite and not zero (then normalized)."""
    return bool(
        np.all(np.isfinite(quaternion)) and np.linalg.norm(quaternion) > MIN_QUATERNION_NORM
    )


def _ros_rotation(quaternion: Float) -> Float:
    """The rotation matrix of a ROS quaternion (x, y, z, w), w LAST, normalized first (the
    Hamilton convention, as tf2's): pbdkit's quaternions put w first."""
    x, y, z, w = quaternion
    return matrix_from_quaternion(np.array([w, x, y, z], dtype=np.float64))


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
            f"{what}: no message of {topic!r} stamped within the first second of the "
            f"demonstration ([0, 1] s after the first joint state); {span}. Give the position "
            "as x,y,z, or choose start"
        )
    if not finite:
        raise ValueError(
            f"{what}: the {len(window)} message(s) of {topic!r} stamped within the first "
            "second of the demonstration all hold NaN or infinite positions. Give the position "
            "as x,y,z, or choose start"
        )
    if len(frames) > 1:
        raise ValueError(
            f"{what}: the messages of {topic!r} are in several frames {sorted(frames)}"
        )
    if msgtype in POSE_TYPES and not rotations:
        raise ValueError(
            f"{what}: none of the {len(finite)} message(s) of {topic!r} with a finite position "
            "stamped within the first second of the demonstration holds an orientation: their "
            f"quaternions ({POSE_TYPES[msgtype]}: x, y, z, w) are all zero, NaN or infinite. "
            "Give the pose as x,y,z,qw,qx,qy,qz (quaternion w first), or choose start"
        )
    position = np.asarray(np.median(np.stack(finite), axis=0), dtype=np.float64)
    rotation = mean_rotation(np.stack(rotations)) if rotations else None
    (frame,) = frames
    if frame not in ("", base):
        rot, trans = tf_tree().transform(frame, base, f"{what} (frame {frame!r} of {topic!r})")
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
                f"gripper_topic: message {i} of {topic!r} holds {value}; the gripper signal "
                f"must be finite (closed where > {GRIPPER_THRESHOLD})"
            )
        closed[k] = value > GRIPPER_THRESHOLD
    idx = np.searchsorted(logs, joint_logs, side="right") - 1
    out = np.zeros(joint_logs.shape[0], dtype=np.float64)
    held_at = idx >= 0
    out[held_at] = closed[idx[held_at]]
    return out


# ============================================================================ tf
class _TfTree:
    """The tf links of a demonstration's first second: child -> (parent, rotation, translation),
    the child frame's pose in its parent's."""

    def __init__(self, links: Mapping[str, tuple[str, Float, Float]], source: str) -> None:
        self.links = dict(links)
        self.source = source

    @classmethod
    def from_bag(cls, bag: _Bag, t0: int) -> _TfTree:
        present = [t for t in TF_TOPICS if t in bag.topics]
        if not present:
            raise ValueError(
                f"tf: the bag {bag.path} has neither /tf nor /tf_static, needed to place a "
                f"frame in the robot's base frame; {bag.listing()}"
            )
        samples: dict[tuple[str, str], list[tuple[Float, Float]]] = {}
        for topic in present:
            bag.check_topic(topic, (TF_TYPE,), "tf")
            static = topic == "/tf_static"
            for _, msg in bag.messages(topic):
                for tr in msg.transforms:
                    ns = _stamp_ns(tr.header.stamp)
                    if not static and not t0 <= ns <= t0 + OBJECT_WINDOW_NS:
                        continue
                    v, r = tr.transform.translation, tr.transform.rotation
                    key = (_frame(str(tr.header.frame_id)), _frame(str(tr.child_frame_id)))
                    samples.setdefault(key, []).append(
                        (np.array([v.x, v.y, v.z]), np.array([r.x, r.y, r.z, r.w]))
                    )
        links: dict[str, tuple[str, Float, Float]] = {}
        for (parent, child), items in samples.items():
            if child in links:
                raise ValueError(
                    f"tf: frame {child!r} has two parents, {links[child][0]!r} and {parent!r}"
                )
            links[child] = (parent, *_mean_transform(items, parent, child))
        return cls(links, " and ".join(present))

    def _to_root(self, frame: str) -> tuple[list[str], Float, Float]:
        """The chain frame <- parent <- ... <- root and the pose of ``frame`` in the root."""
        chain = [frame]
        rot, trans = np.eye(3), np.zeros(3)
        while chain[-1] in self.links:
            parent, r, p = self.links[chain[-1]]
            if parent in chain:
                raise ValueError(f"tf: the frames {[*chain, parent]} form a cycle")
            # T_parent_frame = T_parent_child @ T_child_frame
            rot, trans = r @ rot, r @ trans + p
            chain.append(parent)
        return chain, rot, trans

    def transform(self, frame: str, base: str, what: str) -> tuple[Float, Float]:
        """Rotation (3, 3) and translation (3,) of ``frame`` in ``base``."""
        chain_f, rot_f, trans_f = self._to_root(frame)
        chain_b, rot_b, trans_b = self._to_root(base)
        if chain_f[-1] != chain_b[-1]:
            raise ValueError(
                f"{what}: tf does not join {frame!r} to the robot's base {base!r}: "
                f"{' <- '.join(chain_f)} and {' <- '.join(chain_b)} end in different roots "
                f"(transforms of {self.source} during the first second)"
            )
        # T_base_frame = T_root_base^-1 @ T_root_frame
        return rot_b.T @ rot_f, rot_b.T @ (trans_f - trans_b)

    def pose(self, frame: str, base: str, what: str) -> Float:
        """The pose (4, 4) of ``frame`` in ``base``: its origin (m) and axes."""
        rot, trans = self.transform(frame, base, f"{what} (tf:{frame})")
        return pose_matrix(trans, rot)


def _mean_transform(
    items: Sequence[tuple[Float, Float]], parent: str, child: str
) -> tuple[Float, Float]:
    """Rotation and translation of one link from its samples (quaternions (x, y, z, w), ROS's
    order): median translation, mean of the sign-aligned quaternions, normalized (the chordal
    mean: exact for equal samples). A zero quaternion (no rotation) counts for the translation
    only: as the reference of the signs it would leave them unaligned."""
    items = [(p, q) for p, q in items if np.all(np.isfinite(p)) and np.all(np.isfinite(q))]
    if not items:  # non-finite samples are dropped as outliers, as an object topic's are
        raise ValueError(
            f"tf: the transforms {parent!r} -> {child!r} of the first second are all NaN or "
            "infinite"
        )
    trans = np.median(np.stack([p for p, _ in items]), axis=0)
    quats = np.stack([q for _, q in items if _is_rotation(q)] or [np.zeros(4)])
    quats = quats * np.where(quats @ quats[0] < 0, -1.0, 1.0)[:, None]
    q = quats.mean(axis=0)
    norm = float(np.linalg.norm(q))
    if not (np.isfinite(norm) and norm > 1e-9 and np.all(np.isfinite(trans))):
        raise ValueError(f"tf: the transform {parent!r} -> {child!r} is not a valid rotation")
    return _ros_rotation(q / norm), np.asarray(trans, dtype=np.float64)


# ============================================================================ writing
def _check_new_path(path: str | os.PathLike[str], name: str = "path") -> Path:
    p = Path(path)
    if p.exists() or p.is_symlink():
        raise ValueError(
            f"{name} {p} exists; give a new path (a bag is a directory and is never overwritten)"
        )
    return p


def _check_storage(storage: object) -> Storage:
    if storage not in STORAGES:
        raise ValueError(f"storage must be one of {list(STORAGES)}, got {storage!r}")
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
                f"not starting with a digit, e.g. '/joint_trajectory'), got {topic!r}"
            )
        if topic in seen:
            raise ValueError(
                f"{name} must differ from {seen[topic]} ({topic!r}): a topic carries one "
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

    Raises
    ------
    ValueError
        An existing ``path``, or a shape, value or name that does not fit (named). Every
        argument is checked before anything is written.
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
) -> tuple[memoryview, list[tuple[int, memoryview]]]:
    """The checked arguments of :func:`write_trajectory_bag` as its serialized messages: the
    JointTrajectory, and (log time ns, Bool) of the gripper's. Nothing is written: `pbdkit
    reproduce --bag` calls it to refuse a bag before it writes ``--out``."""
    _check_topics({"topic": topic, **({} if gripper is None else {"gripper_topic": gripper_topic})})
    t_ = check_array(t, "t", ndim=1, min_rows=1)
    if t_[0] < 0:
        raise ValueError(f"t must be >= 0 (time from start), got t[0]={float(t_[0])!r}")
    if np.any(t_ >= _MAX_ROS_SECONDS):
        i = int(np.argmax(t_ >= _MAX_ROS_SECONDS))
        raise ValueError(
            f"t must be < {_MAX_ROS_SECONDS} s (2**31: time_from_start holds int32 seconds), "
            f"got t[{i}]={float(t_[i])!r}"
        )
    ns = np.round(t_ * _NS).astype(np.int64)  # < 2**31 s: within int64 ns
    if np.any(np.diff(ns) <= 0):
        i = int(np.argmax(np.diff(ns) <= 0))
        a, b = float(t_[i]), float(t_[i + 1])
        if b > a:  # increasing, but not at the resolution of the stamps
            raise ValueError(
                f"t must increase by at least 1 ns (the resolution of time_from_start), got "
                f"t[{i}]={a!r} and t[{i + 1}]={b!r}, {b - a:.3g} s apart"
            )
        raise ValueError(f"t must increase strictly, got t[{i}]={a!r} and t[{i + 1}]={b!r}")
    q = check_array(joints, "joints", shape=(t_.shape[0], None))
    if q.shape[1] == 0:
        raise ValueError(f"joints must have one column per joint, at least 1, got shape {q.shape}")
    names = _check_names(joint_names, q.shape[1], "joint_names")
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
            f"start_time={start_time!r}"
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
            **{f"object_topics[{n!r}]": v for n, v in topics.items() if v is not None},
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
