"""``--perturb obstacle``: a box put in the reproduction's way after the demonstrations, and the
collision check of every run against the task's scene (:attr:`pbdkit.sim.TaskSpec.scene`).

**The obstacle.** A cube of :data:`OBSTACLE_SIZE` centred on the fused controller's path as it
is reproduced without avoidance for the trial's true placement, at its mid-carry step (the
middle of the first stretch where the gripper is closed, the lead-in left out): the hand and
what it carries go through it unless the controller avoids it. It is a static body of the
simulated world, so a run that does not avoid it hits it. The same box for every controller of
a trial (it depends on the trial alone).

**The check.** After a run, its measured joint angles and gripper command are checked against
the task's scene (the table, the shelf, the basin's walls, the tray's; the objects' shapes at
their true placements) plus the obstacle, by :class:`pbdkit.collision.CollisionChecker`, with a
contact at :data:`CONTACT_DISTANCE` or closer: the simulated drives stop at a contact, so the
measured arm touches rather than passes through. The run's summary gets ``"collided"``,
``"min_clearance_m"`` and its first contacts (``"contacts"``: [seconds, body, body]).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..collision import CollisionChecker, Scene
from ._execute import ExecutionResult
from ._perturb import Disturbance, PlaceObstacle
from ._tasks import TaskSpec

__all__ = ["CONTACT_DISTANCE", "avoided_scene", "run_collisions"]

Float = NDArray[np.float64]

#: A measured run touches a body at this distance or closer (m).
CONTACT_DISTANCE = 1e-3

#: The most samples of a run that are checked (evenly spread; a run records every 2 ms).
MAX_CHECKED_SAMPLES = 2500

#: The most contacts a run's summary lists.
MAX_LISTED_CONTACTS = 5


def avoided_scene(
    spec: TaskSpec, objects: Mapping[str, Float], act: Disturbance, *, whole: bool
) -> Scene | None:
    """What the fused controller avoids in a run: the obstacle (``--perturb obstacle``), or
    the task's whole scene with it (``whole``: ``--avoid-scene``), with the objects' shapes
    either way (what the hand carries is kept clear too); None: nothing."""
    box = act.box if isinstance(act, PlaceObstacle) else None
    if spec.scene is None or (box is None and not whole):
        return None
    scene: Scene = spec.scene(objects)
    if not whole:  # the box, and the objects' shapes: the glass the hand carries past it
        scene = Scene([], objects=scene.objects)
    return scene if box is None else scene.with_shapes(box)


def run_collisions(
    robot: Any,
    spec: TaskSpec,
    objects: Mapping[str, Float],
    ex: ExecutionResult,
    act: Disturbance | None,
) -> dict[str, Any]:
    """The collision check of an executed run (module docstring): ``{"collided",
    "min_clearance_m", "contacts"}``, or ``{}`` for a task without a scene."""
    if spec.scene is None:
        return {}
    scene = spec.scene(objects)
    if isinstance(act, PlaceObstacle):
        scene = scene.with_shapes(act.box)
    stride = max(1, -(-len(ex.t) // MAX_CHECKED_SAMPLES))
    rows = np.arange(0, len(ex.t), stride)
    checker = CollisionChecker(robot, scene, dict(objects))
    report = checker.check(ex.joints[rows], ex.gripper[rows], contact=CONTACT_DISTANCE)
    contacts = [[float(ex.t[rows[k]]), a, b] for k, a, b in report.collisions]
    return {
        "collided": bool(report.collisions),
        "min_clearance_m": report.min_clearance,
        "contacts": contacts[:MAX_LISTED_CONTACTS],
    }
