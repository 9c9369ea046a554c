"""Task 1 of the paper (Sec. III), set the table: grasp the glass on a shelf, put it on a coaster.

Both objects move between placements, so both are tracked by the cameras and both get a
task-space constraint. Reference points: the glass's (:mod:`.._glass`); the coaster's is the
centre of its top face.

Success: the glass stands upright (tilt < 10 deg) and rests on the coaster (its bottom within
5 mm of the coaster's top face, not held), its axis within 15 mm of the coaster's centre
(horizontally). Metrics: ``placement_error_mm`` (horizontal distance glass axis - coaster centre),
``height_error_mm`` (glass bottom above the coaster top), ``tilt_deg``, ``released`` (1.0 if the
fingers no longer touch the glass).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...collision import Box, Cylinder, Scene
from .._gl import mujoco
from .._glass import GLASS_PATCH_CENTER, GLASS_PATCH_PREFIX, GRASP_OFFSET
from .._scene import Simulation
from .._task_scenes import glass_shape, table_shape
from .._tasks import ObjectMove, Outcome, PlacementRange, RunStats, TaskSpec, ViaPoint
from .._teacher import APPROACH, UP, Person, between, grasp_via_points, radial
from .._world import add_glass

__all__ = ["SPEC", "add_objects", "judge", "scene", "via_points"]

Float = NDArray[np.float64]

COASTER_RADIUS = 0.045
COASTER_THICKNESS = 0.006

SHELF_HEIGHT = 0.10  # top face of the shelf board (m)
# Shelf board extent (x, y) in the base frame: it holds every glass placement.
SHELF_X = (0.38, 0.58)
SHELF_Y = (0.06, 0.32)

MAX_TILT_DEG = 10.0
MAX_PLACEMENT_ERROR = 0.015  # m, horizontal
MAX_REST_HEIGHT = 0.005  # m, glass bottom above the coaster top

_GLASS_ON_SHELF_Z = SHELF_HEIGHT + GLASS_PATCH_CENTER

#: Placement ranges: the glass stands on the shelf (z fixed), the coaster lies on the table.
RANGES: dict[str, PlacementRange] = {
    "glass": PlacementRange.box((0.44, 0.12, _GLASS_ON_SHELF_Z), (0.50, 0.24, _GLASS_ON_SHELF_Z)),
    "coaster": PlacementRange.box(
        (0.45, -0.24, COASTER_THICKNESS), (0.52, -0.10, COASTER_THICKNESS)
    ),
}

DESCRIPTION = (
    "Set the table: grasp the glass on the shelf and put it on the coaster. Both objects "
    "move between demonstrations. The hand must be precise relative to the glass while "
    "grasping and relative to the coaster while placing; in between, the joint-space "
    "posture of the demonstrations is the best guide."
)


SHELF_THICKNESS = 0.015  # the board (m)
SHELF_LEG = 0.02  # the legs' side (m), 1.5 cm in from the board's corners


def _leg_centres() -> list[tuple[float, float]]:
    (x0, x1), (y0, y1) = SHELF_X, SHELF_Y
    return [
        (x0 + 0.015, y0 + 0.015),
        (x0 + 0.015, y1 - 0.015),
        (x1 - 0.015, y0 + 0.015),
        (x1 - 0.015, y1 - 0.015),
    ]


def scene(objects: Mapping[str, Float]) -> Scene:
    """The table, the shelf's board and legs; the glass's and the coaster's shapes."""
    (x0, x1), (y0, y1) = SHELF_X, SHELF_Y
    thick, leg_h = SHELF_THICKNESS, SHELF_HEIGHT - SHELF_THICKNESS
    board = Box(
        (x1 - x0, y1 - y0, thick),
        ((x0 + x1) / 2, (y0 + y1) / 2, SHELF_HEIGHT - thick / 2),
        name="shelf_board",
    )
    legs = [
        Box((SHELF_LEG, SHELF_LEG, leg_h), (x, y, leg_h / 2), name=f"shelf_leg{i}")
        for i, (x, y) in enumerate(_leg_centres())
    ]
    coaster = Cylinder(COASTER_RADIUS, COASTER_THICKNESS, (0.0, 0.0, -COASTER_THICKNESS / 2))
    return Scene(
        [table_shape(), board, *legs], objects={"glass": glass_shape(), "coaster": coaster}
    )


def _add_shelf(world: Any) -> None:
    (x0, x1), (y0, y1) = SHELF_X, SHELF_Y
    thick = SHELF_THICKNESS
    body = world.add_body(name="shelf", pos=[0.0, 0.0, 0.0])
    wood = [0.55, 0.4, 0.25, 1.0]
    body.add_geom(
        name="shelf_board",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[(x1 - x0) / 2, (y1 - y0) / 2, thick / 2],
        pos=[(x0 + x1) / 2, (y0 + y1) / 2, SHELF_HEIGHT - thick / 2],
        rgba=wood,
    )
    leg_h = SHELF_HEIGHT - thick
    for i, (x, y) in enumerate(_leg_centres()):
        body.add_geom(
            name=f"shelf_leg{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[SHELF_LEG / 2, SHELF_LEG / 2, leg_h / 2],
            pos=[x, y, leg_h / 2],
            rgba=wood,
        )


def _add_coaster(world: Any, pos: Float) -> None:
    # The blue cylinder is also the coaster's patch for the cameras (SPEC.patches). A mocap
    # body: static for the physics, but ``--perturb move`` can slide it (SPEC.move).
    body = world.add_body(name="coaster", pos=[pos[0], pos[1], 0.0], mocap=True)
    body.add_geom(
        name="coaster",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[COASTER_RADIUS, COASTER_THICKNESS / 2, 0.0],
        pos=[0.0, 0.0, COASTER_THICKNESS / 2],
        rgba=[0.1, 0.25, 0.9, 1.0],
        friction=[1.0, 0.01, 0.001],
    )


def add_objects(world: Any, objects: Mapping[str, Float], rng: np.random.Generator) -> None:
    """The shelf, the coaster on the table and the glass on the shelf."""
    _add_shelf(world)
    _add_coaster(world, objects["coaster"])
    glass = objects["glass"]
    add_glass(world, np.array([glass[0], glass[1], SHELF_HEIGHT]))


def via_points(
    objects: Mapping[str, Float], rng: np.random.Generator, speed: float = 1.0
) -> list[ViaPoint]:
    """Via points for given glass and coaster positions: grasp, lift, carry, place, retreat."""
    person = Person(rng, speed)
    p = person
    g, c = objects["glass"], objects["coaster"]
    uc = radial(c)
    # Glass bottom 2 mm above the coaster's top when released: it drops onto it.
    place = c + UP * (GLASS_PATCH_CENTER + 0.002) + GRASP_OFFSET
    grasp = g + GRASP_OFFSET
    carry = between(grasp, place) + UP * rng.uniform(0.10, 0.15) + p.jitter(0.015)
    return [
        *grasp_via_points(person, g, 0.06, 1.6),
        ViaPoint(p.duration(1.8), carry, p.holding_pitch(), p.roll(), True),
        ViaPoint(
            p.duration(1.5), place + UP * 0.05 + p.jitter(0.005), p.holding_pitch(), 0.0, True
        ),
        ViaPoint(p.duration(1.0), place, p.hold_pitch, 0.0, True),
        ViaPoint(p.duration(0.6), place, p.hold_pitch, 0.0, False),  # open and wait
        ViaPoint(
            p.duration(1.8),
            place - APPROACH * uc + p.jitter(0.002),
            p.hold_pitch,
            p.roll(),
            False,
            free_pitch=True,
            joint_space=True,
        ),
        ViaPoint(
            p.duration(2.5),
            place - APPROACH * uc + UP * 0.08 + p.jitter(0.01),
            p.free_pitch(),
            p.roll(),
            False,
            free_pitch=True,
            joint_space=True,
        ),
    ]


def judge(sim: Simulation, run: RunStats) -> Outcome:
    """Success and metrics (module docstring) of the state after a run."""
    bottom, _ = sim.grasped_frame()
    tilt = math.degrees(sim.grasped_tilt())
    coaster = sim.object_positions()["coaster"]  # where it is now (it may have slid)
    err = float(np.linalg.norm(bottom[:2] - coaster[:2]))
    height = float(bottom[2] - coaster[2])
    released = sim.grasped_released()
    ok = (
        tilt < MAX_TILT_DEG
        and err <= MAX_PLACEMENT_ERROR
        and abs(height) <= MAX_REST_HEIGHT
        and released
    )
    metrics = {
        "placement_error_mm": 1e3 * err,
        "height_error_mm": 1e3 * height,
        "tilt_deg": tilt,
        "released": float(released),
    }
    return Outcome(bool(ok), metrics)


SPEC = TaskSpec(
    name="coaster",
    description=DESCRIPTION,
    ranges=RANGES,
    add_objects=add_objects,
    via_points=via_points,
    judge=judge,
    patches={"glass": GLASS_PATCH_PREFIX, "coaster": "coaster"},
    # --perturb move: the coaster slides 5 cm while the glass is carried.
    move=ObjectMove("coaster", 0.05, "while_carried"),
    scene=scene,
)
