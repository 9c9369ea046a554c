"""The paper's experiment in simulation: teach, learn, reproduce for new placements, execute.

Controllers (paper Sec. II-B and Fig. 6) are named as in ``pbdkit evaluate``'s JSON:

- ``"fused"``: every constraint, fused as a product of Gaussians (eq. (1));
- ``"joint"``: the joint-space constraint only;
- ``"task:OBJECT"``: the task-space constraint of one object only (null-space term alpha = 0.5).

A trial samples new object positions inside the demonstrated ranges
(:data:`pbdkit.sim.tasks.PLACEMENT_RANGES`), reproduces the skill with a controller, executes the
joint trajectory under physics over the demonstrations' mean duration, and judges the outcome
(:func:`pbdkit.sim.execute.evaluate_outcome`).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..demos import Demonstration
from ..reproduce import ReachWarning, ReproductionResult
from ..robots import katana
from ..skill import Skill
from . import tasks as T
from .execute import ExecutionResult, execute
from .scene import Simulation
from .teacher import teach

__all__ = [
    "ControllerRun",
    "TaskSkill",
    "controller_names",
    "controller_use",
    "evaluate",
    "learn_task",
    "run_controller",
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


@dataclass
class TaskSkill:
    """A skill learned from simulated demonstrations of a task."""

    task: str
    demos: list[Demonstration]
    skill: Skill
    learn_seconds: float
    teach_seconds: float


def learn_task(
    task: str, *, n_demos: int = 5, seed: int = 0, n_steps: int = 1000, max_components: int = 10
) -> TaskSkill:
    """Demonstrate ``task`` ``n_demos`` times with the simulated teacher and learn the skill."""
    T.check_task(task)
    start = time.perf_counter()
    demos = teach(task, n_demos, seed=seed)
    teach_s = time.perf_counter() - start
    start = time.perf_counter()
    skill = Skill.learn(
        demos, katana(), n_steps=n_steps, n_components="bic", max_components=max_components
    )
    learn_s = time.perf_counter() - start
    return TaskSkill(task, demos, skill, learn_s, teach_s)


@dataclass
class ControllerRun:
    """One controller's reproduction and its execution under physics."""

    controller: str
    objects: dict[str, Float]
    reproduction: ReproductionResult
    execution: ExecutionResult
    reproduce_seconds: float
    warnings: list[str] = field(default_factory=list)

    @property
    def success(self) -> bool:
        return bool(self.execution.outcome.success)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: success, the task's metrics, and the reproduction's task errors (mm)."""
        out: dict[str, Any] = {"success": self.success}
        out.update({k: _finite(v) for k, v in self.execution.outcome.metrics.items()})
        return out


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def run_controller(
    ts: TaskSkill,
    objects: dict[str, Float],
    controller: str,
    *,
    camera: str | None = None,
    fps: float = 15.0,
    sim_objects: dict[str, Float] | None = None,
) -> ControllerRun:
    """Reproduce with one controller for ``objects`` and execute it in a fresh simulation.

    ``objects`` are the positions the skill is told (e.g. from the tracker); ``sim_objects``,
    the true positions in the simulated world (default: the same).
    """
    use = controller_use(controller, ts.skill.object_names)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ReachWarning)
        res = ts.skill.reproduce(objects, use=use, on_unreachable="warn")
    rep_s = time.perf_counter() - start
    sim = Simulation.from_task(ts.task, sim_objects if sim_objects is not None else objects)
    try:
        ex = execute(sim, ts.skill.times(res), res.joints, res.gripper, camera=camera, fps=fps)
    finally:
        sim.close()
    return ControllerRun(controller, objects, res, ex, rep_s, [str(w.message) for w in caught])


def evaluate(
    task: str,
    trials: int,
    seed: int,
    *,
    n_demos: int = 5,
    controllers: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    task_skill: TaskSkill | None = None,
) -> dict[str, Any]:
    """Success rate of every controller over ``trials`` random new placements.

    Returns a JSON-ready dict ``{"task", "trials", "seed", "n_components", "controllers":
    {NAME: {"success_rate", "successes", "metrics": {metric: {"mean", "median", "max"}}}},
    "placements": [...]}``. ``progress(done, total)`` is called after every execution.
    """
    T.check_task(task)
    if trials < 1:
        raise ValueError(f"trials must be >= 1, got {trials}")
    ts = task_skill or learn_task(task, n_demos=n_demos, seed=seed)
    names = list(controllers) if controllers else controller_names(ts.skill.object_names)
    for name in names:
        controller_use(name, ts.skill.object_names)
    # Placements come from their own stream so that they do not depend on the teacher's draws.
    rng = np.random.default_rng([seed, 1])
    placements = [T.sample_objects(task, rng) for _ in range(trials)]
    runs: dict[str, list[dict[str, Any]]] = {n: [] for n in names}
    total, done = trials * len(names), 0
    for objects in placements:
        for name in names:
            runs[name].append(run_controller(ts, objects, name).summary())
            done += 1
            if progress is not None:
                progress(done, total)
    summary: dict[str, Any] = {}
    for name, rows in runs.items():
        successes = sum(bool(r["success"]) for r in rows)
        metric_names = [k for k in rows[0] if k != "success"]
        stats = {}
        for m in metric_names:
            vals = np.array([r[m] for r in rows if r[m] is not None], dtype=float)
            stats[m] = (
                {
                    "mean": float(vals.mean()),
                    "median": float(np.median(vals)),
                    "max": float(vals.max()),
                }
                if len(vals)
                else None
            )
        summary[name] = {
            "success_rate": successes / len(rows),
            "successes": successes,
            "metrics": stats,
        }
    return {
        "task": task,
        "trials": trials,
        "seed": seed,
        "n_demos": n_demos,
        "n_components": ts.skill.n_components,
        "learn_seconds": ts.learn_seconds,
        "controllers": summary,
        "placements": [{k: v.tolist() for k, v in p.items()} for p in placements],
        "runs": runs,
    }
