"""The simulated world of the experiment (MuJoCo): tasks, scene, cameras, execution, teacher.

The only part of pbdkit that imports MuJoCo (the ``sim`` extra: ``pip install -e '.[sim]'``);
learning and reproduction never depend on it. Names are imported on first use, MuJoCo with the
first that needs it (``import pbdkit.sim`` imports none of it).

- Tasks: a task is one :class:`TaskSpec` (placement ranges, scene objects, the teacher's via
  points, the success judge) in a registry (:func:`register_task`, :func:`get_task`,
  :func:`task_names`); the built-in ``"coaster"`` and ``"basin"`` (the paper's two) and
  ``"slot"``, registered before the first look-up. A task's name becomes its spec once, at the
  edge (the command line, :func:`evaluate`, :func:`learn_task`, :func:`teach`); below that,
  everything takes the spec (:class:`Simulation`, :func:`build_scene`).
- :class:`Simulation` (:func:`build_scene`): the Katana (from the same URDF as
  :func:`pbdkit.robots.katana`), a two-finger gripper, the task's objects, two 320x240 cameras.
- :func:`teach`: simulated kinesthetic demonstrations (:class:`pbdkit.Demonstration`).
- :func:`learn_task`: a task's skill (:class:`TaskSkill`).
- :func:`execute`: plays a joint trajectory under physics and judges it (:class:`ExecutionResult`);
  :func:`execute_online` runs a :class:`pbdkit.Controller` in the physics loop.
- Disturbances (:class:`Perturbation`, :func:`register_perturbation`,
  :func:`perturbation_names`): ``move``, ``push``, ``rotate``.
- :func:`evaluate`: the success rate of every controller over new placements
  (:class:`Evaluation`), serially or on Dask workers, under one set of
  :class:`TrialConditions` (online or not, the disturbance, cameras or ground truth, the seed).
- :func:`save_video`: recorded frames to MP4.

Rendering is headless: ``MUJOCO_GL`` defaults to ``egl`` (``osmesa`` if only OSMesa is installed);
set it before the simulation is first used to choose another backend (:mod:`pbdkit.sim._gl`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .._validation import short

if TYPE_CHECKING:
    from ._evaluation import Evaluation, evaluate
    from ._execute import ExecutionResult, execute
    from ._online import execute_online
    from ._perturb import Disturbance, Perturbation, perturbation_names, register_perturbation
    from ._scene import Simulation
    from ._task_registry import (
        get_task,
        nominal_objects,
        register_task,
        sample_objects,
        task_names,
    )
    from ._task_skill import TaskSkill, learn_task, teach
    from ._tasks import (
        ObjectMove,
        ObjectTurn,
        Outcome,
        PlacementRange,
        TaskSpec,
        ViaPoint,
    )
    from ._trials import TrialConditions
    from ._video import save_video
    from ._world import build_scene

_WHERE = {
    "Disturbance": "_perturb",
    "Evaluation": "_evaluation",
    "ExecutionResult": "_execute",
    "ObjectMove": "_tasks",
    "ObjectTurn": "_tasks",
    "Outcome": "_tasks",
    "Perturbation": "_perturb",
    "PlacementRange": "_tasks",
    "Simulation": "_scene",
    "TaskSkill": "_task_skill",
    "TaskSpec": "_tasks",
    "TrialConditions": "_trials",
    "ViaPoint": "_tasks",
    "build_scene": "_world",
    "evaluate": "_evaluation",
    "execute": "_execute",
    "execute_online": "_online",
    "get_task": "_task_registry",
    "learn_task": "_task_skill",
    "nominal_objects": "_task_registry",
    "perturbation_names": "_perturb",
    "register_perturbation": "_perturb",
    "register_task": "_task_registry",
    "sample_objects": "_task_registry",
    "save_video": "_video",
    "task_names": "_task_registry",
    "teach": "_task_skill",
}

__all__ = [
    "Disturbance",
    "Evaluation",
    "ExecutionResult",
    "ObjectMove",
    "ObjectTurn",
    "Outcome",
    "Perturbation",
    "PlacementRange",
    "Simulation",
    "TaskSkill",
    "TaskSpec",
    "TrialConditions",
    "ViaPoint",
    "build_scene",
    "evaluate",
    "execute",
    "execute_online",
    "get_task",
    "learn_task",
    "nominal_objects",
    "perturbation_names",
    "register_perturbation",
    "register_task",
    "sample_objects",
    "save_video",
    "task_names",
    "teach",
]


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'pbdkit.sim' has no attribute {short(name)}")
    value = getattr(importlib.import_module(f".{where}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
