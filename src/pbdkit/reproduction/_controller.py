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

import dataclasses
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import log3
from .._validation import check_array, short
from ..data._placement import position_of, rotation_of
from ..motion._limits import MotionLimits, RetimeWarning
from ..motion._motion import Motion, brake
from ..motion._otg import join
from ..robots._protocols import KinematicModel
from ._command import Command
from ._constraints import Constraints
from ._planner import (
    InlinePlanner,
    Planner,
    PlannerKind,
    PlanRequest,
    ProcessPlanner,
)
from ._plans import _Handover, _Plan, _Timed
from ._probabilistic_ik import CollisionWarning, SceneRun
from ._setup import RunOptions, _check_reach, check_objects, setup_run
from ._stream import CommandStream
from ._table_ii import make_step
from ._timing import check_timing

__all__ = [
    "PLANNERS",
    "REPLAN_ANGLE",
    "REPLAN_DISTANCE",
    "Command",
    "CommandStream",
    "Controller",
    "PlanFailedWarning",
]

#: With motion limits, an object that moves farther than this (m) from the position the plan
#: was made for makes the controller plan again (:doc:`/reproduction`, "The online
#: controller"): about twice the cameras' noise (pbdkit.sim._tracking: 0.6 mm), a tenth of the
#: coaster task's tolerance.
REPLAN_DISTANCE = 1e-3
#: With motion limits, an object whose pose turns farther than this (rad) from the one the plan
#: was made for makes the controller plan again: 1 mm at 0.1 m from its origin, as
#: :data:`REPLAN_DISTANCE`.
REPLAN_ANGLE = 1e-2

#: Where the plans of a controller with motion limits are made: in a separate process (the loop
#: never waits for one) or where they are needed (:mod:`pbdkit.reproduction._planner`).
PLANNERS: tuple[PlannerKind, ...] = ("process", "inline")
#: With the process planner: the hand-over of the first plans is predicted this far ahead (s),
#: then from the planner's measured latencies (:meth:`Controller._lead`).
FIRST_LEAD = 0.1
#: The hand-over is predicted this many times the planner's longest recent latency (per step
#: planned, times the steps the new plan makes) ahead, plus :data:`LEAD_MARGIN` s.
LEAD_FACTOR = 1.25
LEAD_MARGIN = 0.005
#: A plan whose reply comes after its hand-over time is joined from the commands' state by a
#: jerk-limited segment lasting the first of these (s) it can (:func:`pbdkit.motion._otg.join`);
#: where none can, it is asked for again, further ahead.
LATE_JOINS = (0.02, 0.04, 0.07, 0.1, 0.15, 0.2)

Float = NDArray[np.float64]


#: The warnings a plan may raise, said again by the controller (:class:`PlanReply` notes).
_WARNINGS: dict[str, type[Warning]] = {"RetimeWarning": RetimeWarning}


class PlanFailedWarning(RuntimeWarning):
    """A plan of the online controller could not be made: the arm is brought to rest
    (:attr:`Controller.fault` says why)."""


def _moved(now: Float, planned: Float, distance: float) -> bool:
    """Whether an object moved by more than ``distance`` (m) or turned by more than
    :data:`REPLAN_ANGLE` from ``planned`` (both positions (3,) or both poses (4, 4))."""
    if float(np.linalg.norm(position_of(now) - position_of(planned))) > distance:
        return True
    rot, ref = rotation_of(now), rotation_of(planned)
    if rot is None or ref is None:
        return False
    return float(np.linalg.norm(log3(rot @ ref.T))) > REPLAN_ANGLE


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
    planner : {"inline", "process"}
        With motion limits, where its plans are made (:doc:`/reproduction`, "Plans off the
        control loop"). "inline" (default): in :meth:`step`, which then waits for them (25-150
        ms on the coaster skill), and a run depends only on its inputs (a simulation). "process":
        in a separate process started here (1-3 s), :meth:`step` never waits for one: until a
        plan is ready the commands continue the current motion, and it takes over at a
        hand-over time predicted from the planner's latency, from the state the commands are
        in then. Call :meth:`close` (or let the controller be collected) to end the process.
    scene : SceneRun, optional
        With motion limits: every plan is checked against this scene and, with its ``avoid``,
        keeps its margin (:doc:`/collisions`); a plan that would still collide is not
        followed: the arm is brought to rest and :attr:`fault` says why.

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
    handover_delay : float
        With the process planner: seconds added to every predicted hand-over (default 0), the
        longest the commands take to reach the arm's controller (``pbdkit ros run
        --latency``): a new plan then diverges from the commands already sent only after
        they have arrived.
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
        planner: PlannerKind = "inline",
        scene: SceneRun | None = None,
    ) -> None:
        if planner not in PLANNERS:
            raise ValueError(f"planner must be one of {PLANNERS}, got {short(planner)}")
        timed = check_timing(limits, dt)
        if scene is not None and not timed:
            raise ValueError(
                "a controller keeps clear of a scene with motion limits (its plans): pass "
                "the robot's limits, or check the commands with skill.check"
            )
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
            raise ValueError(f"max_lag must be > 0 (steps), got {short(max_lag)}")
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
        self.handover_delay = 0.0
        if timed:
            assert limits is not None
            distance = float(replan_distance)
            if not (distance >= 0):
                raise ValueError(f"replan_distance must be >= 0 (m), got {short(replan_distance)}")
            self._timed = _Timed(limits, distance, robot, run, self.dt, scene)
            if planner != "inline":
                self._use_planner(planner)
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

    @property
    def fault(self) -> str | None:
        """Why the controller brought the arm to rest, in one line (a plan that could not be
        made, the planner process gone); None while it runs normally."""
        return None if self._timed is None else self._timed.fault

    @property
    def planner(self) -> PlannerKind | None:
        """Where the plans are made ("inline" or "process"; None without motion limits)."""
        return None if self._timed is None else self._timed.planner.kind

    def stream(
        self, rate_hz: float, planner: PlannerKind | Planner | None = "process"
    ) -> CommandStream:
        """Setpoints at ``rate_hz`` following this controller's plans (see
        :class:`CommandStream`); this controller must not have been stepped yet.

        ``planner``: where the plans are made from now on ("process", the default: the loop
        never waits for a plan; "inline": in the call that needs one, as :meth:`step` by
        default; None: as this controller was built).
        """
        return CommandStream(self, rate_hz, planner)

    def close(self) -> None:
        """End the planner process, if any (the controller then plans inline)."""
        st = self._timed
        if st is not None and st.planner.kind == "process":
            st.planner.close()
            self._use_planner("inline")

    def _use_planner(self, planner: PlannerKind | Planner) -> None:
        st = self._timed
        assert st is not None
        if isinstance(planner, Planner):
            new: Planner = planner
        elif planner not in PLANNERS:
            raise ValueError(f"planner must be one of {PLANNERS}, got {short(planner)}")
        elif planner == "process":
            new = ProcessPlanner(st.setup)
        else:
            new = InlinePlanner(st.setup)
        old, st.planner = st.planner, new
        if old is not new:
            old.close()

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

    def _command(self, q: Float, st: _Timed, held: bool) -> Command:
        """The command at the next cycle: the motion's state then, and the phase of the plan
        in use (held where none is: before the first plan, braking after a push)."""
        st.q_measured = q
        st.cycle += 1
        t = st.cycle * self.dt
        handover = st.handover
        if handover is not None and t >= handover[0] - 1e-9:
            # The new plan takes over (from its hand-over time on: the setpoints of a stream
            # before it, up to this command, still sample the motion before it).
            st.plan, st.handover = handover[1], None
            st.active, st.braking = True, False
        p, v, a, stopped = self._guard(*st.motion.at(t))
        st.last = (p, v, a)
        plan = st.plan
        details: tuple[_Plan, int] | None = None
        limited = False
        if plan is not None and st.active:
            st.phase, sample = plan.phase_at(t)
            limited = bool(plan.result.limited[sample])
            details = (plan, sample)
        st.done = (
            t >= st.motion.end - 1e-9
            and st.handover is None
            and (st.fault is not None or (st.active and st.pending is None and not st.want))
        )
        index = min(self._c.n_steps - 1, math.floor(st.phase + 1e-9))
        self._last = _Targets(p, index, None, None)
        return Command(
            self,
            p.copy(),
            index,
            limited,
            self._no_jac if details is not None else None,
            held,
            v,
            a,
            phase=st.phase,
            details=details,
            at_position_limit=stopped,
        )

    # ------------------------------------------------------------------ with motion limits
    def _step_timed(self, q: Float, st: _Timed) -> Command:
        """:meth:`step` with motion limits (:doc:`/reproduction`, "The online controller"):
        with the process planner, no call waits for a plan ("Plans off the control
        loop")."""
        held = False
        now = st.cycle * self.dt
        motion = st.motion
        if isinstance(motion, _Handover) and now >= motion.t0 - 1e-9:
            st.motion = motion.new  # the hand-over is past
        if st.cycle == 0:
            # At rest where measured until the first plan takes over.
            st.motion = Motion(now, (q, np.zeros_like(q), np.zeros_like(q)))
            st.last = st.motion.at(now)
            st.want = True
        elif st.fault is None:
            lag = float((np.abs(q - st.last[0]) / self._step_bound).max())
            if lag > self.max_lag:
                # A push: brake from the measured state as hard as the limits allow, the phase
                # held, and plan again from where the brake stops (a reply on its way is void).
                held = True
                assert st.q_measured is not None
                v = np.clip((q - st.q_measured) / self.dt, -st.velocity, st.velocity)
                st.motion = brake(now, (q, v, np.zeros_like(q)), st.plan_limits)
                st.last = st.motion.at(now)
                st.handover, st.active, st.braking = None, False, True
                st.generation += 1
                st.want = True
        self._service(st, now)
        return self._command(q, st, held)

    def _service(self, st: _Timed, now: float) -> None:
        """Take a plan that is ready, and ask for one where wanted (an object moved, a push,
        a late plan), one at a time (``now``: the time of the last command or setpoint
        given)."""
        if st.pending is not None:
            self._receive(st, now)
        if st.moved:
            st.want, st.moved = True, False
        if st.want and st.pending is None and st.handover is None and st.fault is None:
            self._request(st, now)
            if st.planner.kind == "inline":
                self._receive(st, now)  # made in the request: it takes over now

    def _steps_left(self, phase: float) -> float:
        """The steps a plan from ``phase`` makes (its cost is about proportional to them)."""
        return max(1.0, self._c.n_steps - phase)

    def _lead(self, st: _Timed) -> float:
        """Seconds from a request to its hand-over: 0 inline; else :data:`LEAD_FACTOR` times
        the planner's longest latency per step of its last five plans, times the steps left,
        plus :data:`LEAD_MARGIN` (a plan's cost is about proportional to the steps it makes: the
        first, the whole skill, takes twice as long as one from halfway);
        :data:`FIRST_LEAD` before any; plus :attr:`handover_delay`."""
        if st.planner.kind == "inline":
            return 0.0
        if not st.latencies:
            return FIRST_LEAD + self.handover_delay
        lead = LEAD_FACTOR * max(st.latencies) * self._steps_left(st.phase) + LEAD_MARGIN
        return lead + self.handover_delay

    def _request(self, st: _Timed, now: float) -> None:
        """Ask the planner for a plan taking over at a predicted hand-over time, from the state
        and phase the commands will be in then."""
        motion = st.motion
        t0 = now  # at rest, the state is the same at any time: the plan starts when ready
        if not motion.at_rest_after(now):
            t0 = now + self._lead(st)
            if st.braking:  # after a push, from where the brake stops
                t0 = max(t0, motion.end)
        p, v, a = motion.at(t0)
        if motion.at_rest_after(t0):
            v, a = np.zeros_like(p), np.zeros_like(p)
        p, v, a, _ = self._guard(p, v, a)
        phase = st.plan.phase_at(t0)[0] if st.plan is not None and st.active else st.phase
        objects = {k: o.copy() for k, o in self._objs.items()}
        st.planned_objects = objects
        st.pending = (PlanRequest(st.generation, t0, (p, v, a), phase, objects), now)
        st.want = False
        st.planner.submit(st.pending[0])

    def _receive(self, st: _Timed, now: float) -> None:
        """Take the planner's reply, if it is ready (``now``: the time of the last command or
        setpoint given): the plan takes over at its hand-over time; a late one, or one for a
        state given up, is asked for again."""
        reply = st.planner.poll()
        if reply is None:
            return
        assert st.pending is not None
        request, asked = st.pending
        st.pending = None
        st.latencies.append((now - asked) / self._steps_left(request.phase))
        if reply.generation == -1:  # the planner process is gone
            assert reply.error is not None
            self._fault(st, now, reply.error)
            return
        if reply.generation != st.generation:
            st.want = True  # made for a state given up (a push since)
            return
        if reply.error is not None:
            if reply.collides and st.plan is not None and st.active and not st.braking:
                # A re-plan (an object moved) that would collide: the plan in use was checked
                # and is kept; said, not followed (docs: "Collisions").
                st.refused += 1
                warnings.warn(
                    f"the controller keeps its plan: {reply.error}", CollisionWarning, stacklevel=4
                )
                return
            self._fault(st, now, reply.error)
            return
        for category, message in reply.notes:  # said where the plan was made: said here too
            warnings.warn(message, _WARNINGS.get(category, RuntimeWarning), stacklevel=4)
        assert reply.motion is not None and reply.result is not None
        t0 = reply.t0
        motion: Motion | _Handover = reply.motion
        start = now + self.handover_delay  # the commands sent until then are the arm's
        if t0 < start - 1e-9:
            if st.motion.at_rest_after(t0):
                # Made from rest, and still there: it starts now (the delay on).
                moved = reply.motion.shifted(start - t0)
                reply = dataclasses.replace(reply, t0=start, motion=moved)
                t0, motion = start, moved
            else:
                # Late: joined from where the commands are by a short segment onto it, where
                # one within the limits exists; else asked again, further ahead (the latency is
                # measured).
                p, v, a, _ = self._guard(*st.motion.at(start))
                run = st.setup.run
                bounds = (np.minimum(run.lower, p), np.maximum(run.upper, p))
                joined = join(start, (p, v, a), reply.motion, st.plan_limits, LATE_JOINS, bounds)
                if joined is None:
                    st.want = True
                    return
                assert reply.motion is not None
                t0, motion = start, _Handover(joined, reply.motion, joined.end)
                st.joins += 1
        plan = _Plan.of(reply, request.objects)
        if st.plan is not None:
            st.replans += 1
        st.handover = (t0, plan, motion)
        st.motion = _Handover(st.motion, motion, t0)

    def _guard(
        self, p: Float, v: Float, a: Float
    ) -> tuple[Float, Float, Float, NDArray[np.bool_] | None]:
        """A state of the motion within the joint limits: a joint beyond one stopped on it
        (velocity and acceleration 0), and which joints were (None: none)."""
        lower, upper = self._lower, self._upper
        out = (p < lower) | (p > upper)
        if not out.any():
            return p, v, a, None
        p = np.minimum(np.maximum(p, lower), upper)
        return p, np.where(out, 0.0, v), np.where(out, 0.0, a), out

    def _fault(self, st: _Timed, now: float, reason: str) -> None:
        """No plan: bring the arm to rest from where the commands are at ``now``, and say
        why."""
        st.fault = reason
        start = now + self.handover_delay  # the commands sent until then are the arm's
        stop = brake(start, st.motion.at(start), st.plan_limits)
        st.motion = stop if start == now else _Handover(st.motion, stop, start)
        st.last = st.motion.at(now)
        st.handover, st.active, st.want = None, False, False
        warnings.warn(
            f"the controller could not plan ({reason}): the arm is brought to rest",
            PlanFailedWarning,
            stacklevel=4,
        )

    def _jacobian_at(self, q: Float) -> Float:
        """J at q, the per-step stacks set to the objects in use (the details of a command
        made without a plan)."""
        step = self._step
        if not step.needs_kinematics:
            return self._no_jac
        step.set_objects(self._objs)
        return step.kinematics(q)[1]

    def _checked_objects(self, objects: Mapping[str, npt.ArrayLike]) -> dict[str, Float]:
        """An update of some objects, checked as :meth:`step` checks it (names, form, reach),
        or a ValueError; nothing is kept."""
        names = self._c.object_names
        given = check_objects(objects, names, oriented=self._c.oriented, partial=True)
        if self._run.reach is not None:
            self._check_reach(given)
        return given

    def _unchanged(
        self, objects: Mapping[str, npt.ArrayLike], pending: Mapping[str, Float] | None = None
    ) -> bool:
        """Every object given exactly as it is in use (or in ``pending``, checked and not yet
        in use; float64 arrays of its stored form): a loop that passes the objects on every
        call pays for nothing until one moves."""
        objs = {**self._objs, **pending} if pending else self._objs
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
            planned = st.planned_objects
            if planned is not None:
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
