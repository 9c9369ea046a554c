"""The simulated tasks' scenes, ``--perturb obstacle`` and the collision check of every run
(issue 38, item 6)."""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace

import numpy as np
import pytest

from pbdkit.collision import Box, CollisionChecker, Scene
from pbdkit.robots import katana
from pbdkit.sim import get_task
from pbdkit.sim._evaluation import evaluate
from pbdkit.sim._obstacle import avoided_scene, run_collisions
from pbdkit.sim._perturb import OBSTACLE_NAME, DisturbanceSetup, PlaceObstacle, place_obstacle
from pbdkit.sim._runs import run_controller, run_online
from pbdkit.sim._task_skill import TaskSkill
from pbdkit.sim._trials import TrialConditions
from pbdkit.sim._world import build_scene


@pytest.fixture(scope="module")
def coaster(small_task_skill: Callable[..., TaskSkill]) -> TaskSkill:
    # Small: 3 fast demonstrations, a coarse time grid (test_online.py's too).
    return small_task_skill("coaster", 3, seed=1, n_steps=150)


def _setup(ts: TaskSkill, truth: dict[str, np.ndarray]) -> DisturbanceSetup:
    """What ``--perturb obstacle``'s factory is given for a trial at ``truth``."""
    return DisturbanceSetup(
        task=ts.task,
        objects=truth,
        times=np.zeros(2),
        gripper=None,
        rng=np.random.default_rng(0),
        skill=ts.skill,
    )


@pytest.mark.parametrize("task", ["coaster", "basin", "slot"])
def test_a_tasks_scene_is_its_simulated_worlds_bodies(task: str) -> None:
    # Every obstacle of the scene is the MuJoCo geom of the same name: same centre, same size.
    mujoco = pytest.importorskip("mujoco")
    spec = get_task(task)
    objects = spec.sample_objects(np.random.default_rng(3))
    scene = spec.scene(spec.full_placement(objects))
    model, _ = build_scene(spec, objects)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for shape in scene.shapes:
        assert isinstance(shape, Box)
        geom = model.geom(str(shape.name))
        np.testing.assert_allclose(data.geom_xpos[geom.id], shape.pose[:3, 3], atol=1e-9)
        np.testing.assert_allclose(2.0 * model.geom_size[geom.id], shape.size, atol=1e-9)
    assert scene.names[0] == "table"
    assert set(scene.objects) <= set(spec.ranges)


@pytest.mark.parametrize("task", ["coaster", "basin", "slot"])
def test_the_teachers_demonstrations_are_free_of_the_scene(
    task: str, fast_demos: Callable[..., list]
) -> None:
    # The grasp rules at work: the hand closes on the grasped object, which rests on its
    # support and is put on its target; nothing else touches.
    spec = get_task(task)
    for demo in fast_demos(task, 2, 1):
        objects = spec.full_placement(dict(demo.objects))
        checker = CollisionChecker(katana(), spec.scene(objects), objects)
        report = checker.check(demo.joints, demo.gripper)
        assert report.free, report.collisions[:3]
        assert [g[0] for g in checker.grasps] == [spec.grasped]


def test_the_obstacle_sits_on_the_fused_path_at_mid_carry(coaster: TaskSkill) -> None:
    spec, skill = coaster.task, coaster.skill
    truth = spec.sample_objects(np.random.default_rng(0))
    act = place_obstacle(_setup(coaster, truth))
    res = skill.reproduce({k: truth[k] for k in skill.object_names}, on_unreachable="warn")
    np.testing.assert_allclose(act.box.pose[:3, 3], res.positions[act.step])
    closed = np.flatnonzero(res.gripper & ~res.lead_in)
    assert closed[0] < act.step < closed[-1]
    assert abs(act.step - (closed[0] + closed[-1]) / 2) <= 1
    assert act.as_dict()["name"] == "obstacle" and act.box.name == OBSTACLE_NAME
    # What the fused controller avoids: the box and the objects' shapes (the carried glass).
    scene = avoided_scene(spec, spec.full_placement(truth), act, whole=False)
    assert scene is not None and scene.names == [OBSTACLE_NAME]
    assert set(scene.objects) == {"glass", "coaster"}
    whole = avoided_scene(spec, spec.full_placement(truth), act, whole=True)
    assert whole is not None and {"table", "shelf_board", OBSTACLE_NAME} <= set(whole.names)


def test_a_run_through_the_obstacle_is_a_collision(coaster: TaskSkill) -> None:
    spec, skill = coaster.task, coaster.skill
    truth = spec.full_placement(spec.sample_objects(np.random.default_rng(0)))
    res = skill.reproduce({k: truth[k] for k in skill.object_names}, on_unreachable="warn")
    ex = SimpleNamespace(t=res.times, joints=res.joints, gripper=res.gripper)
    act = place_obstacle(_setup(coaster, truth))
    hit = run_collisions(skill.robot, spec, truth, ex, act)  # type: ignore[arg-type]
    assert hit["collided"] and hit["min_clearance_m"] < 0.0
    assert any(OBSTACLE_NAME in c for c in hit["contacts"])
    free = run_collisions(skill.robot, spec, truth, ex, None)  # type: ignore[arg-type]
    assert not free["collided"] and free["contacts"] == []


def test_the_online_fused_controller_keeps_clear_of_a_box(coaster: TaskSkill) -> None:
    # The online controller in the physics loop, a box of the world 7.5 cm under the fused
    # path at mid-carry: the carried glass grazes it unless every plan keeps clear of it.
    # This small skill's carry runs at the step bound (0.1 rad a step): lifted over the box,
    # the glass cannot come down to the coaster in time on most placements, and the plan is
    # refused, without contact (test_a_plan_that_cannot_keep_clear_is_not_played). Of the
    # placements of seeds 0-5 one passes offline, with this skill (seed 1) as with the skill
    # of before the hand's speed entered the alignment (seed 0).
    spec = coaster.task
    truth = spec.full_placement(spec.sample_objects(np.random.default_rng(1)))
    step = place_obstacle(_setup(coaster, truth)).step
    at = coaster.skill.reproduce({k: truth[k] for k in coaster.skill.object_names}).positions
    box = Box((0.05, 0.05, 0.05), at[step] - np.array([0.0, 0.0, 0.075]), name=OBSTACLE_NAME)
    act = PlaceObstacle(box=box, step=step)
    blind = run_online(coaster, truth, "fused", disturbance=act).as_dict()
    assert blind["collided"] and any(OBSTACLE_NAME in c for c in blind["contacts"])
    avoid = avoided_scene(spec, truth, act, whole=False)
    run = run_online(coaster, truth, "fused", disturbance=act, avoid=avoid).as_dict()
    assert run["success"] and not run["collided"] and "fault" not in run, run["contacts"]
    assert run["min_clearance_m"] > 0.002
    # --online takes --perturb obstacle and --avoid-scene now.
    conditions = TrialConditions(online=True, perturb="obstacle", avoid_scene=True)
    assert conditions.online and conditions.avoid_scene
    with pytest.raises(ValueError, match="avoid_scene must be True or False"):
        TrialConditions(avoid_scene="yes")  # type: ignore[arg-type]


def test_evaluate_reports_collisions_per_controller(coaster: TaskSkill) -> None:
    ev = evaluate(
        "coaster",
        1,
        0,
        task_skill=coaster,
        controllers=["fused", "task:glass"],
        ground_truth=True,
        perturb="obstacle",
    )
    data = ev.as_dict()
    assert data["perturb"] == "obstacle" and data["avoid_scene"] is False
    for name in ("fused", "task:glass"):
        stats = data["controllers"][name]
        (row,) = data["runs"][name]
        assert stats["collision_rate"] == float(row["collided"])
        assert stats["min_clearance_m"] == row["min_clearance_m"]
    (p,) = data["perturbations"]
    assert p["name"] == "obstacle" and p["size"] == [0.05, 0.05, 0.05]
    # A single-space controller does not avoid: the glass-only one meets the box. (The
    # joint-space one passed 0.7 mm from it and met the shelf's leg, once the gripper was
    # scored in the joint space's K.)
    (task,) = data["runs"]["task:glass"]
    assert task["collided"] and any(OBSTACLE_NAME in c for c in task["contacts"])


def test_a_plan_that_cannot_keep_clear_is_not_played(coaster: TaskSkill) -> None:
    # A crate over the glass: the grasp (a tight constraint) and the clearance cannot both
    # hold. The plan says so and the simulated arm stays where it starts: a failure, no contact.
    spec = coaster.task
    truth = spec.full_placement(spec.sample_objects(np.random.default_rng(0)))
    crate = Box((0.14, 0.14, 0.14), truth["glass"] + np.array([0.0, 0.0, 0.07]), name="crate")
    act = PlaceObstacle(box=crate, step=0)
    run = run_controller(
        coaster, truth, "fused", disturbance=act, avoid=avoided_scene(spec, truth, act, whole=False)
    )
    assert any("cannot both hold" in w for w in run.warnings)
    summary = run.as_dict()
    assert "crate" in summary["infeasible"] and not summary["success"]
    assert not summary["collided"]
    moved = np.abs(run.execution.joints - run.reproduction.joints[0]).max()
    assert moved < 0.02  # held at the start (the drives' sag under gravity)


def _benchmark_case(
    teach_seed: int, index: int
) -> tuple[TaskSkill, dict[str, np.ndarray], Scene | None]:
    """``benchmarks/obstacle_plans.py``'s case: the coaster skill of ``teach_seed`` (5
    demonstrations), evaluate's placement ``index`` (seed 0) and the scene its box makes."""
    from pbdkit.sim._task_skill import learn_task
    from pbdkit.sim._trials import trial_disturbance

    spec = get_task("coaster")
    ts = learn_task(spec, n_demos=5, seed=teach_seed)
    rng = np.random.default_rng([0, 1])  # evaluate's placements
    truth = [spec.sample_objects(rng) for _ in range(index + 1)][index]
    act = trial_disturbance(ts, TrialConditions(perturb="obstacle"), truth, index=index)
    told = {k: truth[k] for k in ts.skill.object_names}
    return ts, told, avoided_scene(spec, spec.full_placement(truth), act, whole=False)


@pytest.mark.slow
def test_a_box_just_before_the_coaster_is_passed_and_the_glass_still_lands(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The coaster skill of teach seed 1, evaluate's fourth placement: the path goes down to
    # the coaster just past the box. Lifted over it by bumps linearized once a pass, the glass
    # would land 20 mm off the coaster where its constraint is tight, so the plan was refused
    # (39 of 50 such plans with this skill, benchmarks/obstacle_plans.py --teach-seed 1); now
    # it keeps clear and puts the glass where the plain run does.
    import pbdkit.reproduction._probabilistic_ik as pik

    ts, told, scene = _benchmark_case(teach_seed=1, index=3)
    plain = ts.skill.reproduce(told, scene=scene, avoid=False, on_unreachable="warn")
    res = ts.skill.reproduce(told, scene=scene, on_unreachable="warn")
    assert plain.collisions and not res.collisions and res.infeasible is None
    assert res.clearance is not None and res.clearance.min() > 0.015
    release = np.flatnonzero(res.gripper[:-1] & ~res.gripper[1:])[0]
    kept = np.flatnonzero(plain.gripper[:-1] & ~plain.gripper[1:])[0]
    assert np.linalg.norm(res.positions[release] - plain.positions[kept]) < 0.005
    # Each fallback alone keeps clear too, and since the bump ends before the glass's tight
    # phases (Avoidance's tight) and is linearized at each step's posture, so does over it
    # only (refused before both). Where no growth at all is let at a tight step, the plan is
    # refused, and the message says why.
    for hold, beside in ((True, False), (False, True), (False, False)):
        monkeypatch.setattr(pik, "HOLD", hold)
        monkeypatch.setattr(pik, "BESIDE", beside)
        alone = ts.skill.reproduce(told, scene=scene, on_unreachable="warn")
        assert not alone.collisions and alone.infeasible is None, (hold, beside)
        assert alone.clearance is not None and alone.clearance.min() > 0.015, (hold, beside)
    monkeypatch.setattr(pik, "CONFLICT", 0.0)
    monkeypatch.setattr(pik, "LEFT_SIGMAS", 0.0)
    with pytest.warns(pik.CollisionWarning):
        over = ts.skill.reproduce(told, scene=scene, on_unreachable="warn")
    assert over.collisions and "keeping clear would take the hand" in (over.infeasible or "")


@pytest.mark.slow
def test_passes_that_end_short_of_the_margin_are_held_too() -> None:
    # The coaster skill of teach seed 0, evaluate's placement 13: the 14 passes over the box
    # keep clear of it but end 2.7 mm from it, short of the 20 mm margin (their best; its
    # neighbour placement 1's best, 1.7 mm at the samples, went 1.6 mm into the box between
    # two). Held across the bump's direction the passes reach the margin (19.8 mm), and that
    # plan is kept.
    ts, told, scene = _benchmark_case(teach_seed=0, index=13)
    res = ts.skill.reproduce(told, scene=scene, on_unreachable="warn")
    assert not res.collisions and res.infeasible is None
    assert res.clearance is not None and res.clearance.min() > 0.015
