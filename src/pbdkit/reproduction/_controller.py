"""Online control: a skill run step by step from the measured joint angles
(:class:`Controller`, its :class:`Command` s, and :class:`CommandStream` for a faster loop).

Without motion limits each :meth:`Controller.step` closes Table II on the measured posture q:
the same step as the offline reproduction
(:func:`~pbdkit.reproduction._table_ii.make_step`), linearized at q, so that fed its own targets
with constant objects a controller reproduces :meth:`pbdkit.Skill.reproduce` step for step. The
phase advances one step per call while the arm follows, and holds while

    lag = max_i |q_i - q_last,i| / (v_i dt) > max_lag       (steps at top speed; v_i dt is
                                                            max_step without velocity limits).

With motion limits (the default for a robot that declares them) the commands are samples every
``dt`` of a jerk-limited follower (:func:`pbdkit.motion._otg.follow`) of a plan, the
reproduction within the limits from where the arm is
(:func:`~pbdkit.reproduction._timing.timed_path`), made again when an object moves by more than
:data:`REPLAN_DISTANCE` (or turns by more than :data:`REPLAN_ANGLE`) or the arm is pushed.
Why, and what each case does: :doc:`/reproduction`, "The online controller".
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import log3
from .._validation import check_array
from ..data._placement import position_of, rotation_of
from ..motion._limits import LIMIT_SAFETY, MotionLimits
from ..motion._otg import Motion, follow
from ..robots._protocols import KinematicModel
from ._constraints import Constraints
from ._result import ReproductionResult
from ._setup import RunOptions, _check_reach, check_objects, setup_run
from ._table_ii import make_step
from ._timing import check_timing, timed_path

__all__ = ["REPLAN_ANGLE", "REPLAN_DISTANCE", "Command", "CommandStream", "Controller"]

#: With motion limits, an object that moves farther than this (m) from the position the plan
#: was made for makes the controller plan again (:doc:`/reproduction`, "The online
#: controller"): about twice the cameras' noise (pbdkit.sim._tracking: 0.6 mm), a tenth of the
#: coaster task's tolerance.
REPLAN_DISTANCE = 1e-3
#: With motion limits, an object whose pose turns farther than this (rad) from the one the plan
#: was made for makes the controller plan again: 1 mm at 0.1 m from its origin, as
#: :data:`REPLAN_DISTANCE`.
REPLAN_ANGLE = 1e-2

Float = NDArray[np.float64]


def _moved(now: Float, planned: Float, distance: float) -> bool:
    """Whether an object moved by more than ``distance`` (m) or turned by more than
    :data:`REPLAN_ANGLE` from ``planned`` (both positions (3,) or both poses (4, 4))."""
    if float(np.linalg.norm(position_of(now) - position_of(planned))) > distance:
        return True
    rot, ref = rotation_of(now), rotation_of(planned)
    if rot is None or ref is None:
        return False
    return float(np.linalg.norm(log3(rot @ ref.T))) > REPLAN_ANGLE


class Command:
    """One target of a :class:`Controller` (covariance and influence computed on first use).

    Attributes
    ----------
    q : ndarray, shape (n,)
        The joint angles to reach at the end of this step (within the joint limits).
    gripper : bool
        The generalized gripper command (closed if True).
    index : int
        The step of the skill's time grid it targets.
    limited : bool
        True if a velocity bound (or ``max_step``) shortened the step.
    held : bool
        True if the arm was more than ``max_lag`` steps behind the last target: the phase held
        and the command re-targets from the measured posture (a reference that runs through
        the commands should restart there).
    velocity, acceleration : ndarray, shape (n,), or None
        With motion limits: the command's velocity and acceleration (the state of the
        trajectory generator at the command's time); None without.
    phase : float
        With motion limits: the skill's phase after this command (steps, fractional where the
        limits slowed it); ``index`` without.
    covariance : ndarray, shape (n, n)
        Covariance of the target (the fused Sigma of eq. (1), Sigma^theta for the joint-only
        controller, J+ S J+^T for a task-only one).
    influence : dict str -> float
        Share of each constraint in use, in the hand's space (as
        :attr:`pbdkit.reproduction.ReproductionResult.influence`).
    """

    def __init__(
        self,
        controller: Controller,
        q: Float,
        index: int,
        limited: bool,
        jac: Float,
        held: bool = False,
        velocity: Float | None = None,
        acceleration: Float | None = None,
        phase: float | None = None,
        details: tuple[_Plan, int] | None = None,
    ) -> None:
        self.q = q
        self.index = index
        self.limited = limited
        self.held = held
        self.velocity = velocity
        self.acceleration = acceleration
        self.phase = float(index) if phase is None else phase
        self.gripper = controller._gripper_at(index)
        self._ctrl = controller
        self._jac = jac  # the Jacobian the step was linearized with
        self._details = details  # with motion limits: the plan and its sample at this command

    @cached_property
    def covariance(self) -> Float:
        if self._details is not None:
            plan, i = self._details
            return np.array(plan.result.covariances[i], dtype=np.float64)
        return self._ctrl._covariance(self.index, self._jac)

    @cached_property
    def influence(self) -> dict[str, float]:
        if self._details is not None:
            plan, i = self._details
            return {k: float(v[i]) for k, v in plan.result.influence.items()}
        return self._ctrl._influence(self.index, self._jac, self.covariance)

    def __repr__(self) -> str:
        return f"Command(index={self.index}, q={np.round(self.q, 4).tolist()})"


@dataclass
class _Targets:
    q: Float  # the last target
    index: int
    x: Float | None  # f(q), J(q) and the joint axes, when known
    jac: Float | None
    axes: Float | None = None


class Controller:
    """One closed-loop run of a skill (build it with :meth:`pbdkit.Skill.controller`).

    Parameters
    ----------
    robot : KinematicModel
    constraints : Constraints
        The skill's generalized constraints over its T steps.
    objects : dict str -> array-like, shape (3,), (4, 4) or (7,)
        Position of every object of the skill (base frame).
    options : RunOptions, optional
        As :func:`pbdkit.reproduction._probabilistic_ik.solve`; its ``q0`` is the posture the run
        starts from (default theta_hat_0, clipped to the limits): the first :meth:`step`
        targets step 1.
    step_limit : array-like, shape (n,), optional
        Largest step of each joint (rad per step): velocity limits times :attr:`dt`.
    dt : float
        Seconds per step (NaN when unknown).
    reach : float, optional
        As :func:`pbdkit.reproduction._probabilistic_ik.solve`.
    max_lag : float
        The phase holds while the measured posture is more than this many steps behind the
        last target (module docstring; :doc:`/reproduction`, "The online controller"). ``inf``:
        it always advances.
    limits : MotionLimits, optional
        Velocity, acceleration and jerk limits of the command stream (:doc:`/reproduction`,
        "The online controller"); needs a known ``dt``. ``step_limit`` and ``q0`` are then not used
        (the first measured posture is where the run starts).
    replan_distance : float
        With motion limits: an object that moves farther than this (m) from where the plan
        assumed it makes the controller plan again (:data:`REPLAN_DISTANCE`).

    Attributes
    ----------
    dt : float
        Seconds per step.
    n_steps : int
        T.
    index : int
        The step the last command targeted (0 before the first :meth:`step`).
    target : ndarray, shape (n,)
        The last target (the start posture before the first :meth:`step`).
    gripper : bool
        The gripper command at :attr:`index`.
    done : bool
        True once a command has targeted the last step.
    """

    def __init__(
        self,
        robot: KinematicModel,
        constraints: Constraints,
        objects: Mapping[str, npt.ArrayLike],
        options: RunOptions | None = None,
        *,
        step_limit: npt.ArrayLike | None = None,
        dt: float = float("nan"),
        reach: float | None = None,
        max_lag: float = 3.0,
        limits: MotionLimits | None = None,
        replan_distance: float = REPLAN_DISTANCE,
    ) -> None:
        timed = check_timing(limits, dt)
        if timed:
            step_limit = None  # the trajectory generator bounds the speed
        run = setup_run(
            robot,
            constraints,
            objects,
            RunOptions() if options is None else options,
            step_limit=step_limit,
            reach=reach,
        )
        self._run = run
        lag = float(max_lag)
        if not (lag > 0):  # NaN too
            raise ValueError(f"max_lag must be > 0 (steps), got {max_lag!r}")
        c, n = run.constraints, run.constraints.n_joints
        self._c, self._robot = c, robot
        self._objs, self._used, self._tasks = run.objects, run.used, run.tasks
        self.max_lag = lag
        self.dt = float(dt)
        lower, upper, cap, bound = run.lower, run.upper, run.max_step, run.step_limit
        self._lower, self._upper = lower, upper
        theta0 = run.theta0
        # The largest step of each joint, for the phase rule: the velocity bound, else max_step.
        self._step_bound = bound if bound is not None else np.full(n, cap)
        self._step = make_step(robot, run)
        self._last = _Targets(theta0.copy(), 0, None, None)
        self._no_jac = np.zeros((3, n))
        self._timed: _Timed | None = None
        if timed:
            assert limits is not None
            distance = float(replan_distance)
            if not (distance >= 0):
                raise ValueError(f"replan_distance must be >= 0 (m), got {replan_distance!r}")
            self._timed = _Timed(limits, distance)
            plan = self._timed.plan_limits
            # A lag counts in steps at top speed (max_step where no speed limit).
            self._step_bound = np.where(
                np.isfinite(plan.velocity), plan.velocity * self.dt, min(cap, 1.0)
            )

    # ------------------------------------------------------------------ state
    @property
    def n_steps(self) -> int:
        """T."""
        return self._c.n_steps

    @property
    def index(self) -> int:
        """The step the last command targeted (0 before the first call)."""
        return self._last.index

    @property
    def done(self) -> bool:
        """True once a command has targeted the last step (with motion limits: once the
        command that brings the arm to rest at the last posture was given)."""
        if self._timed is not None:
            return self._timed.done
        return self._last.index >= self._c.n_steps - 1

    @property
    def limits(self) -> MotionLimits | None:
        """The motion limits of the command stream (None without)."""
        return None if self._timed is None else self._timed.limits

    @property
    def phase(self) -> float:
        """The skill's phase (steps): with motion limits fractional, else :attr:`index`."""
        return float(self._last.index) if self._timed is None else self._timed.phase

    @property
    def replans(self) -> int:
        """How many times the controller planned again (motion limits; 0 without)."""
        return 0 if self._timed is None else self._timed.replans

    def stream(self, rate_hz: float) -> CommandStream:
        """Setpoints at ``rate_hz`` following this controller's plans (see
        :class:`CommandStream`); this controller must not have been stepped yet."""
        return CommandStream(self, rate_hz)

    @property
    def target(self) -> Float:
        """The last target (the start posture before the first :meth:`step`), a copy."""
        return self._last.q.copy()

    @property
    def gripper(self) -> bool:
        """The gripper command of the last target's step (of step 0 before the first call)."""
        return self._gripper_at(self._last.index)

    @property
    def objects(self) -> dict[str, Float]:
        """The object positions in use now (copies)."""
        return {k: v.copy() for k, v in self._objs.items()}

    # ------------------------------------------------------------------ the loop
    def step(
        self, q_measured: npt.ArrayLike, objects: Mapping[str, npt.ArrayLike] | None = None
    ) -> Command:
        """The next target, from the measured posture (Table II closed on the arm).

        Parameters
        ----------
        q_measured : array-like, shape (n,)
            The joint angles the arm is at (a measurement slightly outside the joint limits is
            clipped to them).
        objects : dict str -> array-like, shape (3,), (4, 4) or (7,), optional
            New positions of any of the skill's objects, used from this step on.

        Returns
        -------
        command : Command

        Raises
        ------
        ValueError
            A measurement that is not n finite values, an unknown object, or a call after
            :attr:`done`.
        """
        if self.done:
            raise ValueError(
                f"the run is done: the last command targeted the last step ({self.n_steps - 1})"
                if self._timed is None
                else "the run is done: the arm was brought to rest at the last step"
            )
        try:
            q = np.asarray(q_measured)
        except ValueError:  # ragged: the full check names it
            q = np.empty(0)
        if q.dtype != np.float64 or q.shape != self._lower.shape or not np.isfinite(q).all():
            # The full check (integers are converted; complex, bool, strings refused).
            q = check_array(
                q_measured, "q_measured", shape=(self._lower.shape[0],), allow_bool=False
            )
        q = np.minimum(np.maximum(q, self._lower), self._upper)
        if objects is not None:
            self._update_objects(objects)
        if self._timed is not None:
            return self._step_timed(q, self._timed)
        last = self._last
        # Phase: advance while the arm follows (docs: "The online controller").
        lag = float((np.abs(q - last.q) / self._step_bound).max())
        held = last.index > 0 and lag > self.max_lag
        j = last.index if held else last.index + 1
        step = self._step
        x: Float | None = None
        axes: Float | None = None
        if not step.needs_kinematics:
            jac = self._no_jac
        elif last.x is not None and last.jac is not None and lag == 0.0:
            # The arm at the last target exactly (fed its own commands): its f and J are known.
            x, jac, axes = last.x, last.jac, last.axes
        else:
            x, jac, axes = step.kinematics(q)
        new, x_new, jac_new, axes_new, limited = step.advance(
            j, q, x, jac if step.needs_kinematics else None, axes
        )
        if lag > 0.0 and not held:
            # The arm follows but is not at the last target: bound the step from the last
            # target too, so that the reference through consecutive commands keeps the bound.
            # (Held back, the command re-targets from where the arm is: docs.)
            bound = self._step_bound
            capped = np.minimum(np.maximum(new, last.q - bound), last.q + bound)
            capped = np.minimum(np.maximum(capped, self._lower), self._upper)
            if not np.array_equal(capped, new):
                new, x_new, jac_new, limited = capped, None, None, True
        self._last = _Targets(new, j, x_new, jac_new, axes_new if x_new is not None else None)
        return Command(self, new, j, limited, jac, held)

    def _step_timed(self, q: Float, st: _Timed) -> Command:
        """:meth:`step` with motion limits (:doc:`/reproduction`, "The online controller")."""
        held = False
        now = st.cycle * self.dt  # the time of the last command (of the measurement)
        if st.plan is None:
            # The first command starts from the measured posture, at rest.
            self._replan(st, now, (q, np.zeros_like(q), np.zeros_like(q)), 0.0)
        else:
            last = st.last  # the last command's state
            lag = float((np.abs(q - last[0]) / self._step_bound).max())
            if lag > self.max_lag:
                # A push: plan again from the measured state, the phase where it was.
                held = True
                assert st.q_measured is not None
                v = np.clip((q - st.q_measured) / self.dt, -st.velocity, st.velocity)
                self._replan(st, now, (q, v, np.zeros_like(q)), st.phase)
            elif st.moved:
                self._replan(st, now, last, st.phase)
        st.moved = False
        st.q_measured = q
        st.cycle += 1
        t = st.cycle * self.dt
        p, v, a = st.last = st.motion.at(t)
        plan = st.plan
        assert plan is not None
        res = plan.result
        # The phase at the command's time (linear between the plan's samples) and the sample
        # at or after it.
        local = t - plan.t0
        times = plan.times
        sample = min(bisect.bisect_left(times, local - 1e-9), len(times) - 1)
        if sample == 0 or local >= times[-1]:
            st.phase = plan.steps[sample]
        else:
            w = (local - times[sample - 1]) / (times[sample] - times[sample - 1])
            st.phase = plan.steps[sample - 1] + w * (plan.steps[sample] - plan.steps[sample - 1])
        st.done = t >= st.motion.end - 1e-9
        index = min(self._c.n_steps - 1, math.floor(st.phase + 1e-9))
        self._last = _Targets(p, index, None, None)
        return Command(
            self,
            p.copy(),
            index,
            bool(res.limited[sample]),
            self._no_jac,
            held,
            v,
            a,
            phase=st.phase,
            details=(plan, sample),
        )

    def _replan(
        self, st: _Timed, now: float, state: tuple[Float, Float, Float], phase: float
    ) -> None:
        """Plan from ``state`` (position, velocity, acceleration) at time ``now`` and
        ``phase``, with the object positions known now."""
        q, v, a = state
        run = dataclasses.replace(self._run, objects=dict(self._objs), theta0=q)
        moving = bool(np.any(v))
        res = timed_path(
            self._robot, run, st.limits, self.dt, phase=phase, velocity=v if moving else None
        )
        assert res.times is not None
        st.motion = follow(
            now + res.times,
            res.joints,
            st.plan_limits,
            velocities=res.velocities,
            accelerations=res.accelerations,
            start=(q, v, a),
        )
        if st.plan is not None:
            st.replans += 1
        objects = {k: o.copy() for k, o in self._objs.items()}
        # The phase follows the motion: when it reaches each sample of the plan (later than
        # the sample's time where the limits kept it behind, pbdkit.motion._otg.follow).
        reached = (st.motion.sample_times - now).tolist()
        st.plan = _Plan(res, now, objects, reached, res.t.tolist())
        st.last = (np.asarray(q), np.asarray(v), np.asarray(a))

    def _checked_objects(self, objects: Mapping[str, npt.ArrayLike]) -> dict[str, Float]:
        """An update of some objects, checked as :meth:`step` checks it (names, form, reach),
        or a ValueError; nothing is kept."""
        names = self._c.object_names
        given = check_objects(objects, names, oriented=self._c.oriented, partial=True)
        if self._run.reach is not None:
            self._check_reach(given)
        return given

    def _unchanged(self, objects: Mapping[str, npt.ArrayLike]) -> bool:
        """Every object given exactly as it is in use (float64 arrays of its stored form): a
        loop that passes the objects on every call pays for nothing until one moves."""
        objs = self._objs
        for k, v in objects.items():
            held = objs.get(k) if isinstance(k, str) else None
            if (
                held is None
                or type(v) is not np.ndarray
                or v.dtype != held.dtype
                or v.shape != held.shape
                or v.tobytes() != held.tobytes()  # bit for bit (a NaN is never held)
            ):
                return False
        return True

    def _update_objects(self, objects: Mapping[str, npt.ArrayLike]) -> None:
        if self._unchanged(objects):
            return
        # Checked before it is kept: a refused update leaves the positions as they were.
        self._apply_objects(self._checked_objects(objects))

    def _apply_objects(self, given: Mapping[str, Float]) -> None:
        """Use positions already checked (:meth:`_checked_objects`) from this step on."""
        changed = {k: v for k, v in given.items() if not np.array_equal(v, self._objs[k])}
        if not changed:
            return
        self._objs = {**self._objs, **changed}
        st = self._timed
        if st is not None:
            # The plans take the positions from here (_replan); the per-step stacks are not
            # used with motion limits.
            if st.plan is not None:
                planned = st.plan.objects
                st.moved = st.moved or any(
                    _moved(self._objs[k], planned[k], st.replan_distance) for k in changed
                )
            return
        self._step.set_objects(self._objs)

    def _check_reach(self, objs: Mapping[str, Float]) -> None:
        run = self._run
        assert run.reach is not None
        used = {k: o for k, o in objs.items() if k in self._used}
        _check_reach(used, self._c, run.reach, run.on_unreachable)

    # ------------------------------------------------------------------ command details
    def _gripper_at(self, j: int) -> bool:
        g = self._c.gripper
        return bool(g is not None and g[j] > 0.5)

    def _covariance(self, j: int, jac: Float) -> Float:
        return self._step.covariance(j, jac)

    def _influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        return self._step.influence(j, jac, cov)


@dataclass
class _Plan:
    """A plan of a controller with motion limits: the timed reproduction it follows, made at
    time ``t0`` (s from the first command) for these object positions."""

    result: ReproductionResult
    t0: float
    objects: dict[str, Float]
    times: list[float]  # when the motion reaches each sample (from t0), and its step: lists
    steps: list[float]  # for the per-step look-ups


class _Timed:
    """The state of a controller with motion limits."""

    def __init__(self, limits: MotionLimits, replan_distance: float) -> None:
        self.limits = limits
        self.plan_limits = limits.scaled(LIMIT_SAFETY)
        self.velocity = np.where(
            np.isfinite(self.plan_limits.velocity), self.plan_limits.velocity, np.inf
        )
        self.replan_distance = replan_distance
        self.plan: _Plan | None = None
        # The motion the commands are samples of (from the first command's time, 0), and how
        # many commands were given (the last one's time is cycle * dt).
        n = limits.n_joints
        self.motion = Motion(0.0, (np.zeros(n), np.zeros(n), np.zeros(n)))
        self.cycle = 0
        self.last = self.motion.at(0.0)  # the last command's state
        self.phase = 0.0
        self.moved = False
        self.replans = 0
        self.q_measured: Float | None = None
        self.done = False


class CommandStream:
    """Setpoints at a fast rate following a :class:`Controller`'s plans (``ctrl.stream(rate)``).

    Every ``1 / rate_hz`` s, :meth:`step` takes the measured posture and returns the next
    setpoint. The controller is stepped at its cycles (every ``ctrl.dt``), with the measured
    posture and the object positions given since, before any setpoint after that cycle is
    given. The setpoints are samples of the motion the controller follows (its commands are
    samples of the same motion every ``ctrl.dt``: :class:`pbdkit.motion._otg.Motion`), so they are
    one continuous jerk-limited motion, through its re-plans, consecutive ones within the limits at
    this rate. A held command (:attr:`Command.held`: a push) restarts them from the measured
    state.

    Call ``m`` (from 0) returns the setpoint for ``(m + 1) / rate_hz`` s after the first call:
    the motion starts at rest at the posture measured at the first call, one period before the
    first setpoint. A drive that checks its stream (a Franka Panda at 1 kHz) compares the first
    setpoint with the posture it holds: give the first call that posture (libfranka's desired
    posture ``q_d``, not a noisy encoder reading), and check a recorded stream with that posture
    prepended (:class:`pbdkit.motion._limits.StreamMonitor` fed it first).

    Parameters
    ----------
    controller : Controller
        With motion limits (:meth:`pbdkit.Skill.controller` gives them by default), not yet
        stepped.
    rate_hz : float
        Setpoints per second (e.g. 1000), at least one per controller step.

    Attributes
    ----------
    done : bool
        True once the controller is done and the setpoints have come to rest at its end.
    rate : float
    velocity, acceleration : ndarray, shape (n,)
        Of the last setpoint (e.g. as a servo's velocity feed-forward).
    command : Command or None
        The controller's last command.
    """

    def __init__(self, controller: Controller, rate_hz: float) -> None:
        rate = float(rate_hz)
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate_hz must be a positive number of Hz, got {rate_hz!r}")
        if controller.limits is None or controller._timed is None:
            raise ValueError(
                "the controller has no motion limits: a stream needs them (give the robot "
                "acceleration and jerk limits, e.g. Robot.from_urdf(..., joint_limits=YAML))"
            )
        if controller._timed.plan is not None:
            raise ValueError("the controller has already run: make a new one for the stream")
        if rate * controller.dt < 1.0:
            raise ValueError(
                f"rate_hz must give at least one setpoint per controller step "
                f"(>= {1.0 / controller.dt:.6g} Hz), got {rate_hz!r}"
            )
        self.controller = controller
        self.rate = rate
        self.period = 1.0 / rate
        self._timed = controller._timed
        self._ticks = 0  # setpoints given
        self._cycles = 0  # controller steps made
        self._state: tuple[Float, Float, Float] | None = None
        self._pending: dict[str, Float] = {}
        self.command: Command | None = None

    @property
    def done(self) -> bool:
        """The controller is done and the setpoints have come to rest at the end of its
        motion."""
        return self.controller.done and self._ticks * self.period >= self._timed.motion.end - 1e-9

    @property
    def velocity(self) -> Float:
        return np.zeros(self.controller._lower.shape[0]) if self._state is None else self._state[1]

    @property
    def acceleration(self) -> Float:
        return np.zeros(self.controller._lower.shape[0]) if self._state is None else self._state[2]

    def step(
        self, q_measured: npt.ArrayLike, objects: Mapping[str, npt.ArrayLike] | None = None
    ) -> Float:
        """The next setpoint (n,), from the measured posture.

        ``objects`` (any subset of the skill's objects) reach the controller at its next step.
        They are checked in this call, as :meth:`Controller.step` checks them (and only here):
        an unknown object, a wrong form or a position beyond the arm's reach raises ValueError
        here, and the stream goes on with the last accepted positions.
        """
        ctrl = self.controller
        q = check_array(q_measured, "q_measured", shape=(ctrl._lower.shape[0],), allow_bool=False)
        if objects is not None:
            self._pending.update(ctrl._checked_objects(objects))
        if self.done:
            raise ValueError("the stream is done: its setpoints came to rest at the end")
        t = (self._ticks + 1) * self.period  # the time of the setpoint to give
        # The controller decides at its cycles (plans again, holds), before any setpoint after
        # that cycle is given: the setpoints are samples of the motion it plans.
        while not ctrl.done and self._cycles * ctrl.dt < t - 1e-12:
            if self._pending:
                ctrl._apply_objects(self._pending)
                self._pending = {}
            self.command = ctrl.step(q)
            self._cycles += 1
        self._ticks += 1
        p, v, a = self._timed.motion.at(t)
        self._state = (p, v, a)
        return p.copy()
