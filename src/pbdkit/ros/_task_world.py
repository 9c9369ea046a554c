"""A task's MuJoCo world driven like a robot behind joint_trajectory_controllers, on a clock it
is given (:class:`TaskWorld`): the core of ``pbdkit ros sim``
(:class:`pbdkit.ros._sim_world.SimWorld` puts it on a ROS 2 graph). Needs the simulator
(MuJoCo), not ROS.

The world's time t (s) is its physics steps times :data:`pbdkit.sim._world.TIMESTEP` (2 ms);
:meth:`TaskWorld.advance` steps it up to a time (the node's clock, in real time). At every
physics step the arm's servo targets are the desired position and velocity of the arm's JTC
follower (:class:`~pbdkit.ros._jtc.TrajectoryFollower`, the messages' clock is the world's
time), and the gripper is closed while its own follower's desired position is > 0.5. The
objects are observed at :data:`pbdkit.sim.OBSERVE_RATE` (15 Hz): their true poses, or with
cameras the stereo tracker's filtered estimates as in :class:`pbdkit.sim.VisionObserver`
(the grasped object's estimate holds from the gripper's first closing; an object not yet
located is not given; fixed objects are given their true pose).

The run, as ``pbdkit evaluate``'s trials run (:func:`pbdkit.sim.execute_online`):

- it starts at the first accepted arm trajectory (run time 0), the world at placement
  ``placement`` of ``evaluate``'s stream (:func:`pbdkit.ros._teach_replay.placement_objects`),
  the arm at its start posture (:func:`start_posture`) since the world began (settled 0.3 s by
  :func:`pbdkit.sim._execute.start_at`);
- every physics step is recorded (:class:`pbdkit.sim._execute.Recorder`) with the arm
  follower's desired position as the servo target;
- the disturbance (``perturb``) acts before every physics step at run time t. One timed after
  the grasp (:func:`timed_at_grasp`: ``move`` on the coaster task) is built when the gripper
  first closes, the grasp at that run time; one timed before it (``push``) is built at the
  start from a skill's time grid and gripper command, as
  :func:`pbdkit.sim._trials.trial_disturbance` does; either drawn from
  ``np.random.default_rng([seed, 2, placement])``, as trial ``placement`` of ``evaluate``;
- it ends once the followers' last trajectories have reached their ends and ``settle`` s have
  passed (a new trajectory meanwhile moves the end); then the task judges it
  (:attr:`TaskWorld.report`). Later trajectories are followed, not judged.

With ``teach`` the world instead replays the simulated teacher
(:class:`~pbdkit.ros._teach_replay.TeacherReplay`) and follows no trajectory.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import check_int, check_positive_float, short
from ..motion._limits import MotionLimits
from ..robots import katana
from ..sim._execute import Recorder, start_at
from ..sim._metrics import run_summary
from ..sim._online import OBSERVE_RATE, VisionObserver
from ..sim._perturb import (
    Disturbance,
    DisturbanceSetup,
    NoDisturbance,
    check_perturb,
    make_disturbance,
)
from ..sim._scene import Simulation
from ..sim._task_registry import get_task
from ..sim._tasks import TaskSpec
from ..sim._teacher import random_start_posture
from ..sim._tracking import SimTracker
from ..sim._world import TIMESTEP
from ..skill._skill import Skill
from ._jtc import RejectedTrajectory, TrajectoryFollower
from ._teach_replay import TeacherReplay, placement_objects

__all__ = [
    "GRIPPER_JOINT",
    "START_POSTURE_SEED",
    "TaskWorld",
    "WorldSettings",
    "check_world",
    "start_posture",
    "timed_at_grasp",
]

Float = NDArray[np.float64]

#: The gripper's joint in the joint states and on its controller: 0.0 open, 1.0 closed.
GRIPPER_JOINT = "gripper"
#: Without a skill, the arm starts at the teacher's start posture drawn from
#: ``np.random.default_rng(START_POSTURE_SEED)`` (:func:`start_posture`).
START_POSTURE_SEED = 0
#: :meth:`TaskWorld.advance` does at most this many physics steps per call (0.1 s of world
#: time), so that a slow machine still serves its messages; the world then lags the clock.
MAX_STEPS = 50
TEACHING = "the world replays the teacher (teach): it follows no trajectory"


@dataclass(frozen=True, kw_only=True)
class WorldSettings:
    """``pbdkit ros sim``'s options (their defaults are the command's).

    Attributes
    ----------
    task : str
        A registered task (:func:`pbdkit.sim.task_names`).
    seed, placement : int
        The world is trial ``placement`` of ``pbdkit evaluate --seed SEED``.
    interpolate_from_desired_state : bool
        The JTC's option (False: a message's first segment starts from the measured state).
    cameras : bool
        Give the objects as the stereo tracker sees them (False: their true poses).
    perturb : str
        A registered perturbation (:func:`pbdkit.sim.perturbation_names`).
    teach : bool
        Replay the simulated teacher instead of following trajectories.
    takes : int
        The teacher's demonstrations (with ``teach``), >= 1.
    teach_speed : float
        The teacher's speed (> 0; on the Katana its joint velocity limits cap it).
    settle : float
        Seconds at rest after the last trajectory's end before the run is judged.
    time_scale : float
        World seconds per second of the clock: 1 is real time; up to 20 for tests.
    exit_after_run : bool
        The node ends after the run is judged (or the teacher's last take).
    """

    task: str = "coaster"
    seed: int = 0
    placement: int = 0
    interpolate_from_desired_state: bool = False
    cameras: bool = False
    perturb: str = "none"
    teach: bool = False
    takes: int = 5
    teach_speed: float = 1.0
    settle: float = 1.0
    time_scale: float = 1.0
    exit_after_run: bool = False

    def __post_init__(self) -> None:
        for flag in ("interpolate_from_desired_state", "cameras", "teach", "exit_after_run"):
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"{flag} must be True or False, got {short(getattr(self, flag))}")
        check_int(self.seed, "seed", minimum=0)
        check_int(self.placement, "placement", minimum=0)
        check_int(self.takes, "takes", minimum=1)
        check_positive_float(self.teach_speed, "teach_speed")
        check_positive_float(self.settle, "settle", allow_zero=True)
        scale = check_positive_float(self.time_scale, "time_scale")
        if scale > 20.0:
            raise ValueError(f"time_scale must be in (0, 20], got {short(self.time_scale)}")


def start_posture(skill: Skill | None = None) -> Float:
    """Where the arm starts (n,): a skill's start posture (its GMR mean at the first step,
    within the joint limits, as :attr:`pbdkit.sim.TaskSkill.start_posture`), or without one
    the teacher's start posture drawn from ``default_rng(START_POSTURE_SEED)``
    (:func:`pbdkit.sim._teacher.random_start_posture`: the hand raised in front of the
    robot)."""
    robot = katana()
    if skill is None:
        return random_start_posture(robot, np.random.default_rng(START_POSTURE_SEED))
    mean = skill.constraints().joint_mean[0]
    return np.asarray(np.clip(mean, skill.robot.lower, skill.robot.upper), dtype=np.float64)


def timed_at_grasp(perturb: str, spec: TaskSpec) -> bool:
    """Whether the disturbance ``perturb`` of the task ``spec`` acts only after the grasp, so
    that it can be built when the gripper closes (``none``; ``move`` and ``rotate`` of a task
    whose object moves ``"while_carried"``). The others (``push``, the before-grasp moves, a
    perturbation registered elsewhere) are timed on a skill's grasp."""
    if perturb == "none":
        return True
    event = {"move": spec.move, "rotate": spec.rotate}.get(perturb)
    return event is not None and event.when == "while_carried"


def check_world(settings: WorldSettings, skill: Skill | None = None) -> TaskSpec:
    """The task of ``settings`` once the world it describes can be built: a registered task
    and perturbation, one the task can have, a skill of the Katana, and a skill for a
    disturbance timed before the grasp (:func:`timed_at_grasp`). Cheap: a command calls it
    before it starts anything.

    Raises
    ------
    ValueError
        Saying which and what to give.
    """
    spec = get_task(settings.task)
    joints = list(katana().joint_names)
    if skill is not None and list(skill.robot.joint_names) != joints:
        raise ValueError(
            f"skill: its arm's joints {short(list(skill.robot.joint_names))} are not the "
            f"simulated Katana's {joints}"
        )
    check_perturb(settings.perturb, spec)
    if not (settings.teach or timed_at_grasp(settings.perturb, spec)) and skill is None:
        raise ValueError(
            f"perturb {short(settings.perturb)} acts before the grasp: it is timed on a skill's "
            "grasp, as pbdkit evaluate times it; give the skill (--skill SKILL.npz)"
        )
    return spec


@dataclass
class _Run:
    """A run's state: its first world step, the record, the disturbance (None until built),
    the run time of the followers' last trajectory end and whether it has been passed."""

    k0: int
    recorder: Recorder
    act: Disturbance | None
    end: float
    ended: bool = False


class TaskWorld:
    """The world of a task behind two JTC followers, advanced on a clock (module docstring).

    Parameters
    ----------
    settings : WorldSettings
    skill : Skill, optional
        Its start posture is the arm's (:func:`start_posture`), and its time grid and gripper
        command time a disturbance that acts before the grasp (required for one).
    q0 : array_like, shape (5,), optional
        The arm's start posture instead (default: :func:`start_posture`).
    log : callable, optional
        Where the teacher's takes are announced (one line each).

    Raises
    ------
    ValueError
        An unknown task or perturbation, a perturbation the task cannot have, one timed before
        the grasp without a skill, a skill of another arm.
    """

    def __init__(
        self,
        settings: WorldSettings,
        *,
        skill: Skill | None = None,
        q0: Any = None,
        log: Callable[[str], None] | None = None,
    ) -> None:
        self.settings = s = settings
        self.spec = check_world(s, skill)
        self.log = log or (lambda line: None)
        robot = katana()
        self.joint_names: list[str] = list(robot.joint_names)
        self.grasp_timed = s.teach or timed_at_grasp(s.perturb, self.spec)
        self.skill = skill
        q_start = start_posture(skill) if q0 is None else np.asarray(q0, dtype=np.float64)
        if q_start.shape != (len(self.joint_names),) or not np.all(np.isfinite(q_start)):
            raise ValueError(f"q0 must be {len(self.joint_names)} finite angles, got {short(q0)}")
        self.q0 = q_start
        self.replay = TeacherReplay(self.spec, s.seed, s.takes, s.teach_speed) if s.teach else None
        self.tracker = _calibrate(self.spec, self.q0) if s.cameras else None
        self.velocity_limit = MotionLimits.from_robot(robot, robot.n_joints).velocity
        self.steps = 0
        self.closed = False
        self.sim: Simulation | None = None
        self.observer: VisionObserver | None = None
        self.objects: dict[str, Float] = {}
        self.take = -1
        self._announced = -1
        self._next_obs = 0.0  # world time of the next observation of the objects
        self._vadr = np.zeros(0, dtype=np.intp)  # the arm's velocity addresses (_place)
        if self.replay is not None:
            self._begin_take(0)
        else:
            self._place(placement_objects(self.spec, s.seed, s.placement), self.q0, False)
        self.arm = TrajectoryFollower(
            self.joint_names,
            self.q0,
            interpolate_from_desired_state=s.interpolate_from_desired_state,
        )
        self.gripper = TrajectoryFollower(
            [GRIPPER_JOINT], [0.0], interpolate_from_desired_state=s.interpolate_from_desired_state
        )
        #: Per follower ("arm", "gripper"): messages accepted and rejected.
        self.messages = {k: {"accepted": 0, "rejected": 0} for k in ("arm", "gripper")}
        #: The objects' latest poses (4, 4), base frame, and their world time; the count of
        #: observations so far (a new one: new poses to publish).
        self.seen: dict[str, Float] = {}
        self.seen_t = 0.0
        self.observations = 0
        self.run: _Run | None = None
        #: The run's judgement (or, with ``teach``, the replay's account) once there is one.
        self.report: dict[str, Any] | None = None
        #: The largest lag of the world behind the clock after an :meth:`advance` (s).
        self.max_lag = 0.0

    # -- the world ---------------------------------------------------------------------------
    @property
    def t(self) -> float:
        """The world's time (s): its physics steps so far times TIMESTEP."""
        return self.steps * TIMESTEP

    @property
    def object_names(self) -> list[str]:
        """Every object of the task, in range order."""
        return list(self.spec.ranges)

    @property
    def finished(self) -> bool:
        """True once the run is judged (or the teacher's last take has ended)."""
        return self.report is not None

    def _place(self, objects: dict[str, Float], q: Float, closed: bool) -> None:
        """A new scene with ``objects``, the arm settled at ``q`` (:func:`start_at`)."""
        if self.sim is not None:
            self.sim.close()
        sim = Simulation.from_task(self.spec, objects)
        start_at(sim, q, closed)
        m = sim.model
        self._vadr = np.array([m.jnt_dofadr[m.joint(j).id] for j in sim.info.arm_joints])
        self.sim, self.objects, self.closed = sim, objects, closed
        self.observer = (
            None
            if self.tracker is None
            else VisionObserver(self.tracker, self.spec.tracked_objects)
        )
        self._next_obs = self.t  # observed at once

    def _scene(self) -> Simulation:
        assert self.sim is not None  # built in __init__
        return self.sim

    def joint_velocities(self) -> Float:
        """The arm's measured joint velocities (n,)."""
        return np.array(self._scene().data.qvel[self._vadr], dtype=np.float64)

    def joint_state(self) -> tuple[list[str], Float, Float]:
        """The joint states now: names (the arm's, then :data:`GRIPPER_JOINT`), positions and
        velocities (n + 1,): measured for the arm, the command for the gripper (1.0 closed)."""
        q = np.append(self._scene().joints(), 1.0 if self.closed else 0.0)
        v = np.append(self.joint_velocities(), 0.0)
        return [*self.joint_names, GRIPPER_JOINT], q, v

    def advance(self, t: float, max_steps: int = MAX_STEPS) -> int:
        """Step the physics until the world's time is ``t`` (to half a step), at most
        ``max_steps`` steps; returns the steps done."""
        n = 0
        while self.t < t - 0.5 * TIMESTEP and n < max_steps:
            self._step()
            n += 1
        self.max_lag = max(self.max_lag, t - self.t)
        return n

    def _step(self) -> None:
        """One physics step at the world's time: the servos' targets and the gripper, the
        objects observed when due, the run's record and disturbance."""
        t = self.t
        if self.replay is not None:
            i = self.replay.take_at(t)
            if i != self.take:
                self._begin_take(i)
            if i != self._announced:
                self._announce(i)
            q, dq, closed = self.replay.takes[i].command(t)
            if self.report is None and t >= self.replay.end:
                self.report = self._teach_report()
                self.log(f"teach: done, {len(self.replay.takes)} takes")
        else:
            q, dq, _ = self.arm.desired(t)
            closed = bool(self.gripper.desired(t)[0][0] > 0.5)
        if t >= self._next_obs - 1e-9:
            self._observe(t, closed)
            self._next_obs += 1.0 / OBSERVE_RATE
        sim = self._scene()
        sim.set_targets(q, dq)
        sim.set_gripper(closed)
        self.closed = closed
        if self.run is not None and self.report is None:
            self._run_step(self.run, q, closed)
        sim.step()
        self.steps += 1

    def _observe(self, t: float, closed: bool) -> None:
        sim = self._scene()
        sim.refresh()
        poses = sim.object_poses()
        if self.observer is None:
            seen = poses
        else:
            self.observer(sim, t, closed)
            seen = {k: _as_pose(v) for k, v in self.observer.filter.estimates.items()}
            seen.update({k: poses[k] for k in self.spec.fixed_objects})
        self.seen = {k: seen[k] for k in self.object_names if k in seen}
        self.seen_t = t
        self.observations += 1

    # -- the trajectories --------------------------------------------------------------------
    def receive_arm(
        self,
        names: Sequence[str],
        times: Any,
        positions: Any,
        velocities: Any = None,
        accelerations: Any = None,
        stamp: float | None = None,
    ) -> None:
        """An arm trajectory arriving now (the world's time; ``stamp``: its header stamp in
        the world's time, None for 0): as :meth:`TrajectoryFollower.receive`, the measured
        state the sim arm's. The first one accepted starts the run. Raises
        RejectedTrajectory (a ValueError) as the JTC refuses, counted in :attr:`messages`."""
        measured = (self._scene().joints(), self.joint_velocities())
        args = (names, times, positions, velocities, accelerations)
        self._receive("arm", self.arm, measured, *args, stamp=stamp)
        self._extend_run(self._ends_in(times, stamp), start=True)

    def receive_gripper(
        self,
        names: Sequence[str],
        times: Any,
        positions: Any,
        velocities: Any = None,
        accelerations: Any = None,
        stamp: float | None = None,
    ) -> None:
        """A gripper trajectory (one joint, :data:`GRIPPER_JOINT`) arriving now: closed while
        its desired position is > 0.5. Raises RejectedTrajectory as the JTC refuses."""
        measured = ([1.0 if self.closed else 0.0], [0.0])
        args = (names, times, positions, velocities, accelerations)
        self._receive("gripper", self.gripper, measured, *args, stamp=stamp)
        self._extend_run(self._ends_in(times, stamp), start=False)

    def _ends_in(self, times: Any, stamp: float | None) -> float:
        """Seconds from now to a message's last point."""
        return float(np.max(times)) + (0.0 if stamp is None else stamp - self.t)

    def _receive(
        self,
        kind: str,
        follower: TrajectoryFollower,
        measured: Any,
        names: Sequence[str],
        times: Any,
        positions: Any,
        velocities: Any,
        accelerations: Any,
        *,
        stamp: float | None = None,
    ) -> None:
        """One trajectory to ``follower`` (``kind``: "arm" or "gripper"), counted in
        :attr:`messages`; refused while the world replays the teacher."""
        if self.replay is not None:
            self.messages[kind]["rejected"] += 1
            raise RejectedTrajectory(
                "the world replays the teacher (teach): it follows no trajectory"
            )
        try:
            follower.receive(
                self.t,
                names,
                times,
                positions,
                velocities,
                accelerations,
                measured=measured,
                stamp=stamp,
            )
        except ValueError:
            self.messages[kind]["rejected"] += 1
            raise
        self.messages[kind]["accepted"] += 1

    def _extend_run(self, duration: float, *, start: bool) -> None:
        """A trajectory of ``duration`` s accepted now: the run starts (an arm trajectory, no
        run yet) or its end moves; nothing once it is judged."""
        if self.report is not None:
            return
        if self.run is None:
            if start:
                self.run = self._start_run(duration)
            return
        now = (self.steps - self.run.k0) * TIMESTEP
        if now + duration > self.run.end:
            self.run.end = now + duration
            self.run.ended = False

    def _start_run(self, duration: float) -> _Run:
        if self.settings.perturb == "none":
            act: Disturbance | None = NoDisturbance()
        else:  # one timed after the grasp is built when the gripper closes (_run_step)
            act = None if self.grasp_timed else self._disturbance_from_skill()
        window = None if act is None else act.force_window()
        recorder = Recorder(self._scene(), 50.0, None, 15.0, force_window=window)
        return _Run(self.steps, recorder, act, duration)

    def _disturbance_rng(self) -> np.random.Generator:
        return np.random.default_rng([self.settings.seed, 2, self.settings.placement])

    def _disturbance_from_skill(self) -> Disturbance:
        """The disturbance timed on the skill's grasp, as trial ``placement`` of evaluate."""
        skill = self.skill
        assert skill is not None  # checked in __init__
        grid = np.arange(skill.n_steps, dtype=np.float64) * skill.step_seconds
        setup = DisturbanceSetup(
            task=self.spec,
            objects=self.objects,
            times=grid,
            gripper=skill.constraints().gripper,
            rng=self._disturbance_rng(),
        )
        return make_disturbance(self.settings.perturb, setup)

    def _run_step(self, run: _Run, q: Float, closed: bool) -> None:
        k = self.steps - run.k0
        t = k * TIMESTEP
        if run.act is None and closed:  # the grasp: a disturbance timed after it
            setup = DisturbanceSetup(
                task=self.spec,
                objects=self.objects,
                times=np.array([t]),
                gripper=np.array([1.0]),
                rng=self._disturbance_rng(),
            )
            run.act = make_disturbance(self.settings.perturb, setup)
        run.recorder.record(k, t, q, closed)
        if not run.ended and t >= run.end - 0.5 * TIMESTEP:
            run.recorder.end_of_trajectory()
            run.ended = True
        if run.ended and t >= run.end + self.settings.settle - 1e-9:
            self.report = self._judge(run, t)
            return
        if run.act is not None:
            run.act.apply(self._scene(), t)

    def _judge(self, run: _Run, t: float) -> dict[str, Any]:
        """The report of a run: the task's judgement and the servo targets' peaks."""
        s = self.settings
        ex = run.recorder.result()
        act = run.act
        window = None if act is None else act.force_window()
        out: dict[str, Any] = {
            "task": self.spec.name,
            "seed": s.seed,
            "placement_index": s.placement,
            "placement": {k: np.asarray(v).tolist() for k, v in self.objects.items()},
            "start_posture": self.q0.tolist(),
        }
        summary = run_summary(ex, self.velocity_limit, window)
        metrics = {k: summary.pop(k) for k in ex.outcome.metrics}
        out.update(summary)
        out["metrics"] = metrics
        out["servo_worst_ratio"] = float(ex.servo_peaks.worst)
        out["perturb"] = act.as_dict() if act is not None else {"name": s.perturb, "grasp_s": None}
        out["trajectory_end_s"] = run.end
        out["judged_s"] = t
        out["messages"] = {k: dict(v) for k, v in self.messages.items()}
        out["max_lag_s"] = self.max_lag
        out["interpolate_from_desired_state"] = s.interpolate_from_desired_state
        out["cameras"] = s.cameras
        return out

    # -- the teacher -------------------------------------------------------------------------
    def _begin_take(self, i: int) -> None:
        assert self.replay is not None
        take = self.replay.takes[i]
        gripper = take.demo.gripper
        closed = bool(gripper is not None and gripper[0] > 0.5)
        self._place(take.objects, take.demo.joints[0], closed)
        self.take = i

    def _announce(self, i: int) -> None:
        assert self.replay is not None
        take = self.replay.takes[i]
        where = ", ".join(
            f"{k} {np.round(np.asarray(v)[:3, 3] if np.ndim(v) == 2 else v, 3).tolist()}"
            for k, v in take.objects.items()
        )
        self.log(
            f"take {i + 1}/{len(self.replay.takes)}: {where}; moves at "
            f"{take.motion_start:.1f}-{take.motion_end:.1f} s"
        )
        self._announced = i

    def _teach_report(self) -> dict[str, Any]:
        assert self.replay is not None
        s = self.settings
        return {
            "task": self.spec.name,
            "seed": s.seed,
            "teach_done": True,
            "teach_speed": s.teach_speed,
            "takes": [take.as_dict() for take in self.replay.takes],
        }

    def close(self) -> None:
        """Free the scene."""
        if self.sim is not None:
            self.sim.close()
            self.sim = None


def _as_pose(placement: Float) -> Float:
    """A position (3,) as a pose (4, 4) with no rotation; a pose as it is."""
    p = np.asarray(placement, dtype=np.float64)
    if p.shape == (4, 4):
        return p
    pose = np.eye(4)
    pose[:3, 3] = p
    return pose


def _calibrate(spec: TaskSpec, arm: Float) -> SimTracker:
    """The stereo tracker of ``spec``, calibrated on its nominal placement with the arm at
    ``arm`` (as :func:`pbdkit.sim._sensing.calibrate_tracker` at a skill's start posture)."""
    calib = Simulation.from_task(spec, spec.nominal_objects())
    try:
        return SimTracker.from_simulation(calib, at_nominal=False, arm=arm)
    finally:
        calib.close()
