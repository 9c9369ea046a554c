"""The tasks by name: a registry of :class:`~pbdkit.sim._tasks.TaskSpec`, the built-in ones first.

A task's name becomes its spec here, once, at the edge (the command line's ``--task``, the public
functions that take a name: :func:`pbdkit.sim.evaluate`, :func:`pbdkit.sim.learn_task`,
:func:`pbdkit.sim.teach`); everything below them takes the spec.

The built-in tasks (:mod:`pbdkit.sim._taskdefs`: coaster, basin, slot, in that order) are
registered when the registry is first used, by any of the functions here: they build MuJoCo
scenes, so that importing this module (or :mod:`pbdkit.sim`) imports no MuJoCo. The task modules
define their specs and do not register themselves: nothing they import comes back here.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ._registry import Registry
from ._tasks import TaskSpec

__all__ = [
    "get_task",
    "nominal_objects",
    "register_task",
    "sample_objects",
    "task_names",
    "unregister_task",
]

Float = NDArray[np.float64]

_TASKS: Registry[TaskSpec] | None = None


def _tasks() -> Registry[TaskSpec]:
    """The registry, with the built-in tasks registered first (on the first call)."""
    global _TASKS
    if _TASKS is None:
        from ._taskdefs import BUILT_IN  # imports MuJoCo: only once a task is asked for

        tasks: Registry[TaskSpec] = Registry(
            "task",
            TaskSpec,
            "spec",
            "task",
            " (a new task is registered with pbdkit.sim.register_task)",
        )
        for spec in BUILT_IN:
            tasks.register(spec)
        _TASKS = tasks
    return _TASKS


def register_task(spec: TaskSpec) -> TaskSpec:
    """Make ``spec`` known by its name (:func:`get_task`, ``--task``); returns it.

    Raises
    ------
    ValueError
        If ``spec`` is not a TaskSpec, or another spec has the same name.
    """
    return _tasks().register(spec)


def unregister_task(name: str) -> TaskSpec:
    """Forget the task ``name`` and return its spec; ValueError if it is not registered."""
    return _tasks().unregister(name)


def task_names() -> tuple[str, ...]:
    """Names of the registered tasks, in registration order (the paper's first)."""
    return _tasks().names()


def get_task(task: str | TaskSpec) -> TaskSpec:
    """The spec of ``task``: a registered name, or a spec (returned as it is).

    Raises
    ------
    ValueError
        If ``task`` is not the name of a registered task.
    """
    if isinstance(task, TaskSpec):
        return task
    return _tasks().get(task)


def nominal_objects(task: str | TaskSpec) -> dict[str, Float]:
    """Centre of every placement range of ``task`` (a name or a spec): name -> position (3,),
    or pose (4, 4) at the centre of its yaw range (:meth:`TaskSpec.nominal_objects`)."""
    return get_task(task).nominal_objects()


def sample_objects(task: str | TaskSpec, rng: np.random.Generator) -> dict[str, Float]:
    """Draw object placements uniformly inside the placement ranges of ``task``.

    Parameters
    ----------
    task : str or TaskSpec
        A registered task name (e.g. "coaster", "basin") or its spec.
    rng : numpy.random.Generator

    Returns
    -------
    dict str -> ndarray, shape (3,) or (4, 4)
        One placement per object of the task (fixed objects at their fixed position; they still
        take their draws from ``rng``).
    """
    return get_task(task).sample_objects(rng)
