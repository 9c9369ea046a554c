"""Tests of pbdkit.motion._otg (Ruckig): valid targets, time-optimal
point-to-point moves, motions through timed samples (continuity, limits at any sampling rate,
samples passed on time, rest at the end, a moving start), their setpoints every period, and the
clamped cubic spline's derivatives."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

pytest.importorskip("ruckig")

from pbdkit.motion._limits import MotionLimits, motion_peaks, retime, times_from_durations
from pbdkit.motion._otg import (
    Motion,
    follow,
    follow_samples,
    point_to_point,
    spline_derivatives,
    valid_target,
)

Float = NDArray[np.float64]
AnyFloat = NDArray[np.floating[Any]]
INF = math.inf

LIM = MotionLimits(np.array([1.0, 1.5, 1.19]), np.array([5.0, 8.0, 6.0]), np.array([50.0, 80, 60]))


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------


def min_jerk(
    t: AnyFloat, duration: float, start: AnyFloat, goal: AnyFloat
) -> tuple[Float, Float, Float]:
    """Positions, velocities and accelerations of a minimum-jerk move (exact)."""
    s = np.clip(t / duration, 0.0, 1.0)[:, None]
    d = goal - start
    p = start + d * (10 * s**3 - 15 * s**4 + 6 * s**5)
    v = d * (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
    a = d * (60 * s - 180 * s**2 + 120 * s**3) / duration**2
    f64 = np.float64
    return p.astype(f64), v.astype(f64), a.astype(f64)


def assert_within_limits(
    times: AnyFloat, q: AnyFloat, limits: MotionLimits, pad_rest: int = 3
) -> None:
    """Divided differences (padded with rest) within the limits, up to 1e-9 relative and the
    rounding of the positions (~1e-14 rad) amplified by the differences: 2, 4, 8 eps / h^k."""
    peaks = motion_peaks(times, q, limits, pad_rest=pad_rest)
    h = float(np.diff(times).min())
    eps = 1e-14 * (1.0 + float(np.abs(q).max()))
    bounds = (limits.velocity, limits.acceleration, limits.jerk)
    for k, (name, bound) in enumerate(
        zip(("velocity", "acceleration", "jerk"), bounds, strict=True), start=1
    ):
        tol = 1e-9 + 2.0**k * eps / h**k / float(bound.min())
        assert getattr(peaks, name) <= 1.0 + tol, (name, getattr(peaks, name), h)


def assert_continuous(motion: Motion, limits: MotionLimits, step: float = 1e-3) -> None:
    """Position, velocity and acceleration of Motion.at change by at most velocity, acceleration
    and jerk limit times the step between any two times ``step`` apart: no jump anywhere."""
    times = np.arange(motion.t0 - 0.01, motion.end + 0.05, step)
    p, v, a = motion.sample(times)
    for x, bound in ((p, limits.velocity), (v, limits.acceleration), (a, limits.jerk)):
        jump = np.abs(np.diff(x, axis=0)).max(axis=0)
        assert np.all(jump <= bound * step * (1 + 1e-9) + 1e-12), (jump, bound * step)
    # the derivatives are those of the positions (central differences at mid-steps)
    mid = times[1:-1]
    pm, vm, am = motion.sample(mid)
    pp, vp, _ = motion.sample(mid + 1e-5)
    pn, vn, _ = motion.sample(mid - 1e-5)
    np.testing.assert_allclose((pp - pn) / 2e-5, vm, atol=1e-7)
    np.testing.assert_allclose((vp - vn) / 2e-5, am, atol=1e-5 * limits.jerk.max())
    assert np.isfinite(pm).all()


def assert_continuous_at(motion: Motion, times: AnyFloat, limits: MotionLimits) -> None:
    """The state just before and just after each time agrees."""
    eps = 1e-9
    for t in times:
        before = motion.at(float(t) - eps)
        after = motion.at(float(t) + eps)
        bounds = (limits.velocity, limits.acceleration, limits.jerk)
        for x0, x1, bound in zip(before, after, bounds, strict=True):
            assert np.all(np.abs(x1 - x0) <= bound * 2 * eps * (1 + 1e-6) + 1e-12), (t, x0, x1)


def clamped_spline_first_derivatives(t: AnyFloat, y: AnyFloat, v0: float, v1: float) -> Float:
    """Slopes at the knots of the C2 cubic spline with the end slopes v0 and v1 (the textbook
    tridiagonal system, solved densely)."""
    k = t.shape[0]
    h = np.diff(t)
    d = np.diff(y) / h
    m = np.zeros((k, k))
    rhs = np.zeros(k)
    m[0, 0], rhs[0] = 1.0, v0
    m[-1, -1], rhs[-1] = 1.0, v1
    for i in range(1, k - 1):
        m[i, i - 1] = 1.0 / h[i - 1]
        m[i, i] = 2.0 * (1.0 / h[i - 1] + 1.0 / h[i])
        m[i, i + 1] = 1.0 / h[i]
        rhs[i] = 3.0 * (d[i - 1] / h[i - 1] + d[i] / h[i])
    return np.asarray(np.linalg.solve(m, rhs), dtype=np.float64)


def hermite_second_derivatives(t: AnyFloat, y: AnyFloat, slopes: AnyFloat) -> Float:
    h = np.diff(t)
    d = np.diff(y) / h
    out = np.empty(y.shape, dtype=np.float64)
    out[:-1] = (6 * d - 4 * slopes[:-1] - 2 * slopes[1:]) / h  # start of each interval
    out[-1] = (-6 * d[-1] + 2 * slopes[-2] + 4 * slopes[-1]) / h[-1]  # end of the last one
    return out


# ------------------------------------------------------------------------------------------
# valid_target
# ------------------------------------------------------------------------------------------


def test_valid_target_clips_velocity_acceleration_and_the_room_left_by_the_jerk() -> None:
    lim = MotionLimits(np.full(4, 1.0), np.full(4, 4.0), np.full(4, 40.0))
    v, a = valid_target(np.array([2.0, 0.5, 0.9, -0.9]), np.array([1.0, 10.0, -4.0, 1.0]), lim)
    np.testing.assert_allclose(v, [1.0, 0.5, 0.9, -0.9])
    # room for a: sqrt(2 J (V - |v|)): 0, sqrt(40) > 4, sqrt(8), sqrt(8)
    np.testing.assert_allclose(a, [0.0, 4.0, -math.sqrt(8.0), 1.0])
    rng = np.random.default_rng(0)
    vr, ar = valid_target(
        rng.normal(scale=1.5, size=(200, 4)), rng.normal(scale=6, size=(200, 4)), lim
    )
    assert np.all(np.abs(vr) <= 1.0)
    assert np.all(np.abs(ar) <= 4.0)
    assert np.all(np.abs(vr) + ar**2 / (2 * 40.0) <= 1.0 + 1e-12)
    # nothing limited: unchanged (no NaN from inf - inf)
    free = MotionLimits.unlimited(2)
    vf, af = valid_target(np.array([5.0, -3.0]), np.array([100.0, -7.0]), free)
    np.testing.assert_array_equal(vf, [5.0, -3.0])
    np.testing.assert_array_equal(af, [100.0, -7.0])


def test_point_to_point_validates_its_cycle_time() -> None:
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="dt must be a positive number"):
            point_to_point(np.zeros(3), np.ones(3), bad, LIM)


# ------------------------------------------------------------------------------------------
# point_to_point: time-optimal, synchronized, at rest at both ends
# ------------------------------------------------------------------------------------------


def test_point_to_point_ends_at_the_goal_at_rest_synchronized_within_the_limits() -> None:
    dt = 0.001
    start = np.array([0.2, -0.5, 1.0])
    goal = np.array([-0.4, 0.3, 1.2])
    p, v, a = point_to_point(start, goal, dt, LIM)
    assert p.shape == v.shape == a.shape
    assert p.shape[1] == 3
    np.testing.assert_array_equal(p[0], start)
    np.testing.assert_array_equal(v[0], 0.0)
    np.testing.assert_array_equal(p[-1], goal)
    np.testing.assert_array_equal(v[-1], 0.0)
    np.testing.assert_array_equal(a[-1], 0.0)
    assert_within_limits(dt * np.arange(p.shape[0]), p, LIM)
    # time-synchronized: no joint arrives before the others
    arrived = np.abs(p - goal) <= 1e-12
    first = [int(np.argmax(arrived[:, j])) for j in range(3)]
    assert first == [p.shape[0] - 1] * 3
    # the same posture: one sample
    p1, v1, a1 = point_to_point(start, start, dt, LIM)
    np.testing.assert_array_equal(p1, start[None])
    assert v1.shape == a1.shape == (1, 3)


def test_point_to_point_stays_on_the_straight_line_in_joint_space() -> None:
    start = np.array([0.2, -0.5, 1.0])
    goal = np.array([-0.4, 0.3, 1.2])
    p, _, _ = point_to_point(start, goal, 0.001, LIM)
    frac = (p - start) / (goal - start)  # every joint at the same fraction of its way
    np.testing.assert_allclose(frac, np.repeat(frac[:, :1], 3, axis=1), atol=1e-6)


@pytest.mark.parametrize(
    ("vel", "acc", "jerk", "distance", "optimal"),
    [
        # only a velocity limit: distance / velocity
        (1.0, INF, INF, 1.2345, 1.2345),
        (0.5, INF, INF, -0.7777, 0.7777 / 0.5),
        # velocity and acceleration reached (distance >= V^2/A + V A / J, V >= A^2 / J): the
        # jerk-limited S-curve takes D / V + V / A + A / J
        (1.0, 4.0, 40.0, 1.2345, 1.2345 + 0.25 + 0.1),
        # velocity only: a trapezoid of acceleration with instant ramps, D / V + V / A
        (1.0, 4.0, INF, 0.8765, 0.8765 + 0.25),
    ],
)
def test_point_to_point_takes_the_time_optimal_duration(
    vel: float, acc: float, jerk: float, distance: float, optimal: float
) -> None:
    dt = 0.001
    lim = MotionLimits(np.array([vel]), np.array([acc]), np.array([jerk]))
    p, v, _ = point_to_point([0.3], [0.3 + distance], dt, lim)
    steps = p.shape[0] - 1
    assert steps == math.ceil(optimal / dt)  # the first cycle at or after the optimal time
    assert np.abs(v).max() == pytest.approx(vel, rel=1e-9)
    assert_within_limits(dt * np.arange(p.shape[0]), p, lim)
    if math.isinf(acc):
        k = np.arange(steps)
        np.testing.assert_allclose(
            p[:steps, 0], 0.3 + math.copysign(vel, distance) * dt * k, rtol=0, atol=1e-12
        )


# ------------------------------------------------------------------------------------------
# follow: motions through timed samples
# ------------------------------------------------------------------------------------------

START = np.array([0.1, -0.3, 0.4])
GOAL = np.array([0.7, 0.5, -0.3])
RATES = [0.001, 0.002, 0.0186]


def _feasible() -> tuple[Float, Float, Float, Float]:
    """A slow min-jerk move sampled at 50 Hz (well within LIM), from t = 2 s."""
    t = 2.0 + np.arange(0.0, 2.0 + 1e-9, 0.02)
    p, v, a = min_jerk(t - 2.0, 2.0, START, GOAL)
    return t, p, v, a


def _retimed() -> tuple[Float, Float]:
    """A fast min-jerk path timed by retime into LIM (what a reproduction plays)."""
    t = np.arange(60) * 0.01
    q, _, _ = min_jerk(t, t[-1], START, GOAL)
    return times_from_durations(retime(q, 0.01, LIM)), q


def _infeasible() -> tuple[Float, Float]:
    """A random walk too fast for LIM: samples are passed by or approached."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.015, 0.03, 25))
    q = START + np.cumsum(rng.normal(0, 0.02, (25, 3)), axis=0)
    return t, q


@pytest.mark.parametrize("case", ["feasible", "retimed", "infeasible"])
def test_follow_is_continuous_at_rest_at_the_last_sample_and_within_limits_at_any_rate(
    case: str,
) -> None:
    if case == "feasible":
        t, q, _, _ = _feasible()
    elif case == "retimed":
        t, q = _retimed()
    else:
        t, q = _infeasible()
        assert motion_peaks(t, q, LIM).worst > 2.0
    motion = follow(t, q, LIM)
    assert motion.t0 == t[0]
    assert motion.end >= t[-1] - 1e-9
    assert_continuous(motion, LIM)
    # at rest at the last sample, and held there
    for at in (motion.end, motion.end + 0.5):
        p, v, a = motion.at(at)
        np.testing.assert_allclose(p, q[-1], atol=1e-9)
        np.testing.assert_allclose(v, 0.0, atol=1e-9)
        np.testing.assert_allclose(a, 0.0, atol=1e-9)
    # before t0: the start state
    p, v, a = motion.at(t[0] - 1.0)
    np.testing.assert_array_equal(p, q[0])
    np.testing.assert_array_equal(v, 0.0)
    # sampled at 1 kHz, 500 Hz, 1 / 0.0186 s and at irregular times: within the limits
    span = motion.end - motion.t0
    for period in RATES:
        times = np.asarray(motion.t0 + period * np.arange(math.ceil(span / period) + 1), np.float64)
        assert_within_limits(times, motion.sample(times)[0], LIM)
    rng = np.random.default_rng(11)
    gaps = rng.uniform(0.002, 0.03, int(span / 0.002) + 2)
    times = motion.t0 + np.r_[0.0, np.cumsum(gaps)]
    times = times[: int(np.searchsorted(times, motion.end)) + 1]
    assert times[-1] >= motion.end
    assert_within_limits(times, motion.sample(times)[0], LIM)


def test_follow_passes_feasible_samples_on_time() -> None:
    t, q, v, a = _feasible()
    for kwargs in ({"velocities": v, "accelerations": a}, {}):
        motion = follow(t, q, LIM, **kwargs)  # type: ignore[arg-type]
        assert motion.end == pytest.approx(t[-1], abs=1e-9)
        p_at, v_at, a_at = motion.sample(t)
        np.testing.assert_allclose(p_at, q, atol=1e-6)
        if kwargs:
            np.testing.assert_allclose(v_at, v, atol=1e-6)
            np.testing.assert_allclose(a_at, a, atol=1e-6)
        assert_continuous_at(motion, t[1:-1], LIM)


def test_follow_a_moving_start_begins_in_that_state() -> None:
    t, q, _, _ = _feasible()
    v0 = np.array([0.3, -0.2, 0.1])
    a0 = np.array([1.0, 0.5, -0.5])
    p0 = q[0] + np.array([0.01, -0.01, 0.0])
    assert np.all(np.abs(v0) + a0**2 / (2 * LIM.jerk) < LIM.velocity)
    motion = follow(t, q, LIM, start=(p0, v0, a0))
    p, v, a = motion.at(t[0])
    np.testing.assert_array_equal(p, p0)
    np.testing.assert_array_equal(v, v0)
    np.testing.assert_array_equal(a, a0)
    # and continues from it (no jump just after t0)
    eps = 1e-7
    p, v, a = motion.at(t[0] + eps)
    np.testing.assert_allclose(p, p0 + v0 * eps + a0 * eps**2 / 2, atol=LIM.jerk.max() * eps**3)
    np.testing.assert_allclose(v, v0 + a0 * eps, atol=LIM.jerk.max() * eps**2)
    np.testing.assert_allclose(a, a0, atol=LIM.jerk.max() * eps * (1 + 1e-9))
    # its setpoints: row 0 is the start state; within the limits when the padding before the
    # first setpoint continues the start state (at rest after the last one)
    period = 0.002
    ps, vs, acs = follow_samples(t, q, LIM, period, start=(p0, v0, a0))
    np.testing.assert_array_equal(ps[0], p0)
    np.testing.assert_array_equal(vs[0], v0)
    np.testing.assert_array_equal(acs[0], a0)
    back = period * np.arange(3, 0, -1)
    tb = t[0] - back
    qb = p0 + np.outer(-back, v0) + np.outer(back**2, a0) / 2
    times = np.r_[tb, t[0] + period * np.arange(ps.shape[0])]
    times = np.r_[times, times[-1] + period * np.arange(1, 4)]
    qs = np.r_[qb, ps, np.repeat(ps[-1:], 3, axis=0)]
    assert_within_limits(times, qs, LIM, pad_rest=0)
    np.testing.assert_allclose(ps[-1], q[-1], atol=1e-9)
    # the same start at rest would be a different motion: the start state matters
    rest = follow(t, q, LIM, start=(p0, np.zeros(3), np.zeros(3)))
    assert not np.allclose(rest.at(t[0] + 0.05)[0], motion.at(t[0] + 0.05)[0], atol=1e-4)


def test_follow_two_samples_with_only_a_velocity_limit_is_time_optimal() -> None:
    lim = MotionLimits(np.array([0.8, 2.0]), np.full(2, INF), np.full(2, INF))
    t = np.array([1.0, 1.1])  # far too short: the move takes what the limits need
    q = np.array([[0.0, 0.0], [1.2, -1.0]])
    motion = follow(t, q, lim)
    assert motion.end - motion.t0 == pytest.approx(1.2 / 0.8, rel=1e-9)
    p, _, _ = motion.at(1.0 + 0.75)
    np.testing.assert_allclose(p, [0.6, -0.5], atol=1e-9)  # synchronized, constant speeds
    # given more time than it needs, it takes that time
    slow = follow(np.array([1.0, 4.0]), q, lim)
    assert slow.end == pytest.approx(4.0, abs=1e-9)


def test_follow_through_too_fast_samples_of_a_monotone_path_does_not_go_back() -> None:
    lim = MotionLimits(np.array([1.19]), np.array([6.0]), np.array([60.0]))
    t = np.asarray(0.02 * np.arange(60), dtype=np.float64)
    q, _, _ = min_jerk(t, t[-1], np.zeros(1), np.ones(1))
    assert motion_peaks(t, q, lim).velocity > 1.2  # too fast for the arm
    motion = follow(t, q, lim)
    p = motion.sample(np.arange(motion.t0, motion.end + 1e-3, 1e-3))[0][:, 0]
    # Samples beyond the limits (a reproduction's are retimed within them first): it goes on
    # as fast as the limits allow, aiming for the samples it cannot reach in time with the
    # least swing beyond the samples on the way. Before that rule, the joint went back from
    # 0.39 to 0.04 rad twice (0.7 rad back in all) and took 5.3 s. Measured now: 0.31 rad back
    # in all (where the spline through the samples leaves the limits), 7.6 mrad past the end,
    # 2.77 s.
    assert -np.minimum(np.diff(p), 0.0).sum() < 0.4
    assert p.min() >= -1e-9 and p.max() <= 1.02
    # a rest-to-rest move over the whole path takes 1/1.19 + 1.19/6 + 6/60 = 1.14 s
    assert motion.end - motion.t0 < 3.5


# ------------------------------------------------------------------------------------------
# follow_samples
# ------------------------------------------------------------------------------------------


def test_follow_samples_rows_are_the_motion_every_period() -> None:
    t, q = _retimed()
    t = t + 3.0
    period = 0.002
    motion = follow(t, q, LIM)
    p, v, a = follow_samples(t, q, LIM, period)
    k = p.shape[0]
    times = t[0] + period * np.arange(k)
    pm, vm, am = motion.sample(times)
    np.testing.assert_allclose(p, pm, atol=1e-12)
    np.testing.assert_allclose(v, vm, atol=1e-12)
    np.testing.assert_allclose(a, am, atol=1e-12)
    # until the first setpoint at or after the end of the motion
    assert times[-1] >= motion.end - 1e-9
    assert times[-2] < motion.end
    np.testing.assert_allclose(p[-1], q[-1], atol=1e-9)
    # a given number of setpoints: beyond the motion, the last one is held
    p2, v2, _ = follow_samples(t, q, LIM, period, n_steps=k + 20)
    assert p2.shape == (k + 20, 3)
    np.testing.assert_allclose(p2[:k], p, atol=1e-12)
    np.testing.assert_allclose(p2[k:], np.repeat(q[-1:], 20, axis=0), atol=1e-9)
    np.testing.assert_allclose(v2[k:], 0.0, atol=1e-9)
    p3, _, _ = follow_samples(t, q, LIM, period, n_steps=5)
    np.testing.assert_allclose(p3, p[:5], atol=1e-12)


# ------------------------------------------------------------------------------------------
# spline_derivatives
# ------------------------------------------------------------------------------------------


def test_spline_derivatives_are_those_of_the_clamped_cubic_spline() -> None:
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.02, 0.1, 15))
    q = np.cumsum(rng.normal(scale=0.1, size=(15, 2)), axis=0)
    v0 = np.array([0.4, -0.3])
    for start in (None, v0):
        v, a = spline_derivatives(t, q, start)
        assert v.shape == a.shape == q.shape
        for j in range(2):
            s0 = 0.0 if start is None else float(v0[j])
            slopes = clamped_spline_first_derivatives(t, q[:, j], s0, 0.0)
            np.testing.assert_allclose(v[:, j], slopes, rtol=1e-9, atol=1e-9)
            acc = hermite_second_derivatives(t, q[:, j], slopes)
            np.testing.assert_allclose(a[:, j], acc, rtol=1e-8, atol=1e-8)
            ref = CubicSpline(t, q[:, j], bc_type=((1, np.array(s0)), (1, np.array(0.0))))
            np.testing.assert_allclose(v[:, j], ref(t, 1), rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(a[:, j], ref(t, 2), rtol=1e-9, atol=1e-9)
        assert v[-1] == pytest.approx([0.0, 0.0], abs=1e-12)
        assert v[0] == pytest.approx([0.0, 0.0] if start is None else v0, abs=1e-12)


def test_spline_derivatives_reproduce_a_cubic_polynomial() -> None:
    # p(t) = (t - T)^2 (alpha t + beta) + gamma: p'(T) = 0, so the spline clamped at rest at the
    # end and at p'(t0) at the start is p itself
    rng = np.random.default_rng(5)
    t = 0.5 + np.sort(rng.uniform(0.0, 2.0, 12))
    end = t[-1]
    alpha = np.array([0.7, -1.3])
    beta = np.array([0.2, 0.5])
    gamma = np.array([0.1, -0.4])
    x = t[:, None]
    q = (x - end) ** 2 * (alpha * x + beta) + gamma
    dq = 2 * (x - end) * (alpha * x + beta) + alpha * (x - end) ** 2
    ddq = 2 * (alpha * x + beta) + 4 * alpha * (x - end)
    v, a = spline_derivatives(t, q, dq[0])
    np.testing.assert_allclose(v, dq, atol=1e-9)
    np.testing.assert_allclose(a, ddq, atol=1e-8)


def test_follow_never_enters_a_state_that_must_overshoot_the_velocity_limit() -> None:
    # A motion already on the way at 0.2 rad/s and 5 rad/s^2, samples at that constant
    # acceleration (the spline through them: about no jerk) up to 0.9 rad/s, then still: a
    # spline piece there has |v| and |a| within the limits but v + a|a| / 2J beyond V, so
    # any segment after it (here Ruckig's braking one) overshoots V (a basin reproduction
    # reached 1.004 x the velocity limit that way). Such pieces are left to Ruckig.
    lim = MotionLimits(np.array([1.0]), np.array([10.0]), np.array([20.0]))
    t = 0.02 * np.arange(60)
    tt = np.minimum(t, 0.14)
    q = (0.2 * tt + 2.5 * tt**2)[:, None]
    assert 0.2 + 5.0 * tt.max() == pytest.approx(0.9) and 0.9 + 25.0 / 40.0 > 1.5
    spline = CubicSpline(t, q, axis=0, bc_type=((1, [0.2]), (1, [0.0])))
    start = (q[0], np.array([0.2]), np.asarray(spline(t[0], 2), dtype=np.float64))
    motion = follow(t, q, lim, start=start)
    times = np.arange(motion.t0, motion.end + 1e-3, 1e-3)
    p, v, _ = motion.sample(times)
    assert np.abs(v).max() <= 1.0 + 1e-9
    # The motion's own samples (it starts moving: no rest before it) within every limit.
    assert_within_limits(times, p, lim, pad_rest=0)


@pytest.mark.parametrize("seed", range(4))
def test_follow_with_bounds_never_passes_a_joint_limit_the_path_stops_on(seed: int) -> None:
    # Issue 35: a path that brakes onto a joint limit (Table II clips it there) harder than the
    # jerk limit lets a motion follow: its samples are within the divided-difference limits,
    # and the motion through them was late and passed the limit (by 0.07 rad on an online
    # coaster plan). Given the bounds, no segment passes them.
    rng = np.random.default_rng(seed)
    lim = MotionLimits(np.array([1.19]), np.array([6.0]), np.array([60.0]))
    bound = 0.3
    x = np.minimum(np.cumsum(rng.uniform(0.02, 0.06, 30)), bound)
    q = np.concatenate([x, np.full(8, bound)])[:, None]
    t = times_from_durations(retime(q, 0.05, lim.scaled(0.995)))
    v, a = spline_derivatives(t, q)
    free = follow(t, q, lim, velocities=v, accelerations=a)
    held = follow(
        t, q, lim, velocities=v, accelerations=a, bounds=(np.array([-1.0]), np.array([bound]))
    )
    grid = np.linspace(t[0], max(free.end, held.end), 6000)
    top_free = max(free.at(float(s))[0][0] for s in grid)
    top_held = max(held.at(float(s))[0][0] for s in grid)
    assert top_held <= bound + 1e-9
    assert held.out_of(np.array([-1.0]), np.array([bound + 1e-9])) == []
    if seed in (0, 2):  # the seeds whose free motion passes the bound by a centimetre or more
        assert top_free > bound + 0.01 and free.out_of(np.array([-1.0]), np.array([bound]))
    # Within the motion limits still, and at rest at the end on the bound.
    s = held.every(1e-3)[0]
    assert motion_peaks(1e-3 * np.arange(len(s)), s, lim).worst <= 1.0 + 1e-6
    np.testing.assert_allclose(held.at(held.end + 1.0)[0], [bound], atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_out_of_finds_the_segments_a_dense_check_finds(seed: int) -> None:
    # Motion.out_of skips a quintic whose bound on its range (|c_k| h^k summed) keeps within the
    # limits: the same answer as checking every segment densely (here: 2001 points of each),
    # before and after pickling (the recipes as arrays).
    import pickle

    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 3.0, 61)
    q = 0.2 * np.sin(np.outer(t, [1.0, 2.0, 3.0]) + rng.uniform(0.0, 6.0, 3))
    start = (q[0] + 0.03, rng.normal(0.0, 0.2, 3), np.zeros(3))
    motion = follow(t, q, LIM, start=start)
    kinds = {type(s).__name__ for s in motion._segments}
    assert {"_Quintic", "Trajectory"} <= kinds
    dense = []  # (start, end, lowest, highest) of each segment
    for s0, d in zip(motion._starts, motion._durations, strict=True):
        pos = np.array([motion.at(float(x))[0] for x in np.linspace(s0, s0 + d, 2001)])
        dense.append((s0, s0 + d, pos.min(axis=0), pos.max(axis=0)))
    lo_all = np.min([x[2] for x in dense], axis=0)
    hi_all = np.max([x[3] for x in dense], axis=0)
    copy = pickle.loads(pickle.dumps(motion))
    found_some = False
    for frac in (0.0, 0.05, 0.2, 0.45):
        # Limits that cut a fraction of the range off at both ends (0: the range itself, padded).
        span = hi_all - lo_all
        lower, upper = lo_all + frac * span - 1e-6, hi_all - frac * span + 1e-6
        # A segment within 1e-7 of a limit is borderline for a dense check: none is counted.
        expected = [
            (a, b)
            for a, b, lo, hi in dense
            if np.any(lo < lower - 1e-7) or np.any(hi > upper + 1e-7)
        ]
        near = [
            (a, b)
            for a, b, lo, hi in dense
            if np.any(np.abs(lo - lower) <= 1e-7) or np.any(np.abs(hi - upper) <= 1e-7)
        ]
        for m in (motion, copy):
            got = m.out_of(lower, upper)
            assert set(expected) <= set(got) <= set(expected) | set(near)
        found_some |= bool(expected)
    assert found_some


def test_join_lands_on_a_motion_exactly_within_the_limits() -> None:
    # The late-plan join (issue 35): from a state moving along one motion onto another, a
    # segment that reaches the other's state (position, velocity, acceleration) at the
    # duration it says, within the limits; None where no duration given can.
    from pbdkit.motion._otg import join

    t = np.linspace(0.0, 2.0, 41)
    base = 0.3 * np.sin(np.outer(t, [1.0, 1.5, 2.0]))
    old = follow(t, base, LIM)
    new = follow(t, base + 0.01 * t[:, None], LIM, start=old.at(0.0))  # drifts 1 cm/s away
    start = old.at(0.5)
    joined = join(0.5, start, new, LIM, (0.005, 0.05, 0.1, 0.2, 0.4))
    assert joined is not None
    d = round(joined.end - 0.5, 9)
    assert d in (0.05, 0.1, 0.2, 0.4)  # 5 ms is too short to take up the drift of 0.5 s
    for a, b in zip(joined.at(0.5), start, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)
    # Onto the new motion's position within 1e-11 rad: Ruckig alone ends within about 1e-8,
    # a step that is 10 rad/s^3 of jerk at 1 kHz (test_planner's hand-over delay: a late plan
    # 5.5e-9 rad off, 1.4 % over the Katana's jerk limit, before join moved its target by the
    # error).
    p1, v1, a1 = joined.at(joined.end)
    np.testing.assert_allclose(p1, new.at(joined.end)[0], rtol=0, atol=1e-11)
    for a, b in zip((v1, a1), new.at(joined.end)[1:], strict=True):
        np.testing.assert_allclose(a, b, atol=1e-8)
    # Sampled at 1 kHz from the old motion through the join onto the new one: within the limits.
    grid = np.arange(0.4, joined.end + 0.1, 1e-3)
    s = np.array(
        [(old if x < 0.5 else joined if x < joined.end else new).at(float(x))[0] for x in grid]
    )
    assert motion_peaks(grid - grid[0], s, LIM, pad_rest=0).worst <= 1.0 + 1e-6
    # Too short for any, or a joint limit in the way (just short of where it lands): None.
    assert join(0.5, start, new, LIM, (0.005,)) is None
    land = new.at(0.5 + d)[0]
    upper = np.maximum(land, start[0]) + 1.0
    k = int(np.argmax(land - start[0]))
    upper[k] = land[k] - 1e-4
    assert join(0.5, start, new, LIM, (d,), bounds=(land - 1.0, upper)) is None
    assert join(0.5, start, new, LIM, (d,), bounds=(land - 1.0, upper + 2e-4)) is not None
