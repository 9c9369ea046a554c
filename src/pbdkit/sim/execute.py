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
    if camera is not None:
        sim.camera_id(camera)

    sim.set_joints(q_[0])
    sim.set_gripper(bool(g[0]))
    sim.step(round(0.3 / TIMESTEP))
    sim.set_joints(q_[0])  # undo the small sag of the settling phase

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

    rec_every = max(1, round(1.0 / (record_rate * TIMESTEP)))
    frame_every = max(1, round(1.0 / (fps * TIMESTEP)))
    rec: dict[str, list[object]] = {
        k: [] for k in ("t", "q", "target", "tool", "tilt", "grasped", "gripper")
    }
    rec_objects: dict[str, list[Float]] = {k: [] for k in sim.info.objects}
    frames: list[NDArray[np.uint8]] = []
    frame_times: list[float] = []
    max_tilt = 0.0
    held_at_end = False
    start = sim.time
    for k in range(s.shape[0]):
        sim.set_targets(q_target[k], dq_target[k])
        sim.set_gripper(bool(g_target[k]))
        if k % rec_every == 0:
            sim.refresh()
            rec["t"].append(t_[0] + sim.time - start)
            rec["q"].append(sim.joints())
            rec["target"].append(q_target[k].copy())
            rec["tool"].append(sim.tool_position())
            rec["tilt"].append(sim.glass_tilt())
            rec["grasped"].append(sim.glass_grasped())
            rec["gripper"].append(bool(g_target[k]))
            for name, p in sim.object_positions().items():
                rec_objects[name].append(p)
        if camera is not None and k % frame_every == 0:
            frames.append(sim.render(camera))
            frame_times.append(t_[0] + sim.time - start)
        if k == n_play:
            held_at_end = sim.glass_grasped()
        max_tilt = max(max_tilt, sim.glass_tilt())
        if k < s.shape[0] - 1:
            sim.step()

    outcome = evaluate_outcome(sim, held_at_end=held_at_end, max_tilt=max_tilt)
    return ExecutionResult(
        t=np.array(rec["t"], dtype=np.float64),
        joints=np.array(rec["q"], dtype=np.float64),
        targets=np.array(rec["target"], dtype=np.float64),
        tool=np.array(rec["tool"], dtype=np.float64),
        objects={k: np.array(v, dtype=np.float64) for k, v in rec_objects.items()},
        glass_tilt=np.array(rec["tilt"], dtype=np.float64),
        grasped=np.array(rec["grasped"], dtype=bool),
        gripper=np.array(rec["gripper"], dtype=bool),
        liquid=sim.liquid_positions(),
        frames=np.array(frames, dtype=np.uint8) if camera is not None else None,
        frame_times=np.array(frame_times, dtype=np.float64),
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
