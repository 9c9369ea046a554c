"""The public API of ``../shared/design.md`` (a contract: checks outside the repository call these
exact names): every name imports from where design.md says, and returns the documented type and
shape. One test per block of design.md's "Public API"."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from synthetic_teacher import synthetic_demos
from typer.testing import CliRunner

import pbdkit
from pbdkit import robots


@pytest.fixture(scope="module")
def katana() -> pbdkit.Robot:
    return pbdkit.robots.katana()


@pytest.fixture(scope="module")
def demos(katana: pbdkit.Robot) -> list[pbdkit.Demonstration]:
    return synthetic_demos(katana, np.random.default_rng(0))


@pytest.fixture(scope="module")
def skill(katana: pbdkit.Robot, demos: list[pbdkit.Demonstration]) -> pbdkit.Skill:
    return pbdkit.Skill.learn(demos, katana, n_steps=120, n_components="auto", max_components=8)


def test_the_top_level_names_and_sub_modules() -> None:
    for name in (
        "GMM",
        "Robot",
        "Demonstration",
        "Skill",
        "FrameModel",
        "ReproductionResult",
        "Controller",
        "Command",
    ):
        assert isinstance(getattr(pbdkit, name), type), name
    for name in (
        "save_demonstrations",
        "load_demonstrations",
        "read_bag",
        "write_trajectory_bag",
        "align",
        "align_trajectories",
    ):
        assert callable(getattr(pbdkit, name)), name
    for module in ("robots", "datasets", "gaussian"):
        assert getattr(pbdkit, module).__name__.startswith("pbdkit."), module
    for name in ("katana", "panda", "load", "available"):
        assert callable(getattr(robots, name)), name
    assert callable(pbdkit.datasets.reach_grasp_return) and callable(pbdkit.datasets.lasa)
    for name in pbdkit.__all__:
        assert name in dir(pbdkit), name


def test_gmm_as_documented() -> None:
    rng = np.random.default_rng(0)
    t = np.tile(np.linspace(0.0, 1.0, 60), 3)
    x = np.column_stack([t, np.sin(3 * t) + rng.normal(0, 0.02, t.size), np.cos(2 * t)])
    gmm = pbdkit.GMM(n_components=5, reg_covar=1e-6, random_state=0).fit(x)
    k, d = gmm.n_components_, x.shape[1]
    assert isinstance(gmm.n_components_, int) and k == 5
    assert gmm.weights_.shape == (k,) and gmm.means_.shape == (k, d)
    assert gmm.covariances_.shape == (k, d, d)
    assert all(a.dtype == np.float64 for a in (gmm.weights_, gmm.means_, gmm.covariances_))
    assert isinstance(gmm.bic(x), float)
    assert gmm.score_samples(x).shape == (x.shape[0],)
    bic = pbdkit.GMM(n_components="bic", max_components=4).fit(x)
    assert 1 <= bic.n_components_ <= 4
    assert pbdkit.GMM(n_components="auto").fit(x).n_components_ >= 1
    same = pbdkit.GMM.from_params(gmm.weights_, gmm.means_, gmm.covariances_)
    np.testing.assert_array_equal(same.score_samples(x), gmm.score_samples(x))
    query = np.linspace(0.0, 1.0, 7)[:, None]
    for mode in ("exact", "paper"):
        mean, cov = gmm.regress(query, in_dims=[0], covariance=mode)
        assert mean.shape == (7, 2) and cov.shape == (7, 2, 2)
    mean_default, _ = gmm.regress(query, in_dims=[0])
    np.testing.assert_array_equal(mean_default, gmm.regress(query, [0], covariance="exact")[0])


def test_robot_as_documented(katana: pbdkit.Robot, tmp_path: Path) -> None:
    n = katana.n_joints
    assert n == 5 and len(katana.joint_names) == n
    for limits in (
        katana.lower,
        katana.upper,
        katana.velocity_limit,
        katana.acceleration_limit,
        katana.jerk_limit,
    ):
        assert limits.shape == (n,) and limits.dtype == np.float64
    q = 0.5 * (katana.lower + katana.upper)
    batch = np.stack([q, q + 0.1])
    assert katana.fk(q).shape == (3,) and katana.fk(batch).shape == (2, 3)
    assert katana.jacobian(q).shape == (3, n) and katana.jacobian(batch).shape == (2, 3, n)
    again = pbdkit.Robot.from_urdf(
        robots.katana_urdf_path(), tip="tool", joint_limits=robots.katana_joint_limits_path()
    )
    np.testing.assert_array_equal(again.fk(q), katana.fk(q))
    panda = robots.panda()
    assert panda.n_joints == 7 and np.all(np.isfinite(panda.jerk_limit))
    assert isinstance(katana, robots.KinematicModel)


def test_demonstrations_as_documented(
    demos: list[pbdkit.Demonstration], katana: pbdkit.Robot, tmp_path: Path
) -> None:
    d = demos[0]
    t_len = d.t.shape[0]
    made = pbdkit.Demonstration(
        t=d.t, joints=d.joints, objects={"glass": d.objects["glass"]}, gripper=None
    )
    assert made.joints.shape == (t_len, katana.n_joints)
    pbdkit.save_demonstrations(demos, tmp_path / "demos.npz")
    back = pbdkit.load_demonstrations(tmp_path / "demos.npz")
    assert len(back) == len(demos)
    np.testing.assert_array_equal(back[0].joints, d.joints)


def test_skill_reproduction_as_documented(
    skill: pbdkit.Skill, demos: list[pbdkit.Demonstration], katana: pbdkit.Robot, tmp_path: Path
) -> None:
    names = skill.object_names
    assert skill.constraint_names == ["joint", *names]
    assert set(skill.gmms) == set(skill.constraint_names)
    assert all(isinstance(g, pbdkit.GMM) for g in skill.gmms.values())
    assert skill.n_steps == 120 and skill.robot is katana
    assert set(skill.selection_) == set(skill.constraint_names)
    assert skill.n_components_ == {k: g.n_components_ for k, g in skill.gmms.items()}
    assert skill.n_components == skill.n_components_  # the read-only alias
    with pytest.raises(AttributeError):
        skill.n_components = {}  # type: ignore[misc]
    objects = {k: demos[0].objects[k] for k in names}
    res = skill.reproduce(objects, q0=None, use=None, alpha=0.5)
    assert isinstance(res, pbdkit.ReproductionResult)
    big_t, n = res.joints.shape
    assert n == katana.n_joints and res.t.shape == (big_t,)
    assert res.positions.shape == (big_t, 3) and res.covariances.shape == (big_t, n, n)
    assert res.gripper.shape == (big_t,) and res.gripper.dtype == np.bool_
    assert set(res.influence) == set(skill.constraint_names)
    np.testing.assert_allclose(sum(res.influence.values()), 1.0, atol=1e-9)
    assert skill.times(res).shape == (big_t,)
    for use in (["joint"], [names[0]]):
        assert skill.reproduce(objects, use=use).joints.shape[1] == n
    # An object as a position (3,), a 4x4 pose, or (x, y, z, qw, qx, qy, qz).
    pose = np.eye(4)
    pose[:3, 3] = objects[names[0]]
    seven = np.concatenate([objects[names[0]], [1.0, 0.0, 0.0, 0.0]])
    for placement in (pose, seven):
        assert skill.reproduce({**objects, names[0]: placement}).joints.shape[1] == n
    skill.save(tmp_path / "skill.npz")
    back = pbdkit.Skill.load(tmp_path / "skill.npz")
    np.testing.assert_array_equal(back.reproduce(objects).joints, res.joints)


def test_the_controller_as_documented(
    skill: pbdkit.Skill, demos: list[pbdkit.Demonstration]
) -> None:
    objects = {k: demos[0].objects[k] for k in skill.object_names}
    ctrl = skill.controller(objects, q0=None, use=None, alpha=0.5)
    assert isinstance(ctrl, pbdkit.Controller) and ctrl.dt > 0 and not ctrl.done
    q = demos[0].joints[0]
    cmd = ctrl.step(q, objects=None)
    assert isinstance(cmd, pbdkit.Command)
    assert cmd.q.shape == (q.shape[0],) and cmd.covariance.shape == (q.shape[0],) * 2
    assert isinstance(cmd.index, int) and isinstance(cmd.gripper, bool)
    assert isinstance(cmd.held, bool) and set(cmd.influence) == set(skill.constraint_names)
    stream = skill.controller(objects).stream(500.0)
    assert stream.step(q).shape == (q.shape[0],) and not stream.done


def test_alignment_as_documented(demos: list[pbdkit.Demonstration], katana: pbdkit.Robot) -> None:
    aligned = pbdkit.align(demos, katana, band=0.3, reference="medoid")
    assert len(aligned) == len(demos) and all(isinstance(d, pbdkit.Demonstration) for d in aligned)
    assert all(np.array_equal(a.joints, d.joints) for a, d in zip(aligned, demos, strict=True))
    trajs = [np.column_stack([d.t, d.joints]) for d in demos]
    out = pbdkit.align_trajectories(trajs, band=0.3, reference="medoid")
    assert [o.shape for o in out] == [x.shape for x in trajs]
    skill = pbdkit.Skill.learn(demos, katana, n_steps=60, n_components=3, align=True)
    assert skill.aligned_ and skill.aligned_.applied
    assert not pbdkit.Skill.learn(demos, katana, n_steps=60, n_components=3, align=False).aligned_


def test_frame_model_as_documented() -> None:
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 1.0, 40)
    trajectories, frames = [], []
    for _ in range(4):
        b = rng.normal(0.0, 1.0, 2)
        trajectories.append(np.column_stack([t, b + np.column_stack([t, t**2])]))
        frames.append([(np.eye(2), b)])
    model = pbdkit.FrameModel.learn(trajectories, frames, n_components="auto")
    mean, cov = model.reproduce([(np.eye(2), np.zeros(2))], t)
    assert mean.shape == (40, 2) and cov.shape == (40, 2, 2)


def test_datasets_as_documented(katana: pbdkit.Robot) -> None:
    lasa = pbdkit.datasets.lasa("GShape")
    assert len(lasa) == 7 and lasa[0].pos.shape[1] == 2
    q = 0.5 * (katana.lower + katana.upper)
    data = pbdkit.datasets.reach_grasp_return(
        katana, center=[0.3, 0.0, 0.05], home=q, n_demos=3, seed=0
    )
    assert len(data.demos) == 3 and isinstance(data.demos[0], pbdkit.Demonstration)


def test_bags_as_documented(tmp_path: Path, katana: pbdkit.Robot) -> None:
    t = np.linspace(0.0, 1.0, 11)
    joints = np.tile(0.5 * (katana.lower + katana.upper), (11, 1))
    pbdkit.write_trajectory_bag(tmp_path / "traj", t, joints, katana.joint_names)
    assert (tmp_path / "traj").exists()


@pytest.mark.slow
def test_the_commands_and_evaluate_json(tmp_path: Path) -> None:
    from pbdkit.apps import main  # the console script's entry point

    assert callable(main)
    from pbdkit.apps._cli import app

    runner = CliRunner()
    names = {"demo", "evaluate", "teach", "learn", "reproduce", "study", "view"}
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    assert all(name in result.output for name in names)
    pytest.importorskip("mujoco")
    out = tmp_path / "eval.json"
    args = ["evaluate", "--task", "coaster", "--trials", "1", "--seed", "0", "--ground-truth"]
    result = runner.invoke(app, [*args, "--controller", "fused", "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["task"] == "coaster" and data["trials"] == 1
    assert isinstance(data["controllers"]["fused"]["success_rate"], float)
