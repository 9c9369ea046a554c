"""The state of an online controller with motion limits (:mod:`pbdkit.reproduction._controller`):
the plan it follows (:class:`_Plan`), a plan waiting for its hand-over (:class:`_Handover`), and
the rest of its state (:class:`_Timed`)."""

from __future__ import annotations

import bisect
import collections
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..motion._limits import LIMIT_SAFETY, MotionLimits
from ..motion._motion import Motion
from ..robots._protocols import KinematicModel
from ._planner import InlinePlanner, Planner, PlanReply, PlanRequest, PlanSetup
from ._probabilistic_ik import SceneRun
from ._result import ReproductionResult
from ._setup import RunSetup

__all__ = ["_Handover", "_Plan", "_Timed"]

Float = NDArray[np.float64]


@dataclass
class _Plan:
    """A plan of a controller with motion limits: the timed reproduction it follows, made at
    time ``t0`` (s from the first command) for these object positions."""

    result: ReproductionResult
    t0: float
    objects: dict[str, Float]
    times: list[float]  # when the motion reaches each sample (from t0), and its step: lists
    steps: list[float]  # for the per-step look-ups

    @classmethod
    def of(cls, reply: PlanReply, objects: dict[str, Float]) -> _Plan:
        """The plan of a planner's reply (its motion from ``reply.t0``)."""
        assert reply.result is not None and reply.motion is not None
        t0 = reply.t0
        # The phase follows the motion: when it reaches each sample of the plan (later than
        # the sample's time where the limits kept it behind, pbdkit.motion._otg.follow).
        reached = (reply.motion.sample_times - t0).tolist()
        return cls(reply.result, t0, objects, reached, reply.result.t.tolist())

    def phase_at(self, t: float) -> tuple[float, int]:
        """The skill's phase at time ``t`` (linear between the plan's samples), and the sample
        at or after it."""
        local = t - self.t0
        times = self.times
        sample = min(bisect.bisect_left(times, local - 1e-9), len(times) - 1)
        if sample == 0 or local >= times[-1]:
            return self.steps[sample], sample
        w = (local - times[sample - 1]) / (times[sample] - times[sample - 1])
        steps = self.steps
        return steps[sample - 1] + w * (steps[sample] - steps[sample - 1]), sample


class _Handover:
    """The motion of the commands while a new plan waits for its hand-over time: the current
    motion before it, the new plan's from it on (continuous: the new one starts in the state
    the current one is in then)."""

    def __init__(self, current: Motion | _Handover, new: Motion | _Handover, t0: float) -> None:
        self.current, self.new, self.t0 = current, new, t0

    @property
    def end(self) -> float:
        return self.new.end

    def at(self, t: float) -> tuple[Float, Float, Float]:
        return self.current.at(t) if t < self.t0 else self.new.at(t)

    def at_rest_after(self, t: float) -> bool:
        return self.new.at_rest_after(max(t, self.t0))


class _Timed:
    """The state of a controller with motion limits."""

    def __init__(
        self,
        limits: MotionLimits,
        replan_distance: float,
        robot: KinematicModel,
        run: RunSetup,
        dt: float,
        scene: SceneRun | None = None,
    ) -> None:
        self.limits = limits
        self.plan_limits = limits.scaled(LIMIT_SAFETY)
        self.setup = PlanSetup(robot, run, limits, self.plan_limits, dt, scene)
        self.velocity = np.where(
            np.isfinite(self.plan_limits.velocity), self.plan_limits.velocity, np.inf
        )
        self.replan_distance = replan_distance
        self.planner: Planner = InlinePlanner(self.setup)
        # The plan the phase follows (with ``active``: not while braking after a push), the
        # objects of the last plan asked for, and a plan waiting for its hand-over time.
        self.plan: _Plan | None = None
        self.active = False
        self.braking = False  # after a push, until the next plan takes over
        self.planned_objects: dict[str, Float] | None = None
        self.handover: tuple[float, _Plan, Motion | _Handover] | None = None
        # The motion the commands are samples of (from the first command's time, 0), and how
        # many commands were given (the last one's time is cycle * dt).
        n = limits.n_joints
        self.motion: Motion | _Handover = Motion(0.0, (np.zeros(n), np.zeros(n), np.zeros(n)))
        self.cycle = 0
        self.last = self.motion.at(0.0)  # the last command's state
        self.phase = 0.0
        self.moved = False
        self.replans = 0
        self.joins = 0  # late plans joined (:data:`~._controller.LATE_JOINS`)
        self.refused = 0  # re-plans that would collide, not followed (the plan in use kept)
        self.q_measured: Float | None = None
        self.done = False
        self.fault: str | None = None
        # The process planner: the request on its way (and the cycle it was made at), whether
        # one is wanted, the number of the state plans start from (a push starts a new one),
        # and the last latencies (s of the controller's clock from a request to its reply, per
        # step the plan made).
        self.pending: tuple[PlanRequest, float] | None = None
        self.want = False
        self.generation = 0
        self.latencies: collections.deque[float] = collections.deque(maxlen=5)
