"""Tests of pbdkit.reproduction._probabilistic_ik: the Table II loop, fusion in information form,
controllers.

A small spatial 4-joint arm with analytic kinematics (base yaw + three pitch joints) satisfies
the KinematicModel protocol; constraints are built by hand so that every quantity is known.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import numpy.typing as npt
import pytest
from numpy.typing import NDArray

from pbdkit.reproduction import _steps
from pbdkit.reproduction._constraints import Constraints
from pbdkit.reproduction._probabilistic_ik import solve
from pbdkit.reproduction._setup import (
    VELOCITY_SAFETY,
    ReachWarning,
    RunOptions,
    check_objects,
    reach_from_samples,
    step_limit_from_velocity,
)
from pbdkit.robots import KinematicModel
from pbdkit.robots._kinematics import damped_pinv

Float = NDArray[np.float64]


class ToyArm:
    """Base yaw q0, then pitch joints q1..q3 with links ``lengths`` in the vertical plane."""

    def __init__(self, lower: float = -3.0, upper: float = 3.0) -> None:
        self.lengths = np.array([0.3, 0.25, 0.15])
        self.height = 0.1
        self.n_joints = 4
        self.joint_names = ["yaw", "pitch1", "pitch2", "pitch3"]
        self.lower = np.full(4, lower)
        self.upper = np.full(4, upper)
        self.revolute = np.ones(4, dtype=bool)
        self.velocity_limit = self.acceleration_limit = self.jerk_limit = np.full(4, np.inf)

    def fk_jacobian(self, q: npt.ArrayLike) -> tuple[Float, Float]:
        q = np.asarray(q, dtype=np.float64)
        batch = q.ndim == 2
        qq = np.atleast_2d(q)
        phi = np.cumsum(qq[:, 1:], axis=1)  # (M, 3) absolute pitch of each link
        lc, ls = self.lengths * np.cos(phi), self.lengths * np.sin(phi)
        r, z = lc.sum(axis=1), self.height + ls.sum(axis=1)
        c0, s0 = np.cos(qq[:, 0]), np.sin(qq[:, 0])
        x = np.stack([r * c0, r * s0, z], axis=1)
        # d r / d q_k = -sum_{i >= k} l_i sin(phi_i), d z / d q_k = sum_{i >= k} l_i cos(phi_i)
        dr = -np.cumsum(ls[:, ::-1], axis=1)[:, ::-1]
        dz = np.cumsum(lc[:, ::-1], axis=1)[:, ::-1]
        jac = np.zeros((qq.shape[0], 3, 4))
        jac[:, 0, 0], jac[:, 1, 0] = -r * s0, r * c0
        jac[:, 0, 1:], jac[:, 1, 1:], jac[:, 2, 1:] = dr * c0[:, None], dr * s0[:, None], dz
        return (x, jac) if batch else (x[0], jac[0])

    def fk(self, q: npt.ArrayLike) -> Float:
        return self.fk_jacobian(q)[0]

    def fk_jacobian_unchecked(self, q: Float) -> tuple[Float, Float]:
        return self.fk_jacobian(q)

    def fk_jacobian_axes_unchecked(self, q: Float) -> tuple[Float, Float, Float]:
        # The yaw axis is vertical; every pitch axis is horizontal, across the arm's plane.
        x, jac = self.fk_jacobian(q)
        pitch = [np.sin(q[0]), -np.cos(q[0]), 0.0]
        return x, jac, np.array([[0.0, 0.0, 1.0], pitch, pitch, pitch])


def random_spd(rng: np.random.Generator, n: int, scale: float, batch: int) -> Float:
    a = rng.normal(size=(batch, n, n))
    return scale * (a @ np.swapaxes(a, -1, -2) / n + 0.2 * np.eye(n))


def make_constraints(
    rng: np.random.Generator,
    n_steps: int = 40,
    names: tuple[str, ...] = ("a", "b"),
    joint_scale: float = 0.05,
    task_scale: float = 1e-4,
) -> Constraints:
    s = np.linspace(0.0, 1.0, n_steps)[:, None]
    q_start = np.array([0.2, 0.6, -0.9, -0.4])
    q_end = np.array([0.9, 0.3, -1.2, 0.3])
    joint_mean = q_start + (q_end - q_start) * s
    task_mean = {k: 0.05 * rng.normal(size=(n_steps, 3)) for k in names}
    return Constraints(
        t=np.arange(float(n_steps)),
        joint_mean=joint_mean,
        joint_cov=random_spd(rng, 4, joint_scale, n_steps),
        task_mean=task_mean,
        task_cov={k: random_spd(rng, 3, task_scale, n_steps) for k in names},
        gripper=np.linspace(0.0, 1.0, n_steps),
    )


def objects_near_path(c: Constraints, arm: ToyArm) -> dict[str, Float]:
    # Place each object so that its target o + x_hat sits close to the joint-space path.
    mid = c.n_steps // 2
    x_mid = arm.fk(c.joint_mean[mid])
    return {k: x_mid - c.task_mean[k][mid] + 0.02 for k in c.object_names}


def smooth_constraints(rng: np.random.Generator, n_steps: int = 60) -> Constraints:
    """As make_constraints, with task means that move smoothly (a few cm over the grid)."""
    c = make_constraints(rng, n_steps=n_steps)
    s = np.linspace(0.0, np.pi, n_steps)[:, None]
    task_mean = {
        k: 0.03 * np.sin(s + i) * np.array([1.0, -1.0, 0.5]) for i, k in enumerate(c.object_names)
    }
    return Constraints(c.t, c.joint_mean, c.joint_cov, task_mean, c.task_cov, gripper=c.gripper)


def unbounded_step(
    arm: ToyArm,
    c: Constraints,
    objs: dict[str, Float],
    used: list[str],
    theta: Float,
    j: int,
    alpha: float = 0.5,
) -> Float:
    """Step j of Table II from theta with no bound, with explicit inverses (reference)."""
    x, jac = arm.fk_jacobian(theta)
    tasks = [k for k in used if k != "joint"]
    precs = {k: np.linalg.inv(c.task_cov[k][j]) for k in tasks}
    if "joint" in used and tasks:
        lam_theta = np.linalg.inv(c.joint_cov[j])
        lam = lam_theta + sum(jac.T @ p @ jac for p in precs.values())
        eta = lam_theta @ (c.joint_mean[j] - theta)
        eta = eta + sum(jac.T @ p @ (objs[k] + c.task_mean[k][j] - x) for k, p in precs.items())
        return np.asarray(np.linalg.inv(lam) @ eta)
    if "joint" in used:
        return np.asarray(np.clip(c.joint_mean[j], arm.lower, arm.upper) - theta)
    target = np.linalg.inv(sum(precs.values())) @ sum(
        p @ (objs[k] + c.task_mean[k][j]) for k, p in precs.items()
    )
    jp = damped_pinv(jac)
    return np.asarray(
        jp @ (target - x) + alpha * (np.eye(4) - jp @ jac) @ (c.joint_mean[j] - theta)
    )


def right_pinv(jac: Float) -> Float:
    """Undamped right pseudo-inverse J^T (J J^T)^-1 (the design's correction of Table II)."""
    return np.asarray(jac.T @ np.linalg.inv(jac @ jac.T))


def paper_fused_loop(
    arm: ToyArm, c: Constraints, objs: dict[str, Float], q0: Float, alpha: float
) -> tuple[Float, Float]:
    """Table II literally: dtheta^(n) with the null-space term; Sigma^(n) = J+ S J+^T inverted
    by the Moore-Penrose pseudo-inverse (the matrix is singular); explicit inverses."""
    theta = q0.copy()
    joints, covs = [theta.copy()], []
    for j in range(1, c.n_steps):
        x, jac = arm.fk_jacobian(theta)
        jp = right_pinv(jac)
        null = np.eye(4) - jp @ jac
        lams = [np.linalg.inv(c.joint_cov[j])]
        steps = [c.joint_mean[j] - theta]
        for k, o in objs.items():
            dx = o + c.task_mean[k][j] - x
            steps.append(jp @ dx + alpha * null @ (c.joint_mean[j] - theta))
            lams.append(np.linalg.pinv(jp @ c.task_cov[k][j] @ jp.T, rcond=1e-10, hermitian=True))
        cov = np.linalg.inv(sum(lams))
        theta = theta + cov @ sum(lam @ d for lam, d in zip(lams, steps, strict=True))
        joints.append(theta.copy())
        covs.append(cov)
    return np.array(joints), np.array(covs)


# ----------------------------------------------------------------------------- the toy arm
def test_toy_arm_is_a_kinematic_model_with_a_correct_jacobian() -> None:
    rng = np.random.default_rng(0)
    arm = ToyArm()
    assert isinstance(arm, KinematicModel)
    q = rng.uniform(-1, 1, 4)
    x, jac = arm.fk_jacobian(q)
    h = 1e-6
    fd = np.stack([(arm.fk(q + h * e) - arm.fk(q - h * e)) / (2 * h) for e in np.eye(4)], axis=1)
    np.testing.assert_allclose(jac, fd, rtol=0, atol=1e-8)
    xb, jb = arm.fk_jacobian(np.stack([q, q]))
    np.testing.assert_allclose(xb[1], x, atol=1e-15)
    np.testing.assert_allclose(jb[1], jac, atol=1e-15)
    # The axes give the second derivatives of a serial chain: d J_b / d q_a = w_a x J_b, a <= b.
    _, _, axes = arm.fk_jacobian_axes_unchecked(q)
    for a in range(4):
        e = h * np.eye(4)[a]
        djac = (arm.fk_jacobian(q + e)[1] - arm.fk_jacobian(q - e)[1]) / (2 * h)
        for b in range(a, 4):
            np.testing.assert_allclose(djac[:, b], np.cross(axes[a], jac[:, b]), atol=1e-7)


# ----------------------------------------------------------------------------- fusion
def test_fused_step_is_eq1_with_a_regularized_inverse_in_the_limit() -> None:
    rng = np.random.default_rng(1)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=2)
    objs = objects_near_path(c, arm)
    q0 = c.joint_mean[0] + 0.05 * rng.normal(size=4)
    res = solve(arm, c, objs, RunOptions(q0=q0, max_step=None, newton=False))
    step, cov = res.joints[1] - q0, res.covariances[1]

    x, jac = arm.fk_jacobian(q0)
    jp = right_pinv(jac)
    null = np.eye(4) - jp @ jac
    d_joint = c.joint_mean[1] - q0

    def eq1(eps_rel: float, tikhonov: bool) -> tuple[Float, Float]:
        lams, steps = [np.linalg.inv(c.joint_cov[1])], [d_joint]
        for k, o in objs.items():
            m = jp @ c.task_cov[k][1] @ jp.T  # Table II's Sigma^(n), rank 3
            eps = eps_rel * np.linalg.norm(m, 2) ** (2 if tikhonov else 1)
            if tikhonov:  # (M^2 + eps I)^-1 M -> M^+ as eps -> 0
                lam = np.linalg.solve(m @ m + eps * np.eye(4), m)
            else:  # the naive regularization (M + eps I)^-1
                lam = np.linalg.inv(m + eps * np.eye(4))
            lams.append(lam)
            steps.append(jp @ (o + c.task_mean[k][1] - x) + 0.5 * null @ d_joint)
        s = np.linalg.inv(sum(lams))
        return s @ sum(lm @ d for lm, d in zip(lams, steps, strict=True)), s

    errors, cov_errors = [], []
    for eps_rel in (1e-2, 1e-4, 1e-6, 1e-8):
        ref_step, ref_cov = eq1(eps_rel, tikhonov=True)
        errors.append(np.linalg.norm(ref_step - step) / np.linalg.norm(step))
        cov_errors.append(np.linalg.norm(ref_cov - cov) / np.linalg.norm(cov))
    # Converges linearly in eps: every factor 100 in eps gains a factor 10 to 100.
    assert errors[-1] < 1e-6 and cov_errors[-1] < 1e-6, (errors, cov_errors)
    for e in (errors, cov_errors):
        assert all(b < 0.1 * a for a, b in itertools.pairwise(e)), e
    # The naive (Sigma^(n) + eps I)^-1 does not converge to it: it pins the null-space motion.
    naive_step, _ = eq1(1e-8, tikhonov=False)
    assert np.linalg.norm(naive_step - step) / np.linalg.norm(step) > 1e-2


def test_null_space_term_has_no_effect_on_the_fused_controller() -> None:
    rng = np.random.default_rng(2)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=40)
    objs = objects_near_path(c, arm)
    q0 = c.joint_mean[0]
    ref0, cov0 = paper_fused_loop(arm, c, objs, q0, alpha=0.0)
    ref5, cov5 = paper_fused_loop(arm, c, objs, q0, alpha=0.5)
    np.testing.assert_allclose(ref5, ref0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cov5, cov0, rtol=0, atol=1e-12 * np.abs(cov0).max())
    for alpha in (0.0, 0.5):
        res = solve(arm, c, objs, RunOptions(alpha=alpha, max_step=None, newton=False))
        np.testing.assert_allclose(res.joints, ref5, rtol=0, atol=1e-10)
        np.testing.assert_allclose(
            res.covariances[1:], cov5, rtol=0, atol=1e-9 * np.abs(cov5).max()
        )
        np.testing.assert_allclose(res.positions, arm.fk(res.joints), rtol=0, atol=1e-14)
    assert res.used == ("joint", "a", "b")


def test_task_only_controller_is_table_ii_and_alpha_acts_there() -> None:
    rng = np.random.default_rng(3)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=30, names=("a",))
    objs = objects_near_path(c, arm)
    runs = {}
    for alpha in (0.0, 0.5):
        res = solve(arm, c, objs, RunOptions(use=["a"], alpha=alpha, max_step=None))
        theta = c.joint_mean[0].copy()
        ref = [theta.copy()]
        for j in range(1, c.n_steps):
            x, jac = arm.fk_jacobian(theta)
            jp = damped_pinv(jac)
            d_hat = c.joint_mean[j] - theta
            theta = theta + jp @ (objs["a"] + c.task_mean["a"][j] - x)
            theta = theta + alpha * (np.eye(4) - jp @ jac) @ d_hat
            ref.append(theta.copy())
        np.testing.assert_allclose(res.joints, np.array(ref), rtol=0, atol=1e-12)
        # The task is tracked one step late (closed loop on x_j): the error is the target's
        # motion between two steps, a few cm here for random x_hat.
        np.testing.assert_allclose(res.influence["a"], 1.0, rtol=0, atol=1e-9)
        assert res.covariances.shape == (30, 4, 4)
        assert np.linalg.matrix_rank(res.covariances[5], tol=1e-12) == 3
        runs[alpha] = res.joints
    assert np.abs(runs[0.5] - runs[0.0]).max() > 1e-2


def test_task_subset_is_fused_in_task_space() -> None:
    rng = np.random.default_rng(4)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=20)
    objs = objects_near_path(c, arm)
    res = solve(arm, c, objs, RunOptions(use=["b", "a"], max_step=None))
    assert res.used == ("a", "b")
    # Step 1 from theta_0: J+ (fused target - x_0) + alpha N (theta_hat_1 - theta_0).
    theta0 = c.joint_mean[0]
    x, jac = arm.fk_jacobian(theta0)
    pa, pb = np.linalg.inv(c.task_cov["a"][1]), np.linalg.inv(c.task_cov["b"][1])
    target = np.linalg.solve(
        pa + pb, pa @ (objs["a"] + c.task_mean["a"][1]) + pb @ (objs["b"] + c.task_mean["b"][1])
    )
    jp = damped_pinv(jac)
    expected = (
        theta0 + jp @ (target - x) + 0.5 * (np.eye(4) - jp @ jac) @ (c.joint_mean[1] - theta0)
    )
    np.testing.assert_allclose(res.joints[1], expected, rtol=0, atol=1e-12)
    total = res.influence["a"] + res.influence["b"]
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-9)


def test_joint_only_controller_follows_theta_hat() -> None:
    rng = np.random.default_rng(5)
    arm = ToyArm()
    c = make_constraints(rng)
    res = solve(arm, c, objects_near_path(c, arm), RunOptions(use="joint"))
    np.testing.assert_array_equal(res.joints, c.joint_mean)
    np.testing.assert_array_equal(res.covariances, c.joint_cov)
    np.testing.assert_array_equal(res.influence["joint"], np.ones(c.n_steps))
    np.testing.assert_allclose(res.positions, arm.fk(c.joint_mean), atol=1e-15)


def test_joint_only_controller_from_a_distant_q0_is_step_limited() -> None:
    rng = np.random.default_rng(13)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=40)
    q0 = c.joint_mean[0] + np.array([0.5, -0.4, 0.3, 0.2])
    res = solve(arm, c, objects_near_path(c, arm), RunOptions(q0=q0, use=["joint"], max_step=0.1))
    steps = np.linalg.norm(np.diff(res.joints, axis=0), axis=1)
    assert steps.max() <= 0.1 + 1e-12
    np.testing.assert_array_equal(res.joints[0], q0)
    np.testing.assert_allclose(res.joints[-10:], c.joint_mean[-10:], rtol=0, atol=1e-12)
    full = solve(arm, c, objects_near_path(c, arm), RunOptions(q0=q0, use=["joint"], max_step=None))
    np.testing.assert_array_equal(full.joints[1:], c.joint_mean[1:])  # the paper's full step


def test_influence_shares_sum_to_one_and_follow_the_precisions() -> None:
    rng = np.random.default_rng(6)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=30)
    # Make task 'a' very tight in the second half only.
    cov_a = c.task_cov["a"].copy()
    cov_a[15:] *= 1e-4
    covs = {"a": cov_a, "b": c.task_cov["b"]}
    c2 = Constraints(c.t, c.joint_mean, c.joint_cov, c.task_mean, covs, gripper=c.gripper)
    res = solve(arm, c2, objects_near_path(c2, arm))
    for influence in (res.influence, res.influence_joint_space):
        assert list(influence) == ["joint", "a", "b"]
        total = sum(influence.values())
        np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-9)
        for share in influence.values():
            assert share.shape == (30,)
            assert np.all(share >= -1e-12) and np.all(share <= 1 + 1e-12)
    # In hand space the tight constraint dictates where the hand goes: its share nears 1.
    assert res.influence["a"][20:].min() > 0.99
    assert res.influence["a"][:14].max() < res.influence["a"][20:].min() - 0.1
    # In joint space a task constraint informs 3 of the 4 directions: its share is at most 3/4.
    share_js = res.influence_joint_space["a"]
    assert share_js[20:].min() > 0.7 and share_js[20:].max() <= 0.75 + 1e-9
    assert share_js[:14].max() < share_js[20:].min() - 0.1
    assert res.gripper.dtype == bool and res.gripper_signal is not None
    np.testing.assert_array_equal(res.gripper, res.gripper_signal > 0.5)


def test_hand_space_precisions_add_by_woodbury() -> None:
    # S = J Sigma J^T with Sigma = (Lambda_theta + J^T P J)^-1: S^-1 = (J Sigma_theta J^T)^-1 + P.
    rng = np.random.default_rng(14)
    for n in (3, 4, 5, 7):
        sigma_theta = random_spd(rng, n, 0.1, 1)[0]
        precs = random_spd(rng, 3, 50.0, 3)  # P_n of three task constraints
        jac = rng.normal(size=(3, n))
        sigma = np.linalg.inv(np.linalg.inv(sigma_theta) + jac.T @ precs.sum(axis=0) @ jac)
        s = jac @ sigma @ jac.T
        prior = np.linalg.inv(jac @ sigma_theta @ jac.T)
        np.testing.assert_allclose(np.linalg.inv(s), prior + precs.sum(axis=0), rtol=1e-9)
        shares = [np.trace(s @ prior) / 3, *(np.trace(s @ p) / 3 for p in precs)]
        assert sum(shares) == pytest.approx(1.0, abs=1e-9)
        assert all(0.0 <= v <= 1.0 for v in shares)


@pytest.mark.parametrize("names", [("a",), ("a", "b")])
def test_influence_is_the_hand_space_share_computed_the_explicit_way(
    names: tuple[str, ...],
) -> None:
    rng = np.random.default_rng(15)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=25, names=names)
    res = solve(arm, c, objects_near_path(c, arm), RunOptions(max_step=None))
    assert res.used == ("joint", *names)
    for j in range(c.n_steps):
        # Step j was linearized at theta_{j-1} (step 0 reports J(theta_0)).
        jac = arm.fk_jacobian(res.joints[max(j - 1, 0)])[1]
        lam = {"joint": np.linalg.inv(c.joint_cov[j])}
        hand = {"joint": np.linalg.inv(jac @ c.joint_cov[j] @ jac.T)}
        for k in names:
            hand[k] = np.linalg.inv(c.task_cov[k][j])
            lam[k] = jac.T @ hand[k] @ jac
        sigma = np.linalg.inv(sum(lam.values()))
        s = jac @ sigma @ jac.T
        for k in ("joint", *names):
            expected_hand = np.trace(s @ hand[k]) / 3
            expected_js = np.trace(sigma @ lam[k]) / 4
            assert res.influence[k][j] == pytest.approx(expected_hand, abs=1e-9), (j, k)
            assert res.influence_joint_space[k][j] == pytest.approx(expected_js, abs=1e-9)


def test_influence_of_the_single_space_controllers() -> None:
    rng = np.random.default_rng(16)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=20)
    objs = objects_near_path(c, arm)
    joint = solve(arm, c, objs, RunOptions(use="joint"))
    assert joint.influence.keys() == joint.influence_joint_space.keys() == {"joint"}
    np.testing.assert_array_equal(joint.influence_joint_space["joint"], 1.0)
    task = solve(arm, c, objs, RunOptions(use=["a", "b"]))
    s_fused = np.linalg.inv(np.linalg.inv(c.task_cov["a"]) + np.linalg.inv(c.task_cov["b"]))
    expected = np.trace(s_fused @ np.linalg.inv(c.task_cov["a"]), axis1=1, axis2=2) / 3
    np.testing.assert_allclose(task.influence["a"], expected, rtol=0, atol=1e-9)
    for k in ("a", "b"):  # no joint-space precision (rank-3 covariance): the same shares
        np.testing.assert_array_equal(task.influence_joint_space[k], task.influence[k])
        assert task.influence_joint_space[k] is not task.influence[k]


# ----------------------------------------------------------------------------- step bounds
@pytest.mark.parametrize("use", [None, ["joint"], ["a"], ["a", "b"]])
def test_step_limit_scales_steps_uniformly_exactly_where_a_bound_binds(
    use: list[str] | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The bounds alone: the fused loop's reversal damping, which also scales a step down
    # (tests/test_motion.py), is left out here.
    monkeypatch.setattr(_steps, "REVERSAL_FRACTION", math.inf)
    rng = np.random.default_rng(17)
    arm = ToyArm()
    c = smooth_constraints(rng, n_steps=60)
    objs = objects_near_path(c, arm)
    q0 = c.joint_mean[0] + np.array([0.4, -0.3, 0.3, 0.25])  # far from theta_hat_0
    limit, max_step = np.array([0.02, 0.03, 0.025, 0.04]), 0.045
    options = RunOptions(q0=q0, use=use, max_step=max_step, newton=False)
    res = solve(arm, c, objs, options, step_limit=limit)
    steps = np.diff(res.joints, axis=0)
    assert np.all(np.abs(steps) <= limit * (1 + 1e-12))
    assert np.linalg.norm(steps, axis=1).max() <= max_step * (1 + 1e-12)
    used = list(res.used)
    by_joint, by_norm = [], []
    for j in range(1, c.n_steps):
        raw = unbounded_step(arm, c, objs, used, res.joints[j - 1], j)
        s_joint = 1.0 / np.max(np.abs(raw) / limit)
        s_norm = max_step / np.linalg.norm(raw)
        scale = min(1.0, s_joint, s_norm)
        # Away from ties, so that the reference and the loop agree on whether a bound binds.
        assert scale == 1.0 or scale < 1.0 - 1e-9, (j, scale)
        assert res.limited[j] == (scale < 1.0), j
        expected = np.clip(res.joints[j - 1] + scale * raw, arm.lower, arm.upper)
        np.testing.assert_allclose(res.joints[j], expected, rtol=0, atol=1e-10)
        by_joint.append(s_joint < min(1.0, s_norm))
        by_norm.append(s_norm < min(1.0, s_joint))
    assert not res.limited[0] and res.limited.dtype == bool and res.limited.shape == (60,)
    # A scaled step meets the bound that binds: the binding joint moves at its top speed.
    assert np.all((res.joints > arm.lower) & (res.joints < arm.upper))  # no clipping here
    ratio = np.max(np.abs(steps) / limit, axis=1)
    norm = np.linalg.norm(steps, axis=1) / max_step
    np.testing.assert_allclose(ratio[np.array(by_joint)], 1.0, rtol=1e-12)
    np.testing.assert_allclose(norm[np.array(by_norm)], 1.0, rtol=1e-12)
    # The far q0 is caught up without a jump, and the bounds let go afterwards: they bind only
    # while the posture lags behind the constraints.
    assert res.limited[1:5].all() and not res.limited.all()
    assert any(by_joint)
    if use is None:
        assert any(by_norm)  # here max_step binds too, where it is the tighter bound


@pytest.mark.parametrize("use", [None, ["joint"], ["a"]])
def test_a_step_limit_that_never_binds_changes_nothing(use: list[str] | None) -> None:
    rng = np.random.default_rng(18)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=30)
    objs = objects_near_path(c, arm)
    q0 = c.joint_mean[0] + np.array([0.4, -0.3, 0.3, 0.25])  # max_step binds
    ref = solve(arm, c, objs, RunOptions(q0=q0, use=use))
    for limit in (1e9, np.inf, [np.inf, 1e9, np.inf, np.inf]):
        res = solve(arm, c, objs, RunOptions(q0=q0, use=use), step_limit=limit)
        for field in ("joints", "positions", "covariances", "limited"):
            np.testing.assert_array_equal(getattr(res, field), getattr(ref, field))
        for k in ref.influence:
            np.testing.assert_array_equal(res.influence[k], ref.influence[k])
    assert ref.limited.any()  # by max_step
    free = solve(arm, c, objs, RunOptions(use="joint"), step_limit=1e9)
    assert not free.limited.any()


def test_step_limit_from_velocity() -> None:
    arm = ToyArm()
    assert step_limit_from_velocity("robot", arm, 0.02) is None  # the toy arm has no limits
    arm.velocity_limit = np.array([1.0, 0.0, -1.0, np.inf])  # type: ignore[attr-defined]
    limit = step_limit_from_velocity("robot", arm, 0.02)
    assert limit is not None
    np.testing.assert_array_equal(limit, [0.02 * VELOCITY_SAFETY, np.inf, np.inf, np.inf])
    assert VELOCITY_SAFETY == 1 - 1e-6
    assert step_limit_from_velocity("robot", arm, float("nan")) is None  # unknown timing
    arm.velocity_limit = np.zeros(4)  # type: ignore[attr-defined]
    assert step_limit_from_velocity("robot", arm, 0.02) is None
    assert step_limit_from_velocity(None, arm, 0.02) is None
    explicit = step_limit_from_velocity(2.0, arm, 0.01)
    assert explicit is not None
    np.testing.assert_array_equal(explicit, np.full(4, 2.0 * (0.01 * VELOCITY_SAFETY)))
    per_joint = step_limit_from_velocity([1.0, 2.0, 3.0, np.inf], arm, 0.5)
    assert per_joint is not None
    np.testing.assert_allclose(per_joint, [0.5, 1.0, 1.5, np.inf], rtol=2e-6)
    assert np.all(per_joint[:3] < [0.5, 1.0, 1.5])
    with pytest.raises(ValueError, match=r"velocity_limit is in rad/s .* unknown"):
        step_limit_from_velocity(1.0, arm, float("nan"))
    with pytest.raises(ValueError, match=r"velocity_limit\[1\] must be > 0 \(rad/s"):
        step_limit_from_velocity([1.0, 0.0, 1.0, 1.0], arm, 0.02)
    with pytest.raises(ValueError, match=r"velocity_limit must be a number or have shape \(4,\)"):
        step_limit_from_velocity([1.0, 1.0], arm, 0.02)
    with pytest.raises(ValueError, match=r"velocity_limit must be 'robot', a number"):
        step_limit_from_velocity("urdf", arm, 0.02)
    arm.velocity_limit = np.ones(3)  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match=r"robot\.velocity_limit must have shape \(4,\)"):
        step_limit_from_velocity("robot", arm, 0.02)


# ----------------------------------------------------------------------------- limits, reach
@pytest.mark.parametrize("step_limit", [None, [0.02, 0.05, 0.03, 0.04]])
@pytest.mark.parametrize("use", [None, ["joint"], ["a"], ["a", "b"]])
def test_reproduction_never_leaves_the_joint_limits(
    use: list[str] | None, step_limit: list[float] | None
) -> None:
    rng = np.random.default_rng(7)
    arm = ToyArm(lower=-0.8, upper=0.8)
    c = make_constraints(rng)  # theta_hat leaves [-0.8, 0.8] (lift to -1.2)
    objs = {k: np.array([0.1, 0.6, 0.1]) for k in c.object_names}  # pulls the arm around
    res = solve(arm, c, objs, RunOptions(use=use), step_limit=step_limit)
    assert np.all(np.isfinite(res.joints)) and np.all(np.isfinite(res.covariances))
    assert np.all(res.joints >= arm.lower) and np.all(res.joints <= arm.upper)
    assert np.any(np.isclose(res.joints, arm.lower, atol=0, rtol=0) | (res.joints == arm.upper))
    if step_limit is not None:  # clipping only shortens a bounded step
        assert np.all(np.abs(np.diff(res.joints, axis=0)) <= np.array(step_limit) * (1 + 1e-12))


@pytest.mark.parametrize("use", [None, ["a"]])
def test_unreachable_target_warns_or_raises_and_never_gives_nan(use: list[str] | None) -> None:
    rng = np.random.default_rng(8)
    arm = ToyArm()
    c = make_constraints(rng, names=("a",), task_scale=1e-6)
    reach = reach_from_samples(arm)
    assert 0.79 <= reach <= 1.02 * 0.8  # the arm reaches 0.7 m from (0, 0, 0.1): <= 0.8
    far = {"a": np.array([1.5, 0.0, 0.2]) - c.task_mean["a"].mean(axis=0)}
    with pytest.raises(ValueError, match=r"objects\['a'\]: the hand must be at .* beyond the arm"):
        solve(arm, c, far, RunOptions(use=use), reach=reach)
    with pytest.warns(ReachWarning, match="beyond the arm's reach"):
        res = solve(arm, c, far, RunOptions(use=use, on_unreachable="warn"), reach=reach)
    assert np.all(np.isfinite(res.joints)) and np.all(np.isfinite(res.positions))
    assert np.all(np.isfinite(res.covariances))
    # No step is longer than max_step (0.1 rad by default), although the target is 1 m away.
    assert np.linalg.norm(np.diff(res.joints, axis=0), axis=1).max() <= 0.1 + 1e-12
    # The hand stretches toward the target: as far as the arm reaches.
    assert np.linalg.norm(res.positions[-1] - [0.0, 0.0, 0.1]) > 0.65


def test_singular_posture_stays_finite() -> None:
    rng = np.random.default_rng(9)
    arm = ToyArm()
    c = make_constraints(rng, names=("a",))
    straight = np.zeros(4)  # all pitch joints 0: the arm is stretched, J has rank 2
    assert np.linalg.matrix_rank(arm.fk_jacobian(straight)[1]) == 2
    objs = {"a": np.array([0.0, 0.0, 0.0])}
    for use in (None, ["a"]):
        res = solve(arm, c, objs, RunOptions(q0=straight, use=use))
        assert np.all(np.isfinite(res.joints)) and np.all(np.isfinite(res.covariances))
        # The hand-space shares need no inverse of the rank-2 J Sigma_theta J^T at step 0.
        np.testing.assert_allclose(sum(res.influence.values()), 1.0, rtol=0, atol=1e-9)
        for share in res.influence.values():
            assert np.all(np.isfinite(share)) and np.all((share >= 0) & (share <= 1 + 1e-12))


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"objects": {"a": [0, 0, 0]}}, r"missing position\(s\) for \['b'\]"),
        ({"objects": {"a": [0, 0, 0], "b": [0, 0, 0], "c": [0, 0, 0]}}, r"unknown object.*'c'"),
        ({"objects": {"a": [0, 0, np.nan], "b": [0, 0, 0]}}, r"objects\['a'\] must be finite"),
        ({"objects": {"a": [0, 0], "b": [0, 0, 0]}}, r"objects\['a'\] must be a position \(3,\)"),
        ({"objects": [[0, 0, 0]]}, r"objects must be a dict"),
        ({"q0": [0.0, 0.0, 0.0]}, r"q0 must have shape \(4,\), got \(3,\)"),
        ({"q0": [0.0, 0.0, 0.0, np.inf]}, r"q0 must be finite"),
        (
            {"q0": [0.0, 3.5, 0.0, 0.0]},
            r"q0\[1\] must be within the joint limits \[-3, 3\], got 3.5",
        ),
        ({"use": ["c"]}, r"use: unknown constraint\(s\) \['c'\]"),
        ({"use": []}, r"use must name at least one constraint"),
        ({"use": ["a", "a"]}, r"use must not repeat"),
        ({"use": 5}, r"use must be None, a constraint name or a sequence of names, got 5"),
        ({"use": [5]}, r"use must be None, a constraint name or a sequence of names, got \[5\]"),
        ({"use": {"a": 1}}, r"use must be None, a constraint name or a sequence of names"),
        ({"use": b"a"}, r"use must be None, a constraint name or a sequence of names, got b'a'"),
        ({"alpha": -0.5}, r"alpha must be finite and >= 0"),
        ({"alpha": float("nan")}, r"alpha must be finite"),
        ({"on_unreachable": "ignore"}, r"on_unreachable must be 'raise' or 'warn'"),
        ({"max_step": 0.0}, r"max_step must be finite and > 0"),
        ({"step_limit": 0.0}, r"step_limit\[0\] must be > 0 \(rad per step; inf leaves"),
        ({"step_limit": [0.1, -0.1, 0.1, 0.1]}, r"step_limit\[1\] must be > 0 .* got -0.1"),
        ({"step_limit": [0.1, 0.1, np.nan, 0.1]}, r"step_limit\[2\] must be > 0 .* got nan"),
        ({"step_limit": -np.inf}, r"step_limit\[0\] must be > 0 .* got -inf"),
        ({"step_limit": [0.1, 0.1]}, r"step_limit must be a number or have shape \(4,\)"),
        ({"step_limit": [[0.1] * 4]}, r"step_limit must be 0-D or 1-D, got 2-D"),
        ({"step_limit": "fast"}, r"step_limit must be an array of numbers, got str"),
    ],
)
def test_reproduce_rejects_bad_input(kwargs: dict[str, object], match: str) -> None:
    rng = np.random.default_rng(10)
    arm = ToyArm()
    c = make_constraints(rng, n_steps=5)
    args: dict[str, object] = {"objects": {"a": [0.3, 0, 0.2], "b": [0.3, 0, 0.2]}}
    args.update(kwargs)
    objects = args.pop("objects")
    step_limit = args.pop("step_limit", None)
    with pytest.raises(ValueError, match=match):
        solve(arm, c, objects, RunOptions(**args), step_limit=step_limit)  # type: ignore[arg-type]


def test_reproduce_rejects_mismatched_robot_and_constraints() -> None:
    rng = np.random.default_rng(11)
    c = make_constraints(rng, n_steps=5)
    arm = ToyArm()
    arm.n_joints = 5
    with pytest.raises(ValueError, match="robot has 5 joints, the constraints have 4"):
        solve(arm, c, {"a": [0, 0, 0], "b": [0, 0, 0]})
    with pytest.raises(ValueError, match="constraints must be a Constraints, got dict"):
        solve(ToyArm(), {}, {})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"unknown object name\(s\) \['x'\]; this skill knows"):
        check_objects({"x": [0, 0, 0]}, ["a"])


def test_constraints_validate_their_arrays() -> None:
    rng = np.random.default_rng(12)
    t = np.arange(5.0)
    jm, jc = np.zeros((5, 4)), random_spd(rng, 4, 0.1, 5)
    tm, tc = {"a": np.zeros((5, 3))}, {"a": random_spd(rng, 3, 1e-3, 5)}
    c = Constraints(t, jm, jc, tm, tc)
    assert c.names == ["joint", "a"] and c.n_steps == 5 and c.n_joints == 4
    np.testing.assert_allclose(c.joint_prec @ jc, np.broadcast_to(np.eye(4), (5, 4, 4)), atol=1e-10)
    with pytest.raises(ValueError, match=r"joint_cov must have shape \(5, 4, 4\)"):
        Constraints(t, jm, jc[:, :3, :3], tm, tc)
    with pytest.raises(ValueError, match=r"task_mean\['a'\] must have shape \(5, 3\)"):
        Constraints(t, jm, jc, {"a": np.zeros((4, 3))}, tc)
    with pytest.raises(ValueError, match="the same keys"):
        Constraints(t, jm, jc, tm, {"b": tc["a"]})
    with pytest.raises(ValueError, match="'joint' is reserved"):
        Constraints(t, jm, jc, {"joint": tm["a"]}, {"joint": tc["a"]})
    bad = jc.copy()
    bad[2] = -np.eye(4)
    with pytest.raises(ValueError, match=r"joint_cov must be positive definite .* steps \[2\]"):
        Constraints(t, jm, bad, tm, tc)
    with pytest.raises(ValueError, match=r"joint_mean must be finite"):
        Constraints(t, np.full((5, 4), np.nan), jc, tm, tc)
