"""A test object for pose tracking, shared by tests/test_pose_tracking.py and
benchmarks/bench_pose_tracking.py: the slot task with its tray replaced by a flat plate whose
marks lie to the side of its point, so that the cameras' bias turns with the object."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import mujoco
import numpy as np

from pbdkit.sim import get_task
from pbdkit.sim._parts import TRAY_MARK_A_RGBA, TRAY_MARK_B_RGBA, add_block
from pbdkit.sim._tasks import PlacementRange, TaskSpec, yaw_of

#: The plate's marks' centres lie this far to the side of its point (m).
PLATE_SIDE = 0.03


def plate_task() -> TaskSpec:
    """The slot task with its tray replaced by a flat plate (a static body, posed) whose two
    marks (the tray's colors, 16 x 30 mm, 84 mm apart) lie :data:`PLATE_SIDE` to the side of
    its point (the body's origin): a bias of the object, which turns with it."""
    slot = get_task("slot")

    def add_objects(world: Any, objects: Any, rng: np.random.Generator) -> None:
        add_block(world, objects["block"])
        p = objects["tray"]
        yaw = yaw_of(p)
        body = world.add_body(
            name="tray", pos=p[:3, 3].tolist(), quat=[math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]
        )
        body.add_geom(  # the plate: gray, 2 mm thick, its top face at the point's height
            name="tray_plate",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.055, 0.05, 0.001],
            pos=[0.0, PLATE_SIDE / 2, -0.001],
            rgba=[0.42, 0.42, 0.45, 1.0],
        )
        for end, x, rgba in (("a", -0.042, TRAY_MARK_A_RGBA), ("b", 0.042, TRAY_MARK_B_RGBA)):
            body.add_geom(
                name=f"tray_mark_{end}",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=[0.008, 0.015, 0.0002],
                pos=[x, PLATE_SIDE, 0.0002],
                rgba=list(rgba),
                contype=0,
                conaffinity=0,
            )

    z = 0.002
    r = slot.ranges["tray"]
    ranges = {
        "block": slot.ranges["block"],
        "tray": PlacementRange.box(
            (r.low[0], r.low[1], z), (r.high[0], r.high[1], z), (-math.pi / 3, math.pi / 3)
        ),
    }
    return dataclasses.replace(slot, name="plate", ranges=ranges, add_objects=add_objects)
