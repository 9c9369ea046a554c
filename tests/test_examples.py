"""The scripts in examples/ run as a user runs them (a fresh interpreter, an output folder) and
do what they print: bags read back by rosbags' own reader, a trajectory for the new objects."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from subprocess import PIPE

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from pbdkit import Skill, demonstration_from_csv, read_bag
from pbdkit.robots import panda

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCRIPTS = ("panda_from_bags.py", "your_arm.py")
TS = get_typestore(Stores.ROS2_HUMBLE)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, str]]:
    """Every example run once, side by side (two cores): script -> (its folder, its output)."""
    procs = {}
    for script in SCRIPTS:
        out = tmp_path_factory.mktemp(script.removesuffix(".py"))
        cmd = [sys.executable, str(EXAMPLES / script), str(out)]
        procs[script] = (out, subprocess.Popen(cmd, stdout=PIPE, stderr=PIPE, text=True))
    results = {}
    for script, (out, proc) in procs.items():
        try:
            stdout, stderr = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
        assert proc.returncode == 0, f"{script} failed:\n{stdout}{stderr}"
        results[script] = (out, stdout)
    return results


def _trajectory(path: Path) -> tuple[list[str], np.ndarray, np.ndarray, list[bool]]:
    """Joint names, positions (T, n), times (T,) and the gripper messages of a trajectory bag."""
    with AnyReader([path], default_typestore=TS) as reader:
        msgs = {
            c.topic: [reader.deserialize(raw, c.msgtype) for _, _, raw in reader.messages([c])]
            for c in reader.connections
        }
    (traj,) = msgs["/joint_trajectory"]
    q = np.stack([p.positions for p in traj.points])
    t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in traj.points])
    return list(traj.joint_names), q, t, [m.data for m in msgs["/gripper"]]


def _number(pattern: str, text: str) -> float:
    match = re.search(pattern, text)
    assert match is not None, f"{pattern!r} not in the output:\n{text}"
    return float(match.group(1))


def test_panda_from_bags(runs: dict[str, tuple[Path, str]]) -> None:
    tmp_path, text = runs["panda_from_bags.py"]
    robot = panda()
    bags = sorted(tmp_path.glob("demo_*"))
    assert len(bags) == 5
    assert {p.suffix for b in bags for p in b.iterdir()} == {".yaml", ".db3", ".mcap"}
    demo = read_bag(
        bags[0], robot=robot, objects={"glass": "/glass/pose"}, gripper_topic="/gripper"
    )
    assert demo.n_joints == 7 and demo.gripper is not None
    # The hand is at the glass while the gripper closes: the demonstration is consistent.
    closing = int(np.argmax(demo.gripper > 0.5))
    assert np.linalg.norm(robot.fk(demo.joints[closing]) - demo.objects["glass"]) < 0.005
    names, q, t, grip = _trajectory(tmp_path / "trajectory")
    assert names == robot.joint_names and q.shape == (1000, 7)
    assert np.all(np.diff(t) > 0) and t[0] == 0.0
    assert abs(t[-1] - _number(r"(\d+\.\d+) s\n", text.split("wrote")[-1])) < 0.01
    assert grip == [False, True]
    assert np.all(robot.within_limits(q, tol=1e-9))
    # The printed closest approach is the trajectory's: the hand reaches the new glass.
    found = re.search(r"new glass at (\[.*?\]) m", text)
    assert found is not None, text
    glass = np.array(json.loads(found.group(1)))
    closest = np.linalg.norm(robot.fk(q) - glass, axis=1).min()
    assert closest < 0.005
    assert abs(1000 * closest - _number(r"closest approach to the glass: (\d+\.\d) mm", text)) < 1.5
    assert _number(r"joint space only, the demonstrated postures: (\d+\.\d) mm", text) > 20


def test_your_arm(runs: dict[str, tuple[Path, str]]) -> None:
    tmp_path, text = runs["your_arm.py"]
    skill = Skill.load(tmp_path / "skill.npz")  # the robot comes back from the URDF it holds
    robot = skill.robot
    assert robot.joint_names == ["yaw", "shoulder", "elbow", "wrist"]  # type: ignore[attr-defined]
    csvs = sorted(tmp_path.glob("demo*.csv"))
    assert len(csvs) == 5
    demo = demonstration_from_csv(csvs[0], objects={})
    assert demo.n_joints == 4 and demo.gripper is not None
    names, q, t, grip = _trajectory(tmp_path / "trajectory")
    assert names == ["yaw", "shoulder", "elbow", "wrist"] and q.shape == (1000, 4)
    assert grip == [False, True, False]
    np.testing.assert_allclose(t[-1], skill.duration, rtol=1e-9)
    for name in ("cup", "bin"):
        assert _number(rf"closest approach: .*{name} (\d+\.\d) mm", text) < 5.0
    assert _number(r"hand at grasp (\d+\.\d) mm from the cup", text) < 5.0
    assert _number(r"at release (\d+\.\d) mm", text) < 5.0
    assert _number(r"online: (\d+) commands", text) == 999
