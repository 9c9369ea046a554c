"""The steps of Table II's controllers when a task constraint in use is oriented: the hand's
position and orientation fused with the other constraints.

An oriented constraint n, placed in the base frame (:meth:`Constraints.world_task`), has the
error r_n = [x - x_n ; log(R_hand R_n^T)] with precision P_n (6 x 6), and its Jacobian
G_n = [J_p ; J_l(e_n)^-1 J_w] (J_l the left Jacobian of SO(3), :mod:`pbdkit._rotations`; J_p,
J_w the rows of the 6-D Jacobian): the controllers of :mod:`pbdkit.reproduction._steps` carry
over with G_n in place of J (:class:`PoseFusedStep`, :class:`PoseTaskStep`). The shares of the
constraints are measured in the hand's 6-D pose space: share_n = tr(Sigma Lambda_n) / 6,
Lambda_n = G_n^T P_n G_n. Derivation: :doc:`/reproduction`, "Orientation constraints".
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dposv

from .._rotations import exp_map, left_jacobian_inverse, left_jacobian_inverse3, log3, log_map
from ..robots._kinematics import damped_pinv
from ..robots._protocols import PoseKinematicModel
from ._constraints import JOINT, Constraints, WorldTask
from ._setup import RunSetup
from ._steps import (
    MAX_HALVINGS,
    ControllerStep,
    LoopOutput,
    _bound_step,
    _free_step2,
    _limited_mask,
    _spd_inverse,
    _task_stack,
)

__all__ = ["PoseFusedStep", "PoseTaskStep"]

Float = NDArray[np.float64]


class PoseFusedStep(ControllerStep):
    """One step of the fused controller when some task constraint in use is oriented.

    The fused energy of step j adds, for each oriented constraint n, the 6-D error
    r_n = [x - x_n ; log(R_hand R_n^T)] weighted by its world precision P_n
    (:meth:`Constraints.world_task`); position-only constraints keep their 3-D term. One
    Gauss-Newton step on it, with the error's Jacobian G_n = [J_p ; J_l(e_n)^-1 J_w] from the
    robot's 6-D Jacobian (:meth:`pbdkit.Robot.jacobian6`):

        dtheta = -(Lambda_theta + sum_n G_n^T P_n G_n)^-1 (Lambda_theta (theta - theta_hat)
                 + sum_n G_n^T P_n r_n),

    the product of the Gaussians in information form as for positions (precisions add). An arm
    of fewer than 6 joints (the Katana has 5) cannot meet a position and an orientation at
    once in general: the precisions weigh what each constraint gives up, exactly as the joint
    constraint and the task constraints are weighed already. The step is bounded and
    line-searched on the fused energy like :class:`.FusedStep`'s; Newton's
    curvature term is not used (Gauss-Newton steps).
    """

    mode = "fused"

    def __init__(self, robot: PoseKinematicModel, run: RunSetup) -> None:
        c = run.constraints
        self.c, self.tasks, self.n = c, run.tasks, c.n_joints
        self.lower, self.upper = run.lower, run.upper
        self.max_step, self.step_limit, self.line_search = (
            run.max_step,
            run.step_limit,
            run.line_search,
        )
        self.kin = robot.fk_pose_jacobian_unchecked
        self.free2 = _free_step2(run.max_step, run.step_limit)
        self.prec_list, self.eta_list = list(c.joint_prec), list(c.joint_eta)
        self.set_objects(run.objects)

    def set_objects(self, objs: Mapping[str, Float]) -> None:
        """New placements (every object in use), for every step from now on."""
        c = self.c
        flat = [k for k in self.tasks if k not in c.rotation_base]
        self.oriented_tasks = [k for k in self.tasks if k in c.rotation_base]
        if flat:
            _, p_sum, h = _task_stack(c, objs, flat)
        else:
            p_sum, h = np.zeros((c.n_steps, 3, 3)), np.zeros((c.n_steps, 3))
        self.p_sum_list, self.h_list = list(p_sum), list(h)
        self.world = {k: c.world_task(k, objs[k]) for k in self.tasks}
        self.oriented_terms = [
            (list(w.position), list(w.rotation), list(w.precision))
            for k in self.oriented_tasks
            for w in (self.world[k],)
            if w.rotation is not None
        ]

    def kinematics(self, theta: Float) -> tuple[Float, Float, Float | None]:
        """f(theta), the 6-D Jacobian J(theta) (6, n) and the hand's orientation (3, 3)."""
        x, rot, jac = self.kin(theta)
        return x, jac, rot

    def _terms(self, j: int, x: Float, jac: Float, rot: Float) -> tuple[Float, Float, float]:
        """sum_n G_n^T P_n G_n, sum_n G_n^T P_n r_n and the task energy at one posture."""
        jp, jw = jac[:3], jac[3:]
        p_sum, h = self.p_sum_list[j], self.h_list[j]
        px = p_sum.dot(x)
        a = jp.T.dot(p_sum)
        lam = a.dot(jp)
        grad = jp.T.dot(px - h)
        energy = 0.5 * x.dot(px) - h.dot(x)
        for pos, rots, precs in self.oriented_terms:
            e = log3(rot.dot(rots[j].T))
            g = np.concatenate([jp, left_jacobian_inverse3(e).dot(jw)])
            r = np.concatenate([x - pos[j], e])
            gp = g.T.dot(precs[j])
            lam = lam + gp.dot(g)
            grad = grad + gp.dot(r)
            energy += 0.5 * r.dot(precs[j].dot(r))
        return lam, grad, energy

    def _energy(self, j: int, theta: Float, x: Float, rot: Float) -> float:
        e_joint = 0.5 * theta.dot(self.prec_list[j].dot(theta)) - self.eta_list[j].dot(theta)
        p_sum, h = self.p_sum_list[j], self.h_list[j]
        energy = float(e_joint + 0.5 * x.dot(p_sum.dot(x)) - h.dot(x))
        for pos, rots, precs in self.oriented_terms:
            r = np.concatenate([x - pos[j], log3(rot.dot(rots[j].T))])
            energy += 0.5 * float(r.dot(precs[j].dot(r)))
        return energy

    def advance(
        self, j: int, theta: Float, x: Float | None, jac: Float | None, axes: Float | None
    ) -> tuple[Float, Float | None, Float | None, Float | None, bool]:
        """theta_j from theta_{j-1} = ``theta`` (x, the 6-D jac and the orientation ``axes``
        from :meth:`kinematics`)."""
        assert x is not None and jac is not None and axes is not None
        lam_t, grad_t, task_energy = self._terms(j, x, jac, axes)
        lam = self.prec_list[j] + lam_t
        grad = self.prec_list[j].dot(theta) - self.eta_list[j] + grad_t
        _, step, info = dposv(lam, -grad)
        if info != 0:
            raise np.linalg.LinAlgError(f"the fused precision at step {j} is not positive definite")
        step, limited = _bound_step(step, self.free2, self.step_limit, self.max_step)
        new = np.minimum(np.maximum(theta + step, self.lower), self.upper)
        x_new, rot_new, jac_new = self.kin(new)
        if self.line_search:
            prec_t = self.prec_list[j]
            before = float(
                0.5 * theta.dot(prec_t.dot(theta)) - self.eta_list[j].dot(theta) + task_energy
            )
            halvings = 0
            while self._energy(j, new, x_new, rot_new) > before and halvings < MAX_HALVINGS:
                halvings += 1
                new = theta + 0.5 * (new - theta)
                x_new, rot_new, jac_new = self.kin(new)
        return new, x_new, jac_new, rot_new, limited

    def precisions(self, j: int, jac: Float) -> dict[str, Float]:
        """The joint-space precision of every constraint in use at step j, with the 6-D
        Jacobian ``jac`` (the orientation errors linearized at 0: G_n = J)."""
        out = {JOINT: self.prec_list[j]}
        jp = jac[:3]
        for k in self.tasks:
            w = self.world[k]
            g = jp if w.rotation is None else jac
            out[k] = g.T.dot(w.precision[j]).dot(g)
        return out

    def covariance(self, j: int, jac: Float) -> Float:
        """Sigma_j = (sum of the precisions)^-1 with the 6-D Jacobian ``jac`` used."""
        inv = np.linalg.inv(sum(self.precisions(j, jac).values()))
        return np.asarray(0.5 * (inv + inv.T))

    def outputs(self, start: int, jacs: Float) -> tuple[Float, dict[str, Float], dict[str, Float]]:
        """:meth:`covariance`, :meth:`influence` and :meth:`influence_joint_space` for the
        steps ``start`` .. T - 1 at once, with the 6-D Jacobians ``jacs`` (T - start, 6, n)
        used at them."""
        jt = np.swapaxes(jacs, -1, -2)
        prec = {JOINT: self.c.joint_prec[start:]}
        for k in self.tasks:
            w = self.world[k]
            if w.rotation is None:
                prec[k] = jt[:, :, :3] @ w.precision[start:] @ jacs[:, :3]
            else:
                prec[k] = jt @ w.precision[start:] @ jacs
        cov = _spd_inverse(np.sum(list(prec.values()), axis=0))
        traces = {k: np.einsum("tij,tji->t", cov, p) for k, p in prec.items()}
        shares = {k: traces[k] / 6 for k in self.tasks}
        influence = {JOINT: np.clip(1.0 - sum(shares.values()), 0.0, 1.0), **shares}
        influence_js = {k: tr / self.n for k, tr in traces.items()}
        return cov, influence, influence_js

    def influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        """Hand pose space (6-D): share_n = tr(Sigma Lambda_n) / 6, the joint constraint the
        rest (:doc:`/reproduction`, "Orientation constraints")."""
        prec = self.precisions(j, jac)
        shares = {k: float(np.trace(cov.dot(prec[k]))) / 6 for k in self.tasks}
        return {JOINT: min(1.0, max(0.0, 1.0 - math.fsum(shares.values()))), **shares}

    def influence_joint_space(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        """Joint space: tr(Sigma Lambda_c) / n for every constraint c in use."""
        prec = self.precisions(j, jac)
        return {k: float(np.trace(cov.dot(p))) / self.n for k, p in prec.items()}


class PoseTaskStep(ControllerStep):
    """One step of a task-only controller when some task constraint in use is oriented.

    The task constraints in use are fused in the hand's pose space first, at every step: the
    pose that minimizes sum_n r_n^T P_n r_n (:func:`pbdkit._rotations.fuse_poses`'s
    Gauss-Newton, batched over the time grid; a position-only constraint weighs the position
    only), with fused precision P. Then, with W = chol(P)^T and G = [J_p ; J_l(e)^-1 J_w],
    dtheta = (W G)+ W dx + alpha (I - (W G)+ W G)(theta_hat - theta): Table II's step with the
    damped pseudo-inverse of the precision-weighted Jacobian, dx = [x* - x ; -e] the error to
    the fused pose. With 6 joints or more it is the plain right inverse (the weights cancel);
    with fewer (the Katana) the weighted least-squares step: the precisions weigh what cannot
    all be met.
    """

    mode = "task"

    def __init__(self, robot: PoseKinematicModel, run: RunSetup) -> None:
        c = run.constraints
        self.c, self.tasks, self.alpha, self.n = c, run.tasks, run.alpha, c.n_joints
        self.lower, self.upper = run.lower, run.upper
        self.max_step, self.step_limit = run.max_step, run.step_limit
        self.kin = robot.fk_pose_jacobian_unchecked
        self.free2 = _free_step2(run.max_step, run.step_limit)
        self.eye = np.eye(c.n_joints)
        self.set_objects(run.objects)

    def set_objects(self, objs: Mapping[str, Float]) -> None:
        """New placements (every object in use), for every step from now on."""
        c = self.c
        self.world = {k: c.world_task(k, objs[k]) for k in self.tasks}
        self.target, self.target_rot, self.fused_prec = _fuse_world_tasks(
            [self.world[k] for k in self.tasks]
        )
        self.weights = np.swapaxes(np.linalg.cholesky(self.fused_prec), -1, -2)  # W^T W = P
        self.s_fused = _spd_inverse(self.fused_prec)

    def kinematics(self, theta: Float) -> tuple[Float, Float, Float | None]:
        x, rot, jac = self.kin(theta)
        return x, jac, rot

    def _weighted(self, j: int, x: Float, jac: Float, rot: Float) -> tuple[Float, Float]:
        e = log3(rot.dot(self.target_rot[j].T))
        g = np.concatenate([jac[:3], left_jacobian_inverse3(e).dot(jac[3:])])
        dx = np.concatenate([self.target[j] - x, -e])
        w = self.weights[j]
        return w.dot(g), w.dot(dx)

    def advance(
        self, j: int, theta: Float, x: Float | None, jac: Float | None, axes: Float | None
    ) -> tuple[Float, Float | None, Float | None, Float | None, bool]:
        assert x is not None and jac is not None and axes is not None
        wg, wdx = self._weighted(j, x, jac, axes)
        jp = damped_pinv(wg)
        d_hat = self.c.joint_mean[j] - theta
        step = jp.dot(wdx) + self.alpha * (self.eye - jp.dot(wg)).dot(d_hat)
        step, limited = _bound_step(step, self.free2, self.step_limit, self.max_step)
        new = np.minimum(np.maximum(theta + step, self.lower), self.upper)
        x_new, rot_new, jac_new = self.kin(new)
        return new, x_new, jac_new, rot_new, limited

    def covariance(self, j: int, jac: Float) -> Float:
        """The paper's J+ Sigma^x J+^T in pose space: (W J)+ (W J)+^T, rank <= 6."""
        jp = damped_pinv(self.weights[j].dot(jac))
        return np.asarray(jp.dot(jp.T))

    def influence(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        """In the hand's pose space: share_n = tr(S_fused P_n) / 6 (a position-only
        constraint's P_n padded with zeros), summing to 1."""
        s = self.s_fused[j]
        out: dict[str, float] = {}
        for k in self.tasks:
            p = self.world[k].precision[j]
            d = p.shape[0]
            out[k] = float(np.trace(s[:d, :d].dot(p))) / 6
        return out

    def influence_joint_space(self, j: int, jac: Float, cov: Float) -> dict[str, float]:
        return self.influence(j, jac, cov)


def _fuse_world_tasks(
    tasks: Sequence[WorldTask], iterations: int = 30
) -> tuple[Float, Float, Float]:
    """The product of task constraints in the hand's pose space at every step (T batched):
    target positions (T, 3), orientations (T, 3, 3) and the fused 6x6 precision (T, 6, 6),
    by Gauss-Newton on sum_n r_n^T P_n r_n (:func:`pbdkit._rotations.fuse_poses`)."""
    n_steps = tasks[0].position.shape[0]
    # Start: the product of the position parts, the first orientation.
    p_blocks = [t.precision[:, :3, :3] for t in tasks]
    pos = np.linalg.solve(
        sum(p_blocks),
        sum(np.einsum("tij,tj->ti", b, t.position) for b, t in zip(p_blocks, tasks, strict=True))[
            ..., None
        ],
    )[..., 0]
    rot = next(t.rotation for t in tasks if t.rotation is not None).copy()
    info = np.zeros((n_steps, 6, 6))
    for _ in range(iterations):
        info = np.zeros((n_steps, 6, 6))
        grad = np.zeros((n_steps, 6))
        for t in tasks:
            if t.rotation is None:
                info[:, :3, :3] += t.precision
                grad[:, :3] += np.einsum("tij,tj->ti", t.precision, pos - t.position)
                continue
            e = log_map(rot @ np.swapaxes(t.rotation, -1, -2))
            g = np.zeros((n_steps, 6, 6))
            g[:, :3, :3] = np.eye(3)
            g[:, 3:, 3:] = left_jacobian_inverse(e)
            gp = np.swapaxes(g, -1, -2) @ t.precision
            info += gp @ g
            grad += np.einsum("tij,tj->ti", gp, np.concatenate([pos - t.position, e], axis=1))
        delta = -np.linalg.solve(info, grad[..., None])[..., 0]
        pos = pos + delta[:, :3]
        rot = exp_map(delta[:, 3:]) @ rot
        if float(np.abs(delta).max()) < 1e-12:
            break
    return pos, rot, 0.5 * (info + np.swapaxes(info, -1, -2))


def _pose_loop(
    c: Constraints, step: PoseFusedStep | PoseTaskStep, theta0: Float, start: int = 0
) -> LoopOutput:
    """The loop of an oriented controller (:class:`PoseFusedStep` or :class:`PoseTaskStep`)
    over every step from ``start``: the same outputs as
    :func:`~pbdkit.reproduction._steps._fused_loop`."""
    n_steps = c.n_steps - start
    limited: list[int] = []
    theta = theta0
    x, jac, rot = step.kinematics(theta)
    joints_l, positions_l, jacs_l = [theta], [x], [jac]
    for j in range(start + 1, c.n_steps):
        theta, x_new, jac_new, rot, was_limited = step.advance(j, theta, x, jac, rot)
        assert x_new is not None and jac_new is not None
        x, jac = x_new, jac_new
        if was_limited:
            limited.append(j - start)
        joints_l.append(theta)
        positions_l.append(x)
        jacs_l.append(jac)
    jac_used = [jacs_l[0], *jacs_l[:-1]]
    if isinstance(step, PoseFusedStep):
        covs_b, influence_b, influence_js_b = step.outputs(start, np.array(jac_used))
        return LoopOutput(
            np.array(joints_l),
            np.array(positions_l),
            covs_b,
            influence_b,
            influence_js_b,
            _limited_mask(n_steps, limited),
        )
    covs = np.empty((n_steps, c.n_joints, c.n_joints))
    influence: dict[str, list[float]] = {}
    influence_js: dict[str, list[float]] = {}
    for i in range(n_steps):
        j = start + i
        covs[i] = step.covariance(j, jac_used[i])
        for k, v in step.influence(j, jac_used[i], covs[i]).items():
            influence.setdefault(k, []).append(v)
        for k, v in step.influence_joint_space(j, jac_used[i], covs[i]).items():
            influence_js.setdefault(k, []).append(v)
    return LoopOutput(
        np.array(joints_l),
        np.array(positions_l),
        covs,
        {k: np.array(v) for k, v in influence.items()},
        {k: np.array(v) for k, v in influence_js.items()},
        _limited_mask(n_steps, limited),
    )
