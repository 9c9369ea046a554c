"""Jerk-limited trajectory generation (Ruckig): commands and setpoints a real arm accepts.

Ruckig (community version, https://github.com/pantor/ruckig, MIT) computes, from a current state
(position, velocity, acceleration) to a target state, the time-optimal trajectory within
velocity, acceleration and jerk limits (piecewise-constant jerk); it is what MoveIt 2 and
Franka's tools use for online motion. pbdkit calls it state to state and chains its
trajectories with polynomial pieces, each starting in the state the previous one ended in: the
result is one continuous motion (position, velocity and acceleration continuous, jerk within
the limit), so its samples pass the divided-difference check of :mod:`pbdkit.motion._limits` at any
rate.

- :func:`point_to_point`: a move between two postures at rest, sampled every ``dt`` (the
  lead-in of a reproduction from a distant posture).
- :func:`follow`: the :class:`Motion` through a timed trajectory's samples (a reproduction,
  played over :meth:`pbdkit.Skill.times`) from a given state: the pieces of the spline through
  them where those are within the limits, quintic joins and Ruckig trajectories elsewhere,
  each planned once; sampled at any rate (:func:`follow_samples`: the simulator's 500 Hz
  servos, a 1 kHz ``ros2_control`` or Franka loop, the online controller's cycle).

Ruckig is imported when one of them is first used.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import short
from ._limits import MotionLimits
from ._motion import (
    Motion,
    _Quintic,
    _quintic_coefficients,
    _quintic_positions,
    _ruckig,
    _ruckig_plan,
    brake,
    ruckig_recipe,
)

__all__ = [
    "MERGE_SAMPLES",
    "Motion",
    "brake",
    "follow",
    "follow_samples",
    "join",
    "point_to_point",
    "spline_derivatives",
    "valid_target",
]

#: A sample :func:`follow_samples` cannot reach in its time is passed by toward one of the next
#: ones, up to this many samples ahead.
MERGE_SAMPLES = 8
#: How far (rad) a segment of :func:`follow` may pass a joint limit it is given (rounding).
BOUNDS_TOL = 1e-9
#: :func:`follow` takes a piece of the spline through the samples as it is where the piece is
#: within this fraction of the limits (the rest is room for joining it from where the motion
#: is).
SPLINE_MARGIN = 0.99

Float = NDArray[np.float64]


def valid_target(velocity: Float, acceleration: Float, limits: MotionLimits) -> tuple[Float, Float]:
    """A target velocity and acceleration Ruckig accepts: ``|v| <= V``, ``|a| <= A`` and
    ``|v| + a^2 / (2 J) <= V`` (a state with an acceleration must have come from, and must go
    to, velocities within the limit while its acceleration ramps at the jerk limit)."""
    vmax, amax, jmax = limits.velocity, limits.acceleration, limits.jerk
    v = np.clip(velocity, -vmax, vmax)
    a = np.clip(acceleration, -amax, amax)
    with np.errstate(invalid="ignore"):
        room = np.sqrt(np.maximum(2.0 * jmax * (vmax - np.abs(v)), 0.0))
    room = np.where(np.isnan(room), np.inf, room)  # inf - inf where nothing is limited
    return v, np.clip(a, -room, room)


def point_to_point(
    start: npt.ArrayLike, goal: npt.ArrayLike, dt: float, limits: MotionLimits
) -> tuple[Float, Float, Float]:
    """The time-optimal move from ``start`` to ``goal``, at rest at both ends, every ``dt``.

    Phase-synchronized (Ruckig): the joints move together along the straight line in joint
    space (where Ruckig cannot, it falls back to arriving together).

    Returns
    -------
    positions, velocities, accelerations : ndarray, shape (K, n)
        K >= 1 samples every ``dt`` from the start (sample 0) to the goal at rest (last, the
        first sample at or after the move's end).
    """
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {short(dt)}")
    p0 = np.asarray(start, dtype=np.float64)
    p1 = np.asarray(goal, dtype=np.float64)
    n = p0.shape[0]
    if np.array_equal(p0, p1):
        return p0[None].copy(), np.zeros((1, n)), np.zeros((1, n))
    rk = _ruckig()
    inp = rk.InputParameter(n)
    inp.max_velocity = limits.velocity.tolist()
    inp.max_acceleration = limits.acceleration.tolist()
    inp.max_jerk = limits.jerk.tolist()
    inp.synchronization = rk.Synchronization.Phase
    inp.current_position = p0.tolist()
    inp.target_position = p1.tolist()
    traj = rk.Trajectory(n)
    result = rk.Ruckig(n).calculate(inp, traj)
    if result not in (rk.Result.Working, rk.Result.Finished):
        raise RuntimeError(f"Ruckig could not plan the move: {result}")
    duration = float(traj.duration)
    count = max(1, math.ceil(duration / dt - 1e-9))
    rows = [traj.at_time(min(k * dt, duration)) for k in range(count + 1)]
    pos = np.array([r[0] for r in rows], dtype=np.float64)
    vel = np.array([r[1] for r in rows], dtype=np.float64)
    acc = np.array([r[2] for r in rows], dtype=np.float64)
    pos[0], pos[-1] = p0, p1  # exactly where it starts and ends, at rest
    vel[[0, -1]] = 0.0
    acc[[0, -1]] = 0.0
    return pos, vel, acc


def spline_derivatives(
    t: Float, q: Float, start_velocity: Float | None = None
) -> tuple[Float, Float]:
    """Velocity and acceleration at the samples of the cubic spline through them, at rest at
    the end and at the start (or moving at ``start_velocity`` there)."""
    from scipy.interpolate import CubicSpline

    n = q.shape[1]
    start = np.zeros(n) if start_velocity is None else start_velocity
    spline = CubicSpline(t, q, axis=0, bc_type=((1, start), (1, np.zeros(n))))
    return np.asarray(spline(t, 1), dtype=np.float64), np.asarray(spline(t, 2), dtype=np.float64)


def follow(
    t: Float,
    q: Float,
    limits: MotionLimits,
    *,
    velocities: Float | None = None,
    accelerations: Float | None = None,
    start: tuple[Float, Float, Float] | None = None,
    bounds: tuple[Float, Float] | None = None,
) -> Motion:
    """The jerk-limited motion through timed samples, segment by segment.

    From ``start`` (position, velocity, acceleration at t[0]; default: at rest at q[0]), each
    sample is reached with its velocity and acceleration (the cubic spline's by default) at
    its time, the motion coming to rest at the last one. Segment by segment, from the state
    the motion is in:

    1. on the samples' states and on time: the quintic to the next sample's state (with the
       spline's derivatives, the spline's own piece: smooth, its jerk constant), where it is
       within ``SPLINE_MARGIN`` of the limits and ends in a state the next segment can take
       over (v + a|a| / 2J within the velocity limit);
    2. else, on time: the quintic from the motion's state to a sample's of the next
       :data:`MERGE_SAMPLES` (the next one, or a later one with the time of all), within the
       limits;
    3. else Ruckig (time-synchronized, lasting at least the time left: exactly it when it
       can): to a sample of that window on time, with its velocity and acceleration or its
       velocity alone, never swinging back beyond the samples on the way; failing that, late,
       as fast as the limits allow, to the sample it swings the least for.

    Where the limits keep the motion behind a sample's time, the rest of the samples are aimed
    for as much later (the motion keeps to the path and its pace, instead of chasing a schedule
    it has fallen behind), and :attr:`Motion.sample_times` says when each sample is reached:
    what a gripper event or a phase should follow. Samples within the limits whose spline is
    too are followed exactly, on time.

    Each segment is planned once and the motion is sampled afterwards at any rate
    (:meth:`Motion.at`): re-planned at every setpoint with the time left, a motion through
    samples at the pace of a timed reproduction (close to time-optimal) falls into one of
    Ruckig's blocked intervals of duration and turns into a detour (0.2 rad off the samples,
    measured on a coaster reproduction).

    Parameters
    ----------
    t : ndarray, shape (T,)
        Strictly increasing sample times (s), T >= 2.
    q : ndarray, shape (T, n)
    limits : MotionLimits
        Planned with as given (give them a margin: :data:`pbdkit.motion._limits.LIMIT_SAFETY`).
    velocities, accelerations : ndarray, shape (T, n), optional
        At the samples; None: the cubic spline's through them, at rest at the end and at the
        start (or moving at ``start``'s velocity).
    start : (ndarray (n,), ndarray (n,), ndarray (n,)), optional
        The state at t[0].
    bounds : (ndarray (n,), ndarray (n,)), optional
        Joint position limits (lower, upper) the samples are within: no segment leaves them
        where one that stays within exists (the quintics are checked at 33 points, Ruckig's
        trajectories at their extrema; of the late ones, the one that leaves them least).

    Returns
    -------
    Motion
        From t[0].
    """
    rk = _ruckig()
    n = q.shape[1]
    if start is None:
        start = (q[0].copy(), np.zeros(n), np.zeros(n))
    p0, v0, a0 = (np.asarray(x, dtype=np.float64) for x in start)
    if velocities is None or accelerations is None:
        v_spline, a_spline = spline_derivatives(t, q, v0 if np.any(v0) else None)
        velocities = v_spline if velocities is None else velocities
        accelerations = a_spline if accelerations is None else accelerations
    # Where the quintic between two samples' states is within the limits and the motion is on
    # it, it is the motion (with the spline's derivatives: the spline's piece, its jerk
    # constant); elsewhere Ruckig.
    on_spline = _KnotPieces(t, q, velocities, accelerations, limits, bounds)
    knot_v, knot_a = valid_target(velocities, accelerations, limits)
    otg = rk.Ruckig(n)
    inp = rk.InputParameter(n)
    inp.max_velocity = limits.velocity.tolist()
    inp.max_acceleration = limits.acceleration.tolist()
    inp.max_jerk = limits.jerk.tolist()
    ok = (rk.Result.Working, rk.Result.Finished)
    zeros = [0.0] * n
    last = t.shape[0] - 1
    motion = Motion(float(t[0]), (p0, v0, a0), limits)

    recipes: dict[int, tuple[Float, float, int]] = {}  # id of a trajectory -> its recipe

    def plan_to(
        j: int, now: float, with_acceleration: bool = True, stop: bool = False
    ) -> tuple[Any, float]:
        """A trajectory from the current state (at ``now``) to sample j (``stop``: at rest
        there), never before its time; and the time left."""
        traj = rk.Trajectory(n)
        inp.target_position = q[j].tolist()
        inp.target_velocity = zeros if j == last or stop else knot_v[j].tolist()
        use_a = with_acceleration and j != last
        inp.target_acceleration = knot_a[j].tolist() if use_a else zeros
        left = float(t[j]) + delay - now
        inp.minimum_duration = left if left > 0 else None
        try:
            result = otg.calculate(inp, traj)
        except rk.RuckigError:
            inp.target_acceleration = zeros
            result = otg.calculate(inp, traj)
        if result not in ok:
            raise RuntimeError(f"Ruckig could not plan the motion to sample {j}: {result}")
        recipes[id(traj)] = ruckig_recipe(inp)
        return traj, left

    def on_time(traj: Any, left: float) -> bool:
        return float(traj.duration) <= left * (1.0 + 1e-9) + 1e-12

    def beyond(traj: Any, i: int, j: int, p_now: Float, lenient: bool) -> float:
        """How far (rad) the trajectory to sample j swings beyond the range of the samples on
        the way from i and of where the motion is, give or take 1e-6 (``lenient``: and one
        sample's step); plus a thousand times how far it leaves the joint limits."""
        way = np.vstack([p_now, q[i : j + 1]])
        tol = 1e-9 + 1e-6 * float(np.abs(way).max())
        slack = tol + (np.abs(np.diff(way, axis=0)).max(axis=0) if lenient else 0.0)
        lo, hi = way.min(axis=0) - slack, way.max(axis=0) + slack
        extrema = traj.position_extrema
        over = max(max(lo[k] - e.min, e.max - hi[k], 0.0) for k, e in enumerate(extrema))
        if bounds is not None:  # beyond a joint limit counts a thousand times more
            lower, upper = bounds[0] - BOUNDS_TOL, bounds[1] + BOUNDS_TOL
            out = max(max(lower[k] - e.min, e.max - upper[k], 0.0) for k, e in enumerate(extrema))
            # And where it ends: a state from which no stop keeps within them is one the rest
            # of the motion cannot recover from.
            if isinstance(traj, _Quintic):
                e_p, e_v, e_a = traj.end
            else:
                e_p, e_v, e_a = (np.array(x) for x in traj.at_time(float(traj.duration)))
            stop = _stop_overshoot(e_p[None], e_v[None], e_a[None], bounds, limits)
            over += 1e3 * max(out, float(stop[0]))
        return float(over)

    # Where the limits kept the motion from a sample's time, the rest of the samples are aimed
    # for as much later (``delay``): the motion keeps following the path and its timing
    # instead of chasing a schedule it has fallen behind (which would leave the samples behind
    # for good). ``reached``: when the motion reaches (or passes) each sample.
    delay = 0.0
    reached = np.empty(t.shape[0])
    reached[0] = t[0]

    def arrived(i: int, j: int, traj: Any) -> tuple[list[float], list[float], list[float]]:
        """The segment ``traj`` to sample j appended (samples i..j reached); its end state."""
        nonlocal delay
        motion.append(traj, None if isinstance(traj, _Quintic) else recipes[id(traj)])
        recipes.clear()  # the other candidates are dropped (their ids may be reused)
        end = motion.end
        if i == j:  # the common case, as the general one computes it (w = 1 exactly)
            prev = float(reached[i - 1])
            reached[i] = prev + 1.0 * (end - prev)
        else:  # merged samples: reached in proportion to their times
            span = t[i - 1 : j + 1]
            w = (span[1:] - span[0]) / (span[-1] - span[0]) if span[-1] > span[0] else 1.0
            reached[i : j + 1] = reached[i - 1] + w * (end - reached[i - 1])
        delay = max(delay, end - float(t[j]))
        if isinstance(traj, _Quintic):
            return traj.end_state()
        end_p, end_v, end_a = traj.at_time(float(traj.duration))
        return list(end_p), list(end_v), list(end_a)

    state = (p0.tolist(), v0.tolist(), a0.tolist())
    i = 1
    while i <= last:
        now = motion.end
        # On the spline, on time, and its piece to the next sample within the limits (not
        # the last piece: the motion ends at rest, acceleration included): that piece.
        piece = on_spline.piece(i, now - delay, state) if i < last else None
        if piece is not None:
            state = arrived(i, i, piece)
            i += 1
            continue
        inp.current_position, inp.current_velocity, inp.current_acceleration = state
        window = range(i, min(i + MERGE_SAMPLES, last + 1))
        p_now = np.asarray(state[0])
        # Off the spline's pieces but on time: the quintic from here to a sample's state (the
        # next, or one of the window's with the time of all), if it is within the limits.
        bridge = (
            on_spline.bridge(window, now - delay, state, limits, bounds)
            if window[-1] < last
            else None
        )
        if bridge is not None:
            j, piece = bridge
            state = arrived(i, j, piece)
            i = j + 1
            continue
        found = None
        # On time: with the sample's velocity and acceleration, else its velocity alone (an
        # acceleration estimate the jerk limit cannot reach in time). Never swinging back
        # beyond the samples on the way: a sample's velocity that the motion cannot reach in
        # the distance left makes a time-optimal move back up for a run-up.
        for with_acceleration in (True, False):
            for j in window:
                traj, left = plan_to(j, now, with_acceleration)
                if on_time(traj, left) and beyond(traj, i, j, p_now, True) == 0.0:
                    found = j, traj
                    break
            if found is not None:
                break
        if found is None:
            # Late: as fast as the limits allow, to the sample of the window it swings the
            # least beyond the samples on the way for (the first that does not at all). With
            # the sample's velocity, or (with bounds) stopping there where that swings less:
            # samples that brake harder than the jerk limit lets the motion would otherwise be
            # overshot by the whole braking distance (0.12 rad, out of the joint limits,
            # measured on an online coaster plan whose path stops on lift3's limit).
            best = math.inf
            for j in window:
                for stop in (False, True) if bounds is not None else (False,):
                    traj, _ = plan_to(j, now, False, stop)
                    over = beyond(traj, i, j, p_now, False)
                    if over < best:
                        best, found = over, (j, traj)
                    if over == 0.0:
                        break
                if best == 0.0:
                    break
            if bounds is not None and best >= 1e3 * BOUNDS_TOL and any(state[1]):
                # Every way on leaves a joint limit: brake to rest first, as hard as the
                # limits allow (the least any motion from here can pass), then go on from
                # there (from rest, stopping at a sample within the limits never leaves them).
                rows = np.array([*state, state[0], zeros, zeros], dtype=np.float64)
                stop = _ruckig_plan(
                    rows, math.nan, 1, limits.velocity, limits.acceleration, limits.jerk
                )
                if beyond(stop, i, i, p_now, False) < best:
                    motion.append(stop, (rows, math.nan, 1))
                    end_p = stop.at_time(float(stop.duration))[0]
                    state = (list(end_p), [0.0] * n, [0.0] * n)
                    continue
        assert found is not None
        j, traj = found
        state = arrived(i, j, traj)
        i = j + 1
    motion.sample_times = reached
    return motion


def join(
    t: float,
    start: tuple[Float, Float, Float],
    target: Any,
    limits: MotionLimits,
    durations: tuple[float, ...],
    bounds: tuple[Float, Float] | None = None,
) -> Motion | None:
    """A jerk-limited segment from ``start`` (position, velocity, acceleration at ``t``) onto
    the motion ``target`` (anything with ``at(time)``: its state then), lasting exactly the
    first of ``durations`` (s) that Ruckig can (within ``limits``, and ``bounds``: the joint
    position limits, (lower, upper)): a :class:`Motion` from ``t``, or None.

    Continuous in position, velocity and acceleration at both ends: the online controller
    joins a plan whose reply came after its hand-over time this way, instead of asking again.
    """
    p0, v0, a0 = (np.asarray(x, dtype=np.float64) for x in start)
    for d in durations:
        p1, v1, a1 = target.at(t + d)
        rows = np.array([p0, v0, a0, p1, v1, a1], dtype=np.float64)
        traj = _lasting(rows, d, limits)
        if traj is None:
            continue
        rows, traj = _onto_target(rows, traj, d, limits)
        if bounds is not None and any(
            e.min < bounds[0][k] - BOUNDS_TOL or e.max > bounds[1][k] + BOUNDS_TOL
            for k, e in enumerate(traj.position_extrema)
        ):
            continue
        motion = Motion(t, (p0, v0, a0), limits)
        motion.append(traj, (rows, d, 0))
        return motion
    return None


def _lasting(rows: Float, d: float, limits: MotionLimits) -> Any:
    """Ruckig's segment from ``rows`` (its input: current and target position, velocity,
    acceleration, (6, n)) lasting exactly ``d``, or None where it cannot arrive then (too
    soon, or a blocked duration)."""
    try:
        traj = _ruckig_plan(rows, d, 0, limits.velocity, limits.acceleration, limits.jerk)
    except RuntimeError:
        return None
    return traj if abs(float(traj.duration) - d) <= 1e-9 * max(1.0, d) else None


def _onto_target(rows: Float, traj: Any, d: float, limits: MotionLimits) -> tuple[Float, Any]:
    """A Ruckig segment of duration ``d`` planned from ``rows`` again, its target position
    moved by the error it ended with, where that one ends nearer: (its rows, it).

    Ruckig reaches a target position within about 1e-8 rad. Where a segment hands over to
    another motion (:func:`join`), that error is a step: 5.5e-9 rad is 5.5 rad/s^3 of jerk in
    1 kHz commands, 9 % of the Katana's limit. One step against it ends within 1e-11.
    """
    err = rows[3] - np.asarray(traj.at_time(d)[0], dtype=np.float64)
    if not np.any(err):
        return rows, traj
    again = rows.copy()
    again[3] = rows[3] + err
    better = _lasting(again, d, limits)
    if better is None:
        return rows, traj
    left = rows[3] - np.asarray(better.at_time(d)[0], dtype=np.float64)
    if float(np.abs(left).max()) >= float(np.abs(err).max()):
        return rows, traj
    return again, better


def _quintics_within(
    c: Float,
    h: Float,
    v1: Float,
    a1: Float,
    lim: MotionLimits,
    bounds: tuple[Float, Float] | None = None,
) -> Float:
    """Which quintics (coefficients ``c`` (6, m, n), durations ``h`` (m, 1), ending at velocity
    ``v1`` and acceleration ``a1`` (m, n)) stay within ``lim``: (m,) bool.

    Jerk and acceleration exactly (their extrema in closed form), velocity at 33 points of
    each. And where each ends, the velocity reached if the acceleration were ramped down at the
    jerk limit (what the next segment must be able to do, whatever it is): else a Ruckig
    segment after it would overshoot the velocity limit. With ``bounds`` (joint position
    limits (lower, upper), each (n,)), positions within them at the same 33 points.
    """
    c3, c4, c5 = c[3], c[4], c[5]
    # jerk 6 c3 + 24 c4 s + 60 c5 s^2: at the ends and its vertex; acceleration at the ends
    # and at the jerk's roots inside the piece.
    jerk = np.maximum(np.abs(6.0 * c3), np.abs(6.0 * c3 + 24.0 * c4 * h + 60.0 * c5 * h * h))
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(c5 != 0.0, -24.0 * c4 / (120.0 * c5), -1.0)
        inside = (vertex > 0.0) & (vertex < h)
        sv = np.where(inside, vertex, 0.0)
        jerk = np.maximum(jerk, np.abs(6.0 * c3 + 24.0 * c4 * sv + 60.0 * c5 * sv * sv))

        def acc(s_: Float) -> Float:
            return np.asarray(2.0 * c[2] + 6.0 * c3 * s_ + 12.0 * c4 * s_ * s_ + 20.0 * c5 * s_**3)

        big = np.maximum(np.abs(acc(np.zeros_like(h))), np.abs(acc(h + 0.0 * c3)))
        disc = (24.0 * c4) ** 2 - 4.0 * (60.0 * c5) * (6.0 * c3)
        root = np.sqrt(np.maximum(disc, 0.0))
        for sign in (1.0, -1.0):
            s_r = np.where(c5 != 0.0, (-24.0 * c4 + sign * root) / (120.0 * c5), -1.0)
            ok = (disc >= 0.0) & (s_r > 0.0) & (s_r < h)
            big = np.maximum(big, np.where(ok, np.abs(acc(np.where(ok, s_r, 0.0))), 0.0))
        coast = np.where(np.isinf(lim.jerk), 0.0, a1 * np.abs(a1) / (2.0 * lim.jerk))
    frac = np.linspace(0.0, 1.0, 33)[:, None, None]
    s_v = frac * h
    vel = (((5.0 * c5 * s_v + 4.0 * c4) * s_v + 3.0 * c3) * s_v + 2.0 * c[2]) * s_v + c[1]
    within = (
        (jerk <= lim.jerk)
        & (big <= lim.acceleration)
        & (np.abs(vel).max(axis=0) <= lim.velocity)
        & (np.abs(v1 + coast) <= lim.velocity)
        & np.isfinite(jerk)
    )
    ok = within.all(axis=1)
    if bounds is not None:
        pos = _quintic_positions(c, s_v)
        # Between two of the 33 points, a position passes the straight line through them by at
        # most (largest |acceleration|) (spacing)^2 / 8: a bound, not an estimate.
        gap = big * (h / 32.0) ** 2 / 8.0
        ok &= (
            (pos.min(axis=0) - gap >= bounds[0] - BOUNDS_TOL)
            & (pos.max(axis=0) + gap <= bounds[1] + BOUNDS_TOL)
        ).all(axis=1)
        # Ending where a stop still keeps within them (a state the rest can recover from).
        ok &= _stop_overshoot(pos[-1], v1 + 0.0 * pos[-1], a1 + 0.0 * pos[-1], bounds, lim) <= 0.0
    return np.asarray(ok)


def _stop_overshoot(
    p: Float, v: Float, a: Float, bounds: tuple[Float, Float], limits: MotionLimits
) -> Float:
    """How far (rad) past a joint limit the hardest stop from each state goes (rows of p, v, a:
    (m, n)): the largest over the joints of each row, 0 where every stop keeps within.

    A bound on the stopping distance first (the acceleration ramped down at the jerk limit,
    then braking at the acceleration limit, all at the speed reached); Ruckig's exact stop
    (its velocity interface) only for the joints that bound does not clear."""
    amax, jmax = limits.acceleration, limits.jerk
    s = np.where(v != 0.0, np.sign(v), np.sign(a))
    push = np.maximum(s * a, 0.0)  # acceleration still toward the motion's direction
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ramp = np.where(np.isinf(jmax), 0.0, push / jmax)
        v_top = np.abs(v) + np.where(np.isinf(jmax), 0.0, push * push / (2.0 * jmax))
        t_brake = np.where(np.isinf(amax), 0.0, v_top / amax) + np.where(
            np.isinf(jmax), 0.0, amax / jmax
        )
        far = np.where(np.isfinite(t_brake), v_top * (t_ramp + t_brake), np.inf)
    room = np.where(s > 0, bounds[1] - p, np.where(s < 0, p - bounds[0], np.inf))
    out = np.zeros(p.shape[0])
    rows, cols = np.nonzero(far > room - BOUNDS_TOL)
    if rows.size == 0:
        return out
    for r, k in zip(rows.tolist(), cols.tolist(), strict=True):
        one = slice(k, k + 1)
        recipe = np.array([p[r, one], v[r, one], a[r, one], p[r, one], [0.0], [0.0]])
        try:  # the brake() of one joint
            traj = _ruckig_plan(recipe, math.nan, 1, limits.velocity[one], amax[one], jmax[one])
        except RuntimeError:
            out[r] = np.inf
            continue
        e = traj.position_extrema[0]
        out[r] = max(out[r], bounds[0][k] - BOUNDS_TOL - e.min, e.max - bounds[1][k] - BOUNDS_TOL)
    return out


class _KnotPieces:
    """The quintics through consecutive samples' states (position, velocity, acceleration),
    where they are within motion limits, joined from where the motion is.

    With the cubic spline's velocities and accelerations at the samples, each quintic is the
    spline's piece itself (the spline is C2). A piece within ``SPLINE_MARGIN`` of the limits is
    followed when the motion is at its start (within rounding of the sample's state: Ruckig
    ends a trajectory within about 1e-9 of its target): as the quintic from the motion's state
    to the next sample's, which is the piece itself when the motion is exactly on it and lands
    on the next sample exactly otherwise (a jump of 1e-9 rad would be a jerk of 6 rad/s^3 at
    1 kHz). Jerk and acceleration are checked exactly (their extrema in closed form), velocity
    at 33 points of each piece, inside the margin.
    """

    def __init__(
        self,
        t: Float,
        q: Float,
        v: Float,
        a: Float,
        limits: MotionLimits,
        bounds: tuple[Float, Float] | None = None,
    ) -> None:
        self.t = t
        self.state = (q, v, a)
        self.rows = [q.tolist(), v.tolist(), a.tolist()]  # exact, for comparing with a state
        h = np.diff(t)[:, None]
        c = _quintic_coefficients((q[:-1], v[:-1], a[:-1]), (q[1:], v[1:], a[1:]), h)
        self.c = c  # (6, T - 1, n)
        self.feasible = _quintics_within(c, h, v[1:], a[1:], limits.scaled(SPLINE_MARGIN), bounds)

    def bridge(
        self,
        window: range,
        now: float,
        state: tuple[list[float], list[float], list[float]],
        limits: MotionLimits,
        bounds: tuple[Float, Float] | None = None,
    ) -> tuple[int, _Quintic] | None:
        """The first sample j of ``window`` the quintic from ``state`` (at ``now``) reaches on
        time within ``limits`` (and ``bounds``): (j, that quintic), or None."""
        js = np.array([j for j in window if self.t[j] > now + 1e-9], dtype=np.intp)
        if js.size == 0:
            return None
        p, v, a = (np.asarray(x, dtype=np.float64)[None] for x in state)
        h = (self.t[js] - now)[:, None]
        end = (self.state[0][js], self.state[1][js], self.state[2][js])
        c = _quintic_coefficients((p, v, a), end, h)
        ok = np.flatnonzero(_quintics_within(c, h, end[1], end[2], limits, bounds))
        if ok.size == 0:
            return None
        k = int(ok[0])
        j = int(js[k])
        return j, _Quintic(None, (end[0][k], end[1][k], end[2][k]), float(h[k, 0]), c[:, k])

    def piece(
        self, i: int, now: float, state: tuple[list[float], list[float], list[float]]
    ) -> _Quintic | None:
        """The piece to sample i, if it is feasible and the motion is at its start, on time."""
        k = i - 1
        if not self.feasible[k] or abs(now - float(self.t[k])) > 1e-9:
            return None
        end = (self.state[0][i], self.state[1][i], self.state[2][i])
        duration = float(self.t[i] - self.t[k])
        rows = self.rows
        if state[0] == rows[0][k] and state[1] == rows[1][k] and state[2] == rows[2][k]:
            return _Quintic(None, end, duration, self.c[:, k])  # exactly on it: the piece
        p, v, a = (np.asarray(x, dtype=np.float64) for x in state)
        q0, v0, a0 = (x[k] for x in self.state)
        scale = 1.0 + float(np.abs(q0).max())
        if (
            np.abs(p - q0).max() > 1e-8 * scale
            or np.abs(v - v0).max() > 1e-7 * scale
            or np.abs(a - a0).max() > 1e-6 * scale
        ):
            return None
        return _Quintic((p, v, a), end, duration)


def follow_samples(
    t: Float,
    q: Float,
    limits: MotionLimits,
    period: float,
    *,
    velocities: Float | None = None,
    accelerations: Float | None = None,
    start: tuple[Float, Float, Float] | None = None,
    n_steps: int | None = None,
) -> tuple[Float, Float, Float]:
    """Setpoints every ``period`` of the motion :func:`follow` makes through timed samples.

    Parameters
    ----------
    t, q, limits, velocities, accelerations, start
        As :func:`follow`.
    period : float
        Seconds between setpoints.
    n_steps : int, optional
        Number of setpoints; default: until the motion is at rest at the last sample (the
        first setpoint at or after its end). Beyond the motion, the last setpoint is held.

    Returns
    -------
    positions, velocities, accelerations : ndarray, shape (K, n)
        Row k at t[0] + k period; row 0 is the start state.
    """
    motion = follow(t, q, limits, velocities=velocities, accelerations=accelerations, start=start)
    return motion.every(period, n_steps)
