"""A skill run on a live arm through its joint_trajectory_controller (:func:`run_skill`, the
core of ``pbdkit ros run``, issue 37): joint states in by name, JointTrajectory messages out,
each a continuation of the motion in force (:func:`~pbdkit.ros._jtc.trajectory_points`).

The controller (:meth:`pbdkit.Skill.controller`, inline plans) steps at its own ``dt`` on the
node's monotonic clock, fed its own commands: the joint states, which lag the commands by the
graph and the JTC's interpolation, serve to start from the measured posture, to watch
staleness and the following error, and to see the end. Every new plan is sent as a message
whose points run from two controller periods plus 20 ms ahead to the end, at rest.

Exit codes: :data:`EXIT_CODES`. Every failure after the first message first sends a braking
trajectory (from the commanded state, within the limits) and then says why, in one line.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..motion._limits import MotionLimits, with_defaults
from ..motion._motion import brake
from ._graph import QOS_DEPTH, JointStateListener, receiving
from ._joints import JointOrder
from ._jtc import splice_lead, trajectory_points
from ._objects import ObjectSources

__all__ = ["EXIT_CODES", "RunFailed", "RunSettings", "run_skill"]

Float = NDArray[np.float64]

#: ``pbdkit ros run``'s exit codes.
EXIT_CODES = {
    "done": 0,  # the skill ran to its end and the arm is at rest
    "usage": 2,  # usage or refused
    "stale": 3,  # joint states older than --stale
    "no_controller": 4,  # no subscriber, or no motion within --timeout
    "following": 5,  # a following error over --max-following-error
    "plan": 6,  # a plan would collide (--scene) or could not be made: nothing sent, or at rest
    "signal": 130,  # SIGINT or SIGTERM, after bringing the arm to rest
}
#: The JTC's quintics between exact states of a jerk-limited motion overshoot its jerk (1.40x at
#: 20 ms between points on a smooth path, tests/test_ros_jtc.py; up to about 1.6x on a skill's
#: lead-in, measured through the sim arm): the jerk limit is planned this much lower, so that
#: what the controller executes stays within the arm's (the sim arm's commands: 0.67 of the
#: limits at 2.0, 1.05-1.09 at 1.45).
JTC_JERK_MARGIN = 2.0
#: Seconds between the points of a message (the JTC's quintics between them follow the motion
#: closer, and overshoot its jerk less, the closer they are: 1.29x at 10 ms, 1.40x at 20 ms).
POINT_SPACING = 0.01
#: The longest ``--latency`` (s): a re-plan then reacts this much later.
MAX_LATENCY = 0.5


class RunFailed(Exception):
    """A run that ends early: its exit code (:data:`EXIT_CODES`) and one line."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.code = EXIT_CODES[reason]


@dataclass(frozen=True)
class RunSettings:
    """``pbdkit ros run``'s options (their defaults are the command's)."""

    controller: str = "arm_controller"
    joint_states: str = "/joint_states"
    joint_map: Mapping[str, str] = field(default_factory=dict)
    speed: float = 1.0
    stale: float = 0.2
    max_following_error: float = 0.05
    timeout: float = 5.0
    controller_period: float = 0.004  # the JTC's update period it plans ahead of (250 Hz)
    dry_run: bool = False
    assume_limits: bool = False  # an arm without acceleration or jerk limits: the defaults
    gripper_controller: str | None = None
    gripper_joint: tuple[str, float, float] | None = None  # NAME, OPEN, CLOSED positions
    gripper_seconds: float = 0.3  # each gripper message's one point, this far ahead
    grasped: str | None = None  # its source is ignored once the gripper closes
    scene: Any = None  # a pbdkit.Scene: every plan checked against it and kept clear of it
    # The longest the arm's controller takes to take a message (s): each arm message is
    # stamped with the run's clock, its first point at least this far ahead (None: stamp 0).
    latency: float | None = None

    def __post_init__(self) -> None:
        if not 0.1 <= self.speed <= 1.0:
            raise ValueError(f"--speed must be in [0.1, 1], got {self.speed}")
        if self.latency is not None and not (0.0 < self.latency <= MAX_LATENCY):
            raise ValueError(f"--latency must be in (0, {MAX_LATENCY:g}] s, got {self.latency}")
        if (self.gripper_controller is None) != (self.gripper_joint is None):
            raise ValueError("--gripper-controller and --gripper-joint go together")
        for name in ("stale", "max_following_error", "timeout", "controller_period",
                     "gripper_seconds"):  # fmt: skip
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"--{name.replace('_', '-')} must be > 0, got {value}")


def scaled_limits(limits: MotionLimits, speed: float) -> MotionLimits:
    """The arm's limits at ``speed`` (time scaled: velocity by s, acceleration by s^2, jerk by
    s^3), the jerk lowered by :data:`JTC_JERK_MARGIN`."""
    return MotionLimits._derived(
        limits.velocity * speed,
        limits.acceleration * speed**2,
        limits.jerk * speed**3 / JTC_JERK_MARGIN,
    )


def run_skill(
    node: Any,
    skill: Any,
    objects: Mapping[str, Any],
    settings: RunSettings,
    *,
    log: Callable[[str], None] = print,
    stop: Callable[[], bool] = lambda: False,
) -> int:
    """Run ``skill`` on the arm behind ``settings.controller``, its objects from ``objects``
    (name -> a topic, or fixed coordinates: :class:`~pbdkit.ros._objects.ObjectSources`);
    returns the exit code (0: ran to its end, at rest). ``stop()`` true (a signal) brakes and
    returns 130. Raises RunFailed for the other endings, after braking where a message was
    sent."""
    from trajectory_msgs.msg import JointTrajectory

    try:
        sources = ObjectSources(node, objects, skill.oriented, log=log)
    except ValueError as err:
        raise RunFailed("usage", str(err)) from None
    order = JointOrder(skill.robot.joint_names, settings.joint_map)
    listener = JointStateListener(node, settings.joint_states, order)
    topic = f"/{settings.controller}/joint_trajectory"
    pub = node.create_publisher(JointTrajectory, topic, QOS_DEPTH)
    gripper = _Gripper(node, settings)
    runner = _Runner(node, pub, order, settings, log)

    spin = time.sleep  # the messages come meanwhile, on the receiving thread
    with receiving(node):  # (one ROS callback a turn of the loop left the states stale)
        _wait_for_graph(listener, [(pub, topic), *gripper.publishers()], settings, spin)
        try:
            sources.subscribe(settings.timeout, spin)
        except TimeoutError as err:
            raise RunFailed("stale", f"objects: {err}") from None
        except ValueError as err:
            raise RunFailed("usage", str(err)) from None
        limits = scaled_limits(_arm_limits(skill, settings), settings.speed)
        ctrl = skill.controller(  # its planner's process takes a second to start
            dict(sources.values),
            velocity_limit=limits.velocity,
            acceleration_limit=limits.acceleration,
            jerk_limit=limits.jerk,
            planner="inline" if settings.dry_run else "process",
            scene=settings.scene,
        )
        ctrl.handover_delay = 0.0 if settings.latency is None else settings.latency
        try:
            count = listener.count  # the posture to start from: a state that came after that
            while listener.count == count:
                if listener.age() > settings.timeout:
                    raise RunFailed(
                        "stale", f"joint states on {settings.joint_states} stopped before the run"
                    )
                spin(0.01)
            assert listener.q is not None
            q0 = listener.q.copy()
            if settings.scene is not None:
                _check_scene(skill, dict(sources.values), q0, limits, settings.scene, log)
            return _loop(ctrl, q0, listener, sources, runner, gripper, settings, log, stop, spin)
        finally:
            ctrl.close()


def _check_scene(
    skill: Any,
    objects: dict[str, Any],
    q0: Float,
    limits: MotionLimits,
    scene: Any,
    log: Callable[[str], None],
) -> None:
    """``--scene``: the run's first plan, from the arm's posture, checked against the scene
    (and kept clear of it) before anything is sent; RunFailed (exit 6) where it would
    collide."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # said in the error
        res = skill.reproduce(
            objects,
            q0=q0,
            velocity_limit=limits.velocity,
            acceleration_limit=limits.acceleration,
            jerk_limit=limits.jerk,
            on_unreachable="warn",
            scene=scene,
        )
    if res.infeasible is not None:
        raise RunFailed("plan", f"--scene: the plan would collide, nothing sent: {res.infeasible}")
    log(f"scene: the plan keeps {1e3 * float(np.min(res.clearance)):.1f} mm clear")


def _wait_for_graph(
    listener: JointStateListener,
    publishers: list[tuple[Any, str]],
    settings: RunSettings,
    spin: Callable[[float], None],
) -> None:
    """Wait for joint states (exit 3 after the time-out) and a subscriber on each of
    ``publishers`` (exit 4)."""
    waited = time.monotonic()
    while listener.q is None:
        if listener.error is not None:
            raise RunFailed("usage", listener.error)
        if time.monotonic() - waited > settings.timeout:
            raise RunFailed(
                "stale", f"no joint states on {settings.joint_states} in {settings.timeout:g} s"
            )
        spin(0.05)
    for pub, topic in publishers:
        while pub.get_subscription_count() == 0 and not settings.dry_run:
            if time.monotonic() - waited > settings.timeout:
                raise RunFailed(
                    "no_controller",
                    f"nothing subscribes to {topic} ({topic.split('/')[1]} not loaded?) "
                    f"within {settings.timeout:g} s",
                )
            spin(0.05)


def _arm_limits(skill: Any, settings: RunSettings) -> MotionLimits:
    """The skill's arm's limits; refused (exit 2) without acceleration or jerk limits unless
    ``--assume-limits``."""
    declared = MotionLimits.from_robot(skill.robot, skill.robot.n_joints)
    if np.all(np.isfinite(declared.acceleration)) and np.all(np.isfinite(declared.jerk)):
        return declared
    if not settings.assume_limits:
        raise RunFailed(
            "usage",
            "the skill's arm declares no acceleration or jerk limit for some joint: give them "
            "(a joint_limits.yaml when learning) or --assume-limits (a = v / 0.25 s, "
            "j = a / 0.1 s)",
        )
    return with_defaults(declared, skill.robot.joint_names)


def _loop(
    ctrl: Any,
    q0: Float,
    listener: JointStateListener,
    sources: ObjectSources,
    runner: _Runner,
    gripper: _Gripper,
    settings: RunSettings,
    log: Callable[[str], None],
    stop: Callable[[], bool],
    spin: Callable[[float], None],
) -> int:
    """The run from the first plan to its end (see :func:`run_skill`)."""
    st = ctrl._timed
    start = runner.t0 = time.monotonic()
    cmd = ctrl.step(q0)
    first = st.motion.at(0.0)[0]
    if float(np.abs(first - q0).max()) > 1e-9:  # a guard: the controller starts where measured
        raise RunFailed(
            "usage", f"the plan starts at {first.tolist()}, not at the arm's {q0.tolist()}"
        )
    runner.jerk = ctrl.limits.jerk
    runner.send(st.motion, 0.0)
    gripper.send(cmd.gripper)
    log(f"objects: {sources.describe()}")
    log(f"running {ctrl.n_steps} steps at speed {settings.speed:g}")
    if settings.dry_run:
        log("dry run: nothing sent")
        return EXIT_CODES["done"]
    moved_by, moved = start + settings.timeout, False
    q_cmd = cmd.q
    said = -1.0
    while True:
        now = time.monotonic() - start
        if stop():
            runner.brake(st.motion, now, ctrl.limits)
            return EXIT_CODES["signal"]
        if listener.age() > settings.stale:
            runner.brake(st.motion, now, ctrl.limits)
            raise RunFailed(
                "stale",
                f"joint states on {settings.joint_states} are {listener.age():.2f} s old "
                f"(--stale {settings.stale:g} s)",
            )
        q = listener.q
        assert q is not None
        moved = moved or float(np.abs(q - q0).max()) >= 1e-4
        if not moved and time.monotonic() > moved_by and not st.motion.at_rest_after(0.0):
            runner.brake(st.motion, now, ctrl.limits)
            raise RunFailed(
                "no_controller",
                f"the arm did not move within {settings.timeout:g} s of the first "
                f"message on /{settings.controller}/joint_trajectory (the controller inactive?)",
            )
        err = runner.following_error(st.motion, now, q)
        if err > settings.max_following_error:
            runner.brake(st.motion, now, ctrl.limits)
            raise RunFailed(
                "following",
                f"following error {err:.3f} rad (--max-following-error "
                f"{settings.max_following_error:g})",
            )
        sources.check_silent()
        if ctrl.done:
            end = st.motion.at(st.motion.end)[0]
            if float(np.abs(q - end).max()) < 1e-3 and float(np.abs(listener.v).max()) < 1e-3:
                if ctrl.fault is not None:  # a plan refused (a collision) or not made
                    raise RunFailed("plan", f"brought to rest: {ctrl.fault}")
                log(f"done: at rest after {now:.2f} s, {ctrl.replans} re-plan(s)")
                return EXIT_CODES["done"]
        elif now >= st.cycle * ctrl.dt:
            cmd = ctrl.step(q_cmd, sources.take_new() or None)  # fed its own commands
            q_cmd = cmd.q
            if gripper.send(cmd.gripper) and cmd.gripper and settings.grasped is not None:
                sources.ignore(settings.grasped)
            if runner.changed(st.motion):
                runner.send(st.motion, time.monotonic() - start)
                if ctrl.replans:
                    log(f"re-planned at step {cmd.index}: {sources.describe()}")
                else:
                    log(f"planned: at rest after {st.motion.end:.2f} s")
            if now - said >= 1.0:
                said = now
                log(
                    f"t {now:5.1f} s  step {cmd.index}/{ctrl.n_steps}  gripper "
                    f"{'closed' if cmd.gripper else 'open'}"
                )
        spin(0.002)


class _Gripper:
    """The gripper's commands: a JointTrajectory of its one joint to ``--gripper-controller``
    whenever the skill's command changes (nothing without one)."""

    def __init__(self, node: Any, settings: RunSettings) -> None:
        self.settings = settings
        self.closed: bool | None = None
        self.pub: Any = None
        self.topic = ""
        if settings.gripper_controller is not None:
            from trajectory_msgs.msg import JointTrajectory

            self.topic = f"/{settings.gripper_controller}/joint_trajectory"
            self.pub = node.create_publisher(JointTrajectory, self.topic, QOS_DEPTH)

    def publishers(self) -> list[tuple[Any, str]]:
        return [] if self.pub is None else [(self.pub, self.topic)]

    def send(self, closed: bool) -> bool:
        """Send ``closed`` if it changed (or is the first); True if it changed."""
        if closed == self.closed:
            return False
        self.closed = closed
        if self.pub is None or self.settings.dry_run:
            return True
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        name, open_, shut = self.settings.gripper_joint or ("", 0.0, 1.0)
        sec = self.settings.gripper_seconds
        point = JointTrajectoryPoint(
            positions=[shut if closed else open_],
            velocities=[0.0],
            time_from_start=Duration(sec=math.floor(sec), nanosec=round(sec % 1.0 * 1e9) % 10**9),
        )
        self.pub.publish(JointTrajectory(joint_names=[name], points=[point]))
        return True


class _Then:
    """``first`` until ``at``, then ``then`` (a motion: ``at(t)`` and ``end``)."""

    def __init__(self, first: Any, at: float, then: Any) -> None:
        self.first, self.at_, self.then, self.end = first, at, then, then.end

    def at(self, t: float) -> Any:
        return (self.first if t < self.at_ else self.then).at(t)


class _Runner:
    """What :func:`run_skill` sends: messages of a motion's points, and a brake."""

    def __init__(
        self,
        node: Any,
        pub: Any,
        order: JointOrder,
        settings: RunSettings,
        log: Callable[[str], None],
    ) -> None:
        self.node, self.pub, self.order, self.settings, self.log = node, pub, order, settings, log
        self.motion: Any = None  # the motion last sent
        self.jerk: Any = np.inf  # the planned jerk limit (the splices' lead: splice_lead)
        self.sent = 0
        self.t0 = time.monotonic()  # the run's clock's 0 (set by _loop)

    def changed(self, motion: Any) -> bool:
        """Whether ``motion`` (the controller's now) is not the one last sent: a new plan's
        hand-over, or a brake. The hand-over's own end (the new plan alone) is the same
        motion from then on, and is not sent again."""
        last = self.motion
        if motion is last or (last is not None and motion is getattr(last, "new", None)):
            self.motion = motion
            return False
        return True

    def send(self, motion: Any, now: float, lead: float | None = None) -> None:
        """The points of ``motion`` from ``now`` (s on the run's clock) as one message, the
        first ``lead`` s ahead (default: :func:`~pbdkit.ros._jtc.splice_lead`); with
        ``settings.latency`` its header stamp is the node's clock at ``now``, and from rest its
        first point at least that far ahead (moving, the motion sent continues the one the
        controller follows until the message has reached it: the controller's
        ``handover_delay``, :meth:`brake`)."""
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

        self.motion = motion
        period = self.settings.controller_period
        if lead is None:
            velocity = motion.at(now)[1]
            lead = splice_lead(velocity, self.jerk, period)
            if self.settings.latency is not None and not np.any(velocity):
                lead = max(lead, self.settings.latency)
        tfs, p, v, a = trajectory_points(motion, now, period, POINT_SPACING, lead)
        if self.settings.dry_run:
            return
        msg = JointTrajectory(joint_names=list(self.order.graph_names))
        if self.settings.latency is not None:  # the node's clock at the run's ``now``
            from rclpy.time import Time

            ago = round((time.monotonic() - self.t0 - now) * 1e9)
            clock_now = int(self.node.get_clock().now().nanoseconds)
            msg.header.stamp = Time(nanoseconds=clock_now - ago).to_msg()
        for k in range(tfs.shape[0]):
            sec = math.floor(tfs[k])
            msg.points.append(
                JointTrajectoryPoint(
                    positions=p[k].tolist(),
                    velocities=v[k].tolist(),
                    accelerations=a[k].tolist(),
                    time_from_start=Duration(sec=sec, nanosec=round((tfs[k] - sec) * 1e9) % 10**9),
                )
            )
        self.pub.publish(msg)
        self.sent += 1

    def brake(self, motion: Any, now: float, limits: MotionLimits | None) -> None:
        """A braking trajectory from the commanded state at the message's first point (with
        ``settings.latency``: the motion in force until then, the brake from that far ahead)."""
        if limits is None or self.sent == 0:
            return
        lead = splice_lead(motion.at(now)[1], limits.jerk, self.settings.controller_period)
        latency = self.settings.latency
        at = now + (lead if latency is None else max(lead, latency))
        stop = brake(at, motion.at(at), limits.scaled(0.995))
        self.send(_Then(motion, at, stop), now, lead)
        self.log("braking")

    @staticmethod
    def following_error(motion: Any, now: float, q: Float) -> float:
        """How far the measured posture is from the commanded motion, over the last 0.15 s of
        commands (the states lag them by the graph and the controller's interpolation)."""
        times = np.linspace(max(0.0, now - 0.15), now, 16)
        return float(min(np.abs(q - motion.at(float(t))[0]).max() for t in times))
