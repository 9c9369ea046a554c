"""Hostile joint_limits YAML (issue 36, items 3, 13, 14 and 16, and item 2's alias bomb in every
field): pbdkit.robots._joint_limits and the matching of its joint names to a robot's.

Each bad input gets a one-line ValueError naming the file (or form) and the joint and key, within
seconds and bounded memory: a joint name the URDF does not have (a typo, a file for another arm),
YAML nested 5000 levels deep, a file over the size cap, a limit beyond the float range, and a
0.5 KB alias bomb as any field of the file.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hostile import bounded
from typer.testing import CliRunner

from pbdkit import _yaml, robots
from pbdkit.apps._cli import app
from pbdkit.robots import _joint_limits
from pbdkit.robots._joint_limits import joint_limits_mapping, read_joint_limits
from pbdkit.robots._robot import Robot

PANDA_URDF = Path(__file__).resolve().parent / "data" / "arms" / "panda.urdf"
KATANA = ("pan", "lift1", "lift2", "lift3", "wrist_roll")


def _entry(**limits: Any) -> dict[str, Any]:
    return {"has_acceleration_limits": True, "max_acceleration": 6.0, **limits}


def _katana(joint_limits: Any) -> Robot:
    return Robot.from_urdf(robots.katana_urdf_path(), tip="tool", joint_limits=joint_limits)


def _one_line(exc: pytest.ExceptionInfo[BaseException], limit: int = 700) -> str:
    text = str(exc.value)
    assert "\n" not in text and len(text) < limit, text[:2000]
    return text


# ----------------------------------------------------------------- item 3: names the robot lacks
def test_a_misspelt_joint_name_is_refused_naming_it_and_the_robots_joints() -> None:
    table = {name: _entry() for name in KATANA}
    table["lift_2"] = table.pop("lift2")  # a typo: lift2 would keep an infinite acceleration
    with pytest.raises(ValueError, match=r"'lift_2'") as info:
        _katana({"joint_limits": table})
    text = _one_line(info)
    assert "joint_limits (mapping)" in text and "'lift2'" in text and "'wrist_roll'" in text


def test_a_file_for_another_arm_is_refused_naming_the_file(tmp_path: Path) -> None:
    path = tmp_path / "limits.yaml"
    path.write_text(robots.panda_joint_limits_path().read_text(encoding="utf-8"))
    with pytest.raises(ValueError, match=r"'panda_joint1'") as info:
        _katana(path)
    text = _one_line(info)
    assert f"joint_limits file '{path}'" in text and "'pan'" in text and "7 joints" in text


def test_the_list_of_unknown_and_known_names_is_bounded() -> None:
    table = {f"joint_{i}": _entry() for i in range(5000)}
    urdf = robots.katana_urdf_path().read_text(encoding="utf-8")
    for i in range(300):  # a URDF with many joints besides the chain
        urdf = urdf.replace(
            "</robot>",
            f'<link name="x{i}"/><joint name="x{i}" type="fixed"><parent link="base_link"/>'
            f'<child link="x{i}"/></joint></robot>',
        )
    with pytest.raises(ValueError, match=r"5000 joints") as info:
        Robot.from_urdf(urdf, tip="tool", joint_limits={"joint_limits": table})
    _one_line(info)


def test_a_urdf_joint_off_the_chain_stays_allowed_and_ignored() -> None:
    # MoveIt's files name the fingers too: joints of the URDF that do not move the tip.
    names = [f"panda_joint{i}" for i in range(1, 8)]
    table = {name: _entry() for name in [*names, "panda_finger_joint1", "panda_hand_joint"]}
    robot = Robot.from_urdf(PANDA_URDF, tip="panda_hand_tcp", joint_limits={"joint_limits": table})
    assert robot.joint_names == names
    np.testing.assert_array_equal(robot.acceleration_limit, np.full(7, 6.0))


@pytest.mark.parametrize(
    ("robot", "path"),
    [
        (robots.katana, robots.katana_joint_limits_path),
        (robots.panda, robots.panda_joint_limits_path),
    ],
    ids=["katana", "panda"],
)
def test_the_shipped_limits_files_still_load(
    robot: Callable[[], Robot], path: Callable[[], Path]
) -> None:
    arm = robot()
    assert set(read_joint_limits(path())) == set(arm.joint_names)
    assert np.all(np.isfinite(arm.acceleration_limit)) and np.all(np.isfinite(arm.jerk_limit))


def test_learn_refuses_a_misspelt_joint_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    table = {name: _entry() for name in KATANA}
    table["wrist"] = table.pop("wrist_roll")
    Path("limits.yaml").write_text(yaml.safe_dump({"joint_limits": table}), encoding="utf-8")
    urdf = str(robots.katana_urdf_path())
    args = ["learn", "demos.npz", "--robot", urdf, "--joint-limits", "limits.yaml"]
    result = CliRunner().invoke(app, args)
    text = result.output.strip()
    assert result.exit_code == 2, text
    assert text.startswith("error: ") and "\n" not in text, text
    assert "joint_limits file 'limits.yaml'" in text and "'wrist'" in text, text
    assert not Path("skill.npz").exists()


# ----------------------------------------------------------------- item 13: deep nesting and co.
DEEP = "[" * 5000 + "]" * 5000  # 10 KB
CHOKING = {
    "flow": (f"joint_limits:\n  pan: {DEEP}\n", "nest"),
    "flow-unused-key": (f"joint_limits:\n  pan:\n    max_effort: {DEEP}\n", "nest"),
    "block": ("joint_limits:\n" + "- " * 5000 + "x\n", "nest"),
    "key": (f"? {DEEP}\n: 1\njoint_limits: {{}}\n", ""),
    "13th-month": (
        "joint_limits:\n  pan: {has_velocity_limits: true, max_velocity: 2001-13-01}\n",
        "month",
    ),
    "5000-digits": (f"joint_limits:\n  pan: {{max_effort: {'7' * 5000}}}\n", "digits"),
}
# PyYAML's pure-Python loader, the fallback where libyaml is missing, takes up to 1 s on each
# deep case (it looks 1024 characters ahead for a simple key): three of them are enough.
LOADERS = [("libyaml", case) for case in CHOKING] + [
    ("python", case) for case in ("flow", "block", "13th-month")
]


@pytest.mark.parametrize(("loader", "case"), LOADERS, ids=[f"{a}-{b}" for a, b in LOADERS])
def test_yaml_the_loader_chokes_on_is_refused_naming_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, loader: str, case: str
) -> None:
    text, detail = CHOKING[case]
    megabytes: float | None = 20
    if loader == "python":
        monkeypatch.setattr(_yaml, "SAFE_LOADER", yaml.SafeLoader)
        megabytes = None
    path = tmp_path / "limits.yaml"
    path.write_text(text, encoding="utf-8")
    limit = bounded(seconds=3.0, megabytes=megabytes)
    with limit, pytest.raises(ValueError, match=r"is not valid YAML \(") as info:
        read_joint_limits(path)
    message = _one_line(info)
    assert message.startswith(f"joint_limits file '{path}' is not valid YAML"), message
    assert detail in message, message


@pytest.mark.parametrize(
    "text",
    [
        "joint_limits:\n  pan: *" + "a" * 100_000 + "\n",  # an undefined alias
        "joint_limits:\n  pan: !<" + "t" * 100_000 + "> 1\n",  # an unknown tag
    ],
    ids=["alias", "tag"],
)
def test_the_loaders_message_is_bounded(text: str) -> None:
    with pytest.raises(ValueError, match=r"joint_limits \(YAML text\) is not valid YAML") as info:
        read_joint_limits(text)
    _one_line(info)


def test_python_tags_stay_refused_by_the_fast_loader(tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    path = tmp_path / "limits.yaml"
    path.write_text(f"joint_limits: !!python/object/apply:os.system ['touch {marker}']\n")
    with pytest.raises(ValueError, match=r"is not valid YAML .*python/object/apply"):
        read_joint_limits(path)
    assert not marker.exists()


# ----------------------------------------------------------------- item 14: the size cap
def test_a_file_over_the_cap_is_refused_before_reading(tmp_path: Path) -> None:
    cap = _joint_limits.MAX_YAML_BYTES
    assert 64 * 1024 <= cap <= 16 * 1024 * 1024  # a limits file is a few KB
    path = tmp_path / "limits.yaml"
    path.write_text("# " + "x" * cap + "\njoint_limits: {}\n", encoding="utf-8")
    size = path.stat().st_size
    limit = bounded(seconds=1.0, megabytes=cap / 1e6 / 4)
    with limit, pytest.raises(ValueError, match=r"over the cap") as info:
        read_joint_limits(path)
    text = _one_line(info)
    assert f"joint_limits file '{path}'" in text and str(size) in text and str(cap) in text, text


def test_yaml_text_over_the_cap_is_refused() -> None:
    cap = _joint_limits.MAX_YAML_BYTES
    text = "joint_limits: {}\n" + "# " + "x" * cap + "\n"
    with (
        bounded(seconds=1.0, megabytes=1),
        pytest.raises(ValueError, match=r"over the cap") as info,
    ):
        read_joint_limits(text)
    message = _one_line(info)
    assert "joint_limits (YAML text)" in message and str(cap) in message, message


@pytest.mark.skipif(not yaml.__with_libyaml__, reason="PyYAML built without libyaml")
def test_libyamls_safe_loader_reads_a_large_file_fast(tmp_path: Path) -> None:
    assert _yaml.SAFE_LOADER is yaml.CSafeLoader  # 5x the pure-Python loader's speed
    entry = "{has_velocity_limits: true, max_velocity: 1.5, has_jerk_limits: false}"
    lines = ["joint_limits:", *(f"  joint_{i}: {entry}" for i in range(3000))]
    path = tmp_path / "limits.yaml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")  # 250 KB
    start = time.perf_counter()
    limits = read_joint_limits(path)
    assert time.perf_counter() - start < 1.5  # the pure-Python loader: about 6 s a MB
    assert len(limits) == 3000 and limits["joint_2999"].velocity == 1.5


# ----------------------------------------------------------------- item 16: beyond float range
@pytest.mark.parametrize(
    ("entry", "key"),
    [
        ({"has_velocity_limits": True, "max_velocity": 10**400}, "max_velocity"),
        ({"has_jerk_limits": True, "max_jerk": -(10**400)}, "max_jerk"),
        (
            {"has_position_limits": True, "min_position": -(10**400), "max_position": 1.0},
            "min_position",
        ),
    ],
    ids=["velocity", "jerk", "position"],
)
def test_a_limit_beyond_the_float_range_is_refused_naming_joint_and_key(
    entry: dict[str, Any], key: str
) -> None:
    with pytest.raises(ValueError, match=rf"joint_limits \(mapping\): joint 'pan': {key} ") as info:
        _katana({"joint_limits": {"pan": entry}})
    _one_line(info)


def test_a_hexadecimal_limit_beyond_the_float_range_in_a_file(tmp_path: Path) -> None:
    path = tmp_path / "limits.yaml"
    path.write_text(
        f"joint_limits:\n  pan:\n    has_jerk_limits: true\n    max_jerk: 0x{'f' * 400}\n"
    )
    with pytest.raises(ValueError, match=r"limits\.yaml': joint 'pan': max_jerk ") as info:
        read_joint_limits(path)
    _one_line(info)


def test_joint_limits_mapping_refuses_a_value_beyond_the_float_range() -> None:
    with pytest.raises(ValueError, match=r"velocity") as info:
        joint_limits_mapping(["a", "b"], velocity=[1.0, 10**400])
    _one_line(info)


# ----------------------------------------------------------------- item 2's kin: the alias bomb
def _bomb(levels: int = 8) -> str:
    """Anchors x0..x{levels}, each nine aliases of the one before: 9**(levels + 1) strings."""
    lines = ["x0: &x0 [" + ", ".join(['"lol"'] * 9) + "]"]
    lines += [f"x{i}: &x{i} [" + ", ".join([f"*x{i - 1}"] * 9) + "]" for i in range(1, levels + 1)]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("tail", "match"),
    [
        ("joint_limits: *x8\n", r"'joint_limits' holds a list"),
        ("joint_limits:\n  pan: *x8\n", r"joint 'pan' must map keys"),
        ("joint_limits:\n  pan: {has_velocity_limits: *x8}\n", r"has_velocity_limits must be"),
        ("joint_limits:\n  pan: {has_jerk_limits: true, max_jerk: *x8}\n", r"max_jerk must be"),
        (
            "joint_limits:\n  pan: {has_position_limits: true, min_position: *x8}\n",
            r"min_position must be a number",
        ),
        ("limits: *x8\n", r"the 'joint_limits' key is missing"),
        ("joint_limits:\n  *x8 : {}\n", r"is not valid YAML"),  # a list as a key
    ],
    ids=["table", "entry", "flag", "value", "position", "other-key", "name"],
)
def test_an_alias_bomb_in_any_field_is_refused_fast(tmp_path: Path, tail: str, match: str) -> None:
    path = tmp_path / "limits.yaml"
    path.write_text(_bomb() + tail, encoding="utf-8")
    assert path.stat().st_size < 1000
    with bounded(seconds=2.0, megabytes=20), pytest.raises(ValueError, match=match) as info:
        _katana(path)
    _one_line(info)


def test_an_alias_bomb_under_an_unused_key_loads_without_expanding_it(tmp_path: Path) -> None:
    path = tmp_path / "limits.yaml"
    text = "default_velocity_scaling_factor: *x8\njoint_limits:\n  pan: {max_effort: *x8}\n"
    path.write_text(_bomb() + text, encoding="utf-8")
    with bounded(seconds=2.0, megabytes=20):
        robot = _katana(path)
    assert robot.acceleration_limit[0] == np.inf and robot.velocity_limit[0] == 1.19


def test_many_keys_and_long_names_give_bounded_messages() -> None:
    many = {f"key_{i}": i for i in range(50_000)}  # no joint_limits among them
    with pytest.raises(ValueError, match=r"the 'joint_limits' key is missing") as info:
        read_joint_limits(many)
    _one_line(info)
    long_name = "j" * 100_000
    with pytest.raises(ValueError, match=r"must map keys") as info:
        read_joint_limits({"joint_limits": {long_name: 1.0}})
    _one_line(info)


@pytest.mark.parametrize(
    ("key", "value"),
    [("max_velocity", "1.0e-300"), ("max_acceleration", "1.0e-9"), ("max_jerk", "1.0e+300")],
)
def test_a_limit_no_arm_has_is_refused_where_the_file_is_read(
    tmp_path: Path, key: str, value: str
) -> None:
    # Issue 36, item 9 through the file: `pbdkit learn --joint-limits` took 1e-300 and wrote a
    # skill whose reproduction died inside Ruckig; the reader now names the file and the key.
    kind = key.removeprefix("max_")
    path = tmp_path / "joint_limits.yaml"
    path.write_text(f"joint_limits:\n  lift1:\n    has_{kind}_limits: true\n    {key}: {value}\n")
    with pytest.raises(ValueError, match=rf"joint_limits file .*lift1.*{key} must be in \[") as exc:
        read_joint_limits(path)
    assert "\n" not in str(exc.value) and "LIMIT_RANGES" in str(exc.value)
