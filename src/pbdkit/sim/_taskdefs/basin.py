"""Task 2 of the paper (Sec. III), clear the table: grasp the glass, empty it into a fixed basin.

The glass moves between placements (tracked, with a task-space constraint); the basin is fixed
(known without vision, no constraint in the paper's configuration: the pouring gesture is a
joint-space constraint). Reference points: the glass's (:mod:`.._glass`); the basin's is the
centre of its floor's top face. The glass holds :data:`N_LIQUID` liquid spheres.

Success: the glass is still held at the end of the trajectory and at least 90 % of the liquid
spheres end inside the basin. Metrics: ``liquid_fraction`` (share of spheres in the basin),
``held`` (1.0 if the glass is held at the end of the trajectory), ``pour_error_mm`` (horizontal
distance from the basin's centre to the mean of the spheres that left the glass), ``tilt_deg``
(largest tilt of the glass during the run).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...collision import Box, Scene
from .._gl import mujoco
from .._glass import GLASS_HEIGHT, GLASS_PATCH_CENTER, GLASS_RADIUS, GRASP_OFFSET
from .._scene import Simulation
from .._task_scenes import glass_shape, table_shape
from .._tasks import ObjectMove, Outcome, PlacementRange, RunStats, TaskSpec, ViaPoint
from .._teacher import UP, Person, between, grasp_via_points, radial
from .._world import LIQUID, SOLID, add_glass, add_liquid

__all__ = ["SPEC", "add_objects", "judge", "scene", "via_points"]

Float = NDArray[np.float64]

BASIN_CENTER_XY = (0.45, -0.22)
BASIN_INNER = 0.20  # inner side length (square), m
BASIN_WALL_HEIGHT = 0.06  # above the floor's top face
BASIN_FLOOR = 0.02  # floor thickness (thick: falling spheres must not pass through it)

N_LIQUID = 20
MIN_LIQUID_FRACTION = 0.9

# Pouring gesture: wrist-roll angle reached, rad. Past 90 deg the open top points downwards and
# the spheres run out.
POUR_ROLL = 2.0
POUR_SHIFT = 0.06  # m, hand position behind the basin's centre, against the pouring direction

_GLASS_ON_TABLE_Z = GLASS_PATCH_CENTER
_BASIN_POS = (BASIN_CENTER_XY[0], BASIN_CENTER_XY[1], BASIN_FLOOR)

#: Placement ranges: the glass stands on the table (z fixed); the basin is fixed.
RANGES: dict[str, PlacementRange] = {
    "glass": PlacementRange.box((0.47, 0.08, _GLASS_ON_TABLE_Z), (0.54, 0.22, _GLASS_ON_TABLE_Z)),
    "basin": PlacementRange.box(_BASIN_POS, _BASIN_POS),
}

DESCRIPTION = (
    "Clear the table: grasp the glass from the table and empty it into the basin (at a fixed "
    "place) by tilting it with the wrist. The hand must be precise relative to the glass "
    "while grasping; the pouring gesture is the same joint motion in every demonstration."
)


BASIN_WALL = 0.008  # wall thickness (m)


def _basin_boxes() -> list[tuple[str, tuple[float, float, float], tuple[float, float, float]]]:
    """The basin's floor and walls: (name, half sides, centre in the basin's frame, whose
    origin is the floor's centre on the table)."""
    half, wall, h = BASIN_INNER / 2, BASIN_WALL, BASIN_WALL_HEIGHT
    zc = BASIN_FLOOR + h / 2
    boxes = [
        ("basin_floor", (half + wall, half + wall, BASIN_FLOOR / 2), (0.0, 0.0, BASIN_FLOOR / 2))
    ]
    for i, (x, y, sx, sy) in enumerate(
        [
            (half + wall / 2, 0.0, wall / 2, half + wall),
            (-half - wall / 2, 0.0, wall / 2, half + wall),
            (0.0, half + wall / 2, half, wall / 2),
            (0.0, -half - wall / 2, half, wall / 2),
        ]
    ):
        boxes.append((f"basin_wall{i}", (sx, sy, h / 2), (x, y, zc)))
    return boxes


def scene(objects: Mapping[str, Float]) -> Scene:
    """The table, the basin's floor and walls (fixed obstacles); the glass's shape."""
    p = objects["basin"]
    parts = [
        Box([2.0 * v for v in size], (p[0] + c[0], p[1] + c[1], c[2]), name=name)
        for name, size, c in _basin_boxes()
    ]
    return Scene([table_shape(), *parts], objects={"glass": glass_shape()})


def _add_basin(world: Any, pos: Float) -> None:
    # Basin frame: floor centre on the table; pos[2] is the floor's top face.
    body = world.add_body(name="basin", pos=[pos[0], pos[1], 0.0])
    grey = [0.85, 0.85, 0.8, 1.0]
    for name, size, centre in _basin_boxes():
        body.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(size),
            pos=list(centre),
            rgba=grey,
            contype=SOLID | LIQUID,
            conaffinity=SOLID | LIQUID,
        )


def add_objects(world: Any, objects: Mapping[str, Float], rng: np.random.Generator) -> None:
    """The basin, the glass on the table and the liquid in it (jittered by ``rng``)."""
    _add_basin(world, objects["basin"])
    glass = objects["glass"]
    bottom = np.array([glass[0], glass[1], 0.0])
    add_glass(world, bottom)
    add_liquid(world, bottom, N_LIQUID, rng)


def via_points(
    objects: Mapping[str, Float], rng: np.random.Generator, speed: float = 1.0
) -> list[ViaPoint]:
    """Via points for a given glass position (the basin is fixed): grasp, carry, pour."""
    person = Person(rng, speed)
    p = person
    g, b = objects["glass"], objects["basin"]
    grasp = g + GRASP_OFFSET
    # A positive roll tips the glass's mouth towards the tangential direction d (the roll axis
    # points back along the tool). The liquid slides out along the wall and flies ~10 cm further
    # (it leaves at ~0.7 m/s): pour low, from behind the basin's centre.
    ub = radial(b)
    d_pour = np.array([-ub[1], ub[0], 0.0])
    pour = b + UP * rng.uniform(0.13, 0.15) - POUR_SHIFT * d_pour + p.jitter(0.008)
    carry = between(grasp, pour) + UP * rng.uniform(0.06, 0.10) + p.jitter(0.015)
    # The gesture: the same roll profile in every demonstration (joint space), fixed durations.
    return [
        # Near the table the arm folds more: the approach turns the wrist farther, slower.
        *grasp_via_points(person, g, 0.08, 2.6),
        ViaPoint(p.duration(1.6), carry, p.holding_pitch(), p.roll(), True),
        ViaPoint(p.duration(1.4), pour, p.holding_pitch(), 0.0, True),
        # The pour ends the demonstration, as in the paper (joint space most constrained "at the
        # end of the motion"): tilt, then hold while the liquid runs out.
        ViaPoint(p.duration(4.0), pour, p.hold_pitch, POUR_ROLL + p.roll(), True),
        ViaPoint(p.duration(2.0), pour, p.hold_pitch, POUR_ROLL + p.roll(), True),
    ]


def judge(sim: Simulation, run: RunStats) -> Outcome:
    """Success and metrics (module docstring) of the state after a run."""
    bottom, rot = sim.grasped_frame()
    basin = sim.info.objects["basin"]
    liquid = sim.liquid_positions()
    half = BASIN_INNER / 2
    inside = (
        (np.abs(liquid[:, 0] - basin[0]) < half)
        & (np.abs(liquid[:, 1] - basin[1]) < half)
        & (liquid[:, 2] < basin[2] + BASIN_WALL_HEIGHT)
        & (liquid[:, 2] > basin[2] - 0.005)
    )
    frac = float(np.mean(inside)) if liquid.shape[0] else 0.0
    # Spheres that left the glass: farther from its axis than its radius, or below its bottom.
    rel = (liquid - bottom) @ rot
    out = (
        (np.hypot(rel[:, 0], rel[:, 1]) > GLASS_RADIUS)
        | (rel[:, 2] < 0)
        | (rel[:, 2] > GLASS_HEIGHT)
    )
    pour_err = (
        float(np.linalg.norm(liquid[out, :2].mean(axis=0) - basin[:2])) if np.any(out) else math.nan
    )
    ok = run.held_at_end and frac >= MIN_LIQUID_FRACTION
    metrics = {
        "liquid_fraction": frac,
        "held": float(run.held_at_end),
        "pour_error_mm": 1e3 * pour_err,
        "tilt_deg": math.degrees(run.max_tilt),
    }
    return Outcome(bool(ok), metrics)


SPEC = TaskSpec(
    name="basin",
    description=DESCRIPTION,
    ranges=RANGES,
    add_objects=add_objects,
    via_points=via_points,
    judge=judge,
    n_liquid=N_LIQUID,
    # --perturb move: the glass slides 4 cm on the table before the grasp.
    move=ObjectMove("glass", 0.04, "before_grasp"),
    scene=scene,
)
