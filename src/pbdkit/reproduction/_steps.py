"""The steps of Table II's controllers for position constraints: theta_j from the posture
theta_{j-1}, for the joint-space, fused and task-only controllers, and their loops.

A step is what the offline loop (:func:`pbdkit.reproduction._table_ii._table_ii`) and the online
controller (:class:`pbdkit.reproduction.Controller`) share:
:func:`~pbdkit.reproduction._table_ii.make_step` builds the one a run asks for from a
:class:`~pbdkit.reproduction._setup.RunSetup`, so an online run fed its own targets is the
offline reproduction. :class:`ControllerStep` is the interface; :class:`JointStep` follows
theta_hat, :class:`FusedStep` is eq. (1) in information form and :class:`TaskStep` a task-only
controller. Beside each step is its loop over the time grid (a :class:`LoopOutput`), which also
computes the covariances and the influence of the constraints, batched. The steps of oriented
constraints are in :mod:`pbdkit.reproduction._pose_steps`.

Every step is scaled down uniformly by ``step_limit`` (per joint) and ``max_step`` (over the
joints); the fused step is line-searched on the fused energy of its step (at most
``MAX_HALVINGS`` halvings) and takes Newton's term (w x omega_a) . J_b where it stiffens the step.
Why, and the math of each controller: :doc:`/reproduction` ("Step size", "Stability",
"Influence of the constraints", "Performance").
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dposv

from ..robots._kinematics import damped_pinv
from ..robots._protocols import KinematicModel
from ._constraints import JOINT, Constraints
from ._setup import RunSetup

__all__ = ["ControllerStep", "FusedStep", "JointStep", "LoopOutput", "TaskStep"]

Float = NDArray[np.float64]
# skew(w)^T = _LEVI_CIVITA . w: the Levi-Civita symbol, entry (i, j) sum_k eps_ijk w_k.
_LEVI_CIVITA = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _LEVI_CIVITA[_i, _j, _k], _LEVI_CIVITA[_j, _i, _k] = 1.0, -1.0
# Line search of the fused loop: at most this many halvings of a step (docs: "Stability").
MAX_HALVINGS = 8

#: The clearance constraint's key in a result's influence (never a constraint name).
CLEARANCE = "clearance"
#: Where the clearance acts, the trust region is this many times ``max_step`` (and the velocity
#: bound ``step_limit`` does not apply: the timing keeps the limits). Larger let the path jump
#: past an obstacle between two clear samples (docs: "Collisions").
CLEARANCE_STEP = 1.0
#: A fused step in which a joint reverses, moving faster than this fraction of its step bound
#: (``step_limit``, else ``max_step``) in both steps (a reversal as
#: :func:`pbdkit.motion._limits.count_reversals` counts it), shrinks the trust region to half
#: the last step: it lands between the two postures, where a period-2 cycle's energy is lowest.
#: The region then doubles on every step that does not reverse (docs: "Stability").
REVERSAL_FRACTION = 0.25


class LoopOutput(NamedTuple):
    """What a controller's loop over the time grid gives, for steps ``start`` .. T - 1 (row 0:
    the posture it starts from)."""

    joints: Float  # (T', n)
    positions: Float  # (T', 3): f(joints)
    covariances: Float  # (T', n, n)
    influence: dict[str, Float]  # hand space, each (T',), summing to 1
    influence_joint_space: dict[str, Float]
    limited: NDArray[np.bool_]  # (T',): the steps a bound scaled down


def _free_step2(max_step: float, step_limit: Float | None) -> float:
    """Squared length below which no bound can bind (with a margin against rounding)."""
    free = max_step if step_limit is None else min(max_step, float(step_limit.min()))
    return free * free * (1.0 - 1e-9)


def _bound_step(
    step: Float, free2: float, step_limit: Float | None, max_step: float
) -> tuple[Float, bool]:
    """``step`` scaled down by :func:`_step_scale` when it is longer than ``free2`` allows
    (squared, :func:`_free_step2`), and whether it was."""
    step2 = float(step.dot(step))
    if step2 > free2:
        scale = _step_scale(step, step2, step_limit, max_step)
        if scale < 1.0:
            return step * scale, True
    return step, False


def _step_scale(step: Float, step2: float, step_limit: Float | None, max_step: float) -> float:
    """Factor in (0, 1] that brings ``step`` within ``step_limit`` and then ``max_step``.

    Both bounds scale the whole step (its direction is kept), so the factor is the smaller of
    the two: max_i |step_i| / step_limit_i <= 1 and ||step|| <= max_step afterwards.
    """
    scale = 1.0
    if step_limit is not None:
        ratio = float((np.abs(step) / step_limit).max())
        if ratio > 1.0:
            scale = 1.0 / ratio
    if step2 > max_step * max_step:
        scale = min(scale, max_step / math.sqrt(step2))
    return scale


def _limited_mask(n_steps: int, steps: list[int]) -> NDArray[np.bool_]:
    mask = np.zeros(n_steps, dtype=bool)
    mask[steps] = True
    return mask


class ControllerStep:
    """One step of a controller of Table II: theta_j from the posture theta_{j-1}.

    The interface :func:`~pbdkit.reproduction._probabilistic_ik.solve`'s loops and
    :class:`pbdkit.Controller` run every controller through
    (:func:`~pbdkit.reproduction._table_ii.make_step` builds the one a run asks for):
    :class:`FusedStep`, :class:`TaskStep` or :class:`JointStep`, and for oriented constraints
    :class:`~pbdkit.reproduction._pose_steps.PoseFusedStep` or
    :class:`~pbdkit.reproduction._pose_steps.PoseTaskStep` (whose ``jac`` is the 6-D Jacobian and
    whose ``axes`` slot carries the hand's orientation).
    """

    #: "fused", "task" or "joint".
    mode: str
    #: Whether :meth:`advance` uses f(theta) and J(theta) (the joint-space controller does not).
    needs_kinematics: bool = True

    def set_objects(self, objs: Mapping[str, Float]) -> None:
        """New object positions (every object in use), for every step from now on."""

    def kinematics(self, theta: Float) -> tuple[Float, Float, Float | None]:
        """f(theta), J(theta) and the joint axes (n, 3) where the step uses them (else None)."""
        raise NotImplementedError

    def advance(
        self, j: int, theta: Float, x: Float | None, jac: Float | None, axes: Float | None
    ) -> tuple[Float, Float | None, Float | None, Float | None, bool]:
        """theta_j from theta_{j-1} = ``theta`` (x, jac and axes from :meth:`kinematics` at
        it, None where :attr:`needs_kinematics` is False).

        Returns theta_j, f(theta_j), J(theta_j) and its axes where the step computed them
        (else None), and whether a bound scaled the step down.
        """
        raise NotImplementedError

    def covariance(self, j: int, jac: Float) -> Float:
        """The covariance of step j in joint space, (n, n), with the Jacobian ``jac`` used."""
        raise NotImplementedError

    def influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        """The share of each constraint in use at step j (hand space), summing to 1."""
        raise NotImplementedError


class JointStep(ControllerStep):
    """One step of the joint-space controller: theta_j = theta + (theta_hat_j - theta) within the
    bounds (Table II); shared by :func:`~pbdkit.reproduction._probabilistic_ik.solve` and the online
    controller."""

    mode = "joint"
    needs_kinematics = False

    def __init__(self, run: RunSetup) -> None:
        self.c = run.constraints
        self.target = np.clip(self.c.joint_mean, run.lower, run.upper)
        self.max_step, self.step_limit = run.max_step, run.step_limit
        self.free2 = _free_step2(run.max_step, run.step_limit)

    def advance(
        self, j: int, theta: Float, x: Float | None, jac: Float | None, axes: Float | None
    ) -> tuple[Float, Float | None, Float | None, Float | None, bool]:
        new, limited = self(j, theta)
        return new, None, None, None, limited

    def covariance(self, j: int, jac: Float) -> Float:
        return np.array(self.c.joint_cov[j], dtype=np.float64)

    def influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        return {JOINT: 1.0}

    def __call__(self, j: int, theta: Float) -> tuple[Float, bool]:
        """theta_j from theta_{j-1} = ``theta``, and whether a bound scaled the step down."""
        step, limited = _bound_step(
            self.target[j] - theta, self.free2, self.step_limit, self.max_step
        )
        return theta + step, limited  # stays in the box: between theta and target[j]


def _joint_only(step: JointStep, theta0: Float, start: int = 0) -> tuple[Float, NDArray[np.bool_]]:
    """Joint-space controller: :class:`JointStep` over every step (from step ``start``).

    That is theta_hat itself (clipped to the limits), except where a step would exceed
    ``step_limit`` or ``max_step`` (a q0 away from theta_hat_0, or a jump in theta_hat): those
    steps are scaled. Returns the joints and the mask of the scaled steps.
    """
    max_step, step_limit = step.max_step, step.step_limit
    joints = step.target[start:].copy()
    joints[0] = theta0
    n_steps = joints.shape[0]
    d = np.diff(joints, axis=0)
    # The same tests as _step_scale, for all steps at once: nothing binds -> theta_hat itself.
    fits = np.einsum("ij,ij->i", d, d) <= max_step * max_step
    if step_limit is not None:
        fits &= (np.abs(d) / step_limit).max(axis=1) <= 1.0
    if np.all(fits):
        return joints, np.zeros(n_steps, dtype=bool)
    limited: list[int] = []
    theta = theta0
    for j in range(1, n_steps):
        theta, was_limited = step(start + j, theta)
        if was_limited:
            limited.append(j)
        joints[j] = theta
    return joints, _limited_mask(n_steps, limited)


class FusedStep(ControllerStep):
    """One step of the fused controller (Table II with eq. (1) in information form).

    Everything that does not depend on the posture is prepared here for all steps at once;
    :meth:`__call__` takes the posture theta_{j-1} (with f and J there) and returns theta_j.
    :func:`~pbdkit.reproduction._probabilistic_ik.solve` and
    :class:`pbdkit.reproduction.Controller` both run this one step, so an online run fed
    its own targets is the offline reproduction.

    Every task constraint shares J, so sum_n J^T P_n J = J^T (sum_n P_n) J and
    sum_n J^T P_n dx^(n) = J^T (h - (sum_n P_n) x) with h = sum_n P_n (o(n) + x_hat^(n)): per step
    the cost does not grow with the number of objects (P_n = (Sigma^x(n))^-1).
    """

    mode = "fused"

    def __init__(self, robot: KinematicModel, run: RunSetup) -> None:
        c, tasks = run.constraints, run.tasks
        lower, upper, max_step, step_limit = run.lower, run.upper, run.max_step, run.step_limit
        line_search, newton = run.line_search, run.newton
        self.c, self.tasks, self.n = c, tasks, c.n_joints
        self.lower, self.upper = lower, upper
        self.max_step, self.step_limit, self.line_search = max_step, step_limit, line_search
        # No per-step validation: theta stays a clean float64 array.
        self.fk_jac = robot.fk_jacobian_unchecked
        # The curvature term needs the joints' axes (docs: "Stability").
        self.fk_axes = robot.fk_jacobian_axes_unchecked if newton else None
        self.newton = newton
        self._z, self._z_new = np.empty(self.n + 3), np.empty(self.n + 3)  # line search buffers
        # A step shorter than this fits every bound: one comparison (docs: "Performance").
        self.free2 = _free_step2(max_step, step_limit)
        # Lists of per-step views are cheaper to index in the loop than the arrays.
        self.prec_list, self.eta_list = list(c.joint_prec), list(c.joint_eta)
        # The clearance constraint (None: none; docs: "Collisions").
        self.avoid = run.avoid
        # Reversals: steps longer than this (squared) count; the last step and the region.
        self.fast2 = REVERSAL_FRACTION * REVERSAL_FRACTION * self.free2
        self.fast = REVERSAL_FRACTION * (
            math.sqrt(self.free2) if step_limit is None else np.minimum(step_limit, max_step)
        )
        self.cap2 = max_step * max_step
        self.reset()
        self.set_objects(run.objects)

    def reset(self) -> None:
        """Forget the last step (a loop starts: no reversal to damp)."""
        self._prev: Float | None = None
        self._radius2 = math.inf

    def set_objects(self, objs: Mapping[str, Float]) -> None:
        """New object positions (every object in use), for every step from now on."""
        c, n = self.c, self.n
        self.prec, self.p_sum, h = _task_stack(c, objs, self.tasks)
        # [sum_n P_n | h] so that one product gives J^T P and J^T h.
        self.g = list(np.concatenate([self.p_sum, h[:, :, None]], axis=2))  # T x (3, 4)
        self.p_sum_list, self.h_list = list(self.p_sum), list(h)
        # The fused energy of step j in z = [theta | f(theta)]: E_j = 1/2 z^T Q_j z - z . b_j + c
        # with Q_j = diag(Lambda_theta_j, sum_n P_n), b_j = [eta_j | h_j]; the line search
        # compares E_j(z_new) - E_j(z) = d . (Q_j (z_new + z) / 2 - b_j), d = z_new - z (exact:
        # quadratic).
        half_q = np.zeros((c.n_steps, n + 3, n + 3))
        half_q[:, :n, :n] = 0.5 * c.joint_prec
        half_q[:, n:, n:] = 0.5 * self.p_sum
        self.q_list, self.b_list = list(half_q), list(np.concatenate([c.joint_eta, h], axis=1))

    def kinematics(self, theta: Float) -> tuple[Float, Float, Float | None]:
        """f(theta), J(theta) and the joint axes (n, 3) when the Newton term uses them."""
        if self.fk_axes is not None:
            return self.fk_axes(theta)
        x, jac = self.fk_jac(theta)
        return x, jac, None

    def __call__(
        self, j: int, theta: Float, x: Float, jac: Float, axes: Float | None = None
    ) -> tuple[Float, Float, Float, Float | None, bool]:
        """theta_j from theta_{j-1} = ``theta`` (x = f(theta), jac = J(theta), ``axes`` its
        joint axes for the Newton term, see :meth:`kinematics`).

        Returns theta_j, f(theta_j), J(theta_j), its axes (None without the Newton term), and
        whether a bound scaled the step down.
        """
        # ndarray.dot rather than @: for these tiny operands it has half the call overhead
        # (1 us against 2 us per product, measured).
        m = jac.T.dot(self.g[j])  # (n, 4): [J^T P | J^T h]
        a = m[:, :3]
        lam_j = self.prec_list[j] + a.dot(jac)  # eq. (1) in information form: precisions add
        # Solve for the new posture directly: sum_c Lambda_c (theta + dtheta_c)
        # = eta_joint + J^T (h - P x) + J^T P J theta = eta_joint + J^T h + A (J theta - x).
        rhs = self.eta_list[j] + m[:, 3] + a.dot(jac.dot(theta) - x)
        # The clearance, where a pass caught a pair at this step: one more Gaussian, whose
        # precision and information add (docs: "Collisions").
        clearance = None if self.avoid is None else self.avoid.terms(j, theta)
        if clearance is not None:
            lam_j = lam_j + clearance[0]
            rhs = rhs + clearance[1]
        _, target, info = dposv(lam_j, rhs)
        if info != 0:
            raise np.linalg.LinAlgError(f"the fused precision at step {j} is not positive definite")
        step = target - theta
        if axes is not None:
            # Newton: the Hessian of E_j adds sum_i w_i d^2 f_i, w = P x - h, with
            # d^2 x / d theta_a d theta_b = omega_min x J_max, so its (a, b) entry for a <= b is
            # (w x omega_a) . J_b (docs: "Stability"); rows
            # w x omega_a = axes skew(w)^T, skew(w) = LEVI_CIVITA . w (np.cross costs 20x more on
            # these sizes).
            skew_t = _LEVI_CIVITA.dot(self.p_sum_list[j].dot(x) - self.h_list[j])
            # Only its upper triangle is the Hessian's, and only it is read: LAPACK's dposv
            # factors the upper triangle of the symmetric matrix it is given.
            _, newton, info2 = dposv(lam_j + axes.dot(skew_t).dot(jac), lam_j.dot(step))
            # Kept where the curvature stiffens the step (the directions where Gauss-Newton
            # overshoots into a limit cycle); where it softens it, the Gauss-Newton step is the
            # safer one.
            step2 = step.dot(step)
            newton2 = newton.dot(newton)
            if info2 == 0 and newton2 < step2:
                step, step2 = newton, newton2
                target = theta + newton
        else:
            step2 = step.dot(step)
        limited = False
        # A fast step that reverses the last fast one: the trust region halves that step
        # (REVERSAL_FRACTION); otherwise it doubles, and is gone past max_step.
        # (The last step's length only where this one is fast: slow steps skip it.)
        radius2, prev, prev2 = self._radius2, self._prev, 0.0
        reverses = False
        if prev is not None and step2 > self.fast2:
            prev2 = prev.dot(prev)
            reverses = prev2 > self.fast2 and _reverses(step, prev, self.fast)
        if reverses:
            radius2 = 0.25 * prev2
        elif radius2 < math.inf:
            radius2 = 4.0 * radius2 if radius2 < self.cap2 else math.inf
        self._radius2 = radius2
        if step2 > radius2:
            step = step * math.sqrt(radius2 / step2)
            target, step2, limited = theta + step, radius2, True
        # Velocity bound, trust region of the linearization; where the clearance acts, the
        # trust region alone (docs: "Collisions").
        if clearance is not None:
            bound = CLEARANCE_STEP * self.max_step
            if step2 > bound * bound:
                target = theta + step * (bound / np.sqrt(step2))
                limited = True
        elif step2 > self.free2:
            scale = _step_scale(step, step2, self.step_limit, self.max_step)
            if scale < 1.0:
                target = theta + step * scale
                limited = True
        new = np.minimum(np.maximum(target, self.lower), self.upper)
        x_new, jac_new, axes_new = self.kinematics(new)
        if self.line_search:
            # The step must lower the fused energy of step j (docs: "Stability").
            n = self.n
            z, z_new = self._z, self._z_new  # [theta | f(theta)], filled in place
            z[:n], z[n:] = theta, x
            z_new[:n], z_new[n:] = new, x_new
            q_t, b_t = self.q_list[j], self.b_list[j]
            halvings = 0
            while halvings < MAX_HALVINGS and (
                (z_new - z).dot(q_t.dot(z_new + z) - b_t) > 0.0
                if clearance is None
                else _rises(z, z_new, q_t, b_t, clearance)
            ):
                halvings += 1
                new = theta + 0.5 * (new - theta)
                x_new, jac_new, axes_new = self.kinematics(new)
                z_new[:n], z_new[n:] = new, x_new
        self._prev = new - theta
        return new, x_new, jac_new, axes_new, limited

    # The step itself, under the interface's name: no wrapper, one call less per step.
    advance = __call__  # type: ignore[assignment]

    def covariance(self, j: int, jac: Float) -> Float:
        """Sigma_j = (Lambda_theta_j + J^T (sum_n P_n) J)^-1 with the Jacobian ``jac`` used
        (plus the clearance's precision where it acted)."""
        lam = self.prec_list[j] + jac.T.dot(self.p_sum[j]).dot(jac)
        clearance = None if self.avoid is None else self.avoid.terms(j)
        if clearance is not None:
            lam = lam + clearance[0]
        inv = np.linalg.inv(lam)
        return np.asarray(0.5 * (inv + inv.T))

    def influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        """Hand space: share_n = tr(J Sigma J^T P_n) / 3, the joint constraint the rest."""
        s_hand = jac @ cov @ jac.T
        shares = {
            k: float(np.trace(s_hand @ self.prec[j, i])) / 3 for i, k in enumerate(self.tasks)
        }
        return {JOINT: min(1.0, max(0.0, 1.0 - math.fsum(shares.values()))), **shares}


def _reverses(step: Float, prev: Float, fast: Float | float) -> bool:
    """Whether a joint moving fast (more than ``fast``) in both steps reverses."""
    return bool(np.any((step * prev < 0.0) & (np.abs(step) > fast) & (np.abs(prev) > fast)))


def _rises(z: Float, z_new: Float, q_t: Float, b_t: Float, clearance: tuple[Float, Float]) -> bool:
    """Whether z_new = [theta' | f(theta')] raises the fused energy of the step over z: the
    constraints' E_j (exact: quadratic in z) plus, where the clearance acts, its own quadratic
    energy in theta, 1/2 theta^T Lambda_c theta - theta . eta_c."""
    d = z_new - z
    lam_c, eta_c = clearance
    n = eta_c.shape[0]
    rise = d.dot(q_t.dot(z_new + z) - b_t) + d[:n].dot(0.5 * lam_c.dot(z_new[:n] + z[:n]) - eta_c)
    return bool(rise > 0.0)


def _fused_loop(
    c: Constraints,
    tasks: list[str],
    theta0: Float,
    step: FusedStep,
    start: int = 0,
) -> LoopOutput:
    """Table II with eq. (1) in information form: :class:`FusedStep` over every step (from
    step ``start``, at ``theta0``), for steps ``start`` .. T - 1.
    """
    n_steps, n = c.n_steps, c.n_joints
    limited: list[int] = []
    theta = theta0
    step.reset()
    x, jac, axes = step.kinematics(theta)
    # Python lists: appending costs less than writing rows into arrays, step by step.
    joints_l, positions_l, jacs_l = [theta], [x], [jac]
    for j in range(start + 1, n_steps):
        # x, jac are f(theta_{j-1}) and J(theta_{j-1}): Table II linearizes at the current posture.
        theta, x, jac, axes, was_limited = step(j, theta, x, jac, axes)
        if was_limited:
            limited.append(j - start)
        # Entry j holds the state theta_j and the Jacobian that step j+1 will use.
        joints_l.append(theta)
        positions_l.append(x)
        jacs_l.append(jac)
    joints, positions, jacs = np.array(joints_l), np.array(positions_l), np.array(jacs_l)
    # Step 0 reports the constraints at t_0 with J(theta_0); step j >= 1 used J(theta_{j-1}).
    jac_used = np.concatenate([jacs[:1], jacs[:-1]])
    jt = np.swapaxes(jac_used, -1, -2)
    prec_j, prec, p_sum = c.joint_prec[start:], step.prec[start:], step.p_sum[start:]
    lam = prec_j + jt @ p_sum @ jac_used
    clearance = None if step.avoid is None else np.zeros_like(lam)
    if clearance is not None:
        for j, lam_c in step.avoid.precisions.items():
            if start <= j < n_steps:
                clearance[j - start] = lam_c
        lam = lam + clearance
    cov = _spd_inverse(lam)
    # Hand space: S = J Sigma J^T, S^-1 = (J Sigma_theta J^T)^-1 + sum_n P_n (Woodbury), so
    # share_n = tr(S P_n) / 3 and the joint constraint has the rest
    # (docs: "Influence of the constraints").
    s_hand = jac_used @ cov @ jt  # (T, 3, 3)
    traces = [np.einsum("tij,tji->t", s_hand, prec[:, i]) for i in range(len(tasks))]
    influence = {k: tr / 3 for k, tr in zip(tasks, traces, strict=True)}
    # Joint space: tr(Sigma Lambda_c) / n, with tr(Sigma J^T P_n J) = tr(S P_n).
    influence_js = {JOINT: np.einsum("tij,tji->t", cov, prec_j) / n}
    influence_js.update({k: tr / n for k, tr in zip(tasks, traces, strict=True)})
    if clearance is not None:
        # The clearance acts on link points, not on the hand: its share is its joint-space
        # one in both spaces, taken from the joint constraint's rest (docs: "Collisions").
        influence_js[CLEARANCE] = np.einsum("tij,tji->t", cov, clearance) / n
        influence[CLEARANCE] = influence_js[CLEARANCE].copy()
        # Shares of two spaces: where they add up to more than 1, scaled down to 1.
        total = np.maximum(sum(influence.values()), 1.0)
        influence = {k: v / total for k, v in influence.items()}
    rest = 1.0 - sum(influence.values())
    influence = {JOINT: np.clip(rest, 0.0, 1.0), **influence}
    mask = _limited_mask(n_steps - start, limited)
    return LoopOutput(joints, positions, cov, influence, influence_js, mask)


def _task_stack(
    c: Constraints, objs: Mapping[str, Float], tasks: list[str]
) -> tuple[Float, Float, Float]:
    """The task constraints in use, for all steps at once: P_n (T, m, 3, 3), their sum
    sum_n P_n (T, 3, 3) and h = sum_n P_n (o(n) + x_hat^(n)) (T, 3), P_n = (Sigma^x(n))^-1.

    Their product in task space is N(x; (sum_n P_n)^-1 h, (sum_n P_n)^-1): the fused loop uses
    the sums in joint space, the task-only loop the product's mean.
    """
    prec = np.stack([c.task_prec[k] for k in tasks], axis=1)
    targets = np.stack([objs[k] + c.task_mean[k] for k in tasks], axis=1)  # (T, m, 3)
    return prec, prec.sum(axis=1), np.einsum("tkij,tkj->ti", prec, targets)


def _spd_inverse(a: Float) -> Float:
    """Inverse of symmetric positive-definite matrices (..., d, d), symmetrized."""
    inv = np.linalg.inv(a)
    return np.asarray(0.5 * (inv + np.swapaxes(inv, -1, -2)))


class TaskStep(ControllerStep):
    """One step of a task-only controller (Table II): the task constraints in use fused in task
    space, dtheta = J+ dx + alpha (I - J+ J)(theta_hat_j - theta), J+ the damped right inverse
    at the current posture. Shared by :func:`~pbdkit.reproduction._probabilistic_ik.solve` and the
    online controller."""

    mode = "task"

    def __init__(self, robot: KinematicModel, run: RunSetup) -> None:
        c = run.constraints
        self.c, self.tasks, self.alpha = c, run.tasks, run.alpha
        self.lower, self.upper = run.lower, run.upper
        self.max_step, self.step_limit = run.max_step, run.step_limit
        self.fk_jac = robot.fk_jacobian_unchecked
        self.free2 = _free_step2(run.max_step, run.step_limit)
        self.eye = np.eye(c.n_joints)
        self.set_objects(run.objects)

    def kinematics(self, theta: Float) -> tuple[Float, Float, Float | None]:
        x, jac = self.fk_jac(theta)
        return x, jac, None

    def advance(
        self, j: int, theta: Float, x: Float | None, jac: Float | None, axes: Float | None
    ) -> tuple[Float, Float | None, Float | None, Float | None, bool]:
        assert x is not None and jac is not None
        new, x_new, jac_new, limited = self(j, theta, x, jac, damped_pinv(jac))
        return new, x_new, jac_new, None, limited

    def covariance(self, j: int, jac: Float) -> Float:
        """The paper's J+ Sigma^x J+^T (rank 3), J+ at the Jacobian ``jac`` used."""
        jp = damped_pinv(jac)
        return np.asarray(jp @ self.s_fused[j] @ jp.T)

    def influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        """Already in hand space: share_n = tr(S_fused P_n) / 3."""
        s = self.s_fused[j]
        return {k: float(np.trace(s @ self.prec[j, i])) / 3 for i, k in enumerate(self.tasks)}

    def set_objects(self, objs: Mapping[str, Float]) -> None:
        """New object positions (every object in use), for every step from now on."""
        self.prec, prec_sum, h = _task_stack(self.c, objs, self.tasks)
        self.s_fused = _spd_inverse(prec_sum)  # (T, 3, 3)
        # Product of the task-space Gaussians: target = S (sum_n P_n (o_n + x_hat_n)).
        self.target = np.einsum("tij,tj->ti", self.s_fused, h)

    def __call__(
        self, j: int, theta: Float, x: Float, jac: Float, jp: Float
    ) -> tuple[Float, Float, Float, bool]:
        """theta_j from theta_{j-1} = ``theta`` (x, jac at it; jp = damped_pinv(jac))."""
        d_hat = self.c.joint_mean[j] - theta
        # Table II: dtheta = J+ dx + alpha (I - J+ J)(theta_hat_{j+1} - theta_j)
        step = jp @ (self.target[j] - x) + self.alpha * ((self.eye - jp @ jac) @ d_hat)
        step, limited = _bound_step(step, self.free2, self.step_limit, self.max_step)
        new = np.minimum(np.maximum(theta + step, self.lower), self.upper)
        x_new, jac_new = self.fk_jac(new)
        return new, x_new, jac_new, limited


def _task_loop(
    step: TaskStep, theta0: Float, start: int = 0
) -> tuple[Float, Float, Float, dict[str, Float], NDArray[np.bool_]]:
    """Task-only controller of Table II: :class:`TaskStep` over every step (from ``start``)."""
    c, tasks = step.c, step.tasks
    n_steps, n = c.n_steps - start, c.n_joints
    joints = np.empty((n_steps, n))
    positions = np.empty((n_steps, 3))
    pinvs = np.empty((n_steps, n, 3))
    limited: list[int] = []
    theta = theta0
    x, jac = step.fk_jac(theta)
    jp = damped_pinv(jac)
    joints[0], positions[0], pinvs[0] = theta, x, jp
    for j in range(1, n_steps):
        theta, x, jac_new, was_limited = step(start + j, theta, x, jac, jp)
        if was_limited:
            limited.append(j)
        pinvs[j] = jp
        jac = jac_new
        jp = damped_pinv(jac)
        joints[j], positions[j] = theta, x
    s_fused, prec = step.s_fused[start:], step.prec[start:]
    covs = pinvs @ s_fused @ np.swapaxes(pinvs, -1, -2)
    # Already in hand space: share_n = tr(S_fused P_n) / 3, S_fused = (sum_n P_n)^-1.
    influence = {k: np.einsum("tij,tji->t", s_fused, prec[:, i]) / 3 for i, k in enumerate(tasks)}
    return joints, positions, covs, influence, _limited_mask(n_steps, limited)
