"""``pbdkit view``: the skill live in a browser. Drag an object and the plan follows.

A `viser <https://viser.studio>`_ server, bound to 127.0.0.1, serves a page with a 3-D scene and
a panel:

- the arm, drawn from its URDF (``--skill``; with yourdfpy, plus a stick figure through its
  links for a URDF without visual geometry) or from the MuJoCo scene of the task (``--task``:
  the table and the objects as the simulation has them);
- each object the skill knows, as a handle to drag: across the table and about the vertical for
  a task (x, y, and yaw for an object placed as a pose), in 3-D for a skill file; and as number
  fields in the panel;
- on every move, the skill reproduced for the new placement (:meth:`pbdkit.Skill.reproduce`,
  with the chosen controller), and the scene redrawn: the planned hand path, each segment
  colored by the constraint that drives that step (the largest share of
  :attr:`~pbdkit.ReproductionResult.influence`, colors as in the
  report's Fig. 6); the arm at the step of the time slider (and ``play``); the constraints'
  Gaussians at that step, as ellipsoids of :data:`N_SD` standard deviations of the hand
  position each expects (in the object's frame, so they turn with it; the joint-space one
  through the Jacobian), the driving one opaque. A newer move replaces one that waits to be
  planned (:class:`LatestWins`): the page shows the latest placement, never a backlog.
- for a task: ``run in physics`` executes the plan in MuJoCo and replays it with the outcome;
  ``online`` runs the controller in the physics loop at the wall clock's pace, the objects still
  draggable (an object in the hand stays there). The outcome is only shown for the plan it ran:
  a move the run does not see, or another controller, clears it
  (:class:`pbdkit.apps._view_verdict.Verdict`).
- with ``suggest``: where to demonstrate next, as ghosts of the objects to drag them to
  (:class:`pbdkit.apps._view_suggest.ViewSuggestions`).

The library does not need any of this: viser and yourdfpy are the optional extra
``pbdkit[view]`` and are imported only by the view's modules, when the command runs (the server:
:mod:`pbdkit.apps._view_serve`; a skill's arm from its URDF: :mod:`pbdkit.apps._view_urdf`; a
task's MuJoCo world: :mod:`pbdkit.apps._view_world`).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .._rotations import exp_map, matrix_from_quaternion, pose_matrix
from .._validation import short
from ..data._placement import check_placements, position_of
from ..reproduction._constraints import JOINT
from ..reproduction._steps import CLEARANCE
from ..robots._protocols import PoseKinematicModel
from ..skill._naming import controller_names, controller_use
from ._cli_output import metrics_text
from ._view_plan import (
    CLEARANCE_RGB,
    COLOR_NAMES,
    JOINT_RGB,
    N_SD,
    OBJECT_RGBS,
    LatestWins,
    Plan,
    camera_pose,
    carry_transform,
    coarse_skill,
    constraint_colors,
    ellipsoid_pose,
    make_plan,
    quat_wxyz,
    step_gaussians,
    wxyz_of,
    yaw_deg,
    yaw_pose,
)
from ._view_scene import SceneLayer
from ._view_suggest import SuggestSettings, ViewSuggestions
from ._view_verdict import Verdict

if TYPE_CHECKING:
    import viser

    from ..collision import Scene
    from ..sim._task_skill import TaskSkill
    from ..skill._skill import Skill
    from ._view_urdf import UrdfArm
    from ._view_world import SimDrawing

__all__ = [
    "MIN_PREVIEW_STEPS",
    "PATH_SEGMENTS",
    "PREVIEW_BUDGET",
    "PREVIEW_STEPS",
    "ViewApp",
]

Float = NDArray[np.float64]

#: While an object is dragged, plans are previews on a grid of at most this many steps
#: (:func:`pbdkit.apps._view_plan.coarse_skill`); the full plan follows when the drag ends.
PREVIEW_STEPS = 250
#: ... and fewer where a skill's preview would take longer than this (s) to plan
#: (:meth:`ViewApp.calibrate_preview`), down to :data:`MIN_PREVIEW_STEPS`.
PREVIEW_BUDGET = 0.030
MIN_PREVIEW_STEPS = 100
#: At most this many segments in the drawn path.
PATH_SEGMENTS = 400


class ViewApp:
    """The page: scene, panel, planner (module docstring).
    :func:`pbdkit.apps._view_serve.serve` runs it.

    Parameters
    ----------
    skill : Skill
    objects : mapping str -> array
        Where the objects start (every object the skill knows; for a task, every object of the
        task).
    server : viser.ViserServer
        Bound to :data:`pbdkit.apps._view_serve.HOST`; the app adds its scene and panel.
    task_skill : TaskSkill, optional
        For ``--task``: the task's skills (controllers, ``fused-position``), the MuJoCo scene
        and the runs in physics.
    urdf : path or str, optional
        The URDF to draw the arm from, a file (meshes are looked up beside it) or its XML text;
        default: the skill's robot's URDF text. Its joints are the skill's arm's by name, or
        in order (:func:`pbdkit.apps._view_urdf.joint_order`).
    title : str
        Shown at the top of the panel.
    preview_steps : int or None
        While a handle is held, plans are previews of at most this many steps
        (:func:`coarse_skill`; fewer if a preview would take more than
        :data:`PREVIEW_BUDGET`, :meth:`calibrate_preview`); the full plan follows its release.
        None: full plans only.
    scene : Scene, optional
        Obstacles, drawn and kept clear of by the fused controller (a task's own scene is
        checked without it): :class:`pbdkit.apps._view_scene.SceneLayer`.
    suggest : SuggestSettings, optional
        Show the skill's suggestions as ghosts (:attr:`suggestions`).
    """

    def __init__(
        self,
        skill: Skill,
        objects: Mapping[str, Any],
        server: viser.ViserServer,
        *,
        task_skill: TaskSkill | None = None,
        urdf: Path | str | None = None,
        title: str = "pbdkit view",
        preview_steps: int | None = PREVIEW_STEPS,
        scene: Scene | None = None,
        suggest: SuggestSettings | None = None,
    ) -> None:
        self.skill = skill
        #: Steps of a preview plan (None, or a skill of no more steps: no previews).
        self.preview_steps = (
            preview_steps if preview_steps is not None and preview_steps < skill.n_steps else None
        )
        self._coarse_skills: dict[tuple[int, int], Skill] = {}
        self.preview_seconds: float | None = None
        self._max_preview_steps = self.preview_steps or 0
        self._preview_times: deque[float] = deque(maxlen=5)
        self._dragging: set[str] = set()
        self.ts = task_skill
        #: The arm when it gives the hand's orientation (a PoseKinematicModel): the hand's frame
        #: is drawn, and a task's grasped object carried; None: the hand's position only.
        self.pose_robot: PoseKinematicModel | None = (
            skill.robot if isinstance(skill.robot, PoseKinematicModel) else None
        )
        self.server = server
        self._lock = threading.RLock()
        # Positions (3,) and poses (4x4; x, y, z, qw, qx, qy, qz becomes one).
        self.objects: dict[str, Float] = check_placements(objects, "objects")
        missing = [k for k in skill.object_names if k not in self.objects]
        if missing:
            raise ValueError(f"objects: no placement for {missing} (the skill's objects)")
        oriented = task_skill is not None and task_skill.position_skill is not None
        self.controllers = controller_names(skill.object_names, has_oriented=oriented)
        self.controller = "fused"
        self.colors = constraint_colors([JOINT, *skill.object_names])
        if scene is not None:  # kept clear of (the fused controller): the clearance may drive
            self.colors[CLEARANCE] = CLEARANCE_RGB
        self.plan: Plan | None = None
        self.suggestions: ViewSuggestions | None = None  # set last: moves may come before
        self.step = 0
        self.plans = 0
        self._run_thread: threading.Thread | None = None
        self._live: Any = None  # the online run's Sampler while it runs
        #: The last run in physics (:class:`pbdkit.sim._runs.ControllerRun` or
        #: :class:`~pbdkit.sim._runs.OnlineControllerRun`) and its line in the panel.
        self.last_run: Any = None
        self.result_text = ""
        self.verdict = Verdict(self._set_result)  # the outcome, kept to the plan it ran
        self._stop = threading.Event()
        self._updating_fields = False
        self._playing = threading.Event()
        self._draw_world: SimDrawing | None = None
        self._urdf_arm: UrdfArm | None = None
        self._build_scene(urdf)
        self.scene = SceneLayer(server, scene, None if task_skill is None else task_skill.task)
        self._build_panel(title)
        self.planner: LatestWins[tuple[dict[str, Float], str, bool]] = LatestWins(
            self._replan, on_error=self._report_error
        )
        self._player = threading.Thread(
            target=self._play_loop, name="pbdkit-view-play", daemon=True
        )
        self._player.start()
        self.suggestions = None if suggest is None else ViewSuggestions(self, suggest)
        self.request_plan()

    # ------------------------------------------------------------------ scene
    def _build_scene(self, urdf: Path | str | None) -> None:
        scene = self.server.scene
        scene.set_up_direction("+z")
        scene.add_grid("/grid", width=2.0, height=2.0, cell_size=0.1, position=(0.0, 0.0, -0.001))
        camera = self.server.initial_camera
        camera.position, camera.look_at = camera_pose(self.skill.reach, self.objects.values())
        if self.ts is not None:
            from ._view_world import SimDrawing

            self._draw_world = SimDrawing(self.server, self.ts.task, self.objects)
        else:
            from ._view_urdf import UrdfArm

            self._urdf_arm = UrdfArm(self.server, self.skill.robot, urdf)
        self.handles: dict[str, Any] = {}
        movable = self._movable()
        for name in movable:
            value = self.objects[name]
            posed = value.shape == (4, 4)
            if self.ts is not None:  # on the table: across it, and about the vertical
                axes, rotations = (True, True, False), posed
            else:
                axes, rotations = (True, True, True), posed
            handle = scene.add_transform_controls(
                f"/objects/{name}",
                scale=0.12,
                active_axes=axes,
                disable_rotations=not rotations,
                depth_test=False,
                position=np.asarray(position_of(value), dtype=np.float64),
                wxyz=wxyz_of(value),
            )
            if self.ts is None:
                color = self.colors.get(name, (90, 90, 90))
                scene.add_icosphere(f"/objects/{name}/marker", radius=0.02, color=color)
                scene.add_frame(f"/objects/{name}/axes", axes_length=0.06, axes_radius=0.003)
            scene.add_label(f"/objects/{name}/label", name, position=(0.0, 0.0, 0.05))
            handle.on_update(self._dragged(name))
            self.handles[name] = handle
        self.path: Any = None
        self.gauss: dict[str, Any] = {}
        for name in [JOINT, *self.skill.object_names]:
            self.gauss[name] = scene.add_icosphere(
                f"/plan/gauss/{name}",
                radius=1.0,
                color=self.colors[name],
                opacity=0.3,
                subdivisions=3,
                cast_shadow=False,
                receive_shadow=False,
            )
        self.hand = scene.add_frame("/plan/hand", axes_length=0.05, axes_radius=0.003)
        # A dot at the hand in the color of the constraint that drives the step.
        self.hand_dot: Any = scene.add_icosphere(
            "/plan/hand/driving", radius=0.012, color=self.colors[JOINT], cast_shadow=False
        )

    def _movable(self) -> list[str]:
        """The objects that can be dragged: the skill's (for a task, those that move)."""
        if self.ts is not None:
            fixed = set(self.ts.task.fixed_objects)
            return [k for k in self.objects if k not in fixed]
        return list(self.skill.object_names)

    # ------------------------------------------------------------------ panel
    def _build_panel(self, title: str) -> None:
        gui = self.server.gui
        gui.add_markdown(f"**{title}**: drag an object; the plan follows.")
        names = {
            JOINT_RGB: "green",
            CLEARANCE_RGB: "grey",
            **dict(zip(OBJECT_RGBS, COLOR_NAMES, strict=True)),
        }
        legend = ", ".join(f"{k} {names[c]}" for k, c in self.colors.items())
        gui.add_markdown(
            f"Path and dot at the hand: the constraint that drives ({legend}); ellipsoids: "
            f"each constraint's {N_SD:g}-sd Gaussian at the step, the driving one opaque."
        )
        self.ui_controller: Any = gui.add_dropdown(
            "controller", tuple(self.controllers), initial_value=self.controller
        )
        self.ui_controller.on_update(self._controller_changed)
        self.ui_status: Any = gui.add_markdown("planning ...")
        self.ui_end: Any = gui.add_text("hand at the end (mm)", initial_value="", disabled=True)
        self.ui_reproduce: Any = gui.add_text("reproduce (ms)", initial_value="", disabled=True)
        self.ui_driving: Any = gui.add_text("driving now", initial_value="", disabled=True)
        self.ui_step: Any = gui.add_slider("step", min=0, max=1, step=1, initial_value=0)
        self.ui_step.on_update(self._step_changed)
        self.ui_play: Any = gui.add_button("play")
        self.ui_play.on_click(self._play_clicked)
        self.ui_fields: dict[str, tuple[Any, Any]] = {}
        with gui.add_folder("objects"):
            for name in self._movable():
                value = self.objects[name]
                pos: Any = gui.add_vector3(
                    f"{name} (m)",
                    initial_value=np.round(position_of(value), 4),
                    step=0.005,
                )
                yaw: Any = None
                if value.shape == (4, 4):
                    yaw = gui.add_number(
                        f"{name} yaw (deg)", initial_value=round(yaw_deg(value), 2), step=1.0
                    )
                    yaw.on_update(self._field_changed(name))
                pos.on_update(self._field_changed(name))
                self.ui_fields[name] = (pos, yaw)
        self.ui_run: Any = None
        self.ui_online: Any = None
        self.ui_result: Any = None
        if self.ts is not None:
            with gui.add_folder("physics (MuJoCo)"):
                self.ui_run = gui.add_button("run in physics")
                self.ui_run.on_click(self._run_clicked)
                self.ui_online = gui.add_button("online")
                self.ui_online.on_click(self._online_clicked)
                self.ui_result = gui.add_markdown("")

    # ------------------------------------------------------------------ events
    def _dragged(self, name: str) -> Callable[[Any], None]:
        def on_update(event: Any) -> None:
            arrived = time.perf_counter()
            # While the handle is held: previews; at its release, the full plan. viser runs
            # these callbacks in a thread pool, possibly out of order: an update handled after
            # the release plans in full too (and a preview plans in full once nothing is held).
            phase = getattr(event, "phase", "end")
            if phase in ("start", "end"):
                self.hold(name, phase == "start")
            with self._lock:
                held = name in self._dragging
            handle = self.handles[name]
            self.move_object(
                name,
                self._placement_from(name, np.array(handle.position), np.array(handle.wxyz)),
                arrived=arrived,
                from_handle=True,
                preview=held,
            )

        return on_update

    def _placement_from(self, name: str, position: Float, wxyz: Float) -> Float:
        old = self.objects[name]
        if self.ts is not None:  # keep the object on its support
            position = np.array([position[0], position[1], position_of(old)[2]])
        if old.shape != (4, 4):
            return np.asarray(position, dtype=np.float64)
        rot = matrix_from_quaternion(wxyz)
        if self.ts is not None:
            return yaw_pose(position, math.degrees(math.atan2(rot[1, 0], rot[0, 0])))
        pose = np.eye(4)
        pose[:3, :3] = rot
        pose[:3, 3] = position
        return pose

    def _field_changed(self, name: str) -> Callable[[Any], None]:
        def on_update(event: Any) -> None:
            if self._updating_fields or event.client_id is None:
                return  # set by the server itself
            arrived = time.perf_counter()
            pos, yaw = self.ui_fields[name]
            p = np.array(pos.value, dtype=np.float64)
            old = self.objects[name]
            if not (np.isfinite(p).all() and (yaw is None or math.isfinite(float(yaw.value)))):
                with self._lock:  # not a place: the fields show where the object is
                    self._set_fields(name, old)
                return
            if old.shape == (4, 4) and self.ts is not None:
                value = yaw_pose(p, float(yaw.value))
            elif old.shape == (4, 4):  # in 3-D: turned about the vertical by the yaw's change
                turn = exp_map([0.0, 0.0, math.radians(float(yaw.value) - yaw_deg(old))])
                value = pose_matrix(p, turn @ old[:3, :3])
            else:
                value = p
            self.move_object(name, value, arrived=arrived)

        return on_update

    def move_object(
        self,
        name: str,
        placement: Any,
        *,
        arrived: float | None = None,
        from_handle: bool = False,
        preview: bool = False,
    ) -> None:
        """Put object ``name`` at ``placement`` (as a drag does) and plan for it.

        The handle and the panel's fields follow, the scene's object moves at once, and the
        plan is queued (:class:`LatestWins`): a preview (:func:`coarse_skill`, as while the
        handle is held) with ``preview``, else the full plan. In an online run the object
        moves in the physics too.
        """
        if name not in self.handles:
            raise ValueError(
                f"object {short(name)} cannot be moved here; movable: {list(self.handles)}"
            )
        value = np.asarray(placement, dtype=np.float64)
        if value.shape != self.objects[name].shape or not np.isfinite(value).all():
            raise ValueError(
                f"{name}: a placement of shape {self.objects[name].shape} is needed, got "
                f"{value.shape}"
            )
        arrived = time.perf_counter() if arrived is None else arrived
        with self._lock:
            old, self.objects[name] = self.objects[name], value.copy()
            if not from_handle:
                handle = self.handles[name]
                handle.position = np.asarray(position_of(value), dtype=np.float64)
                handle.wxyz = wxyz_of(value)
            self._set_fields(name, value)
            live = self._live
            if live is not None:  # moved in the online run's physics too: its outcome holds
                with live.lock:
                    live.moves[name] = value.copy()
            elif not np.allclose(value, old, rtol=0.0, atol=1e-9):
                self.verdict.changed()  # not for a handle grabbed and let go where it was
        self.request_plan(arrived, preview=preview)
        if self.suggestions is not None:
            self.suggestions.moved()

    def hold(self, name: str, held: bool) -> None:
        """Mark object ``name`` as held (a drag under way: plans are previews) or released,
        as the handle's drag events do."""
        with self._lock:
            if held:
                self._dragging.add(name)
            else:
                self._dragging.discard(name)

    def _set_fields(self, name: str, value: Float) -> None:
        pos, yaw = self.ui_fields[name]
        self._updating_fields = True
        try:
            pos.value = np.round(position_of(value), 4)
            if yaw is not None:
                yaw.value = round(yaw_deg(value), 2)
        finally:
            self._updating_fields = False

    def _controller_changed(self, event: Any) -> None:
        self.controller = str(self.ui_controller.value)
        self.verdict.changed()
        self.request_plan()

    def request_plan(self, arrived: float | None = None, *, preview: bool = False) -> None:
        """Queue a plan (``preview``: on the coarse grid) for the current placement and
        controller."""
        preview = preview and self.preview_steps is not None
        with self._lock:
            request = ({k: v.copy() for k, v in self.objects.items()}, self.controller, preview)
        self.planner.submit(request, arrived, "preview" if preview else "full")

    def preview_skill(self, skill: Skill) -> Skill:
        """The preview skill of ``skill`` (:func:`coarse_skill`, built once per size)."""
        assert self.preview_steps is not None
        key = (id(skill), self.preview_steps)
        coarse = self._coarse_skills.get(key)
        if coarse is None:
            coarse = coarse_skill(skill, self.preview_steps)
            coarse.constraints()  # its GMR, once
            self._coarse_skills[key] = coarse
        return coarse

    def calibrate_preview(self, plan: Plan, use: list[str] | None) -> None:
        """Fit the previews to :data:`PREVIEW_BUDGET`: time a preview of ``plan`` (a full
        plan; the least of three runs), take the cost as affine in the number of steps through
        it and the full plan's, and use the number of steps that fits the budget (between
        :data:`MIN_PREVIEW_STEPS` and the present number)."""
        if self.preview_steps is None:
            return
        full_steps = plan.skill.n_steps
        coarse = self.preview_skill(plan.skill)
        times = []
        for _ in range(3):  # the least of three: the page may be loading meanwhile
            start = time.perf_counter()
            make_plan(coarse, plan.objects, plan.controller, use, preview=True)
            times.append(time.perf_counter() - start)
        t_coarse = min(times)
        n = self.preview_steps
        if t_coarse > PREVIEW_BUDGET and plan.seconds > t_coarse and full_steps > n:
            per_step = (plan.seconds - t_coarse) / (full_steps - n)
            fixed = t_coarse - per_step * n
            fit = int((PREVIEW_BUDGET - fixed) / per_step)
            self.preview_steps = min(n, max(MIN_PREVIEW_STEPS, fit))
        self.preview_seconds = t_coarse

    def _adapt_preview(self, seconds: float) -> None:
        """Keep the previews within :data:`PREVIEW_BUDGET` as they are planned: over the last
        five, a median over the budget takes steps away, one under 0.6 of it gives some back
        (up to the preview size asked for); the calibration at the first plan can be off on a
        busy machine (the page loading)."""
        times = self._preview_times
        times.append(seconds)
        if self.preview_steps is None or len(times) < times.maxlen:  # type: ignore[operator]
            return
        med = float(np.median(times))
        n = self.preview_steps
        if med > PREVIEW_BUDGET:
            new = max(MIN_PREVIEW_STEPS, int(n * PREVIEW_BUDGET / med))
        elif med < 0.6 * PREVIEW_BUDGET:
            new = min(self._max_preview_steps, int(n * 0.8 * PREVIEW_BUDGET / med))
        else:
            return
        if new != n:
            self.preview_steps = new
            times.clear()

    def _skill_for(self, controller: str) -> tuple[Skill, list[str] | None]:
        if self.ts is not None:
            return self.ts.skill_for(controller)
        return self.skill, controller_use(controller, self.skill.object_names)

    def _replan(self, request: tuple[dict[str, Float], str, bool]) -> None:
        objects, controller, preview = request
        skill, use = self._skill_for(controller)
        if preview:
            skill = self.preview_skill(skill)
        scene = self.scene.scene_for(objects)
        avoid = self.scene.avoids and use is None and not skill.oriented
        plan = make_plan(skill, objects, controller, use, preview=preview, scene=scene, avoid=avoid)
        if not preview and self.preview_seconds is None:
            self.calibrate_preview(plan, use)
        elif preview:
            self._adapt_preview(plan.seconds)
        with self._lock:
            old = self.plan
            frac = 0.0 if old is None else self.step / max(len(old.times) - 1, 1)
            self.plan = plan
            self.plans += 1
            n = len(plan.times)
            step = self._first_step(plan) if old is None else round(frac * (n - 1))
            self._draw_plan(plan)
            self._updating_fields = True
            try:
                self.ui_step.max = n - 1
                self.ui_step.value = step
            finally:
                self._updating_fields = False
            self._show_step(step)
        self.server.flush()
        if preview:
            with self._lock:
                settled = not self._dragging
            if settled:  # the release's full plan may have come first (module docstring)
                self.request_plan()

    def _first_step(self, plan: Plan) -> int:
        """The step where the first object's constraint is tightest (the grasp)."""
        if not self.skill.object_names:
            return 0
        c = plan.constraints
        name = self.skill.object_names[0]
        k = int(np.argmin(np.trace(c.task_cov[name][:, :3, :3], axis1=1, axis2=2)))
        return min(k + plan.lead, len(plan.times) - 1)

    def _draw_plan(self, plan: Plan) -> None:
        pts = plan.result.positions
        n = len(pts) - 1
        idx = np.unique(np.linspace(0, n, min(n, PATH_SEGMENTS) + 1).round().astype(int))
        seg = np.stack([pts[idx[:-1]], pts[idx[1:]]], axis=1)
        colors = np.array([self.colors[plan.driving[i]] for i in idx[:-1]], dtype=np.uint8)
        colors = np.repeat(colors[:, None, :], 2, axis=1)
        self.path = self.server.scene.add_line_segments(
            "/plan/path", points=seg.astype(np.float32), colors=colors, thickness=0.004
        )
        end = 1e3 * plan.end
        self.ui_end.value = ", ".join(f"{v:.1f}" for v in end)
        self.ui_reproduce.value = f"{1e3 * plan.seconds:.1f}"
        kind = "preview, " if plan.preview else ""
        text = (
            f"**{plan.controller}**: {kind}{len(plan.times)} steps, {plan.times[-1]:.1f} s; "
            f"planned in {1e3 * plan.seconds:.0f} ms."
        )
        outside = self._outside_range(plan.objects)
        if outside:
            text += f" Outside the demonstrated range: {', '.join(outside)} (extrapolating)."
        if plan.messages:
            text += " " + plan.messages[0].split(".")[0] + "."
        self.ui_status.content = text + self.scene.summary(plan)

    def _outside_range(self, objects: Mapping[str, Float]) -> list[str]:
        if self.ts is None:
            return []
        ranges = self.ts.task.ranges
        return [k for k, v in objects.items() if k in ranges and not ranges[k].contains(v)]

    def _step_changed(self, event: Any) -> None:
        if self._updating_fields:
            return
        with self._lock:
            self._show_step(int(self.ui_step.value))

    def _show_step(self, step: int) -> None:
        plan = self.plan
        if plan is None:
            return
        step = int(np.clip(step, 0, len(plan.times) - 1))
        self.step = step
        q = plan.result.joints[step]
        with self.server.atomic():
            if self._running():
                pass  # the physics draws the arm
            elif self._draw_world is not None:
                carry = (
                    None
                    if self.pose_robot is None
                    else carry_transform(self.pose_robot, plan, step)
                )
                self._draw_world.show_plan(q, plan.objects | self._fixed_objects(), carry)
            elif self._urdf_arm is not None:
                self._urdf_arm.show(q)
            if self.pose_robot is not None:
                hand = self.pose_robot.fk_pose(q)
                self.hand.position = np.asarray(hand[:3, 3])
                self.hand.wxyz = quat_wxyz(hand[:3, :3])
            driving = plan.driving[step]
            self.hand_dot.color = self.colors[driving]
            for name, (mean, cov) in step_gaussians(plan, step).items():
                node = self.gauss[name]
                axes, wxyz = ellipsoid_pose(cov)
                node.position = np.asarray(mean)
                node.wxyz = wxyz
                node.scale = np.asarray(axes)
                node.opacity = 0.75 if name == driving else 0.25
                node.visible = plan.result.used is None or name in plan.result.used
            self.scene.show(plan, step)
            share = plan.result.influence[driving][step]
            when = plan.times[step]
            self.ui_driving.value = f"{driving} ({100 * share:.0f} %) at {when:.2f} s"

    def _fixed_objects(self) -> dict[str, Float]:
        if self.ts is None:
            return {}
        return {k: v for k, v in self.objects.items() if k in self.ts.task.fixed_objects}

    # ------------------------------------------------------------------ time
    def _play_clicked(self, event: Any) -> None:
        if self._playing.is_set():
            self._playing.clear()
            self.ui_play.label = "play"
        else:
            plan = self.plan
            if plan is not None and self.step >= len(plan.times) - 1:
                self.ui_step.value = 0
            self._playing.set()
            self.ui_play.label = "pause"

    def _play_loop(self) -> None:
        last = time.perf_counter()
        while not self._stop.is_set():
            if not self._playing.wait(timeout=0.2):
                last = time.perf_counter()
                continue
            time.sleep(1.0 / 30.0)
            now = time.perf_counter()
            with self._lock:
                plan = self.plan
                if plan is None:
                    continue
                t = plan.times[self.step] + (now - last)
                step = int(np.searchsorted(plan.times, t))
                if step >= len(plan.times) - 1:
                    step = len(plan.times) - 1
                    self._playing.clear()
                    self.ui_play.label = "play"
                self.ui_step.value = step  # redraws through _step_changed
            last = now

    # ------------------------------------------------------------------ physics
    def _running(self) -> bool:
        return self._run_thread is not None and self._run_thread.is_alive()

    def _run_clicked(self, event: Any) -> None:
        self.start_run(online=False)

    def _online_clicked(self, event: Any) -> None:
        self.start_run(online=True)

    def start_run(self, *, online: bool) -> threading.Thread:
        """Run the current plan's controller in MuJoCo (``online``: in the physics loop, live)
        in a background thread; the page replays it and shows the outcome."""
        if self.ts is None:
            raise ValueError("runs in physics need a task (pbdkit view --task)")
        with self._lock:
            if self._running():
                raise ValueError("a run is going on")
            objects = {k: v.copy() for k, v in self.objects.items()}
            controller = self.controller
            kind = "online" if online else "in physics"
            # The token with the copy: a move from now on is one this run does not see.
            token = self.verdict.start(f"running {kind} ({controller}) ...")
            thread = threading.Thread(
                target=self._run_in_physics,
                args=(objects, controller, online, token),
                name="pbdkit-view-physics",
                daemon=True,
            )
            self._run_thread = thread
        thread.start()
        return thread

    def _run_in_physics(
        self, objects: dict[str, Float], controller: str, online: bool, token: int
    ) -> None:
        from ..sim._runs import run_controller, run_online
        from ._view_world import RunStopped, Sampler

        assert self.ts is not None and self._draw_world is not None
        world = self._draw_world
        for b in (self.ui_run, self.ui_online):
            if b is not None:
                b.disabled = True
        self._playing.clear()
        sampler = Sampler(show=world.show_frame if online else None, realtime=online)
        sampler.stop = self._stop
        try:
            if online:
                with self._lock:
                    self._live = sampler
                run: Any = run_online(self.ts, objects, controller, disturbance=sampler)
            else:
                run = run_controller(self.ts, objects, controller, disturbance=sampler)
            with self._lock:
                self._live = None
                if sampler.moves:  # dragged after the run's last step: the run did not see it
                    self.verdict.changed()
            if not online:
                world.replay(sampler.frames, self._stop)
            self.last_run = run
            verdict = "**success**" if run.success else "**failure**"
            shown = metrics_text(run.execution.outcome.metrics)
            kind = "online" if online else "in physics"
            self.verdict.finish(token, f"{controller} {kind}: {verdict} ({shown})")
        except RunStopped:
            self.verdict.finish(token, "run stopped", always=True)
        except Exception as exc:
            self.verdict.finish(token, f"run failed: {' '.join(str(exc).split())}", always=True)
        finally:
            with self._lock:
                self._live = None
            for b in (self.ui_run, self.ui_online):
                if b is not None:
                    b.disabled = False

    def _set_result(self, text: str) -> None:
        if self.ui_result is not None:
            self.ui_result.content = text
        self.result_text = text

    def _report_error(self, exc: BaseException) -> None:
        self.ui_status.content = f"could not plan: {' '.join(str(exc).split())}"

    # ------------------------------------------------------------------ end
    def wait_idle(self, timeout: float | None = 30.0) -> bool:
        """Block until the planner has planned the latest placement."""
        return self.planner.wait_idle(timeout)

    def close(self) -> None:
        """Stop planning, playing and any run (the server is the caller's)."""
        self._stop.set()
        self._playing.clear()
        self.planner.close()
        if self.suggestions is not None:
            self.suggestions.close()
        thread = self._run_thread
        if thread is not None:
            thread.join(timeout=10.0)
        if self._draw_world is not None:
            self._draw_world.close()
