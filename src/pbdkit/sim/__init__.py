"""The simulated world of the experiment (MuJoCo): scene, cameras, execution, success, teacher.

This subpackage is the only part of pbdkit that imports MuJoCo (the ``sim`` extra:
``pip install pbdkit[sim]``); learning and reproduction never depend on it.

- :func:`build_scene`, :class:`Simulation`: the Katana (from the same URDF as
  :func:`pbdkit.robots.katana`), a two-finger gripper, the task's objects, two 320x240 cameras.
- :func:`execute`: plays a joint trajectory under physics and judges the outcome
  (:class:`ExecutionResult`, :class:`Outcome`).
- :func:`teach`: simulated kinesthetic demonstrations (:class:`pbdkit.Demonstration`).
- :func:`save_video`: recorded frames to MP4.
- :mod:`pbdkit.sim.tasks`: object placement ranges (:data:`PLACEMENT_RANGES`,
  :func:`sample_objects`) and which objects move (:func:`tracked_objects`: tracked by the cameras,
  constrained in task space) or are fixed (:func:`fixed_objects`: the basin).

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

from .execute import ExecutionResult, Outcome, evaluate_outcome, execute
from .scene import CAMERAS, SceneInfo, Simulation, build_scene
from .tasks import (
    PLACEMENT_RANGES,
    TASKS,
    PlacementRange,
    fixed_objects,
    full_placement,
    nominal_objects,
    sample_objects,
    tracked_objects,
)
from .teacher import solve_ik, teach, teach_one, tool_pitch
from .video import save_video

__all__ = [
    "CAMERAS",
    "PLACEMENT_RANGES",
    "TASKS",
    "ExecutionResult",
    "Outcome",
    "PlacementRange",
    "SceneInfo",
    "Simulation",
    "build_scene",
    "evaluate_outcome",
    "execute",
    "fixed_objects",
    "full_placement",
    "nominal_objects",
    "sample_objects",
    "save_video",
    "solve_ik",
    "teach",
    "teach_one",
    "tool_pitch",
    "tracked_objects",
]
