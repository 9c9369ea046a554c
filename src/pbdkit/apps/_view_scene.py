"""The view's scene (issue 38): the obstacles drawn, each plan checked against them (and, with a
scene of the user's, kept clear of them by the fused controller), and where the arm comes
within the margin at the step shown, a red mark on it (private).

For ``--task`` the task's own scene (:attr:`pbdkit.sim.TaskSpec.scene`) is checked only, as
``pbdkit evaluate`` checks it: the simulated world already draws it. For a URDF with
``--scene FILE`` the shapes are drawn here and the fused controller keeps clear of them, as
:meth:`pbdkit.Skill.reproduce` with ``scene=`` does.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..collision import Box, CollisionChecker, Cylinder, Scene, Sphere
from ..reproduction._avoid import DEFAULT_MARGIN
from ._view_plan import Plan, quat_wxyz

__all__ = ["SceneLayer"]

Float = NDArray[np.float64]

#: The obstacles' color and opacity.
OBSTACLE_RGB = (150, 150, 160)
OBSTACLE_OPACITY = 0.55
#: The mark where the arm is within the margin: red at contact, orange within the margin.
CONTACT_RGB = (220, 30, 30)
NEAR_RGB = (245, 140, 20)


class SceneLayer:
    """What the view knows of the scene: the user's ``scene`` (drawn, avoided) or, for a
    task, the task's (:meth:`scene_for`; checked only), and the mark of the nearest pair.

    Parameters
    ----------
    server : viser.ViserServer
    scene : Scene, optional
        The user's scene (``pbdkit view --scene FILE``).
    task : TaskSpec, optional
        A task view's task: its scene is built for each placement.
    margin : float
        The clearance kept and marked (m).
    """

    def __init__(
        self,
        server: Any,
        scene: Scene | None = None,
        task: Any = None,
        margin: float = DEFAULT_MARGIN,
    ) -> None:
        self.server, self.scene, self.task, self.margin = server, scene, task, float(margin)
        if scene is not None:
            _draw_shapes(server, scene)
        self.mark: Any = server.scene.add_icosphere(
            "/plan/clearance", radius=0.015, color=NEAR_RGB, opacity=0.8, visible=False
        )
        self.label: Any = server.scene.add_label("/plan/clearance_label", "", visible=False)
        self._checker: tuple[Plan, CollisionChecker] | None = None

    @property
    def active(self) -> bool:
        """Whether there is a scene to check plans against."""
        return self.scene is not None or (self.task is not None and self.task.scene is not None)

    @property
    def avoids(self) -> bool:
        """Whether the fused controller keeps clear of it (the user's scene), or only checks
        (a task's, as ``pbdkit evaluate``)."""
        return self.scene is not None

    def scene_for(self, objects: Mapping[str, Float]) -> Scene | None:
        """The scene a plan for ``objects`` is checked against (None: none)."""
        if self.scene is not None:
            return self.scene
        if self.task is not None and self.task.scene is not None:
            return self.task.scene(self.task.full_placement(dict(objects)))  # type: ignore[no-any-return]
        return None

    def summary(self, plan: Plan) -> str:
        """The plan's clearance in a sentence for the status line ("" without a scene)."""
        res = plan.result
        if res.clearance is None:
            return ""
        low = 1e3 * float(np.min(res.clearance))
        if res.collisions:
            _, first, second = res.collisions[0]
            return f" In contact: {first} and {second} ({len(res.collisions)} samples)."
        return f" Clearance at least {low:.1f} mm."

    def show(self, plan: Plan, step: int) -> None:
        """Mark the nearest pair at ``step`` where it is within the margin (red: in contact);
        hide the mark elsewhere."""
        res = plan.result
        near = None
        if res.clearance is not None and float(res.clearance[step]) < self.margin:
            near = self._nearest(plan, step)
        if near is None:
            self.mark.visible = self.label.visible = False
            return
        distance, bodies, point = near
        self.mark.position = point
        self.mark.color = CONTACT_RGB if distance < 0.0 else NEAR_RGB
        self.label.position = point + np.array([0.0, 0.0, 0.04])
        self.label.text = f"{bodies[0]}-{bodies[1]} {1e3 * distance:.1f} mm"
        self.mark.visible = self.label.visible = True

    def _nearest(self, plan: Plan, step: int) -> tuple[float, tuple[str, str], Float] | None:
        """The nearest pair at a sample of the plan: its distance, bodies and the point on the
        arm (or what it carries)."""
        scene = self.scene_for(plan.objects)
        if scene is None:
            return None
        if self._checker is None or self._checker[0] is not plan:
            checker = CollisionChecker(plan.skill.robot, scene, plan.objects)
            checker.plan_grasps(plan.result.joints, plan.result.gripper_signal)
            self._checker = (plan, checker)
        checker = self._checker[1]
        joints = plan.result.joints
        for lo, hi, state in checker._segments(joints.shape[0], checker.hand_frames(joints)):
            if lo <= step < hi:
                near = checker.near(joints[step], self.margin, state.carried, state.released)
                if not near:
                    return None
                prox = min(near, key=lambda p: p.distance)
                arm = 0 if prox.joints[0] >= 0 else 1
                return prox.distance, prox.bodies, np.asarray(prox.points[arm])
        return None


def _draw_shapes(server: Any, scene: Scene) -> None:
    """The scene's obstacles, grey and half transparent, under ``/scene``."""
    import trimesh

    for i, shape in enumerate(scene.shapes):
        name = f"/scene/{shape.name or i}"
        pose = shape.pose
        position, wxyz = np.asarray(pose[:3, 3]), quat_wxyz(pose[:3, :3])
        common = {"position": position, "wxyz": wxyz}
        if isinstance(shape, Box):
            server.scene.add_box(
                name,
                color=OBSTACLE_RGB,
                dimensions=tuple(float(v) for v in shape.size),
                opacity=OBSTACLE_OPACITY,
                **common,
            )
        elif isinstance(shape, Sphere):
            server.scene.add_icosphere(
                name, radius=shape.radius, color=OBSTACLE_RGB, opacity=OBSTACLE_OPACITY, **common
            )
        elif isinstance(shape, Cylinder):
            mesh = trimesh.creation.cylinder(radius=shape.radius, height=shape.length)
            mesh.visual.face_colors = (*OBSTACLE_RGB, round(255 * OBSTACLE_OPACITY))
            server.scene.add_mesh_trimesh(name, mesh, **common)
