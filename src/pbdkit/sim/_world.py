"""The world builder: the MuJoCo model of a task's scene, compiled from an ``MjSpec``.

:func:`build_scene` compiles a MuJoCo model whose arm is loaded from the very URDF text that
:func:`pbdkit.robots.katana` gives pinocchio (so the two kinematics agree to machine precision; a
test checks it), and adds, in the robot's base frame (table top at z = 0):

- a table, two 320x240 cameras ``cam_left`` and ``cam_right`` (baseline 0.30 m) across it and a
  light; a task may place the cameras elsewhere (:attr:`pbdkit.sim.TaskSpec.cameras`);
- a parallel two-finger gripper on the ``gripper`` link (coupled fingers on slide joints, position
  actuators with a force limit: grasps are physical, by contact and friction);
- position and velocity servos on the 5 arm joints (a PD loop with velocity feed-forward) and
  gravity compensation of the arm's own links, like the Katana's controllers;
- the task's objects, added by its :attr:`pbdkit.sim.TaskSpec.add_objects` with the
  builders of this module: a glass (:func:`add_glass`: an open cylinder of thin boxes around a disk
  bottom, so it holds liquid, with a red band for the cameras), liquid spheres in it
  (:func:`add_liquid`), and the task's own bodies (a shelf, a coaster, a basin ...).

Contact bits: geoms of solids collide through bit :data:`SOLID`, the liquid through bit
:data:`LIQUID`; the glass's bottom disk only meets the liquid (the glass stands on the lower edges
of its wall boxes, which gives many contacts and a stable stand).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import quaternion_from_matrix
from .._validation import short
from ..collision import Box, Cylinder, Shape, Sphere
from ..data._placement import position_of
from ..robots import katana
from ._gl import mujoco
from ._glass import (
    GLASS_BOTTOM,
    GLASS_HEIGHT,
    GLASS_PATCH_CENTER,
    GLASS_PATCH_HIGH,
    GLASS_PATCH_LOW,
    GLASS_RADIUS,
    GLASS_WALL,
    GRASP_OFFSET,
    LIQUID_RADIUS,
    patch_prefix,
)
from ._tasks import CameraRig, TaskSpec, check_task, yaw_of, yaw_pose

__all__ = [
    "ARM_JOINTS",
    "CAMERAS",
    "CAMERA_POSITIONS",
    "CAMERA_TARGET",
    "FINGER_JOINTS",
    "IMAGE_HEIGHT",
    "IMAGE_WIDTH",
    "LIQUID",
    "SOLID",
    "TIMESTEP",
    "SceneInfo",
    "add_glass",
    "add_liquid",
    "build_scene",
    "free_joint",
    "wall_prefix",
]

Float = NDArray[np.float64]

ARM_JOINTS = ("pan", "lift1", "lift2", "lift3", "wrist_roll")
FINGER_JOINTS = ("finger_left", "finger_right")
#: The scene's two cameras (MuJoCo camera names), left and right of the stereo pair.
CAMERAS = ("cam_left", "cam_right")
IMAGE_WIDTH = 320
IMAGE_HEIGHT = 240

TIMESTEP = 0.002  # physics step (s): 500 Hz
# Arm servo: torque = KP (q* - q) + KV (dq* - dq). Armature models the motors' reflected inertia
# (the Katana has harmonic drives); without it the light wrist would make KP unstable at 500 Hz.
ARM_KP = 1000.0  # N m / rad
ARM_KV = 20.0  # N m s / rad
ARM_ARMATURE = 0.05  # kg m^2
ARM_DAMPING = 0.5  # N m s / rad, joint friction
# Fingers: opening q of each finger = distance from the tool axis to its inner face (m).
FINGER_OPEN = 0.04
FINGER_CLOSED = 0.0  # target when closing: the force limit, not the target, sets the grip
FINGER_RANGE = (0.0, 0.045)
FINGER_KP = 1000.0  # N / m
FINGER_FORCE = 12.0  # N, grip force limit per finger
FINGER_HALF = (0.011, 0.005, 0.032)  # finger box half sizes in the gripper frame (x, y, z)
# Length of the gripper's palm box along the roll axis. The URDF's 0.13 m box reaches within 2 cm
# of the tool point, which is where the glass's axis is held: a 25 mm glass would hit it. The scene
# shortens the palm (visual and collision) to 0.118 m; the kinematics are untouched.
PALM_LENGTH = 0.118
TOOL_DISTANCE = 0.1505  # tool point on the roll axis, from the URDF

#: Contact bits (contype / conaffinity): ordinary solids, and the liquid spheres.
SOLID, LIQUID = 1, 2

# Cameras: position, look-at point (base frame), vertical field of view.
CAMERA_TARGET = (0.47, 0.0, 0.06)
CAMERA_POSITIONS = {"cam_left": (1.05, 0.15, 0.52), "cam_right": (1.05, -0.15, 0.52)}
CAMERA_FOVY = 42.0  # degrees


@dataclass(frozen=True)
class SceneInfo:
    """What :func:`build_scene` built.

    Attributes
    ----------
    spec : TaskSpec
        The task (its judge, ranges and patches).
    objects : dict str -> ndarray, shape (3,)
        Initial object positions (base frame, metres; the task's docstring says which point of
        each object is meant).
    cameras : tuple of str
        Camera names (left first).
    arm_joints : tuple of str
        The arm's joint names, in the order of the joint vectors.
    n_liquid : int
        Number of liquid spheres (0 if the glass holds none).
    grasp_offset : ndarray, shape (3,)
        Tool point minus glass position for an upright glass held on its axis.
    """

    spec: TaskSpec
    objects: dict[str, Float]
    cameras: tuple[str, ...] = CAMERAS
    arm_joints: tuple[str, ...] = ARM_JOINTS
    n_liquid: int = 0
    grasp_offset: Float = field(default_factory=lambda: GRASP_OFFSET.copy())

    @property
    def task(self) -> str:
        """The task's name."""
        return self.spec.name


def _look_at_xyaxes(pos: Float, target: Float) -> list[float]:
    # MuJoCo camera: x right, y up, looking along -z.
    forward = target - pos
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return [*right.tolist(), *up.tolist()]


def _check_objects(spec: TaskSpec, objects: Mapping[str, npt.ArrayLike] | None) -> dict[str, Float]:
    """Every object's position for the scene: :meth:`TaskSpec.check_placement` (moving objects
    left out at their range's centre), then each object set on its support."""
    if objects is None:
        return spec.nominal_objects()
    out = spec.check_placement(objects, fill_moving=True)
    for name, r in spec.ranges.items():
        placed = out[name]
        p = position_of(placed)
        # Objects rest on their support: the height is not free.
        if abs(p[2] - r.low[2]) > 0.02:
            raise ValueError(
                f"objects[{short(name)}]: z must be {r.low[2]:.4f} (the {name} rests on its "
                "support), "
                f"got {p[2]:.4f}"
            )
        if placed.shape == (4, 4):  # a pose: on its support, turned about the vertical only
            out[name] = yaw_pose([p[0], p[1], r.low[2]], yaw_of(placed))
        else:
            out[name] = np.array([p[0], p[1], r.low[2]])
    return out


#: The table: half sides (m) and centre (its top face at z = 0).
TABLE_HALF = (0.65, 0.75, 0.02)
TABLE_CENTRE = (0.25, 0.0, -0.02)


def _add_table(world: Any) -> None:
    world.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(TABLE_HALF),
        pos=list(TABLE_CENTRE),
        rgba=[0.78, 0.68, 0.52, 1.0],
        contype=SOLID | LIQUID,
        conaffinity=SOLID | LIQUID,
    )
    world.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[3.0, 3.0, 0.1],
        pos=[0.0, 0.0, -0.75],
        rgba=[0.35, 0.35, 0.38, 1.0],
    )


def _add_obstacle(world: Any, shape: Shape) -> None:
    """A static geom of ``shape`` (a box, sphere or cylinder posed in the base frame)."""
    if isinstance(shape, Box):
        kind, size = mujoco.mjtGeom.mjGEOM_BOX, [float(v) / 2 for v in shape.size]
    elif isinstance(shape, Sphere):
        kind, size = mujoco.mjtGeom.mjGEOM_SPHERE, [shape.radius, 0.0, 0.0]
    elif isinstance(shape, Cylinder):
        kind, size = mujoco.mjtGeom.mjGEOM_CYLINDER, [shape.radius, shape.length / 2, 0.0]
    else:
        raise ValueError(f"obstacles: a Box, Sphere or Cylinder, got {type(shape).__name__}")
    world.add_geom(
        name=str(shape.name),
        type=kind,
        size=size,
        pos=shape.pose[:3, 3].tolist(),
        quat=quaternion_from_matrix(shape.pose[:3, :3]).tolist(),
        rgba=[0.95, 0.45, 0.1, 1.0],
        contype=SOLID,
        conaffinity=SOLID,
    )


def wall_prefix(name: str) -> str:
    """Name prefix of the wall geoms of the glass ``name`` (``NAME_wall0..``): what the fingers
    touch when they hold it."""
    return f"{name}_wall"


def free_joint(name: str) -> str:
    """Name of the free joint of the glass ``name``."""
    return f"{name}_free"


def add_glass(world: Any, bottom: Float, n_walls: int = 12, *, name: str = "glass") -> None:
    """Add a glass (body ``name``, free) standing upright with its bottom face centred at
    ``bottom``.

    Parameters
    ----------
    world : mujoco.MjsBody
        The worldbody of the scene's ``MjSpec``.
    bottom : ndarray, shape (3,)
        Centre of the glass's bottom face (base frame): on its support. The glass's reference
        point is ``bottom + (0, 0, GLASS_PATCH_CENTER)``.
    n_walls : int
        Number of wall boxes around the axis.
    name : str
        The body's name, the task's :attr:`~pbdkit.sim.TaskSpec.grasped` (default
        ``"glass"``); its geoms are ``NAME_wall0..``, ``NAME_patch0..`` (the red band,
        :func:`pbdkit.sim._tasks.patch_prefix`) and ``NAME_bottom``, its free joint
        ``NAME_free``.
    """
    # Body frame: centre of the bottom face, z along the glass's axis.
    body = world.add_body(name=name, pos=bottom.tolist())
    body.add_freejoint(name=free_joint(name))
    r_out, wt, h = GLASS_RADIUS, GLASS_WALL, GLASS_HEIGHT
    r_mid = r_out - wt / 2
    # Facets slightly wider than the polygon's side so that neighbouring boxes overlap: no gap
    # for a liquid sphere to leak through.
    width = 2.0 * r_out * math.tan(math.pi / n_walls) * 1.08
    glass_rgba = [0.82, 0.88, 0.92, 1.0]
    for i in range(n_walls):
        a = 2.0 * math.pi * i / n_walls
        quat = [math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]
        body.add_geom(
            name=f"{wall_prefix(name)}{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[wt / 2, width / 2, h / 2],
            pos=[r_mid * math.cos(a), r_mid * math.sin(a), h / 2],
            quat=quat,
            rgba=glass_rgba,
            density=2500.0,
            condim=4,
            friction=[1.0, 0.02, 0.001],
            contype=SOLID | LIQUID,
            conaffinity=SOLID | LIQUID,
        )
        # Red band, visual only, just outside the wall.
        body.add_geom(
            name=f"{patch_prefix(name)}{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.0005, width / 2, (GLASS_PATCH_HIGH - GLASS_PATCH_LOW) / 2],
            pos=[
                (r_out + 0.0005) * math.cos(a),
                (r_out + 0.0005) * math.sin(a),
                GLASS_PATCH_CENTER,
            ],
            quat=quat,
            rgba=[0.9, 0.05, 0.05, 1.0],
            contype=0,
            conaffinity=0,
            density=0.0,
        )
    body.add_geom(
        name=f"{name}_bottom",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[r_out - wt, GLASS_BOTTOM / 2, 0.0],
        pos=[0.0, 0.0, GLASS_BOTTOM / 2],
        rgba=glass_rgba,
        density=2500.0,
        contype=LIQUID,
        conaffinity=LIQUID,
    )


def _liquid_layout(n: int, rng: np.random.Generator) -> Float:
    """Initial sphere centres in the glass frame, shape (n, 3): hexagonal layers of 7."""
    r = LIQUID_RADIUS
    ring = 2.0 * r + 0.0006
    per_layer = [(0.0, 0.0)] + [
        (ring * math.cos(k * math.pi / 3), ring * math.sin(k * math.pi / 3)) for k in range(6)
    ]
    pts: list[tuple[float, float, float]] = []
    layer = 0
    while len(pts) < n:
        z = GLASS_BOTTOM + r + 0.001 + layer * (2.0 * r + 0.001)
        rot = (math.pi / 6) * (layer % 2)
        for x, y in per_layer:
            if len(pts) == n:
                break
            c, s = math.cos(rot), math.sin(rot)
            pts.append((c * x - s * y, s * x + c * y, z))
        layer += 1
    out = np.array(pts, dtype=np.float64)
    out[:, :2] += rng.uniform(-2e-4, 2e-4, size=(n, 2))
    return out


def add_liquid(world: Any, bottom: Float, n: int, rng: np.random.Generator) -> None:
    """Add ``n`` liquid spheres (free bodies ``liquid0..``) inside a glass whose bottom face is
    centred at ``bottom`` (3,), jittered by ``rng`` (0.2 mm); the task's ``n_liquid`` is ``n``."""
    for i, p in enumerate(_liquid_layout(n, rng)):
        body = world.add_body(name=f"liquid{i}", pos=(bottom + p).tolist())
        body.add_freejoint(name=f"liquid{i}_free")
        body.add_geom(
            name=f"liquid{i}",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[LIQUID_RADIUS, 0.0, 0.0],
            rgba=[0.2, 0.8, 0.3, 1.0],
            density=1000.0,
            # Frictionless (condim 1 wins through the higher priority): the spheres flow out
            # of a tilted glass like a liquid instead of sticking to its wall.
            condim=1,
            priority=1,
            # Stiff contacts: a 0.7 g sphere falling 0.2 m (2 m/s) into the basin would sink
            # through its floor with the default 0.02 s time constant.
            solref=[2.0 * TIMESTEP, 1.0],
            solimp=[0.95, 0.99, 0.001, 0.5, 2.0],
            contype=SOLID | LIQUID,
            conaffinity=SOLID | LIQUID,
        )


def _add_gripper(spec: Any) -> None:
    grip = spec.body("gripper")
    # Shorten the palm (see PALM_LENGTH) and keep one collision geom only.
    for g in list(grip.geoms):
        g.size = [g.size[0], g.size[1], PALM_LENGTH / 2]
        g.pos = [0.0, 0.0, -PALM_LENGTH / 2]
    fx, fy, fz = FINGER_HALF
    for name, sign in (("finger_left", 1.0), ("finger_right", -1.0)):
        body = grip.add_body(name=name, pos=[0.0, 0.0, -TOOL_DISTANCE])
        body.gravcomp = 1.0
        joint = body.add_joint(
            name=name,
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0.0, sign, 0.0],
            range=list(FINGER_RANGE),
            armature=0.01,
        )
        _set_damping(joint, 2.0)
        # Inner face at distance q from the axis: the box centre is half a thickness outside it.
        body.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[fx, fy, fz],
            pos=[0.0, sign * fy, 0.0],
            rgba=[0.25, 0.25, 0.28, 1.0],
            mass=0.02,
            # Stiff contact (time constant 2 steps, high impedance): MuJoCo's default
            # (0.02 s) lets a light finger squeezing at 12 N sink through a 3 mm wall.
            # The priority makes these parameters win over the glass's.
            priority=2,
            solref=[2.0 * TIMESTEP, 1.0],
            solimp=[0.95, 0.99, 0.001, 0.5, 2.0],
            condim=4,
            friction=[1.5, 0.02, 0.001],
            contype=SOLID | LIQUID,
            conaffinity=SOLID | LIQUID,
        )


def _set_damping(joint: Any, value: float) -> None:
    # MuJoCo 4 made joint damping a vector of polynomial coefficients (linear term first);
    # MuJoCo 3 takes a scalar.
    if np.ndim(joint.damping) == 0:
        joint.damping = value
    else:
        coefs = np.zeros(len(joint.damping))
        coefs[0] = value
        joint.damping = coefs


def _couple_fingers(spec: Any) -> None:
    # One mechanism moves both fingers (a parallel gripper): without this coupling, two
    # independent force-limited fingers let a held glass slide freely along the closing axis.
    eq = spec.add_equality(
        name="finger_coupling",
        type=mujoco.mjtEq.mjEQ_JOINT,
        name1="finger_left",
        name2="finger_right",
        solref=[2.0 * TIMESTEP, 1.0],
    )
    # Polynomial q_left = c0 + c1 q_right + ...; the data length differs between MuJoCo versions.
    data = np.zeros(len(eq.data))
    data[1] = 1.0
    eq.data = data


def _add_actuators(spec: Any) -> None:
    for j in ARM_JOINTS:
        joint = spec.joint(j)
        joint.armature = ARM_ARMATURE
        _set_damping(joint, ARM_DAMPING)
        pos = spec.add_actuator(name=f"pos_{j}", target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        pos.set_to_position(kp=ARM_KP)
        vel = spec.add_actuator(name=f"vel_{j}", target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        vel.set_to_velocity(kv=ARM_KV)
    for j in FINGER_JOINTS:
        act = spec.add_actuator(name=f"pos_{j}", target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=FINGER_KP, dampratio=1.0)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-FINGER_FORCE, FINGER_FORCE]


def _add_cameras_and_lights(world: Any, rig: CameraRig | None) -> None:
    # The task's rig, or the paper's (TaskSpec.cameras None).
    target = np.array(CAMERA_TARGET if rig is None else rig.target)
    fovy = CAMERA_FOVY if rig is None else rig.fovy
    for name in CAMERAS:
        pos = np.array(CAMERA_POSITIONS[name] if rig is None else rig.position(name))
        world.add_camera(
            name=name, pos=pos.tolist(), xyaxes=_look_at_xyaxes(pos, target), fovy=fovy
        )
    world.add_light(
        name="sun",
        pos=[0.3, 0.0, 1.5],
        dir=[0.0, 0.0, -1.0],
        castshadow=0,
        diffuse=[0.6, 0.6, 0.6],
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
    )


def build_scene(
    spec: TaskSpec,
    objects: Mapping[str, npt.ArrayLike] | None = None,
    seed: int | None = 0,
    *,
    obstacles: Sequence[Shape] = (),
) -> tuple[Any, SceneInfo]:
    """Compile the MuJoCo model of a task.

    Parameters
    ----------
    spec : TaskSpec
        The task (e.g. ``get_task("coaster")``: glass on a shelf, coaster on the table;
        ``get_task("basin")``: glass on the table with the liquid, fixed basin).
    objects : dict str -> array-like, shape (3,), optional
        Object positions (base frame; see the task). Missing objects, or all of them if None,
        are put at the centre of their placement range. Objects rest on their support, so z
        must match the support height (within 2 cm; it is then set exactly).
    seed : int or None
        Seeds the task's jitter (0.2 mm on the liquid spheres' initial positions). The default,
        0, makes the scene, and so every run under physics, the same each time for the same
        inputs; None draws a new jitter.
    obstacles : sequence of pbdkit.collision.Shape
        Static bodies added to the world (``--perturb obstacle``'s box), solid for the arm and
        what it carries.

    Returns
    -------
    model : mujoco.MjModel
    info : SceneInfo

    Raises
    ------
    ValueError
        ``spec`` not a TaskSpec, an unknown object name, a position that is not a finite (3,)
        vector, a fixed object moved, or a height off its support; a task whose
        ``add_objects`` built no glass, or not its ``n_liquid`` spheres.
    """
    spec = check_task(spec, "spec")
    objs = _check_objects(spec, objects)
    rng = np.random.default_rng(seed)

    # The arm: the same URDF text pinocchio loads (its <mujoco> block keeps the tool body).
    mj = mujoco.MjSpec.from_string(katana().urdf)
    mj.modelname = f"pbdkit_{spec.name}"
    mj.option.timestep = TIMESTEP
    # implicitfast: the servos' damping is integrated implicitly (stable at high gains);
    # elliptic cones with impratio > 1 make friction stiffer, so a held glass does not creep.
    mj.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    mj.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    mj.option.impratio = 10.0
    # Offscreen rendering at 320x240: no multisampling and no shadows (~2 ms per frame, not 75).
    mj.visual.quality.offsamples = 0
    mj.visual.quality.shadowsize = 0
    # Coarser tessellation of cylinders (28 x 16 by default): still round at this size, faster.
    mj.visual.quality.numslices = 16
    mj.visual.quality.numstacks = 8
    mj.visual.global_.offwidth = max(640, IMAGE_WIDTH)
    mj.visual.global_.offheight = max(480, IMAGE_HEIGHT)

    for name in ("pan_link", "upper_arm", "forearm", "wrist", "gripper", "tool"):
        mj.body(name).gravcomp = 1.0
    mj.body("tool").add_site(name="tool", size=[0.005, 0.0, 0.0], rgba=[1.0, 1.0, 0.0, 0.0])
    _add_gripper(mj)
    _couple_fingers(mj)
    _add_actuators(mj)

    world = mj.worldbody
    _add_table(world)
    _add_cameras_and_lights(world, spec.cameras)
    spec.add_objects(world, objs, rng)
    for shape in obstacles:
        _add_obstacle(world, shape)

    model = mj.compile()
    names = [model.body(i).name for i in range(model.nbody)]
    n_liquid = sum(name.startswith("liquid") for name in names)
    held = spec.grasped
    if held not in names or n_liquid != spec.n_liquid:
        raise ValueError(
            f"task {short(spec.name)}: add_objects must add the {held} (add_glass(..., "
            f"name={short(held)})) and n_liquid = {spec.n_liquid} liquid spheres (add_liquid); it "
            f"added {'the' if held in names else 'no'} {held} and {n_liquid} spheres"
        )
    info = SceneInfo(spec=spec, objects={k: v.copy() for k, v in objs.items()}, n_liquid=n_liquid)
    return model, info
