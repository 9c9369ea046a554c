"""Online control: a skill's Table II loop run step by step from the measured joint angles.

:meth:`pbdkit.Skill.reproduce` computes a whole trajectory from object positions seen once. A
real arm is controlled step by step: :meth:`pbdkit.Skill.controller` returns a
:class:`Controller` whose :meth:`Controller.step` closes the loop of Table II on the measured
posture q and returns the next target. Each call runs the same step as the offline
reproduction (:class:`pbdkit.reproduce.FusedStep`, :class:`~pbdkit.reproduce.TaskStep`,
:class:`~pbdkit.reproduce.JointStep`), linearized at q instead of at the previous target: fed
its own targets with constant objects, a controller reproduces :meth:`Skill.reproduce` step for
step. Objects may move: ``step(q, objects={...})`` updates any subset of the positions from
that step on (the tracker's 15 Hz updates in between steps keep the last ones).

Timing and phase. Step j of the skill's time grid is meant to be reached ``dt`` seconds after
step j - 1 (:attr:`Controller.dt`: the demonstrations' mean duration spread over the steps, as
:meth:`Skill.times`). Table II indexes the constraints by time, so a controller that advanced
one step per call whatever the arm does would race ahead of an arm that is held back (a push,
a joint at its velocity limit): the constraints would move on to a phase the arm has not
reached. The phase therefore advances by one step per call only while the arm follows: when
the measured posture is more than ``max_lag`` steps behind the last target, in units of the
largest step each joint may take (its velocity limit times dt; ``max_step`` without velocity
limits), the phase holds and the command re-targets the same step, from where the arm is,
until it has caught up. A command never asks a joint to move faster than its velocity limit
over ``dt`` from the measured posture, and never leaves the joint limits (the same bounds as
the offline loop). While the arm follows, the step is also bounded from the last target, so
that a reference through consecutive commands keeps the speed limits despite a small tracking
error. Held back (:attr:`Command.held`), the command re-targets from where the arm is: a pushed
arm is not snapped back to where it was, it is steered back to the constraints at the speed
limits from where the push left it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ._validation import check_array, check_positions
from .kinematics import damped_pinv
from .reproduce import (
    JOINT,
    Constraints,
    FusedStep,
    JointStep,
    KinematicModel,
    TaskStep,
    _check_reach,
    setup_run,
)

__all__ = ["Command", "Controller"]

Float = NDArray[np.float64]


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
    covariance : ndarray, shape (n, n)
        Covariance of the target (the fused Sigma of eq. (1), Sigma^theta for the joint-only
        controller, J+ S J+^T for a task-only one).
    influence : dict str -> float
        Share of each constraint in use, in the hand's space (as
        :attr:`pbdkit.reproduce.ReproductionResult.influence`).
    """

    def __init__(
        self,
        controller: Controller,
        q: Float,
        index: int,
        limited: bool,
        jac: Float,
        held: bool = False,
    ) -> None:
        self.q = q
        self.index = index
        self.limited = limited
        self.held = held
        self.gripper = controller._gripper_at(index)
        self._ctrl = controller
        self._jac = jac  # the Jacobian the step was linearized with

    @cached_property
    def covariance(self) -> Float:
        return self._ctrl._covariance(self.index, self._jac)

    @cached_property
    def influence(self) -> dict[str, float]:
        return self._ctrl._influence(self.index, self._jac, self.covariance)

    def __repr__(self) -> str:
        return f"Command(index={self.index}, q={np.round(self.q, 4).tolist()})"


@dataclass
class _Targets:
    q: Float  # the last target
    index: int
    x: Float | None  # f(q) and J(q), when known
    jac: Float | None


class Controller:
    """One closed-loop run of a skill (build it with :meth:`pbdkit.Skill.controller`).

    Parameters
    ----------
    robot : KinematicModel
    constraints : Constraints
        The skill's generalized constraints over its T steps.
    objects : dict str -> array-like, shape (3,)
        Position of every object of the skill (base frame).
    q0 : array-like, shape (n,), optional
        The posture the run starts from (default theta_hat_0, clipped to the limits); the
        first :meth:`step` targets step 1.
    use, alpha, max_step, reach, on_unreachable
        As :func:`pbdkit.reproduce.reproduce`.
    step_limit : array-like, shape (n,), optional
        Largest step of each joint (rad per step): velocity limits times :attr:`dt`.
    dt : float
        Seconds per step (NaN when unknown).
    line_search : bool
        As :func:`pbdkit.reproduce.reproduce`.
    max_lag : float
        The phase holds while the measured posture is more than this many steps behind the
        last target (module docstring, "Timing and phase"). ``inf``: it always advances.

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
        *,
        q0: npt.ArrayLike | None = None,
        use: Sequence[str] | str | None = None,
        alpha: float = 0.5,
        max_step: float | None = 0.1,
        step_limit: npt.ArrayLike | None = None,
        dt: float = float("nan"),
        line_search: bool = True,
        reach: float | None = None,
        on_unreachable: str = "raise",
        max_lag: float = 3.0,
    ) -> None:
        run = setup_run(
            robot,
            constraints,
            objects,
            q0=q0,
            use=use,
            alpha=alpha,
            max_step=max_step,
            step_limit=step_limit,
            reach=reach,
            on_unreachable=on_unreachable,
        )
        lag = float(max_lag)
        if not (lag > 0):  # NaN too
            raise ValueError(f"max_lag must be > 0 (steps), got {max_lag!r}")
        c, n = run.constraints, run.constraints.n_joints
        self._c, self._robot = c, robot
        self._objs, self._used, self._tasks = run.objects, run.used, run.tasks
        self._reach, self._on_unreachable = reach, on_unreachable
        self.max_lag = lag
        self.dt = float(dt)
        lower, upper, cap, bound = run.lower, run.upper, run.max_step, run.step_limit
        self._lower, self._upper = lower, upper
        theta0 = run.theta0
        # The largest step of each joint, for the phase rule: the velocity bound, else max_step.
        self._step_bound = bound if bound is not None else np.full(n, cap)
        self._fk_jac = getattr(robot, "fk_jacobian_unchecked", robot.fk_jacobian)
        if JOINT not in self._used:
            self._mode = "task"
        else:
            self._mode = "fused" if self._tasks else "joint"
        if self._mode == "fused":
            self._fused = FusedStep(
                robot, c, self._objs, self._tasks, lower, upper, cap, bound, bool(line_search)
            )
        elif self._mode == "task":
            self._task = TaskStep(
                robot, c, self._objs, self._tasks, lower, upper, run.alpha, cap, bound
            )
        else:
            self._joint = JointStep(c.joint_mean, lower, upper, cap, bound)
        self._last = _Targets(theta0.copy(), 0, None, None)
        self._no_jac = np.zeros((3, n))

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
        """True once a command has targeted the last step."""
        return self._last.index >= self._c.n_steps - 1

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
        objects : dict str -> array-like, shape (3,), optional
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
            )
        q = np.asarray(q_measured, dtype=np.float64)
        if q.shape != self._lower.shape or not np.isfinite(q).all():
            # the full check, for its message
            q = check_array(q_measured, "q_measured", shape=(self._lower.shape[0],))
        q = np.minimum(np.maximum(q, self._lower), self._upper)
        if objects is not None:
            self._update_objects(objects)
        last = self._last
        # Phase: advance while the arm follows (module docstring, "Timing and phase").
        lag = float((np.abs(q - last.q) / self._step_bound).max())
        held = last.index > 0 and lag > self.max_lag
        j = last.index if held else last.index + 1
        if self._mode == "joint":
            jac = self._no_jac
            new, limited = self._joint(j, q)
            x_new: Float | None = None
            jac_new: Float | None = None
        else:
            # The arm at the last target exactly (fed its own commands): its f and J are known.
            if last.x is not None and last.jac is not None and lag == 0.0:
                x, jac = last.x, last.jac
            else:
                x, jac = self._fk_jac(q)
            if self._mode == "fused":
                new, x_new, jac_new, limited = self._fused(j, q, x, jac)
            else:
                new, x_new, jac_new, limited = self._task(j, q, x, jac, damped_pinv(jac))
        if lag > 0.0 and not held:
            # The arm follows but is not at the last target: bound the step from the last
            # target too, so that the reference through consecutive commands keeps the bound.
            # (Held back, the command re-targets from where the arm is: module docstring.)
            bound = self._step_bound
            capped = np.minimum(np.maximum(new, last.q - bound), last.q + bound)
            capped = np.minimum(np.maximum(capped, self._lower), self._upper)
            if not np.array_equal(capped, new):
                new, x_new, jac_new, limited = capped, None, None, True
        self._last = _Targets(new, j, x_new, jac_new)
        return Command(self, new, j, limited, jac, held)

    def _update_objects(self, objects: Mapping[str, npt.ArrayLike]) -> None:
        names = self._c.object_names
        given = check_positions(objects, "objects")
        unknown = [k for k in given if k not in names]
        if unknown:
            raise ValueError(f"objects: unknown object name(s) {unknown}; this skill knows {names}")
        self._objs = {**self._objs, **given}
        if self._reach is not None:
            self._check_reach(self._objs)
        if self._mode == "fused":
            self._fused.set_objects(self._objs)
        elif self._mode == "task":
            self._task.set_objects(self._objs)

    def _check_reach(self, objs: Mapping[str, Float]) -> None:
        assert self._reach is not None
        used = {k: o for k, o in objs.items() if k in self._used}
        _check_reach(used, self._c, float(self._reach), self._on_unreachable)

    # ------------------------------------------------------------------ command details
    def _gripper_at(self, j: int) -> bool:
        g = self._c.gripper
        return bool(g is not None and g[j] > 0.5)

    def _covariance(self, j: int, jac: Float) -> Float:
        if self._mode == "fused":
            return self._fused.covariance(j, jac)
        if self._mode == "task":
            jp = damped_pinv(jac)
            return np.asarray(jp @ self._task.s_fused[j] @ jp.T)
        return np.array(self._c.joint_cov[j], dtype=np.float64)

    def _influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        if self._mode == "joint":
            return {JOINT: 1.0}
        if self._mode == "task":
            s = self._task.s_fused[j]
            return {
                k: float(np.trace(s @ self._task.prec[j, i])) / 3 for i, k in enumerate(self._tasks)
            }
        s_hand = jac @ cov @ jac.T
        shares = {
            k: float(np.trace(s_hand @ self._fused.prec[j, i])) / 3
            for i, k in enumerate(self._tasks)
        }
        return {JOINT: min(1.0, max(0.0, 1.0 - math.fsum(shares.values()))), **shares}
