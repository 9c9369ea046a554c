"""Tests of the simulated world: tasks as data, scene, kinematic agreement, cameras, physics,
teacher, and the experiment's configuration (which objects a task's skill constrains)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")

import mujoco
from typer.testing import CliRunner

from pbdkit._defaults import MAX_COMPONENTS
from pbdkit.apps._cli import app
from pbdkit.data._demonstration import load_demonstrations
from pbdkit.motion._limits import LIMIT_SAFETY, MotionLimits, StreamMonitor, motion_peaks
from pbdkit.motion._otg import follow
from pbdkit.robots import katana
from pbdkit.sim import (
    Outcome,
    PlacementRange,
    Simulation,
    TaskSpec,
    ViaPoint,
    build_scene,
    execute,
    get_task,
    register_task,
    sample_objects,
    task_names,
    teach,
)
from pbdkit.sim import _glass as G
from pbdkit.sim._evaluation import Evaluation, evaluate, summarize
from pbdkit.sim._execute import TIMESTEP, Recorder, servo_stream
from pbdkit.sim._runs import ControllerRun, run_controller
from pbdkit.sim._task_registry import unregister_task
from pbdkit.sim._task_skill import TaskSkill, constrained_objects, learn_task
from pbdkit.sim._taskdefs import basin as B
from pbdkit.sim._taskdefs import coaster as C
from pbdkit.sim._tasks import RunStats
from pbdkit.sim._teacher import (
    APPROACH,
    UP,
    Person,
    between,
    grasp_via_points,
    radial,
    solve_ik,
    tool_pitch,
)
from pbdkit.sim._trials import Trial, TrialConditions
from pbdkit.sim._world import CAMERA_POSITIONS, CAMERA_TARGET, add_glass
from pbdkit.skill._naming import controller_names
from pbdkit.skill._skill import Skill


def _red_mask(image: np.ndarray) -> np.ndarray:
    rgb = image.astype(np.int32)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 90) & (r > 2.5 * g) & (r > 2.5 * b)


@pytest.mark.parametrize("task", ["coaster", "basin"])
def test_tool_position_matches_pinocchio(task: str) -> None:
    # The scene's arm comes from the same URDF text as the kinematics: no offset may creep in.
    rng = np.random.default_rng(0)
    robot = katana()
    with Simulation.from_task(get_task(task)) as sim:
        for _ in range(200):
            q = rng.uniform(robot.lower, robot.upper)
            sim.set_joints(q)
            np.testing.assert_allclose(sim.tool_position(), robot.fk(q), rtol=0, atol=1e-9)
            assert np.allclose(sim.joints(), q, rtol=0, atol=1e-12)


def test_tool_pitch_and_roll_conventions() -> None:
    # The teacher relies on pitch = lift1 + lift2 - lift3 and on the roll leaving the tool
    # point in place; both are checked against MuJoCo's tool frame.
    rng = np.random.default_rng(1)
    robot = katana()
    with Simulation.from_task(get_task("coaster")) as sim:
        for _ in range(50):
            q = rng.uniform(robot.lower, robot.upper)
            sim.set_joints(q)
            axis = sim.tool_rotation()[:, 0]  # the tool's x axis points out of the gripper
            # elevation of the tool axis, with the sign of its horizontal part along the pan
            horiz = axis[0] * math.cos(q[0]) + axis[1] * math.sin(q[0])
            pitch = math.atan2(axis[2], horiz)
            diff = (pitch - tool_pitch(q) + math.pi) % (2 * math.pi) - math.pi
            assert abs(diff) < 1e-9
            x0 = sim.tool_position()
            q2 = q.copy()
            q2[4] = rng.uniform(robot.lower[4], robot.upper[4])
            sim.set_joints(q2)
            np.testing.assert_allclose(sim.tool_position(), x0, rtol=0, atol=1e-12)


def test_build_scene_places_objects_and_validates() -> None:
    rng = np.random.default_rng(2)
    objects = sample_objects("coaster", rng)
    model, info = build_scene(get_task("coaster"), objects)
    assert model.nu == 12  # 5 position + 5 velocity servos, 2 fingers
    assert info.n_liquid == 0
    for name, p in objects.items():
        np.testing.assert_allclose(info.objects[name], p, rtol=0, atol=1e-12)
    sim = Simulation(model, info)
    np.testing.assert_allclose(sim.object_positions()["glass"], objects["glass"], atol=1e-9)
    sim.step(250)  # the glass rests on the shelf: it does not move
    np.testing.assert_allclose(sim.object_positions()["glass"], objects["glass"], atol=5e-4)

    _, info_b = build_scene(get_task("basin"), seed=0)
    assert info_b.n_liquid == B.N_LIQUID
    assert info_b.spec is get_task("basin") and info_b.task == "basin"

    with pytest.raises(ValueError, match=r"spec must be a TaskSpec .*get_task.*got 'coaster'"):
        build_scene("coaster")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown object"):
        build_scene(get_task("coaster"), {"cup": [0.5, 0.0, 0.1]})
    with pytest.raises(ValueError, match=r"objects\['glass'\]: z must be"):
        build_scene(get_task("coaster"), {"glass": [0.47, 0.2, 0.5]})
    with pytest.raises(ValueError, match="fixed"):
        build_scene(get_task("basin"), {"basin": [0.3, -0.2, B.BASIN_FLOOR]})
    with pytest.raises(ValueError, match="finite"):
        build_scene(get_task("coaster"), {"glass": [np.nan, 0.2, 0.175]})


def test_sample_objects_inside_ranges() -> None:
    rng = np.random.default_rng(3)
    for task in task_names():
        ranges = get_task(task).ranges
        for _ in range(20):
            objects = sample_objects(task, rng)
            assert set(objects) == set(ranges)
            assert all(ranges[k].contains(v) for k, v in objects.items())
    assert get_task("basin").ranges["basin"].fixed


def test_tracked_and_fixed_objects_come_from_the_ranges() -> None:
    coaster_spec, basin_spec = get_task("coaster"), get_task("basin")
    assert coaster_spec.tracked_objects == ("glass", "coaster")
    assert coaster_spec.fixed_objects == ()
    assert basin_spec.tracked_objects == ("glass",)
    assert basin_spec.fixed_objects == ("basin",)
    rng = np.random.default_rng(20)
    glass = sample_objects("basin", rng)["glass"]
    placement = basin_spec.full_placement({"glass": glass})
    assert list(placement) == ["glass", "basin"]
    np.testing.assert_array_equal(placement["glass"], glass)
    np.testing.assert_array_equal(placement["basin"], basin_spec.ranges["basin"].low)
    coaster = sample_objects("coaster", rng)
    full = coaster_spec.full_placement(coaster)
    assert all(np.array_equal(full[k], coaster[k]) for k in coaster)
    with pytest.raises(ValueError, match=r"missing position\(s\) for \['glass'\]"):
        basin_spec.full_placement({"basin": placement["basin"]})
    with pytest.raises(ValueError, match=r"missing position\(s\) for \['coaster'\]"):
        coaster_spec.full_placement({"glass": coaster["glass"]})
    with pytest.raises(ValueError, match=r"unknown object\(s\) \['coaster'\]"):
        basin_spec.full_placement({"glass": glass, "coaster": coaster["coaster"]})
    with pytest.raises(ValueError, match="task must be one of"):
        sample_objects("juggling", rng)


def test_constrained_objects_are_the_moving_ones_unless_asked() -> None:
    basin, coaster = get_task("basin"), get_task("coaster")
    assert constrained_objects(basin) == ["glass"]
    assert constrained_objects(basin, constrain_fixed=True) == ["glass", "basin"]
    # Nothing is fixed in the coaster task: the option changes nothing there.
    for flag in (False, True):
        assert constrained_objects(coaster, constrain_fixed=flag) == ["glass", "coaster"]


@pytest.mark.parametrize(
    ("constrain_fixed", "constraints"),
    [(False, ["joint", "glass"]), (True, ["joint", "glass", "basin"])],
)
def test_basin_skill_constraints(constrain_fixed: bool, constraints: list[str]) -> None:
    ts = learn_task(
        "basin", n_demos=2, seed=21, n_steps=100, max_components=2, constrain_fixed=constrain_fixed
    )
    # The demonstrations record the basin either way (a user's recording would).
    assert all(set(d.objects) == {"glass", "basin"} for d in ts.demos)
    assert ts.skill.constraint_names == constraints
    assert ts.constrain_fixed is constrain_fixed
    assert controller_names(ts.skill.object_names) == [
        "fused",
        "joint",
        *(f"task:{k}" for k in constraints[1:]),
    ]


@pytest.fixture(scope="module")
def basin_skill(small_task_skill: Callable[..., TaskSkill]) -> TaskSkill:
    # The paper's configuration, small: a fast teacher, 2 demonstrations, a coarse time grid.
    return small_task_skill("basin", 2, seed=22, n_steps=100, max_components=3)


@pytest.mark.slow
def test_basin_run_without_a_basin_constraint_is_judged_on_the_scene_basin(
    basin_skill: TaskSkill,
) -> None:
    assert basin_skill.skill.object_names == ["glass"]
    rng = np.random.default_rng(23)
    glass = sample_objects("basin", rng)["glass"]
    # The robot knows the glass only; the basin comes from the task's fixed geometry.
    run = run_controller(basin_skill, {"glass": glass}, "fused")
    assert list(run.objects) == ["glass"]
    basin = get_task("basin").ranges["basin"].low
    np.testing.assert_allclose(run.execution.objects["basin"][-1], basin, atol=1e-12)
    m = run.execution.outcome.metrics
    assert set(m) == {"liquid_fraction", "held", "pour_error_mm", "tilt_deg"}
    # The judge counted the spheres in the scene's basin (recomputed here from the same box).
    liquid, half = run.execution.liquid, B.BASIN_INNER / 2
    inside = (
        np.all(np.abs(liquid[:, :2] - basin[:2]) < half, axis=1)
        & (liquid[:, 2] < basin[2] + B.BASIN_WALL_HEIGHT)
        & (liquid[:, 2] > basin[2] - 0.005)
    )
    assert m["liquid_fraction"] == pytest.approx(inside.mean(), abs=1e-12)
    assert run.success == (m["held"] == 1.0 and m["liquid_fraction"] >= 0.9)
    assert run.as_dict()["success"] is run.success
    # A moving object the robot does not know is an error, not a guess.
    with pytest.raises(ValueError, match=r"missing position\(s\) for \['glass'\]"):
        run_controller(basin_skill, {"basin": basin}, "fused")
    with pytest.raises(
        ValueError, match=r"controller must be one of \['fused', 'joint', 'task:glass'\]"
    ):
        run_controller(basin_skill, {"glass": glass}, "task:basin")


def test_render_frames_and_red_patch_in_both_cameras() -> None:
    with Simulation.from_task(get_task("coaster")) as sim:
        glass = sim.object_positions()["glass"]
        for cam in sim.info.cameras:
            image = sim.render(cam)
            assert image.shape == (240, 320, 3)
            assert image.dtype == np.uint8
            red = _red_mask(image)
            assert red.sum() > 30, f"red patch not visible in {cam}"
            # The patch's centroid lies where the camera model projects the glass (the band's
            # visible front is a few pixels off the axis point).
            K, R, t, w, h = sim.camera_parameters(cam)
            assert (w, h) == (320, 240)
            uvw = K @ (R @ glass + t)
            uv = uvw[:2] / uvw[2]
            rows, cols = np.nonzero(red)
            assert abs(cols.mean() - uv[0]) < 6.0
            assert abs(rows.mean() - uv[1]) < 10.0


def test_camera_parameters_conventions() -> None:
    with Simulation.from_task(get_task("basin")) as sim:
        centres = []
        for cam in sim.info.cameras:
            K, R, t, w, h = sim.camera_parameters(cam)
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
            assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
            centre = -R.T @ t
            np.testing.assert_allclose(centre, CAMERA_POSITIONS[cam], atol=1e-9)
            centres.append(centre)
            # OpenCV convention: the look-at point is in front (z > 0) at the image centre.
            pc = R @ np.array(CAMERA_TARGET) + t
            assert pc[2] > 0
            uv = (K @ pc)[:2] / pc[2]
            np.testing.assert_allclose(uv, [(w - 1) / 2, (h - 1) / 2], atol=1e-6)
            # y down: a point above the target is higher in the image (smaller v)
            above = R @ (np.array(CAMERA_TARGET) + np.array([0.0, 0.0, 0.1])) + t
            assert (K @ above)[1] / above[2] < uv[1]
        assert np.linalg.norm(centres[0] - centres[1]) == pytest.approx(0.30)
        with pytest.raises(ValueError, match="camera must be one of"):
            sim.render("cam_top")


def test_solve_ik_reaches_targets() -> None:
    rng = np.random.default_rng(4)
    robot = katana()
    for _ in range(20):
        q_true = rng.uniform(robot.lower + 0.3, robot.upper - 0.3)
        x = robot.fk(q_true)
        q = solve_ik(robot, x, float(tool_pitch(q_true)), float(q_true[4]), q_true + 0.05)
        np.testing.assert_allclose(robot.fk(q), x, rtol=0, atol=1e-6)
        assert tool_pitch(q) == pytest.approx(tool_pitch(q_true), abs=1e-6)
    with pytest.raises(ValueError, match="IK did not reach"):
        solve_ik(robot, np.array([2.0, 0.0, 0.2]), 0.0, 0.0, np.zeros(5))


def test_execute_validates_input() -> None:
    sim = Simulation.from_task(get_task("coaster"))
    t = np.linspace(0.0, 1.0, 11)
    q = np.zeros((11, 5))
    with pytest.raises(ValueError, match="joints must have shape"):
        execute(sim, t, q[:, :4])
    with pytest.raises(ValueError, match="strictly increasing"):
        execute(sim, t[::-1], q)
    with pytest.raises(ValueError, match="gripper must be"):
        execute(sim, t, q, np.ones(3))
    with pytest.raises(ValueError, match="finite"):
        execute(sim, t, np.full((11, 5), np.nan))
    with pytest.raises(ValueError, match="duration must be"):
        execute(sim, t, q, duration=-1.0)
    with pytest.raises(ValueError, match=r"velocities must have shape \(11, 5\)"):
        execute(sim, t, q, velocities=np.zeros((10, 5)))
    with pytest.raises(ValueError, match="limits must be for the arm's 5 joints"):
        execute(sim, t, q, limits=MotionLimits.unlimited(4))
    # Time steps of a reproduction, played over 0.2 s.
    res = execute(sim, np.arange(11.0), q, settle=0.0, record_rate=100.0, duration=0.2)
    assert res.t[-1] == pytest.approx(0.2, abs=0.011)


@pytest.mark.slow
def test_teacher_demonstrations_structure() -> None:
    robot = katana()
    demos = teach("coaster", n_demos=3, seed=5)
    durations = [d.t[-1] for d in demos]
    assert len(set(np.round(durations, 2))) > 1  # a person's timing varies
    for d in demos:
        np.testing.assert_allclose(np.diff(d.t), 0.01, atol=1e-9)  # 100 Hz encoders
        assert np.all(d.joints >= robot.lower) and np.all(d.joints <= robot.upper)
        # the Katana's motors cap joint speeds (1.19 rad/s): the teacher stays below
        speed = np.abs(np.diff(d.joints, axis=0)) / np.diff(d.t)[:, None]
        assert np.all(speed <= robot.velocity_limit)
        assert set(d.objects) == {"glass", "coaster"}
        assert d.gripper is not None
        x = robot.fk(d.joints)
        # Tight relative to the glass when the gripper closes, to the coaster when it opens.
        close = int(np.argmax(d.gripper > 0.5))
        open_ = close + int(np.argmax(d.gripper[close:] < 0.5))
        np.testing.assert_allclose(x[close] - d.objects["glass"], G.GRASP_OFFSET, atol=1e-6)
        expected = np.array([0.0, 0.0, G.GLASS_PATCH_CENTER + 0.002]) + G.GRASP_OFFSET
        np.testing.assert_allclose(x[open_] - d.objects["coaster"], expected, atol=1e-6)
    basin = teach("basin", n_demos=2, seed=6)
    # The pouring gesture is the same in joint space: roll profiles after the roll starts.
    rolls = []
    for d in basin:
        k = int(np.argmax(d.joints[:, 4] > 0.1))
        rolls.append(d.joints[k : k + 400, 4])
    np.testing.assert_allclose(rolls[0], rolls[1], atol=0.1)
    assert max(rolls[0]) > 1.9


def _run_demos(task: str, n: int, seed: int) -> list[dict[str, float]]:
    metrics = []
    for i, d in enumerate(teach(task, n_demos=n, seed=seed)):
        with Simulation.from_task(get_task(task), d.objects, seed=i) as sim:
            res = execute(sim, d.t, d.joints, d.gripper, settle=0.8, record_rate=20.0)
        assert res.outcome.success, (task, i, res.outcome.metrics)
        # the servos track the demonstration: no collision held the arm back
        assert np.max(np.abs(res.joints - res.targets)) < 0.01
        metrics.append(res.outcome.metrics)
    return metrics


@pytest.mark.slow
def test_teacher_coaster_demonstrations_succeed_in_physics() -> None:
    # Physical grasp (friction only) holds through lift and carry; the glass ends upright on
    # the coaster, centred within 15 mm.
    for m in _run_demos("coaster", n=2, seed=7):
        assert m["placement_error_mm"] < 15.0
        assert m["tilt_deg"] < 10.0


@pytest.mark.slow
def test_teacher_basin_demonstration_succeeds_in_physics() -> None:
    (m,) = _run_demos("basin", n=1, seed=8)
    assert m["liquid_fraction"] >= 0.9
    assert m["held"] == 1.0


@pytest.mark.slow
@pytest.mark.parametrize("task", ["coaster", "basin"])
def test_every_demonstration_succeeds(task: str) -> None:
    _run_demos(task, n=5, seed=11)


def test_execute_records_frames() -> None:
    rng = np.random.default_rng(9)
    robot = katana()
    with Simulation.from_task(get_task("coaster")) as sim:
        q0 = np.array([0.0, 1.6, -1.9, 0.0, 0.0]) + rng.normal(0.0, 0.01, 5)
        t = np.linspace(0.0, 0.5, 51)
        q = np.tile(q0, (51, 1))
        q[:, 0] = np.linspace(q0[0], q0[0] + 0.3, 51)
        res = execute(sim, t, q, None, settle=0.1, camera="cam_left", fps=10.0)
        assert res.frames is not None and res.frames.shape[1:] == (240, 320, 3)
        assert res.frames.shape[0] == res.frame_times.shape[0] >= 5
        np.testing.assert_allclose(res.joints[-1], q[-1], atol=5e-3)
        np.testing.assert_allclose(res.tool[-1], robot.fk(res.joints[-1]), atol=1e-9)
        assert not res.outcome.success  # nothing was placed


def test_save_video(tmp_path: Path) -> None:
    from pbdkit.sim._video import save_video

    rng = np.random.default_rng(10)
    frames = rng.integers(0, 255, size=(6, 240, 320, 3), dtype=np.uint8)
    out = save_video(frames, tmp_path / "run.mp4", fps=15.0)
    assert out.exists() and out.stat().st_size > 1000
    assert [p.name for p in out.parent.iterdir()] == ["run.mp4"]  # no temporary file left
    with pytest.raises(ValueError, match="uint8"):
        save_video(frames.astype(np.float64), tmp_path / "bad.mp4")


@pytest.mark.slow
def test_outcome_detects_a_failed_grasp() -> None:
    # The same motion without closing the gripper never lifts the glass (the open fingers may
    # drag it along the shelf): a failure, with the error measured from where the glass is.
    (d,) = teach("coaster", n_demos=1, seed=12)
    with Simulation.from_task(get_task("coaster"), d.objects) as sim:
        res = execute(sim, d.t, d.joints, np.zeros_like(d.t), settle=0.2, record_rate=10.0)
        glass_xy = sim.grasped_frame()[0][:2]
    assert not res.outcome.success
    assert not res.grasped.any()
    assert np.all(res.objects["glass"][:, 2] < d.objects["glass"][2] + 0.005)
    error = 1e3 * np.linalg.norm(glass_xy - d.objects["coaster"][:2])
    assert res.outcome.metrics["placement_error_mm"] == pytest.approx(error, abs=1e-6)
    assert error > 100.0


@pytest.mark.slow
@pytest.mark.parametrize(("task", "seed"), [("coaster", 1), ("basin", 0), ("basin", 2)])
def test_default_learning_captures_every_demonstrated_feature(task: str, seed: int) -> None:
    # The teach seeds where K by the effective-sample-size BIC lost the pouring gesture
    # (basin 0 and 2: joint K = 3, wrist roll 0.53 rad off at the end) or under-fitted the
    # joints (coaster 1: RMSE 2.15 x the floor). benchmarks/bench_selection.py: seeds 0-9.
    demos = teach(task, 5, seed=seed)
    skill = Skill.learn(demos, katana(), task_objects=constrained_objects(get_task(task)))
    cap = MAX_COMPONENTS
    # No space collapses; the joints' K is interior. (A task space may reach the cap: where
    # the demonstrations agree, narrower components keep predicting a left-out demonstration a
    # little better, e.g. basin 2's glass: 1.55 at K = 20, 1.45 at K = 30.)
    assert all(k >= 2 for k in skill.n_components.values()), skill.n_components
    assert skill.n_components["joint"] <= cap - 1, skill.n_components
    rescaled = np.stack([d.rescaled(skill.n_steps).joints for d in demos])
    mean = skill.constraints().joint_mean
    floor = np.sqrt(((rescaled - rescaled.mean(axis=0)) ** 2).mean(axis=(0, 1)))
    rmse = np.sqrt(((rescaled - mean) ** 2).mean(axis=(0, 1)))
    assert np.all(rmse <= 1.6 * floor), rmse / floor
    if task == "basin":
        roll = rescaled[:, :, 4]
        assert abs(mean[-1, 4] - roll[:, -1].mean()) <= 0.1
        assert mean[:, 4].max() - roll.max() <= 0.1


@pytest.mark.slow
def test_a_run_under_physics_is_the_same_every_time() -> None:
    # The liquid's initial jitter was drawn unseeded: the same joint trajectory could pour or
    # spill from one run to the next (seen on a borderline basin trial).
    (demo,) = teach("basin", n_demos=1, seed=3, speed=2.0)
    runs = []
    for _ in range(2):
        sim = Simulation.from_task(get_task("basin"), dict(demo.objects))
        try:
            ex = execute(sim, demo.t, demo.joints, demo.gripper)
        finally:
            sim.close()
        runs.append(ex)
    np.testing.assert_array_equal(runs[0].liquid, runs[1].liquid)
    np.testing.assert_array_equal(runs[0].joints, runs[1].joints)


# ----------------------------------------------------------------------------- servo stream
KINDS = ("velocity", "acceleration", "jerk")


def _min_jerk(t: np.ndarray, amplitude: np.ndarray, duration: float) -> tuple[np.ndarray, ...]:
    """A rest-to-rest minimum-jerk move: positions, velocities, accelerations (len(t), n)."""
    s = (t / duration)[:, None]
    q = amplitude * (10 * s**3 - 15 * s**4 + 6 * s**5)
    v = amplitude * (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
    a = amplitude * (60 * s - 180 * s**2 + 120 * s**3) / duration**2
    return q, v, a


def test_servo_stream_passes_samples_off_the_physics_grid_on_time() -> None:
    # 55 samples 37 ms apart (off the 2 ms grid) of a move within the Katana's limits: the
    # stream passes each one at its grid step, moved along its motion by the difference.
    limits = MotionLimits.from_robot(katana(), 5)
    amplitude = np.array([0.5, -0.3, 0.1, 0.0, 0.2])
    t = np.linspace(0.0, 2.0, 55)
    q, v, a = _min_jerk(t, amplitude, 2.0)
    pos, vel = servo_stream(t, q, limits, velocities=v, accelerations=a)
    assert pos.shape == vel.shape == (1001, 5)  # at rest at the last sample, on time
    grid = TIMESTEP * np.arange(pos.shape[0])
    q_grid, v_grid, _ = _min_jerk(grid, amplitude, 2.0)
    at_samples = np.ceil(t / TIMESTEP - 1e-9).astype(int)
    # Measured: 3.5e-9 rad at the samples' grid steps, 2e-5 rad between, 1.8e-3 rad/s.
    np.testing.assert_allclose(pos[at_samples], q_grid[at_samples], rtol=0, atol=1e-7)
    np.testing.assert_allclose(pos, q_grid, rtol=0, atol=1e-4)
    np.testing.assert_allclose(vel, v_grid, rtol=0, atol=1e-2)
    peaks = motion_peaks(grid, pos, limits)
    assert max(peaks.velocity, peaks.acceleration, peaks.jerk) <= 1.0
    # Without the samples' derivatives, the cubic spline's are aimed for: as close here.
    pos_spline, _ = servo_stream(t, q, limits)
    np.testing.assert_allclose(pos_spline[at_samples], q_grid[at_samples], rtol=0, atol=1e-7)
    # Without limits: the samples interpolated linearly, the segment's slope as velocity.
    lin, slope = servo_stream(t, q, MotionLimits.unlimited(5))
    for j in range(5):
        np.testing.assert_allclose(lin[:, j], np.interp(grid, t, q[:, j]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(slope[1], (q[1] - q[0]) / (t[1] - t[0]), rtol=1e-12)


def test_recorder_measures_the_servo_stream_as_a_stream_monitor_outside_a_push() -> None:
    # A target stream with a jump at 0.15 s, inside a force window: the jump does not count,
    # with the same numbers as a StreamMonitor told counted=False there.
    limits = MotionLimits.from_robot(katana(), 5)
    rng = np.random.default_rng(40)
    q, _, _ = _min_jerk(TIMESTEP * np.arange(200), rng.uniform(-0.05, 0.05, 5), 0.4)
    q[75:] += 0.02
    window = (0.1, 0.2)
    peaks = {}
    with Simulation.from_task(get_task("coaster")) as sim:
        for name, w in (("push", window), ("none", None)):
            rec = Recorder(sim, 50.0, None, 15.0, force_window=w)
            for k, row in enumerate(q):
                rec.record(k, k * TIMESTEP, row, False)
            ex = rec.result()
            np.testing.assert_array_equal(ex.servo_targets, q)
            peaks[name] = ex.servo_peaks
    for name, w in (("push", window), ("none", None)):
        monitor = StreamMonitor(limits, TIMESTEP)
        for k, row in enumerate(q):
            t = k * TIMESTEP
            monitor.update(row, counted=w is None or not (w[0] <= t <= w[1]))
        np.testing.assert_allclose(
            list(monitor.finish().as_dict().values()),
            list(peaks[name].as_dict().values()),
            rtol=1e-9,  # the monitor's differences on a uniform grid, rounded otherwise
            atol=0,
        )
    assert peaks["none"].acceleration > 100.0  # 0.02 rad in one step
    assert peaks["push"].worst <= 1.0


@pytest.fixture(scope="module")
def coaster_run(
    small_task_skill: Callable[..., TaskSkill],
) -> tuple[TaskSkill, ControllerRun]:
    # A quick coaster skill (3 fast demonstrations, 300 steps), its fused run played offline.
    ts = small_task_skill("coaster", 3, seed=30, n_steps=300, max_components=5)
    placement = sample_objects("coaster", np.random.default_rng(31))
    return ts, run_controller(ts, placement, "fused")


@pytest.mark.slow
def test_playback_servo_stream_is_within_the_limits(
    coaster_run: tuple[TaskSkill, ControllerRun],
) -> None:
    ts, run = coaster_run
    ex, res = run.execution, run.reproduction
    limits = MotionLimits.from_robot(ts.skill.robot, 5)
    for k in KINDS:
        np.testing.assert_array_equal(getattr(ex.servo_limits, k), getattr(limits, k))
    t = ts.skill.times(res)
    n_play = math.ceil((t[-1] - t[0]) / TIMESTEP - 1e-9)
    assert ex.servo_period == TIMESTEP
    # The samples played, then 1 s of settling; the targets come to rest at the last sample
    # on time or a little later where the limits kept them behind (measured: 40 ms; 56 ms
    # before the joints were calibrated against the objects).
    played = ex.servo_targets.shape[0] - round(1.0 / TIMESTEP) - 1
    assert n_play <= played <= n_play + round(0.1 / TIMESTEP)
    np.testing.assert_allclose(
        ex.servo_targets[played:], np.broadcast_to(res.joints[-1], (501, 5)), rtol=0, atol=1e-7
    )
    # What a drive checking its command stream sees, setpoint by setpoint.
    monitor = StreamMonitor(limits, TIMESTEP)
    for row in ex.servo_targets:
        monitor.update(row)
    seen = monitor.finish()
    assert max(seen.velocity, seen.acceleration, seen.jerk) <= 1.0
    np.testing.assert_allclose(  # the same differences, rounded differently
        list(seen.as_dict().values()), list(ex.servo_peaks.as_dict().values()), rtol=1e-8
    )
    # The old playback, the same samples interpolated linearly at 500 Hz, jumps in velocity
    # at every sample: measured 153 rad/s^2 against 5.7 here.
    grid = TIMESTEP * np.arange(n_play + 1)
    linear = np.stack([np.interp(grid, t, res.joints[:, j]) for j in range(5)], axis=1)
    old = motion_peaks(grid, linear, limits)
    assert old.acceleration > 10.0
    assert ex.servo_peaks.acceleration_abs < old.acceleration_abs / 10.0
    # evaluate's JSON per trial.
    summary = run.as_dict()
    for k in KINDS:
        assert 0.0 < summary[f"peak_{k}_ratio"] <= 1.0
        assert summary[f"peak_{k}"] == pytest.approx(getattr(ex.servo_peaks, f"{k}_abs"))
    json.dumps(summary)


@pytest.mark.slow
def test_playback_servos_follow_the_samples(
    coaster_run: tuple[TaskSkill, ControllerRun],
) -> None:
    ts, run = coaster_run
    ex, res = run.execution, run.reproduction
    t = ts.skill.times(res)
    grid = ex.servo_period * np.arange(ex.servo_targets.shape[0])
    # The servo targets are the motion pbdkit.motion._otg.follow makes through the samples; it
    # reaches each sample at its time, or later where the limits kept it behind.
    motion = follow(
        t,
        res.joints,
        ex.servo_limits.scaled(LIMIT_SAFETY),
        velocities=res.velocities,
        accelerations=res.accelerations,
    )
    reached = motion.sample_times
    assert np.all(reached >= t - 1e-9) and np.all(np.diff(reached) > 0)
    assert reached[-1] - t[-1] < 0.1  # measured: 40 ms late at the end (56 before)
    at = np.stack([np.interp(reached, grid, ex.servo_targets[:, j]) for j in range(5)], axis=1)
    off = np.abs(at - res.joints).max(axis=1)
    # Measured: 0.042 rad at worst (a sample the motion passes by toward a later one, where
    # the spline through the samples leaves the limits), 4e-4 rad on average; a follower
    # re-planned at every tick was 0.2 rad off.
    assert off.max() < 0.06
    assert off.mean() < 2e-3
    # The measured joints follow the targets (a glass may hold a finger back a little).
    assert run.as_dict()["following_error_rad"] < 0.03


# ----------------------------------------------------------------------------- tasks as data
def test_the_package_and_the_task_data_import_without_mujoco() -> None:
    # MuJoCo comes with the first name that needs it, after the choice of its OpenGL backend;
    # the built-in tasks (which build MuJoCo scenes) with the first look-up of a task.
    code = (
        "import os, sys\n"
        "import pbdkit.sim, pbdkit.sim._tasks, pbdkit.sim._teacher, pbdkit.sim._task_registry\n"
        "print('mujoco' in sys.modules, 'pbdkit.sim._taskdefs' in sys.modules)\n"
        "print(pbdkit.sim.task_names()[:3] == ('coaster', 'basin', 'slot'))\n"
        "gl = sys.modules['mujoco.rendering.classic.gl_context']\n"
        "print(gl._MUJOCO_GL == os.environ['MUJOCO_GL'] == pbdkit.sim._gl.BACKEND)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    assert out.stdout.split() == ["False", "False", "True", "True"]


def test_task_registry_resolves_names_once_and_refuses_bad_specs() -> None:
    assert task_names()[:2] == ("coaster", "basin")
    spec = get_task("coaster")
    assert get_task(spec) is spec
    assert spec.tracked_objects == ("glass", "coaster")
    with pytest.raises(ValueError, match=r"task must be one of \['coaster', 'basin'"):
        get_task("juggling")
    with pytest.raises(ValueError, match="'coaster' is already registered"):
        register_task(TaskSpec("coaster", "", spec.ranges, *_MARK_FUNCTIONS))
    register_task(spec)  # the same spec again: nothing happens
    table = PlacementRange.box((0.5, 0.1, 0.0), (0.5, 0.2, 0.0))
    with pytest.raises(ValueError, match="must include 'glass'"):
        TaskSpec("cup", "", {"cup": table}, *_MARK_FUNCTIONS)
    with pytest.raises(ValueError, match=r"patches of task 'cup' name object\(s\) \['lid'\]"):
        TaskSpec("cup", "", {"glass": table}, *_MARK_FUNCTIONS, patches={"lid": "lid"})
    with pytest.raises(ValueError, match=r"ranges\['glass'\] must be a box with low <= high"):
        TaskSpec("cup", "", {"glass": PlacementRange(table.high, table.low)}, *_MARK_FUNCTIONS)


# A task of one's own, in one place and nothing else touched: put the glass from the table on a
# green mark on the table (the example of pbdkit.sim._tasks' docstring). The mark moves between
# placements, so the cameras track it (its patch is the mark itself) and the skill gets a
# task-space constraint for it.
MARK_TOP = 0.001  # the mark is a 1 mm disk lying on the table; its point is its top's centre
MARK_MAX_ERROR = 0.02  # m, horizontal distance glass axis - mark centre


def _mark_add_objects(
    world: Any, objects: Mapping[str, np.ndarray], rng: np.random.Generator
) -> None:
    m, g = objects["mark"], objects["glass"]
    world.add_geom(
        name="mark",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[0.03, MARK_TOP / 2, 0.0],
        pos=[m[0], m[1], MARK_TOP / 2],
        rgba=[0.1, 0.7, 0.2, 1.0],
        contype=0,  # painted on the table: the glass stands on the table through it
        conaffinity=0,
    )
    add_glass(world, np.array([g[0], g[1], 0.0]))


def _mark_via_points(
    objects: Mapping[str, np.ndarray], rng: np.random.Generator, speed: float
) -> list[ViaPoint]:
    p = Person(rng, speed)
    g, m = objects["glass"], objects["mark"]
    # Released with the glass's bottom 2 mm above the table, centred on the mark.
    place = m + UP * (G.GLASS_PATCH_CENTER + 0.001) + G.GRASP_OFFSET
    back = APPROACH * radial(m)
    carry = between(g + G.GRASP_OFFSET, place) + UP * 0.08 + p.jitter(0.01)
    return [
        *grasp_via_points(p, g, 0.08, 2.6),
        ViaPoint(p.duration(1.8), carry, p.holding_pitch(), p.roll(), True),
        ViaPoint(p.duration(1.5), place + UP * 0.05, p.holding_pitch(), 0.0, True),
        ViaPoint(p.duration(1.0), place, p.hold_pitch, 0.0, True),
        ViaPoint(p.duration(0.6), place, p.hold_pitch, 0.0, False),  # open and wait
        ViaPoint(
            p.duration(1.8),
            place - back,
            p.hold_pitch,
            0.0,
            False,
            free_pitch=True,
            joint_space=True,
        ),
        ViaPoint(
            p.duration(2.0),
            place - back + UP * 0.08,
            p.free_pitch(),
            0.0,
            False,
            free_pitch=True,
            joint_space=True,
        ),
    ]


def _mark_judge(sim: Simulation, run: RunStats) -> Outcome:
    bottom, _ = sim.grasped_frame()
    err = float(np.linalg.norm(bottom[:2] - sim.info.objects["mark"][:2]))
    tilt = math.degrees(sim.grasped_tilt())
    released = sim.grasped_released()
    ok = err <= MARK_MAX_ERROR and tilt < 10.0 and released and abs(bottom[2]) < 0.005
    metrics = {"placement_error_mm": 1e3 * err, "tilt_deg": tilt, "released": float(released)}
    return Outcome(bool(ok), metrics)


_MARK_FUNCTIONS = (_mark_add_objects, _mark_via_points, _mark_judge)
_ON_TABLE = G.GLASS_PATCH_CENTER
MARK = TaskSpec(
    name="mark",
    description="Put the glass from the table on the green mark.",
    ranges={
        "glass": PlacementRange.box((0.47, 0.08, _ON_TABLE), (0.54, 0.22, _ON_TABLE)),
        "mark": PlacementRange.box((0.47, -0.22, MARK_TOP), (0.52, -0.10, MARK_TOP)),
    },
    add_objects=_mark_add_objects,
    via_points=_mark_via_points,
    judge=_mark_judge,
    patches={"glass": G.GLASS_PATCH_PREFIX, "mark": "mark"},
)


@pytest.fixture
def mark_task() -> Iterator[TaskSpec]:
    register_task(MARK)
    try:
        yield MARK
    finally:
        unregister_task("mark")
    assert "mark" not in task_names()


@pytest.mark.slow
def test_a_registered_task_runs_from_teaching_to_evaluation(mark_task: TaskSpec) -> None:
    assert "mark" in task_names()
    assert get_task("mark") is mark_task
    demos = teach("mark", 3, seed=0, speed=2.0)
    assert all(set(d.objects) == {"glass", "mark"} for d in demos)
    # The teacher's via points do the task: its demonstration succeeds under physics.
    d = demos[0]
    with Simulation.from_task(get_task("mark"), d.objects) as sim:
        res = execute(sim, d.t, d.joints, d.gripper, settle=0.8, record_rate=20.0)
    assert res.outcome.success, res.outcome.metrics
    assert res.outcome.metrics["placement_error_mm"] < 2.0

    objects = constrained_objects(mark_task)
    assert objects == ["glass", "mark"]
    skill = Skill.learn(demos, katana(), n_steps=200, max_components=5, task_objects=objects)
    ts = TaskSkill(task=mark_task, demos=demos, skill=skill, learn_seconds=0.0, teach_seconds=0.0)
    with pytest.raises(ValueError, match=r"task must be a TaskSpec .*got 'mark'"):
        TaskSkill(
            task="mark",  # type: ignore[arg-type]
            demos=demos,
            skill=skill,
            learn_seconds=0.0,
            teach_seconds=0.0,
        )
    assert ts.task is mark_task and ts.constrain_fixed is False
    placement = sample_objects("mark", np.random.default_rng(24))
    run = run_controller(ts, placement, "fused")
    assert set(run.execution.objects) == {"glass", "mark"}
    assert set(run.as_dict()) == {
        "success",
        "placement_error_mm",
        "tilt_deg",
        "released",
        "peak_speed_ratio",
        "following_error_rad",
        *(f"peak_{k}{suffix}" for k in KINDS for suffix in ("_ratio", "")),
    }
    assert all(0.0 < run.as_dict()[f"peak_{k}_ratio"] <= 1.0 for k in KINDS)
    assert run.success == (run.execution.outcome.metrics["placement_error_mm"] <= 20.0)
    # Measured: 19-22 mm with 3 fast demonstrations on a 200-step grid (fused, 3 placements;
    # 7-28 mm without calibration, 11-20 mm before issue 34): the mark's 20 mm is at the edge
    # of what three fast demonstrations teach, so this placement may land on either side.
    assert run.execution.outcome.metrics["placement_error_mm"] < 25.0

    evaluation = evaluate("mark", trials=1, seed=0, task_skill=ts, ground_truth=True)
    assert isinstance(evaluation, Evaluation) and len(evaluation.trials) == 1
    assert set(evaluation.controllers) == {"fused", "joint", "task:glass", "task:mark"}
    result = evaluation.as_dict()
    assert result["task"] == "mark"
    assert set(result["controllers"]) == {"fused", "joint", "task:glass", "task:mark"}
    assert set(result["placements"][0]) == {"glass", "mark"}
    assert all(isinstance(r[0]["success"], bool) for r in result["runs"].values())
    # The servo stream's peaks over the limits, per trial and worst / median per controller.
    fused = result["controllers"]["fused"]["metrics"]
    for k in KINDS:
        assert 0.0 < result["runs"]["fused"][0][f"peak_{k}_ratio"] <= 1.0
        assert 0.0 < fused[f"peak_{k}_ratio"]["max"] <= 1.0
        assert fused[f"peak_{k}_ratio"]["median"] <= fused[f"peak_{k}_ratio"]["max"]
        assert fused[f"peak_{k}"]["max"] > 0.0
    json.dumps(result)  # JSON-ready
    # Vision in the loop: the cameras learn the mark's green from the task's patches.
    seen = evaluate("mark", trials=1, seed=0, task_skill=ts, controllers=["fused"]).as_dict()
    assert seen["tracking_failures"] == 0
    assert set(seen["tracking_error_mm"]["per_object"]) == {"glass", "mark"}
    assert seen["tracking_error_mm"]["max"] < 4.0


def test_a_registered_task_is_a_command_line_choice(mark_task: TaskSpec, tmp_path: Path) -> None:
    out = tmp_path / "mark.npz"
    r = CliRunner().invoke(app, ["teach", "--task", "mark", "--demos", "2", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert all(set(d.objects) == {"glass", "mark"} for d in load_demonstrations(out))
    r = CliRunner().invoke(app, ["teach", "--task", "juggling", "--out", str(out)])
    assert r.exit_code != 0
    assert "coaster, basin, slot, mark" in r.output


# The grasped object is the task's (TaskSpec.grasped), not a name the simulation assumes: the
# coaster task with its glass called "cup" runs from teaching to a trial, online, with the
# cameras and the push (which aims across the plane through the grasped object).
def _cup_add_objects(
    world: Any, objects: Mapping[str, np.ndarray], rng: np.random.Generator
) -> None:
    C._add_shelf(world)
    C._add_coaster(world, objects["coaster"])
    cup = objects["cup"]
    add_glass(world, np.array([cup[0], cup[1], C.SHELF_HEIGHT]), name="cup")


def _cup_via_points(
    objects: Mapping[str, np.ndarray], rng: np.random.Generator, speed: float
) -> list[ViaPoint]:
    return C.via_points({"glass": objects["cup"], "coaster": objects["coaster"]}, rng, speed)


CUP = TaskSpec(
    name="cup",
    description="The coaster task, its glass called cup.",
    ranges={"cup": C.RANGES["glass"], "coaster": C.RANGES["coaster"]},
    add_objects=_cup_add_objects,
    via_points=_cup_via_points,
    judge=C.judge,
    patches={"cup": G.patch_prefix("cup"), "coaster": "coaster"},
    move=C.SPEC.move,
    grasped="cup",
)


@pytest.mark.slow
def test_a_task_whose_grasped_object_is_not_called_glass_runs_a_trial() -> None:
    assert G.GLASS_PATCH_PREFIX == G.patch_prefix("glass") == "glass_patch"
    assert TaskSpec("plain", "", CUP.ranges, *_MARK_FUNCTIONS, grasped="cup").patches == {
        "cup": "cup_patch"
    }
    with pytest.raises(ValueError, match=r"must include 'mug' \(the object the gripper holds"):
        TaskSpec("plain", "", CUP.ranges, *_MARK_FUNCTIONS, grasped="mug")
    register_task(CUP)
    try:
        demos = teach("cup", 3, seed=0, speed=2.0)
        assert all(set(d.objects) == {"cup", "coaster"} for d in demos)
        objects = constrained_objects(CUP)
        assert objects == ["cup", "coaster"]
        # At most 10 components (5 before the hand's speed entered the alignment). Three fast
        # demonstrations on a 200-step grid make a skill sensitive to K: the cup stays in the
        # gripper at 5, is put down 32 mm off at 8, 4 mm at 10, tipped 13 degrees at 12.
        skill = Skill.learn(demos, katana(), n_steps=200, max_components=10, task_objects=objects)
        ts = TaskSkill(task=CUP, demos=demos, skill=skill, learn_seconds=0.0, teach_seconds=0.0)
        with Simulation.from_task(CUP) as sim:
            assert set(sim.object_positions()) == {"cup", "coaster"}
            sim.place_object("cup", sim.object_positions()["cup"] + [0.01, 0.0, 0.0])
        cup = evaluate(CUP, 1, 0, task_skill=ts, controllers=["fused"], ground_truth=True)
        # The same task with the name the simulation used to assume: the same run, to the bit
        # (a name changes no physics).
        glass = [d.__class__(d.t, d.joints, {"glass": d.objects["cup"],
                 "coaster": d.objects["coaster"]}, d.gripper) for d in demos]  # fmt: skip
        skill = Skill.learn(glass, katana(), n_steps=200, max_components=10,
                            task_objects=["glass", "coaster"])  # fmt: skip
        ts_glass = TaskSkill(
            task=C.SPEC, demos=glass, skill=skill, learn_seconds=0.0, teach_seconds=0.0
        )
        same = evaluate(C.SPEC, 1, 0, task_skill=ts_glass, controllers=["fused"],
                          ground_truth=True)  # fmt: skip
        # (the coaster task checks its runs against its scene; the cup task declares none)
        checked = {"collided", "min_clearance_m", "contacts"}
        assert checked <= set(same.trials[0].runs["fused"])
        assert cup.trials[0].runs["fused"] == {
            k: v for k, v in same.trials[0].runs["fused"].items() if k not in checked
        }
        run = cup.trials[0].runs["fused"]
        # Carried and set down upright on the coaster, released (placed 4.4 mm off centre).
        assert run["released"] == 1.0 and abs(run["height_error_mm"]) < 5.0
        assert run["tilt_deg"] < 10.0
        online = evaluate(CUP, 1, 0, task_skill=ts, controllers=["fused"], online=True,
                            perturb="push").as_dict()  # fmt: skip
        assert online["tracking_failures"] == 0
        assert set(online["tracking_error_mm"]["per_object"]) == {"cup", "coaster"}
        assert online["perturbations"][0]["name"] == "push"
        assert online["runs"]["fused"][0]["tracking"]["cup"]
    finally:
        unregister_task("cup")


def test_a_scene_without_the_tasks_glass_is_refused() -> None:
    spec = TaskSpec(
        "empty",
        "",
        {"glass": get_task("basin").ranges["glass"]},
        lambda w, o, r: None,
        _mark_via_points,
        _mark_judge,
    )
    with pytest.raises(ValueError, match="add_objects must add the glass"):
        build_scene(spec)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"online": 1}, r"online must be True or False, got 1"),
        ({"ground_truth": "yes"}, r"ground_truth must be True or False, got 'yes'"),
        ({"perturb": None}, r"perturb must be a perturbation's name, got None"),
        ({"seed": -1}, r"seed must be >= 0, got -1"),
        ({"seed": 1.5}, r"seed must be an integer, got 1.5"),
        ({"noise_mm": -2.0}, r"noise_mm must be finite and >= 0, got -2.0"),
        ({"noise_mm": math.nan}, r"noise_mm must be finite and >= 0, got nan"),
    ],
)
def test_trial_conditions_are_one_checked_frozen_value(
    options: dict[str, Any], message: str
) -> None:
    default = TrialConditions()
    assert (default.online, default.perturb, default.ground_truth, default.seed) == (
        False,
        "none",
        False,
        0,
    )
    assert default.vision and not TrialConditions(ground_truth=True).vision
    same = TrialConditions(seed=np.int64(3), noise_mm=2)
    assert same == TrialConditions(seed=3, noise_mm=2.0) and type(same.seed) is int
    with pytest.raises(AttributeError):
        default.seed = 1  # type: ignore[misc]
    with pytest.raises(TypeError):
        TrialConditions(False, "push")  # type: ignore[misc]  # keywords only
    with pytest.raises(ValueError, match=message):
        TrialConditions(**options)


def test_summarize_counts_successes_and_metric_statistics() -> None:
    # The summarising half of evaluate, on hand-made trials (no physics).
    from types import SimpleNamespace

    skill = SimpleNamespace(
        n_components_={"joint": 3, "glass": 4}, constraint_names=["joint", "glass"]
    )
    ts = SimpleNamespace(
        task=SimpleNamespace(name="basin"), skill=skill, constrain_fixed=False, learn_seconds=0.5
    )
    rows = [
        {
            "fused": {"success": True, "err": 1.0, "peak_jerk_ratio": 0.5},
            "joint": {"success": False, "err": 9.0},
        },
        {
            "fused": {"success": True, "err": 3.0, "peak_jerk_ratio": 0.9},
            "joint": {"success": True, "err": None},
        },
        {
            "fused": {"success": False, "tracking_status": {"glass": "lost"}},
            "joint": {"success": False, "tracking_status": {"glass": "lost"}},
        },
    ]
    trials = [
        Trial(
            truth={"glass": np.zeros(3)},
            observed=None if i == 2 else {"glass": np.zeros(3)},
            tracking_status={},
            tracking_error_mm=None,
            runs=r,
        )
        for i, r in enumerate(rows)
    ]
    conditions = TrialConditions(seed=4)
    ev = summarize(ts, trials, conditions, n_demos=5)  # type: ignore[arg-type]
    assert ev.conditions is conditions and ev.vision
    assert ev.controllers["fused"].successes == 2
    assert ev.controllers["fused"].success_rate == pytest.approx(2 / 3)
    assert ev.controllers["fused"].metrics["err"] == {"mean": 2.0, "median": 2.0, "max": 3.0}
    assert ev.controllers["joint"].metrics["err"] == {"mean": 9.0, "median": 9.0, "max": 9.0}
    # A peak ratio's worst trial and median (a trial without a run has none).
    jerk = ev.controllers["fused"].metrics["peak_jerk_ratio"]
    assert jerk == pytest.approx({"mean": 0.7, "median": 0.7, "max": 0.9})
    assert ev.tracking_failures == 1
    d = ev.as_dict()
    assert d["trials"] == 3 and d["observed"][2] is None and d["runs"]["joint"][1]["err"] is None
    assert (d["seed"], d["online"], d["perturb"], d["vision"]) == (4, False, "none", True)
    json.dumps(d)


def test_the_teachers_start_posture_is_within_the_limits() -> None:
    from pbdkit.sim._teacher import random_start_posture

    robot = katana()
    new = random_start_posture(robot, np.random.default_rng(3))
    np.testing.assert_array_equal(new, random_start_posture(robot, np.random.default_rng(3)))
    assert np.all(new >= robot.lower) and np.all(new <= robot.upper)
