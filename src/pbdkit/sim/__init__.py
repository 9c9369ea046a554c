"""The simulated world of the experiment (MuJoCo): tasks, scene, cameras, execution, teacher.

This subpackage is the only part of pbdkit that imports MuJoCo (the ``sim`` extra:
``pip install pbdkit[sim]``); learning and reproduction never depend on it.

- :mod:`pbdkit.sim.tasks`: a task is one :class:`TaskSpec` (placement ranges, scene objects, the
  teacher's via points, the success judge) in a registry (:func:`register_task`,
  :func:`get_task`, :func:`task_names`); the paper's two tasks, ``"coaster"`` and ``"basin"``
  (:mod:`pbdkit.sim.taskdefs`), are registered when this package is imported. The entry points
  below take a task's name or its spec and resolve a name once; what they call takes the spec.
  Which objects move (:func:`tracked_objects`: tracked by the cameras, constrained in task
  space) or are fixed (:func:`fixed_objects`: the basin) comes from the ranges.
- :func:`build_scene` (:mod:`pbdkit.sim.world`), :class:`Simulation`: the Katana (from the same
  URDF as :func:`pbdkit.robots.katana`), a two-finger gripper, the task's objects, two 320x240
  cameras.
- :func:`execute`: plays a joint trajectory under physics and judges the outcome with the task's
  judge (:class:`ExecutionResult`, :class:`Outcome`).
- :func:`execute_online` (:mod:`pbdkit.sim.online`): runs a :class:`pbdkit.Controller` in the
  physics loop, told object positions at 15 Hz by the cameras (through a
  :class:`pbdkit.vision.TrackFilter`) or the truth.
- :mod:`pbdkit.sim.perturb`: disturbances for both ways of running, a registry like the tasks'
  (:func:`register_perturbation`, :func:`perturbation_names`; built in: ``move``, an object
  slides; ``push``, a shove on the arm; ``rotate``, an object placed as a pose turns).
- :func:`teach`: simulated kinesthetic demonstrations (:class:`pbdkit.Demonstration`).
- :func:`save_video`: recorded frames to MP4.
- The experiment (:mod:`pbdkit.sim.experiment` gathers its names), one module per concern:
  controller names (:mod:`~pbdkit.learning.naming`), a task's skill
  (:mod:`~pbdkit.sim.task_skill`), one controller's run (:mod:`~pbdkit.sim.runs`), what is
  measured (:mod:`~pbdkit.sim.metrics`), what the skill is told (:mod:`~pbdkit.sim.sensing`),
  trials (:mod:`~pbdkit.sim.trials`) on Dask workers (:mod:`~pbdkit.sim.parallel`, a pure
  executor), and the evaluation (:mod:`~pbdkit.sim.evaluation`).

Rendering is headless: ``MUJOCO_GL`` defaults to ``egl`` (``osmesa`` if only OSMesa is installed);
set it before importing this package to choose another backend.
"""

from __future__ import annotations

from . import _gl  # noqa: F401  (must run before mujoco is imported)

try:
    import mujoco  # noqa: F401
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError(
        "pbdkit.sim needs MuJoCo: install the 'sim' extra, e.g. pip install 'pbdkit[sim]'"
    ) from exc

from . import taskdefs  # noqa: F401  (registers the built-in tasks)
from .execute import ExecutionResult, evaluate_outcome, execute
from .online import OnlineRun, execute_online
from .perturb import (
    PERTURBATIONS,
    Disturbance,
    DisturbanceSetup,
    Perturbation,
    PushArm,
    SlideObject,
    TurnObject,
    get_perturbation,
    perturbation_names,
    register_perturbation,
    unregister_perturbation,
)
from .scene import CAMERAS, SceneInfo, Simulation, build_scene
from .tasks import (
    ObjectMove,
    ObjectTurn,
    Outcome,
    PlacementRange,
    RunStats,
    TaskSpec,
    ViaPoint,
    fixed_objects,
    full_placement,
    get_task,
    nominal_objects,
    register_task,
    sample_objects,
    task_names,
    tracked_objects,
    unregister_task,
)
from .teacher import solve_ik, teach, teach_one, tool_pitch
from .video import save_video

__all__ = [
    "CAMERAS",
    "PERTURBATIONS",
    "Disturbance",
    "DisturbanceSetup",
    "ExecutionResult",
    "ObjectMove",
    "ObjectTurn",
    "OnlineRun",
    "Outcome",
    "Perturbation",
    "PlacementRange",
    "PushArm",
    "RunStats",
    "SceneInfo",
    "Simulation",
    "SlideObject",
    "TaskSpec",
    "TurnObject",
    "ViaPoint",
    "build_scene",
    "evaluate_outcome",
    "execute",
    "execute_online",
    "fixed_objects",
    "full_placement",
    "get_perturbation",
    "get_task",
    "nominal_objects",
    "perturbation_names",
    "register_perturbation",
    "register_task",
    "sample_objects",
    "save_video",
    "solve_ik",
    "task_names",
    "teach",
    "teach_one",
    "tool_pitch",
    "tracked_objects",
    "unregister_perturbation",
    "unregister_task",
]
