"""Motion limits of an arm: velocity, acceleration and jerk, how a trajectory is checked against
them, and how a sampled path is timed to respect them.

A real arm's drives check the stream of setpoints they are sent: a Franka Panda stops on a
single setpoint whose acceleration or jerk (from the last ones, at 1 kHz) exceeds its published
limits. pbdkit measures a trajectory the same way, on its own samples, and times its
reproductions so that they pass.

Divided differences
-------------------
For samples q_0 .. q_{K-1} at times t_0 < ... < t_{K-1} (uniform or not), the derivatives are
Newton's divided differences times k!: with q[t_a, ..., t_b] the divided difference,

    v = q[t_k, t_{k+1}],   a = 2 q[t_k, t_{k+1}, t_{k+2}],   j = 6 q[t_k, ..., t_{k+3}].

On a uniform grid these are the usual (q_{k+1} - q_k) / h, (q_{k+2} - 2 q_{k+1} + q_k) / h^2 and
(q_{k+3} - 3 q_{k+2} + 3 q_{k+1} - q_k) / h^3. A divided difference is a weighted average of
the derivative over its interval (Peano kernel, positive weights): samples of a continuous
trajectory that respects the limits always pass this check, at any sampling rate.

"Starting and ending at rest" is checked by padding: ``pad_rest`` copies of the first sample
before it and of the last after it, spaced like the neighbouring samples. A trajectory that
starts moving, or with a sudden acceleration, then shows it as a large divided difference.

Reversals
---------
The limit cycle that a real arm would chatter on: a joint reverses direction between two
consecutive steps that are each faster than a quarter of its velocity limit
(:func:`count_reversals`).

Timing a path (:func:`retime`)
------------------------------
A reproduction (paper Table II) is a sequence of postures, one per step of the skill's time
grid, played at the demonstrations' pace: dt = duration / (T - 1) per step. Where that pace
would need more speed, acceleration or jerk than the arm has, the steps there are given more
time; the postures (the path) are kept exactly, so every constraint is met where it was and the
gripper events move with their steps. Scaling the time of a neighbourhood by f divides
velocities by f, accelerations by f^2 and jerks by f^3; so at every sample where a limit is
exceeded by a ratio r (velocity), r_a (acceleration), r_j (jerk), the segments around it are
stretched by max(r, sqrt(r_a), cbrt(r_j)) to the power 1.05 (plus 0.005 per round: neighbouring
stretches interact, and the iteration should end in a few rounds: 2-3 on the teacher's skills,
22 on benchmarks/bench_skill.py's), tapered with a Gaussian window so that the durations vary
smoothly (a sudden change of the duration of the steps is itself an acceleration): 10 steps
either side, or on a grid finer than 5 ms, 10 blocks of 10 ms of the path as timed so far (the
way back to the demonstrations' pace takes a time, not a number of steps), weighting the
logarithm of the stretch (a step slowed 100 times does not slow its neighbours 50 times). A
step over a limit is stretched by at least 1e-6 of its duration (an excess of a few ulps would
otherwise ask for a stretch that rounding loses). This repeats until every divided difference,
padded with rest, is within the limits. A step is never given less than dt: the skill keeps the
demonstrations' pace wherever the arm can follow it.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._limit_values import LIMIT_RANGES, UNITS, check_limit_range, names_of, positive_bounds
from .._validation import check_array, short

__all__ = [
    "DEFAULT_ACCELERATION_TIME",
    "DEFAULT_JERK_TIME",
    "LIMIT_RANGES",
    "LIMIT_SAFETY",
    "DefaultLimitsWarning",
    "MotionLimits",
    "MotionPeaks",
    "RetimeWarning",
    "StreamMonitor",
    "count_reversals",
    "defaults_where_declared",
    "divided_differences",
    "last_differences",
    "motion_peaks",
    "positive_bounds",
    "retime",
    "times_from_durations",
    "with_defaults",
]

Float = NDArray[np.float64]
#: Reproductions and command streams are planned at this fraction of the declared limits, so
#: that floating-point rounding and interpolation never put a measured value above a limit.
LIMIT_SAFETY = 0.995
#: Rest samples added at each end by the checks (a divided difference of order 3 spans 4).
PAD_REST = 3
# retime: overshoot of the stretch factor and the half width (steps) of its taper.
_STRETCH_OVERSHOOT = 1.05
_OVERSHOOT_GROWTH = 0.005
_TAPER_HALF_WIDTH = 10
_TAPER_SIGMA = 4.0
# retime: on a grid finer than this (s, the median step), the taper spans blocks of this
# duration of the path as timed so far, not steps (:func:`_tapered_in_time`). The speed a
# slowed neighbourhood must come back to takes a time to reach within the limits, not a number
# of steps: a taper of 10 steps of 0.3 ms (a skill of 60000 steps) ended 3 ms after its peak,
# the ramp back to the pace was over the limits right after it, and the stretch crept along
# the path by a taper a round, never done in 200 rounds (issue 36: a RuntimeError, or the
# path slowed 160 times as a whole).
_TAPER_BLOCK_SECONDS = 0.01
# retime: grids (median step, s) finer than this are tapered in time; coarser ones over steps
# (the zoo's 6 ms and the teacher's 17 ms keep their timings to the bit).
_FINE_GRID_SECONDS = 0.005
_MAX_ROUNDS = 200
# retime: a step over a limit is stretched by at least this fraction of its duration. An
# excess of a few ulps (a re-plan that continues a motion planned on the limit: 1 + 1e-12)
# asked for a stretch that rounding lost, round after round, and retime gave up (issue 35,
# `tests/data/retime_start_on_the_limit.npz`: 108 rounds with it, 2.35 % longer in all).
_MIN_STRETCH = 1e-6

LimitSpec = float | npt.ArrayLike | Literal["robot"] | None


class RobotLimits(Protocol):
    """What :meth:`MotionLimits.from_robot` reads from a robot: the three limits a
    :class:`pbdkit.robots.KinematicModel` declares, shape (n,) each, ``inf`` where there is
    none."""

    @property
    def velocity_limit(self) -> npt.ArrayLike: ...

    @property
    def acceleration_limit(self) -> npt.ArrayLike: ...

    @property
    def jerk_limit(self) -> npt.ArrayLike: ...


@dataclass(frozen=True)
class MotionLimits:
    """Velocity, acceleration and jerk limits of n joints (inf: that joint is not limited).

    Attributes
    ----------
    velocity : ndarray, shape (n,)
        rad/s (m/s for prismatic joints).
    acceleration : ndarray, shape (n,)
        rad/s^2.
    jerk : ndarray, shape (n,)
        rad/s^3.

    Each finite limit must be within its kind's :data:`LIMIT_RANGES` (ValueError naming the
    kind and the joint otherwise).
    """

    velocity: Float
    acceleration: Float
    jerk: Float

    def __post_init__(self) -> None:
        self._check(in_range=True)

    @classmethod
    def _derived(cls, velocity: Float, acceleration: Float, jerk: Float) -> MotionLimits:
        """Limits computed by pbdkit from limits already checked (a safety margin, the defaults
        of :func:`with_defaults`) or from a trajectory's own speeds: > 0, not held to
        :data:`LIMIT_RANGES` (a margin of 0.995 takes a limit on the range's edge past it)."""
        out = object.__new__(cls)
        for name, value in (("velocity", velocity), ("acceleration", acceleration), ("jerk", jerk)):
            object.__setattr__(out, name, value)
        out._check(in_range=False)
        return out

    def _check(self, *, in_range: bool) -> None:
        """Validate and freeze the three arrays (in place: the dataclass is frozen)."""
        n = None
        for name in ("velocity", "acceleration", "jerk"):
            # A copy: the caller's array (e.g. a robot's attribute) stays its own and writable.
            arr = np.array(check_array(getattr(self, name), name, ndim=1, finite=False))
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise ValueError(
                    f"{name} must have shape ({n},) like velocity, got shape ({arr.shape[0]},)"
                )
            bad = np.flatnonzero(~(arr > 0))
            if bad.size:
                i = int(bad[0])
                raise ValueError(f"{name}[{i}] must be > 0 (inf: no limit), got {short(arr[i])}")
            if in_range:
                check_limit_range(arr, name, name)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @property
    def n_joints(self) -> int:
        """n."""
        return int(self.velocity.shape[0])

    @property
    def any(self) -> bool:
        """True if some joint has a finite limit of some kind."""
        return bool(
            np.isfinite(self.velocity).any()
            or np.isfinite(self.acceleration).any()
            or np.isfinite(self.jerk).any()
        )

    def scaled(self, factor: float) -> MotionLimits:
        """The same limits times ``factor`` (e.g. :data:`LIMIT_SAFETY`)."""
        return MotionLimits._derived(
            self.velocity * factor, self.acceleration * factor, self.jerk * factor
        )

    def as_dict(self) -> dict[str, list[float | None]]:
        """JSON-ready: per kind, one value per joint (None: no limit)."""
        return {
            k: [float(v) if np.isfinite(v) else None for v in getattr(self, k)]
            for k in ("velocity", "acceleration", "jerk")
        }

    @classmethod
    def unlimited(cls, n: int) -> MotionLimits:
        """No limit on any of n joints."""
        inf = np.full(n, np.inf)
        return cls(inf, inf.copy(), inf.copy())

    @classmethod
    def from_robot(
        cls,
        robot: RobotLimits,
        n: int,
        *,
        velocity: LimitSpec = "robot",
        acceleration: LimitSpec = "robot",
        jerk: LimitSpec = "robot",
    ) -> MotionLimits:
        """The limits of a robot, each kind overridable.

        Parameters
        ----------
        robot : KinematicModel
            Its ``velocity_limit``, ``acceleration_limit`` and ``jerk_limit`` (shape (n,) each,
            declared by every :class:`pbdkit.robots.KinematicModel`) are used where a kind is
            ``"robot"``. A value of 0, negative, NaN or inf in them means the joint is not
            limited (URDF writes 0 for that).
        n : int
            Number of joints.
        velocity, acceleration, jerk : "robot", float, array-like of shape (n,), or None
            ``"robot"``: the robot's; a number (every joint) or one value per joint, > 0 (inf:
            not limited); None: not limited.

        Returns
        -------
        limits : MotionLimits
        """
        specs = {"velocity": velocity, "acceleration": acceleration, "jerk": jerk}
        units = UNITS
        declared = {
            "velocity": robot.velocity_limit,
            "acceleration": robot.acceleration_limit,
            "jerk": robot.jerk_limit,
        }
        out: dict[str, Float] = {}
        for kind, spec in specs.items():
            name = f"{kind}_limit"
            if spec is None:
                out[kind] = np.full(n, np.inf)
            elif isinstance(spec, str):
                if spec != "robot":
                    raise ValueError(
                        f"{name} must be 'robot', a number or an array of shape ({n},) in "
                        f"{units[kind]}, or None, got {short(spec)}"
                    )
                arr = check_array(declared[kind], f"robot.{name}", shape=(n,), finite=False)
                out[kind] = np.where(np.isfinite(arr) & (arr > 0), arr, np.inf)
                check_limit_range(out[kind], kind, f"robot.{name}", names_of(robot))
            else:
                out[kind] = positive_bounds(spec, n, name, units[kind])
                check_limit_range(out[kind], kind, name)
        return cls(out["velocity"], out["acceleration"], out["jerk"])


#: A robot that declares velocity limits but no acceleration or jerk limits (a URDF has no
#: field for them) moves within a = v / DEFAULT_ACCELERATION_TIME and j = a / DEFAULT_JERK_TIME
#: per joint: to full speed in 0.25 s, to full acceleration in 0.1 s (:func:`with_defaults`).
DEFAULT_ACCELERATION_TIME = 0.25
DEFAULT_JERK_TIME = 0.1


class DefaultLimitsWarning(UserWarning):
    """A robot without acceleration or jerk limits moves within defaults derived from its
    velocity limits (:func:`with_defaults`)."""


def with_defaults(
    limits: MotionLimits, names: Sequence[str] | None = None, *, warn: bool = True
) -> MotionLimits:
    """``limits`` with the acceleration and jerk limits a joint lacks derived from its velocity
    limit (:data:`DEFAULT_ACCELERATION_TIME`, :data:`DEFAULT_JERK_TIME`), and a
    :class:`DefaultLimitsWarning` that names the joints and says how to give real ones.

    A joint without a velocity limit keeps what it has (nothing to derive from)."""
    v, a, j = limits.velocity, limits.acceleration, limits.jerk
    known = np.isfinite(v)
    need_a = known & ~np.isfinite(a)
    a_new = np.where(need_a, v / DEFAULT_ACCELERATION_TIME, a)
    need_j = np.isfinite(a_new) & ~np.isfinite(j)
    j_new = np.where(need_j, a_new / DEFAULT_JERK_TIME, j)
    if not (need_a.any() or need_j.any()):
        return limits
    if warn:
        idx = np.flatnonzero(need_a | need_j).tolist()
        label = [names[k] if names is not None else f"joint {k}" for k in idx]
        shown = ", ".join(label[:3]) + (f" and {len(label) - 3} more" if len(label) > 3 else "")
        i = idx[0]
        warnings.warn(
            f"{shown} have no acceleration or jerk limit (a URDF has no field for them): "
            f"assumed a = v / {DEFAULT_ACCELERATION_TIME:g} s and j = a / {DEFAULT_JERK_TIME:g} s "
            f"per joint ({label[0]}: {a_new[i]:.3g} rad/s^2, {j_new[i]:.3g} rad/s^3). Give the "
            "arm's own with Robot.from_urdf(..., joint_limits='joint_limits.yaml') (MoveIt's "
            "file) or acceleration_limit= and jerk_limit=",
            DefaultLimitsWarning,
            stacklevel=3,
        )
    return MotionLimits._derived(v, a_new, j_new)


def defaults_where_declared(
    limits: MotionLimits,
    names: Sequence[str],
    velocity: LimitSpec,
    acceleration: LimitSpec,
    jerk: LimitSpec,
) -> MotionLimits:
    """A robot's limits (:meth:`MotionLimits.from_robot` with these specs), its missing
    acceleration and jerk limits derived from its velocity limits (:func:`with_defaults`, with
    a warning) where they are the robot's ("robot"); a robot that declares acceleration or
    jerk limits but no velocity limits is refused (no timing can start from it)."""

    def robot_spec(spec: LimitSpec) -> bool:
        return isinstance(spec, str) and spec == "robot"

    if robot_spec(velocity):
        bare = ~np.isfinite(limits.velocity) & (
            np.isfinite(limits.acceleration) | np.isfinite(limits.jerk)
        )
        if bare.any():
            name = names[int(np.argmax(bare))]
            raise ValueError(
                f"joint {short(name)} has acceleration or jerk limits but no velocity limit: "
                "timed motion needs one (give it in the URDF's <limit velocity=...> or "
                "velocity_limit=), or pass acceleration_limit=None and jerk_limit=None for "
                "the paper's loop"
            )
    if not (robot_spec(acceleration) or robot_spec(jerk)):
        return limits
    filled = with_defaults(limits, names)
    return MotionLimits._derived(
        limits.velocity,
        filled.acceleration if robot_spec(acceleration) else limits.acceleration,
        filled.jerk if robot_spec(jerk) else limits.jerk,
    )


# ----------------------------------------------------------------------------- checks
def _padded(t: Float, q: Float, pad: int, v0: Float | None = None) -> tuple[Float, Float]:
    """``pad`` samples before the first (at rest, or moving at ``v0``) and after the last (at
    rest), spaced like the end steps."""
    if pad <= 0:
        return t, q
    h0 = t[1] - t[0]
    h1 = t[-1] - t[-2]
    before = h0 * np.arange(pad, 0, -1)
    tp = np.concatenate([t[0] - before, t, t[-1] + h1 * np.arange(1, pad + 1)])
    head = np.repeat(q[:1], pad, axis=0)
    if v0 is not None:
        head = head - before[:, None] * v0
    qp = np.concatenate([head, q, np.repeat(q[-1:], pad, axis=0)])
    return tp, qp


def divided_differences(
    t: npt.ArrayLike, q: npt.ArrayLike, *, pad_rest: int = PAD_REST
) -> tuple[Float, Float, Float]:
    """Velocity, acceleration and jerk of samples by divided differences (module docstring).

    Parameters
    ----------
    t : array-like, shape (K,)
        Strictly increasing times (s), K >= 2.
    q : array-like, shape (K, n)
        Joint positions.
    pad_rest : int
        Copies of the first and last samples added before and after them (at the neighbouring
        spacing), so that starting and ending at rest is part of the check. 0: none.

    Returns
    -------
    v : ndarray, shape (K + 2 pad - 1, n)
    a : ndarray, shape (K + 2 pad - 2, n)
    j : ndarray, shape (K + 2 pad - 3, n)
    """
    t_ = check_array(t, "t", ndim=1, min_rows=2)
    q_ = check_array(q, "q", shape=(t_.shape[0], None))
    if np.any(np.diff(t_) <= 0):
        raise ValueError("t must be strictly increasing")
    return _derivatives(*_padded(t_, q_, int(pad_rest)))


def _derivatives(tp: Float, qp: Float) -> tuple[Float, Float, Float]:
    # k! times Newton's divided differences of order k = 1, 2, 3
    v = np.diff(qp, axis=0) / np.diff(tp)[:, None]
    a = 2.0 * np.diff(v, axis=0) / (tp[2:] - tp[:-2])[:, None]
    j = 3.0 * np.diff(a, axis=0) / (tp[3:] - tp[:-3])[:, None]
    return v, a, j


@dataclass(frozen=True)
class MotionPeaks:
    """The largest velocity, acceleration and jerk of a trajectory over its limits.

    Attributes
    ----------
    velocity, acceleration, jerk : float
        max over the samples and joints of ``|derivative|`` / limit (0 where nothing is limited);
        <= 1 means within the limits.
    velocity_abs, acceleration_abs, jerk_abs : float
        The largest absolute values (rad/s, rad/s^2, rad/s^3), over every joint.
    """

    velocity: float
    acceleration: float
    jerk: float
    velocity_abs: float
    acceleration_abs: float
    jerk_abs: float

    @property
    def worst(self) -> float:
        """The largest of the three ratios."""
        return max(self.velocity, self.acceleration, self.jerk)

    def as_dict(self) -> dict[str, float]:
        """JSON-ready: the ratios as ``peak_*_ratio``, the absolute values as ``peak_*``."""
        out: dict[str, float] = {}
        for k in ("velocity", "acceleration", "jerk"):
            out[f"peak_{k}_ratio"] = float(getattr(self, k))
            out[f"peak_{k}"] = float(getattr(self, f"{k}_abs"))
        return out


def motion_peaks(
    t: npt.ArrayLike,
    q: npt.ArrayLike,
    limits: MotionLimits,
    *,
    pad_rest: int = PAD_REST,
    mask: npt.ArrayLike | None = None,
) -> MotionPeaks:
    """Peak velocity, acceleration and jerk of samples over ``limits`` (divided differences).

    Parameters
    ----------
    t : array-like, shape (K,)
    q : array-like, shape (K, n)
    limits : MotionLimits
        n joints.
    pad_rest : int
        As :func:`divided_differences`.
    mask : array-like of bool, shape (K,), optional
        Only the divided differences whose samples are all True count (e.g. outside the
        window where an external force drives the arm).

    Returns
    -------
    MotionPeaks
    """
    v, a, j = divided_differences(t, q, pad_rest=pad_rest)
    if v.shape[1] != limits.n_joints:
        raise ValueError(f"limits are for {limits.n_joints} joints, q has {v.shape[1]}")
    keep = None
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        m = np.concatenate([np.repeat(m[:1], pad_rest), m, np.repeat(m[-1:], pad_rest)])
        keep = [np.all(np.lib.stride_tricks.sliding_window_view(m, w), axis=1) for w in (2, 3, 4)]
    out = []
    kinds = (v, a, j)
    bounds = (limits.velocity, limits.acceleration, limits.jerk)
    for k, (d, lim) in enumerate(zip(kinds, bounds, strict=True)):
        dd = np.abs(d) if keep is None else np.abs(d[keep[k]])
        if dd.size == 0:
            out.append((0.0, 0.0))
            continue
        ratio = dd / lim  # inf limit -> 0
        out.append((float(ratio.max()), float(dd.max())))
    return MotionPeaks(out[0][0], out[1][0], out[2][0], out[0][1], out[1][1], out[2][1])


def count_reversals(
    q: npt.ArrayLike,
    dt: float | npt.ArrayLike,
    velocity_limit: npt.ArrayLike,
    *,
    fraction: float = 0.25,
) -> int:
    """Direction reversals of a joint between two consecutive steps that are each faster than
    ``fraction`` of its velocity limit (the limit cycle a real arm would chatter on).

    Parameters
    ----------
    q : array-like, shape (K, n)
    dt : float or array-like, shape (K - 1,)
        Duration of each step (s).
    velocity_limit : array-like, shape (n,)
        rad/s (inf: that joint is never counted).
    fraction : float

    Returns
    -------
    count : int
        Over every joint and step.
    """
    q_ = np.asarray(q, dtype=np.float64)
    h = np.broadcast_to(np.asarray(dt, dtype=np.float64), (q_.shape[0] - 1,))
    speed = np.diff(q_, axis=0) / h[:, None]
    fast = np.abs(speed) > fraction * np.asarray(velocity_limit, dtype=np.float64)
    flips = np.sign(speed[1:]) * np.sign(speed[:-1]) < 0
    return int(np.count_nonzero(flips & fast[1:] & fast[:-1]))


# ----------------------------------------------------------------------------- timing
def retime(
    q: npt.ArrayLike,
    dt: float | npt.ArrayLike,
    limits: MotionLimits,
    *,
    pad_rest: int = PAD_REST,
    start_velocity: npt.ArrayLike | None = None,
) -> Float:
    """Durations of the steps of a path so that it respects ``limits`` (module docstring).

    Parameters
    ----------
    q : array-like, shape (K, n)
        The path: K >= 2 postures, kept exactly.
    dt : float or array-like, shape (K - 1,)
        The nominal duration of a step (s), > 0, or of each step: no step is made shorter.
    limits : MotionLimits
        Checked with :func:`divided_differences` padded with ``pad_rest`` rest samples at
        both ends (the path starts and ends at rest).
    start_velocity : array-like, shape (n,), optional
        The path starts moving at this velocity (rad/s) instead of at rest: the samples
        padded before it continue it backward (a path that takes over from a motion, e.g. the
        online controller's re-plans). Within the velocity limits: a speed within
        :data:`START_VELOCITY_TOLERANCE` of a limit (e.g. a measured velocity clipped to it) is
        taken as ``1 - 1e-9`` of it.

    Returns
    -------
    h : ndarray, shape (K - 1,)
        Duration of each step (s), >= dt.

    Raises
    ------
    ValueError
        If ``start_velocity`` exceeds a velocity limit (by more than
        :data:`START_VELOCITY_TOLERANCE`).
    RuntimeError
        If the limits are still exceeded after 200 rounds (each round stretches every excess
        by more than it needs, so a finite path never gets there; the loop is bounded anyway)
        and stretching every step alike does not bring them within either.

    Warns
    -----
    RetimeWarning
        After 200 rounds: the whole path is slowed alike instead (the warning says by how
        much), within the limits.
    """
    q_ = check_array(q, "q", ndim=2, min_rows=2)
    k_steps = q_.shape[0] - 1
    nominal = np.asarray(dt, dtype=np.float64)
    if nominal.ndim not in (0, 1) or (nominal.ndim == 1 and nominal.shape != (k_steps,)):
        raise ValueError(
            f"dt must be a number or have shape ({k_steps},) (one per step), got shape "
            f"{nominal.shape}"
        )
    if not np.all(np.isfinite(nominal) & (nominal > 0)):
        raise ValueError(
            f"dt must be a positive number of seconds (or one per step), got {short(dt)}"
        )
    h = np.broadcast_to(nominal, (k_steps,)).astype(np.float64)
    if not limits.any:
        return h
    pad = int(pad_rest)
    v0 = (
        None
        if start_velocity is None
        else _start_velocity(
            check_array(start_velocity, "start_velocity", shape=(q_.shape[1],)), limits.velocity
        )
    )
    offsets = np.arange(-_TAPER_HALF_WIDTH, _TAPER_HALF_WIDTH + 1)
    taper = np.exp(-0.5 * (offsets / _TAPER_SIGMA) ** 2)
    fine = float(np.median(h)) < _FINE_GRID_SECONDS
    vlim, alim, jlim = limits.velocity, limits.acceleration, limits.jerk
    for round_ in range(_MAX_ROUNDS):
        t = np.concatenate([[0.0], np.cumsum(h)])
        v, a, j = _derivatives(*_padded(t, q_, pad, v0))
        rv = (np.abs(v) / vlim).max(axis=1)
        ra = np.sqrt((np.abs(a) / alim).max(axis=1))
        rj = np.cbrt((np.abs(j) / jlim).max(axis=1))
        # Needed stretch of each padded segment: the worst ratio of a difference spanning it.
        n_seg = v.shape[0]
        f = rv.copy()
        for s in range(2):
            f[s : n_seg - 1 + s] = np.maximum(f[s : n_seg - 1 + s], ra)
        for s in range(3):
            f[s : n_seg - 2 + s] = np.maximum(f[s : n_seg - 2 + s], rj)
        if f.max() <= 1.0:
            return h
        need = f[pad : pad + k_steps].copy()
        # The rest padding is spaced like the end steps: its excess is theirs to fix.
        need[0] = max(need[0], float(f[: pad + 1].max()))
        need[-1] = max(need[-1], float(f[pad + k_steps - 1 :].max()))
        # Stretched a little more than each excess needs, and a little more at every round: the
        # stretches of neighbours interact, and a slow convergence would cost many rounds.
        overshoot = _STRETCH_OVERSHOOT + _OVERSHOOT_GROWTH * round_
        excess = np.where(need > 1.0, np.maximum(need**overshoot - 1.0, _MIN_STRETCH), 0.0)
        h = h * (1.0 + (_tapered_in_time(excess, taper, h) if fine else _tapered(excess, taper)))
    # Not converged (never seen since the minimum stretch; the loop is bounded anyway): the
    # durations reached, all stretched alike until every divided difference is within.
    largest = float(f.max())
    slowed = _slowed_uniformly(q_, h, limits, pad, v0)
    if slowed is None:
        raise RuntimeError(
            f"retime: the path is not within the limits after {_MAX_ROUNDS} rounds (largest "
            f"excess {largest:.6g}x), nor slowed as a whole"
        )
    factor = float(slowed.sum() / h.sum())
    warnings.warn(
        f"retime: the path was not within the limits after {_MAX_ROUNDS} rounds (largest excess "
        f"{largest:.6g}x): the whole path is slowed by {factor:.4g}x instead",
        RetimeWarning,
        stacklevel=2,
    )
    return slowed


def _tapered(excess: Float, taper: Float) -> Float:
    """retime's taper over steps: every step gets the largest stretch asked by a step within
    the window, weighted by its distance (the window symmetric: no flip needed)."""
    edge = np.zeros((taper.shape[0] - 1) // 2)
    windows = np.lib.stride_tricks.sliding_window_view(
        np.concatenate([edge, excess, edge]), taper.shape[0]
    )
    return np.asarray((windows * taper).max(axis=1), dtype=np.float64)


def _tapered_in_time(excess: Float, taper: Float, h: Float) -> Float:
    """retime's taper on a fine grid: over blocks of :data:`_TAPER_BLOCK_SECONDS` of the
    durations ``h`` reached (a step in the block of its middle; each block asks for the largest
    stretch of its steps), weighted as :func:`_tapered`'s but on the logarithm of the stretch
    (a stretch by f asks a neighbour for f^w, not 1 + (f - 1) w: a step slowed 100 times does
    not slow its neighbours 50 times), interpolated at each step's middle; every step gets at
    least its own. Only the blocks that hold a step are kept: memory and time O(K) however
    long the path has become."""
    half = (taper.shape[0] - 1) // 2
    middle = np.cumsum(h) - 0.5 * h
    block = np.floor(middle / _TAPER_BLOCK_SECONDS).astype(np.int64)
    first = np.flatnonzero(np.r_[True, np.diff(block) > 0])
    held = block[first]
    asked = np.maximum.reduceat(np.log1p(excess), first)
    spread = asked.copy()
    # The blocks within `half` of a block are among the `half` held ones on either side.
    for m in range(1, min(half, held.shape[0] - 1) + 1):
        gap = held[m:] - held[:-m]
        weight = np.where(gap <= half, taper[half + np.minimum(gap, half)], 0.0)
        np.maximum(spread[m:], weight * asked[:-m], out=spread[m:])
        np.maximum(spread[:-m], weight * asked[m:], out=spread[:-m])
    middles = _TAPER_BLOCK_SECONDS * (held + 0.5)
    return np.maximum(np.expm1(np.interp(middle, middles, spread)), excess)


class RetimeWarning(RuntimeWarning):
    """:func:`retime` fell back to slowing the whole path (the local stretches did not
    converge)."""


def _slowed_uniformly(
    q: Float, h: Float, limits: MotionLimits, pad: int, v0: Float | None
) -> Float | None:
    """Durations ``h`` all stretched alike until the path is within ``limits`` (a uniform
    stretch by f divides velocities by f, accelerations by f^2, jerks by f^3: one step gets
    there but where a moving start does not scale), or None after 20 steps."""
    vlim, alim, jlim = limits.velocity, limits.acceleration, limits.jerk
    for _ in range(20):
        t = np.concatenate([[0.0], np.cumsum(h)])
        v, a, j = _derivatives(*_padded(t, q, pad, v0))
        need = max(
            float((np.abs(v) / vlim).max()),
            float(np.sqrt((np.abs(a) / alim).max())),
            float(np.cbrt((np.abs(j) / jlim).max())),
        )
        if need <= 1.0:
            return h
        h = h * need * 1.001
    return None


#: A start velocity this close to the velocity limit (relative) counts as on it.
START_VELOCITY_TOLERANCE = 1e-9


def _start_velocity(v0: Float, vlim: Float) -> Float:
    """``retime``'s start velocity, within the limit: the padding before the path moves at
    it whatever the stretch, so a speed on the limit (a measured velocity clipped to it) would
    be one rounding error over it at every round. Brought to ``1 - 1e-9`` of the limit;
    beyond the limit by more than that, refused."""
    over = np.abs(v0) > vlim * (1.0 + START_VELOCITY_TOLERANCE)
    if over.any():
        i = int(np.argmax(over))
        raise ValueError(
            f"start_velocity[{i}] is {short(float(v0[i]))} rad/s, beyond the velocity limit "
            f"{short(float(vlim[i]))}: no timing of the path can start from it"
        )
    cap = vlim * (1.0 - START_VELOCITY_TOLERANCE)
    return np.clip(v0, -cap, cap)


def times_from_durations(h: Float, t0: float = 0.0) -> Float:
    """Sample times from step durations: (K - 1,) -> (K,)."""
    return np.concatenate([[t0], t0 + np.cumsum(h)])


def last_differences(q: Sequence[Float], h: float) -> tuple[Float, Float, Float]:
    """Velocity, acceleration and jerk at the last of four setpoints ``h`` s apart (the divided
    differences on a uniform grid, oldest first)."""
    q0, q1, q2, q3 = q
    return (
        (q3 - q2) / h,
        (q3 - 2.0 * q2 + q1) / (h * h),
        (q3 - 3.0 * q2 + 3.0 * q1 - q0) / (h * h * h),
    )


class StreamMonitor:
    """Peak velocity, acceleration and jerk of a stream of setpoints at a fixed period, updated
    one setpoint at a time (what a drive that checks its command stream sees).

    The stream is taken to start at rest at its first setpoint (as :func:`motion_peaks` pads
    it); a setpoint given with ``counted=False`` (e.g. while an external force drives the arm)
    makes every divided difference that includes it not count.

    Parameters
    ----------
    limits : MotionLimits
    period : float
        Time between setpoints (s).
    """

    def __init__(self, limits: MotionLimits, period: float) -> None:
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"period must be a positive number of seconds, got {short(period)}")
        self.limits, self.period = limits, float(period)
        self._q: list[Float] = []
        self._ok: list[bool] = []
        self._ratio = np.zeros(3)
        self._abs = np.zeros(3)
        self.count = 0

    def update(self, q: npt.ArrayLike, counted: bool = True) -> None:
        """The next setpoint (n,)."""
        arr = np.array(q, dtype=np.float64)
        if not self._q:  # at rest before the first setpoint
            self._q = [arr] * 4
            self._ok = [counted] * 4
        self._q = [*self._q[1:], arr]
        self._ok = [*self._ok[1:], bool(counted)]
        self.count += 1
        diffs = last_differences(self._q, self.period)
        bounds = (self.limits.velocity, self.limits.acceleration, self.limits.jerk)
        for k, (d, lim) in enumerate(zip(diffs, bounds, strict=True)):
            if all(self._ok[3 - k - 1 :]):
                ad = np.abs(d)
                self._ratio[k] = max(self._ratio[k], float((ad / lim).max()))
                self._abs[k] = max(self._abs[k], float(ad.max()))

    def peaks(self) -> MotionPeaks:
        """The peaks so far (and, as :func:`motion_peaks`, of coming to rest at the last
        setpoint: call :meth:`finish` first for that)."""
        r, a = self._ratio, self._abs
        return MotionPeaks(
            float(r[0]), float(r[1]), float(r[2]), float(a[0]), float(a[1]), float(a[2])
        )

    def finish(self) -> MotionPeaks:
        """Hold the last setpoint for three periods (at rest afterwards) and return the peaks."""
        if self._q:
            last = self._q[-1]
            for _ in range(3):
                self.update(last, self._ok[-1])
        return self.peaks()
