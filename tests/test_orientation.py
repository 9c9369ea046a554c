"""Oriented task constraints: objects as poses, the hand's orientation in the object's frame,
the 6-D Jacobian, and reproduction with the new poses (issue 23)."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
from arms import KinematicOnly
from pose_teacher import demonstrations, grasp_pose, mug_pose
from scipy.spatial.transform import Rotation

import pbdkit
from pbdkit._rotations import exp_map, left_jacobian_inverse, log3, log_map
from pbdkit.reproduction._pose_steps import PoseFusedStep, PoseTaskStep
from pbdkit.reproduction._setup import RunOptions, setup_run
from pbdkit.reproduction._table_ii import make_step
from pbdkit.skill._spaces import mean_relative_rotation, space_data


@pytest.fixture(scope="module")
def panda() -> pbdkit.Robot:
    return pbdkit.robots.panda()


@pytest.fixture(scope="module")
def mug_demos(panda: pbdkit.Robot) -> list[pbdkit.Demonstration]:
    return demonstrations(panda, seed=0)


@pytest.fixture(scope="module")
def pose_skill(panda: pbdkit.Robot, mug_demos: list[pbdkit.Demonstration]) -> pbdkit.Skill:
    return pbdkit.Skill.learn(mug_demos, panda, n_steps=200)


@pytest.fixture(scope="module")
def position_skill(panda: pbdkit.Robot, mug_demos: list[pbdkit.Demonstration]) -> pbdkit.Skill:
    return pbdkit.Skill.learn(mug_demos, panda, n_steps=200, orientation=False)


def _grasp_error(robot: pbdkit.Robot, res: object, mug: np.ndarray) -> tuple[float, float]:
    """Position (m) and angle (rad) between the hand where the gripper closes and the
    demonstrated grasp for ``mug``."""
    k = int(np.argmax(res.gripper))  # type: ignore[attr-defined]
    hand = robot.fk_pose(res.joints[k])  # type: ignore[attr-defined]
    g = grasp_pose(mug)
    return (
        float(np.linalg.norm(hand[:3, 3] - g[:3, 3])),
        float(np.linalg.norm(log3(hand[:3, :3] @ g[:3, :3].T))),
    )


# ------------------------------------------------------------------ kinematics
def test_fk_pose_and_jacobian6_match_finite_differences_and_the_batched_chain(panda):
    rng = np.random.default_rng(0)
    qs = panda.lower + (panda.upper - panda.lower) * rng.random((4, 7))
    poses, jacs = panda.fk_pose(qs), panda.jacobian6(qs)
    h = 1e-6
    for q, pose, jac in zip(qs, poses, jacs, strict=True):
        np.testing.assert_allclose(panda.fk_pose(q), pose, atol=1e-12)
        np.testing.assert_allclose(pose[:3, 3], panda.fk(q), atol=1e-12)
        np.testing.assert_allclose(panda.jacobian6(q), jac, atol=1e-12)
        for i in range(7):
            dq = np.zeros(7)
            dq[i] = h
            plus, minus = panda.fk_pose(q + dq), panda.fk_pose(q - dq)
            np.testing.assert_allclose(
                (plus[:3, 3] - minus[:3, 3]) / (2 * h), jac[:3, i], atol=1e-7
            )
            # angular velocity: log(R(q + h) R(q - h)^T) / 2h, world axes
            w = log_map(plus[:3, :3] @ minus[:3, :3].T) / (2 * h)
            np.testing.assert_allclose(w, jac[3:, i], atol=1e-7)


def test_orientation_error_jacobian_is_the_inverse_left_jacobian_times_the_angular_rows(panda):
    """d log(R(q) R_t^T) / dq = J_l(e)^-1 J_w: what the oriented step linearizes, against
    central differences, for errors up to 2.5 rad."""
    rng = np.random.default_rng(1)
    for angle in (0.0, 0.3, 1.5, 2.5):
        q = panda.lower + (panda.upper - panda.lower) * rng.random(7)
        axis = rng.normal(size=3)
        rot = panda.fk_pose(q)[:3, :3]
        target = exp_map(-angle * axis / np.linalg.norm(axis)) @ rot  # e has norm `angle`
        e = log3(rot @ target.T)
        assert np.linalg.norm(e) == pytest.approx(angle, abs=1e-9)
        analytic = left_jacobian_inverse(e) @ panda.jacobian6(q)[3:]
        h = 1e-6
        fd = np.empty((3, 7))
        for i in range(7):
            dq = np.zeros(7)
            dq[i] = h
            fd[:, i] = (
                log3(panda.fk_pose(q + dq)[:3, :3] @ target.T)
                - log3(panda.fk_pose(q - dq)[:3, :3] @ target.T)
            ) / (2 * h)
        np.testing.assert_allclose(analytic, fd, atol=1e-6)


# ------------------------------------------------------------------ learning
def test_relative_orientations_live_in_the_tangent_space_at_their_mean_without_flips(panda):
    """Objects turned +-90 degrees under a hand pointing down (about 180 degrees from the
    identity relative to the object): rotation vectors about the mean stay continuous, of
    norm <= pi/2, equal to the object's yaw, where vectors about the identity would flip."""
    rng = np.random.default_rng(2)
    q = np.array([0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785])
    joints = np.repeat(q[None], 3, axis=0)
    yaws = np.radians([-90.0, -45.0, 0.0, 45.0, 90.0])
    demos = [
        pbdkit.Demonstration(
            [0.0, 1.0, 2.0], joints, {"box": mug_pose(y, 0.5, rng.uniform(-0.1, 0.1))}
        )
        for y in yaws
    ]
    hand = panda.fk_pose(q)[:3, :3]
    base = mean_relative_rotation(demos, panda, "box", 3)
    # The mean of yaws symmetric about 0: the hand relative to the unturned box.
    np.testing.assert_allclose(base, hand, atol=1e-9)
    assert np.degrees(np.linalg.norm(log3(base))) > 150
    data = space_data(demos, panda, ["box"], 3, rotation_base={"box": base})["box"]
    r = data[:, :, 4:]
    # R^T R_hand = exp([r]x) M with the box turned by yaw: r = -yaw about z (object axes).
    np.testing.assert_allclose(r[:, 0, 2], -yaws, atol=1e-9)
    np.testing.assert_allclose(r[:, :, :2], 0.0, atol=1e-9)
    # Position part: the hand in the box's frame, R^T (x - p).
    for d, row in zip(demos, data, strict=True):
        pose = d.objects["box"]
        np.testing.assert_allclose(
            row[0, 1:4], pose[:3, :3].T @ (panda.fk(q) - pose[:3, 3]), atol=1e-12
        )


def test_orientation_false_is_the_papers_skill_of_the_positions(panda, mug_demos):
    """orientation=False on posed objects learns exactly what positions would teach: x - p,
    the frames translating only; a pose given to it is used by its position."""
    as_positions = [
        pbdkit.Demonstration(d.t, d.joints, {"mug": d.objects["mug"][:3, 3]}, d.gripper)
        for d in mug_demos
    ]
    a = pbdkit.Skill.learn(mug_demos, panda, n_steps=100, n_components=3, orientation=False)
    b = pbdkit.Skill.learn(as_positions, panda, n_steps=100, n_components=3)
    assert a.oriented == [] and b.oriented == []
    np.testing.assert_array_equal(a.gmms["mug"].means_, b.gmms["mug"].means_)
    mug = mug_pose(0.7, 0.5, 0.05)
    ra = a.reproduce({"mug": mug}, velocity_limit=None, acceleration_limit=None, jerk_limit=None)
    rb = b.reproduce(
        {"mug": mug[:3, 3]}, velocity_limit=None, acceleration_limit=None, jerk_limit=None
    )
    np.testing.assert_array_equal(ra.joints, rb.joints)
    assert ra.orientations is None


# ------------------------------------------------------------------ reproduction
def test_world_task_covariance_matches_a_monte_carlo_of_the_local_gaussian(pose_skill):
    """The world precision of an oriented constraint, B^-T S^-1 B^-1 with
    B = blockdiag(R, R J_l(r)), against samples of the local Gaussian pushed through the exact
    maps (position p + R m, orientation R exp([r]x) M) and read as world errors."""
    c = pose_skill.constraints()
    rng = np.random.default_rng(3)
    j = 120
    mug = mug_pose(0.9, 0.5, -0.05)
    w = c.world_task("mug", mug)
    mean, cov = c.task_mean["mug"][j], c.task_cov["mug"][j]
    samples = rng.multivariate_normal(mean, cov, size=100_000)
    rot, p, base = mug[:3, :3], mug[:3, 3], c.rotation_base["mug"]
    world_pos = p + samples[:, :3] @ rot.T
    world_rot = rot @ exp_map(samples[:, 3:]) @ base
    errors = np.concatenate(
        [world_pos - w.position[j], log_map(world_rot @ w.rotation[j].T)], axis=1
    )
    np.testing.assert_allclose(errors.mean(axis=0), 0.0, atol=3 * np.sqrt(np.diag(cov)).max() / 300)
    empirical = np.cov(errors.T)
    predicted = np.linalg.inv(w.precision[j])
    scale = np.sqrt(np.outer(np.diag(predicted), np.diag(predicted)))
    np.testing.assert_allclose(empirical / scale, predicted / scale, atol=0.02)


def test_pose_skill_grasps_turned_mugs_where_the_position_skill_misses(
    panda, pose_skill, position_skill
):
    rng = np.random.default_rng(4)
    pose_err, flat_err = [], []
    for _ in range(6):
        mug = mug_pose(rng.uniform(-1.3, 1.3), rng.uniform(0.46, 0.54), rng.uniform(-0.08, 0.08))
        res = pose_skill.reproduce({"mug": mug})
        assert res.orientations is not None
        assert set(res.orientation_errors) == {"mug"}
        pose_err.append(_grasp_error(panda, res, mug))
        flat_err.append(_grasp_error(panda, position_skill.reproduce({"mug": mug}), mug))
    pos, ang = np.array(pose_err).T
    assert pos.max() < 0.005 and np.degrees(ang).max() < 5.0
    flat_pos, flat_ang = np.array(flat_err).T
    assert np.median(flat_pos) > 5 * np.median(pos)
    assert np.degrees(np.median(flat_ang)) > 20


def test_quaternion_and_matrix_poses_give_the_same_reproduction(pose_skill):
    mug = mug_pose(-0.6, 0.5, 0.02)
    q = Rotation.from_matrix(mug[:3, :3]).as_quat()  # scipy: x, y, z, w
    seven = np.r_[mug[:3, 3], q[3], q[:3]]  # pbdkit: w first
    a = pose_skill.reproduce({"mug": mug})
    b = pose_skill.reproduce({"mug": seven})
    # The same to rounding: the two conversions to a rotation matrix differ in the last bits,
    # and with the joint constraint widened (calibration) the first steps' solve passes them on
    # amplified (1e-8 rad measured).
    np.testing.assert_allclose(a.joints, b.joints, atol=1e-7)


def test_an_oriented_object_needs_a_pose(pose_skill):
    with pytest.raises(
        ValueError, match=r"objects\['mug'\] must be a pose .*in the frame of 'mug'"
    ):
        pose_skill.reproduce({"mug": [0.5, 0.0, 0.0]})
    with pytest.raises(ValueError, match=r"objects\['mug'\]: the quaternion .* has zero norm"):
        pose_skill.reproduce({"mug": [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]})
    bad = np.eye(4)
    bad[:3, :3] = np.diag([1.0, 1.0, -1.0])
    with pytest.raises(ValueError, match="rotation matrix"):
        pose_skill.reproduce({"mug": bad})


def test_pose_steps_are_chosen_for_oriented_constraints(panda, pose_skill):
    c = pose_skill.constraints()
    objs = {"mug": mug_pose(0.2, 0.5, 0.0)}
    fused = make_step(panda, setup_run(panda, c, objs, RunOptions()))
    task = make_step(panda, setup_run(panda, c, objs, RunOptions(use=["mug"])))
    assert isinstance(fused, PoseFusedStep) and isinstance(task, PoseTaskStep)


def test_oriented_constraints_need_a_pose_kinematic_model_where_the_robot_enters(
    tmp_path, panda, mug_demos, pose_skill
):
    arm = KinematicOnly(panda)  # positions only: no fk_pose, jacobian6, fk_pose_jacobian_unchecked
    lacks = (
        r"PoseKinematicModel .*KinematicOnly lacks fk_pose, jacobian6, fk_pose_jacobian_unchecked"
    )
    with pytest.raises(
        ValueError, match=rf"the objects \['mug'\] are poses: .*orientation=False.*{lacks}"
    ):
        pbdkit.Skill.learn(mug_demos, arm, n_steps=50)
    flat = pbdkit.Skill.learn(mug_demos, arm, n_steps=50, orientation=False)  # the paper's skill
    assert flat.oriented == [] and flat.robot is arm
    pose_skill.save(tmp_path / "pose.npz")
    with pytest.raises(ValueError, match=rf"robot must be a {lacks}"):
        pbdkit.Skill.load(tmp_path / "pose.npz", robot=arm)
    c, objs = pose_skill.constraints(), {"mug": mug_pose(0.2, 0.5, 0.0)}
    for use in (None, ["joint"]):  # the orientation errors of every oriented object need fk_pose
        with pytest.raises(ValueError, match=rf"robot must be a {lacks}"):
            setup_run(arm, c, objs, RunOptions(use=use))


def test_fused_step_lowers_the_fused_energy_and_converges_to_its_minimum(panda, pose_skill):
    """Iterated at one step, the oriented fused step settles where the gradient of the fused
    energy vanishes (the product of the Gaussians), checked by finite differences of the
    energy."""
    c = pose_skill.constraints()
    run = setup_run(panda, c, {"mug": mug_pose(0.4, 0.5, 0.03)}, RunOptions())
    step = make_step(panda, run)
    assert isinstance(step, PoseFusedStep)
    j = 130
    theta = c.joint_mean[j].copy()
    x, jac, rot = step.kinematics(theta)
    energies = []
    for _ in range(60):
        energies.append(step._energy(j, theta, x, rot))
        theta, x, jac, rot, _ = step.advance(j, theta, x, jac, rot)
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(energies))

    def energy(q: np.ndarray) -> float:
        xx, rr, _ = panda.fk_pose_jacobian_unchecked(q)
        return step._energy(j, q, xx, rr)

    h = 1e-6
    grad = np.array([(energy(theta + h * e) - energy(theta - h * e)) / (2 * h) for e in np.eye(7)])
    scale = np.abs(np.diag(c.joint_prec[j])).max()
    assert np.abs(grad).max() < 1e-4 * scale


def test_task_only_pose_controller_reaches_the_object_target(panda, pose_skill):
    mug = mug_pose(0.5, 0.5, 0.0)
    res = pose_skill.reproduce({"mug": mug}, use=["mug"])
    j = np.flatnonzero(~res.lead_in)
    tight = int(np.argmin(np.trace(pose_skill.constraints().position_cov("mug"), axis1=1, axis2=2)))
    k = j[np.argmin(np.abs(res.t[j] - tight))]
    assert res.task_errors["mug"][k] < 2e-3
    assert np.degrees(res.orientation_errors["mug"][k]) < 2.0
    np.testing.assert_allclose(res.influence["mug"], 1.0, atol=1e-9)


def test_influence_shares_sum_to_one_in_the_hands_pose_space(pose_skill):
    res = pose_skill.reproduce({"mug": mug_pose(0.1, 0.5, 0.0)})
    total = res.influence["joint"] + res.influence["mug"]
    np.testing.assert_allclose(total, 1.0, atol=1e-9)
    assert res.influence["mug"].max() > 0.5  # the grasp is the mug's


def test_controller_with_poses_follows_its_own_plan_and_a_turned_mug(panda, pose_skill):
    """Fed its own commands with constant poses, the controller is the reproduction; turning
    the mug mid-way, it heads for the turned grasp."""
    mug = mug_pose(0.3, 0.5, 0.0)
    opts = {"velocity_limit": None, "acceleration_limit": None, "jerk_limit": None}
    res = pose_skill.reproduce({"mug": mug}, **opts)
    ctrl = pose_skill.controller({"mug": mug}, **opts)
    q = res.joints[0]
    for j in range(1, 40):
        cmd = ctrl.step(q)
        np.testing.assert_allclose(cmd.q, res.joints[j], atol=1e-10)
        q = cmd.q
    turned = mug_pose(-0.6, 0.5, 0.0)
    while not ctrl.done:
        q = ctrl.step(q, objects={"mug": turned}).q
    target = pose_skill.reproduce({"mug": turned}, **opts)
    hand, goal = panda.fk_pose(q), panda.fk_pose(target.joints[-1])
    assert np.linalg.norm(hand[:3, 3] - goal[:3, 3]) < 5e-3
    assert np.degrees(np.linalg.norm(log3(hand[:3, :3] @ goal[:3, :3].T))) < 3


def test_a_pose_skill_file_is_version_2_and_loads_bit_identical(
    tmp_path, pose_skill, position_skill
):
    path = tmp_path / "pose.npz"
    pose_skill.save(path)
    with np.load(path) as data:
        assert int(data["version"]) == 3  # learned: it keeps its demonstrations
        np.testing.assert_array_equal(data["rot_base_0"], pose_skill.rotation_base["mug"])
    loaded = pbdkit.Skill.load(path)
    assert loaded.oriented == ["mug"]
    mug = mug_pose(0.25, 0.5, 0.0)
    np.testing.assert_array_equal(
        loaded.reproduce({"mug": mug}).joints, pose_skill.reproduce({"mug": mug}).joints
    )
    flat = tmp_path / "flat.npz"
    position_skill.save(flat)
    with np.load(flat) as data:
        # Learned: version 3 (without its demonstrations, a skill of positions only is written
        # as version 1, readable by older versions: tests/test_skill_store.py).
        assert int(data["version"]) == 3
    # A 7-D mug GMM without its rotation base is refused.
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files if k != "rot_base_0"}
    np.savez(tmp_path / "broken.npz", **arrays)
    with pytest.raises(ValueError, match="GMM dimensions"):
        pbdkit.Skill.load(tmp_path / "broken.npz")


def test_demonstration_files_keep_poses(tmp_path, mug_demos):
    path = tmp_path / "demos.npz"
    pbdkit.save_demonstrations(mug_demos, path)
    back = pbdkit.load_demonstrations(path)
    for a, b in zip(mug_demos, back, strict=True):
        np.testing.assert_array_equal(a.objects["mug"], b.objects["mug"])
    mixed = [
        mug_demos[0],
        pbdkit.Demonstration(
            mug_demos[1].t, mug_demos[1].joints, {"mug": [0.5, 0, 0]}, mug_demos[1].gripper
        ),
    ]
    with pytest.raises(ValueError, match=r"demos\[1\]\.objects\['mug'\] is a position, unlike"):
        pbdkit.Skill.learn(mixed, pbdkit.robots.panda())


def test_katana_weighs_an_orientation_it_cannot_fully_meet(robot):
    """The 5-joint Katana cannot hold an arbitrary 6-D pose: with an oriented constraint the
    fused reproduction stays finite and within the limits, trading position and orientation
    by their precisions."""
    rng = np.random.default_rng(5)
    q = np.array([0.2, 1.2, -1.0, -0.6, 0.3])
    demos = []
    for i in range(4):
        yaw = rng.uniform(-0.5, 0.5)
        obj = mug_pose(yaw, 0.3 + 0.02 * i, 0.05)
        joints = q + np.linspace(0.0, 1.0, 30)[:, None] * rng.normal(0.0, 0.05, 5)
        demos.append(pbdkit.Demonstration(np.linspace(0, 3, 30), joints, {"block": obj}))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pbdkit.data.LimitWarning)
        skill = pbdkit.Skill.learn(demos, robot, n_steps=50, n_components=2)
    assert skill.oriented == ["block"]
    res = skill.reproduce({"block": mug_pose(0.2, 0.31, 0.05)})
    assert np.all(np.isfinite(res.joints))
    assert np.all(robot.within_limits(res.joints, tol=1e-9))
    np.testing.assert_allclose(res.influence["joint"] + res.influence["block"], 1.0, atol=1e-9)
