"""A continuous jerk-limited motion (:class:`Motion`): Ruckig trajectories and quintics one after
another, sampled at any time, sent between processes as arrays; and the hardest stop from a
state (:func:`brake`). :mod:`pbdkit.motion._otg` builds them.

Ruckig is imported when one of them is first planned.
"""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._limits import MotionLimits

__all__ = ["Motion", "brake", "ruckig_recipe"]

Float = NDArray[np.float64]


def _ruckig() -> Any:
    import ruckig

    return ruckig


class Motion:
    """A continuous jerk-limited motion: Ruckig trajectories one after another, each starting in
    the state the previous one ended in, from a start state at ``t0`` (position, velocity and
    acceleration continuous, jerk within the limits it was planned with).

    Samples of it at any times pass the divided-difference check of :mod:`pbdkit.motion._limits`
    against those limits (a divided difference of order k is a weighted average of the k-th
    derivative); before ``t0`` it is the start state, after :attr:`end` it holds the last
    position (at rest when it was planned to end so).

    A motion pickles as arrays (the online controller's planner process sends it): each Ruckig
    segment as the input it was planned from, planned again where it is first sampled (Ruckig
    is deterministic: the same trajectory), each quintic as its coefficients.

    Attributes
    ----------
    t0, end : float
        Start and end times (s).
    """

    def __init__(
        self,
        t0: float,
        start: tuple[Float, Float, Float],
        limits: MotionLimits | None = None,
    ) -> None:
        self.t0 = float(t0)
        self.end = self.t0
        #: Built by :func:`follow`: when the motion reaches each of the samples it follows
        #: (their own times, later where the limits kept it behind).
        self.sample_times: Float = np.array([self.t0])
        p, v, a = (np.array(x, dtype=np.float64) for x in start)
        self._start = (p, v, a)
        self._limits = limits  # what its Ruckig segments were planned within
        self._starts: list[float] = []
        self._durations: list[float] = []
        # A segment's trajectory (a _Quintic or a ruckig.Trajectory), None until it is planned
        # again from its recipe (after unpickling).
        self._segments: list[Any] = []
        # A Ruckig segment's recipe: its input (current and target position, velocity,
        # acceleration: (6, n)), its minimum duration (NaN: none), its control interface (0
        # position, 1 velocity); a quintic's: its coefficients (6, n), NaN, -1.
        self._recipes: list[tuple[Float, float, int]] | tuple[Float, Float, NDArray[np.int8]] = []

    def append(self, trajectory: Any, recipe: tuple[Float, float, int] | None = None) -> None:
        """The next segment (a ``ruckig.Trajectory`` from the state at :attr:`end`, with the
        ``recipe`` it was planned from: :func:`ruckig_recipe`; or a quintic)."""
        duration = float(trajectory.duration)
        if isinstance(trajectory, _Quintic):
            recipe = (trajectory.c, math.nan, -1)
        elif recipe is None:
            raise ValueError("a Ruckig segment needs the recipe it was planned from")
        if not isinstance(self._recipes, list):
            raise ValueError("an unpickled motion cannot be extended")
        self._starts.append(self.end)
        self._durations.append(duration)
        self._segments.append(trajectory)
        self._recipes.append(recipe)
        self.end += duration

    def _segment(self, k: int) -> Any:
        traj = self._segments[k]
        if traj is None:
            traj = self._segments[k] = self._plan_again(k)
        return traj

    def _plan_again(self, k: int) -> Any:
        recipes = self._recipes
        if isinstance(recipes, list):
            rows, min_duration, interface = recipes[k]
        else:  # unpickled: arrays
            rows, min_duration, interface = (
                recipes[0][k],
                float(recipes[1][k]),
                int(recipes[2][k]),
            )
        duration = self._durations[k]
        if interface < 0:
            return _Quintic(None, None, duration, rows)
        assert self._limits is not None
        lim = self._limits
        traj = _ruckig_plan(rows, min_duration, interface, lim.velocity, lim.acceleration, lim.jerk)
        if float(traj.duration) != duration:
            raise RuntimeError("a motion's segment planned again differs from the original")
        return traj

    def _packed(self) -> tuple[Float, Float, NDArray[np.int8]]:
        recipes = self._recipes
        if not isinstance(recipes, list):
            return recipes
        n = self._start[0].shape[0]
        return (
            np.array([r[0] for r in recipes]).reshape(len(recipes), 6, n),
            np.array([r[1] for r in recipes], dtype=np.float64),
            np.array([r[2] for r in recipes], dtype=np.int8),
        )

    def __getstate__(self) -> dict[str, Any]:
        rows, min_durations, interfaces = self._packed()
        return {
            "t0": self.t0,
            "end": self.end,
            "sample_times": self.sample_times,
            "start": np.array(self._start),
            "limits": None
            if self._limits is None
            else np.array([self._limits.velocity, self._limits.acceleration, self._limits.jerk]),
            "starts": np.array(self._starts, dtype=np.float64),
            "durations": np.array(self._durations, dtype=np.float64),
            "rows": rows,
            "min_durations": min_durations,
            "interfaces": interfaces,
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.t0, self.end = state["t0"], state["end"]
        self.sample_times = state["sample_times"]
        p, v, a = (np.array(x) for x in state["start"])
        self._start = (p, v, a)
        lim = state["limits"]
        self._limits = None if lim is None else MotionLimits._derived(lim[0], lim[1], lim[2])
        self._starts = state["starts"].tolist()
        self._durations = state["durations"].tolist()
        self._recipes = (state["rows"], state["min_durations"], state["interfaces"])
        self._segments = [None] * len(self._starts)

    def at(self, t: float) -> tuple[Float, Float, Float]:
        """Position, velocity and acceleration at time ``t`` (s)."""
        if t <= self.t0 or not self._segments:
            p, v, a = self._start
            return p.copy(), v.copy(), a.copy()
        k = max(0, bisect.bisect_right(self._starts, t) - 1)
        duration, traj = self._durations[k], self._segment(k)
        local = t - self._starts[k]
        if local >= duration:
            p, v, a = traj.at_time(duration)
            # Beyond the last segment: at rest where it ended (or moving on at its velocity).
            pv, vv = np.array(p), np.array(v)
            return pv + vv * (local - duration), vv, np.zeros_like(pv)
        p, v, a = traj.at_time(local)  # a quintic's rows, or Ruckig's lists
        return np.array(p), np.array(v), np.array(a)

    def at_rest_after(self, t: float) -> bool:
        """Whether the motion is at rest from time ``t`` on (its last segment ended by then,
        at rest within rounding; or it has none)."""
        if not self._segments:
            return not (np.any(self._start[1]) or np.any(self._start[2]))
        if t < self.end:
            return False
        _, v, a = self.at(self.end)  # Ruckig ends within rounding of rest
        return float(np.abs(v).max()) <= 1e-9 and float(np.abs(a).max()) <= 1e-6

    def out_of(self, lower: Float, upper: Float) -> list[tuple[float, float]]:
        """The segments (start and end times) that pass a joint's ``lower`` or ``upper``
        position limit: Ruckig's at their extrema, quintics at 257 points each (those a bound
        on their whole range, |c_k| h^k summed, keeps within the limits skipped: the same
        answer)."""
        out: list[tuple[float, float]] = []
        recipes = self._recipes
        if isinstance(recipes, list):
            kinds = np.fromiter((r[2] for r in recipes), dtype=np.int8, count=len(recipes))
        else:
            kinds = recipes[2]
        quintics = np.flatnonzero(kinds < 0)
        for k in np.flatnonzero(kinds >= 0).tolist():
            ext = self._segment(k).position_extrema
            if any(e.min < lower[j] or e.max > upper[j] for j, e in enumerate(ext)):
                out.append((self._starts[k], self._starts[k] + self._durations[k]))
        if quintics.size:
            if isinstance(recipes, list):
                c = np.stack([recipes[k][0] for k in quintics.tolist()], axis=1)  # (6, m, n)
            else:
                c = np.swapaxes(recipes[0][quintics], 0, 1)
            h = np.array(self._durations)[quintics][:, None]
            reach = np.zeros_like(c[0])
            power = np.ones_like(h)
            for k in range(1, 6):
                power = power * h
                reach += np.abs(c[k]) * power
            near = ((c[0] - reach < lower) | (c[0] + reach > upper)).any(axis=1)
            if near.any():
                cn = c[:, near]
                s_ = np.linspace(0.0, 1.0, 257)[:, None, None] * h[near][None]
                pos = _quintic_positions(cn, s_)
                bad = quintics[near][((pos < lower) | (pos > upper)).any(axis=(0, 2))]
                out += [
                    (self._starts[k], self._starts[k] + self._durations[k]) for k in bad.tolist()
                ]
        return sorted(out)

    def shifted(self, offset: float) -> Motion:
        """The same motion ``offset`` s later (sharing its segments)."""
        out = Motion(self.t0 + offset, self._start, self._limits)
        out.end = self.end + offset
        out.sample_times = self.sample_times + offset
        out._starts = [s + offset for s in self._starts]
        out._durations = self._durations
        out._segments = self._segments
        out._recipes = self._recipes
        return out

    def sample(self, times: Float) -> tuple[Float, Float, Float]:
        """:meth:`at` for every time, as arrays (len(times), n)."""
        rows = [self.at(float(t)) for t in times]
        return (
            np.array([r[0] for r in rows], dtype=np.float64),
            np.array([r[1] for r in rows], dtype=np.float64),
            np.array([r[2] for r in rows], dtype=np.float64),
        )

    def every(self, period: float, n_steps: int | None = None) -> tuple[Float, Float, Float]:
        """:meth:`sample` every ``period`` from :attr:`t0`: ``n_steps`` rows, or (default) until
        the first at or after :attr:`end`."""
        total = math.ceil((self.end - self.t0) / period - 1e-9) + 1 if n_steps is None else n_steps
        return self.sample(self.t0 + period * np.arange(total, dtype=np.float64))


#: The rows of a Ruckig segment's recipe: the ``ruckig.InputParameter`` fields it was planned
#: from (with its limits, minimum duration and control interface).
_RECIPE_ROWS = (
    "current_position",
    "current_velocity",
    "current_acceleration",
    "target_position",
    "target_velocity",
    "target_acceleration",
)


def _ruckig_plan(
    rows: Float,
    min_duration: float,
    interface: int,
    velocity: Float,
    acceleration: Float,
    jerk: Float,
) -> Any:
    """The Ruckig trajectory of a recipe (:meth:`Motion.append`), within these limits (a
    :class:`MotionLimits`' arrays, or a slice of them)."""
    rk = _ruckig()
    n = rows.shape[1]
    inp = rk.InputParameter(n)
    inp.max_velocity = velocity.tolist()
    inp.max_acceleration = acceleration.tolist()
    inp.max_jerk = jerk.tolist()
    if interface == 1:
        inp.control_interface = rk.ControlInterface.Velocity
    for name, row in zip(_RECIPE_ROWS, rows.tolist(), strict=True):
        setattr(inp, name, row)
    inp.minimum_duration = None if math.isnan(min_duration) else min_duration
    traj = rk.Trajectory(n)
    result = rk.Ruckig(n).calculate(inp, traj)
    if result not in (rk.Result.Working, rk.Result.Finished):
        raise RuntimeError(f"Ruckig could not plan the segment: {result}")
    return traj


def ruckig_recipe(inp: Any) -> tuple[Float, float, int]:
    """What :meth:`Motion.append` keeps of the ``ruckig.InputParameter`` a segment was planned
    from (its limits are the motion's)."""
    rows = np.array([getattr(inp, name) for name in _RECIPE_ROWS], dtype=np.float64)
    md = inp.minimum_duration
    interface = 1 if inp.control_interface == _ruckig().ControlInterface.Velocity else 0
    return rows, math.nan if md is None else float(md), interface


def brake(t0: float, state: tuple[Float, Float, Float], limits: MotionLimits) -> Motion:
    """The motion from ``state`` (position, velocity, acceleration at ``t0``) to rest as fast
    as ``limits`` allow (Ruckig's velocity interface, the joints stopping together; a state
    beyond the limits is first brought within them, as Ruckig does)."""
    p, v, a = (np.asarray(x, dtype=np.float64) for x in state)
    motion = Motion(t0, (p, v, a), limits)
    if not (np.any(v) or np.any(a)):
        return motion
    zeros = np.zeros(p.shape[0])
    rows = np.array([p, v, a, p, zeros, zeros])
    stop = _ruckig_plan(rows, math.nan, 1, limits.velocity, limits.acceleration, limits.jerk)
    motion.append(stop, (rows, math.nan, 1))
    return motion


class _Quintic:
    """A motion segment from one state (position, velocity, acceleration) to another in a
    given time: the quintic polynomial through both (``duration``, ``at_time``)."""

    def __init__(
        self,
        start: tuple[Float, Float, Float] | None,
        end: tuple[Float, Float, Float] | None,
        duration: float,
        coefficients: Float | None = None,
    ) -> None:
        if coefficients is None:
            assert start is not None and end is not None
            coefficients = _quintic_coefficients(start, end, np.full(1, duration))
        self.c = coefficients  # (6, n)
        self.duration = duration
        self._end = end

    @property
    def end(self) -> tuple[Float, Float, Float]:
        """The state it ends in: the one it was built to end in, else (planned again from its
        coefficients) its own at its duration."""
        if self._end is None:
            p, v, a = self.at_time(self.duration)
            self._end = (p, v, a)
        return self._end

    def at_time(self, t: float) -> Float:
        """Position, velocity and acceleration at ``t``: rows of a (3, n) array (one product
        of the powers of t with the coefficients)."""
        t2 = t * t
        t3 = t2 * t
        powers = np.array(
            [
                [1.0, t, t2, t3, t3 * t, t3 * t2],
                [0.0, 1.0, 2.0 * t, 3.0 * t2, 4.0 * t3, 5.0 * t3 * t],
                [0.0, 0.0, 2.0, 6.0 * t, 12.0 * t2, 20.0 * t3],
            ]
        )
        return np.asarray(powers.dot(self.c), dtype=np.float64)

    def end_state(self) -> tuple[list[float], list[float], list[float]]:
        """Exactly the state it was built to end in."""
        p, v, a = self.end
        return list(p.tolist()), list(v.tolist()), list(a.tolist())


def _quintic_coefficients(
    start: tuple[Float, Float, Float], end: tuple[Float, Float, Float], h: Float
) -> Float:
    """Coefficients c_0..c_5 (leading axis) of the quintics from ``start`` to ``end`` (each a
    (position, velocity, acceleration)) in times ``h`` (broadcast against them)."""
    p0, v0, a0 = start
    p1, v1, a1 = end
    d = p1 - (p0 + v0 * h + 0.5 * a0 * h * h)
    e = v1 - (v0 + a0 * h)
    f = a1 - a0
    return np.stack(
        [
            p0 + 0.0 * h,
            v0 + 0.0 * h,
            0.5 * a0 + 0.0 * h,
            (10.0 * d - 4.0 * e * h + 0.5 * f * h * h) / h**3,
            (-15.0 * d + 7.0 * e * h - f * h * h) / h**4,
            (6.0 * d - 3.0 * e * h + 0.5 * f * h * h) / h**5,
        ]
    )


def _quintic_positions(c: Float, s: Float) -> Float:
    """Positions of quintics (coefficients ``c``, leading axis c_0..c_5) at times ``s`` from
    their starts (broadcast against ``c[k]``; Horner's scheme)."""
    return np.asarray(((((c[5] * s + c[4]) * s + c[3]) * s + c[2]) * s + c[1]) * s + c[0])
