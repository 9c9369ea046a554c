"""The pbdkit command line: the LASA demo writes a valid figure and consistent metrics; learn
and reproduce on tiny inputs; bad paths and options are one-line errors found before any work."""

from __future__ import annotations

import errno
import json
import os
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner, Result

from pbdkit.apps._cli import app
from pbdkit.data._demonstration import Demonstration, save_demonstrations
from pbdkit.prob._selection import CV_TOLERANCE
from pbdkit.robots import katana
from pbdkit.skill._skill import Skill

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_demo_lasa_writes_figure_and_metrics(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app, ["demo", "--task", "lasa", "--shape", "Angle", "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    png = tmp_path / "lasa_Angle.png"
    assert png.read_bytes()[:8] == PNG_MAGIC
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["shape"] == "Angle"
    sel = metrics["selection"]
    k = metrics["n_components"]
    assert sel["method"] == "cv" and sel["chosen"] == k
    assert 2 <= k < sel["candidates"][-1]  # an interior K, not the cap
    # The smallest K whose left-out-demonstration error is within the tolerance of the best.
    scores = dict(zip(sel["candidates"], sel["scores"], strict=True))
    bound = (1 + CV_TOLERANCE) * scores[sel["best"]]
    assert scores[k] <= bound and all(scores[j] > bound for j in scores if j < k)
    # The generalized trajectory is a faithful summary of the demonstrations.
    assert metrics["rmse_gmr_to_demos"] < 1.5 * metrics["rmse_pointwise_mean_to_demos"]
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary file


def test_demo_unknown_task_is_a_clear_error(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["demo", "--task", "juggling", "--out", str(tmp_path)])
    assert result.exit_code != 0
    assert "--task" in result.output


# ----------------------------------------------------------------------------- learn, reproduce
def _tiny_demos(path: Path) -> np.ndarray:
    """Three short katana demonstrations reaching a glass; returns the mean glass position."""
    robot = katana()
    rng = np.random.default_rng(3)
    start = np.array([0.0, 1.2, -1.8, -1.4, 0.0])
    reach = np.array([0.5, 0.8, -1.8, -1.0, 0.0])
    demos = []
    for _ in range(3):
        s = np.linspace(0.0, 1.0, 30)[:, None]
        end = reach + rng.normal(0.0, 0.02, 5)
        joints = start + (end - start) * s
        glass = robot.fk(end)
        demos.append(
            Demonstration(
                np.linspace(0.0, 2.0, 30), joints, {"glass": glass}, gripper=(s[:, 0] > 0.8)
            )
        )
    save_demonstrations(demos, path)
    return np.mean([d.objects["glass"] for d in demos], axis=0)


def _one_line_error(result: Result, *fragments: str) -> None:
    assert result.exit_code == 2, result.output
    text = result.output.strip()
    assert text.startswith("error: ") and "\n" not in text, text
    assert "Traceback" not in text
    for fragment in fragments:
        assert fragment in text, text


def test_learn_and_reproduce_with_tiny_inputs(tmp_path: Path) -> None:
    glass = _tiny_demos(tmp_path / "demos.npz")
    runner = CliRunner()
    skill = tmp_path / "skill.npz"
    result = runner.invoke(
        app,
        [
            "learn",
            str(tmp_path / "demos.npz"),
            "--out",
            str(skill),
            "--n-steps",
            "30",
            "--max-components",
            "2",
        ],
    )
    assert result.exit_code == 0, result.output
    assert skill.is_file()
    where = ",".join(f"{v:.4f}" for v in glass)
    out = tmp_path / "repro.npz"
    result = runner.invoke(
        app, ["reproduce", str(skill), "--object", f"glass={where}", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    with np.load(out) as data:
        # The 30 steps after a lead-in from the skill's start posture, timed within the limits.
        lead = int(data["lead_in"].sum())
        assert data["joints"].shape == (30 + lead, 5) and data["t"][lead:].tolist() == list(
            range(30)
        )
        assert data["times"][0] == 0.0 and np.all(np.diff(data["times"]) > 0)
        assert data["velocities"].shape == data["accelerations"].shape == (30 + lead, 5)


@pytest.fixture
def no_simulation(monkeypatch: pytest.MonkeyPatch) -> None:
    """Stand-ins for the simulator modules: a command that reaches them fails the test (and
    none of the simulator's code runs)."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the command started working before checking its output paths")

    sim = [f"pbdkit.sim{m}" for m in ("", ".experiment", ".teacher", ".tracking")]
    names = ["pbdkit.apps._demo", *sim]
    for name in names:
        fake = types.ModuleType(name)
        fake.__getattr__ = lambda attr: refuse  # type: ignore[method-assign]
        monkeypatch.setitem(sys.modules, name, fake)


@pytest.mark.usefixtures("no_simulation")
@pytest.mark.parametrize("kind", ["directory", "missing parent", "parent is a file", "locked"])
@pytest.mark.parametrize(
    ("command", "option"),
    [
        (["learn", "demos.npz"], "--out"),
        (["reproduce", "skill.npz", "--object", "glass=0.3,0,0.1"], "--out"),
        (["teach", "--demos", "3"], "--out"),
        (["evaluate", "--trials", "2"], "--json"),
    ],
)
def test_output_paths_are_checked_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: list[str], option: str, kind: str
) -> None:
    # The inputs (demos.npz, skill.npz) do not exist: an error about them would mean the
    # command started before checking where it writes.
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("")
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access
    # (root may write anywhere: an unwritable directory is simulated)
    monkeypatch.setattr(os, "access", lambda p, mode: Path(p) != locked and real_access(p, mode))
    path, message = {
        "directory": ("folder", "is a directory; give a file path"),
        "missing parent": ("nowhere/out.npz", "nowhere does not exist"),
        "parent is a file": ("file/out.npz", "file is not a directory"),
        "locked": ("locked/out.npz", "locked is not writable"),
    }[kind]
    result = CliRunner().invoke(app, [*command, option, path])
    _one_line_error(result, f"{option} {path}", message)


@pytest.mark.usefixtures("no_simulation")
@pytest.mark.parametrize("task", ["lasa", "coaster"])
def test_demo_out_must_be_a_directory(tmp_path: Path, task: str) -> None:
    file = tmp_path / "results.txt"
    file.write_text("keep me")
    result = CliRunner().invoke(app, ["demo", "--task", task, "--out", str(file)])
    _one_line_error(result, f"--out {file}", "exists and is not a directory")
    assert file.read_text() == "keep me"
    missing = tmp_path / "nowhere" / "results"
    result = CliRunner().invoke(app, ["demo", "--task", task, "--out", str(missing)])
    _one_line_error(result, f"--out {missing}", "does not exist")


@pytest.mark.parametrize(
    "error",
    [
        PermissionError(errno.EACCES, "Permission denied"),
        IsADirectoryError(errno.EISDIR, "Is a directory"),
        FileExistsError(errno.EEXIST, "File exists"),
        MemoryError("Unable to allocate 7.28 TiB for an array"),
    ],
)
def test_file_system_and_memory_errors_are_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, error: Exception
) -> None:
    _tiny_demos(tmp_path / "demos.npz")
    out = tmp_path / "skill.npz"

    def save(self: Skill, path: Path) -> None:
        if isinstance(error, OSError):
            error.filename = str(path)
        raise error

    monkeypatch.setattr(Skill, "save", save)
    result = CliRunner().invoke(
        app,
        [
            "learn",
            str(tmp_path / "demos.npz"),
            "--out",
            str(out),
            "--n-steps",
            "20",
            "--max-components",
            "1",
        ],
    )
    if isinstance(error, MemoryError):
        _one_line_error(result, "out of memory: Unable to allocate 7.28 TiB")
    else:
        _one_line_error(result, f"{error.strerror}: {out}")  # type: ignore[attr-defined]


def test_learn_katana_refuses_a_tip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    _tiny_demos(tmp_path / "demos.npz")
    result = CliRunner().invoke(
        app, ["learn", "demos.npz", "--robot", "katana", "--tip", "link3", "--n-steps", "20"]
    )
    _one_line_error(result, "--tip applies to a URDF robot; the shipped katana has a fixed tool")
    assert not (tmp_path / "skill.npz").exists()


def test_reproduce_refuses_an_object_given_twice(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app,
        [
            "reproduce",
            str(tmp_path / "skill.npz"),
            "--object",
            "glass=0.3,0,0.1",
            "--object",
            "coaster=0.3,0.1,0",
            "--object",
            "glass=0.4,0,0.1",
        ],
    )
    _one_line_error(result, "--object glass is given twice")


# ----------------------------------------------------------------------------- issue 22
@pytest.mark.usefixtures("no_simulation")
@pytest.mark.parametrize("link", ["same path", "symbolic link", "hard link"])
@pytest.mark.parametrize(
    ("command", "label"),
    [
        (["learn", "in.npz"], "DEMOS"),
        (["learn", "demos.npz", "--robot", "in.npz"], "--robot"),
        (
            ["learn", "demos.npz", "--robot", "arm.urdf", "--joint-limits", "in.npz"],
            "--joint-limits",
        ),
        (["reproduce", "in.npz", "--object", "glass=0.3,0,0.1"], "SKILL"),
    ],
)
def test_out_may_not_be_an_input(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: list[str], label: str, link: str
) -> None:
    """Issue 22: `reproduce s.npz --out s.npz` and `learn d.npz --out d.npz` destroyed the input."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "in.npz").write_bytes(b"the input")
    (tmp_path / "arm.urdf").write_text("<robot/>")
    out = {"same path": "in.npz", "symbolic link": "link.npz", "hard link": "hard.npz"}[link]
    if link == "symbolic link":
        (tmp_path / out).symlink_to(tmp_path / "in.npz")
    elif link == "hard link":
        os.link(tmp_path / "in.npz", tmp_path / out)
    result = CliRunner().invoke(app, [*command, "--out", out])
    _one_line_error(result, f"--out {out}: is also {label} in.npz, which the command reads")
    assert (tmp_path / "in.npz").read_bytes() == b"the input"


def test_reproduce_out_may_not_be_the_bag(tmp_path: Path) -> None:
    """Issue 22: `--out X --bag X` wrote the .npz, then failed on the bag."""
    skill = tmp_path / "skill.npz"
    skill.write_bytes(b"not read")
    out = tmp_path / "x"
    result = CliRunner().invoke(
        app,
        [
            "reproduce",
            str(skill),
            "--object",
            "glass=0.3,0,0.1",
            "--out",
            str(out),
            "--bag",
            str(out),
        ],
    )
    _one_line_error(result, f"--out {out}: is also --bag {out}; give each output its own path")
    assert list(tmp_path.iterdir()) == [skill]


@pytest.mark.usefixtures("no_simulation")
@pytest.mark.parametrize(
    "command",
    [
        ["teach", "--demos", "3"],
        ["evaluate", "--trials", "2"],
        ["demo", "--task", "coaster"],
        ["study", "--task", "coaster"],
    ],
)
def test_a_negative_seed_names_the_option(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: list[str]
) -> None:
    """Issue 22: `--seed -1` failed inside NumPy, without naming the option."""
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, [*command, "--seed", "-1"])
    _one_line_error(result, "--seed must be an integer >= 0, got -1")
    assert list(tmp_path.iterdir()) == []


def test_one_object_parser_for_learn_and_reproduce() -> None:
    """`reproduce` takes positions, `learn` also a topic or tf:FRAME; one parser, one set of
    messages (there were two)."""
    from pbdkit.apps._cli_options import parse_objects

    positions = parse_objects(["glass=0.3,0,0.1", "coaster=-1e-1,2,inf"])
    assert list(positions) == ["glass", "coaster"]
    np.testing.assert_array_equal(positions["glass"], [0.3, 0.0, 0.1])
    sources = parse_objects(
        ["glass=/glass/pose", "coaster=tf:coaster", "basin=0.5,0,0"], sources=True
    )
    assert sources["glass"] == "/glass/pose" and sources["coaster"] == "tf:coaster"
    np.testing.assert_array_equal(sources["basin"], [0.5, 0.0, 0.0])
    forms = (
        r"expected NAME=x,y,z \(metres\) or NAME=x,y,z,qw,qx,qy,qz \(a pose, quaternion w first\)"
    )
    for texts, kinds, match in [
        (["glass=/glass/pose"], {}, rf"{forms}, got 'glass=/glass/pose'"),
        (["glass=1,2"], {}, rf"{forms}, got 'glass=1,2'"),
        (["glass=1,2"], {"sources": True}, rf"{forms}, got 'glass=1,2'"),
        (["glass="], {}, rf"{forms}, got 'glass='"),
        (["=1,2,3"], {"sources": True}, r"expected NAME=SOURCE \(a topic, tf:frame, x,y,z or"),
    ]:
        with pytest.raises(typer.BadParameter, match=match):
            parse_objects(texts, **kinds)
    for kinds in ({}, {"sources": True}):
        with pytest.raises(typer.Exit):
            parse_objects(["glass=1,2,3", "glass=1,2,3"], **kinds)


def test_object_parser_takes_a_pose_with_the_quaternion_w_first() -> None:
    """Issue 23: --object NAME=x,y,z,qw,qx,qy,qz is a pose (pytransform3d's order, not ROS's
    x,y,z,w), given on as the 7-vector the library reads; other counts name both forms."""
    from scipy.spatial.transform import Rotation

    from pbdkit.apps._cli_options import parse_objects
    from pbdkit.data._placement import check_placements, position_of, rotation_of

    rng = np.random.default_rng(23)
    rot = Rotation.from_quat(rng.normal(size=4))  # uniform on SO(3)
    x, y, z, w = (float(v) for v in rot.as_quat())  # scipy: x, y, z, w
    text = f"mug=0.5,-0.1,0.02,{w!r},{x!r},{y!r},{z!r}"
    for kinds in ({}, {"sources": True}):
        parsed = parse_objects([text, "glass=0.3,0,0.1"], **kinds)
        np.testing.assert_array_equal(parsed["mug"], [0.5, -0.1, 0.02, w, x, y, z])
        assert parsed["glass"].shape == (3,)
        placed = check_placements(parsed)  # what Demonstration and the skill accept
        np.testing.assert_array_equal(position_of(placed["mug"]), [0.5, -0.1, 0.02])
        rotation = rotation_of(placed["mug"])
        assert rotation is not None and rotation_of(placed["glass"]) is None
        np.testing.assert_allclose(rotation, rot.as_matrix(), rtol=0, atol=1e-12)
    # A quarter turn about z: w first reads as intended; read as x,y,z,w it would not be.
    quarter = parse_objects(["mug=0,0,0,0.7071067811865476,0,0,0.7071067811865476"])
    rotation = rotation_of(check_placements(quarter)["mug"])
    assert rotation is not None
    np.testing.assert_allclose(rotation @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)

    forms = r"NAME=x,y,z \(metres\) or NAME=x,y,z,qw,qx,qy,qz \(a pose, quaternion w first\)"
    for kinds in ({}, {"sources": True}):
        for values in ["1", "1,2", "1,2,3,4", "1,2,3,1,0,0", "1,2,3,1,0,0,0,0"]:
            n = values.count(",") + 1
            with pytest.raises(
                typer.BadParameter, match=rf"expected {forms}, got 'mug={values}' \({n} numbers\)"
            ):
                parse_objects([f"mug={values}"], **kinds)
    # On the command line: a usage error (exit code 2) naming the option and both forms.
    result = CliRunner().invoke(app, ["reproduce", "skill.npz", "--object", "mug=1,2,3,1,0,0"])
    assert result.exit_code == 2, result.output
    text = " ".join(result.output.replace("│", " ").split())
    assert "Invalid value for --object: expected NAME=x,y,z (metres) or" in text, text
    assert "NAME=x,y,z,qw,qx,qy,qz (a pose, quaternion w first)" in text, text
    assert "got 'mug=1,2,3,1,0,0' (6 numbers)" in text, text


# ----------------------------------------------------------------------------- poses (issue 23)
def _mug_demos(path: Path) -> np.ndarray:
    """Five Panda demonstrations grasping a mug given as a pose (``tests/pose_teacher.py``);
    returns a new pose of the mug, as the --object parser gives it (x, y, z, qw, qx, qy, qz)."""
    import pose_teacher

    from pbdkit._rotations import quaternion_from_matrix
    from pbdkit.robots import panda

    save_demonstrations(pose_teacher.demonstrations(panda()), path)
    pose = pose_teacher.mug_pose(0.6, 0.5, 0.05)
    return np.r_[pose[:3, 3], quaternion_from_matrix(pose[:3, :3])]


def _learn_mug(tmp_path: Path, *options: str) -> tuple[Result, Path]:
    out = tmp_path / "skill.npz"
    result = CliRunner().invoke(
        app,
        [
            "learn",
            str(tmp_path / "demos.npz"),
            "--robot",
            "panda",
            "--n-steps",
            "30",
            "--max-components",
            "2",
            "--out",
            str(out),
            *options,
        ],
    )
    assert result.exit_code == 0, result.output
    return result, out


def test_learn_orientation_option_says_which_objects_are_oriented(tmp_path: Path) -> None:
    _mug_demos(tmp_path / "demos.npz")
    result, out = _learn_mug(tmp_path)
    assert Skill.load(out).oriented == ["mug"]
    assert "relative to it): mug" in result.output
    assert "learned as positions only" not in result.output
    result, out = _learn_mug(tmp_path, "--no-orientation")
    assert Skill.load(out).oriented == []
    assert "given as poses, learned as positions only (--no-orientation): mug" in result.output
    assert "oriented" not in result.output.replace(str(tmp_path), "")
    # Demonstrations of positions (the paper's): no word of orientation.
    _tiny_demos(tmp_path / "tiny.npz")
    result = CliRunner().invoke(
        app, ["learn", str(tmp_path / "tiny.npz"), "--out", str(out), "--n-steps", "20"]
    )
    assert result.exit_code == 0, result.output
    assert "orient" not in result.output.replace(str(tmp_path), "")


def test_reproduce_a_posed_object_prints_degrees_and_writes_orientations(tmp_path: Path) -> None:
    from pbdkit.apps._report import closest_approach

    seven = _mug_demos(tmp_path / "demos.npz")
    _, skill_path = _learn_mug(tmp_path)
    out = tmp_path / "repro.npz"
    where = ",".join(repr(float(v)) for v in seven)
    result = CliRunner().invoke(
        app, ["reproduce", str(skill_path), "--object", f"mug={where}", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    expected = Skill.load(skill_path).reproduce({"mug": seven})
    mm, deg = closest_approach(expected)["mug"]
    assert deg is not None
    text = " ".join(result.output.split())
    assert "(distance, and the angle to the expected orientation there)" in text
    assert f"mug {mm:.1f} mm and {deg:.1f} deg" in text
    with np.load(out) as data:
        assert str(data["format"]) == "pbdkit-reproduction" and int(data["version"]) == 1
        rot = data["orientations"]
        assert rot.shape == (len(data["t"]), 3, 3)
        np.testing.assert_allclose(rot, expected.orientations)
        np.testing.assert_allclose(
            rot @ np.swapaxes(rot, 1, 2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-9
        )
        np.testing.assert_allclose(
            data["orientation_error_mug"], expected.orientation_errors["mug"]
        )
        np.testing.assert_allclose(data["task_error_mug"], expected.task_errors["mug"])


def test_reproduce_positions_writes_no_orientation(tmp_path: Path) -> None:
    glass = _tiny_demos(tmp_path / "demos.npz")
    skill = tmp_path / "skill.npz"
    runner = CliRunner()
    args = ["learn", str(tmp_path / "demos.npz"), "--out", str(skill), "--n-steps", "20"]
    assert runner.invoke(app, args).exit_code == 0
    out = tmp_path / "repro.npz"
    where = ",".join(f"{v:.4f}" for v in glass)
    result = runner.invoke(
        app, ["reproduce", str(skill), "--object", f"glass={where}", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    with np.load(out) as data:
        assert int(data["version"]) == 1 and "task_error_glass" in data.files
        assert not [k for k in data.files if k.startswith("orientation")]
        closest = 1e3 * float(data["task_error_glass"].min())
    assert 0.0 < closest < 2.0  # the tiny skill's hand reaches the glass
    assert " deg" not in text and text.endswith(f"; closest approach: glass {closest:.1f} mm")
