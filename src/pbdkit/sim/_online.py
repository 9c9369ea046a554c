"""A skill run online in the simulated world: the controller in the physics loop.

:func:`execute_online` runs a :class:`pbdkit.Controller` the way a real arm would: at the
skill's step rate (one command per :attr:`pbdkit.Controller.dt`) it reads the measured joint
angles, calls :meth:`~pbdkit.Controller.step`, and the servos follow the piecewise-linear
reference through the commands (the segment's slope as velocity feed-forward, as in the offline
playback of :func:`pbdkit.sim.execute`). A command that re-targets from the
measured posture (:attr:`pbdkit.Command.held`: the arm was pushed or held back) restarts the
reference at the arm, so the servos do not snap the arm back to where it was. Between
commands the physics runs at 500 Hz; a :class:`pbdkit.sim.Disturbance` acts before
every physics step.

Object positions reach the controller from an :class:`Observer`, at 15 Hz (the paper's cameras):

- :class:`VisionObserver`: the stereo tracker on the simulator's renders, through a
  :class:`pbdkit.vision.TrackFilter` that holds the last good estimate while the arm hides a
  patch, refuses implausible jumps and says which;
- :class:`TruthObserver`: the simulator's true positions (``--ground-truth``).

An object placed as a pose (the slot task's block and tray) is observed as its pose (4, 4): the
tracker's from its two end patches (:mod:`pbdkit.sim._tracking`), filtered as a whole (either end
hidden: the last good pose holds), or the true one; the controller takes poses as it takes
positions (:meth:`pbdkit.Controller.step`).

Both follow one rule for the grasped object (the task's
:attr:`~pbdkit.sim.TaskSpec.grasped`, the glass): from the first command that closes the
gripper on, its position stays where it was grasped. The skill's constraint relative to it is
relative to its place before it is moved (as in the demonstrations); a controller told the
carried object's position would chase its own hand.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import short
from ..reproduction._controller import Command, Controller
from ..vision import TrackFilter
from ._execute import ExecutionResult, Recorder, start_at
from ._metrics import yaw_errors
from ._perturb import Disturbance, NoDisturbance
from ._scene import Simulation
from ._tracking import SimTracker
from ._world import TIMESTEP

__all__ = [
    "OBSERVE_RATE",
    "Observer",
    "OnlineRun",
    "TruthObserver",
    "VisionObserver",
    "execute_online",
]

Float = NDArray[np.float64]

#: Rate of the object observations (Hz): the paper's cameras ran at 15 Hz.
OBSERVE_RATE = 15.0


class Observer:
    """Object positions for a running controller (base class: the grasped-object rule).

    Parameters
    ----------
    names : sequence of str
        The skill's objects to keep up to date (others, e.g. the fixed basin, are not observed).
    rate : float
        Observations per second.
    """

    def __init__(self, names: Sequence[str], rate: float = OBSERVE_RATE) -> None:
        if not (rate > 0 and math.isfinite(rate)):
            raise ValueError(f"rate must be a positive number of Hz, got {short(rate)}")
        self.names = tuple(names)
        self.rate = float(rate)
        self.grasped = False

    def __call__(self, sim: Simulation, t: float, gripper_closed: bool) -> dict[str, Float]:
        """New positions (a subset of ``names``) observed on ``sim`` at run time ``t``."""
        self.grasped = self.grasped or gripper_closed
        sim.refresh()
        held = (sim.info.spec.grasped,) if self.grasped else ()
        return self.observe(sim, t, held)

    def observe(self, sim: Simulation, t: float, held: tuple[str, ...]) -> dict[str, Float]:
        raise NotImplementedError

    def as_dict(self) -> dict[str, Any] | None:
        """JSON-ready account of the observations (None: nothing to report)."""
        return None


class TruthObserver(Observer):
    """The simulator's true positions (no vision); a posed object's true pose
    (:meth:`Simulation.object_placements`)."""

    def observe(self, sim: Simulation, t: float, held: tuple[str, ...]) -> dict[str, Float]:
        truth = sim.object_placements()
        return {k: truth[k] for k in self.names if k not in held}


class VisionObserver(Observer):
    """The stereo tracker's positions, filtered (:class:`pbdkit.vision.TrackFilter`).

    Parameters
    ----------
    tracker : SimTracker
        Calibrated on the task.
    names : sequence of str
        The skill's objects; those the tracker follows are observed.
    rate : float
    **filter_options
        Passed to :class:`pbdkit.vision.TrackFilter`.
    """

    def __init__(
        self,
        tracker: SimTracker,
        names: Sequence[str],
        rate: float = OBSERVE_RATE,
        **filter_options: Any,
    ) -> None:
        tracked = [k for k in names if k in tracker.objects]
        super().__init__(tracked, rate)
        self.tracker = tracker
        centres = (tracker.tracker.cam_a.center, tracker.tracker.cam_b.center)
        options = {"cameras": centres, **filter_options}
        self.filter = TrackFilter(tracker.objects, **options)
        self.errors_mm: dict[str, list[float]] = {k: [] for k in tracker.objects}
        self.errors_deg: dict[str, list[float]] = {}

    def observe(self, sim: Simulation, t: float, held: tuple[str, ...]) -> dict[str, Float]:
        tracks = self.tracker.locate(sim)
        accepted = self.filter.update(t, tracks, held=held)
        if any(p.shape == (4, 4) for p in accepted.values()):
            poses = sim.object_poses()
            for k, p in accepted.items():
                if p.shape == (4, 4):
                    err = float(np.linalg.norm(p[:3, 3] - poses[k][:3, 3]))
                    self.errors_mm[k].append(1e3 * err)
                    self.errors_deg.setdefault(k, []).append(yaw_errors({k: p}, poses, [k])[k])
                else:
                    self.errors_mm[k].append(1e3 * float(np.linalg.norm(p - poses[k][:3, 3])))
        else:
            truth = sim.object_positions()
            for k, p in accepted.items():
                self.errors_mm[k].append(1e3 * float(np.linalg.norm(p - truth[k])))
        return {k: v for k, v in accepted.items() if k in self.names}

    def as_dict(self) -> dict[str, Any]:
        """Frames per status and status changes (:meth:`TrackFilter.as_dict`), and the error
        of the accepted estimates against the truth (mm): mean and max per object; for posed
        objects also their yaw error (degrees, ``"accepted_error_deg"``)."""
        out = self.filter.as_dict()
        out["accepted_error_mm"] = {
            k: {"mean": float(np.mean(v)), "max": float(np.max(v)), "n": len(v)}
            for k, v in self.errors_mm.items()
            if v
        }
        if self.errors_deg:
            out["accepted_error_deg"] = {
                k: {"mean": float(np.mean(v)), "max": float(np.max(v)), "n": len(v)}
                for k, v in self.errors_deg.items()
                if v
            }
        return out


@dataclass(frozen=True)
class OnlineRun:
    """An online run: the physics record and what the controller did at each command.

    Attributes
    ----------
    execution : ExecutionResult
        As for the offline playback (``targets`` is the servo reference).
    tick_times : ndarray, shape (K,)
        Run time (s) of each command.
    index : ndarray of int, shape (K,)
        The step each command targeted (the phase: it holds while the arm is held back).
    commands : ndarray, shape (K, n)
        The commanded joint angles.
    limited : ndarray of bool, shape (K,)
        Commands shortened by a velocity bound (with motion limits: slowed by the limits).
    held : ndarray of bool, shape (K,)
        Commands that restarted from the measured posture, the arm held back
        (:attr:`pbdkit.reproduction.Command.held`).
    replans : int
        How many times the controller planned again (moved objects, pushes; 0 without motion
        limits).
    objects : dict str -> ndarray, shape (K, 3) or (K, 4, 4)
        The positions the controller used at each command (a posed object's poses).
    tracking : dict or None
        The observer's summary (vision: frames per status, status changes, errors).
    disturbance : dict
        :meth:`Disturbance.as_dict`.
    dt : float
        Seconds per step of the skill (the controller's ``dt``): command k is sent at k dt.
    """

    execution: ExecutionResult
    tick_times: Float
    index: NDArray[np.int_]
    commands: Float
    limited: NDArray[np.bool_]
    held: NDArray[np.bool_]
    replans: int
    objects: dict[str, Float]
    tracking: dict[str, Any] | None
    disturbance: dict[str, Any]
    dt: float

    @property
    def held_steps(self) -> int:
        """Commands given while the arm was held back (the phase held)."""
        return int(np.count_nonzero(self.held))


def execute_online(
    sim: Simulation,
    controller: Controller,
    *,
    observer: Observer | None = None,
    disturbance: Disturbance | None = None,
    settle: float = 1.0,
    record_rate: float = 50.0,
    camera: str | None = None,
    fps: float = 15.0,
) -> OnlineRun:
    """Run ``controller`` in the physics loop of ``sim`` until its last step, then judge.

    The arm is first put at the controller's start posture and the world settles for 0.3 s
    (as :func:`pbdkit.sim.execute`). Then, at run time t = k dt (k = 0, 1, ...), the
    controller gets the measured joint angles and the positions observed since its last
    command, and its command is the servo reference at t + dt. After the last step the last
    target is held for ``settle`` seconds before the task's judge looks.

    Parameters
    ----------
    sim : Simulation
        A fresh simulation of the task.
    controller : Controller
        From :meth:`pbdkit.Skill.controller`, not yet stepped; its ``dt`` must be known.
    observer : Observer, optional
        Object positions at its rate (default: none, the controller keeps its start positions).
    disturbance : Disturbance, optional
        Acts before every physics step (:mod:`pbdkit.sim._perturb`).
    settle, record_rate, camera, fps
        As :func:`pbdkit.sim.execute`.

    Returns
    -------
    OnlineRun
    """
    dt = float(controller.dt)
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"the controller's dt must be known (> 0 s), got {short(controller.dt)}")
    if controller.index != 0:
        raise ValueError("the controller has already run: make a new one for each run")
    if settle < 0:
        raise ValueError(f"settle must be >= 0, got {settle}")
    recorder = Recorder(sim, record_rate, camera, fps)
    act = NoDisturbance() if disturbance is None else disturbance
    q_prev = controller.target
    grip = controller.gripper
    start_at(sim, q_prev, grip)
    # With motion limits the servos follow the controller's jerk-limited setpoint stream at the
    # physics rate; without, the piecewise-linear reference through the commands. The plans
    # inline: the simulation runs in its own time, and a run depends only on its inputs.
    stream = (
        controller.stream(1.0 / TIMESTEP, planner="inline")
        if controller.limits is not None
        else None
    )

    names = list(controller.objects)
    ticks: list[float] = []
    index: list[int] = []
    commands: list[Float] = []
    limited: list[bool] = []
    held: list[bool] = []
    used: dict[str, list[Float]] = {k: [] for k in names}
    pending: dict[str, Float] = {}
    q_next = q_prev.copy()
    ref = q_prev.copy()
    seg_start = 0.0
    next_tick = 0
    next_obs = 0.0
    t_end = math.inf
    ended = False
    last_cmd: Command | None = None
    k = 0
    while True:
        t = k * TIMESTEP
        if observer is not None and t >= next_obs - 1e-9:
            pending.update(observer(sim, t, grip))
            next_obs += 1.0 / observer.rate
        cmd: Command | None = None
        if stream is not None:
            # Setpoint m of the stream is for time (m + 1) / rate: the first physics step holds
            # the start posture, so that the servo targets are the stream's motion sampled at
            # the physics steps, from where it started at rest.
            if k == 0:
                vel = np.zeros_like(ref)
            elif t_end == math.inf:
                ref = stream.step(sim.joints(), pending or None)
                pending = {}
                vel = stream.velocity
                if stream.command is not last_cmd:
                    cmd = last_cmd = stream.command
                if stream.done:
                    t_end = t
            else:
                vel = np.zeros_like(ref)
        else:
            if t_end == math.inf and t >= next_tick * dt - 1e-9:
                cmd = controller.step(sim.joints(), pending or None)
                pending = {}
                # The reference runs through the commands; a command that re-targets from the
                # measured posture (the arm was held back: cmd.held) restarts it there.
                q_prev, q_next = (sim.joints() if cmd.held else q_next), cmd.q
                seg_start = next_tick * dt
                next_tick += 1
                if controller.done:
                    t_end = seg_start + dt
            frac = min(1.0, max(0.0, (t - seg_start) / dt))
            ref = q_prev + frac * (q_next - q_prev)
            vel = (q_next - q_prev) / dt if frac < 1.0 else np.zeros_like(ref)
        if cmd is not None:
            grip = cmd.gripper
            ticks.append(t)
            index.append(cmd.index)
            commands.append(cmd.q)
            limited.append(cmd.limited)
            held.append(cmd.held)
            for name, p in controller.objects.items():
                used[name].append(p)
        sim.set_targets(ref, vel)
        sim.set_gripper(grip)
        recorder.record(k, t, ref, grip)
        if not ended and t >= t_end - 0.5 * TIMESTEP:
            recorder.end_of_trajectory()
            ended = True
        if t >= t_end + settle - 1e-9:
            break
        act.apply(sim, t)
        sim.step()
        k += 1
    return OnlineRun(
        execution=recorder.result(),
        tick_times=np.array(ticks, dtype=np.float64),
        index=np.array(index, dtype=np.int_),
        commands=np.array(commands, dtype=np.float64),
        limited=np.array(limited, dtype=bool),
        held=np.array(held, dtype=bool),
        replans=controller.replans,
        objects={k_: np.array(v, dtype=np.float64) for k_, v in used.items()},
        tracking=None if observer is None else observer.as_dict(),
        disturbance=act.as_dict(),
        dt=dt,
    )
