"""The MuJoCo world of a task as a ROS 2 robot (:class:`SimWorld`, ``pbdkit ros sim``, issue 37):
the arm behind a joint_trajectory_controller, the gripper behind another, the objects' poses on
topics, the run judged as ``pbdkit evaluate`` judges a trial. The world itself is
:class:`pbdkit.ros._task_world.TaskWorld`; this puts it on a node.

Topics (QoS depth :data:`pbdkit.ros._graph.QOS_DEPTH`, reliable):

- ``/joint_states`` (``sensor_msgs/JointState``), every timer period (250 Hz): the arm's
  measured joints (pan, lift1, lift2, lift3, wrist_roll) and ``gripper``, the gripper's
  command (0.0 open, 1.0 closed); positions and velocities;
- ``/objects/NAME`` (``geometry_msgs/PoseStamped``, frame ``base_link``, the robot's base) at
  15 Hz: every object of the task, true or as the cameras see it (no message for an object the
  tracker has not located yet);
- it follows ``/arm_controller/joint_trajectory`` and ``/gripper_controller/joint_trajectory``
  (``trajectory_msgs/JointTrajectory``; the gripper's one joint ``gripper``) by the JTC's rules
  (:class:`~pbdkit.ros._jtc.TrajectoryFollower`), not with ``teach``. A message starts when it
  arrives (header stamp 0) or at its header stamp (read in the world's time, as the stamps it
  publishes); a refused one is logged and counted.

With ``teach`` the replay begins :data:`SUBSCRIBER_GRACE` s after something subscribes to
``/joint_states`` (a recorder: started before or after ``pbdkit ros sim``, it sees the first
take whole); until then the world waits at its first posture, its joint states published.

Header stamps: the node's clock when the world began plus the world's time of the state (to a
physics step the node's clock itself, in real time; with ``time_scale`` > 1 the world's own
time, so that a recorder reading the stamps sees motions at their real pace).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..data._ros import _stamp_ns
from ._graph import QOS_DEPTH
from ._jtc import RejectedTrajectory
from ._task_world import TaskWorld, WorldSettings

__all__ = ["ARM_TOPIC", "BASE_FRAME", "GRIPPER_TOPIC", "SimWorld", "trajectory_arrays"]

#: The arm's controller's topic and the gripper's.
ARM_TOPIC = "/arm_controller/joint_trajectory"
GRIPPER_TOPIC = "/gripper_controller/joint_trajectory"
#: The frame of the objects' poses: the robot's base.
BASE_FRAME = "base_link"
#: Seconds between the timer's ticks: the physics catches up, the joint states are published.
PERIOD = 0.004
#: With ``teach``: seconds (on the clock) the world still waits once ``/joint_states`` has a
#: subscriber. The publisher's side of a match can come before the subscriber's, which loses
#: what is published meanwhile: on a loaded machine a recorder missed the first 0.5-1.9 s of
#: the first take's motion (the rest before it is 0.15 s at ``--time-scale 10``).
SUBSCRIBER_GRACE = 1.0


def trajectory_arrays(msg: Any) -> tuple[list[str], list[float], Any, Any, Any]:
    """A ``trajectory_msgs/JointTrajectory``'s joint names, its points' ``time_from_start``
    (s) and their positions, velocities and accelerations (each None when the points give none,
    else one row per point), as :meth:`TrajectoryFollower.receive` takes them.

    Raises
    ------
    RejectedTrajectory
        A point whose positions do not name every joint, or whose velocities or accelerations
        are given for some points or joints and not others.
    """
    names = [str(n) for n in msg.joint_names]
    points = list(msg.points)
    times = [p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in points]

    def rows(field: str, required: bool) -> Any:
        got = [list(getattr(p, field)) for p in points]
        if not required and all(len(g) == 0 for g in got):
            return None
        if any(len(g) != len(names) for g in got):
            raise RejectedTrajectory(
                f"every point needs {len(names)} {field} (one per joint), got "
                f"{sorted({len(g) for g in got})}"
            )
        return got

    return (
        names,
        times,
        rows("positions", True),
        rows("velocities", False),
        rows("accelerations", False),
    )


class SimWorld:
    """A task's simulated world on ``node`` (module docstring).

    Parameters
    ----------
    node : rclpy.node.Node
    settings : WorldSettings
        The task, the placement, the JTC's option, cameras, the disturbance, the teacher.
    skill : Skill, optional
        The arm's start posture, and the timing of a disturbance before the grasp
        (:class:`~pbdkit.ros._task_world.TaskWorld`).
    q0 : array_like, shape (5,), optional
        The arm's start posture instead.
    log : callable, optional
        Where the teacher's takes are announced (default: the node's logger).
    clock : callable
        Seconds, monotonic (the world's time is ``time_scale`` times its seconds since the
        world began).
    """

    def __init__(
        self,
        node: Any,
        settings: WorldSettings | None = None,
        *,
        skill: Any = None,
        q0: Any = None,
        log: Callable[[str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        self.node = node
        self.settings = settings or WorldSettings()
        self.world = TaskWorld(self.settings, skill=skill, q0=q0, log=log or node.get_logger().info)
        self._joint_state, self._pose = JointState, PoseStamped
        self._js = node.create_publisher(JointState, "/joint_states", QOS_DEPTH)
        self._objects = {
            k: node.create_publisher(PoseStamped, self.object_topic(k), QOS_DEPTH)
            for k in self.world.object_names
        }
        self._subs = []
        if not self.settings.teach:
            for kind, topic in (("arm", ARM_TOPIC), ("gripper", GRIPPER_TOPIC)):
                self._subs.append(
                    node.create_subscription(
                        JointTrajectory,
                        topic,
                        lambda msg, k=kind, t=topic: self._on_trajectory(k, t, msg),
                        QOS_DEPTH,
                    )
                )
        self._published = 0
        self._clock = clock
        self._restart_clock()
        #: With ``teach``: the world waits for a subscriber on /joint_states (module docstring).
        self.waiting = self.settings.teach
        self._subscribed_at: float | None = None  # when the waiting world first saw one
        self._timer = node.create_timer(PERIOD, self._tick)

    @staticmethod
    def object_topic(name: str) -> str:
        """The topic of the object ``name``'s pose."""
        return f"/objects/{name}"

    @property
    def topics(self) -> list[str]:
        """What it publishes (the joint states, then each object's pose)."""
        return ["/joint_states", *(self.object_topic(k) for k in self.world.object_names)]

    @property
    def following(self) -> list[str]:
        """The trajectories it follows (none with ``teach``)."""
        return [] if self.settings.teach else [ARM_TOPIC, GRIPPER_TOPIC]

    def now(self) -> float:
        """The world's time the clock says it is now (s)."""
        return self.settings.time_scale * (self._clock() - self._t0)

    def report(self) -> dict[str, Any] | None:
        """The run's judgement once there is one (:attr:`TaskWorld.report`; with ``teach``,
        the takes once the last has ended), else None."""
        return self.world.report

    @property
    def finished(self) -> bool:
        """True once :meth:`report` is not None."""
        return self.world.finished

    def _on_trajectory(self, kind: str, topic: str, msg: Any) -> None:
        world = self.world
        world.advance(self.now())  # the message starts now
        try:
            arrays = trajectory_arrays(msg)
        except RejectedTrajectory as err:
            world.messages[kind]["rejected"] += 1
            self.node.get_logger().warning(f"{topic}: rejected: {err}")
            return
        receive = world.receive_arm if kind == "arm" else world.receive_gripper
        stamp = _stamp_ns(msg.header.stamp)
        try:  # a stamp in the world's time (the module docstring's header stamps)
            receive(*arrays, stamp=None if stamp == 0 else (stamp - self._stamp0) * 1e-9)
        except ValueError as err:  # RejectedTrajectory, or a malformed point
            self.node.get_logger().warning(f"{topic}: rejected: {err}")

    def _restart_clock(self) -> None:
        """The world's time 0 is now (on the clock and in the header stamps)."""
        self._t0 = self._clock()
        self._stamp0 = int(self.node.get_clock().now().nanoseconds)

    def _tick(self) -> None:
        if self.waiting:
            self._restart_clock()
            if self._js.get_subscription_count() == 0:
                self._subscribed_at = None
            elif self._subscribed_at is None:
                self._subscribed_at = self._clock()
            if (
                self._subscribed_at is None
                or self._clock() - self._subscribed_at < SUBSCRIBER_GRACE
            ):
                self._publish()  # at rest, at world time 0
                return
            self.waiting = False
            self.world.log("teach: /joint_states has a subscriber: the takes begin")
        self.world.advance(self.now())
        self._publish()

    def _stamp(self, t: float) -> Any:
        from rclpy.time import Time

        return Time(nanoseconds=self._stamp0 + round(t * 1e9)).to_msg()

    def _publish(self) -> None:
        world = self.world
        names, q, v = world.joint_state()
        msg = self._joint_state()
        msg.header.stamp = self._stamp(world.t)
        msg.name = names
        msg.position = q.tolist()
        msg.velocity = v.tolist()
        self._js.publish(msg)
        if world.observations == self._published:
            return
        self._published = world.observations
        stamp = self._stamp(world.seen_t)
        for name, pose in world.seen.items():
            self._objects[name].publish(self._pose_msg(pose, stamp))

    def _pose_msg(self, pose: Any, stamp: Any) -> Any:
        from .._rotations import quaternion_from_matrix

        msg = self._pose()
        msg.header.stamp = stamp
        msg.header.frame_id = BASE_FRAME
        p = msg.pose.position
        p.x, p.y, p.z = (float(c) for c in pose[:3, 3])
        w, x, y, z = (float(c) for c in quaternion_from_matrix(np.asarray(pose)[:3, :3]))
        o = msg.pose.orientation
        o.w, o.x, o.y, o.z = w, x, y, z
        return msg

    def close(self) -> None:
        """Stop the timer and free the scene (the node is the caller's)."""
        self.node.destroy_timer(self._timer)
        self.world.close()
