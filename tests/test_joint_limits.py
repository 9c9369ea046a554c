"""Joint limits as data: the joint_limits.yaml of MoveIt / ros2_control read by Robot.from_urdf
(pbdkit.robots._joint_limits), limits kept by pickling, by skill files and by `pbdkit learn`."""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from arms import KinematicOnly, no_limits
from numpy.typing import NDArray
from typer.testing import CliRunner

from pbdkit import robots
from pbdkit.apps._cli import app
from pbdkit.data._demonstration import Demonstration, save_demonstrations
from pbdkit.robots._robot import Robot
from pbdkit.robots._urdf import urdf_from_dh
from pbdkit.skill._skill import Skill

INF = np.inf
LIMITS = ("velocity_limit", "acceleration_limit", "jerk_limit")

# Three revolute joints j1..j3 with URDF velocities 1, 2, 3 rad/s, tip frame "tip", and a
# finger_joint off the chain (a joint_limits file may name it: it is a joint of the URDF).
URDF = urdf_from_dh(
    [[0.0, 0.0, 0.1, 0.0], [0.2, 0.0, 0.0, 0.0], [0.2, 0.0, 0.0, 0.0]],
    joint_names=["j1", "j2", "j3"],
    velocity=[1.0, 2.0, 3.0],
    effort=1.0,
).replace(
    "</robot>",
    '  <link name="finger"/>\n  <joint name="finger_joint" type="prismatic">\n'
    '    <parent link="link3"/>\n    <child link="finger"/>\n    <axis xyz="1 0 0"/>\n'
    '    <limit lower="0" upper="0.04" effort="1.0" velocity="0.1"/>\n  </joint>\n</robot>',
)

# As MoveIt writes them: scaling factors, effort, a finger off the chain; j3 is not named.
YAML = """\
default_velocity_scaling_factor: 0.1
default_acceleration_scaling_factor: 0.1
joint_limits:
  j1:
    has_velocity_limits: true
    max_velocity: 0.5
    has_acceleration_limits: true
    max_acceleration: 4
    has_jerk_limits: true
    max_jerk: 40.0
    has_effort_limits: true
    max_effort: 87.0
  j2:
    has_velocity_limits: false
    max_velocity: 0
    has_acceleration_limits: false
    max_acceleration: 0
    has_jerk_limits: true
    max_jerk: .inf
  finger_joint:
    has_velocity_limits: true
    max_velocity: 0.1
    has_acceleration_limits: true
    max_acceleration: 1.0
"""


def limits_of(robot: Robot) -> dict[str, NDArray[np.float64]]:
    return {name: getattr(robot, name) for name in ("lower", "upper", *LIMITS)}


def with_entry(**entry: Any) -> dict[str, Any]:
    """A joint_limits mapping declaring ``entry`` for joint j1."""
    return {"joint_limits": {"j1": entry}}


# ----------------------------------------------------------------------------- reading the YAML
@pytest.mark.parametrize("form", ["Path", "str path", "text", "mapping"])
def test_limits_from_a_path_from_text_and_from_a_mapping(tmp_path: Path, form: str) -> None:
    file = tmp_path / "joint_limits.yaml"
    file.write_text(YAML, encoding="utf-8")
    source: Any = {
        "Path": file,
        "str path": str(file),
        "text": YAML,
        "mapping": yaml.safe_load(YAML),
    }[form]
    robot = Robot.from_urdf(URDF, tip="tip", joint_limits=source)
    np.testing.assert_array_equal(robot.velocity_limit, [0.5, INF, 3.0])
    np.testing.assert_array_equal(robot.acceleration_limit, [4.0, INF, INF])
    np.testing.assert_array_equal(robot.jerk_limit, [40.0, INF, INF])
    for name in LIMITS:
        assert getattr(robot, name).dtype == np.float64


def test_the_yaml_velocity_wins_over_the_urdf() -> None:
    plain = Robot.from_urdf(URDF, tip="tip")
    np.testing.assert_array_equal(plain.velocity_limit, [1.0, 2.0, 3.0])
    faster = with_entry(has_velocity_limits=True, max_velocity=5.0)
    robot = Robot.from_urdf(URDF, tip="tip", joint_limits=faster)
    np.testing.assert_array_equal(robot.velocity_limit, [5.0, 2.0, 3.0])  # higher, too: it wins


def test_unnamed_joints_keep_the_urdf_velocity_and_get_no_other_limit() -> None:
    only_j2 = {"joint_limits": {"j2": {"has_acceleration_limits": True, "max_acceleration": 2.0}}}
    robot = Robot.from_urdf(URDF, tip="tip", joint_limits=only_j2)
    np.testing.assert_array_equal(robot.velocity_limit, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(robot.acceleration_limit, [INF, 2.0, INF])
    np.testing.assert_array_equal(robot.jerk_limit, [INF, INF, INF])


def test_has_limits_false_means_no_limit_even_with_a_value() -> None:
    entry = {
        "has_velocity_limits": False,
        "max_velocity": 0.3,
        "has_acceleration_limits": False,
        "max_acceleration": 7.0,
        "has_jerk_limits": False,
        "max_jerk": 70.0,
    }
    robot = Robot.from_urdf(URDF, tip="tip", joint_limits=with_entry(**entry))
    for name in LIMITS:
        assert getattr(robot, name)[0] == INF, name
    assert robot.velocity_limit[1] == 2.0  # the other joints keep the URDF's


def test_joints_off_the_chain_are_ignored() -> None:
    finger = {"joint_limits": {"finger_joint": {"has_velocity_limits": True, "max_velocity": 0.1}}}
    robot = Robot.from_urdf(URDF, tip="tip", joint_limits=finger)
    plain = Robot.from_urdf(URDF, tip="tip")
    for name, arr in limits_of(robot).items():
        np.testing.assert_array_equal(arr, getattr(plain, name))
    assert robot.urdf == plain.urdf


def test_position_limits_override_the_urdf_and_are_written_into_it() -> None:
    text = (
        "joint_limits:\n"
        "  j2: {has_position_limits: true, min_position: -1.0, max_position: 0.5}\n"
        "  j3: {has_position_limits: false, min_position: -9, max_position: 9}\n"
    )
    robot = Robot.from_urdf(URDF, tip="tip", joint_limits=text)
    pi = np.pi
    np.testing.assert_array_equal(robot.lower, [-pi, -1.0, -pi])
    np.testing.assert_array_equal(robot.upper, [pi, 0.5, pi])
    with pytest.raises(ValueError, match=r"joint 'j2'\) must be within \[-1, 0\.5\], got 0\.6"):
        robot.check_joints([0.0, 0.6, 0.0], enforce_limits=True)
    # robot.urdf holds them, so a simulator (and a saved skill) sees the same limits
    again = Robot.from_urdf(robot.urdf, tip="tip")
    np.testing.assert_array_equal(again.lower, robot.lower)
    np.testing.assert_array_equal(again.upper, robot.upper)
    # and the kinematics are untouched
    q = np.random.default_rng(0).uniform(-0.5, 0.5, (4, 3))
    np.testing.assert_array_equal(robot.fk(q), Robot.from_urdf(URDF, tip="tip").fk(q))


def test_a_pickled_robot_keeps_the_yaml_limits() -> None:
    text = YAML + "  j3:\n    has_position_limits: true\n    min_position: -0.25\n"
    text += "    max_position: 0.75\n"
    robot = Robot.from_urdf(URDF, tip="tip", joint_limits=text)
    assert robot.upper[2] == 0.75 and robot.velocity_limit[0] == 0.5  # the YAML's
    copy = pickle.loads(pickle.dumps(robot))
    for name, arr in limits_of(robot).items():
        np.testing.assert_array_equal(getattr(copy, name), arr)
    assert copy.urdf == robot.urdf and copy.joint_names == robot.joint_names


def test_the_yaml_is_read_without_running_code(tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    text = f"joint_limits: !!python/object/apply:os.system ['touch {marker}']\n"
    with pytest.raises(ValueError, match=r"joint_limits \(YAML text\) is not valid YAML"):
        Robot.from_urdf(URDF, tip="tip", joint_limits=text)
    assert not marker.exists()


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("source", "match"),
    [
        ("joint_limits:\n  j1: [1, 2\n", r"joint_limits \(YAML text\) is not valid YAML \("),
        (
            "limits:\n  j1: {}\n",
            r"joint_limits \(YAML text\) must hold a mapping 'joint_limits: \{joint name: "
            r"\{key: value\}\}' .*; the 'joint_limits' key is missing \(keys: \['limits'\]\)",
        ),
        ("joint_limits: 3\n", r"'joint_limits' holds a int"),
        ("joint_limits:\n", r"'joint_limits' holds a NoneType"),
        ({"other": 1}, r"joint_limits \(mapping\) must hold .* 'joint_limits' key is missing"),
        ("joint_limits:\n  j1: 2.0\n", r"joint 'j1' must map keys .* got float 2\.0"),
        (
            with_entry(has_acceleration_limits=True),
            r"joint_limits \(mapping\): joint 'j1': has_acceleration_limits is true but "
            r"max_acceleration is missing",
        ),
        (
            with_entry(has_jerk_limits=True, max_jerk=-1),
            r"joint 'j1': max_jerk must be a number > 0 \(rad/s\^3; \.inf for no limit\), "
            r"got -1\.0",
        ),
        (
            with_entry(has_velocity_limits=True, max_velocity=0.0),
            r"joint 'j1': max_velocity must be a number > 0 \(rad/s; .*got 0\.0",
        ),
        (
            "joint_limits:\n  j1: {has_acceleration_limits: true, max_acceleration: .nan}\n",
            r"joint 'j1': max_acceleration must be a number > 0 .*got nan",
        ),
        (
            with_entry(has_acceleration_limits=True, max_acceleration="fast"),
            r"joint 'j1': max_acceleration must be a number, got 'fast'",
        ),
        (
            with_entry(has_acceleration_limits=True, max_acceleration=True),
            r"joint 'j1': max_acceleration must be a number, got True",
        ),
        (
            "joint_limits:\n  j1: {has_jerk_limits: 'yes', max_jerk: 1.0}\n",
            r"joint 'j1': has_jerk_limits must be true or false, got 'yes'",
        ),
        (
            with_entry(has_velocity_limits=1, max_velocity=1.0),
            r"joint 'j1': has_velocity_limits must be true or false, got 1",
        ),
        (
            with_entry(max_acceleration=3.0),
            r"joint 'j1': max_acceleration is given without has_acceleration_limits; add "
            r"'has_acceleration_limits: true'",
        ),
        (
            with_entry(has_position_limits=True, min_position=-1.0),
            r"joint 'j1': has_position_limits is true but max_position is missing",
        ),
        (
            with_entry(has_position_limits=True, min_position=1.0, max_position=-1.0),
            r"joint 'j1': min_position and max_position must be finite with min_position <= "
            r"max_position, got 1\.0 and -1\.0",
        ),
        (
            with_entry(min_position=-1.0, max_position=1.0),
            r"joint 'j1': min_position and max_position given without has_position_limits",
        ),
        (3, r"joint_limits must be a path to a joint_limits\.yaml file, .* got int"),
    ],
)
def test_bad_joint_limits(source: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Robot.from_urdf(URDF, tip="tip", joint_limits=source)


def test_bad_joint_limits_files_are_named(tmp_path: Path) -> None:
    missing = tmp_path / "nope.yaml"
    with pytest.raises(ValueError, match=r"joint_limits file '.*nope\.yaml' does not exist"):
        Robot.from_urdf(URDF, tip="tip", joint_limits=missing)
    with pytest.raises(ValueError, match=r"joint_limits file 'nope\.yaml' does not exist"):
        Robot.from_urdf(URDF, tip="tip", joint_limits="nope.yaml")
    with pytest.raises(ValueError, match=r"joint_limits file '.*' is a directory"):
        Robot.from_urdf(URDF, tip="tip", joint_limits=tmp_path)
    binary = tmp_path / "limits.yaml"
    binary.write_bytes(b"\xff\xfe\x00joint")
    with pytest.raises(ValueError, match=r"joint_limits file '.*limits\.yaml' is not UTF-8 text"):
        Robot.from_urdf(URDF, tip="tip", joint_limits=binary)
    bad = tmp_path / "bad.yaml"
    bad.write_text("joint_limits:\n  j2:\n    has_jerk_limits: true\n", encoding="utf-8")
    with pytest.raises(
        ValueError,
        match=r"joint_limits file '.*bad\.yaml': joint 'j2': has_jerk_limits is true but "
        r"max_jerk is missing",
    ):
        Robot.from_urdf(URDF, tip="tip", joint_limits=bad)


def test_the_shipped_yaml_files_are_valid_joint_limits_files() -> None:
    for path, robot in (
        (robots.katana_joint_limits_path(), robots.katana()),
        (robots.panda_joint_limits_path(), robots.panda()),
    ):
        declared = yaml.safe_load(path.read_text(encoding="utf-8"))["joint_limits"]
        assert list(declared) == robot.joint_names, path
        for name, entry in zip(robot.joint_names, declared.values(), strict=True):
            j = robot.joint_names.index(name)
            assert entry["max_acceleration"] == robot.acceleration_limit[j]
            assert entry["max_jerk"] == robot.jerk_limit[j]


# ----------------------------------------------------------------------------- skill files
def tiny_demos(robot: Robot) -> list[Demonstration]:
    """Three short demonstrations of the Katana reaching a glass."""
    rng = np.random.default_rng(3)
    start = np.array([0.0, 1.2, -1.8, -1.4, 0.0])
    reach = np.array([0.5, 0.8, -1.8, -1.0, 0.0])
    demos = []
    for _ in range(3):
        s = np.linspace(0.0, 1.0, 30)[:, None]
        end = reach + rng.normal(0.0, 0.02, 5)
        demos.append(
            Demonstration(
                np.linspace(0.0, 2.0, 30),
                start + (end - start) * s,
                {"glass": robot.fk(end)},
                gripper=s[:, 0] > 0.8,
            )
        )
    return demos


# The Katana with its URDF and limits other than the shipped ones (a velocity the URDF lacks).
CUSTOM = {
    "joint_limits": {
        "pan": {"has_velocity_limits": True, "max_velocity": 0.8},
        "lift1": {"has_velocity_limits": False, "has_jerk_limits": True, "max_jerk": 12.5},
        "lift3": {"has_acceleration_limits": True, "max_acceleration": 2.25},
    }
}


@pytest.fixture(scope="module")
def custom_katana() -> Robot:
    return Robot.from_urdf(robots.katana_urdf_path(), tip="tool", joint_limits=CUSTOM)


@pytest.fixture(scope="module")
def saved_skill(custom_katana: Robot, tmp_path_factory: pytest.TempPathFactory) -> Path:
    skill = Skill.learn(tiny_demos(custom_katana), custom_katana, n_steps=100, n_components=2)
    path = tmp_path_factory.mktemp("skill") / "skill.npz"
    skill.save(path)
    return path


def test_a_saved_and_loaded_skill_keeps_the_limits(saved_skill: Path, custom_katana: Robot) -> None:
    np.testing.assert_array_equal(custom_katana.velocity_limit, [0.8, INF, 1.19, 1.19, 1.19])
    with np.load(saved_skill, allow_pickle=False) as data:
        assert int(data["version"]) == 3  # learned: it keeps its demonstrations
        for name in LIMITS:
            stored = data[f"robot_{name}"]
            assert stored.dtype == np.float64 and stored.shape == (5,)
            np.testing.assert_array_equal(stored, getattr(custom_katana, name))
    robot = Skill.load(saved_skill).robot
    assert isinstance(robot, Robot)
    for name, arr in limits_of(custom_katana).items():
        np.testing.assert_array_equal(getattr(robot, name), arr)


def test_a_file_without_the_limit_keys_loads_as_before(saved_skill: Path, tmp_path: Path) -> None:
    with np.load(saved_skill, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files if not k.endswith("_limit")}
    assert len(arrays) == len(np.load(saved_skill).files) - 3
    old = tmp_path / "old.npz"
    np.savez(old, **arrays)
    robot = Skill.load(old).robot
    assert isinstance(robot, Robot)
    np.testing.assert_array_equal(robot.velocity_limit, np.full(5, 1.19))  # the URDF's
    np.testing.assert_array_equal(robot.acceleration_limit, np.full(5, INF))
    np.testing.assert_array_equal(robot.jerk_limit, np.full(5, INF))


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("robot_velocity_limit", np.ones(4), r"robot_velocity_limit must be an array of numbers "),
        (
            "robot_jerk_limit",
            np.ones((5, 1)),
            r"robot_jerk_limit .* shape \(5,\) .* shape \(5, 1\)",
        ),
        ("robot_jerk_limit", np.array(["a"] * 5), r"robot_jerk_limit must be an array of numbers"),
        (
            "robot_acceleration_limit",
            np.array([1.0, 1.0, 0.0, 1.0, 1.0]),
            r"robot_acceleration_limit\[2\] must be > 0 \(inf for no limit\), got 0\.0",
        ),
        ("robot_jerk_limit", np.full(5, np.nan), r"robot_jerk_limit\[0\] must be > 0 .* got nan"),
        ("robot_velocity_limit", -np.ones(5), r"robot_velocity_limit\[0\] must be > 0 .*got -1"),
    ],
)
def test_bad_stored_limits_are_refused(
    saved_skill: Path, tmp_path: Path, key: str, value: NDArray[Any], match: str
) -> None:
    with np.load(saved_skill, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    bad = tmp_path / "bad.npz"
    np.savez(bad, **{**arrays, key: value})
    with pytest.raises(ValueError, match=r"bad\.npz is not a valid pbdkit-skill file: " + match):
        Skill.load(bad)


def test_a_robot_without_a_urdf_stores_its_limits_with_zero_as_inf(
    custom_katana: Robot, tmp_path: Path
) -> None:
    def Arm() -> KinematicOnly:  # a KinematicModel, not a Robot; 0 = not limited
        limits = {**no_limits(5), "velocity_limit": np.array([1.0, 0.0, 1.0, 1.0, 1.0])}
        return KinematicOnly(custom_katana, **limits)

    skill = Skill.learn(tiny_demos(custom_katana), Arm(), n_steps=100, n_components=2)
    skill.save(tmp_path / "arm.npz")
    with np.load(tmp_path / "arm.npz", allow_pickle=False) as data:
        np.testing.assert_array_equal(data["robot_velocity_limit"], [1.0, INF, 1.0, 1.0, 1.0])
        np.testing.assert_array_equal(data["robot_acceleration_limit"], np.full(5, INF))
    Skill.load(tmp_path / "arm.npz", robot=Arm())  # valid


# ----------------------------------------------------------------------------- pbdkit learn
def test_learn_with_joint_limits(tmp_path: Path) -> None:
    save_demonstrations(tiny_demos(robots.katana()), tmp_path / "demos.npz")
    limits = tmp_path / "limits.yaml"
    limits.write_text(yaml.safe_dump(CUSTOM), encoding="utf-8")
    out = tmp_path / "skill.npz"
    args = ["learn", str(tmp_path / "demos.npz"), "--out", str(out), "--n-steps", "30"]
    urdf = str(robots.katana_urdf_path())
    result = CliRunner().invoke(
        app, [*args, "--max-components", "2", "--robot", urdf, "--joint-limits", str(limits)]
    )
    assert result.exit_code == 0, result.output
    robot = Skill.load(out).robot
    assert isinstance(robot, Robot)
    np.testing.assert_array_equal(robot.velocity_limit, [0.8, INF, 1.19, 1.19, 1.19])
    np.testing.assert_array_equal(robot.jerk_limit, [INF, 12.5, INF, INF, INF])


@pytest.mark.parametrize(
    ("robot", "limits", "fragments"),
    [
        ("katana", "limits.yaml", ["--joint-limits applies to a URDF robot; the shipped katana"]),
        ("urdf", "nope.yaml", ["joint_limits file 'nope.yaml' does not exist"]),
    ],
)
def test_learn_joint_limits_errors(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, robot: str, limits: str, fragments: list[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    save_demonstrations(tiny_demos(robots.katana()), tmp_path / "demos.npz")
    (tmp_path / "limits.yaml").write_text(yaml.safe_dump(CUSTOM), encoding="utf-8")
    arm = str(robots.katana_urdf_path()) if robot == "urdf" else robot
    result = CliRunner().invoke(
        app, ["learn", "demos.npz", "--robot", arm, "--joint-limits", limits, "--n-steps", "20"]
    )
    assert result.exit_code == 2, result.output
    text = result.output.strip()
    assert text.startswith("error: ") and "\n" not in text and "Traceback" not in text, text
    for fragment in fragments:
        assert fragment in text, text
    assert not (tmp_path / "skill.npz").exists()
