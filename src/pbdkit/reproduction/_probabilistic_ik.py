"""Reproduction of a skill by probabilistic inverse kinematics (paper Table II): :func:`solve`.

Given a skill's generalized constraints over its time grid (:class:`Constraints`) and the new
placements o(n) of the objects, the closed loop of Table II computes theta_0 .. theta_{T-1}. At
step j -> j+1, with x_j = f(theta_j) and J = J(theta_j):

- joint-space constraint: dtheta^(joint) = theta_hat_{j+1} - theta_j, covariance
  Sigma^theta_{j+1};
- task-space constraint of object n: dx^(n) = (o(n) + x_hat^(n)_{j+1}) - x_j, covariance
  Sigma^x(n)_{j+1};
- fused, eq. (1) in information form with Lambda^(n) = J^T (Sigma^x(n))^-1 J (the pseudo-inverse
  of the paper's rank-3 J+ Sigma^x(n) J+^T; the null-space term cancels)::

      dtheta = (Lambda^(joint) + sum_n Lambda^(n))^-1 (Lambda^(joint) dtheta^(joint)
               + sum_n J^T (Sigma^x(n))^-1 dx^(n)),   Sigma_{j+1} = (sum of the precisions)^-1;

- task-only: the task constraints fused in task space, then
  dtheta = J+ dx + alpha (I - J+ J)(theta_hat_{j+1} - theta_j), J+ = J^T (J J^T + lambda^2 I)^-1.

Every step is bounded (``step_limit``, ``max_step``), clipped to the joint limits, and the fused
step is line-searched on the fused energy of its step with Newton's curvature term (Nocedal &
Wright, Numerical Optimization, ch. 10). The run is set up by :mod:`._setup`, looped by
:mod:`._table_ii` with the steps of :mod:`._steps` and :mod:`._pose_steps`, and timed within
motion limits by :mod:`._timing`; the result is a :class:`ReproductionResult`. The derivations,
and where they depart from the paper's text: :doc:`/reproduction`.

Reference: S. Calinon and A. Billard, "A probabilistic programming by demonstration framework
handling constraints in joint space and task space", IROS 2008.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_positive_float
from ..collision import CollisionChecker, CollisionReport, Scene
from ..motion._limits import MotionLimits
from ..robots._protocols import KinematicModel
from ._avoid import DEFAULT_MARGIN, MAX_PASSES, TOLERANCE, Avoidance
from ._constraints import JOINT, Constraints
from ._result import ReproductionResult
from ._setup import RunOptions, RunSetup, setup_run
from ._steps import CLEARANCE
from ._table_ii import _path_result, _table_ii
from ._timing import check_timing, timed_path

__all__ = ["CollisionWarning", "SceneRun", "solve", "with_scene"]

#: Makes a run again with a run set-up (its avoidance set): from the start, or from a state
#: along the way.
Remake = Callable[[RunSetup], ReproductionResult]

#: A task constraint is tight where its standard deviation, in its loosest direction, is under
#: this (m): there the clearance does not get to move the hand (:func:`_leaves_tight`).
TIGHT = 0.005
#: ... by more than this (m) further from it than the plain run, nor by more than LEFT_SIGMAS
#: of that deviation (a constraint 4.7 mm wide just after the grasp is not left by 5.8 mm: a
#: plan lifted over the box was refused so, on 3 of 50 coaster placements of one skill:
#: the hand's speed at a full weight, docs/alignment.md).
CONFLICT = 0.005
#: In a constraint's tightest phase (its loosest direction's standard deviation within
#: TIGHTEST times its smallest along the path), a hand moved further than LEFT_SIGMAS of those
#: deviations (and CONFLICT) leaves it too: a skill learned 7 mm loose at its grasp is not
#: given up by 20 cm there.
TIGHTEST = 2.0
LEFT_SIGMAS = 3.0
#: Where the passes that go over an obstacle still meet it or leave a tight constraint, passes
#: that go beside it (level, away from it: :class:`._avoid.Avoidance`'s ``beside``) are run
#: too, and kept where they do neither. A path that goes down and away past a box (a coaster
#: skill whose placement is near it) cannot be lifted over it without leaving the placement.
BESIDE = True
#: Where the passes still meet the obstacle, leave a tight constraint, or end short of the
#: margin, passes that hold the encounter's point across the bump's direction
#: (:class:`._avoid.Avoidance`'s ``hold``) are run too, over it and then beside it, and kept
#: where they do neither and keep more clearance. Short of the margin: a coaster plan whose 14
#: passes ended 1.7 mm from the box at its samples went 1.6 mm into it between two; held, 13.4
#: mm at both. Asked for one coordinate, a carried glass was lifted by postures that also swung
#: it back and forth along its way, and the passes met the box somewhere new each time (plans
#: touching the box, teach seeds 0 / 1 / 2 of ``benchmarks/obstacle_plans.py``: 0 / 11 / 29 of
#: 50 before). Not the first try: held along its way, an online re-plan's path took steps that
#: its motion cut through (a test's box kept 2 mm where the passes without it keep 25).
HOLD = True


class CollisionWarning(UserWarning):
    """A reproduction with avoidance still collides: a tight constraint of the skill and the
    clearance cannot both hold (the message names the first sample and the bodies)."""


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
    scene: Scene | None = None,
    avoid: bool = True,
    margin: float = DEFAULT_MARGIN,
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
        constraint needs (:func:`~pbdkit.reproduction._setup.check_objects`).
    options : RunOptions, optional
        The start posture, the constraints in use and how the loop steps (default
        ``RunOptions()``: every constraint fused, from theta_hat_0).
    step_limit : float or array-like, shape (n,), optional
        Largest step of each joint (rad per step; a number applies to every joint, inf leaves a
        joint unbounded): a step with ``|dtheta_i| > step_limit_i`` for some joint is scaled down
        uniformly, keeping its direction, before ``max_step`` applies. Velocity limits v (rad/s)
        give v dt (:func:`~pbdkit.reproduction._setup.step_limit_from_velocity`). None
        (default): no per-joint bound. Not used with ``limits`` (the timing bounds the speed
        there).
    reach : float, optional
        Reach of the arm (m, from the base origin). If given, the most constrained target
        o + x_hat of every object in use is checked against it (``options.on_unreachable``
        says what then happens; the result stays finite and within limits).
    limits : MotionLimits, optional
        Velocity, acceleration and jerk limits (:doc:`/reproduction`, "Motion limits and
        lead-in"): the result then has :attr:`ReproductionResult.times` within them, a lead-in
        from ``q0`` and rest at both ends. Needs ``dt``.
    dt : float, optional
        The duration of a step at the demonstrations' pace (s), with ``limits``.
    scene : pbdkit.Scene, optional
        Obstacles and object shapes (:doc:`/collisions`): the result then has its
        ``clearance`` and ``collisions``, and with ``avoid`` the fused controller keeps
        ``margin`` from them (the robot needs a collision model).
    avoid : bool
        With a scene: keep clear (True) or only check (False).
    margin : float
        The clearance (m) avoidance keeps; pairs farther apart add nothing.

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
    res = _run(robot, run, limits, dt, timed)
    if scene is None:
        return res

    def remake(again: RunSetup) -> ReproductionResult:
        return _run(robot, again, limits, dt, timed)

    return with_scene(robot, run, res, SceneRun(scene, avoid, margin), remake)


def _run(
    robot: KinematicModel, run: RunSetup, limits: MotionLimits | None, dt: float | None, timed: bool
) -> ReproductionResult:
    if timed:
        assert limits is not None and dt is not None
        return timed_path(robot, run, limits, dt)
    path = _table_ii(robot, run, run.theta0)
    return _path_result(robot, run, run.constraints.t.copy(), path)


def _path_steps(res: ReproductionResult) -> tuple[NDArray[np.bool_], int]:
    """The samples of a run that are its path (not its lead-in), and the skill's step its
    first one is at (0 from the start; floor(phase) for a plan along the way)."""
    own = ~res.lead_in if res.lead_in is not None else np.ones(len(res.t), dtype=bool)
    return own, int(np.floor(res.t[own][0] + 1e-9))


def _avoid_passes(
    run: RunSetup,
    res: ReproductionResult,
    checker: CollisionChecker,
    report: CollisionReport,
    margin: float,
    remake: Remake,
    **how: bool,
) -> tuple[ReproductionResult, CollisionReport]:
    """The passes of :mod:`._avoid`: Table II again (``remake``) with the encounters each
    pass meets, until the path keeps the margin or ``MAX_PASSES`` are run; the best pass (the
    largest smallest clearance) and its check (``report``: the check of ``res``). ``how``:
    :class:`._avoid.Avoidance`'s ``beside`` and ``hold``. A bump ends before the steps where
    the skill is tight (:func:`_tightness`): there the clearance does not get to move the
    hand."""
    first = _path_steps(res)[1]
    steps = np.arange(first, run.constraints.n_steps)
    tight = np.zeros(run.constraints.n_steps, dtype=bool)
    for _, at in _tightness(run, steps).values():
        tight[steps] |= at
    avoidance = Avoidance(checker, margin, tight=tight, **how)
    run = dataclasses.replace(run, avoid=avoidance)
    best: tuple[ReproductionResult, CollisionReport] | None = None
    for _ in range(MAX_PASSES):
        own, first = _path_steps(res)
        signal = None if res.gripper_signal is None else res.gripper_signal[own]
        checker.plan_grasps(res.joints[own], signal)
        # The pass meets the scene only where its check found it within the margin.
        outside = report.scene_clearance
        near = None if outside is None else np.flatnonzero(outside[own] < margin)
        avoidance.update(res.joints[own], signal, first=first, near=near)
        res = remake(run)
        report = checker.check(res.joints, res.gripper_signal, margin=margin)
        kept = _scene_min(report)
        if best is None or kept > _scene_min(best[1]):
            best = (res, report)
        if kept >= margin - TOLERANCE:
            break
    assert best is not None
    return best


def _fallbacks() -> list[dict[str, bool]]:
    """The passes tried, in order, where the first ones still meet the obstacle or leave a
    tight constraint (:data:`HOLD`, :data:`BESIDE`)."""
    out = [{"hold": True}] if HOLD else []
    if BESIDE:
        out.append({"beside": True, "hold": HOLD})
    return out


def _tightness(
    run: RunSetup, steps: NDArray[np.intp]
) -> dict[str, tuple[NDArray[np.float64], NDArray[np.bool_]]]:
    """Per task constraint, at the skill's ``steps`` (a run's, in order): the standard
    deviation of its loosest direction (m), and where it is tight: under :data:`TIGHT`, or
    within :data:`TIGHTEST` times its smallest over ``steps`` (its tightest phase)."""
    out = {}
    for name in run.tasks:
        cov = run.constraints.task_cov[name][steps, :3, :3]
        loosest = np.sqrt(np.linalg.eigvalsh(cov)[:, -1])
        out[name] = (loosest, (loosest < TIGHT) | (loosest < TIGHTEST * loosest.min()))
    return out


def _leaves_tight(
    run: RunSetup, plain: ReproductionResult, avoided: ReproductionResult
) -> tuple[int, str, float] | None:
    """Where the avoided run leaves a tight constraint of the skill that the plain run kept:
    the first (sample, constraint, the avoided run's hand error there in m) whose error grows
    by more than :data:`CONFLICT` and more than :data:`LEFT_SIGMAS` of the constraint's standard
    deviation (its loosest direction) where that is under :data:`TIGHT` or in its tightest phase
    (:data:`TIGHTEST`); None where the clearance and the skill agree."""
    own = np.flatnonzero(_path_steps(avoided)[0])
    steps = np.floor(avoided.t[own] + 1e-9).astype(int)
    # The plain run's samples by the skill's step: the two runs' lead-ins may differ in length.
    kept = np.flatnonzero(_path_steps(plain)[0])
    kept_steps = np.floor(plain.t[kept] + 1e-9).astype(int)
    for name, (loosest, tight) in _tightness(run, steps).items():
        before = np.full(max(int(steps.max()), int(kept_steps.max())) + 1, np.inf)
        before[kept_steps] = plain.task_errors[name][kept]
        grown = avoided.task_errors[name][own] - before[steps]
        bad = np.flatnonzero(tight & (grown > np.maximum(CONFLICT, LEFT_SIGMAS * loosest)))
        if bad.size:
            sample = int(own[bad[0]])
            return (sample, name, float(avoided.task_errors[name][sample]))
    return None


def _scene_min(report: CollisionReport) -> float:
    """The smallest clearance to the scene (the arm's pairs with itself left out)."""
    outside = report.scene_clearance
    return float(outside.min()) if outside is not None and outside.size else float("inf")


@dataclass(frozen=True)
class SceneRun:
    """What a run is checked against and how: the scene, whether the fused controller keeps
    clear of it (``avoid``) and by how much (``margin``, m)."""

    scene: Scene
    avoid: bool = True
    margin: float = DEFAULT_MARGIN


def with_scene(
    robot: KinematicModel,
    run: RunSetup,
    res: ReproductionResult,
    sr: SceneRun,
    remake: Remake,
    *,
    warn: bool = True,
) -> ReproductionResult:
    """The run ``res`` (of ``run``) checked against the scene and, with ``avoid`` and a fused
    controller where it comes within the margin, made again with the clearance constraint
    (:mod:`._avoid`): ``remake(run with its avoidance)`` makes it again, from the start or from
    a state along the way (an online controller's plan). ``warn``: a
    :class:`CollisionWarning` where it still collides (``res.infeasible`` says so either
    way)."""
    scene, avoid = sr.scene, sr.avoid
    margin = check_positive_float(sr.margin, "margin")
    checker = CollisionChecker(robot, scene, run.objects)
    report = checker.check(res.joints, res.gripper_signal, margin=margin)
    fused = avoid and JOINT in run.used and bool(run.tasks) and not run.constraints.oriented
    if avoid and not fused:
        raise ValueError(
            "avoid=True needs the fused controller of position constraints (use=None or "
            "'joint' with objects); pass avoid=False to check only"
        )
    left: tuple[int, str, float] | None = None
    if fused:
        outside = report.scene_clearance
        if outside is not None and outside.size and float(outside.min()) < margin:
            avoided, avoided_report = _avoid_passes(run, res, checker, report, margin, remake)
            # Where keeping the margin would leave a tight constraint of the skill, the plain
            # run stays, its contacts reported: the skill is not given up silently.
            left = _leaves_tight(run, res, avoided)
            for how in _fallbacks():
                # Tried too where the passes kept clear but short of the margin: their best
                # pass can still cut the obstacle between two samples.
                if left is None and _scene_min(avoided_report) >= margin - TOLERANCE:
                    break
                # Over the obstacle did not work: held across, then beside it.
                again, again_report = _avoid_passes(
                    run, res, checker, report, margin, remake, **how
                )
                if _leaves_tight(run, res, again) is None and (
                    left is not None or _scene_min(again_report) > _scene_min(avoided_report)
                ):
                    avoided, avoided_report, left = again, again_report, None
            if left is None:
                res, report = avoided, avoided_report
        else:
            zero = np.zeros(len(res.t))
            res = dataclasses.replace(
                res,
                influence={**res.influence, CLEARANCE: zero},
                influence_joint_space={**res.influence_joint_space, CLEARANCE: zero.copy()},
            )
    infeasible = None
    if avoid and report.collisions:
        step, first, second = report.collisions[0]
        infeasible = (
            f"the skill's constraints and the clearance cannot both hold: {first} and {second} "
            f"collide from sample {step} ({len(report.collisions)} contacts in all)"
        )
        if left is not None:
            infeasible += (
                f"; keeping clear would take the hand {left[2] * 1e3:.0f} mm from the "
                f"{left[1]} constraint at sample {left[0]}, where it is tight"
            )
        if warn:
            warnings.warn(CollisionWarning(infeasible), stacklevel=4)
    return dataclasses.replace(
        res, clearance=report.clearance, collisions=report.collisions, infeasible=infeasible
    )
