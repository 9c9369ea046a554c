"""The simulated world: the Katana of the kinematics, a gripper, the task's objects and two cameras.

:func:`build_scene` compiles a MuJoCo model whose arm is loaded from the very URDF text that
:func:`pbdkit.robots.katana` gives pinocchio (so the two kinematics agree to machine precision; a
test checks it), and adds, in the robot's base frame (table top at z = 0):

- a table, and for the ``"coaster"`` task a shelf holding the glass and a blue coaster on the table;
  for the ``"basin"`` task a fixed basin (a low open box) and liquid spheres inside the glass;
- a glass: an open cylinder of thin boxes around a disk bottom, so it holds the spheres, with a red
  band for the cameras;
- a parallel two-finger gripper on the ``gripper`` link (coupled fingers on slide joints, position
  actuators with a force limit: grasps are physical, by contact and friction);
- position and velocity servos on the 5 arm joints (a PD loop with velocity feed-forward) and
  gravity compensation of the arm's own links, like the Katana's controllers;
- two 320x240 cameras ``cam_left`` and ``cam_right`` (baseline 0.30 m) across the table.

:class:`Simulation` wraps the model and its data: joints, tool position, object positions (ground
truth), rendering and the cameras' OpenCV parameters.

Camera conventions. A MuJoCo camera looks along its local -z with y up and x to the right. OpenCV's
pinhole model looks along +z with y down. :meth:`Simulation.camera_parameters` returns OpenCV's
``K, R, t`` with ``u ~ K (R X + t)`` for a world (base-frame) point X and pixel coordinates whose
integer values are pixel centres, (0, 0) being the centre of the top-left pixel.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ..robots import katana
from . import tasks as T

Float = NDArray[np.float64]

ARM_JOINTS = ("pan", "lift1", "lift2", "lift3", "wrist_roll")
FINGER_JOINTS = ("finger_left", "finger_right")
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

# Contact bits: 1 = ordinary solids, 2 = liquid. The glass bottom only meets the liquid (the glass
# stands on the lower edges of its wall boxes, which gives many contacts and a stable stand).
_SOLID, _LIQUID = 1, 2

# Cameras: position, look-at point (base frame), vertical field of view.
CAMERA_TARGET = (0.47, 0.0, 0.06)
CAMERA_POSITIONS = {"cam_left": (1.05, 0.15, 0.52), "cam_right": (1.05, -0.15, 0.52)}
CAMERA_FOVY = 42.0  # degrees


@dataclass(frozen=True)
class SceneInfo:
    """What :func:`build_scene` built.

    Attributes
    ----------
    task : str
        "coaster" or "basin".
    objects : dict str -> ndarray, shape (3,)
        Initial object positions (base frame, metres; see :mod:`pbdkit.sim.tasks` for the point
        of each object that is meant).
    cameras : tuple of str
        Camera names (left first).
    arm_joints : tuple of str
        The arm's joint names, in the order of the joint vectors.
    n_liquid : int
        Number of liquid spheres (0 for the coaster task).
    grasp_offset : ndarray, shape (3,)
        Tool point minus glass position for an upright glass held on its axis.
    """

    task: str
    objects: dict[str, Float]
    cameras: tuple[str, ...] = CAMERAS
    arm_joints: tuple[str, ...] = ARM_JOINTS
    n_liquid: int = 0
    grasp_offset: Float = field(default_factory=lambda: T.GRASP_OFFSET.copy())


def _look_at_xyaxes(pos: Float, target: Float) -> list[float]:
    # MuJoCo camera: x right, y up, looking along -z.
    forward = target - pos
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return [*right.tolist(), *up.tolist()]


def _check_objects(task: str, objects: Mapping[str, npt.ArrayLike] | None) -> dict[str, Float]:
    ranges = T.PLACEMENT_RANGES[task]
    if objects is None:
        return T.nominal_objects(task)
    unknown = sorted(set(objects) - set(ranges))
    if unknown:
        raise ValueError(
            f"objects: unknown object(s) {unknown} for task {task!r}; expected {sorted(ranges)}"
        )
    out: dict[str, Float] = {}
    for name, r in ranges.items():
        if name not in objects:
            out[name] = r.center.copy()
            continue
        p = np.asarray(objects[name], dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"objects[{name!r}] must be a finite (3,) position, got {p!r}")
        if r.fixed and not np.allclose(p, r.low, atol=1e-6):
            raise ValueError(f"objects[{name!r}]: the {name} is fixed at {r.low.tolist()}, got {p}")
        # Objects rest on their support: the height is not free.
        if abs(p[2] - r.low[2]) > 0.02:
            raise ValueError(
                f"objects[{name!r}]: z must be {r.low[2]:.4f} (the {name} rests on its support), "
                f"got {p[2]:.4f}"
            )
        out[name] = np.array([p[0], p[1], r.low[2]])
    return out


def _add_table(world: Any) -> None:
    world.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[0.65, 0.75, 0.02],
        pos=[0.25, 0.0, -0.02],
        rgba=[0.78, 0.68, 0.52, 1.0],
        contype=_SOLID | _LIQUID,
        conaffinity=_SOLID | _LIQUID,
    )
    world.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[3.0, 3.0, 0.1],
        pos=[0.0, 0.0, -0.75],
        rgba=[0.35, 0.35, 0.38, 1.0],
    )


def _add_shelf(world: Any) -> None:
    (x0, x1), (y0, y1) = T.SHELF_X, T.SHELF_Y
    thick = 0.015
    body = world.add_body(name="shelf", pos=[0.0, 0.0, 0.0])
    wood = [0.55, 0.4, 0.25, 1.0]
    body.add_geom(
        name="shelf_board",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[(x1 - x0) / 2, (y1 - y0) / 2, thick / 2],
        pos=[(x0 + x1) / 2, (y0 + y1) / 2, T.SHELF_HEIGHT - thick / 2],
        rgba=wood,
    )
    leg_h = T.SHELF_HEIGHT - thick
    for i, (x, y) in enumerate(
        [
            (x0 + 0.015, y0 + 0.015),
            (x0 + 0.015, y1 - 0.015),
            (x1 - 0.015, y0 + 0.015),
            (x1 - 0.015, y1 - 0.015),
        ]
    ):
        body.add_geom(
            name=f"shelf_leg{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.01, 0.01, leg_h / 2],
            pos=[x, y, leg_h / 2],
            rgba=wood,
        )


def _add_coaster(world: Any, pos: Float) -> None:
    body = world.add_body(name="coaster", pos=[pos[0], pos[1], 0.0])
    body.add_geom(
        name="coaster",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[T.COASTER_RADIUS, T.COASTER_THICKNESS / 2, 0.0],
        pos=[0.0, 0.0, T.COASTER_THICKNESS / 2],
        rgba=[0.1, 0.25, 0.9, 1.0],
        friction=[1.0, 0.01, 0.001],
    )


def _add_basin(world: Any, pos: Float) -> None:
    # Basin frame: floor centre on the table; pos[2] is the floor's top face.
    body = world.add_body(name="basin", pos=[pos[0], pos[1], 0.0])
    half = T.BASIN_INNER / 2
    wall = 0.008
    grey = [0.85, 0.85, 0.8, 1.0]
    body.add_geom(
        name="basin_floor",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[half + wall, half + wall, T.BASIN_FLOOR / 2],
        pos=[0.0, 0.0, T.BASIN_FLOOR / 2],
        rgba=grey,
        contype=_SOLID | _LIQUID,
        conaffinity=_SOLID | _LIQUID,
    )
    h = T.BASIN_WALL_HEIGHT
    zc = T.BASIN_FLOOR + h / 2
    for i, (x, y, sx, sy) in enumerate(
        [
            (half + wall / 2, 0.0, wall / 2, half + wall),
            (-half - wall / 2, 0.0, wall / 2, half + wall),
            (0.0, half + wall / 2, half, wall / 2),
            (0.0, -half - wall / 2, half, wall / 2),
        ]
    ):
        body.add_geom(
            name=f"basin_wall{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[sx, sy, h / 2],
            pos=[x, y, zc],
            rgba=grey,
            contype=_SOLID | _LIQUID,
            conaffinity=_SOLID | _LIQUID,
        )


def _add_glass(world: Any, bottom: Float, n_walls: int = 12) -> None:
    # Body frame: centre of the bottom face, z along the glass's axis.
    body = world.add_body(name="glass", pos=bottom.tolist())
    body.add_freejoint(name="glass_free")
    r_out, wt, h = T.GLASS_RADIUS, T.GLASS_WALL, T.GLASS_HEIGHT
    r_mid = r_out - wt / 2
    # Facets slightly wider than the polygon's side so that neighbouring boxes overlap: no gap
    # for a liquid sphere to leak through.
    width = 2.0 * r_out * math.tan(math.pi / n_walls) * 1.08
    glass_rgba = [0.82, 0.88, 0.92, 1.0]
    for i in range(n_walls):
        a = 2.0 * math.pi * i / n_walls
        quat = [math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]
        body.add_geom(
            name=f"glass_wall{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[wt / 2, width / 2, h / 2],
            pos=[r_mid * math.cos(a), r_mid * math.sin(a), h / 2],
            quat=quat,
            rgba=glass_rgba,
            density=2500.0,
            condim=4,
            friction=[1.0, 0.02, 0.001],
            contype=_SOLID | _LIQUID,
            conaffinity=_SOLID | _LIQUID,
        )
        # Red band, visual only, just outside the wall.
        body.add_geom(
            name=f"glass_patch{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[0.0005, width / 2, (T.GLASS_PATCH_HIGH - T.GLASS_PATCH_LOW) / 2],
            pos=[
                (r_out + 0.0005) * math.cos(a),
                (r_out + 0.0005) * math.sin(a),
                T.GLASS_PATCH_CENTER,
            ],
            quat=quat,
            rgba=[0.9, 0.05, 0.05, 1.0],
            contype=0,
            conaffinity=0,
            density=0.0,
        )
    body.add_geom(
        name="glass_bottom",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[r_out - wt, T.GLASS_BOTTOM / 2, 0.0],
        pos=[0.0, 0.0, T.GLASS_BOTTOM / 2],
        rgba=glass_rgba,
        density=2500.0,
        contype=_LIQUID,
        conaffinity=_LIQUID,
    )


def _liquid_layout(n: int, rng: np.random.Generator) -> Float:
    """Initial sphere centres in the glass frame, shape (n, 3): hexagonal layers of 7."""
    r = T.LIQUID_RADIUS
    ring = 2.0 * r + 0.0006
    per_layer = [(0.0, 0.0)] + [
        (ring * math.cos(k * math.pi / 3), ring * math.sin(k * math.pi / 3)) for k in range(6)
    ]
    pts: list[tuple[float, float, float]] = []
    layer = 0
    while len(pts) < n:
        z = T.GLASS_BOTTOM + r + 0.001 + layer * (2.0 * r + 0.001)
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


def _add_liquid(world: Any, bottom: Float, n: int, rng: np.random.Generator) -> None:
    for i, p in enumerate(_liquid_layout(n, rng)):
        body = world.add_body(name=f"liquid{i}", pos=(bottom + p).tolist())
        body.add_freejoint(name=f"liquid{i}_free")
        body.add_geom(
            name=f"liquid{i}",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[T.LIQUID_RADIUS, 0.0, 0.0],
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
            contype=_SOLID | _LIQUID,
            conaffinity=_SOLID | _LIQUID,
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
            contype=_SOLID | _LIQUID,
            conaffinity=_SOLID | _LIQUID,
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


def _add_cameras_and_lights(world: Any) -> None:
    target = np.array(CAMERA_TARGET)
    for name in CAMERAS:
        pos = np.array(CAMERA_POSITIONS[name])
        world.add_camera(
            name=name, pos=pos.tolist(), xyaxes=_look_at_xyaxes(pos, target), fovy=CAMERA_FOVY
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
    task: str,
    objects: Mapping[str, npt.ArrayLike] | None = None,
    seed: int | None = 0,
) -> tuple[Any, SceneInfo]:
    """Compile the MuJoCo model of a task.

    Parameters
    ----------
    task : {"coaster", "basin"}
        "coaster": glass on a shelf, coaster on the table. "basin": glass on the table (with the
        liquid), fixed basin.
    objects : dict str -> array-like, shape (3,), optional
        Object positions (base frame; see :mod:`pbdkit.sim.tasks`). Missing objects, or all of
        them if None, are put at the centre of their placement range. Objects rest on their
        support, so z must match the support height (within 2 cm; it is then set exactly).
    seed : int or None
        Seeds the small jitter (0.2 mm) of the liquid spheres' initial positions. The default, 0,
        makes the scene, and so every run under physics, the same each time for the same
        inputs; None draws a new jitter.

    Returns
    -------
    model : mujoco.MjModel
    info : SceneInfo

    Raises
    ------
    ValueError
        Unknown task or object name, a position that is not a finite (3,) vector, a fixed object
        moved, or a height off its support.
    """
    T.check_task(task)
    objs = _check_objects(task, objects)
    rng = np.random.default_rng(seed)

    # The arm: the same URDF text pinocchio loads (its <mujoco> block keeps the tool body).
    spec = mujoco.MjSpec.from_string(katana().urdf)
    spec.modelname = f"pbdkit_{task}"
    spec.option.timestep = TIMESTEP
    # implicitfast: the servos' damping is integrated implicitly (stable at high gains);
    # elliptic cones with impratio > 1 make friction stiffer, so a held glass does not creep.
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    # Offscreen rendering at 320x240: no multisampling and no shadows (~2 ms per frame, not 75).
    spec.visual.quality.offsamples = 0
    spec.visual.quality.shadowsize = 0
    # Coarser tessellation of cylinders (28 x 16 by default): still round at this size, faster.
    spec.visual.quality.numslices = 16
    spec.visual.quality.numstacks = 8
    spec.visual.global_.offwidth = max(640, IMAGE_WIDTH)
    spec.visual.global_.offheight = max(480, IMAGE_HEIGHT)

    for name in ("pan_link", "upper_arm", "forearm", "wrist", "gripper", "tool"):
        spec.body(name).gravcomp = 1.0
    spec.body("tool").add_site(name="tool", size=[0.005, 0.0, 0.0], rgba=[1.0, 1.0, 0.0, 0.0])
    _add_gripper(spec)
    _couple_fingers(spec)
    _add_actuators(spec)

    world = spec.worldbody
    _add_table(world)
    _add_cameras_and_lights(world)
    n_liquid = 0
    glass = objs["glass"]
    if task == "coaster":
        _add_shelf(world)
        _add_coaster(world, objs["coaster"])
        support = T.SHELF_HEIGHT
    else:
        _add_basin(world, objs["basin"])
        support = 0.0
    bottom = np.array([glass[0], glass[1], support])
    _add_glass(world, bottom)
    if task == "basin":
        n_liquid = T.N_LIQUID
        _add_liquid(world, bottom, n_liquid, rng)

    model = spec.compile()
    info = SceneInfo(task=task, objects={k: v.copy() for k, v in objs.items()}, n_liquid=n_liquid)
    return model, info


class Simulation:
    """A MuJoCo model and its state, with the operations the experiment needs.

    Parameters
    ----------
    model : mujoco.MjModel
        From :func:`build_scene`.
    info : SceneInfo
        From :func:`build_scene`.

    Attributes
    ----------
    model : mujoco.MjModel
    data : mujoco.MjData
    info : SceneInfo
    n_joints : int
        Number of arm joints (5).
    """

    def __init__(self, model: Any, info: SceneInfo) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.info = info
        self.n_joints = len(info.arm_joints)
        m = model
        self._qadr = np.array([m.jnt_qposadr[m.joint(j).id] for j in info.arm_joints])
        self._vadr = np.array([m.jnt_dofadr[m.joint(j).id] for j in info.arm_joints])
        self._pos_act = np.array([m.actuator(f"pos_{j}").id for j in info.arm_joints])
        self._vel_act = np.array([m.actuator(f"vel_{j}").id for j in info.arm_joints])
        self._finger_act = np.array([m.actuator(f"pos_{j}").id for j in FINGER_JOINTS])
        self._finger_qadr = np.array([m.jnt_qposadr[m.joint(j).id] for j in FINGER_JOINTS])
        self._tool_site = m.site("tool").id
        self._glass_body = m.body("glass").id
        self._liquid_bodies = np.array(
            [m.body(f"liquid{i}").id for i in range(info.n_liquid)], dtype=np.intp
        )
        self._renderer: Any = None
        self._prefix_masks: dict[str, NDArray[np.bool_]] = {}
        self.set_gripper(False)
        mujoco.mj_forward(m, self.data)

    @classmethod
    def from_task(
        cls, task: str, objects: Mapping[str, npt.ArrayLike] | None = None, seed: int | None = 0
    ) -> Simulation:
        """Build the scene of ``task`` (see :func:`build_scene`) and wrap it."""
        model, info = build_scene(task, objects, seed)
        return cls(model, info)

    # -- state -------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return float(self.data.time)

    def joints(self) -> Float:
        """Arm joint angles theta, shape (n,)."""
        return np.array(self.data.qpos[self._qadr], dtype=np.float64)

    def set_joints(self, q: npt.ArrayLike) -> None:
        """Put the arm at ``q`` (n,) at rest, with the servos' targets at ``q``; no physics step.

        Raises
        ------
        ValueError
            If q is not a finite (n,) vector.
        """
        q_ = np.asarray(q, dtype=np.float64)
        if q_.shape != (self.n_joints,) or not np.all(np.isfinite(q_)):
            raise ValueError(f"q must be a finite ({self.n_joints},) vector, got {q_!r}")
        self.data.qpos[self._qadr] = q_
        self.data.qvel[self._vadr] = 0.0
        self.set_targets(q_, np.zeros(self.n_joints))
        mujoco.mj_forward(self.model, self.data)

    def set_targets(self, q: Float, dq: Float) -> None:
        """Servo targets: joint angles q (n,) and joint velocities dq (n,) (feed-forward)."""
        self.data.ctrl[self._pos_act] = q
        self.data.ctrl[self._vel_act] = dq

    def set_gripper(self, closed: bool) -> None:
        """Close (force-limited squeeze) or open the two fingers."""
        self.data.ctrl[self._finger_act] = FINGER_CLOSED if closed else FINGER_OPEN

    def finger_opening(self) -> Float:
        """Distance of each finger's inner face from the tool axis (m), shape (2,)."""
        return np.array(self.data.qpos[self._finger_qadr], dtype=np.float64)

    def step(self, n: int = 1) -> None:
        """Advance the physics by ``n`` steps of :data:`TIMESTEP`."""
        mujoco.mj_step(self.model, self.data, nstep=n)

    def refresh(self) -> None:
        """Recompute positions from the current joint state.

        After :meth:`step`, body and site positions are those computed at the start of the step
        (MuJoCo integrates after computing them); call this before reading them with the
        joints.
        """
        mujoco.mj_kinematics(self.model, self.data)

    def tool_position(self) -> Float:
        """Tool point position x in the base frame (MuJoCo's site at the URDF's ``tool``), (3,)."""
        return np.array(self.data.site_xpos[self._tool_site], dtype=np.float64)

    def tool_rotation(self) -> Float:
        """Orientation of the tool frame in the base frame, shape (3, 3) (columns = axes)."""
        return np.array(self.data.site_xmat[self._tool_site], dtype=np.float64).reshape(3, 3)

    def glass_pose(self) -> tuple[Float, Float]:
        """Glass bottom centre (3,) and rotation (3, 3) in the base frame."""
        b = self._glass_body
        return (
            np.array(self.data.xpos[b], dtype=np.float64),
            np.array(self.data.xmat[b], dtype=np.float64).reshape(3, 3),
        )

    def glass_tilt(self) -> float:
        """Angle between the glass's axis and the vertical (rad)."""
        _, rot = self.glass_pose()
        return float(np.arccos(np.clip(rot[2, 2], -1.0, 1.0)))

    def object_positions(self) -> dict[str, Float]:
        """Ground-truth object positions o (base frame), name -> (3,), as the cameras define them.

        The glass's point is on its axis at the height of the red band's centre; the coaster's
        and the basin's are fixed at their build positions.
        """
        out = {k: v.copy() for k, v in self.info.objects.items()}
        bottom, rot = self.glass_pose()
        out["glass"] = bottom + rot[:, 2] * T.GLASS_PATCH_CENTER
        return out

    def liquid_positions(self) -> Float:
        """Centres of the liquid spheres, shape (n_liquid, 3)."""
        return np.array(self.data.xpos[self._liquid_bodies], dtype=np.float64).reshape(-1, 3)

    def _geom_ids(self, prefix: str) -> NDArray[np.bool_]:
        """Mask over geoms, shape (ngeom,): True where the geom's name starts with ``prefix``."""
        mask = self._prefix_masks.get(prefix)
        if mask is None:
            m = self.model
            mask = np.array([m.geom(i).name.startswith(prefix) for i in range(m.ngeom)])
            self._prefix_masks[prefix] = mask
        return mask

    def contacts(self, geom_prefix_a: str, geom_prefix_b: str) -> int:
        """Number of active contacts between geoms whose names start with the given prefixes."""
        if self.data.ncon == 0:
            return 0
        pairs = np.asarray(self.data.contact.geom)  # (ncon, 2) geom ids
        a, b = self._geom_ids(geom_prefix_a), self._geom_ids(geom_prefix_b)
        hits = (a[pairs[:, 0]] & b[pairs[:, 1]]) | (b[pairs[:, 0]] & a[pairs[:, 1]])
        return int(np.count_nonzero(hits))

    def glass_grasped(self) -> bool:
        """True if both fingers touch the glass."""
        return (
            self.contacts("finger_left", "glass_wall") > 0
            and self.contacts("finger_right", "glass_wall") > 0
        )

    # -- cameras -----------------------------------------------------------------------------
    def camera_id(self, camera: str) -> int:
        """MuJoCo id of a camera of ``info.cameras``; ValueError for another name."""
        if camera not in self.info.cameras:
            raise ValueError(f"camera must be one of {list(self.info.cameras)}, got {camera!r}")
        return int(self.model.camera(camera).id)

    # Kept for callers written against the first version.
    _check_camera = camera_id

    def render(self, camera: str) -> NDArray[np.uint8]:
        """Render one camera image of the current state.

        Parameters
        ----------
        camera : str
            One of ``info.cameras``.

        Returns
        -------
        image : ndarray of uint8, shape (240, 320, 3)
            RGB, first row at the top.
        """
        cam_id = self.camera_id(camera)
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, IMAGE_HEIGHT, IMAGE_WIDTH)
            self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
        self._renderer.update_scene(self.data, camera=cam_id)
        image: NDArray[np.uint8] = self._renderer.render()
        return image.copy()

    def camera_parameters(self, camera: str) -> tuple[Float, Float, Float, int, int]:
        """OpenCV pinhole parameters of a camera.

        A base-frame point X (3,) projects to pixel (u, v) with ``[u, v, 1] ~ K (R X + t)``, pixel
        centres at integer coordinates and (0, 0) the top-left pixel. OpenCV's camera looks along
        +z with y down; MuJoCo's along -z with y up, hence ``R = diag(1, -1, -1) R_mj^T``.

        Parameters
        ----------
        camera : str
            One of ``info.cameras``.

        Returns
        -------
        K : ndarray, shape (3, 3)
            Intrinsics; focal length f = (height / 2) / tan(fovy / 2) pixels, square pixels.
        R : ndarray, shape (3, 3)
            Rotation from the base frame to the OpenCV camera frame.
        t : ndarray, shape (3,)
            Translation: the base frame's origin in the camera frame.
        width, height : int
            Image size (320, 240).
        """
        cam_id = self.camera_id(camera)
        m, d = self.model, self.data
        mujoco.mj_kinematics(m, d)
        fovy = math.radians(float(m.cam_fovy[cam_id]))
        f = 0.5 * IMAGE_HEIGHT / math.tan(0.5 * fovy)
        # OpenGL's image spans [0, W] x [0, H] in pixel edges; a pixel centre is at +0.5 there,
        # at an integer in OpenCV's convention: the principal point moves by half a pixel.
        K = np.array(
            [
                [f, 0.0, 0.5 * IMAGE_WIDTH - 0.5],
                [0.0, f, 0.5 * IMAGE_HEIGHT - 0.5],
                [0.0, 0.0, 1.0],
            ]
        )
        r_mj = np.array(d.cam_xmat[cam_id], dtype=np.float64).reshape(3, 3)
        R = np.diag([1.0, -1.0, -1.0]) @ r_mj.T
        t = -R @ np.array(d.cam_xpos[cam_id], dtype=np.float64)
        return K, R, t, IMAGE_WIDTH, IMAGE_HEIGHT

    def close(self) -> None:
        """Free the renderer's OpenGL context (the model and data stay usable)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
