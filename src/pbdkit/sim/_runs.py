"""One controller's run for a placement, in a fresh simulation: offline (reproduce once, play the
trajectory, :func:`run_controller`) or online (the controller in the physics loop,
:func:`run_online`)."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..collision import Scene
from ..motion._limits import MotionLimits
from ..reproduction._controller import PlanFailedWarning
from ..reproduction._probabilistic_ik import CollisionWarning
from ..reproduction._result import ReproductionResult
from ..reproduction._setup import ReachWarning
from ..skill._skill import Skill
from ._execute import ExecutionResult, execute
from ._metrics import run_summary
from ._obstacle import run_collisions
from ._online import Observer, OnlineRun, TruthObserver, VisionObserver, execute_online
from ._perturb import Disturbance, PlaceObstacle
from ._scene import Simulation
from ._task_skill import TaskSkill
from ._tracking import SimTracker

__all__ = ["ControllerRun", "OnlineControllerRun", "run_controller", "run_online"]

Float = NDArray[np.float64]


@dataclass(kw_only=True)
class ControllerRun:
    """One controller's reproduction and its execution under physics.

    ``objects`` holds the positions the skill was told (its own objects only).
    """

    controller: str
    objects: dict[str, Float]
    reproduction: ReproductionResult
    execution: ExecutionResult
    reproduce_seconds: float
    warnings: list[str] = field(default_factory=list)
    velocity_limit: Float | None = None
    force_window: tuple[float, float] | None = None
    collisions: dict[str, Any] = field(default_factory=dict)
    infeasible: str | None = None

    @property
    def success(self) -> bool:
        return bool(self.execution.outcome.success)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: success, the task's metrics, ``peak_speed_ratio`` and
        ``following_error_rad`` (:func:`pbdkit.sim._metrics.peak_speed_ratio`,
        :func:`pbdkit.sim._metrics.following_error`), and the peaks of the servo targets over
        the arm's limits, ``peak_velocity_ratio``, ``peak_acceleration_ratio``,
        ``peak_jerk_ratio`` (<= 1: within the limits) with the absolute ``peak_velocity``,
        ``peak_acceleration``, ``peak_jerk`` (rad/s, rad/s^2, rad/s^3;
        :func:`pbdkit.sim._metrics.servo_peaks`); all outside a push."""
        out = {
            **run_summary(self.execution, self.velocity_limit, self.force_window),
            **self.collisions,
        }
        if self.infeasible is not None:
            out["infeasible"] = self.infeasible
        return out


@dataclass(kw_only=True)
class OnlineControllerRun:
    """One controller run online, in the physics loop (:func:`pbdkit.sim.execute_online`).

    ``objects`` holds the positions the skill was told at the start (its own objects only).
    """

    controller: str
    objects: dict[str, Float]
    online: OnlineRun
    velocity_limit: Float
    warnings: list[str] = field(default_factory=list)
    force_window: tuple[float, float] | None = None
    collisions: dict[str, Any] = field(default_factory=dict)
    fault: str | None = None

    @property
    def execution(self) -> ExecutionResult:
        return self.online.execution

    @property
    def success(self) -> bool:
        return bool(self.execution.outcome.success)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: as :meth:`ControllerRun.as_dict`, plus ``phase_held_steps`` (commands
        that re-targeted the previous step) and, with vision, ``tracking`` (frames per status
        of the :class:`pbdkit.vision.TrackFilter`, per object)."""
        out = run_summary(self.execution, self.velocity_limit, self.force_window)
        out.update(self.collisions)
        if self.fault is not None:
            out["fault"] = self.fault
        out["phase_held_steps"] = self.online.held_steps
        if self.online.tracking is not None:
            out["tracking"] = self.online.tracking["frames"]
        return out


def _velocity_limit(skill: Skill) -> Float:
    """The arm's joint velocity limits (rad/s; inf where it has none), which a run's peak
    speed is measured against (:func:`pbdkit.sim._metrics.peak_speed_ratio`)."""
    return MotionLimits.from_robot(skill.robot, skill.n_joints).velocity


def _prepare_run(
    ts: TaskSkill,
    objects: dict[str, Float],
    controller: str,
    sim_objects: dict[str, Float] | None,
) -> tuple[Skill, list[str] | None, dict[str, Float], dict[str, Float]]:
    """The controller's skill (:meth:`TaskSkill.skill_for`) and ``use``, the placements the
    skill is told (its own objects) and the world's (every object), for
    :func:`run_controller` and :func:`run_online`."""
    skill, use = ts.skill_for(controller)
    known = ts.task.full_placement(objects)
    world = ts.task.full_placement(sim_objects) if sim_objects is not None else known
    return skill, use, {k: known[k] for k in skill.object_names}, world


def run_controller(
    ts: TaskSkill,
    objects: dict[str, Float],
    controller: str,
    *,
    camera: str | None = None,
    fps: float = 15.0,
    sim_objects: dict[str, Float] | None = None,
    disturbance: Disturbance | None = None,
    avoid: Scene | None = None,
) -> ControllerRun:
    """Reproduce with one controller for ``objects`` and execute it in a fresh simulation.

    The reproduction is computed once, from ``objects``, and played open loop (offline); a
    ``disturbance`` (:mod:`pbdkit.sim._perturb`) acts on the world while it plays.

    ``objects`` are the positions the robot knows (e.g. from the tracker); ``sim_objects``,
    the true positions in the simulated world (default: the same). Either may leave out the
    fixed objects (they are added from the task's ranges) and may hold
    objects the skill has no constraint on: the skill is told only its own objects, the
    simulation and the success judge get every object.

    Raises
    ------
    ValueError
        An unknown controller or object, or a moving object without a position.
    """
    skill, use, told, world = _prepare_run(ts, objects, controller, sim_objects)
    scene = avoid if avoid is not None and _avoids(skill, use) else None
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ReachWarning)
        warnings.simplefilter("always", CollisionWarning)
        res = skill.reproduce(told, use=use, on_unreachable="warn", scene=scene)
    rep_s = time.perf_counter() - start
    boxes = [disturbance.box] if isinstance(disturbance, PlaceObstacle) else []
    sim = Simulation.from_task(ts.task, world, obstacles=boxes)
    # A plan that says it cannot keep clear is not played: the arm stays where it starts.
    refused = scene is not None and res.infeasible is not None
    try:
        if refused:
            rest = np.repeat(res.joints[:1], 2, axis=0)
            ex = execute(sim, [0.0, 1.0], rest, camera=camera, fps=fps)
        else:
            ex = execute(
                sim,
                skill.times(res),
                res.joints,
                res.gripper,
                camera=camera,
                fps=fps,
                disturbance=disturbance,
                velocities=res.velocities,
                accelerations=res.accelerations,
            )
    finally:
        sim.close()
    return ControllerRun(
        controller=controller,
        objects=told,
        reproduction=res,
        execution=ex,
        reproduce_seconds=rep_s,
        warnings=[str(w.message) for w in caught],
        velocity_limit=_velocity_limit(skill),
        force_window=None if disturbance is None else disturbance.force_window(),
        collisions=run_collisions(skill.robot, ts.task, world, ex, disturbance),
        infeasible=res.infeasible if refused else None,
    )


def _avoids(skill: Skill, use: list[str] | None) -> bool:
    """Whether the controller (``use``) of ``skill`` can keep a clearance: the fused one of
    position constraints (:doc:`/collisions`)."""
    fused = use is None or ("joint" in use and len(use) > 1)
    return fused and bool(skill.object_names) and not skill.oriented


def run_online(
    ts: TaskSkill,
    objects: dict[str, Float],
    controller: str,
    *,
    tracker: SimTracker | None = None,
    camera: str | None = None,
    fps: float = 15.0,
    sim_objects: dict[str, Float] | None = None,
    disturbance: Disturbance | None = None,
    avoid: Scene | None = None,
) -> OnlineControllerRun:
    """Run one controller online (in the physics loop) from ``objects``, in a fresh simulation.

    The controller (:meth:`pbdkit.Skill.controller`) starts from the positions ``objects``
    (what the cameras saw before the run, or the truth) and is then told new positions at
    15 Hz: the tracker's (filtered, :class:`pbdkit.sim._online.VisionObserver`) with a
    ``tracker``, else the true ones (:class:`pbdkit.sim._online.TruthObserver`). Arguments as
    :func:`run_controller`; with ``avoid``, every plan of the fused controller keeps clear of
    it, and one that would not is not followed (the arm brakes to rest: the run's
    ``"fault"``).
    """
    skill, use, told, world = _prepare_run(ts, objects, controller, sim_objects)
    names = skill.object_names
    observer: Observer = TruthObserver(names) if tracker is None else VisionObserver(tracker, names)
    scene = avoid if avoid is not None and _avoids(skill, use) else None
    boxes = [disturbance.box] if isinstance(disturbance, PlaceObstacle) else []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ReachWarning)
        warnings.simplefilter("always", PlanFailedWarning)
        ctrl = skill.controller(told, use=use, on_unreachable="warn", scene=scene)
        sim = Simulation.from_task(ts.task, world, obstacles=boxes)
        try:
            run = execute_online(
                sim, ctrl, observer=observer, disturbance=disturbance, camera=camera, fps=fps
            )
        finally:
            sim.close()
    return OnlineControllerRun(
        controller=controller,
        objects=told,
        online=run,
        velocity_limit=_velocity_limit(skill),
        warnings=[str(w.message) for w in caught],
        force_window=None if disturbance is None else disturbance.force_window(),
        collisions=run_collisions(skill.robot, ts.task, world, run.execution, disturbance),
        fault=ctrl.fault,
    )
