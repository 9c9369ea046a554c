"""The paper's experiment in simulation: teach, learn, reproduce for new placements, execute.

Controllers (paper Sec. II-B and Fig. 6) are named as in ``pbdkit evaluate``'s JSON:

- ``"fused"``: every constraint, fused as a product of Gaussians (eq. (1));
- ``"joint"``: the joint-space constraint only;
- ``"task:OBJECT"``: the task-space constraint of one object only (null-space term alpha = 0.5).

Which constraints a task's skill has (:func:`constrained_objects`): the joint space and one
task-space constraint per object that moves between placements, as in the paper (Sec. III: the
cameras track the moving objects; the basin of task 2 is fixed and only the gesture, a
joint-space constraint, relates to it). So the coaster task's controllers are ``"fused"``,
``"joint"``, ``"task:glass"``, ``"task:coaster"`` and the basin task's ``"fused"``, ``"joint"``,
``"task:glass"``. ``constrain_fixed=True`` (``pbdkit evaluate --constrain-fixed``) also learns a
constraint relative to the fixed basin (and adds ``"task:basin"``), which the paper does not.
The demonstrations record every object either way; the simulated world and the success judge
always get every object's position (:meth:`pbdkit.sim.tasks.TaskSpec.full_placement`), the skill
only its own objects'.

A trial samples new object positions inside the demonstrated ranges
(:attr:`pbdkit.sim.tasks.TaskSpec.ranges`), reproduces the skill with a controller, executes the
joint trajectory under physics over the demonstrations' mean duration, and judges the outcome
with the task's judge (:func:`pbdkit.sim.execute.evaluate_outcome`).

Every function takes a task's name or its :class:`pbdkit.sim.tasks.TaskSpec`; a name is resolved
once, at the entry (:func:`pbdkit.sim.tasks.get_task`).

Vision in the loop (default of :func:`evaluate`): the skill is told the positions the stereo
tracker measures (:mod:`pbdkit.sim.tracking`, calibrated once per evaluation), while the simulated
world keeps the true ones; ``ground_truth=True`` tells it the true positions instead. A placement
whose objects the cameras cannot locate counts as a failure of every controller (the robot would
not move), reported in ``"tracking_failures"``; it never falls back to the true positions.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ..learning.demonstration import Demonstration
from ..learning.probabilistic_ik import ReachWarning, ReproductionResult
from ..learning.skill import Skill
from ..motion.limits import MotionPeaks
from ..prob.gmm import MAX_COMPONENTS
from ..robots import katana
from . import tasks as T
from .execute import ExecutionResult, execute, stream_peaks
from .online import Observer, OnlineRun, TruthObserver, VisionObserver, execute_online
from .parallel import TrialJob, session
from .perturb import Disturbance, DisturbanceSetup, check_perturb, make_disturbance
from .scene import Simulation
from .tasks import TaskSpec
from .teacher import teach
from .tracking import ObjectNotSeenError, SimTracker, observed_objects

__all__ = [
    "ControllerOutcome",
    "ControllerRun",
    "ControllerStats",
    "Evaluation",
    "OnlineControllerRun",
    "TaskSkill",
    "Trial",
    "TrialObservation",
    "assemble_trial",
    "calibrate_tracker",
    "constrained_objects",
    "controller_names",
    "controller_use",
    "evaluate",
    "following_error",
    "learn_task",
    "observation_noise",
    "observe",
    "observe_trial",
    "peak_speed_ratio",
    "run_controller",
    "run_online",
    "run_trial",
    "run_trial_controller",
    "run_trials",
    "servo_peaks",
    "start_posture",
    "summarize",
    "tracking_errors",
    "tracking_summary",
    "trial_disturbance",
]

Float = NDArray[np.float64]


def controller_names(object_names: Sequence[str]) -> list[str]:
    """``["fused", "joint", "task:OBJ", ...]`` for a skill's objects."""
    return ["fused", "joint", *(f"task:{k}" for k in object_names)]


def controller_use(controller: str, object_names: Sequence[str]) -> list[str] | None:
    """The ``use`` argument of :meth:`pbdkit.Skill.reproduce` for a controller name."""
    if controller == "fused":
        return None
    if controller == "joint":
        return ["joint"]
    if controller.startswith("task:") and controller[5:] in object_names:
        return [controller[5:]]
    raise ValueError(
        f"controller must be one of {controller_names(object_names)}, got {controller!r}"
    )


def constrained_objects(task: str | TaskSpec, *, constrain_fixed: bool = False) -> list[str]:
    """The objects of ``task`` that get a task-space constraint, in range order.

    Parameters
    ----------
    task : str or TaskSpec
        A registered task name (e.g. "coaster", "basin") or its spec.
    constrain_fixed : bool
        False (the paper): only the objects that move (:func:`pbdkit.sim.tasks.tracked_objects`).
        True: every object, the fixed ones (the basin) too.

    Returns
    -------
    names : list of str
        The ``objects`` argument of :meth:`pbdkit.Skill.learn`.
    """
    spec = T.get_task(task)
    if constrain_fixed:
        return list(spec.ranges)
    return list(spec.tracked_objects)


@dataclass
class TaskSkill:
    """A skill learned from simulated demonstrations of a task.

    ``task`` is the task's spec; a registered name given instead is resolved on construction.
    """

    task: TaskSpec
    demos: list[Demonstration]
    skill: Skill
    learn_seconds: float
    teach_seconds: float

    def __post_init__(self) -> None:
        self.task = T.get_task(self.task)

    @property
    def constrain_fixed(self) -> bool:
        """True if the skill has a task-space constraint relative to a fixed object."""
        fixed = self.task.fixed_objects
        return any(k in fixed for k in self.skill.object_names)


def learn_task(
    task: str | TaskSpec,
    *,
    n_demos: int = 5,
    seed: int = 0,
    n_steps: int = 1000,
    max_components: int = MAX_COMPONENTS,
    constrain_fixed: bool = False,
) -> TaskSkill:
    """Demonstrate ``task`` ``n_demos`` times with the simulated teacher and learn the skill.

    The demonstrations record every object; the skill gets a task-space constraint for the
    objects of :func:`constrained_objects` (by default the moving ones, as in the paper;
    ``constrain_fixed=True`` adds the fixed basin).
    """
    spec = T.get_task(task)
    start = time.perf_counter()
    demos = teach(spec, n_demos, seed=seed)
    teach_s = time.perf_counter() - start
    start = time.perf_counter()
    skill = Skill.learn(
        demos,
        katana(),
        n_steps=n_steps,
        max_components=max_components,
        objects=constrained_objects(spec, constrain_fixed=constrain_fixed),
    )
    learn_s = time.perf_counter() - start
    return TaskSkill(spec, demos, skill, learn_s, teach_s)


@dataclass
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

    @property
    def success(self) -> bool:
        return bool(self.execution.outcome.success)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: success, the task's metrics, ``peak_speed_ratio`` and
        ``following_error_rad`` (:func:`peak_speed_ratio`, :func:`following_error`), and the
        peaks of the servo targets over the arm's limits, ``peak_velocity_ratio``,
        ``peak_acceleration_ratio``, ``peak_jerk_ratio`` (<= 1: within the limits) with the
        absolute ``peak_velocity``, ``peak_acceleration``, ``peak_jerk`` (rad/s, rad/s^2,
        rad/s^3; :func:`servo_peaks`); all outside a push."""
        return _run_summary(self.execution, self.velocity_limit, self.force_window)


@dataclass
class OnlineControllerRun:
    """One controller run online, in the physics loop (:func:`pbdkit.sim.online.execute_online`).

    ``objects`` holds the positions the skill was told at the start (its own objects only).
    """

    controller: str
    objects: dict[str, Float]
    online: OnlineRun
    velocity_limit: Float
    warnings: list[str] = field(default_factory=list)
    force_window: tuple[float, float] | None = None

    @property
    def execution(self) -> ExecutionResult:
        return self.online.execution

    @property
    def success(self) -> bool:
        return bool(self.execution.outcome.success)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: as :meth:`ControllerRun.summary`, plus ``phase_held_steps`` (commands
        that re-targeted the previous step) and, with vision, ``tracking`` (frames per status
        of the :class:`pbdkit.vision.TrackFilter`, per object)."""
        out = _run_summary(self.execution, self.velocity_limit, self.force_window)
        out["phase_held_steps"] = self.online.held_steps
        if self.online.tracking is not None:
            out["tracking"] = self.online.tracking["frames"]
        return out


def following_error(
    execution: ExecutionResult, exclude: tuple[float, float] | None = None
) -> float:
    """Largest distance (rad) of a measured joint angle from the servo reference (recorded
    samples): a real drive faults beyond its following-error limit. ``exclude`` as
    :func:`peak_speed_ratio`."""
    err = np.abs(execution.joints - execution.targets).max(axis=1)
    if exclude is not None:
        t = execution.t
        err = err[(t < exclude[0]) | (t > exclude[1])]
    return float(err.max()) if err.size else 0.0


def peak_speed_ratio(
    execution: ExecutionResult,
    velocity_limit: Float,
    exclude: tuple[float, float] | None = None,
) -> float:
    """Largest measured joint speed over the velocity limits (recorded samples, 50 Hz).

    ``exclude``: a window of run time (s) left out, where an external force drives the arm
    (:meth:`pbdkit.sim.perturb.Disturbance.force_window`).
    """
    dq = np.abs(np.diff(execution.joints, axis=0)) / np.diff(execution.t)[:, None]
    ratio = (dq / velocity_limit).max(axis=1) if dq.size else np.zeros(0)
    if exclude is not None:
        t = execution.t[1:]
        ratio = ratio[(t < exclude[0]) | (execution.t[:-1] > exclude[1])]
    return float(ratio.max()) if ratio.size else 0.0


def servo_peaks(
    execution: ExecutionResult, exclude: tuple[float, float] | None = None
) -> MotionPeaks:
    """Peak velocity, acceleration and jerk of what the servos were sent (every physics step,
    from the trajectory's start to the end of the settling time) over the arm's limits: a real
    drive refuses a setpoint stream beyond them.

    ``exclude``: a window of run time (s) left out, as :func:`peak_speed_ratio` (the
    setpoints restart from the arm where a push moved it). Without, the peaks the run
    recorded (:attr:`pbdkit.sim.execute.ExecutionResult.servo_peaks`).
    """
    if exclude is None:
        return execution.servo_peaks
    return stream_peaks(
        execution.servo_targets, execution.servo_period, execution.servo_limits, exclude
    )


def _run_summary(
    execution: ExecutionResult,
    velocity_limit: Float | None,
    exclude: tuple[float, float] | None = None,
) -> dict[str, Any]:
    out: dict[str, Any] = {"success": bool(execution.outcome.success)}
    out.update({k: _finite(v) for k, v in execution.outcome.metrics.items()})
    if velocity_limit is not None:
        ratio = peak_speed_ratio(execution, velocity_limit, exclude)
        out["peak_speed_ratio"] = _finite(ratio)
    out["following_error_rad"] = _finite(following_error(execution, exclude))
    out.update({k: _finite(v) for k, v in servo_peaks(execution, exclude).as_dict().items()})
    return out


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _prepare_run(
    ts: TaskSkill,
    objects: dict[str, Float],
    controller: str,
    sim_objects: dict[str, Float] | None,
) -> tuple[list[str] | None, dict[str, Float], dict[str, Float]]:
    """The controller's ``use``, the positions the skill is told (its own objects) and the
    world's (every object), for :func:`run_controller` and :func:`run_online`."""
    use = controller_use(controller, ts.skill.object_names)
    known = ts.task.full_placement(objects)
    world = ts.task.full_placement(sim_objects) if sim_objects is not None else known
    return use, {k: known[k] for k in ts.skill.object_names}, world


def run_controller(
    ts: TaskSkill,
    objects: dict[str, Float],
    controller: str,
    *,
    camera: str | None = None,
    fps: float = 15.0,
    sim_objects: dict[str, Float] | None = None,
    disturbance: Disturbance | None = None,
) -> ControllerRun:
    """Reproduce with one controller for ``objects`` and execute it in a fresh simulation.

    The reproduction is computed once, from ``objects``, and played open loop (offline); a
    ``disturbance`` (:mod:`pbdkit.sim.perturb`) acts on the world while it plays.

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
    use, told, world = _prepare_run(ts, objects, controller, sim_objects)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ReachWarning)
        res = ts.skill.reproduce(told, use=use, on_unreachable="warn")
    rep_s = time.perf_counter() - start
    sim = Simulation.from_task(ts.task, world)
    try:
        ex = execute(
            sim,
            ts.skill.times(res),
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
    messages = [str(w.message) for w in caught]
    limit = _velocity_limit(ts)
    window = None if disturbance is None else disturbance.force_window()
    return ControllerRun(
        controller, told, res, ex, rep_s, messages, velocity_limit=limit, force_window=window
    )


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
) -> OnlineControllerRun:
    """Run one controller online (in the physics loop) from ``objects``, in a fresh simulation.

    The controller (:meth:`pbdkit.Skill.controller`) starts from the positions ``objects``
    (what the cameras saw before the run, or the truth) and is then told new positions at
    15 Hz: the tracker's (filtered, :class:`pbdkit.sim.online.VisionObserver`) with a
    ``tracker``, else the true ones (:class:`pbdkit.sim.online.TruthObserver`). Arguments as
    :func:`run_controller`.
    """
    use, told, world = _prepare_run(ts, objects, controller, sim_objects)
    names = ts.skill.object_names
    observer: Observer = TruthObserver(names) if tracker is None else VisionObserver(tracker, names)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ReachWarning)
        ctrl = ts.skill.controller(told, use=use, on_unreachable="warn")
        sim = Simulation.from_task(ts.task, world)
        try:
            run = execute_online(
                sim, ctrl, observer=observer, disturbance=disturbance, camera=camera, fps=fps
            )
        finally:
            sim.close()
    messages = [str(w.message) for w in caught]
    window = None if disturbance is None else disturbance.force_window()
    limit = _velocity_limit(ts)
    return OnlineControllerRun(controller, told, run, limit, messages, force_window=window)


def _velocity_limit(ts: TaskSkill) -> Float:
    """The robot's joint velocity limits (rad/s; inf where it has none)."""
    n = ts.skill.robot.n_joints
    limit = getattr(ts.skill.robot, "velocity_limit", None)
    return np.full(n, np.inf) if limit is None else np.asarray(limit, dtype=np.float64)


def start_posture(ts: TaskSkill) -> Float:
    """The skill's start posture theta_hat_0 (n,) (GMR mean at the first step, within limits).

    The robot waits there while the cameras locate the objects: it does not depend on them.
    """
    robot = ts.skill.robot
    return np.asarray(np.clip(ts.skill.constraints().joint_mean[0], robot.lower, robot.upper))


def observe(
    task: str | TaskSpec,
    truth: dict[str, Float],
    tracker: SimTracker,
    arm: npt.ArrayLike | None = None,
) -> dict[str, Float]:
    """Object positions the cameras give for a placement (fixed objects passed through).

    Builds the scene of ``task`` with the objects at ``truth`` and the arm at ``arm``, runs one
    tracker cycle and closes the scene. The arm must be out of the cameras' way: a patch partly
    hidden gives a biased position, not a refusal (``bench_tracking.py``, arm at rest q = 0:
    up to 10.5 mm on the coaster and 32 mm on the glass on the table; none at a start posture).

    Parameters
    ----------
    task : str or TaskSpec
        A registered task name (e.g. "coaster", "basin") or its spec.
    truth : dict str -> ndarray, shape (3,)
        True positions of the objects of the task; fixed ones may be left out (they are added
        from the task's ranges).
    tracker : SimTracker
        Calibrated on ``task``.
    arm : array-like, shape (n,), optional
        Arm joint angles while the cameras look (e.g. :func:`start_posture`); default q = 0.

    Returns
    -------
    objects : dict str -> ndarray, shape (3,)
        Every object of the task, whatever the skill constrains: tracked positions for the
        tracked objects, the true ones for the others (fixed objects, known without vision).

    Raises
    ------
    ObjectNotSeenError
        If a tracked object is not located.
    """
    spec = T.get_task(task)
    truth = spec.full_placement(truth)
    sim = Simulation.from_task(spec, truth)
    try:
        if arm is not None:
            sim.set_joints(arm)
        fixed = {k: v for k, v in truth.items() if k not in tracker.objects}
        seen = observed_objects(sim, tracker, fixed)
    finally:
        sim.close()
    return {k: seen[k] for k in truth}


def tracking_errors(
    observed: dict[str, Float], truth: dict[str, Float], names: Sequence[str]
) -> dict[str, float]:
    """3-D distance (mm) between observed and true positions of the objects ``names``."""
    return {k: 1e3 * float(np.linalg.norm(observed[k] - truth[k])) for k in names}


def tracking_summary(errors: Sequence[dict[str, float]]) -> dict[str, Any] | None:
    """Mean and standard deviation (mm) of tracking errors, pooled and per object.

    Parameters
    ----------
    errors : sequence of dict str -> float
        One dict per observed placement (from :func:`tracking_errors`).

    Returns
    -------
    summary : dict or None
        ``{"mean", "std", "max", "n", "per_object": {name: {"mean", "std", "max", "n"}}}``;
        None when nothing was observed.
    """

    def stats(v: NDArray[np.float64]) -> dict[str, Any]:
        return {"mean": float(v.mean()), "std": float(v.std()), "max": float(v.max()), "n": len(v)}

    pooled = np.array([e for row in errors for e in row.values()], dtype=np.float64)
    if pooled.size == 0:
        return None
    names = list(dict.fromkeys(k for row in errors for k in row))
    per = {k: stats(np.array([row[k] for row in errors if k in row])) for k in names}
    return {**stats(pooled), "per_object": per}


def calibrate_tracker(ts: TaskSkill) -> SimTracker:
    """The stereo tracker of a task, calibrated on its nominal placement with the arm at the
    skill's start posture (where it waits while the cameras look; :func:`start_posture`)."""
    calib = Simulation.from_task(ts.task, ts.task.nominal_objects())
    try:
        return SimTracker.from_simulation(calib, at_nominal=False, arm=start_posture(ts))
    finally:
        calib.close()


@dataclass(frozen=True)
class Trial:
    """One placement of an evaluation and what every controller did there.

    Attributes
    ----------
    truth : dict str -> ndarray, shape (3,)
        The true positions of every object.
    observed : dict str -> ndarray, shape (3,), or None
        What the skill was told (the cameras' positions with vision, else ``truth``); None if
        the cameras did not locate every tracked object.
    tracking_status : dict str -> str
        The tracker's status per object when ``observed`` is None, else empty.
    tracking_error_mm : dict str -> float or None
        Distance from the observed to the true position, per tracked object (vision only).
    runs : dict str -> dict
        Per controller, :meth:`ControllerRun.summary` (JSON-ready), or ``{"success": False,
        "tracking_status": ...}`` when the objects were not located.
    perturb : dict
        The trial's disturbance (:meth:`pbdkit.sim.perturb.Disturbance.as_dict`;
        ``{"name": "none"}`` without one).
    """

    truth: dict[str, Float]
    observed: dict[str, Float] | None
    tracking_status: dict[str, str]
    tracking_error_mm: dict[str, float] | None
    runs: dict[str, dict[str, Any]]
    perturb: dict[str, Any] = field(default_factory=lambda: {"name": "none"})


def run_trials(
    ts: TaskSkill,
    placements: Sequence[dict[str, Float]],
    controllers: Sequence[str],
    *,
    tracker: SimTracker | None = None,
    progress: Callable[[int, int], None] | None = None,
    online: bool = False,
    perturb: str = "none",
    seed: int = 0,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    noise_mm: float = 0.0,
) -> list[Trial]:
    """Execute every controller on every placement (the running half of :func:`evaluate`).

    Parameters
    ----------
    ts : TaskSkill
    placements : sequence of dict str -> ndarray, shape (3,)
        True positions of every object of the task.
    controllers : sequence of str
        Names from :func:`controller_names`.
    tracker : SimTracker, optional
        With a tracker the skill is told the positions the cameras measure; without, the true
        ones.
    progress : callable, optional
        ``progress(done, total)`` after every execution.
    online : bool
        Run the controllers online, in the physics loop (:func:`run_online`), instead of
        reproducing once and playing the trajectory (:func:`run_controller`).
    perturb : str
        A disturbance of :data:`pbdkit.sim.perturb.PERTURBATIONS`, drawn per trial (the same
        for every controller of the trial) from ``seed`` and the trial's index.
    seed : int
        Seeds the disturbances.
    workers : int, optional
        Run the trials in this many local worker processes (a Dask ``LocalCluster``,
        :mod:`pbdkit.sim.parallel`); results are identical to the serial run.
    scheduler : str, optional
        Run them on the Dask cluster at this address (``tcp://HOST:PORT``) instead.
    client : distributed.Client or pbdkit.sim.parallel.Session, optional
        Run them with this Dask client, or the client of this session (kept open: a study runs
        many evaluations on one cluster).
    noise_mm : float
        Noise on the positions the skill is told (:func:`run_trial`).

    Returns
    -------
    trials : list of Trial
        In the order of ``placements``.
    """
    for name in controllers:
        controller_use(name, ts.skill.object_names)
    check_perturb(perturb, ts.task)
    job = TrialJob(ts, tuple(controllers), tracker, online, perturb, seed, noise_mm)
    if workers is not None or scheduler is not None or client is not None:
        from .parallel import run_trials_dask

        return run_trials_dask(
            job, placements, progress=progress, workers=workers, scheduler=scheduler, client=client
        )
    total = len(placements) * len(controllers)
    out = []
    for i, truth in enumerate(placements):

        def tick(k: int, i: int = i) -> None:
            if progress is not None:
                progress(i * len(controllers) + k, total)

        out.append(job.run(i, truth, progress=tick))
    return out


def run_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    controllers: Sequence[str],
    *,
    tracker: SimTracker | None = None,
    online: bool = False,
    perturb: str = "none",
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
    noise_mm: float = 0.0,
) -> Trial:
    """One trial of :func:`run_trials`: trial ``index``, every controller at placement ``truth``.

    Depends on nothing but its arguments (the disturbance is drawn from ``seed`` and
    ``index``), so trials may run in any order, in any process, with the same results.
    ``progress(k)`` is called after the k-th controller's run. ``noise_mm`` > 0 adds Gaussian
    noise to the positions the skill is told of the moving objects (after the cameras, if
    any): isotropic, scaled so that its mean 3-D length is ``noise_mm`` (per-axis standard
    deviation ``noise_mm / sqrt(8 / pi)``), drawn from ``seed`` and ``index``.

    The same three steps run apart on Dask workers (:mod:`pbdkit.sim.parallel`):
    :func:`observe_trial` once, :func:`run_trial_controller` per controller, then
    :func:`assemble_trial`.
    """
    seen = observe_trial(ts, truth, index, tracker=tracker, seed=seed, noise_mm=noise_mm)
    runs: list[ControllerOutcome] = []
    for k, name in enumerate(controllers, start=1):
        runs.append(
            run_trial_controller(
                ts, seen, truth, index, name,
                tracker=tracker, online=online, perturb=perturb, seed=seed,
            )
        )  # fmt: skip
        if progress is not None:
            progress(k)
    return assemble_trial(ts, truth, index, seen, runs, perturb=perturb, seed=seed)


@dataclass(frozen=True)
class TrialObservation:
    """What the skill of a trial is told (:func:`observe_trial`).

    Attributes
    ----------
    told : dict str -> ndarray, shape (3,), or None
        The positions the skill is told; None if the cameras did not locate every tracked
        object.
    statuses : dict str -> str
        The tracker's status per object when ``told`` is None, else empty.
    errors_mm : dict str -> float or None
        Distance from the observed to the true position per tracked object (vision only).
    """

    told: dict[str, Float] | None
    statuses: dict[str, str]
    errors_mm: dict[str, float] | None


@dataclass(frozen=True)
class ControllerOutcome:
    """One controller's run in a trial (:func:`run_trial_controller`): its name, its summary
    (:meth:`ControllerRun.summary`) and the trial's disturbance as it acted
    (:meth:`pbdkit.sim.perturb.Disturbance.as_dict`; None if nothing ran)."""

    controller: str
    summary: dict[str, Any]
    disturbance: dict[str, Any] | None


def observe_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    *,
    tracker: SimTracker | None = None,
    seed: int = 0,
    noise_mm: float = 0.0,
) -> TrialObservation:
    """The positions the skill of trial ``index`` is told (:func:`run_trial`): the cameras'
    with a ``tracker`` (the arm waiting at its start posture), else the truth; plus
    ``noise_mm`` of noise drawn from ``seed`` and ``index``."""
    told: dict[str, Float] | None = truth
    statuses: dict[str, str] = {}
    errors: dict[str, float] | None = None
    if tracker is not None:
        try:
            told = observe(ts.task, truth, tracker, arm=start_posture(ts))
        except ObjectNotSeenError as exc:
            told = None
            statuses = {k: str(tr.status) for k, tr in exc.tracks.items()}
        else:
            errors = tracking_errors(told, truth, tracker.objects)
    if noise_mm > 0.0 and told is not None:
        told = observation_noise(ts.task, told, noise_mm, seed=seed, index=index)
    return TrialObservation(told, statuses, errors)


def run_trial_controller(
    ts: TaskSkill,
    seen: TrialObservation,
    truth: dict[str, Float],
    index: int,
    controller: str,
    *,
    tracker: SimTracker | None = None,
    online: bool = False,
    perturb: str = "none",
    seed: int = 0,
) -> ControllerOutcome:
    """One controller of trial ``index`` (:func:`run_trial`), told ``seen``; a failure
    without running when the cameras did not locate the objects."""
    if seen.told is None:
        return ControllerOutcome(
            controller, {"success": False, "tracking_status": seen.statuses}, None
        )
    act = trial_disturbance(ts, perturb, truth, seed=seed, index=index)
    if online:
        summary = run_online(
            ts, seen.told, controller, tracker=tracker, sim_objects=truth, disturbance=act
        ).summary()
    else:
        summary = run_controller(
            ts, seen.told, controller, sim_objects=truth, disturbance=act
        ).summary()
    return ControllerOutcome(controller, summary, act.as_dict())


def assemble_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    seen: TrialObservation,
    runs: Sequence[ControllerOutcome],
    *,
    perturb: str = "none",
    seed: int = 0,
) -> Trial:
    """The :class:`Trial` of :func:`run_trial` from its observation and its controllers' runs
    (in the order of the controllers)."""
    acted = [r.disturbance for r in runs if r.disturbance is not None]
    described = (
        acted[-1]
        if acted
        else trial_disturbance(ts, perturb, truth, seed=seed, index=index).as_dict()
    )
    return Trial(
        truth,
        seen.told,
        seen.statuses,
        seen.errors_mm,
        {r.controller: r.summary for r in runs},
        described,
    )


def observation_noise(
    task: TaskSpec, objects: dict[str, Float], noise_mm: float, *, seed: int, index: int
) -> dict[str, Float]:
    """``objects`` with Gaussian noise on the moving objects, of mean 3-D length ``noise_mm``
    (see :func:`run_trial`), drawn from ``seed`` and ``index``."""
    if not (noise_mm >= 0.0 and math.isfinite(noise_mm)):
        raise ValueError(f"noise_mm must be a finite number >= 0, got {noise_mm!r}")
    rng = np.random.default_rng([seed, 3, index])
    sd = 1e-3 * noise_mm / math.sqrt(8.0 / math.pi)
    moving = set(task.tracked_objects)
    return {k: (v + rng.normal(0.0, sd, 3) if k in moving else v) for k, v in objects.items()}


def trial_disturbance(
    ts: TaskSkill, perturb: str, truth: dict[str, Float], *, seed: int, index: int = 0
) -> Disturbance:
    """The disturbance ``perturb`` of trial ``index``: :func:`pbdkit.sim.perturb.make_disturbance`
    timed on the skill's grasp and drawn from ``seed`` and ``index``. A new object each call (a
    disturbance keeps state while it acts), the same disturbance for the same arguments."""
    grid = np.arange(ts.skill.n_steps, dtype=np.float64) * _step_seconds(ts)
    gripper = ts.skill.constraints().gripper
    rng = np.random.default_rng([seed, 2, index])
    return make_disturbance(perturb, DisturbanceSetup(ts.task, truth, grid, gripper, rng))


def _step_seconds(ts: TaskSkill) -> float:
    """Seconds per step of the skill's time grid (its duration over T - 1 steps)."""
    return float(ts.skill.duration) / max(ts.skill.n_steps - 1, 1)


@dataclass(frozen=True)
class ControllerStats:
    """Success rate of one controller over an evaluation and its metrics' statistics.

    Attributes
    ----------
    success_rate : float
    successes : int
    metrics : dict str -> dict or None
        Per metric of the runs' summaries (the task's judge's, and ``peak_speed_ratio``,
        ``following_error_rad``, the servo stream's ``peak_*_ratio`` and ``peak_*``),
        ``{"mean", "median", "max"}`` over the trials where it is defined (None where it
        never is): for a peak ratio, ``max`` is the worst trial.
    """

    success_rate: float
    successes: int
    metrics: dict[str, dict[str, float] | None]


@dataclass(frozen=True)
class Evaluation:
    """The result of :func:`evaluate`; :meth:`as_dict` is ``pbdkit evaluate``'s JSON."""

    task: str
    seed: int
    n_demos: int
    n_components: dict[str, int]
    constraints: list[str]
    constrain_fixed: bool
    learn_seconds: float
    vision: bool
    controllers: dict[str, ControllerStats]
    tracking_error_mm: dict[str, Any] | None
    trials: list[Trial]
    online: bool = False
    perturb: str = "none"

    @property
    def tracking_failures(self) -> int:
        """Placements where the cameras did not locate every tracked object."""
        return sum(t.observed is None for t in self.trials) if self.vision else 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"task", "trials", "seed", "n_demos", "n_components", "constraints",
        "constrain_fixed", "learn_seconds", "vision", "online", "perturb", "controllers":
        {NAME: {"success_rate", "successes", "metrics"}}, "tracking_error_mm",
        "tracking_failures", "placements", "observed", "perturbations", "runs"}`` (``runs``:
        per controller, one summary per trial; ``perturbations``: one disturbance per
        trial)."""
        names = list(self.controllers)
        return {
            "task": self.task,
            "trials": len(self.trials),
            "seed": self.seed,
            "n_demos": self.n_demos,
            "n_components": dict(self.n_components),
            "constraints": list(self.constraints),
            "constrain_fixed": self.constrain_fixed,
            "learn_seconds": self.learn_seconds,
            "vision": self.vision,
            "online": self.online,
            "perturb": self.perturb,
            "controllers": {
                k: {"success_rate": v.success_rate, "successes": v.successes, "metrics": v.metrics}
                for k, v in self.controllers.items()
            },
            "tracking_error_mm": self.tracking_error_mm,
            "tracking_failures": self.tracking_failures,
            "placements": [{k: v.tolist() for k, v in t.truth.items()} for t in self.trials],
            "observed": [
                None if t.observed is None else {k: v.tolist() for k, v in t.observed.items()}
                for t in self.trials
            ],
            "perturbations": [dict(t.perturb) for t in self.trials],
            "runs": {k: [t.runs[k] for t in self.trials] for k in names},
        }


def summarize(
    ts: TaskSkill,
    trials: Sequence[Trial],
    *,
    seed: int,
    n_demos: int,
    vision: bool,
    online: bool = False,
    perturb: str = "none",
    workers: int | None = None,
    scheduler: str | None = None,
) -> Evaluation:
    """The summarising half of :func:`evaluate`: success rates and metric statistics."""
    names = list(trials[0].runs) if trials else []
    stats: dict[str, ControllerStats] = {}
    for name in names:
        rows = [t.runs[name] for t in trials]
        successes = sum(bool(r["success"]) for r in rows)
        metric_names = list(
            dict.fromkeys(
                k
                for r in rows
                for k, v in r.items()
                if k != "success" and (v is None or isinstance(v, (int, float)))
            )
        )
        metrics: dict[str, dict[str, float] | None] = {}
        for m in metric_names:
            vals = np.array([r[m] for r in rows if r.get(m) is not None], dtype=float)
            metrics[m] = (
                {
                    "mean": float(vals.mean()),
                    "median": float(np.median(vals)),
                    "max": float(vals.max()),
                }
                if len(vals)
                else None
            )
        stats[name] = ControllerStats(successes / len(rows), successes, metrics)
    errors = [t.tracking_error_mm for t in trials if t.tracking_error_mm is not None]
    return Evaluation(
        task=ts.task.name,
        seed=seed,
        n_demos=n_demos,
        n_components=ts.skill.n_components,
        constraints=list(ts.skill.constraint_names),
        constrain_fixed=ts.constrain_fixed,
        learn_seconds=ts.learn_seconds,
        vision=vision,
        controllers=stats,
        tracking_error_mm=tracking_summary(errors) if vision else None,
        trials=list(trials),
        online=online,
        perturb=perturb,
    )


def evaluate(
    task: str | TaskSpec,
    trials: int,
    seed: int,
    *,
    n_demos: int = 5,
    controllers: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    task_skill: TaskSkill | None = None,
    ground_truth: bool = False,
    tracker: SimTracker | None = None,
    constrain_fixed: bool = False,
    online: bool = False,
    perturb: str = "none",
    workers: int | None = None,
    scheduler: str | None = None,
) -> Evaluation:
    """Success rate of every controller over ``trials`` random new placements.

    Teaches and learns (unless ``task_skill`` is given), draws the placements, runs
    :func:`run_trials` and :func:`summarize`.

    Parameters
    ----------
    task : str or TaskSpec
        A registered task name (e.g. "coaster", "basin") or its spec.
    trials : int
        Number of new placements (>= 1).
    seed : int
        Seeds the demonstrations and the placements.
    n_demos : int
    controllers : sequence of str, optional
        Default: every controller (:func:`controller_names`).
    progress : callable, optional
        ``progress(done, total)`` after every execution.
    task_skill : TaskSkill, optional
        A skill already learned (skips teaching and learning).
    ground_truth : bool
        Tell the skill the true object positions instead of the tracked ones.
    tracker : SimTracker, optional
        With vision: the tracker to use (default: :func:`calibrate_tracker`).
    constrain_fixed : bool
        When learning here: also learn a task-space constraint relative to the fixed objects
        (the basin), which the paper does not (:func:`learn_task`). With ``task_skill``, the
        skill's own constraints are used and recorded.
    online : bool
        Run the controllers online, in the physics loop, told the tracker's (or, with
        ``ground_truth``, the true) positions at 15 Hz (:func:`run_online`); default: reproduce
        once from the positions seen at the start and play the trajectory.
    perturb : str
        ``"none"``, ``"move"`` or ``"push"`` (:mod:`pbdkit.sim.perturb`).
    workers, scheduler
        Run the trials in parallel (:func:`run_trials`): ``workers`` local processes, or on
        the Dask cluster at ``scheduler``. The results are those of the serial run.

    Returns
    -------
    result : Evaluation
        ``result.as_dict()`` is JSON-ready (``pbdkit evaluate --json``).
    """
    spec = T.get_task(task)
    if trials < 1:
        raise ValueError(f"trials must be >= 1, got {trials}")
    check_perturb(perturb, spec)
    # The cluster starts first: its workers import while the skill is learned here.
    with session(workers, scheduler) as client:
        ts = task_skill or learn_task(
            spec, n_demos=n_demos, seed=seed, constrain_fixed=constrain_fixed
        )
        names = list(controllers) if controllers else controller_names(ts.skill.object_names)
        for name in names:
            controller_use(name, ts.skill.object_names)
        # Placements come from their own stream so that they do not depend on the teacher's
        # draws.
        rng = np.random.default_rng([seed, 1])
        placements = [spec.sample_objects(rng) for _ in range(trials)]
        vision = not ground_truth
        if vision and tracker is None:
            tracker = calibrate_tracker(ts)
        done = run_trials(
            ts,
            placements,
            names,
            tracker=tracker if vision else None,
            progress=progress,
            online=online,
            perturb=perturb,
            seed=seed,
            client=client,
        )
    return summarize(
        ts, done, seed=seed, n_demos=n_demos, vision=vision, online=online, perturb=perturb
    )
