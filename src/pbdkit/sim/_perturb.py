"""Disturbances of a run (``pbdkit evaluate --perturb NAME``): objects that move or turn, a pushed
arm.

A :class:`Disturbance` acts on the simulation before every physics step of a run, at the run's
time t (seconds from the start of the trajectory, the first command). Both ways of running a
skill take one: the offline playback (:func:`pbdkit.sim.execute`) and the online loop
(:func:`pbdkit.sim.execute_online`), so the two meet the same disturbance.

The named disturbances are a registry, like the tasks: a :class:`Perturbation` (a name, a help
text and a factory) per name, :func:`register_perturbation`, :func:`get_perturbation`,
:func:`perturbation_names`; ``pbdkit evaluate --perturb``'s choices and help come from it. A new
one is one :func:`register_perturbation` call (in a module the Dask workers import too, when the
trials run there). :func:`make_disturbance` builds the disturbance of a trial from its
:class:`DisturbanceSetup`. The built-in ones are timed from the skill itself: ``t_grasp`` is the
time of the first step where the skill's generalized gripper command closes.

- ``"none"``: nothing happens.
- ``"move"``: the task's :class:`pbdkit.sim.ObjectMove`. Coaster task: the coaster slides
  5 cm while the glass is carried, over 1 s from ``t_grasp + 0.5 s``. Basin task: the glass slides
  4 cm on the table before the grasp, over 1 s ending 1.5 s before ``t_grasp`` (the hand is
  then still on its way, behind and above the glass). The direction is drawn at random among
  those whose end point stays inside the object's placement range (the demonstrated range).
- ``"rotate"``: the task's :class:`pbdkit.sim.ObjectTurn`. Slot task: the tray turns by
  20-30 degrees about the vertical through its centre (its reference point, which stays where it
  is), at constant speed over 1 s from ``t_grasp + 1 s`` while the block is carried: the fingers
  take about 0.5 s to close on the block (measured: first contact of both 0.4-0.5 s after
  ``t_grasp``), so the turn starts once it is held, as the hand lifts it, and ends well before
  the hand lowers it into the pocket (``"before_grasp"``: as ``"move"``'s, ending 1.5 s before
  ``t_grasp``). The size
  is drawn uniformly in the task's range, the direction at random among those that keep the yaw
  inside the object's yaw range (the demonstrated range). An offline trajectory, planned for the
  tray's first yaw, puts the block in at that yaw; the online controller is told the turned pose
  and follows it.
- ``"obstacle"``: a 5 cm cube, static, centred on the fused controller's path (reproduced
  without avoidance for the trial's placement) at its mid-carry step; the fused controller
  avoids it, the others meet it (:mod:`pbdkit.sim._obstacle`).
- ``"push"``: a horizontal force of 40 N on the gripper for 0.3 s, starting halfway to the
  grasp (``t_grasp / 2``), across the arm (perpendicular to the vertical plane through the
  base axis and the grasped object, :attr:`pbdkit.sim.TaskSpec.grasped`), with a random
  sign. It exceeds what the pan drive can hold (its
  URDF effort, 10 N m): the simulated servos give way and the hand is shoved 10-30 cm off its
  path (measured on the coaster task: 5-8 mm at 15-30 N, 12 cm at 34 N, 28 cm at 40 N).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import short
from ..collision import Box
from ._registry import Registry
from ._scene import Simulation
from ._tasks import TaskSpec, yaw_of

__all__ = [
    "PERTURBATIONS",
    "Disturbance",
    "DisturbanceSetup",
    "NoDisturbance",
    "Perturbation",
    "PushArm",
    "SlideObject",
    "TurnObject",
    "check_perturb",
    "get_perturbation",
    "grasp_time",
    "make_disturbance",
    "perturbation_help",
    "perturbation_names",
    "register_perturbation",
    "unregister_perturbation",
]

Float = NDArray[np.float64]

PUSH_FORCE = 40.0  # N
PUSH_DURATION = 0.3  # s
PUSH_BODY = "gripper"
SLIDE_DURATION = 1.0  # s
#: ``"rotate"`` while carried: the turn starts this long after ``t_grasp`` (s; module docstring).
TURN_DELAY = 1.0
#: ``"obstacle"``: the side of its cube (m), and its name in the scene and collision reports.
OBSTACLE_SIZE = 0.05
OBSTACLE_NAME = "obstacle"


class Disturbance:
    """What acts on a run besides the controller. Subclasses override :meth:`apply`."""

    name = "none"

    def apply(self, sim: Simulation, t: float) -> None:
        """Act on ``sim`` before the physics step at run time ``t`` (s)."""

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready description (``"perturb"`` of a trial)."""
        return {"name": self.name}

    def force_window(self) -> tuple[float, float] | None:
        """Run times (s) during which an external force drives the arm, plus 0.1 s for it to
        stop (None: never). A joint speed measured there is the push's, not the
        controller's."""
        return None


class NoDisturbance(Disturbance):
    """Nothing happens (``--perturb none``)."""


@dataclass
class SlideObject(Disturbance):
    """An object slides by ``displacement`` at constant speed during ``[start, start + duration)``.

    Attributes
    ----------
    obj : str
        The object (the glass, or a mocap object: :meth:`Simulation.place_object`).
    displacement : ndarray, shape (3,)
        Metres, horizontal (z = 0).
    start, duration : float
        Seconds of run time.
    """

    obj: str
    displacement: Float
    start: float
    duration: float = SLIDE_DURATION
    grasp_s: float | None = None
    name: str = field(default="move", init=False)
    _origin: Float | None = field(default=None, init=False, repr=False)
    _done: bool = field(default=False, init=False, repr=False)

    def apply(self, sim: Simulation, t: float) -> None:
        if t < self.start or self._done:
            return
        if self._origin is None:
            self._origin = sim.object_positions()[self.obj]
        if t >= self.start + self.duration + 1e-12:
            # the end: put it at its final place once, at rest
            sim.place_object(self.obj, self._origin + self.displacement)
            self._done = True
            return
        frac = (t - self.start) / self.duration
        velocity = self.displacement / self.duration
        sim.place_object(self.obj, self._origin + frac * self.displacement, velocity)

    def as_dict(self) -> dict[str, Any]:
        end = self._origin + self.displacement if self._origin is not None else None
        return {
            "name": self.name,
            "object": self.obj,
            "displacement_m": [float(v) for v in self.displacement],
            "start_s": float(self.start),
            "duration_s": float(self.duration),
            "final_position": None if end is None else [float(v) for v in end],
            "grasp_s": self.grasp_s,
        }

    def __post_init__(self) -> None:
        self.displacement = np.asarray(self.displacement, dtype=np.float64)


class _Placed(NamedTuple):
    """Where a turned object stood when its turn began: its point (3,) and yaw (rad)."""

    point: Float
    yaw: float


@dataclass
class TurnObject(Disturbance):
    """An object turns about the vertical through its reference point by ``angle`` at constant
    speed during ``[start, start + duration)``; its reference point stays where it is.

    Attributes
    ----------
    obj : str
        The object (a mocap object: :meth:`Simulation.place_object` with ``yaw``).
    angle : float
        The turn (rad, counter-clockwise seen from above).
    start, duration : float
        Seconds of run time.
    """

    obj: str
    angle: float
    start: float
    duration: float = SLIDE_DURATION
    grasp_s: float | None = None
    name: str = field(default="rotate", init=False)
    _origin: _Placed | None = field(default=None, init=False, repr=False)
    _done: bool = field(default=False, init=False, repr=False)

    def apply(self, sim: Simulation, t: float) -> None:
        if t < self.start or self._done:
            return
        if self._origin is None:
            pose = sim.object_poses()[self.obj]
            self._origin = _Placed(pose[:3, 3].copy(), yaw_of(pose))
        point, yaw0 = self._origin
        if t >= self.start + self.duration + 1e-12:
            sim.place_object(self.obj, point, yaw=yaw0 + self.angle)  # the end, once
            self._done = True
            return
        frac = (t - self.start) / self.duration
        sim.place_object(self.obj, point, yaw=yaw0 + frac * self.angle)

    def as_dict(self) -> dict[str, Any]:
        origin = self._origin
        return {
            "name": self.name,
            "object": self.obj,
            "angle_deg": math.degrees(self.angle),
            "start_s": float(self.start),
            "duration_s": float(self.duration),
            "initial_yaw_deg": None if origin is None else math.degrees(origin.yaw),
            "final_yaw_deg": None if origin is None else math.degrees(origin.yaw + self.angle),
            "grasp_s": self.grasp_s,
        }

    def __post_init__(self) -> None:
        self.angle = float(self.angle)
        if not math.isfinite(self.angle):
            raise ValueError(f"angle must be finite (rad), got {short(self.angle)}")


@dataclass
class PushArm(Disturbance):
    """A constant external force on an arm body during ``[start, start + duration)``.

    Attributes
    ----------
    force : ndarray, shape (3,)
        Newtons, base frame, applied at the body's centre of mass.
    start, duration : float
        Seconds of run time.
    body : str
        A body of the simulated arm (default the forearm).
    """

    force: Float
    start: float
    duration: float = PUSH_DURATION
    body: str = PUSH_BODY
    grasp_s: float | None = None
    name: str = field(default="push", init=False)

    def __post_init__(self) -> None:
        self.force = np.asarray(self.force, dtype=np.float64)

    def apply(self, sim: Simulation, t: float) -> None:
        bid = sim.model.body(self.body).id
        active = self.start <= t < self.start + self.duration
        sim.data.xfrc_applied[bid, :3] = self.force if active else 0.0

    def force_window(self) -> tuple[float, float]:
        return (self.start, self.start + self.duration + 0.1)

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "body": self.body,
            "force_n": [float(v) for v in self.force],
            "start_s": float(self.start),
            "duration_s": float(self.duration),
            "grasp_s": self.grasp_s,
        }


def grasp_time(times: Float, gripper: Float | None) -> float:
    """Time (s) of the first step whose gripper command closes (> 0.5).

    Raises
    ------
    ValueError
        If the skill never closes its gripper (no grasp to time a disturbance from).
    """
    if gripper is None or not np.any(np.asarray(gripper) > 0.5):
        raise ValueError("the skill never closes its gripper: there is no grasp to time from")
    return float(times[int(np.argmax(np.asarray(gripper) > 0.5))])


def _slide_direction(
    spec: TaskSpec, obj: str, start: Float, distance: float, rng: np.random.Generator
) -> Float:
    r = spec.ranges[obj]
    for _ in range(1000):
        a = rng.uniform(0.0, 2.0 * math.pi)
        d = distance * np.array([math.cos(a), math.sin(a), 0.0])
        end = start + d
        if np.all(end[:2] >= r.low[:2] - 1e-9) and np.all(end[:2] <= r.high[:2] + 1e-9):
            return d
    raise ValueError(
        f"no slide of {distance} m keeps {short(obj)} inside its placement range from "
        f"{start.tolist()}"
    )


@dataclass(frozen=True, kw_only=True)
class DisturbanceSetup:
    """What a perturbation's factory knows of the trial it disturbs.

    Attributes
    ----------
    task : TaskSpec
        The task (its ``move``, ranges and ``grasped`` object).
    objects : dict str -> ndarray, shape (3,) or (4, 4)
        The trial's true object placements at the start, every object of the task (poses for
        the objects placed as poses, :attr:`pbdkit.sim.PlacementRange.yaw`).
    times : ndarray, shape (T,)
        The skill's time grid (s), :meth:`pbdkit.Skill.times`.
    gripper : ndarray, shape (T,), or None
        The skill's generalized gripper command.
    rng : numpy.random.Generator
        The trial's own stream for the disturbance's draws (the same for every controller).
    skill : pbdkit.Skill, optional
        The trial's skill (``"obstacle"`` reproduces it to find its path).
    """

    task: TaskSpec
    objects: Mapping[str, Float]
    times: Float
    gripper: Float | None
    rng: np.random.Generator
    skill: Any = None

    def grasp_time(self) -> float:
        """``t_grasp``: :func:`grasp_time` of the skill's command (ValueError if it never
        closes its gripper)."""
        return grasp_time(self.times, self.gripper)


@dataclass(frozen=True)
class Perturbation:
    """A named disturbance of the registry (``--perturb NAME``).

    Attributes
    ----------
    name : str
        Registry key.
    help : str
        What happens, in a few words (the command line's help lists it after the name).
    make : callable
        ``make(setup) -> Disturbance``: the disturbance of one trial (:class:`DisturbanceSetup`).
        It draws only from ``setup.rng``, so that a trial's disturbance depends on nothing but
        the trial.
    check : callable, optional
        ``check(task)`` raises ValueError for a task it cannot disturb (``move``: a task without
        :attr:`~pbdkit.sim.TaskSpec.move`); called before any work.
    """

    name: str
    help: str
    make: Callable[[DisturbanceSetup], Disturbance]
    check: Callable[[TaskSpec], None] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"name must be a non-empty string, got {short(self.name)}")
        if not isinstance(self.help, str) or not self.help.strip():
            raise ValueError(f"help of perturbation {short(self.name)} must be a non-empty string")
        for what in ("make", "check"):
            f = getattr(self, what)
            if f is not None and not callable(f):
                raise ValueError(f"{what} of perturbation {short(self.name)} must be callable")


_REGISTRY: Registry[Perturbation] = Registry(
    "perturbation", Perturbation, "perturbation", "perturb"
)

#: The registered perturbations, name -> :class:`Perturbation` (a read-only view of the registry,
#: in registration order): the names ``--perturb`` accepts.
PERTURBATIONS: Mapping[str, Perturbation] = _REGISTRY.view


def register_perturbation(perturbation: Perturbation) -> Perturbation:
    """Make ``perturbation`` known by its name (``--perturb``, :func:`make_disturbance`);
    returns it.

    Raises
    ------
    ValueError
        If it is not a Perturbation, or another one has the same name.
    """
    return _REGISTRY.register(perturbation)


def unregister_perturbation(name: str) -> Perturbation:
    """Forget the perturbation ``name`` and return it; ValueError if it is not registered."""
    return _REGISTRY.unregister(name)


def perturbation_names() -> tuple[str, ...]:
    """Names of the registered perturbations, in registration order (``"none"`` first)."""
    return _REGISTRY.names()


def get_perturbation(name: str) -> Perturbation:
    """The registered perturbation ``name``.

    Raises
    ------
    ValueError
        If no perturbation of that name is registered (the message lists them).
    """
    return _REGISTRY.get(name)


def perturbation_help() -> str:
    """The registered perturbations in words, for a command's help: ``"none (nothing
    happens), move (...) or push (...)"``."""
    items = [f"{p.name} ({p.help})" for p in PERTURBATIONS.values()]
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} or {items[-1]}"


def check_perturb(name: str, spec: TaskSpec | None = None) -> None:
    """Refuse a name that is not registered, or a perturbation that cannot disturb the task
    ``spec`` (e.g. ``"move"`` for a task without :attr:`TaskSpec.move`).

    Raises
    ------
    ValueError
    """
    found = get_perturbation(name)
    if spec is not None and found.check is not None:
        found.check(spec)


def make_disturbance(name: str, setup: DisturbanceSetup) -> Disturbance:
    """The disturbance ``name`` (a registered :class:`Perturbation`) for one trial.

    Parameters
    ----------
    name : str
        A name of :func:`perturbation_names` (module docstring).
    setup : DisturbanceSetup
        The trial: its task, true object positions, the skill's time grid and gripper command,
        and the stream to draw from.

    Raises
    ------
    ValueError
        An unknown name, or a task the perturbation cannot disturb (``"move"`` for a task
        without :attr:`TaskSpec.move`).
    """
    check_perturb(name, setup.task)
    return get_perturbation(name).make(setup)


def _nothing(setup: DisturbanceSetup) -> Disturbance:
    return NoDisturbance()


def _has_move(spec: TaskSpec) -> None:
    if spec.move is None:
        raise ValueError(f"task {short(spec.name)} has no 'move' disturbance (TaskSpec.move)")


def _slide(setup: DisturbanceSetup) -> Disturbance:
    """The task's :class:`~pbdkit.sim.ObjectMove` (module docstring)."""
    t_grasp = setup.grasp_time()
    spec = setup.task
    move = spec.move
    assert move is not None  # _has_move
    d = _slide_direction(spec, move.obj, setup.objects[move.obj], move.distance, setup.rng)
    if move.when == "while_carried":
        start = t_grasp + 0.5
    else:
        start = max(0.0, t_grasp - 1.5 - SLIDE_DURATION)
    return SlideObject(move.obj, d, start, grasp_s=t_grasp)


def _has_rotate(spec: TaskSpec) -> None:
    if spec.rotate is None:
        raise ValueError(f"task {short(spec.name)} has no 'rotate' disturbance (TaskSpec.rotate)")


def _turn_angle(
    spec: TaskSpec, obj: str, yaw: float, size: float, rng: np.random.Generator
) -> float:
    """A turn of ``size`` (rad) whose end keeps the yaw of ``obj`` (now ``yaw``) inside its
    yaw range: either direction when both do, at random."""
    r = spec.ranges[obj].yaw
    assert r is not None  # TaskSpec checks it
    signs = [s for s in (1.0, -1.0) if r[0] - 1e-9 <= yaw + s * size <= r[1] + 1e-9]
    if not signs:
        raise ValueError(
            f"no turn of {math.degrees(size):g} degrees keeps {short(obj)} inside its yaw range "
            "from "
            f"{math.degrees(yaw):g} degrees"
        )
    sign = signs[0] if len(signs) == 1 else (1.0 if rng.uniform() < 0.5 else -1.0)
    return sign * size


def _turn(setup: DisturbanceSetup) -> Disturbance:
    """The task's :class:`~pbdkit.sim.ObjectTurn` (module docstring)."""
    t_grasp = setup.grasp_time()
    spec = setup.task
    turn = spec.rotate
    assert turn is not None  # _has_rotate
    size = math.radians(float(setup.rng.uniform(*turn.degrees)))
    placed = np.asarray(setup.objects[turn.obj], dtype=np.float64)
    if placed.shape != (4, 4):
        raise ValueError(
            f"{short(turn.obj)} must be placed as a pose (4, 4) to turn, got {placed.shape}"
        )
    angle = _turn_angle(spec, turn.obj, yaw_of(placed), size, setup.rng)
    if turn.when == "while_carried":
        start = t_grasp + TURN_DELAY
    else:
        start = max(0.0, t_grasp - 1.5 - SLIDE_DURATION)
    return TurnObject(turn.obj, angle, start, grasp_s=t_grasp)


def _push(setup: DisturbanceSetup) -> Disturbance:
    """A shove across the vertical plane through the base axis and the grasped object (the
    hand passes near it at the push's time), halfway to the grasp (module docstring)."""
    t_grasp = setup.grasp_time()
    arm_plane = setup.objects[setup.task.grasped]
    radial = np.array([arm_plane[0], arm_plane[1], 0.0])
    radial /= max(float(np.linalg.norm(radial)), 1e-9)
    across = np.array([-radial[1], radial[0], 0.0])
    sign = 1.0 if setup.rng.uniform() < 0.5 else -1.0
    return PushArm(sign * PUSH_FORCE * across, 0.5 * t_grasp, grasp_s=t_grasp)


register_perturbation(Perturbation("none", "nothing happens", _nothing))
register_perturbation(
    Perturbation(
        "move",
        "an object slides, the task's TaskSpec.move: the coaster 5 cm while the glass is "
        "carried; basin task: the glass 4 cm before the grasp",
        _slide,
        check=_has_move,
    )
)
register_perturbation(
    Perturbation("push", f"a {PUSH_DURATION:g} s shove on the arm halfway to the grasp", _push)
)
register_perturbation(
    Perturbation(
        "rotate",
        "an object turns about its centre, the task's TaskSpec.rotate: slot task: the tray "
        "20-30 degrees while the block is carried",
        _turn,
        check=_has_rotate,
    )
)


def _has_scene(spec: TaskSpec) -> None:
    if spec.scene is None:
        raise ValueError(
            f"task {short(spec.name)} declares no scene (TaskSpec.scene): --perturb obstacle "
            "needs one to check against"
        )


@dataclass
class PlaceObstacle(Disturbance):
    """A static box in the way (``--perturb obstacle``): it acts by being there, not over
    time (:meth:`apply` does nothing)."""

    box: Box
    step: int
    name = "obstacle"

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "centre": [float(v) for v in self.box.pose[:3, 3]],
            "size": [float(v) for v in self.box.size],
            "step": self.step,
        }


def place_obstacle(setup: DisturbanceSetup) -> PlaceObstacle:
    """The box at the fused path's mid-carry step (module docstring, ``"obstacle"``;
    :mod:`pbdkit.sim._obstacle`)."""
    skill = setup.skill
    if skill is None:
        raise ValueError("--perturb obstacle needs the trial's skill (DisturbanceSetup.skill)")
    told = {k: setup.objects[k] for k in skill.object_names}
    res = skill.reproduce(told, on_unreachable="warn")
    own = np.ones(len(res.t), dtype=bool) if res.lead_in is None else ~res.lead_in
    closed = np.flatnonzero(res.gripper & own)
    if not closed.size:
        raise ValueError("--perturb obstacle needs a skill that closes its gripper (a carry)")
    first = int(closed[0])
    gaps = np.flatnonzero(np.diff(closed) > 1)
    last = int(closed[gaps[0]]) if gaps.size else int(closed[-1])
    step = (first + last) // 2
    box = Box([OBSTACLE_SIZE] * 3, res.positions[step], name=OBSTACLE_NAME)
    return PlaceObstacle(box=box, step=step)


register_perturbation(
    Perturbation(
        "obstacle",
        f"a {OBSTACLE_SIZE * 100:g} cm box on the fused path at mid-carry, put there after the "
        "demonstrations (pbdkit.sim._obstacle)",
        place_obstacle,
        check=_has_scene,
    )
)
