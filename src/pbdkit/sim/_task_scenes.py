"""The shapes the simulated tasks' scenes share (:attr:`pbdkit.sim.TaskSpec.scene`): the table
and the glass, from the same dimensions the simulated world is built with."""

from __future__ import annotations

from ..collision import Box, Cylinder
from ._glass import GLASS_HEIGHT, GLASS_PATCH_CENTER, GLASS_RADIUS
from ._world import TABLE_CENTRE, TABLE_HALF

__all__ = ["glass_shape", "table_shape"]


def table_shape() -> Box:
    """The table (its top face at z = 0), named ``table``."""
    return Box([2.0 * h for h in TABLE_HALF], TABLE_CENTRE, name="table")


def glass_shape() -> Cylinder:
    """The glass in its own frame: its reference point is on its axis, ``GLASS_PATCH_CENTER``
    above its bottom face."""
    return Cylinder(GLASS_RADIUS, GLASS_HEIGHT, (0.0, 0.0, GLASS_HEIGHT / 2 - GLASS_PATCH_CENTER))
