"""A block and a tray with a pocket that fits it: the bodies of a task where orientation matters.

:func:`add_block` adds a free rectangular block lying on the table, :func:`add_tray` a tray whose
rectangular pocket is the block's footprint plus :data:`POCKET_CLEARANCE` on every side. Both take
a pose (a 4x4 homogeneous matrix in the robot's base frame) whose rotation is a yaw about the
vertical: they lie flat. A task places them with posed ranges (``PlacementRange.box(low, high,
yaw=(lo, hi))``), whose placements are such poses (:func:`pbdkit.sim._tasks.yaw_pose`), and hands
its ``add_objects``' ``objects[name]`` on as it is.

Reference points and yaw (what the cameras measure)
---------------------------------------------------
- The block's point is the centre of its top face, and its body frame sits there: x along its
  length, from end a to end b, z up. The top face carries two flat colored marks, one at each end
  (geoms ``NAME_mark_a`` at -x, color :data:`BLOCK_MARK_A_RGBA`, and ``NAME_mark_b`` at +x,
  :data:`BLOCK_MARK_B_RGBA`), the same size and at the same distance from the centre: the midpoint
  of the two marks' centres is the block's point (0.2 mm above it, the marks' half thickness), and
  the block's yaw is the heading of the direction from mark a to mark b, ``atan2(dy, dx)``
  (:func:`pbdkit.sim._tasks.yaw_of` of its pose).
- The tray's point is the centre of the pocket's rim plane (the top faces of its walls; the
  pocket's floor is :data:`TRAY_DEPTH` lower), and its body frame sits there: x along the
  pocket's length, from end a to end b, z up. The tops of its two end walls carry its marks
  (``NAME_mark_a`` at -x, :data:`TRAY_MARK_A_RGBA`; ``NAME_mark_b`` at +x,
  :data:`TRAY_MARK_B_RGBA`), symmetric about the point as the block's are.

The block, the gripper and the pocket all look the same turned by 180 degrees; the marks are what
tells the two ends apart. The block fits the pocket at a relative yaw of 0 or 180 degrees, within
about +-5.7 degrees when centred (:func:`footprint_margin` says how far inside the pocket a
footprint is). Measured: dropped from 1-5 mm above the rim at the pocket's yaw (+-2 deg, +-1.5 mm)
it falls onto the floor; turned 10 degrees or more it rests on the rim, its bottom
:data:`TRAY_DEPTH` above the floor (``tests/test_slot_world.py`` checks both); a dropped block
twists in up to about 6 degrees off (20 drops of 20 at 6 degrees, 14 at 7, 12 at 8, 2 at 9, 0
at 10), while a held block lowered onto the rim by the arm at 8-15 degrees stayed on it.
Contacts of both bodies are stiff (the fingers' parameters): with MuJoCo's default, a block
pressed on the rim sank millimetres into it and the contact pushed it sideways into the pocket.

Colors
------
The four marks' colors are saturated hues apart from each other and from the colors the cameras
already track or see, in the CbCr plane of :mod:`pbdkit.vision._color` (hue = direction of
(Cb - 128, Cr - 128); a render's shading scales the chroma and keeps the hue, measured on the
scene's cameras): the block's yellow 161 deg and magenta 62 deg, the tray's cyan -68 deg and
violet 17 deg, against the glass's red band 109 deg, the coaster's blue -20 deg, the liquid's
green -120 deg and the table's tan 147 deg (chroma 28 only: the marks' is 75-100). The bodies
themselves are neutral gray, as the arm is, so they are never a patch
(:class:`pbdkit.vision.ColorModel` ignores achromatic pixels).

Grasping the block (the Katana's gripper of :mod:`pbdkit.sim._world`)
--------------------------------------------------------------------
With the hand pointing down (pitch -90 deg), the fingers close along the heading
``pan + roll + 90 deg``: a wrist roll ``yaw - pan`` (mod 180 deg) closes them across a block of
yaw ``yaw``. The finger pads reach :data:`FINGER_REACH` below the tool point and the palm ends
32.5 mm above it. A tool point :data:`BLOCK_GRASP_HEIGHT` above the block's top face holds the
top 9 mm of the block, leaving its lower 16 mm free: the block can then be lowered into the
pocket (its bottom 1 mm above the floor) with the fingertips 2 mm above the rim, which they must
stay above (the pocket's 3 mm of clearance leaves no room for a 5 mm finger beside the block).

Reach, hand pointing down (:func:`pbdkit.sim._teacher.solve_ik` with pitch -pi/2, 0.03 rad off the
joint limits): the grasp height (tool point 48 mm above the table) is reachable 0.05-0.29 m from
the base axis, 53 mm (release) 0.04-0.28 m, 90 mm 0.04-0.245 m, 120 mm 0.09-0.18 m; above
about 0.12 m the hand cannot point down (lift3 reaches its limit). Closer than 0.13 m an open
finger or the palm hits the base column (radius 0.07 m) when the fingers close radially, and a
tray (102 x 42 mm) would overlap it: objects belong 0.14-0.25 m from the base axis.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import short
from ._gl import mujoco
from ._tasks import yaw_of
from ._world import FINGER_HALF, SOLID, TIMESTEP, free_joint

__all__ = [
    "BLOCK_FRICTION",
    "BLOCK_GRASP_HEIGHT",
    "BLOCK_HEIGHT",
    "BLOCK_LENGTH",
    "BLOCK_MARK_A_RGBA",
    "BLOCK_MARK_B_RGBA",
    "BLOCK_MARK_LENGTH",
    "BLOCK_MASS",
    "BLOCK_RGBA",
    "BLOCK_WIDTH",
    "FINGER_REACH",
    "MARK_THICKNESS",
    "POCKET_CLEARANCE",
    "POCKET_LENGTH",
    "POCKET_WIDTH",
    "TRAY_DEPTH",
    "TRAY_END_WALL",
    "TRAY_FLOOR",
    "TRAY_LENGTH",
    "TRAY_MARK_A_RGBA",
    "TRAY_MARK_B_RGBA",
    "TRAY_MARK_LENGTH",
    "TRAY_RGBA",
    "TRAY_RIM_HEIGHT",
    "TRAY_SIDE_WALL",
    "TRAY_WIDTH",
    "add_block",
    "add_tray",
    "block_geom",
    "footprint_margin",
    "mark_prefix",
]

Float = NDArray[np.float64]

# -- the block --------------------------------------------------------------------------------
BLOCK_LENGTH = 0.060  # m, along its x axis (end a at -x, end b at +x)
BLOCK_WIDTH = 0.020  # m, along y: the fingers close across it
BLOCK_HEIGHT = 0.025  # m
BLOCK_MASS = 0.06  # kg (a dense plastic: 2000 kg/m^3)
#: Sliding, torsional and rolling friction of the block (MuJoCo's three coefficients). The
#: fingers' own (1.5, :mod:`pbdkit.sim._world`) win on the finger contacts by their priority.
BLOCK_FRICTION = (0.8, 0.005, 0.0001)
BLOCK_RGBA = (0.82, 0.82, 0.82, 1.0)  # neutral light gray: never a patch
#: Length of each mark along the block (m); a mark spans the top face's width less 1 mm a side
#: and stops 1 mm short of the end, so its centre is 22 mm from the block's point.
BLOCK_MARK_LENGTH = 0.016
#: Mark at end a (-x): yellow. Mark at end b (+x): magenta.
BLOCK_MARK_A_RGBA = (0.95, 0.80, 0.05, 1.0)
BLOCK_MARK_B_RGBA = (0.85, 0.10, 0.70, 1.0)
MARK_THICKNESS = 0.0004  # m, the marks stand this much proud of the face they lie on

# -- the tray ---------------------------------------------------------------------------------
POCKET_CLEARANCE = 0.003  # m, between the block and the pocket's wall, on every side
POCKET_LENGTH = BLOCK_LENGTH + 2.0 * POCKET_CLEARANCE  # 66 mm
POCKET_WIDTH = BLOCK_WIDTH + 2.0 * POCKET_CLEARANCE  # 26 mm
TRAY_FLOOR = 0.004  # m, the pocket's floor (top face) above the table
TRAY_DEPTH = 0.015  # m, the rim above the pocket's floor
TRAY_RIM_HEIGHT = TRAY_FLOOR + TRAY_DEPTH  # m, above the table: the tray's point's height
TRAY_SIDE_WALL = 0.008  # m, thickness of the long walls
TRAY_END_WALL = 0.018  # m, thickness of the end walls (they carry the marks)
TRAY_LENGTH = POCKET_LENGTH + 2.0 * TRAY_END_WALL  # 102 mm, outer
TRAY_WIDTH = POCKET_WIDTH + 2.0 * TRAY_SIDE_WALL  # 42 mm, outer
TRAY_RGBA = (0.42, 0.42, 0.45, 1.0)  # neutral dark gray
#: Length of each tray mark along the tray (m), centred on its end wall's top face, which it
#: covers across the tray's width less 1 mm a side.
TRAY_MARK_LENGTH = 0.016
#: Mark at end a (-x): cyan. Mark at end b (+x): violet.
TRAY_MARK_A_RGBA = (0.05, 0.75, 0.80, 1.0)
TRAY_MARK_B_RGBA = (0.45, 0.15, 0.85, 1.0)

# -- the gripper, for a top-down grasp ----------------------------------------------------------
#: How far the finger pads reach beyond the tool point along the tool axis (m).
FINGER_REACH = FINGER_HALF[2]
#: Tool point above the block's top face for a top-down grasp (m): the pads hold the top
#: 9 mm of the block (FINGER_REACH - BLOCK_GRASP_HEIGHT).
BLOCK_GRASP_HEIGHT = 0.023


# Stiff contacts for the block and the tray (the fingers' parameters, pbdkit.sim._world): with
# MuJoCo's default (a 0.02 s time constant) a block pressed on the pocket's rim by the arm sinks
# millimetres into it, and the contact then resolves sideways along the wall's inner face and
# screws a misaligned block into the pocket.
_STIFF: dict[str, Any] = {
    "priority": 1,
    "solref": [2.0 * TIMESTEP, 1.0],
    "solimp": [0.95, 0.99, 0.001, 0.5, 2.0],
}


def block_geom(name: str) -> str:
    """Name of the collision geom of the block ``name`` (``NAME_box``): what the fingers touch."""
    return f"{name}_box"


def mark_prefix(name: str, end: str) -> str:
    """Name (and prefix) of the geom of the mark at ``end`` ("a" or "b") of object ``name``."""
    if end not in ("a", "b"):
        raise ValueError(f"end must be 'a' or 'b', got {short(end)}")
    return f"{name}_mark_{end}"


def _check_flat_pose(pose: npt.ArrayLike, what: str) -> tuple[Float, float]:
    """Position (3,) and yaw of a 4x4 pose whose rotation turns about the vertical only."""
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (4, 4) or not np.all(np.isfinite(p)):
        raise ValueError(f"{what}: pose must be a finite 4x4 matrix, got shape {p.shape}")
    rot = p[:3, :3]
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or abs(rot[2, 2] - 1.0) > 1e-6:
        raise ValueError(
            f"{what}: the pose's rotation must be a yaw about the vertical (z up), got "
            f"{np.round(rot, 6).tolist()}"
        )
    return p[:3, 3].copy(), yaw_of(p)


def _yaw_quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def _add_mark(
    body: Any, name: str, x: float, z: float, half: tuple[float, float], rgba: Any
) -> None:
    # A flat colored patch: visual only (no contact, no mass).
    body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[half[0], half[1], MARK_THICKNESS / 2],
        pos=[x, 0.0, z + MARK_THICKNESS / 2],
        rgba=list(rgba),
        contype=0,
        conaffinity=0,
        density=0.0,
    )


def add_block(world: Any, pose: npt.ArrayLike, *, name: str = "block") -> None:
    """Add a free block (body ``name``) lying on the table.

    Parameters
    ----------
    world : mujoco.MjsBody
        The worldbody of the scene's ``MjSpec``.
    pose : array-like, shape (4, 4)
        Base frame pose of the block's point, the centre of its top face (module docstring):
        its position (z = :data:`BLOCK_HEIGHT` for the block on the table) and its yaw about the
        vertical (x along the block, from mark a to mark b).
    name : str
        The body's name (a task's :attr:`~pbdkit.sim.TaskSpec.grasped` when the gripper
        holds it). Its geoms are ``NAME_box`` (the solid, :func:`block_geom`), ``NAME_mark_a``
        and ``NAME_mark_b`` (:func:`mark_prefix`); its free joint is ``NAME_free``
        (:func:`pbdkit.sim._world.free_joint`, as a glass's).

    Raises
    ------
    ValueError
        A pose that is not a finite 4x4 matrix with a yaw-only rotation.
    """
    pos, yaw = _check_flat_pose(pose, f"add_block({short(name)})")
    body = world.add_body(name=name, pos=pos.tolist(), quat=_yaw_quat(yaw))
    body.add_freejoint(name=free_joint(name))
    hx, hy, hz = BLOCK_LENGTH / 2, BLOCK_WIDTH / 2, BLOCK_HEIGHT / 2
    body.add_geom(
        name=block_geom(name),
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[hx, hy, hz],
        pos=[0.0, 0.0, -hz],
        rgba=list(BLOCK_RGBA),
        mass=BLOCK_MASS,
        condim=4,
        **_STIFF,
        friction=list(BLOCK_FRICTION),
        contype=SOLID,
        conaffinity=SOLID,
    )
    half = (BLOCK_MARK_LENGTH / 2, hy - 0.001)
    x = hx - 0.001 - BLOCK_MARK_LENGTH / 2
    _add_mark(body, mark_prefix(name, "a"), -x, 0.0, half, BLOCK_MARK_A_RGBA)
    _add_mark(body, mark_prefix(name, "b"), x, 0.0, half, BLOCK_MARK_B_RGBA)


def add_tray(world: Any, pose: npt.ArrayLike, *, name: str = "tray", mocap: bool = False) -> None:
    """Add a tray (body ``name``) standing on the table, with a pocket that fits the block.

    Parameters
    ----------
    world : mujoco.MjsBody
        The worldbody of the scene's ``MjSpec``.
    pose : array-like, shape (4, 4)
        Base frame pose of the tray's point, the centre of the pocket's rim plane (module
        docstring): its position (z = :data:`TRAY_RIM_HEIGHT` for the tray on the table) and its
        yaw about the vertical (x along the pocket, from mark a to mark b).
    name : str
        The body's name. Its geoms are ``NAME_floor``, ``NAME_wall0..3``, ``NAME_mark_a`` and
        ``NAME_mark_b``.
    mocap : bool
        Build it as a MuJoCo mocap body: static for the physics, but
        :meth:`pbdkit.sim.Simulation.place_object` can move and turn it (a disturbance).

    Raises
    ------
    ValueError
        A pose that is not a finite 4x4 matrix with a yaw-only rotation.
    """
    pos, yaw = _check_flat_pose(pose, f"add_tray({short(name)})")
    body = world.add_body(name=name, pos=pos.tolist(), quat=_yaw_quat(yaw), mocap=mocap)
    solid: dict[str, Any] = {
        "type": mujoco.mjtGeom.mjGEOM_BOX,
        "rgba": list(TRAY_RGBA),
        "friction": [0.8, 0.005, 0.0001],
        "contype": SOLID,
        "conaffinity": SOLID,
        **_STIFF,
    }
    lx, ly = TRAY_LENGTH / 2, TRAY_WIDTH / 2
    # Body frame at the rim plane: the tray's bottom is TRAY_RIM_HEIGHT below.
    body.add_geom(
        name=f"{name}_floor",
        size=[lx, ly, TRAY_FLOOR / 2],
        pos=[0.0, 0.0, -TRAY_RIM_HEIGHT + TRAY_FLOOR / 2],
        **solid,
    )
    zc, hz = -TRAY_DEPTH / 2, TRAY_DEPTH / 2
    px, py = POCKET_LENGTH / 2, POCKET_WIDTH / 2
    walls = [
        # end walls (across the whole width), then side walls (between the end walls)
        (-(px + TRAY_END_WALL / 2), 0.0, TRAY_END_WALL / 2, ly),
        (px + TRAY_END_WALL / 2, 0.0, TRAY_END_WALL / 2, ly),
        (0.0, -(py + TRAY_SIDE_WALL / 2), px, TRAY_SIDE_WALL / 2),
        (0.0, py + TRAY_SIDE_WALL / 2, px, TRAY_SIDE_WALL / 2),
    ]
    for i, (x, y, sx, sy) in enumerate(walls):
        body.add_geom(name=f"{name}_wall{i}", size=[sx, sy, hz], pos=[x, y, zc], **solid)
    half = (TRAY_MARK_LENGTH / 2, ly - 0.001)
    x = px + TRAY_END_WALL / 2
    _add_mark(body, mark_prefix(name, "a"), -x, 0.0, half, TRAY_MARK_A_RGBA)
    _add_mark(body, mark_prefix(name, "b"), x, 0.0, half, TRAY_MARK_B_RGBA)


def footprint_margin(block_pose: npt.ArrayLike, tray_pose: npt.ArrayLike) -> float:
    """How far the block's footprint lies inside the tray's pocket, horizontally (m).

    The smallest distance from a corner of the block's footprint (its rectangle seen from
    above, at the pose's yaw) to the pocket's inner walls, taken positive inside: > 0 when the
    whole footprint is within the walls (the block can sit on the pocket's floor), < 0 when a
    corner lies over or beyond a wall. Heights are ignored: compare the block's height with the
    floor's (:data:`TRAY_DEPTH` below the tray's point) to tell a block in the pocket from one
    resting on the rim. Centred and aligned (relative yaw 0 or 180 deg), the margin is
    :data:`POCKET_CLEARANCE`; it reaches 0 at a relative yaw of about 5.7 deg.

    Parameters
    ----------
    block_pose, tray_pose : array-like, shape (4, 4)
        Poses of the block's and the tray's points (only the positions' x, y and the yaws are
        used).
    """
    b = np.asarray(block_pose, dtype=np.float64)
    t = np.asarray(tray_pose, dtype=np.float64)
    yaw = yaw_of(b) - yaw_of(t)
    ct, st = math.cos(yaw_of(t)), math.sin(yaw_of(t))
    d = b[:2, 3] - t[:2, 3]
    centre = np.array([ct * d[0] + st * d[1], -st * d[0] + ct * d[1]])  # in the tray's frame
    c, s = math.cos(yaw), math.sin(yaw)
    hx, hy = BLOCK_LENGTH / 2, BLOCK_WIDTH / 2
    corners = np.array([[sx * hx, sy * hy] for sx in (-1, 1) for sy in (-1, 1)])
    pts = centre + corners @ np.array([[c, s], [-s, c]])
    inside = np.minimum(POCKET_LENGTH / 2 - np.abs(pts[:, 0]), POCKET_WIDTH / 2 - np.abs(pts[:, 1]))
    return float(inside.min())
