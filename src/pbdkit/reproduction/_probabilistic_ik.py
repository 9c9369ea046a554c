"""Reproduction of a skill by probabilistic inverse kinematics (paper Table II).

Given the generalized constraints of a skill (GMR outputs over the whole time grid) and the new
positions o(n) of the objects, the closed loop of Table II computes the joint trajectory
theta_0, ..., theta_{T-1}. At step j -> j+1, with x_j = f(theta_j) and J = J(theta_j):

- joint-space constraint: dtheta^(joint) = theta_hat_{j+1} - theta_j, covariance
  Sigma^theta_{j+1} (Table II);
- task-space constraint of object n: dx^(n) = (o(n) + x_hat^(n)_{j+1}) - x_j, covariance
  Sigma^x(n)_{j+1} in task space (Table II).

This module runs the loop (:func:`solve`, :func:`timed_path`) and documents its math below. The
constraints are :class:`Constraints` (:mod:`pbdkit.reproduction._constraints`); one step of each
controller, shared with the online controller, is in :mod:`pbdkit.reproduction._steps`
(:func:`make_step` picks it). A constraint that also holds the hand's orientation, for an object
given as a pose, has the steps of :mod:`._pose_steps`, whose docstring says how an
orientation is fused ("Orientation", "Influence"); what follows is written for positions.

Corrections to the paper (design.md, "Math notes")
--------------------------------------------------
- Pseudo-inverse. The paper's J+ = (J^T J)^-1 J^T is singular for a 3 x n Jacobian with n > 3;
  the task-only controller uses the damped right inverse J^T (J J^T + lambda^2 I)^-1 of
  :func:`pbdkit.robots.damped_pinv` (lambda > 0 only near singularities).
- Fusion in information form. The paper's Sigma^(n) = J+ Sigma^x(n) J+^T has rank 3 in n-D joint
  space, so eq. (1) cannot invert it. Its Moore-Penrose pseudo-inverse is exactly
  Lambda^(n) = J^T (Sigma^x(n))^-1 J, and the information vector is
  eta^(n) = Lambda^(n) dtheta^(n) = J^T (Sigma^x(n))^-1 dx^(n): with
  dtheta^(n) = J+ dx + alpha (I - J+ J)(theta_hat - theta), J J+ = I and J (I - J+ J) = 0, so
  the null-space term cancels. The fused step is (eq. (1) in information form)

      dtheta = (Lambda^(joint) + sum_n Lambda^(n))^-1 (Lambda^(joint) dtheta^(joint)
               + sum_n J^T (Sigma^x(n))^-1 dx^(n)),   Sigma_{j+1} = (sum of the precisions)^-1.

  ``alpha`` therefore has no effect on any controller that includes the joint constraint; it
  acts only in the task-only controllers. This equals eq. (1) with the Tikhonov-regularized
  inverse (S^2 + eps I)^-1 S of each Sigma^(n) in the limit eps -> 0 (tested). The naive
  (Sigma^(n) + eps I)^-1 does *not* converge to it: it gives precision 1/eps to the null space
  of J and freezes the null-space motion at the task constraint's own alpha term.
- Task-only controllers (``use`` without ``"joint"``): the task constraints in use are fused in
  task space first (precisions add: dx = (sum_n P_n)^-1 sum_n P_n dx^(n), P_n = (Sigma^x(n))^-1),
  then theta_{j+1} = theta_j + J+ dx + alpha (I - J+ J)(theta_hat_{j+1} - theta_j) (Table II); with
  one object this is exactly the paper's controller for that object. The reported covariance is
  the paper's J+ Sigma^x J+^T (rank 3).

Joint limits. After every step theta_{j+1} is clipped to [lower, upper]: the reproduction never
leaves the limits; a constraint that would push a joint beyond its limit is followed as far as
the limit allows (the next steps correct from the clipped posture, the loop being closed).

Step size. Table II takes the full linearized step, however far the target. Two bounds scale a
step down, both uniformly (the step keeps its direction, only its length shrinks):

- ``step_limit`` (rad per step, per joint): ``|dtheta_i| <= step_limit_i`` for every joint i. A
  :class:`pbdkit.Skill` derives it from the arm's velocity limits v_i in rad/s (the URDF's, by
  default) and the time a step takes when the reproduction is executed,
  dt = duration / (T - 1) (:meth:`pbdkit.Skill.times`): step_limit_i = v_i dt (1 - 1e-6), the
  factor keeping floating-point rounding from ever putting a played speed above v_i. Without it
  a reproduction's first steps, whose targets are far from theta_hat_0, command several times
  the arm's limits (measured in the README, "Where we depart from the paper's text").
- ``max_step`` (rad, Euclidean norm over the joints): a trust region of the linearization. When a
  target is far from the hand (out of reach, or a tight constraint at t_0 far from theta_0) a
  full step can throw the arm against its limits, folded. It is a length in rad, whatever the
  timing; on the paper's grid (1000 steps over ~20 s, 0.024 rad per joint and step at the
  Katana's top speed, <= 0.053 rad over its 5 joints) the velocity bound is the tighter one and
  the default 0.1 rad never binds. ``max_step=None`` drops it.

The step is scaled by the smaller of the two factors, then theta_{j+1} is clipped to the joint
limits (which only shortens a step further). Why uniform scaling rather than clipping each joint
to its bound: the direction of the fused step is what the constraints agree on (the
precision-weighted compromise of eq. (1)); saturating some joints while others complete their
motion would turn the step toward a posture none of the constraints asks for. Scaled uniformly,
the arm moves along the agreed direction, at the top speed of the joint that binds, and the
closed loop re-linearizes from where it got. A q0 far from theta_hat_0 is therefore reached
without a jump: the first steps run the binding joint at its top speed until the posture has
caught up with the constraints; after that the bound binds only where the constraints
themselves move faster than the arm can.
``ReproductionResult.limited`` marks the steps that were scaled down.

Stability. Each step of the fused loop is one Gauss-Newton step on the fused energy of that step::

    E_j(theta) = 1/2 |theta - theta_hat_j|^2_(Lambda_theta)
                 + 1/2 sum_n |f(theta) - o(n) - x_hat^(n)_j|^2_(P_n),

whose minimum is the product of the Gaussians. Gauss-Newton drops the curvature of f weighted by
the residual P_n (f(theta) - o(n) - x_hat^(n)); where the constraints disagree (a residual) and a
tight task constraint (P_n ~ 1e6 m^-2 at a 1 mm spread) meets a loose joint constraint, that
curvature outweighs the joint precision in the directions the task leaves free, and the loop
oscillates with growing amplitude (``benchmarks/bench_skill.py``'s skill; a velocity limit
alone only turns that into chatter at top speed). So every step is checked: if it raises E_j,
it is halved (up to ``MAX_HALVINGS`` times, :mod:`pbdkit.reproduction._steps`; a Gauss-Newton step
is a descent direction of E_j, so a short enough step lowers it), the standard line search that
globalizes Gauss-Newton (Nocedal & Wright, Numerical Optimization, ch. 10). The check reuses
f(theta_{j+1}), which the next step needs anyway, and changes nothing where Table II converges
(the steps lower E_j already). ``line_search=False`` gives the paper's loop as written.

The line search alone leaves a limit cycle whose steps each lower E_j: a joint reversing at every
step at the velocity bound (measured on the simulated teacher's coaster skills, seeds 0-9 and 4
placements: 35-128 reversals between fast steps in 6 of 40 reproductions). Its cause is the
curvature Gauss-Newton drops, so the step also uses Newton's Hessian (``newton=True``, the
default): E_j's exact Hessian adds sum_i w_i d^2 f_i / d theta^2 with w = sum_n P_n (f(theta) -
o(n) - x_hat^(n)) = P x - h, and for a serial chain d^2 x / (d theta_a d theta_b) =
omega_a x J_b (a <= b; omega_a the world axis of revolute joint a, J_b the position Jacobian's
column), so the (a, b) entry is (w x omega_a) . J_b: one more n x n product and Cholesky solve
per step, from the frame Jacobian's angular rows (:meth:`pbdkit.Robot.fk_jacobian_axes_unchecked`).
The Newton step is taken where its Hessian is positive definite and the step is shorter than
Gauss-Newton's (where the curvature stiffens it: the directions Gauss-Newton overshoots in);
elsewhere the Gauss-Newton step. Measured: the 35-128 reversals become 0, at the same accuracy
(``tests/test_motion.py``); it costs about 40 % of a step (``benchmarks/bench_motion.py``). A
robot without the axes gets Gauss-Newton steps.

Motion limits. The loop above computes the path, one posture per step of the skill's time grid.
What a real arm needs is a timing within its velocity, acceleration and jerk limits, starting and
ending at rest; Table II at the demonstrations' pace asks up to 20-115 rad/s^2 of the Katana
(limit 6) and starts from rest at full speed. With ``limits`` (:meth:`pbdkit.Skill.reproduce`
gives the robot's by default) the result is :func:`timed_path`'s:

1. a lead-in: the time-optimal jerk-limited move (:func:`pbdkit.motion._otg.point_to_point`) from
   ``q0`` to the skill's first posture (:func:`first_posture`: Table II's step 0 iterated until
   still, the product of the constraints at t_0), so that a start away from it is a separate
   move and the skill keeps its own timing;
2. Table II from that posture, without a velocity bound (``step_limit`` is not used; the
   trust region ``max_step``, the line search, Newton's term and the joint limits apply);
3. the timing: :func:`pbdkit.motion._limits.retime` gives every step the demonstrations' duration
   ``dt``, or more where the limits need it (stretching a neighbourhood by f divides
   velocities by f, accelerations by f^2, jerks by f^3), until the samples played at those
   times, padded with rest at both ends, are within the limits by divided differences. The
   postures are kept exactly: every constraint is met where it was, the gripper events stay
   with their steps, and :attr:`ReproductionResult.stretch` says how much longer the skill's
   part became. A step is never made shorter than ``dt``. Clipping at a joint limit, which stops
   a joint within one step, is slowed by the same rule.

The samples carry velocities and accelerations (:attr:`ReproductionResult.velocities`: the
clamped cubic spline's through them at their times, the lead-in's own), for a
``JointTrajectory`` or a follower: :func:`pbdkit.motion._otg.follow` turns them into a continuous
jerk-limited motion sampled at any rate (the simulator's 500 Hz servos, a 1 kHz loop). The
limits are planned at :data:`pbdkit.motion._limits.LIMIT_SAFETY` of the declared ones so that
rounding never puts a measured value above them. The online controller plans with :func:`timed_path`
too, from a state along the way (a moving start, at a phase).

Reach. With ``reach`` given (a :class:`pbdkit.Skill` passes its estimate, see
:func:`reach_from_samples`), every object in use is checked before the loop: at the step where
its task constraint is tightest (smallest trace of Sigma^x(n)) the hand must be at
o(n) + x_hat^(n); if that point is farther from the base origin than ``reach``, the object is out
of reach: ``on_unreachable="raise"`` (default) raises ValueError, ``"warn"`` issues a
:class:`ReachWarning` and reproduces anyway: the hand stretches toward the target and stops
short; the result stays finite and within the limits (damped pseudo-inverse, step size,
clipping).

Influence of the constraints (paper Fig. 6). Fig. 6 shows which constraint drives the hand when,
so the share of a constraint is measured in the hand's space. With Sigma the fused covariance of
the posture and J the Jacobian of the step, the hand's covariance is S = J Sigma J^T (3 x 3). By
Woodbury, with Sigma = (Lambda_theta + J^T P J)^-1 and P = sum_n P_n,

    S^-1 = (J Sigma_theta J^T)^-1 + sum_n P_n       (precisions add in hand space),

so the share of task constraint n and that of the joint constraint are

    share_n = tr(S P_n) / 3,      share_joint = 1 - sum_n share_n
                                              (= tr(S (J Sigma_theta J^T)^-1) / 3, J of full rank).

Computing share_joint as 1 - sum avoids inverting J Sigma_theta J^T near a singularity. Each
share is in [0, 1], they sum to 1, and a tight task constraint reaches ~1: it then dictates the
hand's position. The shares do not change under a linear change of joint or hand coordinates
(units). Task-only controllers fuse the task constraints in task space first:
share_n = tr(S_fused P_n) / 3 with S_fused = (sum_n P_n)^-1; the joint-only controller has
share_joint = 1.

``ReproductionResult.influence_joint_space`` keeps the share in joint space,
tr(Sigma Lambda_c) / n (Lambda_c the joint-space precision of constraint c, J^T P_n J for task
constraint n), also summing to 1. It tells who governs the posture, including the directions the
hand position does not see (on the 5-DOF Katana the wrist roll, which only the joint constraint
governs): a task constraint informs at most 3 of the n directions, so its share there is at most
3/n (0.6 on the Katana) and never looks dominant, which is why it is not the headline measure.
For the task-only controllers it equals ``influence`` (their covariance J+ S_fused J+^T has rank
3: there is no joint-space precision to compare).

Performance. Every GMR output is independent of the state, so :class:`Constraints` evaluates
them once over the whole grid and precomputes, batched, the joint precisions and information
vectors and the task precisions P_n = (Sigma^x(n))^-1 (Cholesky, no ``inv`` of a covariance). As
every task constraint shares J, sum_n J^T P_n J = J^T (sum_n P_n) J and
sum_n J^T P_n dx^(n) = J^T (h - (sum_n P_n) x_j) with h = sum_n P_n (o(n) + x_hat^(n)), both sums
precomputed for all steps: inside the loop there are only the robot's fk/Jacobian, a few products
of (n, 3) matrices and one n x n Cholesky solve (LAPACK ``dposv``), whatever the number of
objects; a step is bounded by ``step_limit`` and ``max_step`` at the cost of one comparison of
its squared length unless it is long enough for a bound to bind. Covariances and influences are
computed after the loop, batched.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import log_map
from .._validation import check_array, check_positive_float
from ..data._placement import check_placements, is_pose, position_of
from ..motion._limits import (
    LIMIT_SAFETY,
    MotionLimits,
    positive_bounds,
    retime,
    times_from_durations,
)
from ..motion._otg import point_to_point, spline_derivatives
from ._constraints import JOINT, Constraints, KinematicModel
from ._pose_steps import PoseFusedStep, PoseTaskStep, _pose_loop
from ._steps import (
    ControllerStep,
    FusedStep,
    JointStep,
    RunSetup,
    TaskStep,
    _fused_loop,
    _joint_only,
    _task_loop,
)

__all__ = [
    "ReachWarning",
    "ReproductionResult",
    "RunOptions",
    "RunSetup",
    "check_objects",
    "check_timing",
    "first_posture",
    "make_step",
    "reach_from_samples",
    "setup_run",
    "solve",
    "step_limit_from_velocity",
    "timed_path",
]

Float = NDArray[np.float64]
#: The lead-in is planned at this fraction of the limits the whole reproduction is timed with.
LEAD_IN_MARGIN = 0.999
#: The lead-in's samples are at least this far apart (s), whatever the skill's step.
LEAD_IN_PERIOD = 0.01
# step_limit = v dt VELOCITY_SAFETY: floating-point rounding never plays a step above v.
VELOCITY_SAFETY = 1.0 - 1e-6


class ReachWarning(UserWarning):
    """An object's constrained target lies beyond the arm's reach (the hand stops short)."""


@dataclass(frozen=True, eq=False)
class ReproductionResult:
    """Outcome of a reproduction.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Time of each step (steps 0 .. T-1 for a :class:`pbdkit.Skill`).
    joints : ndarray, shape (T, n)
        theta_j, within the joint limits.
    positions : ndarray, shape (T, 3)
        Hand positions x_j = f(theta_j) in the base frame.
    covariances : ndarray, shape (T, n, n)
        Covariance of the posture at each step: the fused Sigma_j of eq. (1) (information form)
        when the joint constraint is in use; Sigma^theta for the joint-only controller;
        J+ Sigma^x J+^T (rank 3) for task-only controllers.
    gripper : ndarray of bool, shape (T,)
        Generalized gripper signal > 0.5 (closed); all False if the skill has no gripper.
    gripper_signal : ndarray, shape (T,) or None
        The generalized (continuous) gripper signal, None if the skill has no gripper.
    influence : dict str -> ndarray, shape (T,)
        Share of each constraint in use in the hand's space (paper Fig. 6): tr(S P_n) / 3 for
        task constraint n, S = J Sigma J^T the hand's covariance, and 1 - their sum for the joint
        constraint. Each in [0, 1], summing to 1 at each step (module docstring, "Influence").
    influence_joint_space : dict str -> ndarray, shape (T,)
        Share of each constraint in joint space, tr(Sigma Lambda_c) / n, summing to 1: who
        governs the posture, including the directions the hand does not see (a task
        constraint's share is at most 3/n there). Task-only controllers: equal to ``influence``.
    task_errors : dict str -> ndarray, shape (T,)
        For every object (in use or not): ||x_j - (o(n) + x_hat^(n)_j)|| in metres, the distance
        from the hand to where that object's constraint expects it.
    used : tuple of str
        The constraints in use.
    limited : ndarray of bool, shape (T,)
        True at the steps j whose step theta_{j-1} -> theta_j was scaled down by ``step_limit``
        (the velocity limit) or ``max_step``; with motion limits (``limits``), the steps whose
        duration the limits stretched. False at step 0.
    times : ndarray, shape (T,), or None
        With motion limits: the time (s) of each sample, from 0, such that the samples played
        at these times respect the limits, starting and ending at rest (module docstring,
        "Motion limits"). None without them (:meth:`pbdkit.Skill.times` then spreads the steps
        over the skill's duration).
    velocities, accelerations : ndarray, shape (T, n), or None
        With motion limits: joint velocities and accelerations at the samples, from the timing
        (the derivatives of the cubic spline through the samples at ``times``, at rest at both
        ends; the lead-in's samples carry the time-optimal move's own, at rest where it
        arrives), e.g. for a ``JointTrajectory``.
    lead_in : ndarray of bool, shape (T,)
        True for the samples of the lead-in move from ``q0`` to the skill's first posture
        (their ``t`` is the first step's); all False without motion limits.
    nominal_dt : float
        With motion limits: the duration of a step at the demonstrations' pace (s); NaN
        without. :attr:`stretch` compares the timing with it.
    orientations : ndarray, shape (T, 3, 3), or None
        For a skill with oriented constraints: the hand's orientation R_hand at each sample
        (the tip frame's axes in the base frame, :meth:`pbdkit.Robot.fk_pose`); None for a
        skill of positions only.
    orientation_errors : dict str -> ndarray, shape (T,)
        For every oriented object (in use or not): the angle (rad) between the hand's
        orientation and the one its constraint expects, the norm of log(R_hand R_target^T).

    With motion limits the result has a sample per step of the skill plus the lead-in samples:
    T = L + n_steps.
    """

    t: Float
    joints: Float
    positions: Float
    covariances: Float
    gripper: NDArray[np.bool_]
    gripper_signal: Float | None
    influence: dict[str, Float]
    influence_joint_space: dict[str, Float]
    task_errors: dict[str, Float]
    used: tuple[str, ...]
    limited: NDArray[np.bool_]
    times: Float | None = None
    velocities: Float | None = None
    accelerations: Float | None = None
    lead_in: NDArray[np.bool_] | None = None
    nominal_dt: float = float("nan")
    orientations: Float | None = None
    orientation_errors: dict[str, Float] = dataclasses.field(default_factory=dict)

    @property
    def stretch(self) -> float:
        """How much longer the motion limits made the skill's own part (after the lead-in)
        than the steps at their nominal duration: 1.0 where nothing was slowed; NaN without
        motion limits."""
        if self.times is None or self.lead_in is None:
            return float("nan")
        start = int(np.count_nonzero(self.lead_in))
        own = self.times[start:]
        nominal = self.nominal_dt * (own.shape[0] - 1)
        return float((own[-1] - own[0]) / nominal) if nominal > 0 else float("nan")


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
                    f"{name}[{k!r}] must be a pose (a 4x4 transform or x, y, z, qw, qx, qy, qz): "
                    f"the skill learned the hand's position and orientation in the frame of {k!r}; "
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
            f"use must be None, a constraint name or a sequence of names, got {use!r}; "
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
    """Compare each object's most constrained target with the arm's reach (module docstring)."""
    for k, o in objs.items():
        # The step where the constraint is tightest is where the hand must be at o + x_hat.
        j = int(np.argmin(np.trace(constraints.position_cov(k), axis1=1, axis2=2)))
        if k in constraints.rotation_base:  # p + R m for a pose
            target = o[:3, 3] + o[:3, :3] @ constraints.task_mean[k][j, :3]
        else:
            target = o + constraints.task_mean[k][j]
        dist = float(np.linalg.norm(target))
        if dist > reach:
            msg = (
                f"objects[{k!r}]: the hand must be at {np.round(target, 4).tolist()} at step "
                f"{j} (o + x_hat, where this object's constraint is tightest), "
                f"{dist:.3f} m from the base, beyond the arm's reach of {reach:.3f} m; "
                "move the object closer"
            )
            if on_unreachable == "raise":
                raise ValueError(msg)
            warnings.warn(msg + " (the hand will stop short)", ReachWarning, stacklevel=3)


@dataclass(frozen=True, eq=False)
class RunOptions:
    """How a reproduction or a controller run goes: the options :meth:`pbdkit.Skill.reproduce`,
    :meth:`pbdkit.Skill.controller`, :func:`solve` and :class:`pbdkit.Controller` share, in one
    object (each is described at :meth:`pbdkit.Skill.reproduce`).

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
        when ``"joint"`` is in use (see the module docstring).
    max_step : float or None
        Largest joint-space step (Euclidean norm over the joints, rad): a longer step is scaled
        down, keeping its direction (module docstring, "Step size"). None: no such bound.
    on_unreachable : {"raise", "warn"}
        With a reach: raise ValueError for an object out of reach, or warn with
        :class:`ReachWarning` and reproduce anyway (the hand then stops short).
    line_search : bool
        Fused controller: shorten a step that would raise the fused energy of its step (module
        docstring, "Stability"). False: the paper's loop as written.
    newton : bool
        Fused controller: use the curvature of the forward kinematics where it stiffens a step
        (module docstring, "Stability"; it needs ``robot.fk_jacobian_axes_unchecked``, which a
        :class:`pbdkit.Robot` has). False: Gauss-Newton steps only.
    """

    q0: npt.ArrayLike | None = None
    use: Sequence[str] | str | None = None
    alpha: float = 0.5
    max_step: float | None = 0.1
    on_unreachable: Literal["raise", "warn"] = "raise"
    line_search: bool = True
    newton: bool = True


def setup_run(
    robot: KinematicModel,
    constraints: Constraints,
    objects: Mapping[str, npt.ArrayLike],
    options: RunOptions,
    *,
    step_limit: npt.ArrayLike | None = None,
    reach: float | None = None,
) -> RunSetup:
    """Validate the inputs shared by :func:`solve` and the online controller."""
    c = constraints
    if not isinstance(c, Constraints):
        raise ValueError(f"constraints must be a Constraints, got {type(c).__name__}")
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
        raise ValueError(f"on_unreachable must be 'raise' or 'warn', got {on_unreachable!r}")
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
        c,
        objs,
        used,
        tasks,
        alpha,
        step_cap,
        bound,
        lower,
        upper,
        theta0,
        bool(options.line_search),
        bool(options.newton),
        None if reach is None else float(reach),
        on_unreachable,
    )


def check_timing(limits: MotionLimits | None, dt: float | None) -> bool:
    """Whether ``limits`` apply to a run (any of them set); they are per second and need the
    duration of a step, ``dt`` > 0 (s): ValueError otherwise."""
    timed = limits is not None and limits.any
    if timed and (dt is None or not (math.isfinite(dt) and dt > 0)):
        raise ValueError(
            f"limits are in seconds and need the duration of a step: pass dt > 0 (s), got {dt!r}"
        )
    return timed


def solve(
    robot: KinematicModel,
    constraints: Constraints,
    objects: Mapping[str, npt.ArrayLike],
    options: RunOptions | None = None,
    *,
    step_limit: npt.ArrayLike | None = None,
    reach: float | None = None,
    limits: MotionLimits | None = None,
    dt: float | None = None,
) -> ReproductionResult:
    """Closed-loop reproduction of Table II for new object positions: the probabilistic
    inverse kinematics over the whole time grid (what :meth:`pbdkit.Skill.reproduce` runs).

    Parameters
    ----------
    robot : KinematicModel
        The arm (e.g. :class:`pbdkit.Robot`); n joints, as the constraints.
    constraints : Constraints
        The skill's generalized constraints over T steps.
    objects : dict str -> array-like, shape (3,), (4, 4) or (7,)
        Where every object of the skill is, in the robot's base frame: a position o(n), or a
        pose (4x4, or x, y, z, qw, qx, qy, qz, quaternion w first), which an oriented
        constraint needs (:func:`check_objects`).
    options : RunOptions, optional
        The start posture, the constraints in use and how the loop steps (default
        ``RunOptions()``: every constraint fused, from theta_hat_0).
    step_limit : float or array-like, shape (n,), optional
        Largest step of each joint (rad per step; a number applies to every joint, inf leaves a
        joint unbounded): a step with ``|dtheta_i| > step_limit_i`` for some joint is scaled down
        uniformly, keeping its direction, before ``max_step`` applies. Velocity limits v (rad/s)
        give v dt (:func:`step_limit_from_velocity`). None (default): no per-joint bound.
        Not used with ``limits`` (the timing bounds the speed there).
    reach : float, optional
        Reach of the arm (m, from the base origin). If given, the most constrained target
        o + x_hat of every object in use is checked against it (``options.on_unreachable``
        says what then happens; the result stays finite and within limits).
    limits : MotionLimits, optional
        Velocity, acceleration and jerk limits (module docstring, "Motion limits"): the result
        then has :attr:`ReproductionResult.times` within them, a lead-in from ``q0`` and rest at
        both ends. Needs ``dt``.
    dt : float, optional
        The duration of a step at the demonstrations' pace (s), with ``limits``.

    Returns
    -------
    result : ReproductionResult
    """
    timed = check_timing(limits, dt)
    if timed:
        step_limit = None  # the timing bounds the speed
    run = setup_run(
        robot,
        constraints,
        objects,
        RunOptions() if options is None else options,
        step_limit=step_limit,
        reach=reach,
    )
    if timed:
        assert limits is not None and dt is not None
        return timed_path(robot, run, limits, dt)
    path = _table_ii(robot, run, run.theta0)
    return _result(robot, run, run.constraints.t.copy(), path, None, None, None, None, float("nan"))


def timed_path(
    robot: KinematicModel,
    run: RunSetup,
    limits: MotionLimits,
    dt: float,
    *,
    theta: Float | None = None,
    phase: float = 0.0,
    velocity: Float | None = None,
) -> ReproductionResult:
    """The reproduction within motion limits (module docstring, "Motion limits"), from the
    start or from a state along the way.

    From the start (``phase`` 0, ``velocity`` None): a lead-in from ``theta`` (default
    ``run.theta0``) to the skill's first posture (:func:`first_posture`), then Table II from
    there. Along the way (what the online controller re-plans from): Table II from ``theta``
    at ``phase`` (steps floor(phase) + 1 .. T - 1 follow), the path starting at ``velocity``
    (rad/s). Either way the samples are timed by :func:`pbdkit.motion._limits.retime` (within
    ``limits`` times :data:`pbdkit.motion._limits.LIMIT_SAFETY`, at rest at the end), and their
    velocities and accelerations are those of the cubic spline through them at those times.

    Returns
    -------
    ReproductionResult
        Its ``t`` holds each sample's phase (``phase`` for the first one along the way, the
        first step's for the lead-in); ``times`` start at 0.
    """
    c = run.constraints
    plan = limits.scaled(LIMIT_SAFETY)
    theta0 = run.theta0 if theta is None else np.asarray(theta, dtype=np.float64)
    moving = velocity is not None and bool(np.any(velocity))
    step = make_step(robot, run)
    if phase <= 0.0 and not moving:
        start = first_posture(robot, run, step=step)
        path = _table_ii(robot, run, start, step=step)
        steps = c.t.copy()
        # Planned a little inside `plan`, so that rounding never puts it above what is checked;
        # sampled every step, or every LEAD_IN_PERIOD s for a skill of very short steps.
        lead_dt = max(float(dt), LEAD_IN_PERIOD)
        lead_q, lead_v, lead_a = point_to_point(theta0, start, lead_dt, plan.scaled(LEAD_IN_MARGIN))
    else:
        first = min(math.floor(phase), c.n_steps - 1)
        path = _table_ii(robot, run, theta0, start=first, step=step)
        steps = c.t[first:].copy()
        steps[0] = min(float(phase), float(c.n_steps - 1))
        lead_q = lead_v = lead_a = theta0[:0].reshape(0, theta0.shape[0])
        lead_dt = float(dt)
    joints, positions, covs, influence, influence_js, limited = path
    n_lead = lead_q.shape[0] - 1 if lead_q.shape[0] else 0  # its last sample is the path's first
    lead_q = lead_q[:n_lead]
    lead = np.zeros(joints.shape[0], dtype=bool)
    if n_lead:
        joints = np.concatenate([lead_q, joints])
        positions = np.concatenate([np.asarray(robot.fk(lead_q), dtype=np.float64), positions])
        covs, steps = _lead(covs, n_lead), _lead(steps, n_lead)
        influence = {k: _lead(v, n_lead) for k, v in influence.items()}
        influence_js = {k: _lead(v, n_lead) for k, v in influence_js.items()}
        lead = np.concatenate([np.ones(n_lead, dtype=bool), lead])
    v0 = np.asarray(velocity, dtype=np.float64) if moving else None
    if joints.shape[0] == 1:  # the last step already: stay
        joints = np.concatenate([joints, joints])
        positions, covs, steps, lead = (
            np.concatenate([a, a]) for a in (positions, covs, steps, lead)
        )
        influence = {k: np.concatenate([v, v]) for k, v in influence.items()}
        influence_js = {k: np.concatenate([v, v]) for k, v in influence_js.items()}
    nominal = np.full(joints.shape[0] - 1, float(dt))
    if n_lead:
        nominal[:n_lead] = lead_dt
    h = retime(joints, nominal, plan, start_velocity=v0)
    times = times_from_durations(h)
    limited = np.concatenate([[False], h > nominal * (1.0 + 1e-9)])
    velocities, accelerations = spline_derivatives(times, joints, v0)
    if n_lead and np.all(h[:n_lead] == lead_dt):
        # The lead-in's own derivatives, at rest where it arrives (a time-optimal move: the
        # spline through its samples would ask for more jerk than it has).
        velocities[: n_lead + 1] = lead_v
        accelerations[: n_lead + 1] = lead_a
    path = (joints, positions, covs, influence, influence_js, limited)
    return _result(robot, run, steps, path, times, velocities, accelerations, lead, float(dt))


def _result(
    robot: KinematicModel | None,
    run: RunSetup,
    steps: Float,
    path: tuple[Float, Float, Float, dict[str, Float], dict[str, Float], NDArray[np.bool_]],
    times: Float | None,
    velocities: Float | None,
    accelerations: Float | None,
    lead: NDArray[np.bool_] | None,
    nominal_dt: float,
) -> ReproductionResult:
    """A :class:`ReproductionResult` from a path and the phase of its samples."""
    c, objs = run.constraints, run.objects
    joints, positions, covs, influence, influence_js, limited = path
    index = np.asarray(np.floor(steps + 1e-9), dtype=np.intp)
    world = {k: c.world_task(k, o) for k, o in objs.items()}
    task_errors = {
        k: np.linalg.norm(positions - w.position[index], axis=1) for k, w in world.items()
    }
    orientations = None
    orientation_errors: dict[str, Float] = {}
    if c.oriented:
        assert robot is not None
        orientations = np.asarray(robot.fk_pose(joints), dtype=np.float64)[:, :3, :3]  # type: ignore[attr-defined]
        for k, w in world.items():
            if w.rotation is not None:
                err = log_map(orientations @ np.swapaxes(w.rotation[index], -1, -2))
                orientation_errors[k] = np.linalg.norm(err, axis=1)
    signal = None if c.gripper is None else c.gripper[index].copy()
    closed = np.zeros(index.shape[0], dtype=bool) if signal is None else signal > 0.5
    return ReproductionResult(
        t=np.asarray(steps, dtype=np.float64),
        joints=joints,
        positions=positions,
        covariances=covs,
        gripper=closed,
        gripper_signal=signal,
        influence=influence,
        influence_joint_space=influence_js,
        task_errors=task_errors,
        used=tuple(run.used),
        limited=limited,
        times=times,
        velocities=velocities,
        accelerations=accelerations,
        lead_in=np.zeros(joints.shape[0], dtype=bool) if lead is None else lead,
        nominal_dt=nominal_dt,
        orientations=orientations,
        orientation_errors=orientation_errors,
    )


def _lead(a: NDArray[Any], n_lead: int) -> NDArray[Any]:
    """``a`` with its first row repeated ``n_lead`` times in front (the lead-in's samples)."""
    return np.concatenate([np.repeat(a[:1], n_lead, axis=0), a])


def make_step(robot: KinematicModel, run: RunSetup) -> ControllerStep:
    """The step of the controller ``run`` asks for (its constraints in use): the one place
    the offline loop (:func:`solve`) and the online controller get it from."""
    oriented = any(k in run.constraints.rotation_base for k in run.tasks)
    if oriented and not hasattr(robot, "fk_pose_jacobian_unchecked"):
        raise ValueError(
            "oriented task constraints need the tip's orientation and 6-D Jacobian: the robot "
            "must provide fk_pose and fk_pose_jacobian_unchecked (pbdkit.Robot does), got "
            f"{type(robot).__name__}"
        )
    if JOINT not in run.used:
        return PoseTaskStep(robot, run) if oriented else TaskStep(robot, run)
    if run.tasks:
        return PoseFusedStep(robot, run) if oriented else FusedStep(robot, run)
    return JointStep(run)


def _table_ii(
    robot: KinematicModel,
    run: RunSetup,
    theta0: Float,
    *,
    start: int = 0,
    step: ControllerStep | None = None,
) -> tuple[Float, Float, Float, dict[str, Float], dict[str, Float], NDArray[np.bool_]]:
    """The loop of the controller ``run`` asks for, from ``theta0`` at step ``start``: joints,
    positions, covariances, influence (hand space and joint space) and the mask of scaled
    steps, for steps ``start`` .. T - 1 (row 0: ``theta0``). ``step``: the controller's step
    (:func:`make_step`), if already built."""
    c = run.constraints
    step = make_step(robot, run) if step is None else step
    if isinstance(step, FusedStep):
        return _fused_loop(c, run.tasks, theta0, step, start=start)
    if isinstance(step, JointStep):
        joints, limited = _joint_only(step, theta0, start=start)
        positions = np.asarray(robot.fk(joints), dtype=np.float64)
        ones = {JOINT: np.ones(c.n_steps - start)}
        covs = c.joint_cov[start:].copy()
        return joints, positions, covs, ones, {JOINT: ones[JOINT].copy()}, limited
    if isinstance(step, (PoseFusedStep, PoseTaskStep)):
        return _pose_loop(c, step, theta0, start=start)
    assert isinstance(step, TaskStep)
    joints, positions, covs, influence, limited = _task_loop(step, theta0, start=start)
    # Rank-3 covariance: no joint-space precision to compare; the task-space shares.
    influence_js = {k: v.copy() for k, v in influence.items()}
    return joints, positions, covs, influence, influence_js, limited


#: first_posture: at most this many steps at t_0, and the step length (rad) that counts as still.
FIRST_POSTURE_STEPS = 500
FIRST_POSTURE_TOL = 1e-9


def first_posture(
    robot: KinematicModel,
    run: RunSetup,
    *,
    step: ControllerStep | None = None,
) -> Float:
    """The skill's first posture for the controller of ``run``: Table II's step 0 iterated from
    theta_hat_0 (clipped to the limits) until it stands still, i.e. the product of the
    constraints at t_0 (the joint-only controller: theta_hat_0 itself).

    It does not depend on where the arm is: a reproduction from any q0 begins with a lead-in
    move to it, then the skill runs with its own timing (module docstring, "Motion limits").
    ``step``: the controller's step for ``run`` (:func:`make_step`), if already built.
    """
    c = run.constraints
    theta = np.clip(c.joint_mean[0], run.lower, run.upper)
    if not run.tasks:
        return np.asarray(theta, dtype=np.float64)
    if step is None:
        step = make_step(robot, run)
    if isinstance(step, (TaskStep, PoseTaskStep, PoseFusedStep)) and step.step_limit is not None:
        # Standing still at t_0 is not bounded by a speed: the step without its velocity bound.
        step = type(step)(robot, dataclasses.replace(run, step_limit=None))
    x: Float | None
    jac: Float | None
    x, jac, axes = step.kinematics(theta)
    for _ in range(FIRST_POSTURE_STEPS):
        new, x, jac, axes, _limited = step.advance(0, theta, x, jac, axes)
        moved = float(np.abs(new - theta).max())
        theta = new
        if moved <= FIRST_POSTURE_TOL:
            break
    return np.asarray(theta, dtype=np.float64)


def step_limit_from_velocity(
    velocity_limit: float | npt.ArrayLike | Literal["robot"] | None,
    robot: KinematicModel,
    dt: float,
) -> Float | None:
    """Per-joint step bound for :func:`solve` from joint velocity limits.

    Parameters
    ----------
    velocity_limit : "robot", float, array-like of shape (n,), or None
        In rad/s. ``"robot"``: ``robot.velocity_limit`` (a :class:`pbdkit.Robot` has its URDF's)
        with the joints whose limit is 0, negative, NaN or inf left unlimited; no limit if the
        robot has no such attribute or ``dt`` is unknown. A number (every joint) or one value
        per joint, > 0 (inf leaves a joint unlimited). None: no limit.
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
                f"or None, got {velocity_limit!r}"
            )
        urdf = getattr(robot, "velocity_limit", None)
        if urdf is None or not known:
            return None
        v = check_array(urdf, "robot.velocity_limit", shape=(n,), finite=False)
        # A URDF writes 0 (or leaves out) the limit of a joint it does not limit.
        v = np.where(np.isfinite(v) & (v > 0), v, np.inf)
    else:
        if not known:
            raise ValueError(
                "velocity_limit is in rad/s and needs the duration of a step to bound the steps; "
                f"it is unknown (dt = {dt!r}: the skill has no known duration): pass "
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
