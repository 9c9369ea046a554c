"""The simulated world in ``pbdkit view --task``: the MuJoCo scene drawn in the page, and the
runs in physics that the page replays.

:class:`SimDrawing` turns the scene's visible geoms (boxes, cylinders, spheres, capsules,
ellipsoids and meshes; the floor plane is left to the page's grid) into one mesh per body, in
the body's frame, and moves the bodies: for a posture of the arm and a placement of the objects
(:meth:`SimDrawing.show_plan`, kinematics only), or as a recorded run left them
(:meth:`SimDrawing.show_frame`). :class:`Sampler` is the
:class:`pbdkit.sim.Disturbance` that records such frames while a run goes on (and, for
the online run, paces it to the wall clock and moves the objects the user drags).

This module imports MuJoCo and the simulation (the ``sim`` extra); :mod:`pbdkit.apps._view`
imports it only for a task.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import NDArray

from ..data._placement import position_of
from ..sim._gl import mujoco
from ..sim._perturb import Disturbance
from ..sim._scene import Simulation
from ..sim._tasks import TaskSpec, yaw_of

if TYPE_CHECKING:
    import trimesh
    import viser

__all__ = ["Frame", "RunStopped", "Sampler", "SimDrawing", "geom_mesh"]

Float = NDArray[np.float64]

#: Geom groups drawn (MuJoCo's default visible groups; the arm's collision copies are group 1
#: in the URDF's MuJoCo block and are not drawn twice).
DRAWN_GROUPS = (0,)
#: Frames per second of a recorded run (:class:`Sampler`).
FRAME_RATE = 30.0


def geom_mesh(model: mujoco.MjModel, g: int) -> trimesh.Trimesh | None:
    """Geom ``g`` of ``model`` as a mesh in its body's frame, colored by its rgba (None for a
    plane or a height field, which the page does not draw)."""
    import trimesh

    kind = int(model.geom_type[g])
    size = np.asarray(model.geom_size[g], dtype=np.float64)
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        mesh = trimesh.creation.box(extents=2.0 * size)
    elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        mesh = trimesh.creation.cylinder(radius=size[0], height=2.0 * size[1], sections=32)
    elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        mesh = trimesh.creation.capsule(height=2.0 * size[1], radius=size[0], count=[16, 16])
    elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        mesh.apply_scale(size)
    elif kind == mujoco.mjtGeom.mjGEOM_MESH:
        m = int(model.geom_dataid[g])
        v0, nv = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        f0, nf = int(model.mesh_faceadr[m]), int(model.mesh_facenum[m])
        mesh = trimesh.Trimesh(
            vertices=np.array(model.mesh_vert[v0 : v0 + nv]),
            faces=np.array(model.mesh_face[f0 : f0 + nf]),
            process=False,
        )
    else:
        return None
    pose = np.eye(4)
    quat = np.asarray(model.geom_quat[g], dtype=np.float64)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, quat)
    pose[:3, :3] = rot.reshape(3, 3)
    pose[:3, 3] = model.geom_pos[g]
    mesh.apply_transform(pose)
    rgba = np.array(model.geom_rgba[g], dtype=np.float64)
    if int(model.geom_matid[g]) >= 0:
        rgba = np.array(model.mat_rgba[int(model.geom_matid[g])], dtype=np.float64)
    mesh.visual.face_colors = np.clip(np.round(255.0 * rgba), 0, 255).astype(np.uint8)
    return cast("trimesh.Trimesh", mesh)


@dataclass(frozen=True)
class Frame:
    """One recorded instant of a run: time (s) and every body's pose."""

    t: float
    xpos: Float
    xquat: Float


class SimDrawing:
    """The task's MuJoCo scene in a viser scene, one node per body under ``/sim``.

    Parameters
    ----------
    server : viser.ViserServer
    spec : TaskSpec
    objects : mapping str -> array
        The placement the scene is built for (every object; fixed ones at their place).
    """

    def __init__(
        self, server: viser.ViserServer, spec: TaskSpec, objects: Mapping[str, Any]
    ) -> None:
        import trimesh

        self.spec = spec
        self.sim = Simulation.from_task(spec, dict(objects))
        self.model = self.sim.model
        m = self.model
        self._server = server
        self._nodes: dict[int, Any] = {}
        meshes: dict[int, list[trimesh.Trimesh]] = {}
        for g in range(m.ngeom):
            if int(m.geom_group[g]) not in DRAWN_GROUPS or m.geom_rgba[g][3] <= 0.0:
                continue
            mesh = geom_mesh(m, g)
            if mesh is not None:
                meshes.setdefault(int(m.geom_bodyid[g]), []).append(mesh)
        #: Bodies of the liquid (basin task): drawn in a run, hidden in a plan (they stay where
        #: the scene was built while the glass is dragged).
        self.liquid = {b for b in meshes if m.body(b).name.startswith("liquid")}
        self._grasped = int(m.body(spec.grasped).id)
        for b, parts in meshes.items():
            name = m.body(b).name or f"body{b}"
            whole = cast("trimesh.Trimesh", trimesh.util.concatenate(parts))
            self._nodes[b] = server.scene.add_mesh_trimesh(f"/sim/{name}", whole)

    def _place(self, objects: Mapping[str, Any]) -> None:
        """Put the movable objects of ``objects`` where they say (kinematically)."""
        for name, value in objects.items():
            if name in self.spec.fixed_objects:
                continue
            v = np.asarray(value, dtype=np.float64)
            yaw = yaw_of(v) if v.shape == (4, 4) else None
            self.sim.place_object(name, position_of(v), yaw=yaw)

    def show_plan(self, q: Float, objects: Mapping[str, Any], carry: Float | None = None) -> None:
        """The arm at joint angles ``q`` and the objects at ``objects``, by kinematics (no
        physics step; the fingers as the scene was built); ``carry``: a 4x4 transform that
        moves the grasped object from where it lies
        (:func:`pbdkit.apps._view_plan.carry_transform`)."""
        self._place(objects)
        self.sim.set_joints(q)
        xpos, xquat = self.sim.data.xpos, self.sim.data.xquat
        if carry is not None:
            xpos, xquat = np.array(xpos), np.array(xquat)
            b = self._grasped
            body = np.eye(4)
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, xquat[b])
            body[:3, :3], body[:3, 3] = rot.reshape(3, 3), xpos[b]
            moved = carry @ body
            xpos[b] = moved[:3, 3]
            mujoco.mju_mat2Quat(xquat[b], moved[:3, :3].reshape(-1))
        self._send(xpos, xquat, liquid=False)

    def show_frame(self, frame: Frame) -> None:
        """A recorded instant of a run."""
        self._send(frame.xpos, frame.xquat, liquid=True)

    def replay(self, frames: list[Frame], stop: threading.Event) -> None:
        """Show a recorded run's ``frames`` at the pace they were taken, until ``stop`` is
        set."""
        if not frames:
            return
        start = time.perf_counter() - frames[0].t
        for frame in frames:
            if stop.is_set():
                return
            wait = start + frame.t - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            self.show_frame(frame)

    def _send(self, xpos: Float, xquat: Float, *, liquid: bool) -> None:
        with self._server.atomic():
            for b, node in self._nodes.items():
                if b in self.liquid:
                    node.visible = liquid
                    if not liquid:
                        continue
                node.position = np.array(xpos[b], dtype=np.float64)
                node.wxyz = np.array(xquat[b], dtype=np.float64)

    def close(self) -> None:
        """Free the simulation's renderer (the nodes stay in the scene)."""
        self.sim.close()


class RunStopped(Exception):
    """A run in physics was stopped from outside (the page closed, the server stopping)."""


@dataclass
class Sampler(Disturbance):
    """Records :class:`Frame`\\ s of a run at :data:`FRAME_RATE`; live (the online run), it also
    shows each frame as it is taken, keeps the run at the wall clock's pace, and moves objects
    the user drags (those not in the hand).

    Attributes
    ----------
    show : callable, optional
        Called with each frame as it is taken (live runs).
    realtime : bool
        Sleep so that run time follows the wall clock.
    moves : dict str -> array
        Placements dragged since the last physics step, taken (and emptied) by the run; set
        items under ``lock``.
    stop : threading.Event
        Set it to end the run (:class:`RunStopped` is raised inside the physics loop).
    """

    show: Callable[[Frame], None] | None = None
    realtime: bool = False
    moves: dict[str, Float] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    stop: threading.Event = field(default_factory=threading.Event)
    frames: list[Frame] = field(default_factory=list)
    name: str = field(default="view", init=False)
    _next: float = field(default=0.0, init=False)
    _wall0: float | None = field(default=None, init=False)

    def apply(self, sim: Simulation, t: float) -> None:
        if self.stop.is_set():
            raise RunStopped
        if self.moves:
            with self.lock:
                moves, self.moves = self.moves, {}
            held = sim.grasped_held()
            for name, value in moves.items():
                if held and name == sim.info.spec.grasped:
                    continue  # in the hand: the hand decides where it is
                v = np.asarray(value, dtype=np.float64)
                yaw = yaw_of(v) if v.shape == (4, 4) else None
                sim.place_object(name, position_of(v), yaw=yaw)
        if t + 1e-9 < self._next:
            return
        self._next += 1.0 / FRAME_RATE
        frame = Frame(t, np.array(sim.data.xpos), np.array(sim.data.xquat))
        self.frames.append(frame)
        if self.show is not None:
            self.show(frame)
        if self.realtime:
            now = time.perf_counter()
            if self._wall0 is None:
                self._wall0 = now - t
            ahead = self._wall0 + t - now
            if ahead > 0:
                time.sleep(min(ahead, 0.1))

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "frames": len(self.frames)}
