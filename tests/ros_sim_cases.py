"""Cases of ``pbdkit ros sim`` run on a private ROS 2 graph by ``tests/rosgraph.py`` (issue 37),
one per command line: ``python tests/ros_sim_cases.py CASE ARGS``. Each starts ``pbdkit ros sim``
in another process, talks to it over the graph, and prints OK or fails with an assertion."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

SIM = [sys.executable, "-m", "pbdkit", "ros", "sim"]
KATANA = ["pan", "lift1", "lift2", "lift3", "wrist_roll"]


class Graph:
    """A tester's node: every joint state and object pose it hears (with its header stamp,
    s), publishers of the arm's and the gripper's trajectories."""

    def __init__(self, objects: tuple[str, ...] = ("glass", "coaster")) -> None:
        import rclpy
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        rclpy.init()
        self.node = rclpy.create_node("tester")
        self.states: list[tuple[float, float, dict[str, float]]] = []  # (stamp, heard, q)
        self.poses: dict[str, list[tuple[float, np.ndarray, str]]] = {k: [] for k in objects}
        self.node.create_subscription(JointState, "/joint_states", self._on_state, 50)
        for name in objects:
            self.node.create_subscription(
                PoseStamped, f"/objects/{name}", lambda m, n=name: self._on_pose(n, m), 50
            )
        self.arm = self.node.create_publisher(
            JointTrajectory, "/arm_controller/joint_trajectory", 10
        )
        self.gripper = self.node.create_publisher(
            JointTrajectory, "/gripper_controller/joint_trajectory", 10
        )

    def _on_state(self, msg: Any) -> None:
        q = dict(zip(msg.name, msg.position, strict=True))
        self.states.append((_seconds(msg.header.stamp), time.monotonic(), q))

    def _on_pose(self, name: str, msg: Any) -> None:
        p = msg.pose.position
        self.poses[name].append(
            (_seconds(msg.header.stamp), np.array([p.x, p.y, p.z]), msg.header.frame_id)
        )

    def spin(self, seconds: float) -> None:
        import rclpy

        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.01)

    def wait(self, ready: Callable[[], bool], timeout: float, what: str) -> float:
        """Spin until ``ready()``; its seconds. Fails after ``timeout``."""
        import rclpy

        start = time.monotonic()
        while not ready():
            assert time.monotonic() - start < timeout, f"{what} not within {timeout} s"
            rclpy.spin_once(self.node, timeout_sec=0.01)
        return time.monotonic() - start

    def q(self) -> np.ndarray:
        """The latest arm joints (Katana order)."""
        return np.array([self.states[-1][2][k] for k in KATANA])

    def close(self) -> None:
        import rclpy

        self.node.destroy_node()
        rclpy.shutdown()


def _seconds(stamp: Any) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def _trajectory(
    names: list[str], times: list[float], positions: list[list[float]], velocities: bool
) -> Any:
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    msg = JointTrajectory(joint_names=names)
    for t, p in zip(times, positions, strict=True):
        point = JointTrajectoryPoint(
            positions=[float(x) for x in p],
            time_from_start=Duration(sec=int(t), nanosec=round((t % 1) * 1e9)),
        )
        if velocities:
            point.velocities = [0.0] * len(names)
        msg.points.append(point)
    return msg


def follow(report_path: str) -> None:
    """`pbdkit ros sim --exit-after-run`: a trajectory with the joints in another order is
    followed to its last point, an empty one rejected, the gripper's closes the gripper; the
    objects are placement 0's, in base_link; 1 s after the end the run is judged (a failure:
    the glass is not on the coaster), the report written, exit 1."""
    from pbdkit.ros._task_world import start_posture
    from pbdkit.ros._teach_replay import placement_objects
    from pbdkit.sim import get_task

    launched = time.monotonic()
    sim = subprocess.Popen(
        [*SIM, "--exit-after-run", "--report", report_path], stdout=subprocess.PIPE, text=True
    )
    graph = Graph()
    try:
        up = graph.wait(
            lambda: (
                bool(graph.states)
                and all(graph.poses.values())
                and graph.arm.get_subscription_count() > 0
                and graph.gripper.get_subscription_count() > 0
            ),
            30.0,
            "joint states, object poses and the controllers",
        )
        q0 = start_posture()
        np.testing.assert_allclose(graph.q(), q0, atol=1e-3)
        assert graph.states[-1][2]["gripper"] == 0.0
        truth = placement_objects(get_task("coaster"), 0, 0)
        for name, heard in graph.poses.items():
            _, p, frame = heard[-1]
            assert frame == "base_link", frame
            np.testing.assert_allclose(p, truth[name], atol=2e-3)
        q1 = q0 + np.array([0.2, -0.1, 0.1, 0.1, 0.2])
        back = KATANA[::-1]
        mid = 0.5 * (q0 + q1)
        graph.arm.publish(
            _trajectory(back, [0.5, 1.0], [mid[::-1].tolist(), q1[::-1].tolist()], True)
        )
        graph.arm.publish(_trajectory(KATANA, [], [], False))  # empty: rejected, the first goes on
        graph.gripper.publish(_trajectory(["gripper"], [0.3], [[1.0]], False))
        graph.spin(1.8)
        np.testing.assert_allclose(graph.q(), q1, atol=2e-3)
        assert graph.states[-1][2]["gripper"] == 1.0
        out, _ = sim.communicate(timeout=15)
    finally:
        if sim.poll() is None:
            sim.kill()
        graph.close()
    took = time.monotonic() - launched
    assert sim.returncode == 1, (sim.returncode, out)
    lines = out.splitlines()
    assert lines[0].startswith("ros sim: coaster placement 0 (seed 0), perturb none; publishing "
                               "/joint_states, /objects/glass, /objects/coaster; following "
                               "/arm_controller/joint_trajectory"), lines[0]  # fmt: skip
    assert lines[-1].startswith("run: failure (placement_error_mm"), lines[-1]
    report = json.loads(Path(report_path).read_text())
    assert report["success"] is False and report["perturb"] == {"name": "none"}, report
    assert report["messages"] == {
        "arm": {"accepted": 1, "rejected": 1},
        "gripper": {"accepted": 1, "rejected": 0},
    }, report["messages"]
    assert report["placement"] == {k: v.tolist() for k, v in truth.items()}
    assert abs(report["judged_s"] - report["trajectory_end_s"] - 1.0) < 0.003, report
    print(f"OK: up (joint states, poses, controllers) {up:.2f} s after the launch; ran "
          f"{took:.1f} s; {lines[-1]}")  # fmt: skip


def teach(report_path: str) -> None:
    """`pbdkit ros sim --teach --takes 2 --teach-speed 3 --time-scale 12`: two takes, each the
    arm at rest at its first posture 1.5 s, moving through the teacher's demonstration, at rest
    after it; the objects those of placements 0 and 1; the stamps the world's time."""
    from pbdkit.ros._teach_replay import TeacherReplay
    from pbdkit.sim import get_task

    launched = time.monotonic()
    args = ["--teach", "--takes", "2", "--teach-speed", "3", "--time-scale", "12"]
    sim = subprocess.Popen(
        [*SIM, *args, "--exit-after-run", "--report", report_path],
        stdout=subprocess.PIPE,
        text=True,
    )
    graph = Graph()
    replay = TeacherReplay(get_task("coaster"), 0, 2, 3.0)  # what it replays
    try:
        graph.wait(lambda: sim.poll() is not None, 60.0, "the end of the takes")
        out = sim.stdout.read() if sim.stdout else ""
    finally:
        if sim.poll() is None:
            sim.kill()
        graph.close()
    took = time.monotonic() - launched
    assert sim.returncode == 0, (sim.returncode, out)
    report = json.loads(Path(report_path).read_text())
    assert report["teach_done"] is True and len(report["takes"]) == 2, report
    assert [t["start_s"] for t in report["takes"]] == [t.start for t in replay.takes]
    take0, take1 = replay.takes
    # The world's time of the stamps: the glass is first seen at placement 1 when take 1 begins.
    glass = graph.poses["glass"]
    first = next(s for s, p, _ in glass if np.linalg.norm(p - take1.objects["glass"]) < 2e-3)
    stamp0 = first - take1.start
    states = [
        (s - stamp0, np.array([q[k] for k in KATANA]), q["gripper"]) for s, _, q in graph.states
    ]
    poses = [(s - stamp0, p) for s, p, _ in glass]

    def at(lo: float, hi: float) -> list[np.ndarray]:
        got = [q for t, q, _ in states if lo <= t <= hi]
        assert len(got) > 5, (lo, hi, len(got))
        return got

    # A subscriber sees the first take whole: the world waits SUBSCRIBER_GRACE after it came.
    assert states[0][0] <= take0.start, states[0][0]
    for take in (take0, take1):
        demo = take.demo
        rest = at(take.start + 0.1, take.motion_start - 0.05)
        assert max(float(np.abs(q - demo.joints[0]).max()) for q in rest) < 1e-3
        moving = at(take.motion_start + 1.0, take.motion_end - 1.0)
        assert max(float(np.abs(q - demo.joints[0]).max()) for q in moving) > 0.3
        after = at(take.motion_end + 1.5, take.end - 0.1)
        assert max(float(np.abs(q - demo.joints[-1]).max()) for q in after) < 2e-2
        assert any(g == 1.0 for t, _, g in states if take.motion_start <= t <= take.motion_end)
        seen = [p for t, p in poses if take.start <= t <= take.motion_start]
        assert seen and all(np.linalg.norm(p - take.objects["glass"]) < 2e-3 for p in seen)
    moved = float(np.linalg.norm(take1.objects["glass"] - take0.objects["glass"]))
    assert moved > 0.01, moved
    world = replay.end
    print(f"OK: two takes, {world:.1f} s of world in {took:.1f} s (launch included); the glass "
          f"moved {100 * moved:.1f} cm between them")  # fmt: skip


CASES = {"follow": follow, "teach": teach}


if __name__ == "__main__":
    case, *rest = sys.argv[1:]
    CASES[case](*rest)
