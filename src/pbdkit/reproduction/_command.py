"""One command of an online controller (:class:`Command`)."""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ._plans import _Plan

__all__ = ["Command"]

Float = NDArray[np.float64]


class _Source(Protocol):
    """What a command asks of the controller that gave it."""

    def _gripper_at(self, j: int) -> bool: ...

    def _jacobian_at(self, q: Float) -> Float: ...

    def _covariance(self, j: int, jac: Float) -> Float: ...

    def _influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]: ...


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
    at_position_limit : ndarray of bool, shape (n,)
        With motion limits: the joints the command stopped on a joint limit, where the motion
        would have crossed it (after a push toward it: the brake could not stop in the room
        left). Its velocity and acceleration there are 0; the acceleration and jerk this
        forces is the stream's :attr:`~pbdkit.reproduction.CommandStream.limit_violations`.
        All False without motion limits (the commands are clipped to the limits).
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
        controller: _Source,
        q: Float,
        index: int,
        limited: bool,
        jac: Float | None,
        held: bool = False,
        velocity: Float | None = None,
        acceleration: Float | None = None,
        phase: float | None = None,
        details: tuple[_Plan, int] | None = None,
        at_position_limit: NDArray[np.bool_] | None = None,
    ) -> None:
        self.q = q
        self.index = index
        self.limited = limited
        self.held = held
        self.velocity = velocity
        self.acceleration = acceleration
        self.phase = float(index) if phase is None else phase
        self.at_position_limit = (
            np.zeros(q.shape[0], dtype=bool) if at_position_limit is None else at_position_limit
        )
        self.gripper = controller._gripper_at(index)
        self._ctrl = controller
        # The Jacobian the step was linearized with (None: f and J at q, when first needed).
        self._jac = jac
        self._details = details  # with motion limits: the plan and its sample at this command

    @cached_property
    def _jacobian(self) -> Float:
        if self._jac is None:
            return self._ctrl._jacobian_at(self.q)
        return self._jac

    @cached_property
    def covariance(self) -> Float:
        if self._details is not None:
            plan, i = self._details
            return np.array(plan.result.covariances[i], dtype=np.float64)
        return self._ctrl._covariance(self.index, self._jacobian)

    @cached_property
    def influence(self) -> dict[str, float]:
        if self._details is not None:
            plan, i = self._details
            return {k: float(v[i]) for k, v in plan.result.influence.items()}
        return self._ctrl._influence(self.index, self._jacobian, self.covariance)

    def __repr__(self) -> str:
        return f"Command(index={self.index}, q={np.round(self.q, 4).tolist()})"
