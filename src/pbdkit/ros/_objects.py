"""Object positions from a live graph (:class:`ObjectSources`, ``pbdkit ros run --object
NAME=SOURCE``): a ``geometry_msgs`` PoseStamped or PointStamped topic in the robot's base frame,
or fixed coordinates.

A topic's type is read from the graph (the first publisher's). A pose is passed on as a
7-vector (x, y, z, qw, qx, qy, qz) for an object the skill constrains in orientation
(:attr:`pbdkit.Skill.oriented`), as its position otherwise. A source that goes silent for
:data:`SILENT_AFTER` keeps its last pose, with a warning (and a line when it speaks again).

``tf:FRAME`` is refused: tf2_msgs has no PyPI wheel of the ROS 2 Jazzy set, so a node without
a ROS install cannot read /tf (``pbdkit learn`` reads tf from bags, which needs no message
package). Publish the object's pose as a PoseStamped instead.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import short
from ._graph import QOS_DEPTH

__all__ = ["SILENT_AFTER", "ObjectSources", "check_sources"]

Float = NDArray[np.float64]

#: Seconds without a message after which an object's source counts as silent.
SILENT_AFTER = 1.0
#: The message types an object's topic may carry.
TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PointStamped")
TF_REFUSED = (
    "tf is not read on a live graph: tf2_msgs has no PyPI wheel (the ros extra is PyPI's ROS 2 "
    "Jazzy wheels); publish the object's pose as a geometry_msgs/PoseStamped in the robot's "
    "base frame and give its topic"
)


def check_sources(sources: Mapping[str, str | Any]) -> None:
    """Refuse the sources a live node cannot read (``tf:FRAME``; a name that is neither a
    topic nor numbers), with a message (ValueError)."""
    for name, source in sources.items():
        if isinstance(source, str):
            if source.startswith("tf:"):
                raise ValueError(f"--object {name}={source}: {TF_REFUSED}")
            if not source.startswith("/"):
                raise ValueError(
                    f"--object {name}={short(source)}: give a topic (/NAME), x,y,z or "
                    "x,y,z,qw,qx,qy,qz"
                )


class ObjectSources:
    """The skill's objects, each from a topic or fixed, for a running controller.

    Parameters
    ----------
    node : rclpy.node.Node
    sources : dict str -> str or array
        A topic name (starting with ``/``) or fixed coordinates ((3,) or (7,)).
    oriented : sequence of str
        The objects the skill constrains in orientation (passed on as poses).
    log : callable
        Where the warnings and the objects seen go (one line each).
    """

    def __init__(
        self,
        node: Any,
        sources: Mapping[str, str | Any],
        oriented: Sequence[str] = (),
        *,
        log: Callable[[str], None] = print,
    ) -> None:
        check_sources(sources)
        self.node, self.log = node, log
        self.oriented = set(oriented)
        self.topics = {k: v for k, v in sources.items() if isinstance(v, str)}
        self.values: dict[str, Float] = {
            k: np.asarray(v, dtype=np.float64) for k, v in sources.items() if not isinstance(v, str)
        }
        self.received: dict[str, float] = {}
        self.frames: dict[str, str] = {}
        self.fresh: dict[str, Float] = {}  # arrived since the last take_new()
        self.silent: set[str] = set()
        self.ignored: set[str] = set()  # e.g. the grasped object once the gripper closed
        self._subs: dict[str, Any] = {}
        self._lock = threading.Lock()  # the messages may come on another thread (receiving)

    def subscribe(self, timeout: float, spin: Callable[[float], None]) -> None:
        """Find each topic's type on the graph and subscribe; then wait for a first message of
        each. Raises TimeoutError naming the topics missing after ``timeout`` s, ValueError
        for a topic of another type."""
        from geometry_msgs.msg import PointStamped, PoseStamped

        kinds = {TYPES[0]: PoseStamped, TYPES[1]: PointStamped}
        start = time.monotonic()
        while len(self._subs) < len(self.topics):
            found = dict(self.node.get_topic_names_and_types())
            for name, topic in self.topics.items():
                if name in self._subs or topic not in found:
                    continue
                types = [t for t in found[topic] if t in kinds]
                if not types:
                    raise ValueError(
                        f"--object {name}={topic}: the topic carries {found[topic]}, not a "
                        "geometry_msgs PoseStamped or PointStamped"
                    )
                self._subs[name] = self.node.create_subscription(
                    kinds[types[0]],
                    topic,
                    lambda msg, n=name: self._on_message(n, msg),
                    QOS_DEPTH,
                )
            if len(self._subs) < len(self.topics):
                self._check_time(start, timeout, "no publisher on")
                spin(0.05)
        while len(self.received) < len(self.topics):
            self._check_time(start, timeout, "no message on")
            spin(0.05)

    def _check_time(self, start: float, timeout: float, what: str) -> None:
        if time.monotonic() - start > timeout:
            missing = [t for k, t in self.topics.items() if k not in self.received]
            raise TimeoutError(f"{what} {', '.join(missing)} within {timeout:g} s")

    def _on_message(self, name: str, msg: Any) -> None:
        if name in self.ignored:
            return
        if hasattr(msg, "pose"):
            p, o = msg.pose.position, msg.pose.orientation
            value = np.array([p.x, p.y, p.z, o.w, o.x, o.y, o.z], dtype=np.float64)
            if name not in self.oriented:
                value = value[:3]
        else:
            p = msg.point
            value = np.array([p.x, p.y, p.z], dtype=np.float64)
        if not np.all(np.isfinite(value)):
            return
        if name in self.silent:
            self.silent.discard(name)
            self.log(f"{name}: {self.topics[name]} speaks again")
        with self._lock:
            if name in self.ignored:  # (since the check above: ignore() on another thread)
                return
            self.values[name] = value
            self.fresh[name] = value
        self.received[name] = time.monotonic()
        self.frames[name] = str(msg.header.frame_id)

    def check_silent(self) -> None:
        """Warn once for each source silent for :data:`SILENT_AFTER` (its last pose holds)."""
        now = time.monotonic()
        for name, at in self.received.items():
            if name not in self.silent and name not in self.ignored and now - at > SILENT_AFTER:
                self.silent.add(name)
                self.log(
                    f"warning: {name}: nothing on {self.topics[name]} for {now - at:.1f} s; "
                    "keeping its last pose"
                )

    def take_new(self) -> dict[str, Float]:
        """The values that arrived since the last call (for the controller's next step)."""
        with self._lock:
            out, self.fresh = self.fresh, {}
        return out

    def ignore(self, name: str) -> None:
        """Stop taking ``name``'s messages (its last value holds): the object the gripper
        has closed on moves with the hand, and the skill is relative to where it was."""
        if name in self.topics and name not in self.ignored:
            with self._lock:
                self.ignored.add(name)
                self.fresh.pop(name, None)

    def describe(self) -> str:
        """The objects as seen now, one line."""
        parts = []
        for name, value in self.values.items():
            where = self.topics.get(name, "fixed")
            frame = self.frames.get(name)
            where += f" [{frame}]" if frame else ""
            parts.append(f"{name} {np.round(value[:3], 3).tolist()} ({where})")
        return "; ".join(parts)
