"""Disturbances of a run (``pbdkit evaluate --perturb NAME``): objects that move, a pushed arm.

A :class:`Disturbance` acts on the simulation before every physics step of a run, at the run's
time t (seconds from the start of the trajectory, the first command). Both ways of running a
skill take one: the offline playback (:func:`pbdkit.sim.execute.execute`) and the online loop
(:func:`pbdkit.sim.online.execute_online`), so the two meet the same disturbance.

The named disturbances (:func:`make_disturbance`) are timed from the skill itself: ``t_grasp``
is the time of the first step where the skill's generalized gripper command closes.

- ``"none"``: nothing happens.
- ``"move"``: the task's :class:`pbdkit.sim.tasks.ObjectMove`. Coaster task: the coaster slides
  5 cm while the glass is carried, over 1 s from ``t_grasp + 0.5 s``. Basin task: the glass slides
  4 cm on the table before the grasp, over 1 s ending 1.5 s before ``t_grasp`` (the hand is
  then still on its way, behind and above the glass). The direction is drawn at random among
  those whose end point stays inside the object's placement range (the demonstrated range).
- ``"push"``: a horizontal force of 40 N on the gripper for 0.3 s, starting halfway to the
  grasp (``t_grasp / 2``), across the arm (perpendicular to the vertical plane through the
  base axis and the glass), with a random sign. It exceeds what the pan drive can hold (its
  URDF effort, 10 N m): the simulated servos give way and the hand is shoved 10-30 cm off its
  path (measured on the coaster task: 5-8 mm at 15-30 N, 12 cm at 34 N, 28 cm at 40 N).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .scene import Simulation
from .tasks import TaskSpec

__all__ = [
    "PERTURBATIONS",
    "Disturbance",
    "NoDisturbance",
    "PushArm",
    "SlideObject",
    "check_perturb",
    "grasp_time",
    "make_disturbance",
]

Float = NDArray[np.float64]

#: The names ``--perturb`` accepts.
PERTURBATIONS = ("none", "move", "push")

PUSH_FORCE = 40.0  # N
PUSH_DURATION = 0.3  # s
PUSH_BODY = "gripper"
SLIDE_DURATION = 1.0  # s


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


def check_perturb(name: str, spec: TaskSpec | None = None) -> None:
    """Refuse a name that is not one of :data:`PERTURBATIONS`, or ``"move"`` for a task
    (``spec``) without :attr:`TaskSpec.move`.

    Raises
    ------
    ValueError
    """
    if name not in PERTURBATIONS:
        raise ValueError(f"perturb must be one of {list(PERTURBATIONS)}, got {name!r}")
    if name == "move" and spec is not None and spec.move is None:
        raise ValueError(f"task {spec.name!r} has no 'move' disturbance (TaskSpec.move)")


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
        f"no slide of {distance} m keeps {obj!r} inside its placement range from {start.tolist()}"
    )


def make_disturbance(
    name: str,
    spec: TaskSpec,
    objects: dict[str, Float],
    times: Float,
    gripper: Float | None,
    arm_plane: Float,
    rng: np.random.Generator,
) -> Disturbance:
    """The disturbance ``name`` (one of :data:`PERTURBATIONS`) for one trial.

    Parameters
    ----------
    name : str
        "none", "move" or "push" (module docstring).
    spec : TaskSpec
        The task (its ``move`` and ranges).
    objects : dict str -> ndarray, shape (3,)
        The trial's true object positions at the start.
    times : ndarray, shape (T,)
        The skill's time grid (s), :meth:`pbdkit.Skill.times`.
    gripper : ndarray, shape (T,), or None
        The skill's generalized gripper command.
    arm_plane : ndarray, shape (3,)
        A point the hand passes near the push time (the push is across the vertical plane
        through the base axis and it).
    rng : numpy.random.Generator
        Draws the direction (move) or the sign (push).

    Raises
    ------
    ValueError
        An unknown name, or ``"move"`` for a task without :attr:`TaskSpec.move`.
    """
    check_perturb(name, spec)
    if name == "none":
        return NoDisturbance()
    t_grasp = grasp_time(times, gripper)
    if name == "move":
        move = spec.move
        assert move is not None  # check_perturb
        d = _slide_direction(spec, move.obj, objects[move.obj], move.distance, rng)
        if move.when == "while_carried":
            start = t_grasp + 0.5
        else:
            start = max(0.0, t_grasp - 1.5 - SLIDE_DURATION)
        return SlideObject(move.obj, d, start, grasp_s=t_grasp)
    radial = np.array([arm_plane[0], arm_plane[1], 0.0])
    radial /= max(float(np.linalg.norm(radial)), 1e-9)
    across = np.array([-radial[1], radial[0], 0.0])
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    return PushArm(sign * PUSH_FORCE * across, 0.5 * t_grasp, grasp_s=t_grasp)
