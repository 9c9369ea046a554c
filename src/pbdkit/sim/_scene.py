"""The simulated world's state: :class:`Simulation` wraps a compiled scene and its data.

The scene itself (the Katana of the kinematics, a gripper, the task's objects and two cameras) is
built by :func:`pbdkit.sim.build_scene`, re-exported here with its constants.
:class:`Simulation` holds the model and its data: joints, tool position, object positions (ground
truth), stepping, rendering and the cameras' OpenCV parameters.

The grasped object (:attr:`pbdkit.sim.TaskSpec.grasped`) is a glass
(:func:`pbdkit.sim._world.add_glass`) or a block (:func:`pbdkit.sim._parts.add_block`); the
simulation tells which from the scene (a block has a geom ``NAME_box``) and handles both alike:
its pose (:meth:`Simulation.grasped_pose`, :meth:`Simulation.grasped_frame`), tilt, grasp and
release checks (finger contacts with the glass's walls or the block's box), its point
(:meth:`Simulation.object_positions`: on the glass's axis at its red band's height, the centre
of the block's top face) and :meth:`Simulation.place_object`. The ``glass_*`` methods keep their
names for the paper's tasks; with a block they are about the block.

Camera conventions. A MuJoCo camera looks along its local -z with y up and x to the right. OpenCV's
pinhole model looks along +z with y down. :meth:`Simulation.camera_parameters` returns OpenCV's
``K, R, t`` with ``u ~ K (R X + t)`` for a world (base-frame) point X and pixel coordinates whose
integer values are pixel centres, (0, 0) being the centre of the top-left pixel.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import short
from ..collision import Shape
from ..data._placement import position_of, rotation_of
from ._gl import mujoco
from ._glass import GLASS_PATCH_CENTER
from ._parts import block_geom
from ._tasks import TaskSpec
from ._world import (
    FINGER_CLOSED,
    FINGER_JOINTS,
    FINGER_OPEN,
    IMAGE_HEIGHT,
    IMAGE_WIDTH,
    SceneInfo,
    build_scene,
    free_joint,
    wall_prefix,
)

__all__ = ["Simulation"]

Float = NDArray[np.float64]


def _quat_mat(quat: npt.ArrayLike) -> Float:
    """Rotation matrix (3, 3) of a unit quaternion (w, x, y, z)."""
    out = np.empty(9)
    mujoco.mju_quat2Mat(out, np.asarray(quat, dtype=np.float64))
    return out.reshape(3, 3)


def _yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a turn by ``yaw`` (rad) about the vertical."""
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def _heading(xmat: npt.ArrayLike) -> float:
    """Yaw (rad) of a body's x axis, from its flattened rotation matrix (9,)."""
    r = np.asarray(xmat, dtype=np.float64)
    return math.atan2(float(r[3]), float(r[0]))


def _as_slice(idx: NDArray[np.intp]) -> slice | NDArray[np.intp]:
    """``idx`` as an equivalent slice when its steps are equal and positive, else itself."""
    if idx.size >= 2:
        step = int(idx[1] - idx[0])
        if step > 0 and np.all(np.diff(idx) == step):
            return slice(int(idx[0]), int(idx[-1]) + 1, step)
    return idx


class _Mocap(NamedTuple):
    """An object built as a mocap body: its mocap id and its reference point in the body's
    frame."""

    mocap_id: int
    offset: Float


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
        # The object the gripper holds (TaskSpec.grasped): a glass, or a block (it has a box
        # geom). What differs: the geoms the fingers touch, and the object's point on its body's
        # z axis (the glass's body frame is its bottom centre, the block's its top face's).
        self._held = info.spec.grasped
        if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, block_geom(self._held)) >= 0:
            self._held_kind = "block"
            self._held_wall = block_geom(self._held)
            self._held_point_z = 0.0
        else:
            self._held_kind = "glass"
            self._held_wall = wall_prefix(self._held)
            self._held_point_z = GLASS_PATCH_CENTER
        self._glass_body = m.body(self._held).id
        self._liquid_bodies = np.array(
            [m.body(f"liquid{i}").id for i in range(info.n_liquid)], dtype=np.intp
        )
        # Objects built as mocap bodies (a disturbance may slide or turn them): body id ->
        # mocap id, and the object's reference point in the body's frame.
        self._mocap: dict[str, _Mocap] = {}
        # The other objects that are bodies (static): their orientation, for object_poses.
        self._bodies: dict[str, int] = {}
        for name, placed in info.objects.items():
            pos = position_of(placed)
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
            if bid >= 0 and m.body_mocapid[bid] >= 0:
                mid = int(m.body_mocapid[bid])
                rot0 = _quat_mat(m.body_quat[bid])
                offset = rot0.T @ (pos - m.body_pos[bid])
                self._mocap[name] = _Mocap(mid, np.asarray(offset, dtype=np.float64))
            elif bid >= 0:
                self._bodies[name] = bid
        self._glass_qadr = int(m.jnt_qposadr[m.joint(free_joint(self._held)).id])
        self._glass_vadr = int(m.jnt_dofadr[m.joint(free_joint(self._held)).id])
        self._renderer: Any = None
        # The servos' controls as slices where the actuators are evenly spaced (they are:
        # pos_j, vel_j alternate), else index arrays: set at every physics step.
        self._ctrl = self.data.ctrl
        self._pos_slice = _as_slice(self._pos_act)
        self._vel_slice = _as_slice(self._vel_act)
        self._closed: bool | None = None
        both = np.concatenate([self._pos_act, self._vel_act])
        self._servo_span = (int(both.min()), int(both.max()) + 1)
        self._prefix_masks: dict[str, NDArray[np.bool_]] = {}
        self.set_gripper(False)
        mujoco.mj_forward(m, self.data)

    @classmethod
    def from_task(
        cls,
        spec: TaskSpec,
        objects: Mapping[str, npt.ArrayLike] | None = None,
        seed: int | None = 0,
        *,
        obstacles: Sequence[Shape] = (),
    ) -> Simulation:
        """Build the scene of the task ``spec`` (see :func:`build_scene`) and wrap it."""
        model, info = build_scene(spec, objects, seed, obstacles=obstacles)
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
            raise ValueError(f"q must be a finite ({self.n_joints},) vector, got {short(q_)}")
        self.data.qpos[self._qadr] = q_
        self.data.qvel[self._vadr] = 0.0
        self.set_targets(q_, np.zeros(self.n_joints))
        mujoco.mj_forward(self.model, self.data)

    def set_targets(self, q: Float, dq: Float) -> None:
        """Servo targets: joint angles q (n,) and joint velocities dq (n,) (feed-forward)."""
        self._ctrl[self._pos_slice] = q
        self._ctrl[self._vel_slice] = dq

    def servo_rows(self, q: Float, dq: Float) -> Float:
        """The servo controls for many steps at once, shape (S, k): row s is what
        :meth:`set_targets` (q[s], dq[s]) writes, for :meth:`set_servo_row` (one copy per
        physics step instead of two scattered writes)."""
        lo, hi = self._servo_span
        rows = np.array(np.broadcast_to(self.data.ctrl[lo:hi], (q.shape[0], hi - lo)))
        rows[:, self._pos_act - lo] = q
        rows[:, self._vel_act - lo] = dq
        return rows

    def set_servo_row(self, row: Float) -> None:
        """Write one row of :meth:`servo_rows` into the controls."""
        lo, hi = self._servo_span
        self._ctrl[lo:hi] = row

    def set_gripper(self, closed: bool) -> None:
        """Close (force-limited squeeze) or open the two fingers."""
        if closed is not self._closed:
            self.data.ctrl[self._finger_act] = FINGER_CLOSED if closed else FINGER_OPEN
            self._closed = closed

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

    @property
    def grasped_kind(self) -> str:
        """What the grasped object is: ``"glass"`` or ``"block"`` (module docstring)."""
        return self._held_kind

    def grasped_frame(self) -> tuple[Float, Float]:
        """The grasped object's body frame in the base frame: its origin (3,) and rotation (3, 3).

        A glass's origin is the centre of its bottom face, a block's the centre of its top face
        (:func:`pbdkit.sim._parts.add_block`); :meth:`grasped_pose` is the same as a 4x4.
        """
        b = self._glass_body
        return (
            np.array(self.data.xpos[b], dtype=np.float64),
            np.array(self.data.xmat[b], dtype=np.float64).reshape(3, 3),
        )

    def grasped_pose(self) -> Float:
        """Pose of the grasped object's body frame in the base frame, shape (4, 4).

        The glass's frame is the centre of its bottom face, z along its axis; a block's is the
        centre of its top face, x along the block from mark a to mark b, z up
        (:mod:`pbdkit.sim._parts`). Its yaw is :func:`pbdkit.sim._tasks.yaw_of` of it.
        """
        pos, rot = self.grasped_frame()
        out = np.eye(4)
        out[:3, :3] = rot
        out[:3, 3] = pos
        return out

    def grasped_tilt(self) -> float:
        """Angle between the glass's axis (a block's vertical, its z axis) and the vertical
        (rad)."""
        # rot[2, 2] of grasped_frame(), read in place: this runs at every physics step.
        c = float(self.data.xmat[self._glass_body, 8])
        return math.acos(min(1.0, max(-1.0, c)))

    def object_positions(self) -> dict[str, Float]:
        """Ground-truth object positions o (base frame), name -> (3,), as the cameras define them.

        The grasped glass's point (:attr:`pbdkit.sim.TaskSpec.grasped`) is on its axis at
        the height of the red band's centre, a grasped block's the centre of its top face; the
        other objects are static bodies, at their build positions, or mocap bodies where they
        are now (:meth:`place_object`).
        """
        out = {k: position_of(v).copy() for k, v in self.info.objects.items()}
        for name, (mid, offset) in self._mocap.items():
            rot = _quat_mat(self.data.mocap_quat[mid])
            out[name] = np.asarray(self.data.mocap_pos[mid] + rot @ offset, dtype=np.float64)
        bottom, rot = self.grasped_frame()
        out[self._held] = bottom + rot[:, 2] * self._held_point_z
        return out

    def object_poses(self) -> dict[str, Float]:
        """Ground-truth object poses (base frame), name -> (4, 4): :meth:`object_positions`'
        points with the objects' orientations.

        The orientation is that of the object's body: the grasped object's (free), a mocap
        body's as it is now, a static body's as built; an object that is no body of its own
        (e.g. a geom of the world) has its placement's (the identity for a position). The yaw
        of a block or a tray is :func:`pbdkit.sim._tasks.yaw_of` of its pose.
        """
        out: dict[str, Float] = {}
        for name, pos in self.object_positions().items():
            pose = np.eye(4)
            pose[:3, 3] = pos
            if name == self._held:
                _, rotation = self.grasped_frame()
                pose[:3, :3] = rotation
            elif name in self._mocap:
                pose[:3, :3] = _quat_mat(self.data.mocap_quat[self._mocap[name].mocap_id])
            elif name in self._bodies:
                pose[:3, :3] = np.asarray(self.data.xmat[self._bodies[name]]).reshape(3, 3)
            else:
                rot = rotation_of(self.info.objects[name])
                if rot is not None:
                    pose[:3, :3] = rot
            out[name] = pose
        return out

    def object_placements(self) -> dict[str, Float]:
        """Ground-truth placements in the task's form, name -> (3,) or (4, 4): the pose
        (:meth:`object_poses`) of an object whose range has a yaw
        (:attr:`pbdkit.sim.PlacementRange.posed`, e.g. the block and the tray), the
        position (:meth:`object_positions`) of the others; what a skill is told of a scene."""
        ranges = self.info.spec.ranges
        if not any(r.posed for r in ranges.values()):
            return self.object_positions()
        poses = self.object_poses()
        return {k: p if ranges[k].posed else p[:3, 3].copy() for k, p in poses.items()}

    def place_object(
        self,
        name: str,
        position: npt.ArrayLike,
        velocity: npt.ArrayLike | None = None,
        *,
        yaw: float | None = None,
    ) -> None:
        """Move an object so that its reference point (:meth:`object_positions`) is at
        ``position``, for a disturbance that slides (or turns) it.

        The grasped object (a free body) is set upright and translated, with the linear velocity
        ``velocity`` (default zero) and no angular velocity, as a hand sliding it would hold
        it; a glass's contents follow through contacts. Upright means: a glass with the
        identity orientation (it is round), a block at its present yaw; ``yaw`` (rad, about the
        vertical: :func:`pbdkit.sim._tasks.yaw_of`) sets the yaw instead. An object built as a
        mocap body (the coaster, a tray) is moved kinematically, keeping its orientation, or
        turned to ``yaw`` about its reference point. Static objects cannot move.

        Raises
        ------
        ValueError
            An unknown or static object, a position that is not a finite (3,) vector, or a yaw
            that is not finite.
        """
        p = np.asarray(position, dtype=np.float64)
        v = np.zeros(3) if velocity is None else np.asarray(velocity, dtype=np.float64)
        if (
            p.shape != (3,)
            or v.shape != (3,)
            or not (np.isfinite(p).all() and np.isfinite(v).all())
        ):
            raise ValueError(
                f"position and velocity must be finite (3,) vectors, got {short(position)}, "
                f"{short(velocity)}"
            )
        if yaw is not None and not math.isfinite(yaw):
            raise ValueError(f"yaw must be finite (rad) or None, got {short(yaw)}")
        if name == self._held:
            a, d = self._glass_qadr, self._glass_vadr
            # Upright, as a hand sliding it would hold it; its reference point is then on the
            # vertical through its body's origin. The glass is built with the identity
            # orientation; a block keeps its heading unless told one.
            if yaw is None and self._held_kind == "block":
                yaw = _heading(self.data.xmat[self._glass_body])
            quat = (1.0, 0.0, 0.0, 0.0) if yaw is None else _yaw_quat(yaw)
            self.data.qpos[a + 3 : a + 7] = quat
            self.data.qvel[d + 3 : d + 6] = 0.0
            mujoco.mj_kinematics(self.model, self.data)
            now = self.object_positions()[self._held]
            self.data.qpos[a : a + 3] += p - now
            self.data.qvel[d : d + 3] = v
        elif name in self._mocap:
            mid, offset = self._mocap[name]
            if yaw is not None:
                self.data.mocap_quat[mid] = _yaw_quat(yaw)
            self.data.mocap_pos[mid] = p - _quat_mat(self.data.mocap_quat[mid]) @ offset
        else:
            movable = [self._held, *self._mocap]
            raise ValueError(f"object {short(name)} cannot move; movable objects: {movable}")
        mujoco.mj_kinematics(self.model, self.data)

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

    def grasped_held(self) -> bool:
        """True if both fingers touch the grasped object (a glass's walls, a block's box)."""
        return (
            self.contacts("finger_left", self._held_wall) > 0
            and self.contacts("finger_right", self._held_wall) > 0
        )

    def grasped_released(self) -> bool:
        """True if no finger touches the grasped object (a glass or a block)."""
        left = self.contacts("finger_left", self._held_wall)
        return not (left or self.contacts("finger_right", self._held_wall))

    # -- cameras -----------------------------------------------------------------------------
    def camera_id(self, camera: str) -> int:
        """MuJoCo id of a camera of ``info.cameras``; ValueError for another name."""
        if camera not in self.info.cameras:
            raise ValueError(
                f"camera must be one of {list(self.info.cameras)}, got {short(camera)}"
            )
        return int(self.model.camera(camera).id)

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
