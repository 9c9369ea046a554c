"""Setpoints at a fast rate following an online controller's plans (:class:`CommandStream`,
``ctrl.stream(rate_hz)``)."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, short
from ..motion._limits import MotionLimits, last_differences
from ._command import Command
from ._planner import Planner, PlannerKind
from ._plans import _Timed

__all__ = ["CommandStream", "LimitViolation"]

Float = NDArray[np.float64]


class _Controller(Protocol):
    """What a stream asks of its controller (:class:`pbdkit.reproduction.Controller`)."""

    dt: float
    _timed: _Timed | None
    _lower: Float

    @property
    def done(self) -> bool: ...

    @property
    def limits(self) -> MotionLimits | None: ...

    @property
    def fault(self) -> str | None: ...

    def step(
        self, q_measured: npt.ArrayLike, objects: Mapping[str, npt.ArrayLike] | None = None
    ) -> Command: ...

    def close(self) -> None: ...

    def _use_planner(self, planner: PlannerKind | Planner) -> None: ...

    def _unchanged(
        self, objects: Mapping[str, npt.ArrayLike], pending: Mapping[str, Float] | None = None
    ) -> bool: ...

    def _checked_objects(self, objects: Mapping[str, npt.ArrayLike]) -> dict[str, Float]: ...

    def _apply_objects(self, given: Mapping[str, Float]) -> None: ...

    def _service(self, st: _Timed, now: float) -> None: ...

    def _guard(
        self, p: Float, v: Float, a: Float
    ) -> tuple[Float, Float, Float, NDArray[np.bool_] | None]: ...


@dataclass(frozen=True)
class LimitViolation:
    """A setpoint whose divided difference exceeds a motion limit because a joint was stopped
    on its position limit (:attr:`CommandStream.limit_violations`).

    Attributes
    ----------
    time : float
        The setpoint's time (s from the stream's start, one period before the first setpoint).
    joint : int
    quantity : {"velocity", "acceleration", "jerk"}
    ratio : float
        Over the limit (> 1).
    """

    time: float
    joint: int
    quantity: str
    ratio: float


class CommandStream:
    """Setpoints at a fast rate following a :class:`Controller`'s plans (``ctrl.stream(rate)``).

    Every ``1 / rate_hz`` s, :meth:`step` takes the measured posture and returns the next
    setpoint. The controller is stepped at its cycles (every ``ctrl.dt``), with the measured
    posture and the object positions given since, before any setpoint after that cycle is
    given. The setpoints are samples of the motion the controller follows (its commands are
    samples of the same motion every ``ctrl.dt``: :class:`pbdkit.motion._motion.Motion`), so
    they are one continuous jerk-limited motion, through its re-plans, consecutive ones within
    the limits at this rate, and within the joint limits. A held command (:attr:`Command.held`:
    a push) restarts them from the measured state, braking as hard as the limits allow; a joint
    the brake cannot stop before its limit is stopped on it (:attr:`at_position_limit`, and the
    excess that forces in :attr:`limit_violations`).

    Call ``m`` (from 0) returns the setpoint for ``(m + 1) / rate_hz`` s after the first call:
    the motion starts at rest at the posture measured at the first call, one period before the
    first setpoint. A drive that checks its stream (a Franka Panda at 1 kHz) compares the first
    setpoint with the posture it holds: give the first call that posture (libfranka's desired
    posture ``q_d``, not a noisy encoder reading), and check a recorded stream with that posture
    prepended (:class:`pbdkit.motion._limits.StreamMonitor` fed it first).

    The plans are made in a separate process by default (``planner="process"``): no call waits
    for one. Until a new plan is ready the setpoints continue the current motion (at rest at the
    first posture before the first plan, 30-150 ms); it takes over at a hand-over time predicted
    from the planner's latency, from the state the setpoints are in then, so that they stay
    continuous in position, velocity and acceleration. After a push the setpoints brake from the
    measured state until the new plan takes over. ``close()`` (or ``with ctrl.stream(...) as
    stream``, or the controller's collection) ends the process.

    Parameters
    ----------
    controller : Controller
        With motion limits (:meth:`pbdkit.Skill.controller` gives them by default), not yet
        stepped.
    rate_hz : float
        Setpoints per second (e.g. 1000), at least one per controller step.
    planner : {"process", "inline"}, optional
        Where the plans are made (:meth:`Controller.stream`); None: as the controller was built.

    Attributes
    ----------
    done : bool
        True once the controller is done and the setpoints have come to rest at its end.
    rate : float
    velocity, acceleration : ndarray, shape (n,)
        Of the last setpoint (e.g. as a servo's velocity feed-forward).
    command, last_command : Command or None
        The controller's last command (the same object). Its ``at_position_limit`` also marks
        the joints a setpoint since was stopped on a joint limit.
    at_position_limit : ndarray of bool, shape (n,)
        The joints the last setpoint stopped on a joint limit (the motion would have crossed
        it: a push toward it that the brake could not stop in the room left).
    limit_violations : list of LimitViolation
        Each velocity, acceleration or jerk excess a stop on a joint limit forced (divided
        differences of consecutive setpoints at this rate): the only excess the setpoints
        have. Precedence: joint position limits, then velocity, then jerk, then acceleration.
    """

    def __init__(
        self,
        controller: _Controller,
        rate_hz: float,
        planner: PlannerKind | Planner | None = "process",
    ) -> None:
        rate = float(rate_hz)
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate_hz must be a positive number of Hz, got {short(rate_hz)}")
        if controller.limits is None or controller._timed is None:
            raise ValueError(
                "the controller has no motion limits: a stream needs them (give the robot "
                "acceleration and jerk limits, e.g. Robot.from_urdf(..., joint_limits=YAML))"
            )
        if controller._timed.cycle > 0:
            raise ValueError("the controller has already run: make a new one for the stream")
        if rate * controller.dt < 1.0:
            raise ValueError(
                f"rate_hz must give at least one setpoint per controller step "
                f"(>= {1.0 / controller.dt:.6g} Hz), got {short(rate_hz)}"
            )
        if planner is not None and not (
            isinstance(planner, str) and planner == controller._timed.planner.kind
        ):
            controller._use_planner(planner)
        self.controller = controller
        self.rate = rate
        self.period = 1.0 / rate
        self._timed = controller._timed
        self._ticks = 0  # setpoints given
        self._cycles = 0  # controller steps made
        self._state: tuple[Float, Float, Float] | None = None
        self._pending: dict[str, Float] = {}
        self.command: Command | None = None
        n = controller._lower.shape[0]
        self.at_position_limit = np.zeros(n, dtype=bool)
        self.limit_violations: list[LimitViolation] = []
        # The last four setpoints, and the ticks since one was stopped on a limit (the
        # divided differences are checked while one is in their window).
        self._recent: deque[Float] = deque(maxlen=4)
        self._since_stop = 4
        self._started = False  # the first setpoint was given (its rest before it counted)
        limits = controller.limits
        self._bounds = (limits.velocity, limits.acceleration, limits.jerk)

    @property
    def last_command(self) -> Command | None:
        """The controller's last command (:attr:`command`)."""
        return self.command

    @property
    def done(self) -> bool:
        """The controller is done and the setpoints have come to rest at the end of its
        motion."""
        return self._finished()

    def _finished(self) -> bool:
        return self.controller.done and self._ticks * self.period >= self._timed.motion.end - 1e-9

    @property
    def fault(self) -> str | None:
        """Why the stream brought the arm to rest (:attr:`Controller.fault`), or None."""
        return self.controller.fault

    def close(self) -> None:
        """End the planner process (the stream can go on, planning inline)."""
        self.controller.close()

    def __enter__(self) -> CommandStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

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
        if objects is not None and not ctrl._unchanged(objects, self._pending):
            self._pending.update(ctrl._checked_objects(objects))
        if self.done:
            raise ValueError("the stream is done: its setpoints came to rest at the end")
        t = (self._ticks + 1) * self.period  # the time of the setpoint to give
        # The controller decides at its cycles (plans again, holds), before any setpoint after
        # that cycle is given: the setpoints are samples of the motion it plans.
        while not ctrl.done and self._cycles * ctrl.dt < t - 1e-12:
            self._hand_over_objects()
            self.command = ctrl.step(q)
            self._cycles += 1
            if self.command.held:  # a push: the setpoints restart from the measured state
                self._recent.clear()
                self._started = True
        st = self._timed
        if st.planner.kind == "process" and self._cycles > 0:
            # Between the controller's cycles too: a moved object is planned for, and a plan
            # that is ready taken, at once (the setpoints given so far reach ticks * period).
            self._hand_over_objects()
            ctrl._service(st, self._ticks * self.period)
        self._ticks += 1
        p, v, a, stopped = ctrl._guard(*self._timed.motion.at(t))
        self._state = (p, v, a)
        if not self._started:  # at rest at the first posture before the first setpoint
            self._recent.extend([st.motion.at(0.0)[0]] * 3)
            self._started = True
        self._recent.append(p)
        if stopped is not None:
            self._since_stop = 0
            self.at_position_limit = stopped
            if self.command is not None:
                self.command.at_position_limit |= stopped
        else:
            self._since_stop += 1
            if self.at_position_limit.any():
                self.at_position_limit = np.zeros_like(self.at_position_limit)
        if self._since_stop < 4 and len(self._recent) == 4:
            self._check_forced(t)
        return p.copy()

    def _hand_over_objects(self) -> None:
        """Give the controller the object positions checked since its last step."""
        if self._pending:
            self.controller._apply_objects(self._pending)
            self._pending = {}

    def _check_forced(self, t: float) -> None:
        """Record the excess of the last setpoints' divided differences (a stop on a joint
        limit in their window)."""
        diffs = last_differences(list(self._recent), self.period)
        for quantity, d, lim in zip(
            ("velocity", "acceleration", "jerk"), diffs, self._bounds, strict=True
        ):
            ratio = np.abs(d) / lim
            for j in np.flatnonzero(ratio > 1.0 + 1e-9):
                self.limit_violations.append(LimitViolation(t, int(j), quantity, float(ratio[j])))
