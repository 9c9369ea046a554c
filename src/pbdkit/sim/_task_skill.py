"""A task's skill: taught by the simulated teacher, learned with the constraints of the paper.

Which constraints a task's skill has (:func:`constrained_objects`): the joint space and one
task-space constraint per object that moves between placements, as in the paper (Sec. III: the
cameras track the moving objects; the basin of task 2 is fixed and only the gesture, a
joint-space constraint, relates to it). ``constrain_fixed=True`` (``pbdkit evaluate
--constrain-fixed``) also learns a constraint relative to the fixed basin (and adds
``"task:basin"``), which the paper does not. The demonstrations record every object either way;
the simulated world and the success judge always get every object's position
(:meth:`pbdkit.sim.TaskSpec.full_placement`), the skill only its own objects'.

:class:`TaskSkill` holds the task's spec: a name is resolved once, by the entry point that takes
it (:func:`learn_task`, :func:`constrained_objects`, :func:`pbdkit.sim.evaluate`);
everything that takes a :class:`TaskSkill` works with its spec.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._defaults import MAX_COMPONENTS
from ..data._demonstration import Demonstration
from ..robots import katana
from ..skill._naming import FUSED_POSITION, controller_names, controller_use
from ..skill._skill import Skill
from ._tasks import TaskSpec, get_task
from ._teacher import teach

__all__ = [
    "TaskSkill",
    "constrained_objects",
    "learn_task",
    "start_posture",
    "step_seconds",
    "velocity_limit",
]

Float = NDArray[np.float64]


def constrained_objects(task: str | TaskSpec, *, constrain_fixed: bool = False) -> list[str]:
    """The objects of ``task`` that get a task-space constraint, in range order.

    Parameters
    ----------
    task : str or TaskSpec
        A registered task name (e.g. "coaster", "basin") or its spec.
    constrain_fixed : bool
        False (the paper): only the objects that move (:func:`pbdkit.sim._tasks.tracked_objects`).
        True: every object, the fixed ones (the basin) too.

    Returns
    -------
    names : list of str
        The ``task_objects`` argument of :meth:`pbdkit.Skill.learn`.
    """
    return _constrained(get_task(task), constrain_fixed)


def _constrained(spec: TaskSpec, constrain_fixed: bool) -> list[str]:
    if constrain_fixed:
        return list(spec.ranges)
    return list(spec.tracked_objects)


@dataclass
class TaskSkill:
    """A skill learned from simulated demonstrations of a task.

    ``task`` is the task's spec; a registered name given instead is resolved on construction
    (for a skill built by hand: the library passes the spec).
    """

    task: TaskSpec
    demos: list[Demonstration]
    skill: Skill
    learn_seconds: float
    teach_seconds: float
    #: For a skill with oriented constraints: the position-only skill of the same
    #: demonstrations (``orientation=False``, the paper's), for the ``"fused-position"``
    #: controller. None otherwise.
    position_skill: Skill | None = None

    def __post_init__(self) -> None:
        self.task = get_task(self.task)

    @property
    def controllers(self) -> list[str]:
        """The controllers of this skill, by name
        (:func:`pbdkit.skill.controller_names`)."""
        return controller_names(self.skill.object_names, oriented=self.position_skill is not None)

    def skill_for(self, controller: str) -> tuple[Skill, list[str] | None]:
        """The skill a controller reproduces and its ``use`` (ValueError for an unknown name)."""
        oriented = self.position_skill is not None
        use = controller_use(controller, self.skill.object_names, oriented=oriented)
        if controller == FUSED_POSITION and self.position_skill is not None:
            return self.position_skill, use
        return self.skill, use

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
    spec = get_task(task)
    start = time.perf_counter()
    demos = teach(spec, n_demos, seed=seed)
    teach_s = time.perf_counter() - start
    start = time.perf_counter()
    robot = katana()
    names = _constrained(spec, constrain_fixed)
    skill = Skill.learn(
        demos, robot, n_steps=n_steps, max_components=max_components, task_objects=names
    )
    learn_s = time.perf_counter() - start
    # Objects placed as poses: the paper's skill of the same demonstrations, for comparison.
    position_skill = None
    if skill.oriented:
        position_skill = Skill.learn(
            demos,
            robot,
            n_steps=n_steps,
            max_components=max_components,
            task_objects=names,
            orientation=False,
        )
    return TaskSkill(spec, demos, skill, learn_s, teach_s, position_skill)


def start_posture(ts: TaskSkill) -> Float:
    """The skill's start posture theta_hat_0 (n,) (GMR mean at the first step, within limits).

    The robot waits there while the cameras locate the objects: it does not depend on them.
    """
    robot = ts.skill.robot
    return np.asarray(np.clip(ts.skill.constraints().joint_mean[0], robot.lower, robot.upper))


def velocity_limit(ts: TaskSkill) -> Float:
    """The robot's joint velocity limits (rad/s; inf where it has none)."""
    n = ts.skill.robot.n_joints
    limit = getattr(ts.skill.robot, "velocity_limit", None)
    return np.full(n, np.inf) if limit is None else np.asarray(limit, dtype=np.float64)


def step_seconds(ts: TaskSkill) -> float:
    """Seconds per step of the skill's time grid (its duration over T - 1 steps)."""
    return float(ts.skill.duration) / max(ts.skill.n_steps - 1, 1)
