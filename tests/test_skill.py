"""Tests of pbdkit.skill on the Katana: learning from synthetic demonstrations, reproduction
for unseen object positions, influence of the constraints, save/load, bad input.

The synthetic teacher rests, reaches the glass mid-motion and holds the hand on it (a grasp)
with postures that differ across demonstrations (the arm is redundant for a position), then
leaves for an end posture and rests; start and end postures are nearly the same in every
demonstration. So the task constraint is tight while grasping and the joint constraint is tight
at the start and the end.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from pbdkit.demos import Demonstration, save_demonstrations
from pbdkit.reproduce import ReachWarning
from pbdkit.robot import Robot
from pbdkit.robots import katana
from pbdkit.skill import Skill

Float = NDArray[np.float64]

N_STEPS = 200
# Phases of the synthetic task (fractions of the duration): rest, approach, hold on the glass,
# leave, rest.
REST_END, REACH_END, HOLD_END, LEAVE_END = 0.1, 0.35, 0.55, 0.85
REACH_STEP = round(0.45 * (N_STEPS - 1))  # middle of the hold
Q_START = np.array([0.0, 1.2, -1.8, -1.4, 0.0])
Q_REACH = np.array([0.5, 0.8, -1.8, -1.0, 0.0])
Q_END = np.array([-0.6, 1.0, -1.5, -1.2, 0.0])
COASTER_OFFSET = np.array([0.0, 0.0, 0.08])  # the hand ends 8 cm above the coaster


def ik(robot: Robot, target: Float, preferred: Float, iters: int = 300) -> Float:
    """Damped least squares with a null-space pull toward ``preferred`` (test data only)."""
    q = preferred.copy()
    for _ in range(iters):
        x, jac = robot.fk_jacobian(q)
        jp = jac.T @ np.linalg.inv(jac @ jac.T + 1e-4 * np.eye(3))
        q = q + jp @ (target - x) + 0.1 * (np.eye(robot.n_joints) - jp @ jac) @ (preferred - q)
        q = np.clip(q, robot.lower, robot.upper)
    assert np.linalg.norm(robot.fk(q) - target) < 1e-3
    return q


def min_jerk(s: Float) -> Float:
    return np.asarray(10 * s**3 - 15 * s**4 + 6 * s**5)


def synthetic_demos(
    robot: Robot, rng: np.random.Generator, n_demos: int = 5, coaster: bool = False
) -> list[Demonstration]:
    glass_nominal = robot.fk(Q_REACH)
    demos = []
    for _ in range(n_demos):
        glass = glass_nominal + np.r_[rng.uniform(-0.06, 0.06, 2), 0.0]
        # Different elbow/wrist postures for the same hand position (redundancy).
        q_reach = ik(robot, glass, Q_REACH + np.r_[0.0, rng.normal(0.0, 0.25, 3), 0.0])
        q_start = Q_START + rng.normal(0.0, 0.02, 5)
        objects = {"glass": glass}
        if coaster:
            place = robot.fk(Q_END) + np.r_[rng.uniform(-0.06, 0.06, 2), 0.0]
            q_end = ik(robot, place, Q_END + np.r_[0.0, rng.normal(0.0, 0.2, 3), 0.0])
            objects["coaster"] = place - COASTER_OFFSET
        else:
            q_end = Q_END + rng.normal(0.0, 0.02, 5)
        n = int(rng.integers(300, 600))
        t = np.sort(rng.uniform(0.0, 1.0, n))
        t = np.unique(np.r_[0.0, t, 1.0]) * rng.uniform(4.0, 6.0)  # seconds, irregular
        s = (t / t[-1])[:, None]
        approach = q_start + (q_reach - q_start) * min_jerk(
            np.clip((s - REST_END) / (REACH_END - REST_END), 0, 1)
        )
        leave = q_reach + (q_end - q_reach) * min_jerk(
            np.clip((s - HOLD_END) / (LEAVE_END - HOLD_END), 0, 1)
        )
        q = np.where(s < REACH_END, approach, np.where(s < HOLD_END, q_reach, leave))
        gripper = (s[:, 0] > 0.45).astype(float)  # closes on the glass
        demos.append(Demonstration(t, q, objects, gripper))
    return demos


@pytest.fixture(scope="module")
def robot() -> Robot:
    return katana()


@pytest.fixture(scope="module")
def demos(robot: Robot) -> list[Demonstration]:
    return synthetic_demos(robot, np.random.default_rng(0))


@pytest.fixture(scope="module")
def skill(robot: Robot, demos: list[Demonstration]) -> Skill:
    return Skill.learn(demos, robot, n_steps=N_STEPS, n_components="bic", random_state=0)


def unseen_glass(demos: list[Demonstration]) -> tuple[Float, float]:
    mean = np.mean([d.objects["glass"] for d in demos], axis=0)
    new = mean + np.array([0.05, -0.07, 0.0])
    return new, float(np.linalg.norm(new - mean))


# ----------------------------------------------------------------------------- learning
def test_learned_skill_structure(skill: Skill, robot: Robot) -> None:
    assert skill.constraint_names == ["joint", "glass"]
    assert skill.object_names == ["glass"] and skill.has_gripper and skill.n_steps == N_STEPS
    k = skill.n_components
    assert set(k) == {"joint", "glass"} and all(1 <= v <= 10 for v in k.values())
    assert skill.gmms["joint"].means_.shape[1] == 1 + 5 + 1  # t, theta, gripper
    assert skill.gmms["glass"].means_.shape[1] == 4  # t, x - o
    # Reach: the Katana's tool can be at most 0.2015 + 0.19 + 0.139 + 0.1523 + 0.1505 m away.
    assert 0.8 < skill.reach < 1.02 * 0.8333 + 1e-9
    c = skill.constraints()
    assert c is skill.constraints()  # cached
    assert c.joint_mean.shape == (N_STEPS, 5) and c.task_cov["glass"].shape == (N_STEPS, 3, 3)
    assert "Skill(" in repr(skill)


# ----------------------------------------------------------------------------- reproduction
def test_fused_reaches_unseen_object_where_joint_only_misses(
    skill: Skill, demos: list[Demonstration]
) -> None:
    glass, displacement = unseen_glass(demos)
    fused = skill.reproduce({"glass": glass})
    joint = skill.reproduce({"glass": glass}, use=["joint"])
    task = skill.reproduce({"glass": glass}, use=["glass"])
    err = {
        name: float(np.linalg.norm(r.positions[REACH_STEP] - glass))
        for name, r in (("fused", fused), ("joint", joint), ("task", task))
    }
    assert displacement > 0.08
    assert err["fused"] < 0.005, err
    assert err["task"] < 0.005, err
    # The joint-space controller reproduces the demonstrated postures: it goes to where the
    # glass used to be, and misses the moved glass by about its displacement.
    assert err["joint"] > 0.8 * displacement, (err, displacement)
    # The hand holds the glass through the whole grasp, not only at one step.
    hold = slice(int(0.40 * N_STEPS), int(0.52 * N_STEPS))
    assert fused.task_errors["glass"][hold].max() < 0.005
    for r in (fused, joint, task):
        assert np.all(r.joints >= skill.robot.lower) and np.all(r.joints <= skill.robot.upper)
        assert np.all(np.isfinite(r.covariances))


def test_fused_follows_joints_where_task_is_loose_and_influence_switches(
    skill: Skill, demos: list[Demonstration]
) -> None:
    glass, _ = unseen_glass(demos)
    res = skill.reproduce({"glass": glass})
    joint = skill.reproduce({"glass": glass}, use=["joint"])
    theta_hat = skill.constraints().joint_mean
    ends = np.r_[0:20, N_STEPS - 20 : N_STEPS]  # resting: joint space tight, task space loose
    # The fused posture stays on the joint-space generalization at rest...
    np.testing.assert_allclose(res.joints[ends], theta_hat[ends], rtol=0, atol=0.03)
    hand_shift = np.linalg.norm(res.positions - joint.positions, axis=1)
    assert hand_shift[ends].max() < 0.015
    # ...and leaves it, by about the glass displacement, while grasping.
    assert hand_shift[REACH_STEP] > 0.07
    share_task, share_joint = res.influence["glass"], res.influence["joint"]
    np.testing.assert_allclose(share_task + share_joint, 1.0, rtol=0, atol=1e-9)
    # On the 5-DOF Katana a task constraint informs 3 of 5 directions: its share is <= 0.6.
    assert share_task.max() <= 0.6 + 1e-9
    assert share_task[REACH_STEP] > 0.5
    assert share_joint[ends].min() > 0.7
    assert share_task[REACH_STEP] > 3 * share_task[ends].mean()


def test_gripper_signal_is_generalized(skill: Skill, demos: list[Demonstration]) -> None:
    glass, _ = unseen_glass(demos)
    res = skill.reproduce({"glass": glass})
    assert res.gripper.dtype == bool and res.gripper.shape == (N_STEPS,)
    assert not res.gripper[: int(0.4 * N_STEPS)].any()
    assert res.gripper[int(0.5 * N_STEPS) :].all()
    assert res.gripper_signal is not None
    np.testing.assert_array_equal(res.gripper, res.gripper_signal > 0.5)
    np.testing.assert_array_equal(res.t, np.arange(float(N_STEPS)))


def test_start_posture_and_paper_covariance(skill: Skill, demos: list[Demonstration]) -> None:
    glass, _ = unseen_glass(demos)
    q0 = Q_START + np.array([0.1, -0.1, 0.05, 0.1, 0.2])
    res = skill.reproduce({"glass": glass}, q0=q0)
    np.testing.assert_array_equal(res.joints[0], q0)
    assert res.task_errors["glass"][REACH_STEP] < 0.005
    paper = skill.reproduce({"glass": glass}, covariance="paper")
    assert paper.task_errors["glass"][REACH_STEP] < 0.005
    # alpha acts only in the task-only controller.
    a0 = skill.reproduce({"glass": glass}, alpha=0.0)
    np.testing.assert_array_equal(a0.joints, skill.reproduce({"glass": glass}).joints)


def test_two_objects_and_a_target_out_of_reach(robot: Robot) -> None:
    rng = np.random.default_rng(1)
    demos = synthetic_demos(robot, rng, n_demos=4, coaster=True)
    skill = Skill.learn(demos, robot, n_steps=100, n_components=4)
    assert skill.constraint_names == ["joint", "glass", "coaster"]
    assert skill.n_components == {"joint": 4, "glass": 4, "coaster": 4}
    objs = {k: np.mean([d.objects[k] for d in demos], axis=0) for k in ("glass", "coaster")}
    res = skill.reproduce(objs)
    np.testing.assert_allclose(sum(res.influence.values()), 1.0, rtol=0, atol=1e-9)
    assert res.task_errors["glass"][45] < 0.005
    assert res.task_errors["coaster"][-1] < 0.005
    # The coaster 2 m away: an error by default, a warning on request, never NaN.
    far = dict(objs, coaster=np.array([2.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r"objects\['coaster'\]: .* beyond the arm's reach"):
        skill.reproduce(far)
    with pytest.warns(ReachWarning, match="the hand will stop short"):
        res = skill.reproduce(far, on_unreachable="warn")
    assert np.all(np.isfinite(res.joints)) and np.all(np.isfinite(res.covariances))
    assert np.all(res.joints >= robot.lower) and np.all(res.joints <= robot.upper)
    # Controllers that do not use the coaster do not care where it is.
    for use in (["joint"], ["glass"], ["joint", "glass"]):
        assert np.all(np.isfinite(skill.reproduce(far, use=use).joints))


def test_skill_without_gripper_or_objects(robot: Robot, demos: list[Demonstration]) -> None:
    bare = [Demonstration(d.t, d.joints) for d in demos]
    skill = Skill.learn(bare, robot, n_steps=60, n_components=3)
    assert skill.constraint_names == ["joint"] and not skill.has_gripper
    assert skill.gmms["joint"].means_.shape[1] == 6
    res = skill.reproduce({})
    assert res.gripper_signal is None and not res.gripper.any()
    np.testing.assert_array_equal(res.joints, np.clip(skill.constraints().joint_mean,
                                                      robot.lower, robot.upper))  # fmt: skip
    np.testing.assert_array_equal(res.influence["joint"], 1.0)
    with pytest.raises(ValueError, match=r"unknown object name\(s\) \['glass'\]"):
        skill.reproduce({"glass": [0.4, 0.2, 0.2]})


# ----------------------------------------------------------------------------- save / load
def test_save_load_reproduces_bit_identical_results(
    skill: Skill, demos: list[Demonstration], tmp_path: Path
) -> None:
    path = tmp_path / "skill.npz"
    skill.save(path)
    back = Skill.load(path)
    assert isinstance(back.robot, Robot) and back.robot.tip == "tool"
    assert back.constraint_names == skill.constraint_names
    assert back.n_components == skill.n_components and back.reach == skill.reach
    glass, _ = unseen_glass(demos)
    for use in (None, ["joint"], ["glass"]):
        a = skill.reproduce({"glass": glass}, use=use)
        b = back.reproduce({"glass": glass}, use=use)
        for field in ("joints", "positions", "covariances", "gripper"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        for k in a.influence:
            np.testing.assert_array_equal(a.influence[k], b.influence[k])
    with np.load(path, allow_pickle=False) as data:
        assert str(data["format"]) == "pbdkit-skill" and int(data["version"]) == 1


def test_save_load_with_a_robot_without_urdf(
    robot: Robot, demos: list[Demonstration], tmp_path: Path
) -> None:
    class Arm:  # a KinematicModel that is not built from a URDF
        n_joints = robot.n_joints
        lower, upper = robot.lower, robot.upper
        fk, fk_jacobian = robot.fk, robot.fk_jacobian

    skill = Skill.learn(demos[:3], Arm(), n_steps=60, n_components=2)
    skill.save(tmp_path / "s.npz")
    with pytest.raises(ValueError, match=r"holds no URDF .* pass robot= to Skill\.load"):
        Skill.load(tmp_path / "s.npz")
    back = Skill.load(tmp_path / "s.npz", robot=Arm())
    objs = {"glass": demos[0].objects["glass"]}
    np.testing.assert_array_equal(back.reproduce(objs).joints, skill.reproduce(objs).joints)
    with pytest.raises(ValueError, match=r"robot has 4 joints, the skill in .* has 5"):
        Skill.load(tmp_path / "s.npz", robot=Robot.from_dh([[0, 0, 0.1, 0]] * 4, "rrrr"))


def test_load_rejects_missing_corrupt_foreign_and_other_versions(
    skill: Skill, demos: list[Demonstration], tmp_path: Path
) -> None:
    with pytest.raises(FileNotFoundError, match="not found"):
        Skill.load(tmp_path / "none.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(np.random.default_rng(2).bytes(300))
    with pytest.raises(ValueError, match=r"corrupt\.npz is not a (valid|readable)"):
        Skill.load(corrupt)
    save_demonstrations(demos, tmp_path / "demos.npz")
    with pytest.raises(ValueError, match="is not a pbdkit-skill file"):
        Skill.load(tmp_path / "demos.npz")
    path = tmp_path / "skill.npz"
    skill.save(path)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    np.savez(tmp_path / "v9.npz", **{**arrays, "version": np.array(9)})
    with pytest.raises(ValueError, match="of version 9; this pbdkit reads version 1"):
        Skill.load(tmp_path / "v9.npz")
    np.savez(tmp_path / "nokey.npz", **{k: v for k, v in arrays.items() if k != "gmm_0_means"})
    with pytest.raises(ValueError, match="missing key 'gmm_0_means'"):
        Skill.load(tmp_path / "nokey.npz")
    np.savez(tmp_path / "dims.npz", **{**arrays, "n_joints": np.array(6)})
    with pytest.raises(ValueError, match="GMM dimensions"):
        Skill.load(tmp_path / "dims.npz")
    weights = arrays["gmm_joint_weights"] * 2
    np.savez(tmp_path / "weights.npz", **{**arrays, "gmm_joint_weights": weights})
    with pytest.raises(ValueError, match="weights must sum to 1"):
        Skill.load(tmp_path / "weights.npz")
    np.savez(tmp_path / "names.npz", **{**arrays, "object_names": np.array(["joint"])})
    with pytest.raises(ValueError, match=r"object names \['joint'\] must be unique"):
        Skill.load(tmp_path / "names.npz")
    np.savez(tmp_path / "urdf.npz", **{**arrays, "robot_urdf": np.array("<robot")})
    with pytest.raises(ValueError, match=r"urdf\.npz is not a valid pbdkit-skill file: its robot"):
        Skill.load(tmp_path / "urdf.npz")


# ----------------------------------------------------------------------------- bad input
def test_learn_rejects_bad_input(robot: Robot, demos: list[Demonstration]) -> None:
    with pytest.raises(ValueError, match="at least 2 demonstrations, got 1"):
        Skill.learn(demos[:1], robot)
    with pytest.raises(ValueError, match="demos have 5 joints, the robot has 4"):
        Skill.learn(demos, Robot.from_dh([[0, 0, 0.1, 0]] * 4, "rrrr"))
    other = Demonstration(demos[1].t, demos[1].joints, {"cup": [0.3, 0, 0.1]}, demos[1].gripper)
    with pytest.raises(ValueError, match=r"demos\[1\] has objects \['cup'\], expected"):
        Skill.learn([demos[0], other], robot)
    fewer = Demonstration(demos[1].t, demos[1].joints[:, :4], demos[1].objects, demos[1].gripper)
    with pytest.raises(ValueError, match=r"demos\[1\] has 4 joints, expected 5"):
        Skill.learn([demos[0], fewer], robot)
    with pytest.raises(ValueError, match="n_steps must be >= 2, got 1"):
        Skill.learn(demos, robot, n_steps=1)
    with pytest.raises(ValueError, match="reg_covar must be finite and >= 0"):
        Skill.learn(demos, robot, reg_covar=-1.0)
    with pytest.raises(ValueError, match="fit_samples must be >= 2, got 1"):
        Skill.learn(demos, robot, fit_samples=1)
    with pytest.raises(ValueError, match="robot must provide n_joints, lower, upper, fk"):
        Skill.learn(demos, "katana")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("objects", "kwargs", "match"),
    [
        ({"cup": [0.4, 0.2, 0.2]}, {}, r"unknown object name\(s\) \['cup'\]"),
        ({}, {}, r"missing position\(s\) for \['glass'\]"),
        ({"glass": [0.4, np.nan, 0.2]}, {}, r"objects\['glass'\] must be finite"),
        ({"glass": [0.4, 0.2]}, {}, r"objects\['glass'\] must have shape \(3,\), got \(2,\)"),
        ({"glass": [3.0, 0.0, 0.2]}, {}, r"objects\['glass'\]: .* beyond the arm's reach"),
        ({"glass": [0.4, 0.2, 0.2]}, {"q0": [0, 3.0, 0, 0, 0]}, r"q0\[1\] must be within"),
        ({"glass": [0.4, 0.2, 0.2]}, {"q0": [0, 0, 0]}, r"q0 must have shape \(5,\)"),
        ({"glass": [0.4, 0.2, 0.2]}, {"use": ["cup"]}, r"use: unknown constraint"),
        ({"glass": [0.4, 0.2, 0.2]}, {"covariance": "full"}, r"covariance must be 'exact'"),
        ({"glass": [0.4, 0.2, 0.2]}, {"max_step": 0.0}, r"max_step must be finite and > 0"),
    ],
)
def test_reproduce_rejects_bad_input(
    skill: Skill, objects: dict[str, object], kwargs: dict[str, object], match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        skill.reproduce(objects, **kwargs)  # type: ignore[arg-type]


def test_duration_is_the_mean_demo_duration_and_survives_save_load(
    skill: Skill, demos: list[Demonstration], tmp_path: Path
) -> None:
    expected = float(np.mean([d.duration for d in demos]))
    assert skill.duration == pytest.approx(expected, rel=1e-12)
    path = tmp_path / "skill.npz"
    skill.save(path)
    loaded = Skill.load(path)
    assert loaded.duration == skill.duration
    res = loaded.reproduce({"glass": demos[0].objects["glass"]})
    t = loaded.times(res)
    assert t[0] == 0.0
    assert t[-1] == pytest.approx(expected)
    assert np.all(np.diff(t) > 0)


def test_learn_objects_selects_the_task_space_constraints(
    robot: Robot, demos: list[Demonstration]
) -> None:
    two = synthetic_demos(robot, np.random.default_rng(3), n_demos=3, coaster=True)
    only_glass = Skill.learn(two, robot, n_steps=60, n_components=2, objects=["glass"])
    assert only_glass.constraint_names == ["joint", "glass"]
    res = only_glass.reproduce({"glass": two[0].objects["glass"]})
    assert set(res.influence) == {"joint", "glass"}
    both = Skill.learn(two, robot, n_steps=60, n_components=2)
    assert both.constraint_names == ["joint", "glass", "coaster"]
    # The same data give the same glass and joint models whichever objects are kept.
    np.testing.assert_array_equal(both.gmms["glass"].means_, only_glass.gmms["glass"].means_)
    with pytest.raises(ValueError, match=r"objects must be distinct names among .*'cup'"):
        Skill.learn(two, robot, objects=["cup"])
    with pytest.raises(ValueError, match=r"objects must be distinct names"):
        Skill.learn(two, robot, objects=["glass", "glass"])
