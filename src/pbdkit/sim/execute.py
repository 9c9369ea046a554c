"""Play a joint trajectory on the simulated arm under physics, record the run and judge the outcome.

The arm follows interpolated servo targets at the physics rate (500 Hz): linear interpolation of the
joint samples for the position target and the segment's slope as velocity feed-forward. The gripper
closes (a force-limited squeeze) while the gripper signal is above 0.5 and opens otherwise. Objects
move only through contacts: a grasp holds by friction or not at all.

Success (design.md):

- coaster task: the glass stands upright (tilt < 10 deg) and rests on the coaster (its bottom within
  5 mm of the coaster's top face, not held), its axis within 15 mm of the coaster's centre
  (horizontally);
- basin task: the glass is still held at the end of the trajectory and at least 90 % of the liquid
  spheres end inside the basin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from . import tasks as T
from .scene import TIMESTEP, Simulation

Float = NDArray[np.float64]

MAX_TILT_DEG = 10.0
MAX_PLACEMENT_ERROR = 0.015  # m, horizontal
MAX_REST_HEIGHT = 0.005  # m, glass bottom above the coaster top
MIN_LIQUID_FRACTION = 0.9


@dataclass(frozen=True)
class Outcome:
    """Success of a run and its measurements.

    Attributes
    ----------
    success : bool
    metrics : dict str -> float
        Coaster task: ``placement_error_mm`` (horizontal distance glass axis - coaster centre),
        ``height_error_mm`` (glass bottom above the coaster top), ``tilt_deg``, ``released``
        (1.0 if the fingers no longer touch the glass). Basin task: ``liquid_fraction`` (share of
        spheres in the basin), ``held`` (1.0 if the glass is held at the end of the trajectory),
        ``pour_error_mm`` (horizontal distance from the basin's centre to the mean of the spheres
        that left the glass), ``tilt_deg`` (largest tilt of the glass during the run).
    """

    success: bool
    metrics: dict[str, float]


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
    """Judge the current state of ``sim`` against the task's success criteria (module docstring).

    Parameters
    ----------
    sim : Simulation
        After the run (and the settling time).
    held_at_end : bool
        Whether the glass was held at the end of the trajectory (basin task).
    max_tilt : float
        Largest tilt of the glass during the run (rad), reported for the basin task.

    Returns
    -------
    Outcome
    """
    task = sim.info.task
    bottom, rot = sim.glass_pose()
    tilt = math.degrees(sim.glass_tilt())
    if task == "coaster":
        coaster = sim.info.objects["coaster"]
        err = float(np.linalg.norm(bottom[:2] - coaster[:2]))
        height = float(bottom[2] - coaster[2])
        released = not (
            sim.contacts("finger_left", "glass_wall") or sim.contacts("finger_right", "glass_wall")
        )
        ok = (
            tilt < MAX_TILT_DEG
            and err <= MAX_PLACEMENT_ERROR
            and abs(height) <= MAX_REST_HEIGHT
            and released
        )
        metrics = {
            "placement_error_mm": 1e3 * err,
            "height_error_mm": 1e3 * height,
            "tilt_deg": tilt,
            "released": float(released),
        }
        return Outcome(bool(ok), metrics)
    basin = sim.info.objects["basin"]
    liquid = sim.liquid_positions()
    half = T.BASIN_INNER / 2
    inside = (
        (np.abs(liquid[:, 0] - basin[0]) < half)
        & (np.abs(liquid[:, 1] - basin[1]) < half)
        & (liquid[:, 2] < basin[2] + T.BASIN_WALL_HEIGHT)
        & (liquid[:, 2] > basin[2] - 0.005)
    )
    frac = float(np.mean(inside)) if liquid.shape[0] else 0.0
    # Spheres that left the glass: farther from its axis than its radius, or below its bottom.
    rel = (liquid - bottom) @ rot
    out = (
        (np.hypot(rel[:, 0], rel[:, 1]) > T.GLASS_RADIUS)
        | (rel[:, 2] < 0)
        | (rel[:, 2] > T.GLASS_HEIGHT)
    )
    pour_err = (
        float(np.linalg.norm(liquid[out, :2].mean(axis=0) - basin[:2])) if np.any(out) else math.nan
    )
    ok = held_at_end and frac >= MIN_LIQUID_FRACTION
    metrics = {
        "liquid_fraction": frac,
        "held": float(held_at_end),
        "pour_error_mm": 1e3 * pour_err,
        "tilt_deg": math.degrees(max_tilt),
    }
    return Outcome(bool(ok), metrics)
