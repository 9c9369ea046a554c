"""The two tasks of the paper (Sec. III), their fixed geometry and the ranges of object placements.

All positions are in the robot's base frame (the frame of the URDF root, ``base_link``), in metres:
x points away from the robot across the table, z up, and the table top is the plane z = 0 (the arm's
base column stands on it).

An object's position ``o`` is the point a camera measures:

- ``glass``: the point on the glass's axis at the height of the centre of its red band;
- ``coaster``: the centre of the coaster's top face;
- ``basin``: the centre of the basin's floor (top face). The basin is fixed.

The Katana holds the glass from the side with its long wrist (0.30 m from the wrist pitch joint to
the tool point) nearly horizontal, which folds the elbow beyond its limit closer than about 0.45 m
from the base axis: placements lie 0.45-0.58 m from it.

Ranges are boxes ``(low, high)`` of shape (3,) each; a range whose low and high are equal is a
fixed object. Demonstrations sample inside them (:func:`sample_objects`) and so can evaluation
trials, which then stay inside the demonstrated range.

Fixed and tracked objects (paper Sec. III): the ranges are the one place that says which objects
move. Those that move (:func:`tracked_objects`) are located by the cameras and get a task-space
constraint; a fixed one (the basin) is at a known place (:func:`fixed_objects`), carries no
patch, and gets no constraint in the paper's configuration: its position is the same in every
demonstration, so the hand's path relative to it is the joint-space constraint seen through the
forward kinematics. Demonstrations still record it, as a user's recording would.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

Float = NDArray[np.float64]

# Glass: an open cylinder (thin boxes around a disk bottom) that can hold the liquid spheres.
GLASS_RADIUS = 0.025  # outer radius (m)
GLASS_WALL = 0.003  # wall thickness (m)
GLASS_HEIGHT = 0.10  # (m)
GLASS_BOTTOM = 0.006  # thickness of the bottom disk (m)
GLASS_PATCH_LOW = 0.065  # red band, height above the glass's bottom face (m)
GLASS_PATCH_HIGH = 0.085
GLASS_PATCH_CENTER = 0.5 * (GLASS_PATCH_LOW + GLASS_PATCH_HIGH)
# Height above the glass's bottom face at which the fingers hold it (centre of the finger pads).
GLASS_GRASP_HEIGHT = 0.045
# Tool point minus glass position when the glass is held upright with the tool on its axis.
GRASP_OFFSET: Float = np.array([0.0, 0.0, GLASS_GRASP_HEIGHT - GLASS_PATCH_CENTER])

COASTER_RADIUS = 0.045
COASTER_THICKNESS = 0.006

SHELF_HEIGHT = 0.10  # top face of the shelf board (m)
# Shelf board extent (x, y) in the base frame: it holds every glass placement of the coaster task.
SHELF_X = (0.38, 0.58)
SHELF_Y = (0.06, 0.32)

BASIN_CENTER_XY = (0.45, -0.22)
BASIN_INNER = 0.20  # inner side length (square), m
BASIN_WALL_HEIGHT = 0.06  # above the floor's top face
BASIN_FLOOR = 0.02  # floor thickness (thick: falling spheres must not pass through it)

LIQUID_RADIUS = 0.0055
N_LIQUID = 20

TASKS = ("coaster", "basin")


@dataclass(frozen=True)
class PlacementRange:
    """Range of positions of one object: a box, uniform sampling.

    Attributes
    ----------
    low, high : ndarray, shape (3,)
        Corners of the box (equal for a fixed object).
    """

    low: Float
    high: Float

    @property
    def fixed(self) -> bool:
        """True if the object never moves."""
        return bool(np.array_equal(self.low, self.high))

    @property
    def center(self) -> Float:
        """Centre of the box, shape (3,)."""
        return 0.5 * (self.low + self.high)

    def contains(self, position: Float, tol: float = 1e-9) -> bool:
        """True if ``position`` (3,) lies in the box (up to ``tol``)."""
        p = np.asarray(position, dtype=np.float64)
        return bool(np.all(p >= self.low - tol) and np.all(p <= self.high + tol))


def _box(low: tuple[float, float, float], high: tuple[float, float, float]) -> PlacementRange:
    return PlacementRange(np.array(low, dtype=np.float64), np.array(high, dtype=np.float64))


_GLASS_ON_SHELF_Z = SHELF_HEIGHT + GLASS_PATCH_CENTER
_GLASS_ON_TABLE_Z = GLASS_PATCH_CENTER
_BASIN_POS = (BASIN_CENTER_XY[0], BASIN_CENTER_XY[1], BASIN_FLOOR)

#: Placement ranges per task: object name -> range. The glass stands on its support (z fixed).
PLACEMENT_RANGES: dict[str, dict[str, PlacementRange]] = {
    "coaster": {
        "glass": _box((0.44, 0.12, _GLASS_ON_SHELF_Z), (0.50, 0.24, _GLASS_ON_SHELF_Z)),
        "coaster": _box((0.45, -0.24, COASTER_THICKNESS), (0.52, -0.10, COASTER_THICKNESS)),
    },
    "basin": {
        "glass": _box((0.47, 0.08, _GLASS_ON_TABLE_Z), (0.54, 0.22, _GLASS_ON_TABLE_Z)),
        "basin": _box(_BASIN_POS, _BASIN_POS),
    },
}


def check_task(task: str) -> str:
    """Return ``task`` if it is a known task name, else raise ValueError."""
    if task not in PLACEMENT_RANGES:
        raise ValueError(f"task must be one of {list(TASKS)}, got {task!r}")
    return task


def tracked_objects(task: str) -> tuple[str, ...]:
    """Objects of ``task`` that move between placements, in range order (the cameras track them)."""
    ranges = PLACEMENT_RANGES[check_task(task)]
    return tuple(name for name, r in ranges.items() if not r.fixed)


def fixed_objects(task: str) -> tuple[str, ...]:
    """Objects of ``task`` that never move (the basin), in range order; known without vision."""
    ranges = PLACEMENT_RANGES[check_task(task)]
    return tuple(name for name, r in ranges.items() if r.fixed)


def full_placement(task: str, objects: Mapping[str, npt.ArrayLike]) -> dict[str, Float]:
    """Every object's position for a placement: ``objects`` plus the fixed objects' positions.

    Use it where a subset of the objects is known (e.g. those of a skill that has no constraint
    on the fixed ones) and the whole scene is needed (the simulation, the success judge).

    Parameters
    ----------
    task : {"coaster", "basin"}
    objects : dict str -> array-like, shape (3,)
        Positions of at least every moving object (:func:`tracked_objects`); fixed objects may
        be given too (they are then kept as given, for :func:`pbdkit.sim.build_scene` to check).

    Returns
    -------
    placement : dict str -> ndarray, shape (3,)
        One position per object of the task, in range order.

    Raises
    ------
    ValueError
        An object that is not one of the task's, or a moving object without a position.
    """
    ranges = PLACEMENT_RANGES[check_task(task)]
    unknown = sorted(set(objects) - set(ranges))
    if unknown:
        raise ValueError(
            f"objects: unknown object(s) {unknown} for task {task!r}; expected {list(ranges)}"
        )
    missing = [k for k in tracked_objects(task) if k not in objects]
    if missing:
        raise ValueError(
            f"objects: missing position(s) for {missing}: they move between placements, so the "
            f"{task!r} task needs them (only fixed objects {list(fixed_objects(task))} are known)"
        )
    return {
        name: np.array(objects[name], dtype=np.float64) if name in objects else r.low.copy()
        for name, r in ranges.items()
    }


def nominal_objects(task: str) -> dict[str, Float]:
    """Centre of every placement range of ``task``: name -> position (3,)."""
    return {name: r.center.copy() for name, r in PLACEMENT_RANGES[check_task(task)].items()}


def sample_objects(task: str, rng: np.random.Generator) -> dict[str, Float]:
    """Draw object positions uniformly inside the placement ranges of ``task``.

    Parameters
    ----------
    task : {"coaster", "basin"}
    rng : numpy.random.Generator

    Returns
    -------
    dict str -> ndarray, shape (3,)
        One position per object of the task (fixed objects at their fixed position).
    """
    ranges = PLACEMENT_RANGES[check_task(task)]
    return {name: rng.uniform(r.low, r.high) for name, r in ranges.items()}
