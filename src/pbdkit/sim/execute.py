"""Play a joint trajectory on the simulated arm under physics, record the run and judge the outcome.

The arm follows interpolated servo targets at the physics rate (500 Hz): linear interpolation of the
joint samples for the position target and the segment's slope as velocity feed-forward. The gripper
closes (a force-limited squeeze) while the gripper signal is above 0.5 and opens otherwise. Objects
move only through contacts: a grasp holds by friction or not at all.

Success is the task's: its :attr:`pbdkit.sim.tasks.TaskSpec.judge` reads the state after the run
(and a settling time) and what was measured during it (:class:`RunStats`); each task's module
states its criteria (:mod:`pbdkit.sim.taskdefs.coaster`, :mod:`pbdkit.sim.taskdefs.basin`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .perturb import Disturbance, NoDisturbance
from .scene import TIMESTEP, Simulation

Float = NDArray[np.float64]


@dataclass(frozen=True)
class Outcome:
    """Success of a run and its measurements.

    Attributes
    ----------
    success : bool
    metrics : dict str -> float
        The task's measurements, named with their unit (e.g. ``placement_error_mm``,
        ``tilt_deg``); see the task's judge.
    """

    success: bool
    metrics: dict[str, float]


@dataclass(frozen=True)
class RunStats:
    """What a judge may need beyond the final state: measured while the trajectory played.

    Attributes
    ----------
    held_at_end : bool
        Both fingers touched the glass at the end of the trajectory (before the settling time).
    max_tilt : float
        Largest tilt of the glass's axis from the vertical during the run (rad).
    """

    held_at_end: bool
    max_tilt: float


@dataclass(frozen=True)
class ExecutionResult:
    """A recorded run.

    Attributes
    ----------
    t : ndarray, shape (S,)
        Record times (s), from the trajectory's first time stamp.
    joints : ndarray, shape (S, n)
        Measured joint angles.
    targets : ndarray, shape (S, n)
        Servo targets at the same times.
    tool : ndarray, shape (S, 3)
        Tool point (base frame).
    objects : dict str -> ndarray, shape (S, 3)
        Object positions (ground truth) over time.
    glass_tilt : ndarray, shape (S,)
        Angle of the glass's axis from the vertical (rad).
    grasped : ndarray of bool, shape (S,)
        Both fingers touch the glass.
    gripper : ndarray of bool, shape (S,)
        Gripper command.
    liquid : ndarray, shape (n_liquid, 3)
        Final positions of the liquid spheres (empty for the coaster task).
    frames : ndarray of uint8, shape (F, 240, 320, 3), or None
        Camera frames, if a camera was given.
    frame_times : ndarray, shape (F,)
    outcome : Outcome
    """

    t: Float
    joints: Float
    targets: Float
    tool: Float
    objects: dict[str, Float]
    glass_tilt: Float
    grasped: NDArray[np.bool_]
    gripper: NDArray[np.bool_]
    liquid: Float
    frames: NDArray[np.uint8] | None
    frame_times: Float
    outcome: Outcome


def _check_trajectory(
    t: npt.ArrayLike, joints: npt.ArrayLike, gripper: npt.ArrayLike | None, n: int
) -> tuple[Float, Float, NDArray[np.bool_]]:
    t_ = np.asarray(t, dtype=np.float64)
    q_ = np.asarray(joints, dtype=np.float64)
    if t_.ndim != 1 or t_.shape[0] < 2:
        raise ValueError(f"t must have shape (T,) with T >= 2, got {t_.shape}")
    if q_.shape != (t_.shape[0], n):
        raise ValueError(f"joints must have shape ({t_.shape[0]}, {n}), got {q_.shape}")
    if not (np.all(np.isfinite(t_)) and np.all(np.isfinite(q_))):
        raise ValueError("t and joints must be finite (no NaN or inf)")
    if np.any(np.diff(t_) <= 0):
        raise ValueError("t must be strictly increasing")
    if gripper is None:
        g = np.zeros(t_.shape[0], dtype=bool)
    else:
        g_arr = np.asarray(gripper, dtype=np.float64)
        if g_arr.shape != t_.shape or not np.all(np.isfinite(g_arr)):
            raise ValueError(
                f"gripper must be a finite array of shape {t_.shape}, got {g_arr.shape}"
            )
        g = g_arr > 0.5
    return t_, q_, g


def execute(
    sim: Simulation,
    t: npt.ArrayLike,
    joints: npt.ArrayLike,
    gripper: npt.ArrayLike | None = None,
    *,
    settle: float = 1.0,
    record_rate: float = 50.0,
    camera: str | None = None,
    fps: float = 15.0,
    duration: float | None = None,
    disturbance: Disturbance | None = None,
) -> ExecutionResult:
    """Play a joint trajectory under physics and judge the task's outcome.

    The arm is first put at ``joints[0]`` (no physics) and the world settles for 0.3 s; then the
    trajectory plays; then the last targets are held for ``settle`` seconds before the outcome is
    measured (a released glass must come to rest, the liquid must land).

    Parameters
    ----------
    sim : Simulation
        A fresh simulation of the task (from :meth:`Simulation.from_task`).
    t : array-like, shape (T,)
        Time stamps (s), strictly increasing.
    joints : array-like, shape (T, n)
        Joint angles theta.
    gripper : array-like, shape (T,), optional
        Gripper signal, closed where > 0.5 (booleans accepted). None: always open.
    settle : float
        Time (s) to hold the last targets before measuring the outcome.
    record_rate : float
        Rate (Hz) of the recorded state.
    camera : str, optional
        Record frames of this camera at ``fps`` (e.g. for a video).
    fps : float
        Frame rate of the recorded frames.
    duration : float, optional
        If given, ``t`` is first mapped linearly onto [0, duration] seconds: a reproduction comes
        in time steps (e.g. 0 ... 999), to be played at the pace of the demonstrations (e.g.
        their mean duration).
    disturbance : Disturbance, optional
        Acts on the world before every physics step (:mod:`pbdkit.sim.perturb`), at the time
        from the trajectory's start.

    Returns
    -------
    ExecutionResult
    """
    n = sim.n_joints
    t_, q_, g = _check_trajectory(t, joints, gripper, n)
    if duration is not None:
        if not (math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be a positive number of seconds, got {duration}")
        t_ = (t_ - t_[0]) * (duration / (t_[-1] - t_[0]))
    if settle < 0 or record_rate <= 0 or fps <= 0:
        raise ValueError(
            f"settle must be >= 0 and record_rate, fps > 0, got {settle}, {record_rate}, {fps}"
        )
    recorder = Recorder(sim, record_rate, camera, fps)

    start_at(sim, q_[0], bool(g[0]))

    # Servo targets at every physics step: linear interpolation and the segment's slope.
    n_play = math.ceil((t_[-1] - t_[0]) / TIMESTEP)
    n_settle = round(settle / TIMESTEP)
    s = t_[0] + TIMESTEP * np.arange(n_play + n_settle + 1)
    seg = np.clip(np.searchsorted(t_, s, side="right") - 1, 0, t_.shape[0] - 2)
    slope = np.diff(q_, axis=0) / np.diff(t_)[:, None]
    q_target = np.empty((s.shape[0], n))
    for j in range(n):
        q_target[:, j] = np.interp(s, t_, q_[:, j])
    dq_target = slope[seg]
    dq_target[s >= t_[-1]] = 0.0
    g_target = g[np.clip(np.searchsorted(t_, s, side="right") - 1, 0, t_.shape[0] - 1)]

    act = NoDisturbance() if disturbance is None else disturbance
    servo = sim.servo_rows(q_target, dq_target)
    for k in range(s.shape[0]):
        sim.set_servo_row(servo[k])
        sim.set_gripper(bool(g_target[k]))
        recorder.record(k, s[k], q_target[k], bool(g_target[k]))
        if k == n_play:
            recorder.end_of_trajectory()
        if k < s.shape[0] - 1:
            act.apply(sim, s[k] - t_[0])
            sim.step()
    return recorder.result()


def start_at(sim: Simulation, q: Float, gripper: bool) -> None:
    """Put the arm at ``q`` with the gripper command, let the world settle for 0.3 s, and put the
    arm back at ``q`` (undoing the small sag of the settling phase): where every run starts."""
    sim.set_joints(q)
    sim.set_gripper(gripper)
    sim.step(round(0.3 / TIMESTEP))
    sim.set_joints(q)


class Recorder:
    """What a run records, at ``record_rate`` (and camera frames at ``fps``), and its judgement.

    Shared by the offline playback (:func:`execute`) and the online loop
    (:func:`pbdkit.sim.online.execute_online`): call :meth:`record` at every physics step,
    :meth:`end_of_trajectory` at the step where the last target is reached, and
    :meth:`result` after the settling time.
    """

    def __init__(self, sim: Simulation, record_rate: float, camera: str | None, fps: float) -> None:
        if record_rate <= 0 or fps <= 0:
            raise ValueError(f"record_rate and fps must be > 0, got {record_rate}, {fps}")
        if camera is not None:
            sim.camera_id(camera)
        self.sim = sim
        self.camera = camera
        self.rec_every = max(1, round(1.0 / (record_rate * TIMESTEP)))
        self.frame_every = max(1, round(1.0 / (fps * TIMESTEP)))
        self.rec: dict[str, list[object]] = {
            k: [] for k in ("t", "q", "target", "tool", "tilt", "grasped", "gripper")
        }
        self.objects: dict[str, list[Float]] = {k: [] for k in sim.info.objects}
        self.frames: list[NDArray[np.uint8]] = []
        self.frame_times: list[float] = []
        self.max_tilt = 0.0
        self.held_at_end = False

    def record(self, k: int, t: float, target: Float, gripper: bool) -> None:
        """At physics step ``k`` (run time ``t``), with the servo target and gripper command."""
        sim = self.sim
        if k % self.rec_every == 0:
            sim.refresh()
            rec = self.rec
            rec["t"].append(t)
            rec["q"].append(sim.joints())
            rec["target"].append(np.array(target, dtype=np.float64))
            rec["tool"].append(sim.tool_position())
            rec["tilt"].append(sim.glass_tilt())
            rec["grasped"].append(sim.glass_grasped())
            rec["gripper"].append(gripper)
            for name, p in sim.object_positions().items():
                self.objects[name].append(p)
        if self.camera is not None and k % self.frame_every == 0:
            self.frames.append(sim.render(self.camera))
            self.frame_times.append(t)
        self.max_tilt = max(self.max_tilt, sim.glass_tilt())

    def end_of_trajectory(self) -> None:
        """The last target is reached now: note whether the glass is held."""
        self.held_at_end = self.sim.glass_grasped()

    def result(self) -> ExecutionResult:
        """The record and the task's judgement of the current state."""
        sim, rec = self.sim, self.rec
        outcome = evaluate_outcome(sim, held_at_end=self.held_at_end, max_tilt=self.max_tilt)
        return ExecutionResult(
            t=np.array(rec["t"], dtype=np.float64),
            joints=np.array(rec["q"], dtype=np.float64),
            targets=np.array(rec["target"], dtype=np.float64),
            tool=np.array(rec["tool"], dtype=np.float64),
            objects={k: np.array(v, dtype=np.float64) for k, v in self.objects.items()},
            glass_tilt=np.array(rec["tilt"], dtype=np.float64),
            grasped=np.array(rec["grasped"], dtype=bool),
            gripper=np.array(rec["gripper"], dtype=bool),
            liquid=sim.liquid_positions(),
            frames=np.array(self.frames, dtype=np.uint8) if self.camera is not None else None,
            frame_times=np.array(self.frame_times, dtype=np.float64),
            outcome=outcome,
        )


def evaluate_outcome(sim: Simulation, *, held_at_end: bool, max_tilt: float) -> Outcome:
    """Judge the current state of ``sim`` with its task's judge (:attr:`TaskSpec.judge`).

    Parameters
    ----------
    sim : Simulation
        After the run (and the settling time).
    held_at_end : bool
        Whether the glass was held at the end of the trajectory.
    max_tilt : float
        Largest tilt of the glass during the run (rad).

    Returns
    -------
    Outcome
    """
    return sim.info.spec.judge(sim, RunStats(held_at_end=held_at_end, max_tilt=max_tilt))
