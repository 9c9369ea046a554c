"""The set-up of a reproduction or controller run: its options (:class:`RunOptions`), their
validation against the skill's constraints and the robot (:func:`setup_run`, giving a
:class:`RunSetup`), and the bounds derived from the arm (its reach, its velocity limits as a
step bound).

Reach: an object in use is out of reach when, at the step where its task constraint is tightest
(smallest trace of Sigma^x(n)), o(n) + x_hat^(n) is farther from the base origin than the arm's
reach (:func:`reach_from_samples`): :doc:`/reproduction`, "Reach".
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_positive_float, short
from ..data._placement import check_placements, is_pose, position_of
from ..motion._limits import positive_bounds
from ..robots._protocols import KinematicModel, PoseKinematicModel, check_robot
from ._constraints import JOINT, Constraints

__all__ = [
    "VELOCITY_SAFETY",
    "ReachWarning",
    "RunOptions",
    "RunSetup",
    "check_objects",
    "reach_from_samples",
    "setup_run",
    "step_limit_from_velocity",
]

Float = NDArray[np.float64]
# step_limit = v dt VELOCITY_SAFETY: floating-point rounding never plays a step above v.
VELOCITY_SAFETY = 1.0 - 1e-6


class ReachWarning(UserWarning):
    """An object's constrained target lies beyond the arm's reach (the hand stops short)."""


@dataclass(frozen=True, eq=False, kw_only=True)
class RunOptions:
    """How a reproduction or a controller run goes: the options :meth:`pbdkit.Skill.reproduce`,
    :meth:`pbdkit.Skill.controller`, :func:`~pbdkit.reproduction._probabilistic_ik.solve` and
    :class:`pbdkit.Controller` share, in one object, built by keyword (each is described at
    :meth:`pbdkit.Skill.reproduce`).

    Attributes
    ----------
    q0 : array-like, shape (n,), optional
        Initial posture, within the joint limits. Default: theta_hat_0 (the paper), clipped to
        the limits.
    use : sequence of str, optional
        Constraints to use: None for all (fused); ``["joint"]`` for the joint-space controller;
        ``["glass"]`` for the task-space controller of one object; several names fuse them.
    alpha : float
        Weight of the null-space term of the task-only controllers (paper: 0.5). Without effect
        when ``"joint"`` is in use (:doc:`/reproduction`, "Fusion in information form").
    max_step : float or None
        Largest joint-space step (Euclidean norm over the joints, rad): a longer step is scaled
        down, keeping its direction (:doc:`/reproduction`, "Step size"). None: no such bound.
    on_unreachable : {"raise", "warn"}
        With a reach: raise ValueError for an object out of reach, or warn with
        :class:`ReachWarning` and reproduce anyway (the hand then stops short).
    line_search : bool
        Fused controller: shorten a step that would raise the fused energy of its step
        (:doc:`/reproduction`, "Stability"). False: the paper's loop as written.
    newton : bool
        Fused controller: use the curvature of the forward kinematics where it stiffens a step
        (:doc:`/reproduction`, "Stability"; from ``robot.fk_jacobian_axes_unchecked``, which
        every :class:`~pbdkit.robots.KinematicModel` has). False: Gauss-Newton steps only.
    """

    q0: npt.ArrayLike | None = None
    use: Sequence[str] | str | None = None
    alpha: float = 0.5
    max_step: float | None = 0.1
    on_unreachable: Literal["raise", "warn"] = "raise"
    line_search: bool = True
    newton: bool = True


@dataclass(frozen=True, kw_only=True)
class RunSetup:
    """The validated inputs of one reproduction or controller run (:func:`setup_run` builds it;
    a re-plan of the online controller replaces its ``objects`` and ``theta0``).

    Attributes
    ----------
    constraints : Constraints
    objects : dict str -> ndarray, shape (3,) or (4, 4)
        Every object of the skill (:func:`check_objects`).
    used : list of str
        The constraints in use, in the skill's order.
    tasks : list of str
        The task constraints in use.
    alpha : float
    max_step : float
        inf: no trust region.
    step_limit : ndarray, shape (n,), or None
    lower, upper : ndarray, shape (n,)
        The robot's joint limits.
    theta0 : ndarray, shape (n,)
        The posture the run starts from.
    line_search, newton : bool
    reach : float or None
    on_unreachable : {"raise", "warn"}
    avoid : Avoidance or None
        The clearance constraint of the fused step (:mod:`._avoid`), None: no avoidance.
    """

    constraints: Constraints
    objects: dict[str, Float]
    used: list[str]
    tasks: list[str]
    alpha: float
    max_step: float
    step_limit: Float | None
    lower: Float
    upper: Float
    theta0: Float
    line_search: bool
    newton: bool
    reach: float | None
    on_unreachable: str
    avoid: Any = None


def setup_run(
    robot: KinematicModel,
    constraints: Constraints,
    objects: Mapping[str, npt.ArrayLike],
    options: RunOptions,
    *,
    step_limit: npt.ArrayLike | None = None,
    reach: float | None = None,
) -> RunSetup:
    """Validate the inputs of a run: where a robot enters a reproduction
    (:func:`~pbdkit.reproduction._probabilistic_ik.solve`) or an online controller.

    The robot must be a :class:`~pbdkit.robots.KinematicModel`, and a
    :class:`~pbdkit.robots.PoseKinematicModel` when some constraint is oriented
    (:func:`~pbdkit.robots.check_robot`); the steps then use its members as they are.
    """
    c = constraints
    if not isinstance(c, Constraints):
        raise ValueError(f"constraints must be a Constraints, got {type(c).__name__}")
    check_robot(robot, PoseKinematicModel if c.oriented else KinematicModel)
    if not isinstance(options, RunOptions):
        raise ValueError(f"options must be a RunOptions, got {type(options).__name__}")
    n = c.n_joints
    if int(robot.n_joints) != n:
        raise ValueError(f"robot has {robot.n_joints} joints, the constraints have {n}")
    objs = check_objects(objects, c.object_names, oriented=c.oriented)
    used = _check_use(options.use, c.names)
    alpha = check_positive_float(options.alpha, "alpha", allow_zero=True)
    max_step = options.max_step
    step_cap = np.inf if max_step is None else check_positive_float(max_step, "max_step")
    bound = _check_step_limit(step_limit, n)
    on_unreachable = options.on_unreachable
    if on_unreachable not in ("raise", "warn"):
        raise ValueError(f"on_unreachable must be 'raise' or 'warn', got {short(on_unreachable)}")
    if reach is not None:
        # Only the objects whose constraints are in use steer the arm.
        _check_reach({k: o for k, o in objs.items() if k in used}, c, float(reach), on_unreachable)
    lower = np.asarray(robot.lower, dtype=np.float64)
    upper = np.asarray(robot.upper, dtype=np.float64)
    # The paper starts at theta_hat_0; clipped in case the GMR mean grazes a limit.
    q0 = options.q0
    theta0 = np.clip(c.joint_mean[0], lower, upper) if q0 is None else _check_q0(q0, lower, upper)
    tasks = [u for u in used if u != JOINT]
    return RunSetup(
        constraints=c,
        objects=objs,
        used=used,
        tasks=tasks,
        alpha=alpha,
        max_step=step_cap,
        step_limit=bound,
        lower=lower,
        upper=upper,
        theta0=theta0,
        line_search=bool(options.line_search),
        newton=bool(options.newton),
        reach=None if reach is None else float(reach),
        on_unreachable=on_unreachable,
    )


def check_objects(
    objects: object,
    names: Sequence[str],
    name: str = "objects",
    *,
    oriented: Sequence[str] = (),
    partial: bool = False,
) -> dict[str, Float]:
    """Validate where the objects are, for a reproduction.

    Parameters
    ----------
    objects : dict str -> array-like
        Must have exactly the keys ``names`` (any subset of them with ``partial``). Each a
        position (3,) or a pose (4x4, or x, y, z, qw, qx, qy, qz with the quaternion w first:
        :mod:`pbdkit.data._placement`).
    names : sequence of str
        Expected object names.
    oriented : sequence of str
        The objects whose constraints are oriented: they need a pose. The others need a
        position; a pose given for one is used by its position (its frame translates only).

    Returns
    -------
    objects : dict str -> ndarray, shape (3,) or (4, 4)
        In the order of ``names``: a position for an object of a position-only constraint, a
        4x4 pose for an oriented one.
    """
    if partial:
        given = check_placements(objects, name)
        unknown = [k for k in given if k not in names]
        if unknown:
            raise ValueError(
                f"{name}: unknown object name(s) {unknown}; this skill knows {list(names)}"
            )
    else:
        given = check_placements(objects, name, expected=names)
    out: dict[str, Float] = {}
    for k, v in given.items():
        if k in oriented:
            if not is_pose(v):
                raise ValueError(
                    f"{name}[{short(k)}] must be a pose (a 4x4 transform or x, y, z, qw, qx, qy, "
                    "qz): "
                    "the skill learned the hand's position and orientation in the frame of "
                    f"{short(k)}; "
                    f"got a position {v.tolist()}"
                )
            out[k] = v
        else:
            out[k] = position_of(v).copy()
    return out


def _check_use(use: Sequence[str] | str | None, names: Sequence[str]) -> list[str]:
    if use is None:
        return list(names)
    if isinstance(use, str):
        use = [use]
    given: object = use  # checked at run time: callers may pass anything
    if (
        isinstance(given, (bytes, bytearray))
        or not isinstance(given, (Sequence, np.ndarray))
        or not all(isinstance(u, str) for u in given)
    ):
        raise ValueError(
            f"use must be None, a constraint name or a sequence of names, got {short(use)}; "
            f"the constraints are {list(names)}"
        )
    out = [str(u) for u in use]
    if not out:
        raise ValueError(f"use must name at least one constraint of {list(names)}, got []")
    bad = [u for u in out if u not in names]
    if bad:
        raise ValueError(f"use: unknown constraint(s) {bad}; choose among {list(names)}")
    if len(set(out)) != len(out):
        raise ValueError(f"use must not repeat a constraint, got {out}")
    # Keep the skill's order so that results do not depend on how `use` is spelled.
    return [n for n in names if n in out]


def _check_reach(
    objs: Mapping[str, Float],
    constraints: Constraints,
    reach: float,
    on_unreachable: str,
) -> None:
    """Compare each object's most constrained target o + x_hat with the arm's reach: at the
    step where its task constraint is tightest (smallest trace of its position covariance)."""
    for k, o in objs.items():
        # The step where the constraint is tightest is where the hand must be at o + x_hat.
        j = int(np.argmin(np.trace(constraints.position_cov(k), axis1=1, axis2=2)))
        if k in constraints.rotation_base:  # p + R m for a pose
            target = o[:3, 3] + o[:3, :3] @ constraints.task_mean[k][j, :3]
        else:
            target = o + constraints.task_mean[k][j]
        with np.errstate(over="ignore"):  # 1e200 m: inf, beyond the reach
            dist = float(np.linalg.norm(target))
        if dist > reach:
            msg = (
                f"objects[{short(k)}]: the hand must be at {np.round(target, 4).tolist()} at step "
                f"{j} (o + x_hat, where this object's constraint is tightest), "
                f"{dist:.3f} m from the base, beyond the arm's reach of {reach:.3f} m; "
                "move the object closer"
            )
            if on_unreachable == "raise":
                raise ValueError(msg)
            warnings.warn(msg + " (the hand will stop short)", ReachWarning, stacklevel=3)


def step_limit_from_velocity(
    velocity_limit: float | npt.ArrayLike | Literal["robot"] | None,
    robot: KinematicModel,
    dt: float,
) -> Float | None:
    """Per-joint step bound for :func:`~pbdkit.reproduction._probabilistic_ik.solve` from
    joint velocity limits.

    Parameters
    ----------
    velocity_limit : "robot", float, array-like of shape (n,), or None
        In rad/s. ``"robot"``: ``robot.velocity_limit`` (a :class:`pbdkit.Robot` has its URDF's)
        with the joints whose limit is 0, negative, NaN or inf left unlimited; no limit if ``dt``
        is unknown. A number (every joint) or one value per joint, > 0 (inf leaves a joint
        unlimited). None: no limit.
    robot : KinematicModel
    dt : float
        Time a step takes when the reproduction is executed (s), > 0; NaN when unknown.

    Returns
    -------
    step_limit : ndarray, shape (n,), or None
        v dt (1 - 1e-6) in rad per step, the factor keeping floating-point rounding from ever
        playing a step above v; inf for an unlimited joint; None when no joint is limited.

    Raises
    ------
    ValueError
        An explicit limit with an unknown ``dt``, or a limit that is not > 0.
    """
    n = int(robot.n_joints)
    known = bool(np.isfinite(dt) and dt > 0)
    if velocity_limit is None:
        return None
    if isinstance(velocity_limit, str):
        if velocity_limit != "robot":
            raise ValueError(
                f"velocity_limit must be 'robot', a number or an array of shape ({n},) in rad/s, "
                f"or None, got {short(velocity_limit)}"
            )
        if not known:
            return None
        v = check_array(robot.velocity_limit, "robot.velocity_limit", shape=(n,), finite=False)
        # A URDF writes 0 (or leaves out) the limit of a joint it does not limit.
        v = np.where(np.isfinite(v) & (v > 0), v, np.inf)
    else:
        if not known:
            raise ValueError(
                "velocity_limit is in rad/s and needs the duration of a step to bound the steps; "
                f"it is unknown (dt = {short(dt)}: the skill has no known duration): pass "
                "velocity_limit=None, or bound the steps in rad with max_step"
            )
        v = positive_bounds(velocity_limit, n, "velocity_limit", "rad/s")
    return _check_step_limit(v * (dt * VELOCITY_SAFETY), n)


def _check_step_limit(step_limit: npt.ArrayLike | None, n: int) -> Float | None:
    """step_limit as ndarray (n,), or None when no joint is bounded."""
    if step_limit is None:
        return None
    arr = positive_bounds(step_limit, n, "step_limit", "rad per step")
    return None if bool(np.all(np.isinf(arr))) else arr


def _check_q0(q0: npt.ArrayLike, lower: Float, upper: Float) -> Float:
    q = check_array(q0, "q0", shape=(lower.shape[0],), allow_bool=False)
    bad = np.flatnonzero((q < lower) | (q > upper))
    if bad.size:
        j = int(bad[0])
        raise ValueError(
            f"q0[{j}] must be within the joint limits [{lower[j]:.6g}, {upper[j]:.6g}], "
            f"got {q[j]:.6g}"
        )
    return q


def reach_from_samples(
    robot: KinematicModel,
    joints: npt.ArrayLike | None = None,
    n_samples: int = 4096,
    seed: int = 0,
) -> float:
    """Estimate of the arm's reach: max ||f(theta)|| over random postures within the limits.

    Parameters
    ----------
    robot : KinematicModel
    joints : array-like, shape (M, n), optional
        Extra postures (e.g. the demonstrated ones) to include.
    n_samples : int
        Number of uniformly random postures.
    seed : int
        Seed of the sampler (the estimate is deterministic).

    Returns
    -------
    reach : float
        In metres, from the base origin; a slight under-estimate of the true maximum, enlarged
        by 2 % so that a target just inside the workspace is never reported out of reach.
    """
    rng = np.random.default_rng(seed)
    lower = np.asarray(robot.lower, dtype=np.float64)
    upper = np.asarray(robot.upper, dtype=np.float64)
    q = lower + (upper - lower) * rng.random((n_samples, lower.shape[0]))
    if joints is not None:
        q = np.concatenate([q, check_array(joints, "joints", shape=(None, lower.shape[0]))])
    x = np.asarray(robot.fk(q), dtype=np.float64)
    return 1.02 * float(np.max(np.linalg.norm(x, axis=1)))
