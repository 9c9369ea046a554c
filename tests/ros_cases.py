"""Cases run on a private ROS 2 graph by ``tests/rosgraph.py`` (issue 37), one per command
line: ``python tests/ros_cases.py CASE``. Each prints OK and exits 0, or fails with an
assertion."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import numpy as np

PANDA = [f"panda_joint{i}" for i in range(1, 8)]
FR3 = [f"fr3_joint{i}" for i in range(1, 8)]
POSTURE = np.array([0.1, -0.7, 0.05, -2.3, 0.02, 1.6, 0.8])


def publish_joint_states(seconds: str) -> None:
    """A driver's joint states: franka_ros2's FR3 names, shuffled, a finger joint among them,
    at 100 Hz; then one message without fr3_joint4."""
    import rclpy
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = rclpy.create_node("fake_driver")
    pub = node.create_publisher(JointState, "/joint_states", 10)
    order = [6, 2, 0, 5, 3, 1, 4]
    names = [FR3[i] for i in order] + ["fr3_finger_joint1"]
    positions = [float(POSTURE[i]) for i in order] + [0.04]
    end = time.monotonic() + float(seconds)
    while time.monotonic() < end:
        pub.publish(JointState(name=names, position=positions))
        time.sleep(0.01)
    pub.publish(
        JointState(name=[n for n in names if n != "fr3_joint4"], position=[*positions[:-2], 0.04])
    )
    time.sleep(0.2)
    node.destroy_node()
    rclpy.shutdown()


def joint_states() -> None:
    """The listener, in this process, matches the driver's (another process's) joint states
    to the Panda model's joints through the joint map."""
    import rclpy

    from pbdkit.ros import JointOrder, parse_joint_map
    from pbdkit.ros._graph import JointStateListener

    driver = subprocess.Popen([sys.executable, __file__, "publish_joint_states", "3"])
    rclpy.init()
    node = rclpy.create_node("listener")
    order = JointOrder(
        PANDA, parse_joint_map([f"{p}={f}" for p, f in zip(PANDA, FR3, strict=True)])
    )
    listener = JointStateListener(node, "/joint_states", order)
    start = time.monotonic()
    while listener.q is None and time.monotonic() - start < 10.0:
        rclpy.spin_once(node, timeout_sec=0.05)
    assert listener.q is not None, "no joint states in 10 s"
    first = time.monotonic() - start
    np.testing.assert_array_equal(listener.q, POSTURE)
    assert listener.age() < 0.5
    while driver.poll() is None:  # until the message without fr3_joint4
        rclpy.spin_once(node, timeout_sec=0.05)
    for _ in range(10):
        rclpy.spin_once(node, timeout_sec=0.05)
    assert driver.returncode == 0
    assert listener.error is not None and "fr3_joint4" in listener.error, listener.error
    np.testing.assert_array_equal(listener.q, POSTURE)  # the last good posture is kept
    node.destroy_node()
    rclpy.shutdown()
    print(f"OK: first joint states after {first:.2f} s, {listener.count} messages")


def sim_arm(seconds: str) -> None:
    """The kinematic arm behind a JTC, for ``seconds``; prints what it received."""
    import rclpy

    from pbdkit.ros._sim_arm import SimArm

    rclpy.init()
    node = rclpy.create_node("sim_arm")
    arm = SimArm(node, PANDA, np.zeros(7), interpolate_from_desired_state=True)
    end = time.monotonic() + float(seconds)
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.01)
    print(f"received {arm.received} rejected {len(arm.rejected)} {arm.rejected}")
    node.destroy_node()
    rclpy.shutdown()


def trajectory_to_sim_arm() -> None:
    """A JointTrajectory sent over the graph to the sim arm (another process): its joint states
    follow it to the last point; an empty one is rejected."""
    import rclpy
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from pbdkit.ros import JointOrder
    from pbdkit.ros._graph import JointStateListener

    arm = subprocess.Popen(
        [sys.executable, __file__, "sim_arm", "4"], stdout=subprocess.PIPE, text=True
    )
    rclpy.init()
    node = rclpy.create_node("sender")
    listener = JointStateListener(node, "/joint_states", JointOrder(PANDA))
    pub = node.create_publisher(JointTrajectory, "/arm_controller/joint_trajectory", 10)
    start = time.monotonic()
    while (
        listener.q is None or pub.get_subscription_count() == 0
    ) and time.monotonic() - start < 10:
        rclpy.spin_once(node, timeout_sec=0.05)
    assert listener.q is not None and pub.get_subscription_count() == 1
    np.testing.assert_array_equal(listener.q, np.zeros(7))
    msg = JointTrajectory(joint_names=PANDA[::-1])  # in another order
    for t, scale in ((0.5, 0.5), (1.0, 1.0)):
        msg.points.append(
            JointTrajectoryPoint(
                positions=(scale * POSTURE[::-1]).tolist(),
                velocities=[0.0] * 7,
                time_from_start=Duration(sec=int(t), nanosec=round((t % 1) * 1e9)),
            )
        )
    pub.publish(msg)
    pub.publish(JointTrajectory(joint_names=PANDA))  # empty: rejected, the first goes on
    sent = time.monotonic()
    while time.monotonic() - sent < 1.6:
        rclpy.spin_once(node, timeout_sec=0.02)
    np.testing.assert_allclose(listener.q, POSTURE, atol=1e-12)
    out, _ = arm.communicate(timeout=10)
    assert arm.returncode == 0 and out.startswith("received 1 rejected 1"), out
    assert "empty" in out, out
    node.destroy_node()
    rclpy.shutdown()
    print("OK: the sim arm followed the trajectory; the empty one was rejected")


CASES = {
    "publish_joint_states": publish_joint_states,
    "joint_states": joint_states,
    "sim_arm": sim_arm,
    "trajectory_to_sim_arm": trajectory_to_sim_arm,
}


def katana_arm(seconds: str, q0: str) -> None:
    """The sim arm with the Katana's joints from ``q0`` (comma-separated), for ``seconds``;
    prints the worst v/a/j of its commands over the Katana's limits."""
    import rclpy

    from pbdkit.motion._limits import MotionLimits, motion_peaks
    from pbdkit.robots import katana
    from pbdkit.ros._sim_arm import SimArm

    robot = katana()
    rclpy.init()
    node = rclpy.create_node("katana_arm")
    start = np.array([float(x) for x in q0.split(",")])
    arm = SimArm(node, robot.joint_names, start, interpolate_from_desired_state=True)
    stop: list[int] = []
    signal.signal(signal.SIGUSR1, lambda *_: stop.append(1))  # the test's "enough"
    print("ready", flush=True)  # the launcher starts its side only now (_start_katana_arm)
    end = time.monotonic() + float(seconds)
    while time.monotonic() < end and not stop:
        rclpy.spin_once(node, timeout_sec=0.01)
    s = np.vstack([np.repeat(start[None], 3, axis=0), np.array(arm.commanded)])
    limits = MotionLimits.from_robot(robot, robot.n_joints)
    peaks = motion_peaks(1e-3 * np.arange(len(s)), s, limits, pad_rest=0)
    print(f"worst {peaks.worst:.4f} received {arm.received} rejected {arm.rejected} {peaks}")
    node.destroy_node()
    rclpy.shutdown()


def _start_katana_arm(seconds: int, q0: str) -> subprocess.Popen[str]:
    """The sim arm in another process, returned once it publishes (a loaded machine takes
    seconds to import; a side started meanwhile would time out waiting for it)."""
    arm = subprocess.Popen(
        [sys.executable, __file__, "katana_arm", str(seconds), q0],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert arm.stdout is not None and arm.stdout.readline().strip() == "ready"
    return arm


def run_on_katana_arm() -> None:
    """`pbdkit ros run`'s core on the sim arm (another process): the synthetic glass skill runs
    to its end; the arm ends where the reproduction does, its commands within the limits."""
    import warnings

    import rclpy

    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
    from synthetic_teacher import synthetic_demos, unseen_glass

    from pbdkit import Skill
    from pbdkit.robots import katana
    from pbdkit.ros._run import RunSettings, run_skill

    warnings.simplefilter("ignore")
    robot = katana()
    demos = synthetic_demos(robot, np.random.default_rng(0))
    skill = Skill.learn(demos, robot, n_steps=200, random_state=0)
    glass, _ = unseen_glass(demos)
    q0 = demos[1].joints[0]
    arm = _start_katana_arm(25, ",".join(map(str, q0)))
    rclpy.init()
    node = rclpy.create_node("pbdkit_run")
    code = run_skill(node, skill, {"glass": glass}, RunSettings(timeout=10.0), log=lambda m: None)
    assert code == 0, code
    end = skill.reproduce({"glass": glass}, q0=q0).joints[-1]
    node.destroy_node()
    rclpy.shutdown()
    arm.send_signal(signal.SIGUSR1)
    out, _ = arm.communicate(timeout=10)
    worst = float(out.split()[1])
    assert worst <= 1.0, out
    print(f"OK: ran to its end; commands' worst v/a/j {worst:.3f}; end {end.round(3).tolist()}")


CASES.update({"katana_arm": katana_arm, "run_on_katana_arm": run_on_katana_arm})


def _ros_run(skill_file: str, controller: str) -> tuple[subprocess.CompletedProcess[str], float]:
    """`pbdkit ros run` of the glass skill with a 1.5 s time-out: its outcome and seconds."""
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "pbdkit", "ros", "run", skill_file, "--controller", controller,
         "--object", "glass=0.45,0.2,0.2", "--timeout", "1.5"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    return done, time.monotonic() - start


def cli_no_arm(skill_file: str) -> None:
    """`pbdkit ros run` with no arm on the graph: exit 3 (no joint states) within the time-out."""
    done, took = _ros_run(skill_file, "arm_controller")
    assert done.returncode == 3, (done.returncode, done.stdout, done.stderr)
    assert "no joint states on /joint_states in 1.5 s" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and took < 10, took
    print(f"OK: exit 3 after {took:.1f} s")


def cli_no_controller(skill_file: str) -> None:
    """`pbdkit ros run` with an arm publishing joint states but no such controller: exit 4."""
    q0 = "1.5,1.8,-1.2,-1.6,0.1"
    arm = _start_katana_arm(20, q0)
    done, took = _ros_run(skill_file, "nobody")
    arm.send_signal(signal.SIGUSR1)
    arm.communicate(timeout=10)
    assert done.returncode == 4, (done.returncode, done.stdout, done.stderr)
    assert "nothing subscribes to /nobody/joint_trajectory" in done.stderr, done.stderr
    print(f"OK: exit 4 after {took:.1f} s")


CASES.update({"cli_no_arm": cli_no_arm, "cli_no_controller": cli_no_controller})


if __name__ == "__main__":
    case, *rest = sys.argv[1:]
    CASES[case](*rest)
