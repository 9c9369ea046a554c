"""A ``trajectory_msgs/JointTrajectory`` as ros2_controllers' joint_trajectory_controller (JTC)
follows it (:class:`TrajectoryFollower`, what ``pbdkit ros sim`` runs), and the points pbdkit
sends one (:func:`trajectory_points`).

The JTC's rules (ros2_controllers' source, Jazzy; issue 37):

- a message replaces the current trajectory as soon as it arrives (header stamp 0: now);
- the segment to the first point starts from the measured state, or from the last command with
  ``interpolate_from_desired_state: true`` (``open_loop_control`` on Humble);
- between points: linear with positions alone, cubic with velocities, quintic with
  accelerations; after the last point it holds its position;
- refused: no points, a joint it does not control or one missing, times not increasing, and
  (by default) a last point that still moves.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import short
from ..motion._motion import _Quintic, _quintic_coefficients

__all__ = ["RejectedTrajectory", "TrajectoryFollower", "splice_lead", "trajectory_points"]

Float = NDArray[np.float64]

#: The first point of a message pbdkit sends is at least this long after it is sent, plus two
#: controller periods: the JTC samples it after the message has crossed the graph.
FIRST_POINT_MARGIN = 0.02
#: How much the JTC's start of a message (its receipt: header stamp 0) may differ from the
#: sender's clock, between two messages (s): the graph's latency varies, and the JTC takes a
#: message at its next update.
SPLICE_JITTER = 0.002
#: The share of the jerk limit a splice's time error may cost (:func:`splice_lead`).
SPLICE_JERK_SHARE = 0.25
#: The longest lead of a message's first point (s).
MAX_LEAD = 0.25


def splice_lead(velocity: Any, jerk_limit: Any, controller_period: float) -> float:
    """How far ahead (s) the first point of a message sent while the arm moves at
    ``velocity`` must lie: the JTC's segment to it absorbs the time error of the splice
    (:data:`SPLICE_JITTER`: a position error of v times it, whose quintic over T has a jerk of
    60 e / T^3), within :data:`SPLICE_JERK_SHARE` of the jerk limit. At rest, two controller
    periods plus :data:`FIRST_POINT_MARGIN`; at most :data:`MAX_LEAD`.

    (Measured through the sim arm: a re-plan's splice 28 ms ahead at 0.5 rad/s took the
    executed jerk to 6.4x the limit from a sub-millisecond time error.)"""
    least = 2.0 * controller_period + FIRST_POINT_MARGIN
    v = np.abs(np.asarray(velocity, dtype=np.float64))
    j = np.asarray(jerk_limit, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(v > 0.0, 60.0 * v * SPLICE_JITTER / (SPLICE_JERK_SHARE * j), 0.0)
    return float(min(MAX_LEAD, max(least, float(np.cbrt(np.nanmax(need, initial=0.0))))))


class RejectedTrajectory(ValueError):
    """A trajectory the JTC refuses (the current one goes on)."""


@dataclass(frozen=True)
class _Trajectory:
    start: float  # its time 0 (s, the follower's clock): its stamp, or when it arrived
    times: Float  # from the start: the state it started from where it came before its first
    # point (at the arrival, <= 0 for a stamp ahead), then time_from_start
    q: Float  # (P + 1, n)
    v: Float | None
    a: Float | None


class TrajectoryFollower:
    """The desired state of a JTC following the messages it is sent.

    Parameters
    ----------
    joint_names : sequence of str
        The controller's joints, in the order of the states it gives.
    q0 : array_like, shape (n,)
        Where it holds before the first message.
    interpolate_from_desired_state : bool
        The segment to a message's first point starts from the last command (True) or from
        the measured state (False, the JTC's default).
    allow_nonzero_velocity_at_trajectory_end : bool
        Accept a last point that moves (False: refused, Jazzy's default).
    """

    def __init__(
        self,
        joint_names: Sequence[str],
        q0: Any,
        *,
        interpolate_from_desired_state: bool = False,
        allow_nonzero_velocity_at_trajectory_end: bool = False,
    ) -> None:
        self.joint_names = [str(n) for n in joint_names]
        q = np.asarray(q0, dtype=np.float64)
        n = len(self.joint_names)
        self.from_desired = interpolate_from_desired_state
        self.allow_moving_end = allow_nonzero_velocity_at_trajectory_end
        zero = np.zeros(n)
        self._traj = _Trajectory(0.0, np.zeros(1), q[None].copy(), zero[None], zero[None])

    def receive(
        self,
        now: float,
        names: Sequence[str],
        times: Any,
        positions: Any,
        velocities: Any = None,
        accelerations: Any = None,
        measured: tuple[Any, Any] | None = None,
        stamp: float | None = None,
    ) -> None:
        """A message arriving at ``now``: its points' ``times`` (time_from_start, s) and per
        point the positions (and velocities, accelerations: each None, or one row per point),
        its joints named ``names`` in any order; ``measured``: the arm's (position, velocity)
        now, where the segment to the first point starts unless
        ``interpolate_from_desired_state``. ``stamp``: its header stamp on the follower's
        clock (None: stamp 0, it starts when it arrives); a stamped message's points are at
        ``stamp + times``, the segment to the first one from now, as the JTC: one whose first
        point is past when it arrives starts on its points (the arm's state dropped), one that
        ends in the past is refused. Raises RejectedTrajectory as the JTC refuses."""
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        if t.size == 0:
            raise RejectedTrajectory("empty trajectory: no points")
        names = [str(x) for x in names]
        unknown = [x for x in names if x not in self.joint_names]
        missing = [x for x in self.joint_names if x not in names]
        if unknown or missing or len(set(names)) != len(names):
            raise RejectedTrajectory(
                f"joints {short(names)} are not the controller's {short(self.joint_names)}"
            )
        order = np.array([names.index(x) for x in self.joint_names])
        if not (t[0] > 0.0 and np.all(np.diff(t) > 0.0)):
            raise RejectedTrajectory(
                f"time_from_start must increase from > 0, got {short(t.tolist())}"
            )
        q, v, a = (
            None if x is None else np.asarray(x, dtype=np.float64).reshape(t.size, -1)[:, order]
            for x in (positions, velocities, accelerations)
        )
        assert q is not None
        if v is not None and not self.allow_moving_end and np.any(v[-1] != 0.0):
            raise RejectedTrajectory("the last point has a non-zero velocity")
        start = now if stamp is None else float(stamp)
        if start + t[-1] < now:
            raise RejectedTrajectory(
                f"stamped {now - start:.3f} s ago, it ends {now - start - t[-1]:.3f} s in the past"
            )
        p0, v0, a0 = self.desired(now)
        if not self.from_desired and measured is not None:
            p0 = np.asarray(measured[0], dtype=np.float64)
            v0 = np.asarray(measured[1], dtype=np.float64)
            a0 = np.zeros_like(p0)
        if now - start >= t[0]:  # its first point is past: on its points from now
            self._traj = _Trajectory(start, t, q, v, a)
            return
        self._traj = _Trajectory(
            start,
            np.concatenate([[now - start], t]),
            np.vstack([p0, q]),
            None if v is None else np.vstack([v0, v]),
            None if a is None else np.vstack([a0, a]),
        )

    def desired(self, now: float) -> tuple[Float, Float, Float]:
        """The desired position, velocity and acceleration at ``now``."""
        tr = self._traj
        s = max(float(tr.times[0]), now - tr.start)  # (before it arrived: where it started)
        if s >= tr.times[-1]:
            n = tr.q.shape[1]
            return tr.q[-1].copy(), np.zeros(n), np.zeros(n)
        k = max(0, int(np.searchsorted(tr.times, s, side="right")) - 1)
        h = tr.times[k + 1] - tr.times[k]
        u = s - tr.times[k]
        p0, p1 = tr.q[k], tr.q[k + 1]
        if tr.v is None:  # linear
            vel = (p1 - p0) / h
            return p0 + vel * u, vel, np.zeros_like(p0)
        v0, v1 = tr.v[k], tr.v[k + 1]
        if tr.a is None:  # cubic (Hermite)
            c2 = (3.0 * (p1 - p0) / h - 2.0 * v0 - v1) / h
            c3 = (2.0 * (p0 - p1) / h + v0 + v1) / (h * h)
            return (
                p0 + v0 * u + c2 * u**2 + c3 * u**3,
                v0 + 2.0 * c2 * u + 3.0 * c3 * u**2,
                2.0 * c2 + 6.0 * c3 * u,
            )
        # quintic: the same polynomial as a motion's quintic segment
        c = _quintic_coefficients((p0, v0, tr.a[k]), (p1, v1, tr.a[k + 1]), h)
        p, v, a = _Quintic(None, None, h, c).at_time(u)
        return p, v, a


def trajectory_points(
    motion: Any, now: float, controller_period: float, spacing: float = 0.02, lead: float = 0.0
) -> tuple[Float, Float, Float, Float]:
    """The points of a JointTrajectory sent at ``now`` for ``motion`` (anything with ``at(t)``
    and ``end``: the plan in force, then a new one after its hand-over): samples of it every
    ``spacing`` s from ``lead`` ahead, at least two controller periods plus
    :data:`FIRST_POINT_MARGIN` (:func:`splice_lead`),
    and its end, at rest. Returns time_from_start (P,) and positions, velocities and
    accelerations (P, n): each point is the motion's own state, so that the message continues
    the motion in force before it diverges, and the JTC's quintics between the points follow
    it.
    """
    first = now + max(lead, 2.0 * controller_period + FIRST_POINT_MARGIN)
    end = float(motion.end)
    times = list(np.arange(first, end, spacing)) if end > first else []
    times.append(max(end, first))
    states = [motion.at(float(t)) for t in times]
    p, v, a = (np.array([s[k] for s in states], dtype=np.float64) for k in range(3))
    v[-1], a[-1] = 0.0, 0.0  # at rest at the last (the motion is, to rounding)
    return np.array(times) - now, p, v, a
