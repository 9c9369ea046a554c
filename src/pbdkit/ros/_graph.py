"""The live side: a node's joint-state listener (:class:`JointStateListener`), with rclpy from
the ``ros`` extra, and the settings that keep a graph private (:func:`private_graph_env`)."""

from __future__ import annotations

import os
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._joints import JointOrder

__all__ = ["JointStateListener", "private_graph_env", "receiving", "ros_available"]

Float = NDArray[np.float64]

#: The ROS 2 quality of service of the joint trajectory controller's topics: reliable, depth 10.
QOS_DEPTH = 10


def ros_available() -> bool:
    """Whether rclpy and the message packages import (the ``ros`` extra)."""
    try:
        import rclpy  # noqa: F401
        import sensor_msgs.msg  # noqa: F401
        import trajectory_msgs.msg  # noqa: F401
    except ImportError:
        return False
    return True


@contextmanager
def receiving(node: Any) -> Iterator[None]:
    """The node's callbacks run on a thread of their own while the block runs: every message
    is taken as it comes, while the caller computes (``rclpy.spin_once`` in a loop takes one
    callback a turn, and none while the caller is busy: a recorder missed takes' starts, a
    run read joint states tens of milliseconds old). The caller then only sleeps between its
    looks at what the callbacks left."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, name="pbdkit-ros-receive", daemon=True)
    thread.start()
    try:
        yield
    finally:
        executor.shutdown(timeout_sec=2.0)
        thread.join(timeout=2.0)


def private_graph_env(name: str, env: dict[str, str] | None = None) -> dict[str, str]:
    """The environment of a process on a private graph: discovery on localhost only, and a
    ROS_DOMAIN_ID in 1-101 drawn from ``name`` (reproducible; two tests with different names
    rarely share one)."""
    out = dict(os.environ if env is None else env)
    out["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    out["ROS_DOMAIN_ID"] = str(1 + zlib.crc32(name.encode()) % 101)
    return out


class JointStateListener:
    """The arm's latest measured posture from ``sensor_msgs/JointState`` on ``topic``, matched by
    name (:class:`JointOrder`), with when it came (``time.monotonic()``, the node's clock for
    staleness: a driver's header stamps may be another machine's).

    A message with none of the arm's joints (another part's, on the same topic) is ignored; one
    that gives some of them but not all is kept as :attr:`error` (the first one) and otherwise
    ignored: the caller decides whether to stop. ``depth``: the subscription's history (the
    messages kept for the node while it is busy elsewhere).
    """

    def __init__(self, node: Any, topic: str, order: JointOrder, depth: int = QOS_DEPTH) -> None:
        from sensor_msgs.msg import JointState

        self.order, self.topic = order, topic
        self._names = frozenset(order.graph_names)
        self.q: Float | None = None
        self.v: Float = np.zeros(len(order.graph_names))  # zeros where a message gives none
        self.received: float | None = None
        self.count = 0
        self.error: str | None = None
        #: Called with each good message's time (its header stamp, s; where that is 0, when it
        #: came on the node's monotonic clock) and positions (the arm's order), if set.
        self.on_state: Callable[[float, Float], None] | None = None
        self._sub = node.create_subscription(JointState, topic, self._on_message, depth)

    def _on_message(self, msg: Any) -> None:
        if self._names.isdisjoint(msg.name):
            return  # another part's states (a gripper's, say) on the same topic
        try:
            q = self.order.positions(list(msg.name), list(msg.position), self.topic)
        except ValueError as err:
            if self.error is None:
                self.error = str(err)
            return
        if len(msg.velocity) == len(msg.name):
            self.v = np.asarray(msg.velocity, dtype=np.float64)[self.order.indices(list(msg.name))]
        self.q, self.received = q, time.monotonic()
        self.count += 1
        if self.on_state is not None:
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            self.on_state(stamp if stamp > 0 else self.received, q)

    def age(self) -> float:
        """Seconds since the last good message (inf before any)."""
        return np.inf if self.received is None else time.monotonic() - self.received
