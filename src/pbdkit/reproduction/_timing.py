"""A reproduction within motion limits: the lead-in to the skill's first posture, Table II's
path, and its timing (:func:`timed_path`), from the start or from a state along the way.

The steps get the demonstrations' duration ``dt``, or more where the limits need it
(:func:`pbdkit.motion._limits.retime`: stretching a neighbourhood by f divides velocities by f,
accelerations by f^2, jerks by f^3); the postures are kept exactly. Why, and how the lead-in
and the online controller's re-plans use it: :doc:`/reproduction`, "Motion limits and lead-in".
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import short
from ..motion._limits import LIMIT_SAFETY, MotionLimits, retime, times_from_durations
from ..motion._otg import point_to_point, spline_derivatives
from ..robots._protocols import KinematicModel
from ._pose_steps import PoseFusedStep, PoseTaskStep
from ._result import ReproductionResult
from ._setup import RunSetup
from ._steps import ControllerStep, LoopOutput, TaskStep
from ._table_ii import _path_result, _table_ii, make_step

__all__ = ["check_timing", "first_posture", "timed_path"]

Float = NDArray[np.float64]
#: The lead-in is planned at this fraction of the limits the whole reproduction is timed with.
LEAD_IN_MARGIN = 0.999
#: The lead-in's samples are at least this far apart (s), whatever the skill's step.
LEAD_IN_PERIOD = 0.01


def check_timing(limits: MotionLimits | None, dt: float | None) -> bool:
    """Whether ``limits`` apply to a run (any of them set); they are per second and need the
    duration of a step, ``dt`` > 0 (s): ValueError otherwise."""
    timed = limits is not None and limits.any
    if timed and (dt is None or not (math.isfinite(dt) and dt > 0)):
        raise ValueError(
            "limits are in seconds and need the duration of a step: pass dt > 0 (s), got "
            f"{short(dt)}"
        )
    return timed


def timed_path(
    robot: KinematicModel,
    run: RunSetup,
    limits: MotionLimits,
    dt: float,
    *,
    theta: Float | None = None,
    phase: float = 0.0,
    velocity: Float | None = None,
    slower: Float | None = None,
) -> ReproductionResult:
    """The reproduction within motion limits (:doc:`/reproduction`, "Motion limits and
    lead-in"), from the start or from a state along the way.

    From the start (``phase`` 0, ``velocity`` None): a lead-in from ``theta`` (default
    ``run.theta0``) to the skill's first posture (:func:`first_posture`), then Table II from
    there. Along the way (what the online controller re-plans from): Table II from ``theta``
    at ``phase`` (steps floor(phase) + 1 .. T - 1 follow), the path starting at ``velocity``
    (rad/s). ``slower``: a factor (>= 1) on the nominal duration of each of the path's steps
    (the online controller's plans where the motion would otherwise leave a joint limit).
    Either way the samples are timed by :func:`pbdkit.motion._limits.retime` (within
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
    if run.avoid is not None:  # where the clearance bent the path
        bent = run.avoid.slower(joints.shape[0], n_lead)
        if bent is not None:
            slower = bent if slower is None else slower * bent
    if slower is not None:
        nominal = nominal * slower
    h = retime(joints, nominal, plan, start_velocity=v0)
    times = times_from_durations(h)
    limited = np.concatenate([[False], h > nominal * (1.0 + 1e-9)])
    velocities, accelerations = spline_derivatives(times, joints, v0)
    if n_lead and np.all(h[:n_lead] == lead_dt):
        # The lead-in's own derivatives, at rest where it arrives (a time-optimal move: the
        # spline through its samples would ask for more jerk than it has).
        velocities[: n_lead + 1] = lead_v
        accelerations[: n_lead + 1] = lead_a
    path = LoopOutput(joints, positions, covs, influence, influence_js, limited)
    return _path_result(
        robot,
        run,
        steps,
        path,
        times=times,
        velocities=velocities,
        accelerations=accelerations,
        lead=lead,
        nominal_dt=float(dt),
    )


def _lead(a: NDArray[Any], n_lead: int) -> NDArray[Any]:
    """``a`` with its first row repeated ``n_lead`` times in front (the lead-in's samples)."""
    return np.concatenate([np.repeat(a[:1], n_lead, axis=0), a])


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
    move to it, then the skill runs with its own timing (:doc:`/reproduction`, "Motion limits
    and lead-in"). ``step``: the controller's step for ``run``
    (:func:`~pbdkit.reproduction._table_ii.make_step`), if already built.
    """
    c = run.constraints
    theta = np.clip(c.joint_mean[0], run.lower, run.upper)
    if not run.tasks:
        return np.asarray(theta, dtype=np.float64)
    if step is None:
        step = make_step(robot, run)
    if isinstance(step, (TaskStep, PoseTaskStep, PoseFusedStep)) and step.step_limit is not None:
        # Standing still at t_0 is not bounded by a speed: the step without its velocity bound.
        step = make_step(robot, dataclasses.replace(run, step_limit=None))  # the same kind
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
