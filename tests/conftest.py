"""Fixtures shared by the test modules.

Two subjects are built once per session and only read by the tests:

- the synthetic glass task on the Katana (``tests/synthetic_teacher.py``): ``robot``, ``demos``,
  ``skill`` and ``limits``, the subject of the skill and controller tests;
- small skills of the simulated tasks (a fast teacher, few demonstrations, a coarse time grid):
  ``fast_demos`` and ``small_task_skill`` build them on demand, once per set of arguments, so
  the modules that ask for the same one share it.

A module that needs something else defines a fixture of the same name, which takes precedence
(``test_bags.py``'s ``demos`` and ``skill`` are skills learned from bags).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import pytest
from synthetic_teacher import N_STEPS, synthetic_demos

from pbdkit.data._demonstration import Demonstration
from pbdkit.motion._limits import MotionLimits
from pbdkit.robots import katana
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill

if TYPE_CHECKING:  # the simulator is optional: imported where a simulated task is built
    from pbdkit.sim._task_skill import TaskSkill

# The teacher of the small simulated skills demonstrates twice as fast as the default one.
FAST = 2.0


# ----------------------------------------------------------------------------- synthetic task
@pytest.fixture(scope="session")
def robot() -> Robot:
    """The shipped 5-DOF Katana."""
    return katana()


@pytest.fixture(scope="session")
def demos(robot: Robot) -> list[Demonstration]:
    """Five synthetic demonstrations of reaching a glass (seed 0)."""
    return synthetic_demos(robot, np.random.default_rng(0))


@pytest.fixture(scope="session")
def skill(robot: Robot, demos: list[Demonstration]) -> Skill:
    """The skill of ``demos`` on a grid of ``synthetic_teacher.N_STEPS`` steps."""
    return Skill.learn(demos, robot, n_steps=N_STEPS, random_state=0)


@pytest.fixture(scope="session")
def limits(robot: Robot) -> MotionLimits:
    """The Katana's declared velocity, acceleration and jerk limits."""
    return MotionLimits.from_robot(robot, robot.n_joints)


# ----------------------------------------------------------------------------- simulated tasks
@functools.cache
def _taught(task: str, n_demos: int, seed: int) -> tuple[Demonstration, ...]:
    from pbdkit.sim._task_skill import teach

    return tuple(teach(task, n_demos, seed=seed, speed=FAST))


@functools.cache
def _small_task_skill(
    task: str,
    n_demos: int,
    seed: int,
    n_steps: int,
    max_components: int | None,
    objects: tuple[str, ...] | None,
) -> TaskSkill:
    from pbdkit.sim._task_registry import get_task
    from pbdkit.sim._task_skill import TaskSkill, constrained_objects

    spec = get_task(task)  # the tests name the task: resolved here, at their edge
    demos = list(_taught(task, n_demos, seed))
    # Skill.learn's own default when no maximum is asked for.
    options = {} if max_components is None else {"max_components": max_components}
    names = constrained_objects(spec) if objects is None else list(objects)
    skill = Skill.learn(demos, katana(), n_steps=n_steps, task_objects=names, **options)
    return TaskSkill(task=spec, demos=demos, skill=skill, learn_seconds=0.0, teach_seconds=0.0)


@pytest.fixture(scope="session")
def fast_demos() -> Callable[..., list[Demonstration]]:
    """``fast_demos(task, n_demos, seed)``: the simulated teacher's demonstrations at speed 2.

    Built once per arguments; the list is new at every call, the demonstrations are shared.
    """
    pytest.importorskip("mujoco")

    def build(task: str, n_demos: int, seed: int) -> list[Demonstration]:
        return list(_taught(task, n_demos, seed))

    return build


@pytest.fixture(scope="session")
def small_task_skill() -> Callable[..., TaskSkill]:
    """``small_task_skill(task, n_demos=3, seed=1, *, n_steps=150, max_components=None,
    objects=None)``: a skill learned from ``fast_demos(task, n_demos, seed)`` on the Katana.

    ``objects=None`` constrains the task's constrained objects
    (:func:`pbdkit.sim._task_skill.constrained_objects`); ``max_components=None`` keeps
    :meth:`Skill.learn`'s default. Built once per arguments and shared: read it, don't change it.
    """
    pytest.importorskip("mujoco")

    def build(
        task: str,
        n_demos: int = 3,
        seed: int = 1,
        *,
        n_steps: int = 150,
        max_components: int | None = None,
        objects: Sequence[str] | None = None,
    ) -> TaskSkill:
        names = None if objects is None else tuple(objects)
        return _small_task_skill(task, n_demos, seed, n_steps, max_components, names)

    return build
