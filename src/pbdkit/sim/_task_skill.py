"""A task's demonstrations and skill: taught by the simulated teacher, learned with the
constraints of the paper.

Which constraints a task's skill has (:func:`constrained_objects`): the joint space and one
task-space constraint per object that moves between placements, as in the paper (Sec. III: the
cameras track the moving objects; the basin of task 2 is fixed and only the gesture, a
joint-space constraint, relates to it). ``constrain_fixed=True`` (``pbdkit evaluate
--constrain-fixed``) also learns a constraint relative to the fixed basin (and adds
``"task:basin"``), which the paper does not. The demonstrations record every object either way;
the simulated world and the success judge always get every object's position
(:meth:`pbdkit.sim.TaskSpec.full_placement`), the skill only its own objects'.

:func:`teach` and :func:`learn_task` take a task's name (or its spec) and resolve it, once;
:class:`TaskSkill` holds the spec, and everything that takes a :class:`TaskSkill` works with it.
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
from ._task_registry import get_task
from ._tasks import TaskSpec, check_task
from ._teacher import teach_one

__all__ = ["TaskSkill", "constrained_objects", "learn_task", "teach"]

Float = NDArray[np.float64]


def constrained_objects(spec: TaskSpec, *, constrain_fixed: bool = False) -> list[str]:
    """The objects of the task ``spec`` that get a task-space constraint, in range order.

    Parameters
    ----------
    spec : TaskSpec
    constrain_fixed : bool
        False (the paper): only the objects that move (:attr:`TaskSpec.tracked_objects`).
        True: every object, the fixed ones (the basin) too.

    Returns
    -------
    names : list of str
        The ``task_objects`` argument of :meth:`pbdkit.Skill.learn`.
    """
    if constrain_fixed:
        return list(spec.ranges)
    return list(spec.tracked_objects)


@dataclass(kw_only=True)
class TaskSkill:
    """A skill learned from simulated demonstrations of a task.

    Attributes
    ----------
    task : TaskSpec
        The task (a registered name is resolved by the caller, :func:`pbdkit.sim.get_task`).
    demos : list of Demonstration
        The demonstrations it was learned from.
    skill : Skill
    learn_seconds, teach_seconds : float
        Wall time of the learning and of the teaching.
    position_skill : Skill, optional
        For a skill with oriented constraints: the position-only skill of the same
        demonstrations (``orientation=False``, the paper's), for the ``"fused-position"``
        controller. None otherwise.
    """

    task: TaskSpec
    demos: list[Demonstration]
    skill: Skill
    learn_seconds: float
    teach_seconds: float
    position_skill: Skill | None = None

    def __post_init__(self) -> None:
        check_task(self.task)

    @property
    def controllers(self) -> list[str]:
        """The controllers of this skill, by name
        (:func:`pbdkit.skill.controller_names`)."""
        return controller_names(
            self.skill.object_names, has_oriented=self.position_skill is not None
        )

    def skill_for(self, controller: str) -> tuple[Skill, list[str] | None]:
        """The skill a controller reproduces and its ``use`` (ValueError for an unknown name)."""
        oriented = self.position_skill is not None
        use = controller_use(controller, self.skill.object_names, has_oriented=oriented)
        if controller == FUSED_POSITION and self.position_skill is not None:
            return self.position_skill, use
        return self.skill, use

    @property
    def constrain_fixed(self) -> bool:
        """True if the skill has a task-space constraint relative to a fixed object."""
        fixed = self.task.fixed_objects
        return any(k in fixed for k in self.skill.object_names)

    @property
    def start_posture(self) -> Float:
        """The skill's start posture theta_hat_0 (n,): the GMR mean at the first step, within
        the joint limits (where a reproduction without ``q0`` starts).

        The robot waits there while the cameras locate the objects: it does not depend on them.
        """
        robot = self.skill.robot
        return np.asarray(np.clip(self.skill.constraints().joint_mean[0], robot.lower, robot.upper))


def teach(
    task: str | TaskSpec, n_demos: int = 5, seed: int | None = None, speed: float = 1.0
) -> list[Demonstration]:
    """Kinesthetic-style demonstrations of ``task`` for random object placements.

    Parameters
    ----------
    task : str or TaskSpec
        A registered task name (e.g. "coaster", "basin") or its spec.
    n_demos : int
        Number of demonstrations (>= 1).
    seed : int, optional
        Seeds the placements and the person's variability.
    speed : float
        Scales every duration by 1 / speed.

    Returns
    -------
    list of Demonstration
        Object positions drawn uniformly in the task's placement ranges
        (:meth:`pbdkit.sim.TaskSpec.sample_objects`); a posed object's yaws spread over
        its yaw range, one demonstration in each of ``n_demos`` equal parts of it.

    Raises
    ------
    ValueError
        An unknown task name, ``n_demos`` < 1.
    """
    spec = get_task(task)
    if n_demos < 1:
        raise ValueError(f"n_demos must be >= 1, got {n_demos}")
    rng = np.random.default_rng(seed)
    robot = katana()
    # A person spans the turns to be learned: each posed object's yaw range is cut in n_demos
    # parts, one demonstration in each, in a random order per object (no draws for the
    # paper's tasks, which have no posed object).
    orders = {k: rng.permutation(n_demos) for k in spec.posed_objects}
    demos = []
    for i in range(n_demos):
        strata = {k: (int(order[i]), n_demos) for k, order in orders.items()}
        objects = spec.sample_objects(rng, strata or None)
        demos.append(teach_one(spec, objects, rng, robot, speed))
    return demos


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
    names = constrained_objects(spec, constrain_fixed=constrain_fixed)
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
    return TaskSkill(
        task=spec,
        demos=demos,
        skill=skill,
        learn_seconds=learn_s,
        teach_seconds=teach_s,
        position_skill=position_skill,
    )
