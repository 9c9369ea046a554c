"""The glass the paper's tasks hold: its dimensions, its colored band, where the fingers hold it.

Built by :func:`pbdkit.sim._world.add_glass`; its reference point (what the cameras measure, a
task's placement of it) is on its axis at the height of the centre of its red band. Lengths in
metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "GLASS_BOTTOM",
    "GLASS_GRASP_HEIGHT",
    "GLASS_HEIGHT",
    "GLASS_PATCH_CENTER",
    "GLASS_PATCH_HIGH",
    "GLASS_PATCH_LOW",
    "GLASS_PATCH_PREFIX",
    "GLASS_RADIUS",
    "GLASS_WALL",
    "GRASP_OFFSET",
    "LIQUID_RADIUS",
    "patch_prefix",
]

Float = NDArray[np.float64]

# Glass: an open cylinder (thin boxes around a disk bottom) that can hold the liquid spheres.
GLASS_RADIUS = 0.025  # outer radius (m)
GLASS_WALL = 0.003  # wall thickness (m)
GLASS_HEIGHT = 0.10  # (m)
GLASS_BOTTOM = 0.006  # thickness of the bottom disk (m)
GLASS_PATCH_LOW = 0.065  # red band, height above the glass's bottom face (m)
GLASS_PATCH_HIGH = 0.085
GLASS_PATCH_CENTER = 0.5 * (GLASS_PATCH_LOW + GLASS_PATCH_HIGH)


def patch_prefix(name: str) -> str:
    """Name prefix of the geoms of the red band of the glass ``name`` (``NAME_patch0..11``,
    :func:`pbdkit.sim._world.add_glass`), for the cameras."""
    return f"{name}_patch"


#: Name prefix of the geoms of the glass's red band (``glass_patch0..11``), for the cameras.
GLASS_PATCH_PREFIX = patch_prefix("glass")
# Height above the glass's bottom face at which the fingers hold it (centre of the finger pads).
GLASS_GRASP_HEIGHT = 0.045
# Tool point minus glass position when the glass is held upright with the tool on its axis.
GRASP_OFFSET: Float = np.array([0.0, 0.0, GLASS_GRASP_HEIGHT - GLASS_PATCH_CENTER])

LIQUID_RADIUS = 0.0055
