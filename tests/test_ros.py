"""pbdkit on a live ROS 2 graph (issue 37): joint states matched by name (any order, extra
joints ignored, a missing joint named, names mapped with --joint-map), and the same over a
real graph of two processes in a private network namespace (``tests/rosgraph.py``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosgraph import needs_ros, run_on_private_graph

from pbdkit import Demonstration, Robot, Skill, load_demonstrations, save_demonstrations
from pbdkit.ros import JointOrder, parse_joint_map
from pbdkit.ros._graph import private_graph_env

KATANA = ["pan", "lift1", "lift2", "lift3", "wrist_roll"]


def test_joint_states_in_any_order_with_extra_joints() -> None:
    order = JointOrder(KATANA)
    names = ["finger", "lift3", "pan", "wrist_roll", "lift1", "lift2"]
    q = order.positions(names, [9.0, 4.0, 1.0, 5.0, 2.0, 3.0])
    np.testing.assert_array_equal(q, [1.0, 2.0, 3.0, 4.0, 5.0])
    assert order.indices(names) is order.indices(list(names))  # cached per names


def test_a_missing_or_repeated_joint_is_a_clear_error() -> None:
    order = JointOrder(KATANA)
    with pytest.raises(
        ValueError, match=r"joint\(s\) \['lift2'\] are not in the joint states.*--joint-map"
    ):
        order.positions(["pan", "lift1", "lift3", "wrist_roll"], [0.0] * 4)
    with pytest.raises(ValueError, match="names a joint twice"):
        order.positions([*KATANA, "pan"], [0.0] * 6)
    with pytest.raises(ValueError, match="6 names and 5 positions"):
        order.positions([*KATANA, "x"], [0.0] * 5)
    with pytest.raises(ValueError, match="not finite"):
        order.positions(KATANA, [0.0, np.nan, 0.0, 0.0, 0.0])


def test_joint_map_maps_fr3_names_to_the_panda_models() -> None:
    panda = [f"panda_joint{i}" for i in range(1, 8)]
    mapping = parse_joint_map([f"panda_joint{i}=fr3_joint{i}" for i in range(1, 8)])
    order = JointOrder(panda, mapping)
    names = [f"fr3_joint{i}" for i in (7, 6, 5, 4, 3, 2, 1)] + ["fr3_finger_joint1"]
    q = order.positions(names, [7, 6, 5, 4, 3, 2, 1, 0.04])
    np.testing.assert_array_equal(q, [1, 2, 3, 4, 5, 6, 7])
    with pytest.raises(ValueError, match="panda_joint3"):  # the model's name is not on the graph
        order.positions(panda, np.zeros(7))


@pytest.mark.parametrize(
    ("items", "match"),
    [
        (["panda_joint1"], "is not FROM=TO"),
        (["=fr3_joint1"], "is not FROM=TO"),
        (["a=b=c"], "is not FROM=TO"),
        (["a=x", "a=y"], "'a' is mapped twice"),
        (["a=x", "b=x"], "'x' is the graph's name of two joints"),
    ],
)
def test_a_malformed_joint_map_is_refused(items: list[str], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        parse_joint_map(items)


def test_a_joint_map_of_joints_the_arm_does_not_have_is_refused() -> None:
    with pytest.raises(ValueError, match=r"\['elbow'\] are not joints of the skill's arm"):
        JointOrder(KATANA, {"elbow": "x"})
    with pytest.raises(ValueError, match="two joints share a name on the graph"):
        JointOrder(KATANA, {"pan": "lift1"})


def test_a_private_graph_has_localhost_discovery_and_a_domain_from_the_name() -> None:
    a, b = private_graph_env("test_a", {}), private_graph_env("test_b", {})
    assert a["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert 1 <= int(a["ROS_DOMAIN_ID"]) <= 101
    assert a == private_graph_env("test_a", {}) and a["ROS_DOMAIN_ID"] != b["ROS_DOMAIN_ID"]


def test_joint_states_over_a_real_graph_fr3_names_mapped() -> None:
    # Two processes on a private graph: a driver publishing franka_ros2's FR3 names (shuffled,
    # a finger among them), and the listener matching them to the Panda model's joints.
    done = run_on_private_graph("test_joint_states_over_a_real_graph", "joint_states")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK"), done.stdout


def test_a_trajectory_over_a_real_graph_is_followed_by_the_sim_arm() -> None:
    # The robot side of `pbdkit ros run`'s tests: a JTC on /arm_controller/joint_trajectory in
    # another process; joints named in another order; an empty trajectory rejected.
    done = run_on_private_graph("test_a_trajectory_over_a_real_graph", "trajectory_to_sim_arm")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK"), done.stdout


def test_a_skill_runs_to_its_end_on_the_sim_arm_within_the_limits() -> None:
    # `pbdkit ros run`'s core (pbdkit.ros._run.run_skill) and the sim arm in two processes:
    # the synthetic glass skill runs to its end (exit code 0, the arm at rest where the
    # reproduction ends), every command the arm's controller executed within v/a/j.
    done = run_on_private_graph("test_a_skill_runs_to_its_end", "run_on_katana_arm", timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK"), done.stdout


@pytest.mark.parametrize(("case", "code"), [("cli_no_arm", 3), ("cli_no_controller", 4)])
def test_pbdkit_ros_run_exits_with_its_code_when_the_graph_lacks_a_side(
    skill: Skill, tmp_path: Path, case: str, code: int
) -> None:
    path = tmp_path / "skill.npz"
    skill.save(path)
    done = run_on_private_graph(f"test_pbdkit_ros_run_{case}", case, str(path))
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith(f"OK: exit {code}"), done.stdout


@pytest.mark.parametrize(
    "case", ["cli_topics_renamed_gripper", "cli_sigint", "cli_arm_dies", "cli_following_error"]
)
def test_pbdkit_ros_run_on_the_sim_arm(skill: Skill, tmp_path: Path, case: str) -> None:
    # `pbdkit ros run` (the CLI) and the sim arm in two processes on a private graph
    # (tests/ros_cases.py says what each case checks): the glass from a topic that moves, the
    # joints renamed and shuffled, the gripper; SIGINT (rest, then 130); the arm dies (3 within
    # 1 s after the staleness bound); an arm that lags (5).
    path = tmp_path / "skill.npz"
    skill.save(path)
    done = run_on_private_graph(f"test_ros_run_{case}", case, str(path), timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK"), done.stdout


def test_pbdkit_ros_run_checks_the_scene_before_it_sends_anything(
    skill: Skill, tmp_path: Path
) -> None:
    # Issue 38: `pbdkit ros run --scene` (tests/ros_cases.py, cli_scene).
    path = tmp_path / "skill.npz"
    skill.save(path)
    done = run_on_private_graph(
        "test_ros_run_scene", "cli_scene", str(path), str(tmp_path), timeout=150
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK"), done.stdout


def test_record_learn_and_run_the_coaster_over_a_real_graph(tmp_path: Path) -> None:
    # The whole chain on a private graph (tests/ros_cases.py, coaster_round_trip): `pbdkit ros
    # sim --teach` replays three takes (10x real time), `pbdkit ros record --auto` records
    # them, `pbdkit learn` learns the skill; `pbdkit ros record --suggest` records two more
    # (another teacher's), saying before each where to put the objects and updating the skill
    # after each; `pbdkit ros run` runs the updated skill against `pbdkit ros sim --perturb
    # move` on another placement: the coaster slides 5 cm while the glass is carried, the
    # run re-plans, and the sim judges the glass placed.
    done = run_on_private_graph("test_record_learn_and_run", "coaster_round_trip",
                                str(tmp_path), timeout=240)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK: success"), done.stdout


def test_record_starts_and_stops_takes_on_enter(tmp_path: Path) -> None:
    # `pbdkit ros record` without --auto, Enter pressed on its stdin (tests/ros_cases.py,
    # record_on_enter): two takes, timed by the driver's stamps, with the driver's samples.
    done = run_on_private_graph("test_record_on_enter", "record_on_enter", str(tmp_path),
                                timeout=90)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK: 2 takes"), done.stdout


def test_record_suggest_keeps_the_poses_the_skill_learned(
    demos: list[Demonstration], robot: Robot, tmp_path: Path
) -> None:
    # `pbdkit ros record --suggest` with the glass skill learned with the glass as a pose, the
    # glass on a PoseStamped topic (tests/ros_cases.py, record_suggest_poses): the take keeps
    # the pose, as the skill's demonstrations do, and the skill learns it. (It kept the
    # topic's position, as without --suggest, and the update refused the take once recorded.)
    from synthetic_teacher import N_STEPS

    posed = []
    for d in demos:
        pose = np.eye(4)
        pose[:3, 3] = d.objects["glass"]
        posed.append(Demonstration(d.t, d.joints, {"glass": pose}))  # no gripper: no joint
    path = tmp_path / "skill.npz"
    Skill.learn(posed, robot, n_steps=N_STEPS, random_state=0).save(path)
    done = run_on_private_graph("test_record_suggest_poses", "record_suggest_poses", str(path),
                                str(tmp_path), timeout=90)  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK: 1 take, learned"), done.stdout
    (take,), learned = load_demonstrations(tmp_path / "demos.npz"), Skill.load(path)
    glass = np.eye(4)
    glass[:3, 3] = [0.4, 0.1, 0.1]  # where the topic has it, not turned
    np.testing.assert_allclose(take.objects["glass"], glass, atol=1e-12)
    assert learned.demonstrations_ is not None and len(learned.demonstrations_) == 6
    np.testing.assert_array_equal(learned.demonstrations_[-1].joints, take.joints)
    np.testing.assert_array_equal(
        learned.demonstrations_[-1].objects["glass"], take.objects["glass"]
    )


def test_ros_sim_publishes_what_the_cameras_see() -> None:
    # `pbdkit ros sim --cameras` over a private graph (tests/ros_cases.py, sim_cameras): the
    # objects' topics carry the stereo tracker's estimates.
    done = run_on_private_graph("test_sim_cameras", "sim_cameras", timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("OK: tracked within"), done.stdout


def test_object_sources_a_live_node_cannot_read_are_refused() -> None:
    from pbdkit.ros._objects import check_sources

    with pytest.raises(ValueError, match=r"tf is not read on a live graph.*PoseStamped"):
        check_sources({"glass": "tf:glass_link"})
    with pytest.raises(ValueError, match=r"give a topic \(/NAME\)"):
        check_sources({"glass": "glass_topic"})
    check_sources({"glass": "/objects/glass", "coaster": np.zeros(3)})  # both readable


@pytest.mark.parametrize(
    ("text", "match"),
    [("gripper", "NAME:OPEN:CLOSED"), ("gripper:0:x", "NAME:OPEN:CLOSED"),
     (":0:1", "two different finite"), ("gripper:1:1", "two different finite"),
     ("gripper:0:inf", "two different finite")],
)  # fmt: skip
def test_a_malformed_gripper_joint_is_refused(text: str, match: str) -> None:
    import typer

    from pbdkit.apps._cli_ros import parse_gripper_joint

    with pytest.raises(typer.BadParameter, match=match):
        parse_gripper_joint(text)
    assert parse_gripper_joint("finger:0.04:0.0") == ("finger", 0.04, 0.0)


def test_run_and_record_settings_refuse_what_cannot_work() -> None:
    from pbdkit.ros._record import RecordSettings
    from pbdkit.ros._run import RunSettings

    with pytest.raises(ValueError, match="--gripper-controller and --gripper-joint go together"):
        RunSettings(gripper_controller="gripper_controller")
    with pytest.raises(ValueError, match="--gripper-seconds must be > 0"):
        RunSettings(gripper_seconds=0.0)
    for latency in (0.0, -0.1, 0.6, float("nan")):
        with pytest.raises(ValueError, match=r"--latency must be in \(0, 0.5\] s"):
            RunSettings(latency=latency)
    assert RunSettings(latency=0.5).latency == 0.5
    with pytest.raises(ValueError, match="--auto needs --takes N"):
        RecordSettings(auto=True)
    with pytest.raises(ValueError, match="--takes must be >= 1"):
        RecordSettings(takes=0)
    with pytest.raises(ValueError, match="--rest must be > 0"):
        RecordSettings(rest=0.0)


def test_record_refuses_an_out_file_its_takes_could_not_join(
    demos: list[Demonstration], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Demonstrations with a gripper in --out, no --gripper-joint: refused in one line before
    # the graph, not after the first take (which save_demonstrations refused, the take lost).
    from typer.testing import CliRunner

    from pbdkit.apps import _cli_ros
    from pbdkit.apps._cli import app

    needs_ros()
    monkeypatch.setattr(_cli_ros, "run_node", _no_graph)
    out = tmp_path / "demos.npz"
    save_demonstrations(demos, out)
    before = out.read_bytes()
    result = CliRunner().invoke(
        app, ["ros", "record", "--out", str(out), "--object", "glass=0.4,0.1,0.1"]
    )
    said = result.output.strip()
    assert result.exit_code == 2 and len(said.splitlines()) == 1, said
    assert said.endswith("objects ['glass'], with a gripper; record into another file"), said
    assert out.read_bytes() == before


def _no_graph(*args: object, **kwargs: object) -> None:
    raise AssertionError("joined the ROS graph: the options should have been refused")
