"""``pbdkit ros sim`` (issue 37): the MuJoCo world of a task as a ROS 2 robot. Its core
(:class:`pbdkit.ros._task_world.TaskWorld`, the teacher's replay) in this process on a clock the
tests advance, then the command over a private graph (``tests/ros_sim_cases.py``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest
import typer
from rosgraph import needs_ros, run_on_private_graph
from typer.testing import CliRunner

pytest.importorskip("mujoco")

from pbdkit.robots import katana
from pbdkit.ros._jtc import RejectedTrajectory
from pbdkit.ros._task_world import TaskWorld, WorldSettings, start_posture
from pbdkit.ros._teach_replay import (
    REST_AFTER,
    REST_BEFORE,
    TeacherReplay,
    placement_objects,
)
from pbdkit.sim import get_task
from pbdkit.sim._perturb import DisturbanceSetup, make_disturbance
from pbdkit.sim._world import TIMESTEP

if TYPE_CHECKING:
    from pbdkit.sim._task_skill import TaskSkill

CASES = Path(__file__).parent / "ros_sim_cases.py"
EVERYTHING = 10**6  # TaskWorld.advance's max_steps: all the way to the time asked for


def _world(**settings: object) -> TaskWorld:
    return TaskWorld(WorldSettings(**settings))  # type: ignore[arg-type]


def _offset(world: TaskWorld) -> np.ndarray:
    return world.q0 + np.array([0.2, -0.1, 0.1, 0.1, 0.2])


def test_placement_k_is_evaluates_trial_k() -> None:
    spec = get_task("coaster")
    rng = np.random.default_rng([3, 1])  # as pbdkit.sim.evaluate draws them
    expected = [spec.sample_objects(rng) for _ in range(20)]
    for k in (0, 7, 19):
        got = placement_objects(spec, 3, k)
        assert list(got) == list(expected[k])
        for name, p in got.items():
            np.testing.assert_array_equal(p, expected[k][name])
    world = _world(seed=3, placement=7)
    for name, p in world.objects.items():
        np.testing.assert_array_equal(p, expected[7][name])
    with pytest.raises(ValueError, match="placement must be >= 0"):
        placement_objects(spec, 3, -1)


def test_the_arm_starts_at_rest_at_the_start_posture_with_the_objects_true() -> None:
    world = _world()
    np.testing.assert_array_equal(world.q0, start_posture())
    world.advance(0.5, EVERYTHING)
    names, q, v = world.joint_state()
    assert names == [*katana().joint_names, "gripper"]
    np.testing.assert_allclose(q[:5], world.q0, atol=1e-4)
    assert q[5] == 0.0 and np.abs(v).max() < 1e-2
    assert world.observations == 8  # 15 Hz from t = 0
    for name, pose in world.seen.items():
        np.testing.assert_allclose(pose[:3, 3], world.objects[name], atol=1e-4)


def test_a_trajectory_in_another_order_is_followed_an_empty_one_rejected() -> None:
    world = _world()
    world.advance(0.2, EVERYTHING)
    q1 = _offset(world)
    back = world.joint_names[::-1]
    world.receive_arm(back, [0.5, 1.0], [(0.5 * (world.q0 + q1))[::-1], q1[::-1]])
    with pytest.raises(RejectedTrajectory, match="empty trajectory"):
        world.receive_arm(world.joint_names, [], [])
    with pytest.raises(RejectedTrajectory, match="not the controller's"):
        world.receive_arm(["pan"], [1.0], [[0.0]])
    world.advance(3.0, EVERYTHING)
    np.testing.assert_allclose(world.joint_state()[1][:5], q1, atol=1e-3)
    assert world.messages["arm"] == {"accepted": 1, "rejected": 2}


@pytest.mark.parametrize("from_desired", [False, True])
def test_a_messages_first_segment_starts_from_the_measured_or_the_desired_state(
    from_desired: bool,
) -> None:
    # The JTC's rule: from the measured state by default, from the last command with
    # interpolate_from_desired_state. Mid-motion the servos lag the command by ~1e-4 rad.
    world = _world(interpolate_from_desired_state=from_desired)
    world.receive_arm(world.joint_names, [1.0], [_offset(world)])
    world.advance(0.5, EVERYTHING)
    desired, _, _ = world.arm.desired(world.t)
    measured = world.joint_state()[1][:5]
    assert np.abs(desired - measured).max() > 5e-5
    world.receive_arm(world.joint_names, [1.0], [world.q0])
    start, _, _ = world.arm.desired(world.t)
    np.testing.assert_allclose(start, desired if from_desired else measured, rtol=0, atol=1e-12)


def test_the_gripper_closes_while_its_trajectory_is_above_one_half() -> None:
    world = _world()
    world.advance(0.1, EVERYTHING)
    opening = world.sim.finger_opening().copy()  # type: ignore[union-attr]
    world.receive_gripper(["gripper"], [0.2, 1.0], [[1.0], [0.0]])
    world.advance(0.1 + 0.1 - TIMESTEP, EVERYTHING)  # 0.5 at 0.1 s: still open
    assert world.joint_state()[1][5] == 0.0
    world.advance(0.5, EVERYTHING)
    assert world.joint_state()[1][5] == 1.0
    assert np.all(world.sim.finger_opening() < opening - 1e-3)  # type: ignore[union-attr]
    world.advance(1.2, EVERYTHING)  # below 0.5 from 0.6 s after it came
    assert world.joint_state()[1][5] == 0.0
    with pytest.raises(RejectedTrajectory, match="not the controller's"):
        world.receive_gripper(["finger"], [0.3], [[1.0]])
    assert world.messages["gripper"] == {"accepted": 1, "rejected": 1}


def test_move_is_built_when_the_gripper_closes_as_evaluates_trial() -> None:
    world = _world(perturb="move", seed=2, placement=4)
    world.advance(0.3, EVERYTHING)
    world.receive_arm(world.joint_names, [2.5], [world.q0])  # the run starts, the arm holds
    world.advance(0.5, EVERYTHING)
    assert world.run is not None and world.run.act is None  # no grasp yet
    world.receive_gripper(["gripper"], [0.2], [[1.0]])
    world.advance(0.8, EVERYTHING)
    act = world.run.act
    assert act is not None
    grasp = act.as_dict()["grasp_s"]
    assert 0.3 - TIMESTEP < grasp < 0.3 + 2 * TIMESTEP, grasp  # 0.2 + 0.1 s into the run
    # The disturbance evaluate's trial 4 of seed 2 draws, the grasp at that run time.
    setup = DisturbanceSetup(
        task=world.spec,
        objects=placement_objects(world.spec, 2, 4),
        times=np.array([grasp]),
        gripper=np.array([1.0]),
        rng=np.random.default_rng([2, 2, 4]),
    )
    expected = make_disturbance("move", setup).as_dict()
    world.advance(3.5, EVERYTHING)  # the slide over (0.8 s after the grasp + 0.5 s + 1 s)
    got = act.as_dict()
    assert got["start_s"] == pytest.approx(grasp + 0.5)
    np.testing.assert_allclose(got["displacement_m"], expected["displacement_m"], rtol=0, atol=0)
    coaster = world.sim.object_positions()["coaster"]  # type: ignore[union-attr]
    np.testing.assert_allclose(coaster, world.objects["coaster"] + got["displacement_m"], atol=1e-9)


def test_push_is_timed_on_the_skills_grasp_as_evaluates_trial(
    small_task_skill: Callable[..., TaskSkill],
) -> None:
    from pbdkit.sim._trials import TrialConditions, trial_disturbance

    ts = small_task_skill("coaster")
    world = TaskWorld(WorldSettings(perturb="push", seed=4, placement=2), skill=ts.skill)
    np.testing.assert_array_equal(world.q0, ts.start_posture)  # where the skill starts
    world.receive_arm(world.joint_names, [1.0], [world.q0])
    assert world.run is not None and world.run.act is not None  # built at the start
    truth = placement_objects(ts.task, 4, 2)
    expected = trial_disturbance(ts, TrialConditions(perturb="push", seed=4), truth, index=2)
    assert world.run.act.as_dict() == expected.as_dict()
    assert world.run.recorder.force_window == expected.force_window()  # not in the peaks


def test_push_before_the_grasp_needs_a_skill() -> None:
    with pytest.raises(ValueError, match=r"acts before the grasp.*--skill"):
        _world(perturb="push")
    with pytest.raises(ValueError, match="rotate"):
        _world(perturb="rotate")  # the coaster task has no turning object


def test_the_run_is_judged_settle_seconds_after_its_trajectorys_end() -> None:
    world = _world(placement=1)
    world.advance(0.25, EVERYTHING)
    q1 = _offset(world)
    world.receive_arm(world.joint_names, [0.6], [q1], [[0.0] * 5])
    world.advance(0.25 + 0.6 + 1.0 - 2 * TIMESTEP, EVERYTHING)
    assert world.report is None
    world.advance(2.0, EVERYTHING)
    report = world.report
    assert report is not None and world.finished
    assert report["judged_s"] == pytest.approx(1.6, abs=1e-9)
    assert report["trajectory_end_s"] == pytest.approx(0.6)
    assert report["success"] is False  # nothing was carried to the coaster
    assert set(report["metrics"]) == {
        "placement_error_mm",
        "height_error_mm",
        "tilt_deg",
        "released",
    }
    assert report["placement_index"] == 1
    assert report["placement"] == {k: v.tolist() for k, v in world.objects.items()}
    assert report["perturb"] == {"name": "none"}
    assert report["messages"]["arm"] == {"accepted": 1, "rejected": 0}
    # A cubic from rest to rest over 0.6 s: peak speed 1.5 * 0.2 / 0.6 rad/s (Katana: 1.19).
    assert report["peak_velocity"] == pytest.approx(0.5, rel=1e-3)
    assert report["servo_worst_ratio"] == max(
        report[f"peak_{k}_ratio"] for k in ("velocity", "acceleration", "jerk")
    )
    json.dumps(report, allow_nan=False)
    world.receive_arm(world.joint_names, [0.5], [world.q0])  # followed, not judged
    world.advance(4.0, EVERYTHING)
    assert world.report is report
    np.testing.assert_allclose(world.joint_state()[1][:5], world.q0, atol=1e-3)


def test_the_teachers_replay_schedule() -> None:
    from pbdkit.sim._teacher import teach_one

    spec = get_task("coaster")
    replay = TeacherReplay(spec, 5, 2, speed=3.0)
    first, second = replay.takes
    assert first.start == 0.0 and second.start == first.end and replay.end == second.end
    for i, take in enumerate(replay.takes):
        demo = teach_one(spec, take.objects, np.random.default_rng([5, 3, i]), katana(), 3.0)
        np.testing.assert_array_equal(take.demo.joints, demo.joints)
        for name, p in placement_objects(spec, 5, i).items():
            np.testing.assert_array_equal(take.objects[name], p)
        assert take.motion_start == take.start + REST_BEFORE
        assert take.end == pytest.approx(take.motion_end + REST_AFTER)
        q, dq, closed = take.command(take.motion_start - 0.1)
        np.testing.assert_array_equal(q, demo.joints[0])
        assert not dq.any() and not closed
        q, dq, closed = take.command(take.motion_start + demo.t[100] + 0.005)  # mid-sample
        np.testing.assert_allclose(q, 0.5 * (demo.joints[100] + demo.joints[101]), atol=1e-12)
        np.testing.assert_allclose(dq, (demo.joints[101] - demo.joints[100]) / 0.01, rtol=1e-9)
        grasp = take.as_dict()["grasp_s"]
        assert take.command(grasp + 1e-9)[2] and not take.command(grasp - 0.011)[2]
        q, dq, _ = take.command(take.end - 0.1)
        np.testing.assert_array_equal(q, demo.joints[-1])
    assert replay.take_at(first.end - 1e-9) == 0 and replay.take_at(first.end) == 1
    assert replay.take_at(replay.end + 100.0) == 1


def test_the_world_replays_the_takes_with_their_objects() -> None:
    lines: list[str] = []
    world = TaskWorld(WorldSettings(teach=True, takes=2, teach_speed=3.0), log=lines.append)
    first, second = world.replay.takes  # type: ignore[union-attr]
    with pytest.raises(RejectedTrajectory, match="replays the teacher"):
        world.receive_arm(world.joint_names, [1.0], [world.q0])
    world.advance(first.motion_start - 0.1, EVERYTHING)
    np.testing.assert_allclose(world.joint_state()[1][:5], first.demo.joints[0], atol=1e-4)
    np.testing.assert_allclose(world.seen["glass"][:3, 3], first.objects["glass"], atol=1e-4)
    world.advance(first.end - 0.1, EVERYTHING)
    np.testing.assert_allclose(world.joint_state()[1][:5], first.demo.joints[-1], atol=1e-2)
    assert world.report is None
    world.advance(second.start + 0.2, EVERYTHING)
    np.testing.assert_allclose(world.joint_state()[1][:5], second.demo.joints[0], atol=1e-4)
    np.testing.assert_allclose(world.seen["glass"][:3, 3], second.objects["glass"], atol=1e-4)
    world.advance(second.end + 0.1, EVERYTHING)
    assert world.report is not None and world.report["teach_done"] is True
    assert [t["take"] for t in world.report["takes"]] == [0, 1]
    assert [x.split(":")[0] for x in lines] == ["take 1/2", "take 2/2", "teach"]


def test_the_cameras_give_the_trackers_estimates_once_located() -> None:
    world = _world(cameras=True)
    assert world.seen == {} and world.observer is not None
    world.advance(0.5, EVERYTHING)
    assert world.observer.filter.status == {"glass": "ok", "coaster": "ok"}
    for name, pose in world.seen.items():
        np.testing.assert_array_equal(pose[:3, 3], world.observer.filter.estimates[name])
        error = np.linalg.norm(pose[:3, 3] - world.objects[name])
        assert 0.0 < error < 3e-3, (name, error)  # the tracker's, not the truth


def test_a_trajectory_message_to_arrays() -> None:
    needs_ros()
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from pbdkit.ros._sim_world import trajectory_arrays

    msg = JointTrajectory(joint_names=["a", "b"])
    for t in (0.25, 1.5):
        duration = Duration(sec=int(t), nanosec=round((t % 1) * 1e9))
        msg.points.append(JointTrajectoryPoint(positions=[t, -t], time_from_start=duration))
    names, times, p, v, a = trajectory_arrays(msg)
    assert names == ["a", "b"] and times == [0.25, 1.5] and v is None and a is None
    assert p == [[0.25, -0.25], [1.5, -1.5]]
    msg.points[1].velocities = [0.0, 0.0]
    with pytest.raises(RejectedTrajectory, match="every point needs 2 velocities"):
        trajectory_arrays(msg)
    msg.points[0].positions = [1.0]
    with pytest.raises(RejectedTrajectory, match="every point needs 2 positions"):
        trajectory_arrays(msg)


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="time_scale must be in"):
        WorldSettings(time_scale=50.0)
    with pytest.raises(ValueError, match="takes must be >= 1"):
        WorldSettings(takes=0)
    with pytest.raises(ValueError, match="cameras must be True or False"):
        WorldSettings(cameras=1)  # type: ignore[arg-type]


def _sim_app() -> typer.Typer:
    """``pbdkit ros sim`` as the ros group registers it."""
    from pbdkit.apps._cli_output import reports_errors
    from pbdkit.apps._cli_ros_sim import sim_command

    app = typer.Typer()
    app.command()(reports_errors(sim_command))
    return app


def test_pbdkit_ros_sim_without_the_ros_extra_is_a_one_line_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import pbdkit.ros._graph

    monkeypatch.setattr(pbdkit.ros._graph, "ros_available", lambda: False)
    done = CliRunner().invoke(_sim_app(), [])
    assert done.exit_code == 2
    # The hint names the checkout: pbdkit is not on a package index.
    assert (
        "error: pbdkit ros needs the ros extra: pip install -e '.[ros]' in the pbdkit"
        in done.output
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--perturb", "push"], "acts before the grasp"),
        (["--perturb", "rotate"], "has no 'rotate' disturbance"),
        (["--perturb", "wind"], "must be one of none, move, push, rotate"),
        (["--task", "nope"], "task must be one of"),
        (["--time-scale", "30"], "time_scale must be in"),
        (["--skill", "/no/such/skill.npz"], "No such file: /no/such/skill.npz"),
    ],
)
def test_pbdkit_ros_sim_refuses_before_it_starts_a_node(args: list[str], message: str) -> None:
    needs_ros()
    done = CliRunner().invoke(_sim_app(), args)
    assert done.exit_code == 2, done.output
    assert message in " ".join(done.output.split()), done.output


# ----------------------------------------------------------------------------- on a graph
def test_pbdkit_ros_sim_follows_trajectories_and_judges_the_run(tmp_path: Path) -> None:
    # `pbdkit ros sim --exit-after-run` in another process: a trajectory with its joints in
    # another order followed to its last point, an empty one rejected, the gripper closed by
    # its own; 1 s after the end the run judged (a failure), the report written, exit 1.
    report = tmp_path / "report.json"
    done = run_on_private_graph("test_pbdkit_ros_sim_follows", "follow", str(report), script=CASES)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK"), done.stdout


def test_pbdkit_ros_sim_teach_publishes_the_takes(tmp_path: Path) -> None:
    # `pbdkit ros sim --teach --takes 2 --time-scale 12`: two takes, at rest, moving, at rest;
    # the objects change between them; exit 0 after the last.
    report = tmp_path / "report.json"
    done = run_on_private_graph("test_pbdkit_ros_sim_teach", "teach", str(report), script=CASES)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK"), done.stdout
