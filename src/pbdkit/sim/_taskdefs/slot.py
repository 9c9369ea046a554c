"""A task where orientation decides success: a turned block into a turned slot (issue 24).

A rectangular block (:func:`pbdkit.sim._parts.add_block`, 60 x 20 x 25 mm) lies on the table at a
random position and yaw; a tray (:func:`pbdkit.sim._parts.add_tray`) whose pocket is 3 mm wider
than the block on every side stands at another random position and yaw. The arm grasps the block
from above, carries it and lowers it into the pocket. Both objects are poses
(:attr:`pbdkit.sim.PlacementRange.yaw`): the skill learns the hand's pose relative to each
(:meth:`pbdkit.Skill.learn` with ``orientation=True``), and the paper's skill of the same
demonstrations (frames that translate only) is the ``"fused-position"`` controller.

Reach. With the hand pointing down, the Katana's wrist-roll joint sits about 0.30 m above the
tool point; at the grasp height the tool reaches the table 0.05-0.29 m from the base axis, and
closer than about 0.13 m an open finger or the palm hits the base column
(:mod:`pbdkit.sim._parts`, "Reach"). Both objects lie 0.14-0.22 m from the base axis: the block to
the robot's left, the tray to its right, boxes of 4 x 6 cm (their far corners 0.22 m from the
axis: the hand rises 35 mm above the grasp and the release, where farther out it cannot point
down without a joint near its limit). The yaw of the hand is free (pan + roll): the wrist
roll ``yaw - pan`` closes the fingers across a block of yaw ``yaw``.

Symmetry. The gripper, the block and the pocket look the same turned by 180 degrees. Yaw is
defined from each object's marks (end a to end b, :mod:`pbdkit.sim._parts`), the teacher always
grasps with the same roll relative to the block's yaw (``yaw - pan``, never the other solution
180 degrees away), and always puts end a of the block to end a of the pocket: the relative yaws
are the same in every demonstration, so the skill does not average two grasps 180 degrees apart.

Success: the block rests in the pocket (its whole footprint inside the walls, its bottom within
3 mm of the pocket's floor) and the fingers have let go. For a 60 mm block in a 66 x 26 mm pocket
that means a relative yaw within about 5.7 degrees (:func:`pbdkit.sim._parts.footprint_margin`).
Metrics: ``yaw_error_deg`` (relative yaw, modulo 180 degrees), ``placement_error_mm`` (horizontal
distance between the block's and the pocket's centres), ``height_error_mm`` (block bottom above
the pocket's floor), ``margin_mm`` (footprint inside the walls, negative when over one),
``released``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...collision import Box, Scene
from .._parts import (
    BLOCK_GRASP_HEIGHT,
    BLOCK_HEIGHT,
    BLOCK_LENGTH,
    BLOCK_WIDTH,
    TRAY_DEPTH,
    TRAY_LENGTH,
    TRAY_RIM_HEIGHT,
    TRAY_WIDTH,
    add_block,
    add_tray,
    footprint_margin,
    mark_prefix,
)
from .._scene import Simulation
from .._task_scenes import table_shape
from .._tasks import (
    CameraRig,
    ObjectTurn,
    Outcome,
    PlacementRange,
    RunStats,
    TaskSpec,
    ViaPoint,
    yaw_of,
)
from .._teacher import UP, Person

__all__ = ["SPEC", "add_objects", "judge", "scene", "via_points"]

Float = NDArray[np.float64]

#: The hand pointing down (tool pitch, rad).
DOWN = -math.pi / 2
YAW_RANGE = (-math.radians(60.0), math.radians(60.0))
#: Above the grasp and the release (m): the hand comes down vertically from there.
HOVER = 0.035
#: The block's bottom above the pocket's floor when the fingers open (m): it drops onto it.
RELEASE_GAP = 0.001
MAX_HEIGHT_ERROR = 0.003  # m

#: Placement ranges: the block to the robot's left, the tray to its right, 0.14-0.22 m from the
#: base axis (module docstring, "Reach"); positions are each object's point (the block's top
#: face centre, the tray's rim plane centre).
RANGES: dict[str, PlacementRange] = {
    "block": PlacementRange.box((0.12, 0.09, BLOCK_HEIGHT), (0.16, 0.15, BLOCK_HEIGHT), YAW_RANGE),
    "tray": PlacementRange.box(
        (0.12, -0.15, TRAY_RIM_HEIGHT), (0.16, -0.09, TRAY_RIM_HEIGHT), YAW_RANGE
    ),
}

#: The cameras: each object's two marks (end a, end b) give its pose (:mod:`pbdkit.sim._tracking`).
PATCHES = {name: (mark_prefix(name, "a"), mark_prefix(name, "b")) for name in ("block", "tray")}

#: The stereo pair for this task: the paper's rig (0.30 m baseline, in front of the robot) moved
#: closer, lower and narrower. From the paper's place (1.05 m out, 0.52 m up, 42 degrees) a
#: mark covered 12-36 pixels; from here (0.85 m out, 0.50 m up, looking at the table between
#: the two objects, 24 degrees) 57-170 (medians: block 68-74, tray 142-170), and a mark's
#: blob stays 19 pixels or more inside the image border. The cameras look under the raised
#: hand of the start posture (x 0.28-0.34 m, 0.27-0.32 m up), which hid the tray's marks from
#: a higher rig (0.62 m out and up); here it hides none (40 placements and start postures).
CAMERAS = CameraRig(
    left=(0.85, 0.15, 0.50), right=(0.85, -0.15, 0.50), target=(0.15, 0.0, 0.0), fovy=24.0
)

DESCRIPTION = (
    "Put the block into the slot: grasp the block lying on the table from above and lower it "
    "into the tray's pocket, 3 mm wider than the block on every side. Both are placed and "
    "turned anew (yaw -60..60 degrees): the hand must turn with the block to grasp it and with "
    "the tray to put it in, within about 5 degrees."
)


def _pan(p: Float) -> float:
    return math.atan2(float(p[1]), float(p[0]))


def _roll_for(yaw: float, p: Float) -> float:
    """The wrist roll that closes the fingers across an object of ``yaw`` at ``p``, always the
    same solution (module docstring, "Symmetry")."""
    return math.remainder(yaw - _pan(p), 2 * math.pi)


def scene(objects: Mapping[str, Float]) -> Scene:
    """The table; the block's and the tray's shapes (the tray as its outer box: the block's
    target, which it may touch)."""
    block = Box((BLOCK_LENGTH, BLOCK_WIDTH, BLOCK_HEIGHT), (0.0, 0.0, -BLOCK_HEIGHT / 2))
    tray = Box((TRAY_LENGTH, TRAY_WIDTH, TRAY_RIM_HEIGHT), (0.0, 0.0, -TRAY_RIM_HEIGHT / 2))
    return Scene([table_shape()], objects={"block": block, "tray": tray})


def add_objects(world: Any, objects: Mapping[str, Float], rng: np.random.Generator) -> None:
    """The block and the tray (no jitter: ``rng`` is unused)."""
    add_block(world, objects["block"])
    add_tray(world, objects["tray"], mocap=True)


def release_point(tray: Float) -> Float:
    """Where the tool point is when the fingers open: the block's bottom :data:`RELEASE_GAP`
    above the pocket's floor, on the pocket's centre."""
    p = tray[:3, 3]
    top = p[2] - TRAY_DEPTH + RELEASE_GAP + BLOCK_HEIGHT
    return np.array([p[0], p[1], top + BLOCK_GRASP_HEIGHT])


def via_points(
    objects: Mapping[str, Float], rng: np.random.Generator, speed: float = 1.0
) -> list[ViaPoint]:
    """Via points for given block and tray poses: above the block, down, close, lift, carry
    above the tray turning the hand with it, down, open, up."""
    p = Person(rng, speed)
    block, tray = objects["block"], objects["tray"]
    grasp = block[:3, 3] + UP * BLOCK_GRASP_HEIGHT
    release = release_point(tray)
    roll_b = _roll_for(yaw_of(block), grasp)
    roll_t = _roll_for(yaw_of(tray), release)
    return [
        # A free swing (joint space) to above the block, the hand turned for the grasp.
        ViaPoint(
            p.duration(3.0),
            grasp + UP * (HOVER + 0.01) + p.jitter(0.005),
            DOWN,
            roll_b,
            False,
            joint_space=True,
        ),
        ViaPoint(p.duration(1.0), grasp + UP * HOVER, DOWN, roll_b, False),
        ViaPoint(p.duration(1.2), grasp, DOWN, roll_b, False),
        ViaPoint(p.duration(0.6), grasp, DOWN, roll_b, True),  # close and wait for the grip
        ViaPoint(p.duration(1.0), grasp + UP * HOVER, DOWN, roll_b, True),
        # Carry: the hand turns from the block's yaw to the tray's on the way.
        ViaPoint(p.duration(2.2), release + UP * HOVER + p.jitter(0.003), DOWN, roll_t, True),
        ViaPoint(p.duration(0.8), release + UP * HOVER, DOWN, roll_t, True),
        ViaPoint(p.duration(1.3), release, DOWN, roll_t, True),
        ViaPoint(p.duration(0.6), release, DOWN, roll_t, False),  # open and wait
        ViaPoint(p.duration(1.2), release + UP * HOVER, DOWN, roll_t, False),
    ]


def judge(sim: Simulation, run: RunStats) -> Outcome:
    """Success and metrics (module docstring) of the state after a run."""
    block = sim.grasped_pose()
    tray = sim.object_poses()["tray"]  # where it is now (it may have turned)
    rel = yaw_of(block) - yaw_of(tray)
    yaw_err = abs(math.degrees(math.remainder(rel, math.pi)))
    margin = footprint_margin(block, tray)
    floor = tray[2, 3] - TRAY_DEPTH
    height = float(block[2, 3] - BLOCK_HEIGHT - floor)
    err = float(np.linalg.norm(block[:2, 3] - tray[:2, 3]))
    released = sim.grasped_released()
    ok = margin > 0.0 and abs(height) <= MAX_HEIGHT_ERROR and released
    metrics = {
        "yaw_error_deg": yaw_err,
        "placement_error_mm": 1e3 * err,
        "height_error_mm": 1e3 * height,
        "margin_mm": 1e3 * margin,
        "released": float(released),
    }
    return Outcome(bool(ok), metrics)


SPEC = TaskSpec(
    name="slot",
    description=DESCRIPTION,
    ranges=RANGES,
    add_objects=add_objects,
    via_points=via_points,
    judge=judge,
    patches=PATCHES,
    cameras=CAMERAS,
    grasped="block",
    # --perturb rotate: the tray turns about its centre while the block is carried, its yaw
    # staying inside YAW_RANGE (pbdkit.sim._perturb).
    rotate=ObjectTurn("tray", (20.0, 30.0), "while_carried"),
    scene=scene,
)
