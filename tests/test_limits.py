"""Tests of pbdkit.motion: MotionLimits (validation, robots' limits), divided differences and
motion peaks against independent formulas, reversals, the jerk-limited braking speed against a
simulated stop, retiming a path into the limits, and the online StreamMonitor."""

from __future__ import annotations

import math
import types
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from pbdkit import robots
from pbdkit.motion._limits import (
    LIMIT_SAFETY,
    MotionLimits,
    MotionPeaks,
    RetimeWarning,
    StreamMonitor,
    count_reversals,
    divided_differences,
    motion_peaks,
    retime,
    times_from_durations,
)

Float = NDArray[np.float64]
AnyFloat = NDArray[np.floating[Any]]
INF = math.inf

DATA = Path(__file__).parent / "data"


# ------------------------------------------------------------------------------------------
# independent helpers
# ------------------------------------------------------------------------------------------


def newton_explicit(t: AnyFloat, y: AnyFloat, order: int) -> Float:
    """k! times the divided differences of every window of order + 1 consecutive samples, by the
    explicit formula q[t_0..t_k] = sum_i q_i / prod_{m != i} (t_i - t_m)."""
    rows = []
    for s in range(t.shape[0] - order):
        w = t[s : s + order + 1]
        total = np.zeros(y.shape[1:])
        for i in range(order + 1):
            denom = np.prod([w[i] - w[m] for m in range(order + 1) if m != i])
            total = total + y[s + i] / denom
        rows.append(math.factorial(order) * total)
    return np.array(rows)


def pad_rest(t: AnyFloat, q: AnyFloat, pad: int) -> tuple[AnyFloat, AnyFloat]:
    """pad copies of the first / last sample before / after them, at the end steps' spacing."""
    h0, h1 = t[1] - t[0], t[-1] - t[-2]
    tb = t[0] - h0 * np.arange(pad, 0, -1)
    ta = t[-1] + h1 * np.arange(1, pad + 1)
    qb = np.repeat(q[:1], pad, axis=0)
    qa = np.repeat(q[-1:], pad, axis=0)
    return np.concatenate([tb, t, ta]), np.concatenate([qb, q, qa])


def min_jerk(t: AnyFloat, duration: float, goal: AnyFloat) -> Float:
    s = t / duration
    return np.asarray((10 * s**3 - 15 * s**4 + 6 * s**5)[:, None] * goal, dtype=np.float64)


def simulated_stop_distance(v0: float, acc: float, jerk: float, dt: float) -> float:
    """Distance a joint at speed v0 and zero acceleration travels until it stops, with the
    fastest stop the limits allow, integrated step by step (piecewise-constant jerk, exact
    within a step): the acceleration ramps down to -acc at the jerk limit, holds, and ramps back
    to 0 when the velocity left equals what the ramp back removes (a^2 / (2 jerk))."""
    x, v, a = 0.0, v0, 0.0
    if math.isinf(jerk):
        a = -acc  # the acceleration jumps
    while v > 0.0:
        if math.isinf(jerk):
            j = 0.0
        elif a * a / (2.0 * jerk) >= v:
            j = jerk  # ramp back to zero acceleration, reaching v = 0 with it
        elif a <= -acc:
            j = 0.0
        else:
            j = -jerk
        step = dt
        if j < 0.0 and a - j * step < -acc:  # the ramp reaches -acc within this step
            step = (a + acc) / -j
        # exact integration over the step; stop at v = 0 (only the last step can cross it)
        v_next = v + a * step + 0.5 * j * step * step
        if v_next < 0.0:
            lo, hi = 0.0, step
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if v + a * mid + 0.5 * j * mid * mid > 0.0:
                    lo = mid
                else:
                    hi = mid
            step = lo
            v_next = 0.0
        x += v * step + 0.5 * a * step**2 + j * step**3 / 6.0
        a = max(a + j * step, -acc)
        if not math.isinf(jerk) and j > 0.0:
            a = min(a, 0.0)
        v = v_next
    return x


def limits3() -> MotionLimits:
    return MotionLimits(
        np.array([1.0, 2.0, INF]), np.array([5.0, 10.0, 8.0]), np.array([50.0, INF, 80.0])
    )


# ------------------------------------------------------------------------------------------
# MotionLimits
# ------------------------------------------------------------------------------------------


def test_motion_limits_basic_properties_scaled_unlimited_and_as_dict() -> None:
    lim = limits3()
    assert lim.n_joints == 3
    assert lim.any
    s = lim.scaled(LIMIT_SAFETY)
    np.testing.assert_array_equal(s.velocity, [LIMIT_SAFETY, 2 * LIMIT_SAFETY, INF])
    np.testing.assert_array_equal(s.acceleration, np.array([5.0, 10.0, 8.0]) * LIMIT_SAFETY)
    np.testing.assert_array_equal(s.jerk, [50 * LIMIT_SAFETY, INF, 80 * LIMIT_SAFETY])
    assert 0.9 < LIMIT_SAFETY < 1.0
    assert lim.as_dict() == {
        "velocity": [1.0, 2.0, None],
        "acceleration": [5.0, 10.0, 8.0],
        "jerk": [50.0, None, 80.0],
    }
    free = MotionLimits.unlimited(4)
    assert free.n_joints == 4
    assert not free.any
    assert free.as_dict() == {k: [None] * 4 for k in ("velocity", "acceleration", "jerk")}
    # frozen, read-only arrays
    with pytest.raises(ValueError, match="read-only"):
        lim.velocity[0] = 3.0
    with pytest.raises(AttributeError):
        lim.velocity = np.ones(3)  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"velocity": [1.0, -1.0]}, r"velocity\[1\] must be > 0"),
        ({"acceleration": [0.0, 1.0]}, r"acceleration\[0\] must be > 0"),
        ({"jerk": [1.0, math.nan]}, r"jerk\[1\] must be > 0.*nan"),
        ({"acceleration": [1.0, 1.0, 1.0]}, r"acceleration must have shape \(2,\)"),
        ({"jerk": [[1.0, 1.0]]}, r"jerk must be 1-D"),
        ({"velocity": "fast"}, r"velocity must be an array of numbers"),
    ],
)
def test_motion_limits_validation_names_the_argument(
    kwargs: dict[str, object], pattern: str
) -> None:
    args: dict[str, object] = {"velocity": [1.0, 1.0], "acceleration": [1.0, 1.0], "jerk": [1, 1]}
    args.update(kwargs)
    with pytest.raises(ValueError, match=pattern):
        MotionLimits(**args)  # type: ignore[arg-type]


def test_motion_limits_leave_the_callers_arrays_writable() -> None:
    velocity = np.array([1.0, 2.0])
    lim = MotionLimits(velocity, np.array([3.0, 4.0]), np.array([5.0, 6.0]))
    velocity[0] = 10.0  # the caller still owns its array
    assert lim.velocity[0] == 1.0


def _declaring(
    n: int, velocity: object = None, acceleration: object = None, jerk: object = None
) -> types.SimpleNamespace:
    """A stub declaring the three limits of a KinematicModel (inf where not given)."""
    inf = np.full(n, INF)
    return types.SimpleNamespace(
        velocity_limit=inf if velocity is None else velocity,
        acceleration_limit=inf if acceleration is None else acceleration,
        jerk_limit=inf if jerk is None else jerk,
    )


def test_from_robot_stub_unlimited_values_and_overrides() -> None:
    robot = types.SimpleNamespace(
        velocity_limit=np.array([1.5, 0.0, -2.0, INF, math.nan]),
        acceleration_limit=[4.0, 5.0, 6.0, 7.0, 8.0],
        jerk_limit=np.full(5, INF),
    )
    lim = MotionLimits.from_robot(robot, 5)
    np.testing.assert_array_equal(lim.velocity, [1.5, INF, INF, INF, INF])
    np.testing.assert_array_equal(lim.acceleration, [4.0, 5.0, 6.0, 7.0, 8.0])
    np.testing.assert_array_equal(lim.jerk, np.full(5, INF))
    # overrides: a number for every joint, one per joint, None
    lim = MotionLimits.from_robot(
        robot, 5, velocity=0.5, acceleration=None, jerk=[10.0, 20.0, 30.0, INF, 50.0]
    )
    np.testing.assert_array_equal(lim.velocity, np.full(5, 0.5))
    np.testing.assert_array_equal(lim.acceleration, np.full(5, INF))
    np.testing.assert_array_equal(lim.jerk, [10.0, 20.0, 30.0, INF, 50.0])
    # a robot without any limit
    assert not MotionLimits.from_robot(_declaring(2), 2).any


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"velocity": "fast"}, r"velocity_limit must be 'robot'.*'fast'"),
        ({"acceleration": -1.0}, r"acceleration_limit\[0\] must be > 0"),
        ({"jerk": [1.0, 0.0, 1.0]}, r"jerk_limit\[1\] must be > 0"),
        ({"velocity": [1.0, 2.0]}, r"velocity_limit must be a number or have shape \(3,\)"),
        ({"acceleration": math.nan}, r"acceleration_limit\[0\] must be > 0"),
    ],
)
def test_from_robot_override_errors_name_the_argument(
    kwargs: dict[str, object], pattern: str
) -> None:
    robot = _declaring(3, velocity=np.ones(3))
    with pytest.raises(ValueError, match=pattern):
        MotionLimits.from_robot(robot, 3, **kwargs)  # type: ignore[arg-type]


def test_from_robot_declared_limits_of_the_wrong_shape_are_refused() -> None:
    robot = _declaring(3, jerk=np.ones(4))
    with pytest.raises(ValueError, match=r"robot\.jerk_limit must have shape \(3,\)"):
        MotionLimits.from_robot(robot, 3)


def test_from_robot_katana_and_panda_published_limits() -> None:
    kat = MotionLimits.from_robot(robots.katana(), 5)
    np.testing.assert_allclose(kat.velocity, np.full(5, 1.19))
    np.testing.assert_allclose(kat.acceleration, np.full(5, 6.0))
    np.testing.assert_allclose(kat.jerk, np.full(5, 60.0))
    pan = MotionLimits.from_robot(robots.panda(), 7)
    np.testing.assert_allclose(pan.velocity, [2.175] * 4 + [2.61] * 3)
    np.testing.assert_allclose(pan.acceleration, [15, 7.5, 10, 12.5, 15, 20, 20])
    np.testing.assert_allclose(pan.jerk, [7500, 3750, 5000, 6250, 7500, 10000, 10000])


# ------------------------------------------------------------------------------------------
# divided differences
# ------------------------------------------------------------------------------------------


def test_divided_differences_uniform_grid_match_the_usual_formulas() -> None:
    rng = np.random.default_rng(0)
    h = 0.004
    t = 1.5 + h * np.arange(30)
    q = rng.normal(size=(30, 4))
    v, a, j = divided_differences(t, q, pad_rest=0)
    assert v.shape == (29, 4)
    assert a.shape == (28, 4)
    assert j.shape == (27, 4)
    np.testing.assert_allclose(v, (q[1:] - q[:-1]) / h, rtol=1e-10)
    np.testing.assert_allclose(a, (q[2:] - 2 * q[1:-1] + q[:-2]) / h**2, rtol=1e-8, atol=1e-6)
    np.testing.assert_allclose(
        j, (q[3:] - 3 * q[2:-1] + 3 * q[1:-2] - q[:-3]) / h**3, rtol=1e-7, atol=1e-3
    )


def test_divided_differences_non_uniform_grid_match_the_explicit_formula() -> None:
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.01, 0.05, 25))
    q = rng.normal(size=(25, 3))
    v, a, j = divided_differences(t, q, pad_rest=0)
    np.testing.assert_allclose(v, newton_explicit(t, q, 1), rtol=1e-10)
    np.testing.assert_allclose(a, newton_explicit(t, q, 2), rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(j, newton_explicit(t, q, 3), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("grid", ["uniform", "non-uniform"])
def test_divided_differences_of_a_cubic_are_its_exact_derivatives(grid: str) -> None:
    rng = np.random.default_rng(2)
    if grid == "uniform":
        t = 0.2 + 0.05 * np.arange(20)
    else:
        t = 0.2 + np.cumsum(rng.uniform(0.02, 0.08, 20))
    c = rng.normal(size=(4, 2))  # q = c0 + c1 t + c2 t^2 + c3 t^3 per joint
    q = c[0] + c[1] * t[:, None] + c[2] * t[:, None] ** 2 + c[3] * t[:, None] ** 3
    v, a, j = divided_differences(t, q, pad_rest=0)
    t0, t1 = t[:-1, None], t[1:, None]
    # velocity: the mean of q' over [t_k, t_k+1]
    v_exact = c[1] + c[2] * (t0 + t1) + c[3] * (t0**2 + t0 * t1 + t1**2)
    np.testing.assert_allclose(v, v_exact, rtol=1e-9, atol=1e-9)
    # acceleration: q'' at the mean of the three times (q'' is affine)
    tm = (t[:-2] + t[1:-1] + t[2:])[:, None] / 3.0
    np.testing.assert_allclose(a, 2 * c[2] + 6 * c[3] * tm, rtol=1e-7, atol=1e-7)
    # jerk: constant 6 c3
    np.testing.assert_allclose(j, np.broadcast_to(6 * c[3], j.shape), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("grid", ["uniform", "non-uniform"])
def test_divided_differences_of_a_smooth_function_lie_within_its_derivatives(grid: str) -> None:
    # Mean value theorem for divided differences: k! q[t_0..t_k] = q^(k)(xi), xi in [t_0, t_k].
    rng = np.random.default_rng(3)
    if grid == "uniform":
        t = np.linspace(0.0, 2.0, 60)
    else:
        t = np.sort(rng.uniform(0.0, 2.0, 60))
        t = t[np.concatenate([[True], np.diff(t) > 1e-3])]
    w = 2.5
    q = np.sin(w * t)[:, None]

    def d1(x: AnyFloat) -> AnyFloat:
        return np.asarray(w * np.cos(w * x), dtype=np.float64)

    def d2(x: AnyFloat) -> AnyFloat:
        return np.asarray(-(w**2) * np.sin(w * x), dtype=np.float64)

    def d3(x: AnyFloat) -> AnyFloat:
        return np.asarray(-(w**3) * np.cos(w * x), dtype=np.float64)

    derivs = [d1, d2, d3]
    for order, (d, f) in enumerate(
        zip(divided_differences(t, q, pad_rest=0), derivs, strict=True), start=1
    ):
        for k in range(d.shape[0]):
            x = np.linspace(t[k], t[k + order], 200)
            vals = f(x)
            tol = 1e-6 * w**order
            assert vals.min() - tol <= d[k, 0] <= vals.max() + tol, (order, k)


def test_divided_differences_pad_with_rest_at_the_neighbouring_spacing() -> None:
    rng = np.random.default_rng(4)
    t = np.concatenate([[0.0, 0.03], 0.03 + np.cumsum(rng.uniform(0.01, 0.02, 10)), [0.5]])
    q = rng.normal(size=(t.shape[0], 2))
    v, a, j = divided_differences(t, q)  # default pad_rest=3
    k = t.shape[0]
    assert v.shape == (k + 5, 2)
    assert a.shape == (k + 4, 2)
    assert j.shape == (k + 3, 2)
    tp, qp = pad_rest(t, q, 3)
    np.testing.assert_allclose(v, newton_explicit(tp, qp, 1), rtol=1e-10)
    np.testing.assert_allclose(a, newton_explicit(tp, qp, 2), rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(j, newton_explicit(tp, qp, 3), rtol=1e-6, atol=1e-6)
    # at rest in the padding; the first move out of rest, on the first step's spacing
    np.testing.assert_array_equal(v[:3], 0.0)
    np.testing.assert_array_equal(v[-3:], 0.0)
    np.testing.assert_allclose(a[2], 2 * ((q[1] - q[0]) / 0.03) / (2 * 0.03))
    np.testing.assert_allclose(
        a[-3], 2 * (0 - (q[-1] - q[-2]) / (0.5 - t[-2])) / (2 * (0.5 - t[-2]))
    )


def test_divided_differences_validate_their_input() -> None:
    with pytest.raises(ValueError, match="strictly increasing"):
        divided_differences([0.0, 0.1, 0.1], np.zeros((3, 1)))
    with pytest.raises(ValueError, match=r"q must have shape \(3, \*\)"):
        divided_differences([0.0, 0.1, 0.2], np.zeros((4, 1)))
    with pytest.raises(ValueError, match="t must have at least 2 rows"):
        divided_differences([0.0], np.zeros((1, 1)))


# ------------------------------------------------------------------------------------------
# motion peaks
# ------------------------------------------------------------------------------------------


def test_motion_peaks_are_the_largest_ratios_and_absolute_values() -> None:
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.01, 0.03, 40))
    q = np.cumsum(rng.normal(scale=0.01, size=(40, 3)), axis=0)
    lim = limits3()
    peaks = motion_peaks(t, q, lim)
    tp, qp = pad_rest(t, q, 3)
    bounds = (lim.velocity, lim.acceleration, lim.jerk)
    for order, bound in enumerate(bounds, start=1):
        d = np.abs(newton_explicit(tp, qp, order))
        name = ("velocity", "acceleration", "jerk")[order - 1]
        assert getattr(peaks, f"{name}_abs") == pytest.approx(d.max(), rel=1e-8)
        assert getattr(peaks, name) == pytest.approx((d / bound).max(), rel=1e-8)
    # the unlimited joint (velocity of joint 2, jerk of joint 1) is not part of the ratio
    d1 = np.abs(newton_explicit(tp, qp, 1))
    assert peaks.velocity == pytest.approx(max(d1[:, 0].max(), d1[:, 1].max() / 2.0), rel=1e-8)
    assert peaks.worst == max(peaks.velocity, peaks.acceleration, peaks.jerk)
    assert peaks.as_dict() == {
        "peak_velocity_ratio": peaks.velocity,
        "peak_velocity": peaks.velocity_abs,
        "peak_acceleration_ratio": peaks.acceleration,
        "peak_acceleration": peaks.acceleration_abs,
        "peak_jerk_ratio": peaks.jerk,
        "peak_jerk": peaks.jerk_abs,
    }


def test_motion_peaks_mask_counts_only_differences_of_kept_samples() -> None:
    rng = np.random.default_rng(6)
    n = 30
    t = 0.02 * np.arange(n)
    q = np.cumsum(rng.normal(scale=0.01, size=(n, 2)), axis=0)
    q[12:17] += 0.5  # a jump while an external force drives the arm
    lim = MotionLimits(np.array([1.0, 2.0]), np.array([5.0, 6.0]), np.array([50.0, 70.0]))
    for mask in (
        np.r_[np.ones(11, bool), np.zeros(7, bool), np.ones(n - 18, bool)],
        np.r_[np.zeros(3, bool), np.ones(n - 3, bool)],
        np.r_[np.ones(n - 2, bool), np.zeros(2, bool)],
    ):
        peaks = motion_peaks(t, q, lim, mask=mask)
        tp, qp = pad_rest(t, q, 3)
        mp = np.r_[np.repeat(mask[:1], 3), mask, np.repeat(mask[-1:], 3)]
        for order, (name, bound) in enumerate(
            [("velocity", lim.velocity), ("acceleration", lim.acceleration), ("jerk", lim.jerk)],
            start=1,
        ):
            d = np.abs(newton_explicit(tp, qp, order))
            keep = [bool(mp[s : s + order + 1].all()) for s in range(d.shape[0])]
            dk = d[keep]
            assert getattr(peaks, f"{name}_abs") == pytest.approx(dk.max(), rel=1e-8)
            assert getattr(peaks, name) == pytest.approx((dk / bound).max(), rel=1e-8)
    # the push (0.5 rad in one 0.02 s step: 25 rad/s) counts only where it is not masked
    assert motion_peaks(t, q, lim).velocity_abs > 20.0
    assert motion_peaks(t, q, lim, mask=np.arange(n) < 11).velocity_abs < 5.0
    # nothing counted: all zero
    nothing = motion_peaks(t, q, lim, mask=np.zeros(n, bool))
    assert nothing == MotionPeaks(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_motion_peaks_refuse_limits_for_another_number_of_joints() -> None:
    with pytest.raises(ValueError, match="limits are for 3 joints, q has 2"):
        motion_peaks([0.0, 0.1], np.zeros((2, 2)), limits3())


# ------------------------------------------------------------------------------------------
# reversals
# ------------------------------------------------------------------------------------------


def test_count_reversals_of_a_zig_zag_exactly_and_none_on_a_smooth_path() -> None:
    dt = 0.01
    vlim = np.array([1.0, 1.0])
    # joint 0: steps of +-0.005 rad (0.5 rad/s, above a quarter of 1 rad/s): 7 reversals
    zig = 0.005 * np.array([0, 1, 0, 1, 0, 1, 0, 1, 2, 3, 2], dtype=float)
    # joint 1: the same pattern at 0.2 rad/s: below the threshold
    small = zig * 0.4
    q = np.c_[zig, small]
    assert count_reversals(q, dt, vlim) == 7
    assert count_reversals(q[:, :1], dt, vlim[:1]) == 7
    assert count_reversals(q[:, 1:], dt, vlim[1:]) == 0
    # a lower threshold counts joint 1 too; a higher one neither
    assert count_reversals(q, dt, vlim, fraction=0.1) == 14
    assert count_reversals(q, dt, vlim, fraction=0.5) == 0  # 0.5 rad/s is not > 0.5
    assert count_reversals(q, dt, vlim, fraction=0.49) == 7
    # an unlimited joint is never counted
    assert count_reversals(q, dt, np.array([INF, 1.0]), fraction=0.1) == 7
    # per-step durations: slowing the steps 2 and 3 (both sides of 2 reversals) hides them
    h = np.full(10, dt)
    h[2:4] = 0.1
    assert count_reversals(q[:, :1], h, vlim[:1]) == 7 - 3
    # a fast but smooth path back and forth reverses through slow steps: none counted
    t = np.linspace(0.0, 4.0, 801)
    smooth = 0.5 * np.sin(np.pi * t)[:, None]
    assert count_reversals(smooth, t[1] - t[0], np.array([1.0])) == 0
    assert np.abs(np.diff(smooth[:, 0])).max() / (t[1] - t[0]) > 1.5  # it is fast
    # the same path with a zig-zag on top chatters at every sample
    jitter = smooth + 0.004 * (-1.0) ** np.arange(801)[:, None]
    assert count_reversals(jitter, t[1] - t[0], np.array([1.0])) > 400


# ------------------------------------------------------------------------------------------
# braking speed
# ------------------------------------------------------------------------------------------


# ------------------------------------------------------------------------------------------
# retime
# ------------------------------------------------------------------------------------------

LIM2 = MotionLimits(np.array([1.0, 1.5]), np.array([4.0, 6.0]), np.array([40.0, 60.0]))


def test_retime_stretches_a_fast_min_jerk_move_into_the_limits() -> None:
    dt = 0.01
    t = dt * np.arange(60)
    q = min_jerk(t, t[-1], np.array([0.9, -1.2]))
    q_before = q.copy()
    assert motion_peaks(t, q, LIM2).worst > 2.0  # it needs stretching
    h = retime(q, dt, LIM2)
    assert h.shape == (59,)
    assert np.all(h >= dt)
    assert h.max() > 1.5 * dt
    times = times_from_durations(h)
    np.testing.assert_allclose(times, np.r_[0.0, np.cumsum(h)])
    assert motion_peaks(times, q, LIM2).worst <= 1.0 + 1e-12
    np.testing.assert_array_equal(q, q_before)  # the path is kept
    # the durations vary smoothly: neighbours differ by a few percent at most
    assert np.abs(np.diff(h) / h[:-1]).max() < 0.25
    assert times_from_durations(h, 2.0)[0] == 2.0


def test_retime_that_does_not_converge_slows_the_whole_path_and_says_so(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Issue 35: a re-plan's retime raised after its rounds and the online run died with a
    # traceback. With one round allowed, the local stretches cannot converge: the whole path
    # is stretched alike instead, within the limits, with a warning that says by how much.
    import pbdkit.motion._limits as L

    monkeypatch.setattr(L, "_MAX_ROUNDS", 1)
    dt = 0.01
    t = dt * np.arange(60)
    q = min_jerk(t, t[-1], np.array([0.9, -1.2]))
    with pytest.warns(RetimeWarning, match=r"the whole path is slowed by \d"):
        h = retime(q, dt, LIM2)
    times = times_from_durations(h)
    assert motion_peaks(times, q, LIM2).worst <= 1.0 + 1e-12
    ratio = h / h[0]
    assert np.all(h >= dt) and ratio.max() > 1.0  # the one round's taper, then a uniform stretch


def test_retime_a_path_with_a_kink_and_leaves_far_away_steps_at_dt() -> None:
    dt = 0.01
    # at rest for 40 steps, then a ramp at 0.8 rad/s (within the velocity limit), a corner, and
    # back at 0.8 rad/s, then at rest for 40 steps
    ramp = 0.008 * np.arange(1, 21)
    q1 = np.r_[np.zeros(40), ramp, ramp[-2::-1], np.zeros(40)]
    q = np.c_[q1, -q1 / 2]
    h = retime(q, dt, LIM2)
    times = times_from_durations(h)
    assert motion_peaks(times, q, LIM2).worst <= 1.0 + 1e-12
    assert np.all(h >= dt)
    assert h[40:80].max() > 2 * dt  # the corner and the starts of the ramps are slowed
    # steps farther than the differences' span (3) plus the taper (10) from any motion: dt
    np.testing.assert_array_equal(h[: 40 - 14], dt)
    np.testing.assert_array_equal(h[-(40 - 14) :], dt)


def test_retime_leaves_a_slow_path_exactly_at_dt() -> None:
    dt = 0.02
    t = dt * np.arange(101)
    q = min_jerk(t, t[-1], np.array([0.3, 0.2]))
    assert motion_peaks(t, q, LIM2).worst < 0.5
    h = retime(q, dt, LIM2)
    np.testing.assert_array_equal(h, np.full(100, dt))
    # no limit at all: dt everywhere however fast
    fast = min_jerk(t, 0.1, np.array([5.0, 5.0]))
    np.testing.assert_array_equal(retime(fast, dt, MotionLimits.unlimited(2)), np.full(100, dt))


def _continued_check(h: Float, q: Float, v0: Float, limits: MotionLimits) -> MotionPeaks:
    """motion_peaks with the padding before the path continuing v0 backward (rest after)."""
    t = times_from_durations(h)
    h0, h1 = t[1] - t[0], t[-1] - t[-2]
    back = h0 * np.arange(3, 0, -1)
    tp = np.r_[t[0] - back, t, t[-1] + h1 * np.arange(1, 4)]
    qp = np.r_[q[0] - back[:, None] * v0, q, np.repeat(q[-1:], 3, axis=0)]
    return motion_peaks(tp, qp, limits, pad_rest=0)


@pytest.mark.parametrize("duration", [1.0, 0.3])
def test_retime_start_velocity_continues_a_moving_start(duration: float) -> None:
    dt = 0.01
    t = np.arange(0.0, duration + 1e-9, dt)
    s = t / duration
    # moving at v0 with zero acceleration at the start, at rest at the end
    v0 = np.array([0.5, -0.25])
    q = (duration * (s - s**3 + s**4 / 2))[:, None] * v0
    lim = MotionLimits(np.array([1.0, 1.0]), np.array([2.0, 2.0]), np.array([20.0, 20.0]))
    moving = retime(q, dt, lim, start_velocity=v0)
    rest = retime(q, dt, lim)
    assert np.all(moving >= dt)
    assert np.all(rest >= dt)
    # each passes its own check (a sudden start from rest is a large acceleration)
    assert _continued_check(moving, q, v0, lim).worst <= 1.0 + 1e-12
    assert motion_peaks(times_from_durations(rest), q, lim).worst <= 1.0 + 1e-12
    assert _continued_check(rest, q, v0, lim).worst > 1.5
    if duration == 1.0:
        assert motion_peaks(times_from_durations(moving), q, lim).worst > 1.5
        # the path continues the start velocity and is within the limits: nothing to stretch
        assert motion_peaks(t, q, lim, pad_rest=0).worst < 1.0
        np.testing.assert_array_equal(moving, np.full(t.shape[0] - 1, dt))
        assert rest[0] > 5 * dt


def test_retime_from_a_start_velocity_on_the_limit() -> None:
    """A measured velocity clipped to the limit (the online controller after a push) is on it
    to the last bit; the padding before the path moves at it whatever the stretch. It used to
    be one rounding error over the limit at every round, and retime gave up after 200."""
    lim = MotionLimits(np.array([0.7, 1.19]), np.array([4.0, 6.0]), np.array([40.0, 60.0]))
    rng = np.random.default_rng(0)
    v0 = lim.velocity * np.array([1.0, -1.0])
    for _ in range(40):  # one of these start postures and steps failed
        dt = rng.uniform(0.005, 0.03)
        q0 = rng.uniform(-2.0, 2.0, 2)
        t = np.arange(60) * dt
        s = t / t[-1]
        q = q0 + (t[-1] * (s - s**3 + s**4 / 2))[:, None] * v0
        h = retime(q, dt, lim, start_velocity=v0)
        assert _continued_check(h, q, v0, lim).worst <= 1.0 + 1e-8
    with pytest.raises(ValueError, match=r"start_velocity\[0\] is 0.707 rad/s, beyond"):
        retime(q, 0.01, lim, start_velocity=v0 * 1.01)


def test_retime_continues_a_motion_planned_on_the_limit() -> None:
    """Issue 35: `pbdkit evaluate --task coaster --trials 10 --seed 616 --perturb move --online`
    (at 8ed3178) died in a re-plan after the coaster moved: "retime: the path is not within
    the limits after 200 rounds (largest excess 1x)". Its input, saved where it raised: 646
    samples continuing the last command's velocity, an excess of 1 + 1e-12 where the padding
    before the path meets its first steps, whose stretch rounding lost at every round."""
    with np.load(DATA / "retime_start_on_the_limit.npz") as d:
        q, dt, v0 = d["q"], d["dt"], d["start_velocity"]
        lim = MotionLimits(d["velocity"], d["acceleration"], d["jerk"])
    h = retime(q, dt, lim, start_velocity=v0)
    assert np.all(h >= dt)
    assert _continued_check(h, q, v0, lim).worst <= 1.0 + 1e-9
    assert h.sum() / dt.sum() < 1.03  # measured: 1.0235 (the steps that needed it before)


def test_retime_validates_its_input() -> None:
    q = np.zeros((5, 2))
    with pytest.raises(ValueError, match="dt must be a positive number"):
        retime(q, 0.0, LIM2)
    with pytest.raises(ValueError, match="dt must be a positive number"):
        retime(q, math.nan, LIM2)
    with pytest.raises(ValueError, match=r"start_velocity must have shape \(2,\)"):
        retime(q, 0.01, LIM2, start_velocity=[0.1])
    with pytest.raises(ValueError, match="q must have at least 2 rows"):
        retime(np.zeros((1, 2)), 0.01, LIM2)
    with pytest.raises(ValueError, match=r"dt must be a number or have shape \(4,\)"):
        retime(q, [0.01, 0.02], LIM2)
    with pytest.raises(ValueError, match="dt must be a positive number"):
        retime(q, [0.01, 0.02, -1.0, 0.01], LIM2)


# ------------------------------------------------------------------------------------------
# StreamMonitor
# ------------------------------------------------------------------------------------------


def _stream(seed: int, k: int = 80) -> Float:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, k)
    q = 0.3 * np.sin(2 * np.pi * t[:, None] * np.array([1.0, 2.0, 0.5]) + 0.4)
    return np.asarray(q + rng.normal(scale=0.002, size=q.shape), dtype=np.float64)


def _assert_same_peaks(a: MotionPeaks, b: MotionPeaks) -> None:
    for name in ("velocity", "acceleration", "jerk"):
        assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-9)
        assert getattr(a, f"{name}_abs") == pytest.approx(getattr(b, f"{name}_abs"), rel=1e-9)


def test_stream_monitor_equals_motion_peaks_of_the_same_stream() -> None:
    period = 0.002
    q = _stream(7)
    lim = limits3()
    mon = StreamMonitor(lim, period)
    for row in q:
        mon.update(row)
    assert mon.count == q.shape[0]
    t = period * np.arange(q.shape[0])
    # before finish: the stream starts at rest, and has not stopped yet
    tb = np.r_[-period * np.arange(3, 0, -1), t]
    qb = np.r_[np.repeat(q[:1], 3, axis=0), q]
    _assert_same_peaks(mon.peaks(), motion_peaks(tb, qb, lim, pad_rest=0))
    done = mon.finish()
    assert mon.count == q.shape[0] + 3
    _assert_same_peaks(done, motion_peaks(t, q, lim))
    _assert_same_peaks(mon.peaks(), done)


def test_stream_monitor_uncounted_setpoints_equal_the_mask() -> None:
    period = 0.004
    q = _stream(8, 60)
    q[20:26] += 0.2  # pushed
    lim = limits3()
    t = period * np.arange(q.shape[0])
    for mask in (
        np.r_[np.ones(19, bool), np.zeros(8, bool), np.ones(33, bool)],
        np.r_[np.zeros(5, bool), np.ones(55, bool)],
        np.r_[np.ones(56, bool), np.zeros(4, bool)],
    ):
        mon = StreamMonitor(lim, period)
        for row, ok in zip(q, mask, strict=True):
            mon.update(row, counted=bool(ok))
        _assert_same_peaks(mon.finish(), motion_peaks(t, q, lim, mask=mask))


def test_stream_monitor_validates_the_period_and_starts_empty() -> None:
    for bad in (0.0, -0.001, math.inf, math.nan):
        with pytest.raises(ValueError, match="period must be a positive number"):
            StreamMonitor(limits3(), bad)
    mon = StreamMonitor(limits3(), 0.001)
    assert mon.finish() == MotionPeaks(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert mon.count == 0
