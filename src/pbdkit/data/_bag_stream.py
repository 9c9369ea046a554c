"""An open ROS bag, streamed: its topics, and the messages of a topic one at a time, header
stamps read from their raw bytes; what cannot be a bag is refused before it is opened.

A FIFO, a device or a socket (or a bag directory holding one) is refused before the reader
opens it; any failure of the reader on a damaged file is a ValueError naming the bag
(:doc:`/reproduction`, "ROS bags").
"""

from __future__ import annotations

import stat
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .._validation import short
from ._ros import _NS, _stamp_ns, _typestore

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection

__all__: list[str] = []


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
                f"{what}: the bag {self.path} has no topic {short(topic)}; {self.listing()}"
            )
        actual = self.topics[topic]
        if actual is None or actual not in expected:
            want = " or ".join(expected)
            got = actual or "several types"
            raise ValueError(f"{what}: topic {short(topic)} must be of type {want}, got {got}")
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
