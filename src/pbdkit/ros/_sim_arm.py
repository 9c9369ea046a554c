"""An arm on a ROS 2 graph without physics (:class:`SimArm`): a joint_trajectory_controller
(:class:`~pbdkit.ros._jtc.TrajectoryFollower`) on ``/NAME/joint_trajectory`` whose commands the
arm follows exactly (a message from when it arrives, or from its header stamp on the node's
clock), its joint states published on ``/joint_states``. The kinematic core of
``pbdkit ros sim`` (issue 37; the MuJoCo world and the objects come on top of it) and the robot
side of the tests of ``pbdkit ros run``."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..data._ros import _stamp_ns
from ._graph import QOS_DEPTH
from ._jtc import RejectedTrajectory, TrajectoryFollower

__all__ = ["SimArm"]

Float = NDArray[np.float64]


class SimArm:
    """A position-controlled arm behind a JTC, on ``node``.

    Parameters
    ----------
    node : rclpy.node.Node
    joint_names : sequence of str
        As it publishes and its controller takes them.
    q0 : array_like, shape (n,)
    controller : str
        The controller's name: it listens on ``/{controller}/joint_trajectory``.
    rate_hz : float
        Joint states published, and the controller updated, this often.
    interpolate_from_desired_state : bool
        The JTC's option (False: a message's first segment starts from the measured state).
    extra_joints : dict str -> float
        Joints it publishes besides the arm's (a finger, say), fixed, after the arm's.
    lag : float
        An arm that lags its controller (for tests of the following error): its joints follow
        the commands as a first-order lag of this time constant (s; 0: exactly).
    """

    def __init__(
        self,
        node: Any,
        joint_names: Sequence[str],
        q0: Any,
        *,
        controller: str = "arm_controller",
        rate_hz: float = 250.0,
        interpolate_from_desired_state: bool = False,
        extra_joints: dict[str, float] | None = None,
        lag: float = 0.0,
    ) -> None:
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        self.node = node
        self.names = [str(n) for n in joint_names]
        self.follower = TrajectoryFollower(
            self.names, q0, interpolate_from_desired_state=interpolate_from_desired_state
        )
        self.extra = dict(extra_joints or {})
        self.lag = float(lag)
        self._ticked = 0.0
        self.t0 = time.monotonic()
        self.q, self.v, _ = self.follower.desired(0.0)
        self.received = 0
        self.rejected: list[str] = []
        #: The desired positions on a 1 kHz grid of the arm's clock, up to the last tick (what
        #: the controller commanded: for checking them against the limits).
        self.commanded: list[Float] = []
        self._msg = JointState
        self._pub = node.create_publisher(JointState, "/joint_states", QOS_DEPTH)
        self._sub = node.create_subscription(
            JointTrajectory, f"/{controller}/joint_trajectory", self._on_trajectory, QOS_DEPTH
        )
        self._timer = node.create_timer(1.0 / rate_hz, self._tick)

    def now(self) -> float:
        """Seconds on the arm's monotonic clock."""
        return time.monotonic() - self.t0

    def _record_until(self, now: float) -> None:
        """The commands on the 1 kHz grid up to ``now``, from the trajectory in force (before
        a new one replaces it: the grid between two ticks is the old one's)."""
        while len(self.commanded) * 1e-3 <= now:
            self.commanded.append(self.follower.desired(len(self.commanded) * 1e-3)[0])

    def _on_trajectory(self, msg: Any) -> None:
        now = self.now()  # one instant: the grid up to it is the old trajectory's
        self._record_until(now)
        points = list(msg.points)
        times = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in points]

        def rows(field: str) -> Any:
            got = [list(getattr(p, field)) for p in points]
            return got if points and all(len(g) == len(self.names) for g in got) else None

        stamp = _stamp_ns(msg.header.stamp)
        ago = (int(self.node.get_clock().now().nanoseconds) - stamp) * 1e-9  # on the node's clock
        try:
            self.follower.receive(
                now,
                list(msg.joint_names),
                times,
                rows("positions"),
                rows("velocities"),
                rows("accelerations"),
                measured=(self.q, self.v),
                stamp=None if stamp == 0 else now - ago,
            )
        except (RejectedTrajectory, ValueError) as err:
            self.rejected.append(str(err))
            return
        self.received += 1

    def _tick(self) -> None:
        now = self.now()
        self._record_until(now)
        q, v, _ = self.follower.desired(now)
        if self.lag > 0.0:
            gain = min(1.0, (now - self._ticked) / self.lag)
            v = (q - self.q) * gain / max(now - self._ticked, 1e-6)
            q = self.q + (q - self.q) * gain
        self.q, self.v, self._ticked = q, v, now
        msg = self._msg()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.name = [*self.names, *self.extra]
        msg.position = [*self.q.tolist(), *self.extra.values()]
        msg.velocity = [*self.v.tolist(), *(0.0 for _ in self.extra)]
        self._pub.publish(msg)
