"""The experiment's evaluation: the success rate of every controller over new placements.

:func:`evaluate` teaches and learns the task's skill (unless given one), draws the placements
inside the demonstrated ranges (:attr:`pbdkit.sim.TaskSpec.ranges`), runs the trials
(:func:`pbdkit.sim._trials.run_trials`: each reproduces the skill with every controller, executes
it under physics over the demonstrations' mean duration and judges the outcome with the task's
judge) and summarises them (:func:`summarize`). It is the entry point that resolves a task's
name (:func:`pbdkit.sim.get_task`) and builds the run's :class:`TrialConditions` from its
options, once; what it calls takes the spec and the conditions.

With the cameras (the default), a placement whose objects they cannot locate counts as a failure
of every controller (the robot would not move), reported in ``"tracking_failures"``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._defaults import MAX_TRIALS
from .._validation import check_int
from ._metrics import tracking_summary, yaw_errors, yaw_summary
from ._parallel import session
from ._perturb import check_perturb
from ._sensing import calibrate_tracker
from ._task_registry import get_task
from ._task_skill import TaskSkill, learn_task
from ._tasks import TaskSpec
from ._tracking import SimTracker
from ._trials import Trial, TrialConditions, run_trials

__all__ = ["ControllerStats", "Evaluation", "evaluate", "summarize"]


@dataclass(frozen=True, kw_only=True)
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
    collision_rate : float or None
        The share of the trials whose run touched something it may not (the task's scene,
        :mod:`pbdkit.sim._obstacle`); None for a task without a scene.
    min_clearance_m : float or None
        The smallest clearance (m) over every trial's run (negative: a penetration).
    """

    success_rate: float
    successes: int
    metrics: dict[str, dict[str, float] | None]
    collision_rate: float | None = None
    min_clearance_m: float | None = None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"success_rate", "successes", "metrics"}``, and with a scene
        ``"collision_rate"`` and ``"min_clearance_m"``."""
        out: dict[str, Any] = {
            "success_rate": self.success_rate,
            "successes": self.successes,
            "metrics": self.metrics,
        }
        if self.collision_rate is not None:
            out["collision_rate"] = self.collision_rate
            out["min_clearance_m"] = self.min_clearance_m
        return out


@dataclass(frozen=True, kw_only=True)
class Evaluation:
    """The result of :func:`evaluate`; :meth:`as_dict` is ``pbdkit evaluate``'s JSON.

    ``conditions`` are the trials' (:class:`pbdkit.sim.TrialConditions`: seed, online,
    perturbation, cameras or ground truth). ``tracking_error_mm`` and ``tracking_error_deg``
    summarise the cameras' errors over the placements they located
    (:func:`pbdkit.sim._metrics.tracking_summary`, :func:`pbdkit.sim._metrics.yaw_summary`;
    None with ``--ground-truth``); ``posed`` says that the task tracks objects placed as poses,
    whose yaw error the JSON then reports.
    """

    task: str
    conditions: TrialConditions
    n_demos: int
    n_components: dict[str, int]
    constraints: list[str]
    constrain_fixed: bool
    learn_seconds: float
    controllers: dict[str, ControllerStats]
    tracking_error_mm: dict[str, Any] | None
    trials: list[Trial]
    tracking_error_deg: dict[str, Any] | None = None
    posed: bool = False

    @property
    def vision(self) -> bool:
        """True when the skill was told what the cameras saw (not ground truth)."""
        return self.conditions.vision

    @property
    def tracking_failures(self) -> int:
        """Placements where the cameras did not locate every tracked object."""
        return sum(t.observed is None for t in self.trials) if self.vision else 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"task", "trials", "seed", "n_demos", "n_components", "constraints",
        "constrain_fixed", "learn_seconds", "vision", "online", "perturb", "avoid_scene",
        "controllers": {NAME: ControllerStats.as_dict()}, "tracking_error_mm",
        "tracking_failures", "placements", "observed", "perturbations", "runs"}`` (``runs``:
        per controller, one summary per trial; ``perturbations``: one disturbance per
        trial); for a task with objects placed as poses (:attr:`posed`), also
        ``"tracking_error_deg"`` after ``"tracking_error_mm"``: the cameras' yaw error,
        ``{"mean", "sd", "max", "n", "per_object"}`` (:func:`pbdkit.sim._metrics.yaw_summary`;
        None with ``--ground-truth``)."""
        names = list(self.controllers)
        out: dict[str, Any] = {
            "task": self.task,
            "trials": len(self.trials),
            "seed": self.conditions.seed,
            "n_demos": self.n_demos,
            "n_components": dict(self.n_components),
            "constraints": list(self.constraints),
            "constrain_fixed": self.constrain_fixed,
            "learn_seconds": self.learn_seconds,
            "vision": self.vision,
            "online": self.conditions.online,
            "perturb": self.conditions.perturb,
            "avoid_scene": self.conditions.avoid_scene,
            "controllers": {k: v.as_dict() for k, v in self.controllers.items()},
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
        if not self.posed:
            return out
        # "tracking_error_deg" right after "tracking_error_mm".
        keys = list(out)
        at = keys.index("tracking_error_mm") + 1
        keys.insert(at, "tracking_error_deg")
        out["tracking_error_deg"] = self.tracking_error_deg
        return {k: out[k] for k in keys}


def summarize(
    ts: TaskSkill,
    trials: Sequence[Trial],
    conditions: TrialConditions,
    *,
    n_demos: int,
) -> Evaluation:
    """The summarising half of :func:`evaluate`: success rates and metric statistics of the
    ``trials`` run under ``conditions``."""
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
                if k not in ("success", "collided") and (v is None or isinstance(v, (int, float)))
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
        checked = [r for r in rows if "collided" in r]
        stats[name] = ControllerStats(
            success_rate=successes / len(rows),
            successes=successes,
            metrics=metrics,
            collision_rate=(
                sum(bool(r["collided"]) for r in checked) / len(checked) if checked else None
            ),
            min_clearance_m=(
                float(min(r["min_clearance_m"] for r in checked)) if checked else None
            ),
        )
    errors = [t.tracking_error_mm for t in trials if t.tracking_error_mm is not None]
    # The yaw error of the tracked objects placed as poses (4x4 placements), where the
    # cameras saw them.
    posed = any(v.shape == (4, 4) for t in trials for v in t.truth.values())
    yaws = [
        yaw_errors(t.observed, t.truth, list(t.tracking_error_mm))
        for t in trials
        if t.observed is not None and t.tracking_error_mm is not None
    ]
    vision = conditions.vision
    return Evaluation(
        task=ts.task.name,
        conditions=conditions,
        n_demos=n_demos,
        n_components=ts.skill.n_components_,
        constraints=list(ts.skill.constraint_names),
        constrain_fixed=ts.constrain_fixed,
        learn_seconds=ts.learn_seconds,
        controllers=stats,
        tracking_error_mm=tracking_summary(errors) if vision else None,
        trials=list(trials),
        tracking_error_deg=yaw_summary(yaws) if vision else None,
        posed=posed,
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
    avoid_scene: bool = False,
) -> Evaluation:
    """Success rate of every controller over ``trials`` random new placements.

    Teaches and learns (unless ``task_skill`` is given), draws the placements, runs
    :func:`run_trials` and :func:`summarize`. ``seed``, ``online``, ``perturb`` and
    ``ground_truth`` become the trials' :class:`TrialConditions`, here, once
    (:attr:`Evaluation.conditions`).

    Parameters
    ----------
    task : str or TaskSpec
        A registered task name (e.g. "coaster", "basin") or its spec.
    trials : int
        Number of new placements, 1 to :data:`pbdkit._defaults.MAX_TRIALS` (100000).
    seed : int
        Seeds the demonstrations and the placements.
    n_demos : int
    controllers : sequence of str, optional
        Default: every controller (:attr:`pbdkit.sim.TaskSkill.controllers`).
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
        ``ground_truth``, the true) positions at 15 Hz (:func:`pbdkit.sim._runs.run_online`);
        default: reproduce once from the positions seen at the start and play the trajectory.
    perturb : str
        A registered perturbation (:func:`pbdkit.sim.perturbation_names`: ``"none"``,
        ``"move"``, ``"push"``, ``"rotate"``, ...).
    workers, scheduler
        Run the trials in parallel (:func:`run_trials`): ``workers`` local processes, or on
        the Dask cluster at ``scheduler``. The results are those of the serial run.
    avoid_scene : bool
        The fused controller avoids the task's whole scene, not only ``"obstacle"``'s box
        (:attr:`TrialConditions.avoid_scene`).

    Returns
    -------
    result : Evaluation
        ``result.as_dict()`` is JSON-ready (``pbdkit evaluate --json``).
    """
    spec = get_task(task)
    trials = check_int(trials, "trials", minimum=1, maximum=MAX_TRIALS)
    conditions = TrialConditions(
        online=online,
        perturb=perturb,
        ground_truth=ground_truth,
        seed=seed,
        avoid_scene=avoid_scene,
    )
    check_perturb(conditions.perturb, spec)
    # The cluster starts first: its workers import while the skill is learned here.
    with session(workers, scheduler) as client:
        ts = task_skill or learn_task(
            spec, n_demos=n_demos, seed=seed, constrain_fixed=constrain_fixed
        )
        names = list(controllers) if controllers else ts.controllers
        for name in names:
            ts.skill_for(name)  # an unknown name: ValueError before anything runs
        # Placements come from their own stream so that they do not depend on the teacher's
        # draws.
        rng = np.random.default_rng([seed, 1])
        placements = [spec.sample_objects(rng) for _ in range(trials)]
        if conditions.vision and tracker is None:
            tracker = calibrate_tracker(ts)
        done = run_trials(
            ts, placements, names, conditions, tracker=tracker, progress=progress, client=client
        )
    return summarize(ts, done, conditions, n_demos=n_demos)
