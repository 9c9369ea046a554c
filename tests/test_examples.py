"""The scripts in examples/ run as a user runs them (a fresh interpreter, an output folder) and
do what they print: bags read back by rosbags' own reader, a trajectory for the new objects
within the arm's limits, and the Panda's 1 kHz setpoints within Franka's."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path
from subprocess import PIPE
from types import ModuleType
from typing import NamedTuple

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from pbdkit import Skill, demonstration_from_csv, read_bag
from pbdkit.learning.probabilistic_ik import ReproductionResult
from pbdkit.motion.limits import MotionLimits, count_reversals, motion_peaks
from pbdkit.robots import panda

# Every test reads the runs of both example scripts (a fresh interpreter each, about 6 s).
pytestmark = pytest.mark.slow

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


class Trajectory(NamedTuple):
    """A trajectory bag as a controller receives it."""

    names: list[str]
    q: np.ndarray  # (T, n) positions
    t: np.ndarray  # (T,) time_from_start, s
    v: np.ndarray  # (T, n) velocities of the points
    a: np.ndarray  # (T, n) accelerations of the points
    gripper: list[bool]  # the /gripper messages


def _trajectory(path: Path) -> Trajectory:
    with AnyReader([path], default_typestore=TS) as reader:
        msgs = {
            c.topic: [reader.deserialize(raw, c.msgtype) for _, _, raw in reader.messages([c])]
            for c in reader.connections
        }
    (traj,) = msgs["/joint_trajectory"]
    return Trajectory(
        list(traj.joint_names),
        np.stack([p.positions for p in traj.points]),
        np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in traj.points]),
        np.stack([p.velocities for p in traj.points]),
        np.stack([p.accelerations for p in traj.points]),
        [m.data for m in msgs["/gripper"]],
    )


def _assert_is_reproduction(traj: Trajectory, res: ReproductionResult) -> None:
    """The bag holds the reproduction: its samples (lead-in included), its timing (to the
    nanosecond of time_from_start), and the velocities and accelerations of that timing."""
    assert res.times is not None and res.velocities is not None and res.accelerations is not None
    np.testing.assert_array_equal(traj.q, res.joints)
    np.testing.assert_allclose(traj.t, res.times, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(traj.v, res.velocities)
    np.testing.assert_array_equal(traj.a, res.accelerations)
    np.testing.assert_allclose(traj.v[[0, -1]], 0.0, atol=1e-12)  # at rest at both ends


def _example(name: str) -> ModuleType:
    """An example script as a module (its main() not run), for its constants and helpers."""
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


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

    # Franka's published limits ("Robot and interface specifications"), which the Panda declares.
    limits = MotionLimits.from_robot(robot, 7)
    np.testing.assert_array_equal(limits.velocity, [2.175] * 4 + [2.61] * 3)
    np.testing.assert_array_equal(limits.acceleration, [15, 7.5, 10, 12.5, 15, 20, 20])
    np.testing.assert_array_equal(limits.jerk, [7500, 3750, 5000, 6250, 7500, 10000, 10000])

    # The online run's record: the setpoints at 1 kHz, the first one where the arm started.
    stream = np.load(tmp_path / "stream.npz")
    t_set, q_set, closed, glass = stream["t"], stream["q"], stream["gripper"], stream["glass"]
    found = re.search(r"new glass at (\[.*?\]) m", text)
    assert found is not None, text
    np.testing.assert_allclose(glass, json.loads(found.group(1)), atol=5e-5)

    # Offline: the saved skill's reproduction for that glass from the same start, in the bag:
    # the lead-in's samples and then one per step, at the reproduction's times.
    traj = _trajectory(tmp_path / "trajectory")
    skill = Skill.load(tmp_path / "skill.npz")
    res = skill.reproduce({"glass": glass}, q0=q_set[0])
    n_lead = int(np.count_nonzero(res.lead_in))
    assert n_lead == _number(r"offline: (\d+) lead-in points", text) > 0
    assert traj.names == robot.joint_names and traj.q.shape == (skill.n_steps + n_lead, 7)
    _assert_is_reproduction(traj, res)
    assert traj.t[0] == 0.0 and np.all(np.diff(traj.t) > 0)
    assert abs(traj.t[-1] - _number(r"(\d+\.\d+) s\n", text.split("wrote")[-1])) < 0.01
    assert traj.gripper == [False, True]
    assert np.all(robot.within_limits(traj.q, tol=1e-9))
    assert motion_peaks(traj.t, traj.q, limits).worst <= 1.0
    # The printed closest approach is the trajectory's: the hand reaches the new glass.
    closest = np.linalg.norm(robot.fk(traj.q) - glass, axis=1).min()
    assert closest < 0.005
    printed = _number(r"closest approach to the glass: (\d+\.\d) mm", text)
    assert abs(1000 * closest - printed) < 0.06
    assert _number(r"joint space only, the demonstrated postures: (\d+\.\d) mm", text) > 20

    # Online at 1 kHz: what a Panda checks, recomputed from the setpoints (the arm at rest at
    # its start before them and at their last after them). Measured: velocity 0.675,
    # acceleration 0.995, jerk 0.995 (the stream is planned at 0.995 of the limits).
    np.testing.assert_allclose(np.diff(t_set), 0.001, rtol=1e-9)
    # It lasts as long as the offline trajectory (measured: 7 ms longer, the follower's end).
    assert t_set[0] == 0.0 and abs(t_set[-1] - traj.t[-1]) < 0.02
    peaks = motion_peaks(t_set, q_set, limits)
    assert peaks.velocity <= 1.0 and peaks.acceleration <= 1.0 and peaks.jerk <= 1.0
    printed = re.search(
        r"1 kHz stream: velocity (\d\.\d+), acceleration (\d\.\d+), jerk (\d\.\d+)", text
    )
    assert printed is not None, text
    np.testing.assert_allclose(
        [float(x) for x in printed.groups()],
        [peaks.velocity, peaks.acceleration, peaks.jerk],
        atol=1e-3,
    )
    assert count_reversals(q_set, 0.001, limits.velocity) == 0
    # It ends at rest at the skill's last posture (the offline one: same start, same glass).
    np.testing.assert_allclose(q_set[-1], res.joints[-1], atol=1e-9)
    assert np.abs(q_set[-1] - q_set[-2]).max() / 0.001 < 0.01  # rad/s, measured 0.0015
    # The gripper closes once, when the offline one does (within a controller step), with the
    # hand at the glass: measured 0.2 mm.
    assert np.count_nonzero(np.diff(closed.astype(int))) == 1
    grasp = int(np.argmax(closed))
    assert abs(t_set[grasp] - traj.t[np.argmax(res.gripper)]) <= skill.step_seconds
    at_grasp = np.linalg.norm(robot.fk(q_set[grasp]) - glass)
    assert at_grasp < 0.001
    assert (
        abs(1000 * at_grasp - _number(r"closes: (\d+\.\d) mm from the glass online", text)) < 0.06
    )


def test_your_arm(runs: dict[str, tuple[Path, str]]) -> None:
    tmp_path, text = runs["your_arm.py"]
    skill = Skill.load(tmp_path / "skill.npz")  # the robot comes back from the URDF it holds
    robot = skill.robot
    assert robot.joint_names == ["yaw", "shoulder", "elbow", "wrist"]  # type: ignore[attr-defined]
    csvs = sorted(tmp_path.glob("demo*.csv"))
    assert len(csvs) == 5
    demo = demonstration_from_csv(csvs[0], objects={})
    assert demo.n_joints == 4 and demo.gripper is not None
    # The URDF's velocity limits are the arm's only ones: the skill keeps them.
    limits = MotionLimits.from_robot(robot, 4)
    np.testing.assert_array_equal(limits.velocity, [1.5, 1.5, 1.5, 2.0])
    assert np.all(np.isinf(limits.acceleration)) and np.all(np.isinf(limits.jerk))

    traj = _trajectory(tmp_path / "trajectory")
    res = skill.reproduce(_example("your_arm").new_places(robot))
    n_lead = int(np.count_nonzero(res.lead_in))
    assert n_lead == _number(rf"\((\d+) lead-in \+ {skill.n_steps} steps\)", text) > 0
    assert traj.names == robot.joint_names and traj.q.shape == (skill.n_steps + n_lead, 4)
    _assert_is_reproduction(traj, res)
    assert traj.gripper == [False, True, False]
    # At the demonstrations' pace (a step is never shorter), within the velocity limits.
    assert traj.t[0] == 0.0 and np.all(np.diff(traj.t) >= skill.step_seconds - 2e-9)
    assert traj.t[-1] >= skill.duration
    assert motion_peaks(traj.t, traj.q, limits).velocity <= 1.0
    for name in ("cup", "bin"):
        assert _number(rf"closest approach: .*{name} (\d+\.\d) mm", text) < 5.0
    assert _number(r"hand at grasp (\d+\.\d) mm from the cup", text) < 5.0
    assert _number(r"at release (\d+\.\d) mm", text) < 5.0
    # Online, one command per ctrl.dt (= step_seconds) until the arm is at rest at the end: the
    # commands take the trajectory's time, to a step (here 1000 commands, 1001 points).
    commands = _number(r"online: (\d+) commands", text)
    assert abs(commands * skill.step_seconds - traj.t[-1]) <= skill.step_seconds
    assert abs(_number(r"commands every .* \((\d+\.\d+) s\)", text) - traj.t[-1]) < 0.01
