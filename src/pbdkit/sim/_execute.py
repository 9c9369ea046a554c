"""Play a joint trajectory on the simulated arm under physics, record the run and judge the outcome.

The arm's servos follow a stream of targets at the physics rate (500 Hz) that a real arm's drives
would accept: a jerk-limited follower (:func:`pbdkit.motion._otg.follow`, Ruckig) through the
trajectory's samples, each aimed for, with its velocity and acceleration, at its time, within the
arm's velocity, acceleration and jerk limits (:func:`servo_stream`); the follower's velocity is
the velocity feed-forward. Without limits the targets are the samples interpolated linearly, with
the segment's slope as feed-forward. The gripper closes (a force-limited squeeze) while the
gripper signal is above 0.5 and opens otherwise. Objects move only through contacts: a grasp holds
by friction or not at all.

Every run measures what the servos were sent at every physics step: the peak velocity,
acceleration and jerk of the target stream over the arm's limits
(:attr:`ExecutionResult.servo_peaks`: divided differences at the physics rate, as
:func:`pbdkit.motion.motion_peaks`), from the trajectory's start to the end of the settling
time.

Success is the task's: its :attr:`pbdkit.sim.TaskSpec.judge` reads the state after the run
(and a settling time) and what was measured during it (:class:`RunStats`); each task's module
states its criteria (:mod:`pbdkit.sim._taskdefs.coaster`, :mod:`pbdkit.sim._taskdefs.basin`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, short
from ..motion._limits import LIMIT_SAFETY, MotionLimits, MotionPeaks, motion_peaks
from ..motion._otg import follow
from ..robots import katana
from ._perturb import Disturbance, NoDisturbance
from ._scene import Simulation
from ._tasks import Outcome, RunStats
from ._world import TIMESTEP

Float = NDArray[np.float64]


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
    grasped_tilt : ndarray, shape (S,)
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
    servo_targets : ndarray, shape (K, n)
        The servos' position targets at every physics step, ``servo_period`` apart, from the
        trajectory's start (row 0) to the end of the settling time: what the drives were sent.
    servo_period : float
        Time between two rows of ``servo_targets`` (s): the physics step.
    servo_limits : MotionLimits
        The arm's limits ``servo_peaks`` is measured against.
    servo_peaks : MotionPeaks
        Peak velocity, acceleration and jerk of ``servo_targets`` over ``servo_limits``
        (divided differences at the physics rate, starting and ending at rest), leaving out
        the steps inside the disturbance's force window when the run knew it
        (:func:`stream_peaks`).
    """

    t: Float
    joints: Float
    targets: Float
    tool: Float
    objects: dict[str, Float]
    grasped_tilt: Float
    grasped: NDArray[np.bool_]
    gripper: NDArray[np.bool_]
    liquid: Float
    frames: NDArray[np.uint8] | None
    frame_times: Float
    outcome: Outcome
    servo_targets: Float
    servo_period: float
    servo_limits: MotionLimits
    servo_peaks: MotionPeaks


@functools.cache
def _katana_limits(n: int) -> MotionLimits:
    return MotionLimits.from_robot(katana(), n)


def scene_limits(sim: Simulation) -> MotionLimits:
    """The motion limits of the simulated arm: the Katana's (:func:`pbdkit.robots.katana`, the
    robot every scene's arm is built from), velocity, acceleration and jerk per joint."""
    return _katana_limits(sim.n_joints)


def _check_limits(limits: MotionLimits, n: int) -> MotionLimits:
    if not isinstance(limits, MotionLimits):
        raise TypeError(f"limits must be a MotionLimits, got {type(limits).__name__}")
    if limits.n_joints != n:
        raise ValueError(f"limits must be for the arm's {n} joints, got {limits.n_joints}")
    return limits


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
    velocities: npt.ArrayLike | None = None,
    accelerations: npt.ArrayLike | None = None,
    limits: MotionLimits | None = None,
) -> ExecutionResult:
    """Play a joint trajectory under physics and judge the task's outcome.

    The arm is first put at ``joints[0]`` (no physics) and the world settles for 0.3 s; then the
    trajectory plays, the servos following the jerk-limited stream of :func:`servo_stream`
    through the samples; then the last targets are held for ``settle`` seconds before the
    outcome is measured (a released glass must come to rest, the liquid must land).

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
        Acts on the world before every physics step (:mod:`pbdkit.sim._perturb`), at the time
        from the trajectory's start. Its force window
        (:meth:`~pbdkit.sim.Disturbance.force_window`) is left out of
        :attr:`ExecutionResult.servo_peaks`.
    velocities, accelerations : array-like, shape (T, n), optional
        Joint velocities and accelerations at the samples (in time units of ``t``, e.g.
        :attr:`pbdkit.reproduction.ReproductionResult.velocities` and
        ``accelerations`` with
        :meth:`pbdkit.Skill.times`), aimed for with the positions. None: those of the cubic
        spline through the samples, at rest at both ends.
    limits : MotionLimits, optional
        The arm's velocity, acceleration and jerk limits, for the servo stream and the
        measured peaks; default: the simulated arm's (:func:`scene_limits`). Without any finite
        limit the samples are interpolated linearly.

    Returns
    -------
    ExecutionResult
    """
    n = sim.n_joints
    t_, q_, g = _check_trajectory(t, joints, gripper, n)
    v_ = None if velocities is None else check_array(velocities, "velocities", shape=q_.shape)
    a_ = (
        None
        if accelerations is None
        else check_array(accelerations, "accelerations", shape=q_.shape)
    )
    if duration is not None:
        if not (math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be a positive number of seconds, got {duration}")
        scale = duration / (t_[-1] - t_[0])  # new seconds per old time unit
        t_ = (t_ - t_[0]) * scale
        v_ = None if v_ is None else v_ / scale
        a_ = None if a_ is None else a_ / scale**2
    if settle < 0 or record_rate <= 0 or fps <= 0:
        raise ValueError(
            f"settle must be >= 0 and record_rate, fps > 0, got {settle}, {record_rate}, {fps}"
        )
    lim = scene_limits(sim) if limits is None else _check_limits(limits, n)
    act = NoDisturbance() if disturbance is None else disturbance
    recorder = Recorder(sim, record_rate, camera, fps, lim, force_window=act.force_window())

    start_at(sim, q_[0], bool(g[0]))

    # Servo targets at every physics step, until they are at rest at the last sample (later
    # than its time if the limits kept them behind); the settling time holds the last one.
    if lim.any:
        q_play, dq_play, reached = _servo_motion(t_, q_, lim, v_, a_, TIMESTEP)
    else:
        q_play, dq_play = servo_stream(t_, q_, lim, period=TIMESTEP)
        reached = t_
    n_play = max(int(_grid_index(t_, TIMESTEP)[-1]), q_play.shape[0] - 1)
    n_settle = round(settle / TIMESTEP)
    s = t_[0] + TIMESTEP * np.arange(n_play + n_settle + 1)
    hold = s.shape[0] - q_play.shape[0]
    q_target = np.concatenate([q_play, np.repeat(q_play[-1:], hold, axis=0)])
    dq_target = np.concatenate([dq_play, np.zeros((hold, n))])
    # The gripper changes when the motion reaches the sample where it changes (later than the
    # sample's time where the limits kept the motion behind).
    g_target = g[np.clip(np.searchsorted(reached, s, side="right") - 1, 0, t_.shape[0] - 1)]

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


def _grid_index(t: Float, period: float) -> NDArray[np.intp]:
    """For each sample time, the first step of the grid t[0] + k period at or after it."""
    # A sample within 1e-9 of a period of a grid time is on it (rounding of t or of the period).
    index: NDArray[np.intp] = np.ceil((t - t[0]) / period - 1e-9).astype(np.intp)
    return index


def servo_stream(
    t: npt.ArrayLike,
    joints: npt.ArrayLike,
    limits: MotionLimits,
    *,
    velocities: npt.ArrayLike | None = None,
    accelerations: npt.ArrayLike | None = None,
    period: float = TIMESTEP,
    n_steps: int | None = None,
) -> tuple[Float, Float]:
    """Servo targets every ``period`` through timed joint samples, within motion limits.

    :func:`pbdkit.motion._otg.follow_samples` with ``limits`` times
    :data:`pbdkit.motion._limits.LIMIT_SAFETY`
    (Ruckig), from rest at ``joints[0]``: each sample is aimed for, with its velocity and
    acceleration, at its time (moved onto the grid), and the targets come to rest at the last
    one. Samples that respect the limits are followed closely (reached on time), the others as
    closely as the limits allow. Consecutive targets are within ``limits`` at this rate (by
    divided differences, :func:`pbdkit.motion.motion_peaks`).

    Without any finite limit: linear interpolation of the samples, with the segment's slope
    as velocity.

    Parameters
    ----------
    t : array-like, shape (T,)
        Strictly increasing sample times (s).
    joints : array-like, shape (T, n)
    limits : MotionLimits
        n joints.
    velocities, accelerations : array-like, shape (T, n), optional
        At the samples; None: the cubic spline's through the samples, at rest at both ends.
    period : float
        Seconds between targets (the physics step).
    n_steps : int, optional
        Number of targets; default: until the follower is at rest at the last sample (its
        grid step, or later if the limits kept it behind). Beyond, the last target is held.

    Returns
    -------
    positions : ndarray, shape (n_steps, n)
        Position target at t[0] + k period, k = 0 .. n_steps - 1.
    velocities : ndarray, shape (n_steps, n)
        The follower's velocity there (the velocity feed-forward).
    """
    t_ = check_array(t, "t", ndim=1, min_rows=2)
    q_ = check_array(joints, "joints", shape=(t_.shape[0], None))
    n = q_.shape[1]
    if np.any(np.diff(t_) <= 0):
        raise ValueError("t must be strictly increasing")
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"period must be a positive number of seconds, got {short(period)}")
    _check_limits(limits, n)
    m = _grid_index(t_, period)
    if n_steps is not None and n_steps < 1:
        raise ValueError(f"n_steps must be >= 1, got {short(n_steps)}")
    if not limits.any:
        total = int(m[-1]) + 1 if n_steps is None else int(n_steps)
        s = t_[0] + period * np.arange(total)
        pos = np.empty((total, n))
        for j in range(n):
            pos[:, j] = np.interp(s, t_, q_[:, j])
        seg = np.clip(np.searchsorted(t_, s, side="right") - 1, 0, t_.shape[0] - 2)
        vel = (np.diff(q_, axis=0) / np.diff(t_)[:, None])[seg]
        vel[s >= t_[-1]] = 0.0
        return pos, vel

    v_ = None if velocities is None else check_array(velocities, "velocities", shape=q_.shape)
    a_ = (
        None
        if accelerations is None
        else check_array(accelerations, "accelerations", shape=q_.shape)
    )
    pos, vel, _ = _servo_motion(t_, q_, limits, v_, a_, period, n_steps)
    return pos, vel


def _servo_motion(
    t: Float,
    q: Float,
    limits: MotionLimits,
    velocities: Float | None,
    accelerations: Float | None,
    period: float,
    n_steps: int | None = None,
) -> tuple[Float, Float, Float]:
    """:func:`servo_stream`'s targets (limits given) and when the motion reaches each sample
    (:attr:`pbdkit.motion._motion.Motion.sample_times`: later than t where the limits kept it
    behind)."""
    motion = follow(
        t,
        q,
        limits.scaled(LIMIT_SAFETY),
        velocities=velocities,
        accelerations=accelerations,
    )
    pos, vel, _ = motion.every(period, n_steps)
    return pos, vel, motion.sample_times


def stream_peaks(
    targets: npt.ArrayLike,
    period: float,
    limits: MotionLimits,
    exclude: tuple[float, float] | None = None,
) -> MotionPeaks:
    """Peak velocity, acceleration and jerk of a stream of servo targets over ``limits``.

    The numbers of a :class:`.StreamMonitor` fed the targets one by one (at rest
    before the first and after the last), computed at once
    (:func:`pbdkit.motion.motion_peaks`
    on the uniform grid): at the physics rate a monitor's update per step would cost a quarter
    of the playback's time.

    Parameters
    ----------
    targets : array-like, shape (K, n)
        One target per ``period``, the first at run time 0.
    period : float
        Seconds between targets.
    limits : MotionLimits
    exclude : (float, float), optional
        A window of run time (s), both ends included, whose targets do not count (every
        divided difference that includes one is left out, as ``counted=False``): where an
        external force drives the arm (:meth:`pbdkit.sim.Disturbance.force_window`).

    Returns
    -------
    MotionPeaks
    """
    q = np.asarray(targets, dtype=np.float64)
    if q.ndim != 2 or q.shape[0] == 0:
        raise ValueError(f"targets must have shape (K, n) with K >= 1, got {q.shape}")
    if q.shape[0] == 1:
        q = np.concatenate([q, q])
    t = period * np.arange(q.shape[0])
    mask = None
    if exclude is not None:
        mask = ~((t >= exclude[0] - 1e-9) & (t <= exclude[1] + 1e-9))
    return motion_peaks(t, q, limits, mask=mask)


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
    (:func:`pbdkit.sim.execute_online`): call :meth:`record` at every physics step,
    from the trajectory's start (k = 0), :meth:`end_of_trajectory` at the step where the last
    target is reached, and :meth:`result` after the settling time.

    Every servo target is kept, for :attr:`ExecutionResult.servo_targets` and its peaks over
    ``limits`` (:func:`stream_peaks`; the steps at run time k * TIMESTEP inside
    ``force_window`` do not count).

    Parameters
    ----------
    sim : Simulation
    record_rate : float
        Rate (Hz) of the recorded state.
    camera : str or None
        Record frames of this camera.
    fps : float
        Frame rate of the recorded frames.
    limits : MotionLimits, optional
        The arm's limits; default: the simulated arm's (:func:`scene_limits`).
    force_window : (float, float), optional
        Run times (s) where an external force drives the arm.
    """

    def __init__(
        self,
        sim: Simulation,
        record_rate: float,
        camera: str | None,
        fps: float,
        limits: MotionLimits | None = None,
        *,
        force_window: tuple[float, float] | None = None,
    ) -> None:
        if record_rate <= 0 or fps <= 0:
            raise ValueError(f"record_rate and fps must be > 0, got {record_rate}, {fps}")
        if camera is not None:
            sim.camera_id(camera)
        self.limits = scene_limits(sim) if limits is None else _check_limits(limits, sim.n_joints)
        self.force_window = force_window
        self._servo: list[Float] = []
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
        self._servo.append(np.array(target, dtype=np.float64))
        if k % self.rec_every == 0:
            sim.refresh()
            rec = self.rec
            rec["t"].append(t)
            rec["q"].append(sim.joints())
            rec["target"].append(np.array(target, dtype=np.float64))
            rec["tool"].append(sim.tool_position())
            rec["tilt"].append(sim.grasped_tilt())
            rec["grasped"].append(sim.grasped_held())
            rec["gripper"].append(gripper)
            for name, p in sim.object_positions().items():
                self.objects[name].append(p)
        if self.camera is not None and k % self.frame_every == 0:
            self.frames.append(sim.render(self.camera))
            self.frame_times.append(t)
        self.max_tilt = max(self.max_tilt, sim.grasped_tilt())

    def end_of_trajectory(self) -> None:
        """The last target is reached now: note whether the glass is held."""
        self.held_at_end = self.sim.grasped_held()

    def result(self) -> ExecutionResult:
        """The record and the task's judgement of the current state."""
        sim, rec = self.sim, self.rec
        outcome = evaluate_outcome(sim, held_at_end=self.held_at_end, max_tilt=self.max_tilt)
        servo = np.array(self._servo, dtype=np.float64).reshape(-1, sim.n_joints)
        peaks = (
            stream_peaks(servo, TIMESTEP, self.limits, self.force_window)
            if servo.shape[0]
            else MotionPeaks(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        )
        return ExecutionResult(
            t=np.array(rec["t"], dtype=np.float64),
            joints=np.array(rec["q"], dtype=np.float64),
            targets=np.array(rec["target"], dtype=np.float64),
            tool=np.array(rec["tool"], dtype=np.float64),
            objects={k: np.array(v, dtype=np.float64) for k, v in self.objects.items()},
            grasped_tilt=np.array(rec["tilt"], dtype=np.float64),
            grasped=np.array(rec["grasped"], dtype=bool),
            gripper=np.array(rec["gripper"], dtype=bool),
            liquid=sim.liquid_positions(),
            frames=np.array(self.frames, dtype=np.uint8) if self.camera is not None else None,
            frame_times=np.array(self.frame_times, dtype=np.float64),
            outcome=outcome,
            servo_targets=servo,
            servo_period=TIMESTEP,
            servo_limits=self.limits,
            servo_peaks=peaks,
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
