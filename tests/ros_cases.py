"""Cases run on a private ROS 2 graph by ``tests/rosgraph.py`` (issue 37), one per command
line: ``python tests/ros_cases.py CASE``. Each prints OK and exits 0, or fails with an
assertion."""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

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
        [sys.executable, __file__, "sim_arm", "8"], stdout=subprocess.PIPE, text=True
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
    # The trajectory lasts 1 s from its arrival; on a loaded machine it may arrive late, so the
    # wait ends when the arm is there (or after 6 s, and the assertion says where it stopped).
    sent = time.monotonic()
    while time.monotonic() - sent < 6.0 and not np.allclose(
        listener.q, POSTURE, rtol=0.0, atol=1e-12
    ):
        rclpy.spin_once(node, timeout_sec=0.02)
    np.testing.assert_allclose(listener.q, POSTURE, atol=1e-12)
    for _ in range(10):  # the arm holds the last point
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


RENAMED = {"pan": "k_pan", "lift1": "k_lift1", "lift2": "k_lift2", "lift3": "k_lift3",
           "wrist_roll": "k_wrist"}  # fmt: skip
SHUFFLE = [2, 0, 4, 1, 3]


def katana_arm(seconds: str, q0: str, options: str = "") -> None:
    """The sim arm with the Katana's joints from ``q0`` (comma-separated), for ``seconds``;
    prints the worst v/a/j of its commands over the Katana's limits and its commands' last
    speed. ``options``: ``renamed`` (the joints named otherwise, in another order, a finger
    joint among them), ``lag`` (its joints lag the commands, 0.5 s)."""
    import rclpy

    from pbdkit.motion._limits import MotionLimits, motion_peaks
    from pbdkit.robots import katana
    from pbdkit.ros._sim_arm import SimArm

    robot = katana()
    rclpy.init()
    node = rclpy.create_node("katana_arm")
    start = np.array([float(x) for x in q0.split(",")])
    names, order, extra = list(robot.joint_names), list(range(5)), {}
    if "renamed" in options:
        names, order = [RENAMED[robot.joint_names[i]] for i in SHUFFLE], SHUFFLE
        extra = {"k_finger": 0.01}
    arm = SimArm(
        node, names, start[order], interpolate_from_desired_state=True, extra_joints=extra,
        lag=0.5 if "lag" in options else 0.0,
    )  # fmt: skip
    hand = None
    if "gripper" in options:  # a gripper behind its own controller, its states apart
        hand = SimArm(node, ["k_gripper"], [0.0], controller="gripper_controller")
    stop: list[int] = []
    signal.signal(signal.SIGUSR1, lambda *_: stop.append(1))  # the test's "enough"
    print("ready", flush=True)  # the launcher starts its side only now (_start_katana_arm)
    end = time.monotonic() + float(seconds)
    while time.monotonic() < end and not stop:
        rclpy.spin_once(node, timeout_sec=0.01)
    s = np.vstack([np.repeat(start[order][None], 3, axis=0), np.array(arm.commanded)])
    s = s[:, np.argsort(order)]  # the Katana's order
    limits = MotionLimits.from_robot(robot, robot.n_joints)
    peaks = motion_peaks(1e-3 * np.arange(len(s)), s, limits, pad_rest=0)
    speed = float(np.abs(s[-1] - s[-2]).max() / 1e-3)
    grip = "" if hand is None else f" gripper {max(float(g[0]) for g in hand.commanded):.2f}"
    va = max(peaks.velocity, peaks.acceleration)
    print(f"worst {peaks.worst:.4f} last_speed {speed:.2e} va {va:.4f} "
          f"end {s[-1].round(4).tolist()} "
          f"received {arm.received} rejected {arm.rejected}{grip} {peaks}")  # fmt: skip
    node.destroy_node()
    rclpy.shutdown()


def _start_katana_arm(seconds: int, q0: str, options: str = "") -> subprocess.Popen[str]:
    """The sim arm in another process, returned once it publishes (a loaded machine takes
    seconds to import; a side started meanwhile would time out waiting for it)."""
    arm = subprocess.Popen(
        [sys.executable, __file__, "katana_arm", str(seconds), q0, options],
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


def _ros_run(
    skill_file: str, controller: str, timeout: float = 1.5
) -> tuple[subprocess.CompletedProcess[str], float]:
    """`pbdkit ros run` of the glass skill with a time-out: its outcome and seconds."""
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "pbdkit", "ros", "run", skill_file, "--controller", controller,
         "--object", "glass=0.45,0.2,0.2", "--timeout", str(timeout)],
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
    # Fast DDS finds a node that joins after the arm's first announcements in up to 2-3 s
    # (measured: 0.15-2.1 s): a time-out of 4 s for it to see the joint states.
    done, took = _ros_run(skill_file, "nobody", timeout=4.0)
    arm.send_signal(signal.SIGUSR1)
    arm.communicate(timeout=10)
    assert done.returncode == 4, (done.returncode, done.stdout, done.stderr)
    assert "nothing subscribes to /nobody/joint_trajectory" in done.stderr, done.stderr
    assert took < 12, took
    print(f"OK: exit 4 after {took:.1f} s")


CASES.update({"cli_no_arm": cli_no_arm, "cli_no_controller": cli_no_controller})


def publish_pose(topic: str, xyz: str, moved: str) -> None:
    """A tracker's PoseStamped on ``topic`` at 15 Hz, at ``xyz``; at ``moved`` from SIGUSR1 on;
    until SIGTERM."""
    import rclpy
    from geometry_msgs.msg import PoseStamped

    rclpy.init()
    node = rclpy.create_node("tracker")
    pub = node.create_publisher(PoseStamped, topic, 10)
    where = [[float(v) for v in xyz.split(",")]]
    signal.signal(signal.SIGUSR1, lambda *_: where.append([float(v) for v in moved.split(",")]))
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    while True:
        msg = PoseStamped()
        msg.header.frame_id = "base_link"
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = where[-1]
        msg.pose.orientation.w = 1.0
        pub.publish(msg)
        time.sleep(1 / 15)


def _glass_setup(skill_file: str) -> tuple[Any, np.ndarray, str]:
    """The synthetic glass skill, a glass none of its demonstrations had, its start posture."""
    import warnings

    sys.path.insert(0, str(Path(__file__).parent))
    from synthetic_teacher import synthetic_demos, unseen_glass

    from pbdkit import Skill
    from pbdkit.robots import katana

    warnings.simplefilter("ignore")
    demos = synthetic_demos(katana(), np.random.default_rng(0))
    glass, _ = unseen_glass(demos)
    return Skill.load(skill_file), glass, ",".join(map(str, demos[1].joints[0]))


def _csv(v: Any) -> str:
    return ",".join(f"{float(x):.6f}" for x in v)


def _stop_arm(arm: subprocess.Popen[str]) -> dict[str, Any]:
    """Stop the sim arm; what it printed: worst v/a/j, the commands' last speed, end."""
    arm.send_signal(signal.SIGUSR1)
    out, _ = arm.communicate(timeout=10)
    words = out.split()
    got = {"worst": float(words[1]), "last_speed": float(words[3]), "va": float(words[5]),
           "out": out}  # fmt: skip
    if " gripper " in out:
        got["gripper"] = float(out.split(" gripper ")[1].split()[0])
    return got


#: The CLI cases that check the commands' limits run with ``--latency 0.3``: without it a
#: message sent while the arm moves starts when the JTC takes it (header stamp 0), and the
#: segment to its first point absorbs the graph's latency, which no bound holds on a loaded
#: machine (docs/ros2.md: up to 1.97x the acceleration limit; cli_sigint unstamped reached
#: 1.24x and 5.2x the jerk on a clean-clone CI run, session 25, after 1.01x before).
#: With ``--latency 0.3`` the jerk (over the limit) a run's commands may reach: 0.60-0.75 with
#: up to one busy loop beside the test, 1.0-1.8 with two on two cores (a message then taken
#: after its hand-over, session 24); velocity and acceleration stay within the limits.
STAMPED_JERK_BOUND = 2.0


def _stamped_ok(got: dict) -> bool:
    """The sim arm's commands (``_stop_arm``) of a run with ``--latency`` (each message starts
    where the run planned it, whatever the graph's latency): velocity and acceleration within
    the limits, the jerk within :data:`STAMPED_JERK_BOUND`."""
    return bool(got["va"] <= 1.0 and got["worst"] <= STAMPED_JERK_BOUND)


def _cli(skill_file: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pbdkit", "ros", "run", skill_file, "--controller",
         "arm_controller", "--timeout", "5", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def _wait_for_line(proc: subprocess.Popen[str], start: str, lines: list[str]) -> None:
    """Read ``proc``'s stdout into ``lines`` until a line starts with ``start``."""
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if line.startswith(start):
            return
    raise AssertionError(f"no line {start!r}: {lines} {proc.stderr and proc.stderr.read()}")


def cli_topics_renamed_gripper(skill_file: str) -> None:
    """`pbdkit ros run` with the glass from a PoseStamped topic that moves mid-run, joint
    states under other names in another order with an extra joint (--joint-map), and the
    gripper behind its own controller: the run re-plans, closes the gripper, ends at rest
    (exit 0), its commands within the limits."""
    _, glass, q0 = _glass_setup(skill_file)
    arm = _start_katana_arm(60, q0, "renamed,gripper")
    moved = glass + np.array([0.0, 0.03, 0.0])
    pose = subprocess.Popen(
        [sys.executable, __file__, "publish_pose", "/objects/glass", _csv(glass), _csv(moved)]
    )
    maps = [f"--joint-map={k}={v}" for k, v in RENAMED.items()]
    cli = _cli(skill_file, "--object", "glass=/objects/glass", "--grasped", "glass",
               "--gripper-controller", "gripper_controller", "--gripper-joint", "k_gripper:0:1",
               "--latency", "0.3", *maps)  # fmt: skip
    lines: list[str] = []
    _wait_for_line(cli, "running", lines)
    time.sleep(0.5)
    pose.send_signal(signal.SIGUSR1)  # the glass moves 3 cm, before the grasp
    out, err = cli.communicate(timeout=60)
    pose.terminate()
    pose.wait(timeout=10)
    got = _stop_arm(arm)
    text = "".join(lines) + out
    assert cli.returncode == 0, (cli.returncode, text, err)
    assert "re-planned" in text and f"{moved[1]:.3f}"[:-1] in text, text
    assert _stamped_ok(got), got
    assert got.get("gripper") == 1.0, got
    print(f"OK: re-planned, gripper closed, worst v/a/j {got['worst']:.3f}")


def cli_sigint(skill_file: str) -> None:
    """SIGINT mid-run: the arm is brought to rest within its limits, then exit 130."""
    _, glass, q0 = _glass_setup(skill_file)
    arm = _start_katana_arm(60, q0)
    cli = _cli(skill_file, "--object", f"glass={_csv(glass)}", "--latency", "0.3")
    lines: list[str] = []
    _wait_for_line(cli, "running", lines)
    time.sleep(1.5)
    cli.send_signal(signal.SIGINT)
    out, err = cli.communicate(timeout=30)
    time.sleep(1.0)  # the brake runs out on the arm
    got = _stop_arm(arm)
    assert cli.returncode == 130, (cli.returncode, out, err)
    assert "braking" in out, out
    assert _stamped_ok(got), got
    assert got["last_speed"] < 1e-6, got
    print(f"OK: exit 130, at rest, worst v/a/j {got['worst']:.3f}")


def cli_arm_dies(skill_file: str) -> None:
    """The robot side dies mid-run: exit 3 within 1 s after the staleness bound (0.2 s)."""
    _, glass, q0 = _glass_setup(skill_file)
    arm = _start_katana_arm(60, q0)
    cli = _cli(skill_file, "--object", f"glass={_csv(glass)}")
    lines: list[str] = []
    _wait_for_line(cli, "running", lines)
    time.sleep(1.0)
    arm.kill()
    killed = time.monotonic()
    out, err = cli.communicate(timeout=30)
    took = time.monotonic() - killed
    assert cli.returncode == 3, (cli.returncode, out, err)
    assert "joint states on /joint_states are" in err and took < 0.2 + 1.0, (took, err)
    print(f"OK: exit 3 {took:.2f} s after the arm died")


def cli_following_error(skill_file: str) -> None:
    """An arm that lags its commands (0.5 s): exit 5, after braking."""
    _, glass, q0 = _glass_setup(skill_file)
    arm = _start_katana_arm(60, q0, "lag")
    cli = _cli(skill_file, "--object", f"glass={_csv(glass)}")
    out, err = cli.communicate(timeout=60)
    _stop_arm(arm)
    assert cli.returncode == 5, (cli.returncode, out, err)
    assert "following error" in err and "braking" in out, (out, err)
    print("OK: exit 5")


def cli_scene(skill_file: str, workdir: str) -> None:
    """`pbdkit ros run --scene` with a crate over the glass: the plan would take the gripper
    into it, so nothing is sent (the arm receives no message) and the exit code is 6; with a
    crate far away the run goes to its end (exit 0)."""
    from pbdkit.collision import Box, Scene

    _, glass, q0 = _glass_setup(skill_file)
    arm = _start_katana_arm(60, q0)
    crate = Path(workdir) / "crate.yaml"
    Scene([Box((0.12, 0.12, 0.12), glass, name="crate")]).save(crate)
    cli = _cli(skill_file, "--object", f"glass={_csv(glass)}", "--scene", str(crate))
    out, err = cli.communicate(timeout=60)
    got = _stop_arm(arm)
    assert cli.returncode == 6, (cli.returncode, out, err)
    assert "the plan would collide, nothing sent" in err and "crate" in err, err
    assert " received 0 " in got["out"], got["out"]
    arm = _start_katana_arm(60, q0)
    far = Path(workdir) / "far.yaml"
    Scene([Box((0.12, 0.12, 0.12), glass + np.array([0.0, 0.0, 0.8]), name="far")]).save(far)
    cli = _cli(skill_file, "--object", f"glass={_csv(glass)}", "--scene", str(far))
    out, err = cli.communicate(timeout=60)
    got = _stop_arm(arm)
    assert cli.returncode == 0, (cli.returncode, out, err)
    assert "scene: the plan keeps" in out and "done: at rest" in out, out
    print(f"OK: exit 6, nothing sent; with a far crate exit 0, {got['out'].split()[9]} messages")


CASES.update(
    {
        "cli_scene": cli_scene,
        "publish_pose": publish_pose,
        "cli_topics_renamed_gripper": cli_topics_renamed_gripper,
        "cli_sigint": cli_sigint,
        "cli_arm_dies": cli_arm_dies,
        "cli_following_error": cli_following_error,
    }
)


def _pbdkit(*args: str, **kw: Any) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pbdkit", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, **kw,
    )  # fmt: skip


COASTER_OBJECTS = ["--object", "glass=/objects/glass", "--object", "coaster=/objects/coaster"]
#: An object's place in a ``put ...`` line of `pbdkit ros record --suggest`.
PLACED = re.compile(r"(\w+) at \((-?[\d.]+), (-?[\d.]+), (-?[\d.]+)\)")
UNCERTAINTY = re.compile(r"\(uncertainty ([\d.]+|inf)\)")


def _teacher(takes: int, seed: int) -> subprocess.Popen[str]:
    """`pbdkit ros sim --teach` (10x real time), the teacher's placements and motions of
    ``seed``: its takes begin when a recorder subscribes."""
    return _pbdkit("ros", "sim", "--task", "coaster", "--teach", "--takes", str(takes),
                   "--seed", str(seed), "--time-scale", "10")  # fmt: skip


def _recorder(demos: Path, takes: int, *extra: str) -> subprocess.Popen[str]:
    """`pbdkit ros record --auto`, ``takes`` takes into ``demos``."""
    return _pbdkit("ros", "record", "--out", str(demos), "--takes", str(takes), "--auto",
                   *COASTER_OBJECTS, "--gripper-joint", "gripper:0:1", "--timeout", "15",
                   *extra)  # fmt: skip


def _recorded(
    teach: subprocess.Popen[str], rec: subprocess.Popen[str], takes: int, said: str = ""
) -> str:
    """Wait for the recorder (its output so far: ``said``), stop the teacher; all it said."""
    out, err = rec.communicate(timeout=120)
    teach.terminate()
    teach.communicate(timeout=10)
    said += out
    assert rec.returncode == 0 and f"{takes} take(s) recorded" in said, (rec.returncode, said, err)
    return said


def _check_whole_takes(demos: Path, teachers: list[tuple[int, int]]) -> None:
    """Each take in ``demos`` holds the whole of the teacher's demonstration it recorded
    (``teachers``: (seed, takes) of each `pbdkit ros sim --teach`, in order): from its first
    posture to its last (within 0.05 rad), the gripper closing when the teacher closed it (within
    0.5 s of the take's start; the recorder keeps up to PRE_ROLL = 0.3 s before the motion).
    A recorder that stopped reading the graph while it saved a take or updated the skill began
    the next take 1.4-1.9 s into its motion (0.6-1.2 rad from its first posture), its gripper
    closing 0.5-0.7 s late (the states read late took the gripper's latest opening)."""
    from pbdkit import load_demonstrations
    from pbdkit.ros._teach_replay import TeacherReplay
    from pbdkit.sim import get_task

    spec = get_task("coaster")
    taught = [take.demo for seed, n in teachers for take in TeacherReplay(spec, seed, n).takes]
    recorded = load_demonstrations(demos)
    assert len(recorded) == len(taught), (len(recorded), len(taught))

    def grasp(d: Any) -> float:
        return float(d.t[int(np.argmax(d.gripper > 0.5))] - d.t[0])

    for k, (got, want) in enumerate(zip(recorded, taught, strict=True)):
        first = float(np.abs(got.joints[0] - want.joints[0]).max())
        last = float(np.abs(got.joints[-1] - want.joints[-1]).max())
        late = grasp(got) - grasp(want)
        assert first < 0.05 and last < 0.05 and abs(late) < 0.5, (k, first, last, late)


def _record_suggested(teach: subprocess.Popen[str], demos: Path, skill: Path, takes: int) -> None:
    """`pbdkit ros record --suggest SKILL` over ``takes`` more takes of ``teach`` (the teacher
    of seed 1: placements and motions the skill has not seen). It places the objects itself,
    it does not follow the suggestions: this checks the record/update loop. Before each take
    a line ``put ...`` names every object's place, the skill's first suggestion then (within
    the 3 decimals printed) inside the default ranges of the skill it began with; after each
    take the skill file loads and holds one more demonstration, the take that was appended
    to ``demos``; the uncertainty printed is the suggestion's; the suggestion before the second
    take is not the first one (its place, or its uncertainty: the teacher does not put the
    objects where it says, so the best place to cover may stay where it was). The files are
    copied as each take leaves them and checked once the takes are done (loading them
    meanwhile would take the recorder's CPU)."""
    from pbdkit import Skill, load_demonstrations
    from pbdkit.apps._cli_suggest import default_ranges

    copies = [(skill.with_suffix(".0.npz"), demos.with_suffix(".0.npz"))]
    for src, dst in zip((skill, demos), copies[0], strict=True):
        shutil.copy(src, dst)
    rec = _recorder(demos, takes, "--suggest", str(skill))
    assert rec.stdout is not None
    lines: list[str] = []
    for line in rec.stdout:
        lines.append(line)
        if " updated: learned from " in line:  # both files are written before this line
            k = len(copies)
            copies.append((skill.with_suffix(f".{k}.npz"), demos.with_suffix(f".{k}.npz")))
            for src, dst in zip((skill, demos), copies[k], strict=True):
                shutil.copy(src, dst)
    said = _recorded(teach, rec, takes, "".join(lines))
    puts = [i for i, line in enumerate(lines) if line.startswith("put ")]
    starts = [lines.index(f"take {k}: recording\n") for k in range(1, takes + 1)]
    assert len(puts) == len(copies) == takes + 1, said
    # a suggestion before each take, one after the last (for the next session)
    assert [i in puts for i in sorted(puts + starts)] == [True, False] * takes + [True], said
    began = Skill.load(copies[0][0])
    first, ranges = len(began.demonstrations_ or []), default_ranges(began)
    placed, scores = [], []
    for k, (skill_k, demos_k) in enumerate(copies):
        learned, recorded = Skill.load(skill_k), load_demonstrations(demos_k)
        assert learned.demonstrations_ is not None
        assert len(learned.demonstrations_) == len(recorded) == first + k, (k, said)
        if k:  # the take: the last of --out and the last the skill learned
            np.testing.assert_array_equal(recorded[-1].t, learned.demonstrations_[-1].t)
            np.testing.assert_array_equal(recorded[-1].joints, learned.demonstrations_[-1].joints)
        put = {m[1]: np.array(m.groups()[1:], dtype=float) for m in PLACED.finditer(lines[puts[k]])}
        assert sorted(put) == sorted(learned.object_names), lines[puts[k]]
        best = learned.suggest(ranges)[0]
        for name, where in put.items():
            np.testing.assert_allclose(where, best.objects[name], atol=6e-4, err_msg=lines[puts[k]])
        score = UNCERTAINTY.search(lines[puts[k]])
        assert score is not None, lines[puts[k]]
        assert abs(float(score[1]) - best.score) <= 0.0051, (lines[puts[k]], best.score)
        placed.append(np.concatenate([put[name] for name in sorted(put)]))
        scores.append(float(score[1]))
    moved = np.abs(placed[1] - placed[0]).max() > 1e-3
    assert moved or scores[1] != scores[0], (lines[puts[0]], lines[puts[1]])


def coaster_round_trip(workdir: str, takes: str = "3", suggested: str = "2",
                       placement: str = "5") -> None:  # fmt: skip
    """`pbdkit ros sim --teach` replays the teacher and `pbdkit ros record --auto` records
    ``takes``; `pbdkit learn` learns them; `pbdkit ros record --suggest` records
    ``suggested`` more, updating the skill after each (:func:`_record_suggested`); `pbdkit
    ros sim --perturb move` and `pbdkit ros run` (two processes) run the updated skill on a
    new placement with the coaster moved while the glass is carried: the sim judges it a
    success, and every command it received is within the limits."""
    work = Path(workdir)
    demos, skill, report = work / "demos.npz", work / "skill.npz", work / "report.json"
    _recorded(_teacher(int(takes), 0), _recorder(demos, int(takes)), int(takes))
    # While it learns: the next teacher starts (it waits for a recorder), _record_suggested
    # imports what it checks with.
    teach = _teacher(int(suggested), 1)
    learn = _pbdkit("learn", str(demos), "--out", str(skill))
    import pbdkit.apps._cli_suggest  # noqa: F401

    lo, le = learn.communicate(timeout=120)
    assert learn.returncode == 0, (lo, le)
    _record_suggested(teach, demos, skill, int(suggested))
    _check_whole_takes(demos, [(0, int(takes)), (1, int(suggested))])
    sim = _pbdkit("ros", "sim", "--task", "coaster", "--placement", placement, "--perturb",
                  "move", "--skill", str(skill), "--exit-after-run", "--report", str(report),
                  "--interpolate-from-desired-state")  # fmt: skip
    lines: list[str] = []
    _wait_for_line(sim, "ros sim:", lines)
    run = _pbdkit("ros", "run", str(skill), "--controller", "arm_controller", *COASTER_OBJECTS,
                  "--grasped", "glass", "--gripper-controller", "gripper_controller",
                  "--gripper-joint", "gripper:0:1", "--timeout", "15",
                  "--latency", "0.3")  # fmt: skip
    ro, re_ = run.communicate(timeout=120)
    so, se = sim.communicate(timeout=60)
    got = json.loads(report.read_text())
    assert run.returncode == 0, (run.returncode, ro, re_, so, se)
    assert sim.returncode == 0 and got["success"], (so, se, got, ro)
    assert got["perturb"]["name"] == "move" and "re-planned" in ro, (got["perturb"], ro)
    # --latency 0.3: each message stamped, the re-plans taking over 0.3 s after they are sent,
    # so that the sim's JTC starts each where the run planned it: velocity and acceleration
    # within the limits, the jerk within STAMPED_JERK_BOUND (0.55-0.75 of the acceleration,
    # 0.60-0.64 of the jerk, with a busy loop beside it; unstamped its splices reached 1.23 x
    # the acceleration limit and 14.7 x the jerk).
    assert got["peak_velocity_ratio"] <= 1.0, got
    assert got["peak_acceleration_ratio"] <= 1.0, got
    assert got["peak_jerk_ratio"] <= STAMPED_JERK_BOUND, got
    print(f"OK: success; worst v/a/j received {got['peak_velocity_ratio']:.3f}/"
          f"{got['peak_acceleration_ratio']:.3f}/{got['peak_jerk_ratio']:.3f}")  # fmt: skip


CASES["coaster_round_trip"] = coaster_round_trip

KATANA = ["pan", "lift1", "lift2", "lift3", "wrist_roll"]


def moving_katana(seconds: str) -> None:
    """A driver's Katana joint states at 100 Hz, stamped with its clock, the pan joint
    sweeping slowly, for ``seconds``."""
    import rclpy
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = rclpy.create_node("katana_driver")
    pub = node.create_publisher(JointState, "/joint_states", 10)
    start = time.monotonic()
    while (elapsed := time.monotonic() - start) < float(seconds):
        msg = JointState(name=KATANA, position=[0.1 * elapsed, 1.2, -1.8, -0.5, 0.0])
        msg.header.stamp = node.get_clock().now().to_msg()
        pub.publish(msg)
        time.sleep(0.01)
    node.destroy_node()
    rclpy.shutdown()


def _wait_for_text(proc: subprocess.Popen[str], text: str, lines: list[str]) -> None:
    """Read ``proc``'s stdout into ``lines`` until a line holds ``text``."""
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if text in line:
            return
    raise AssertionError(f"no line with {text!r}: {lines}")


def record_on_enter(workdir: str) -> None:
    """`pbdkit ros record` without --auto: Enter starts and stops each take. Two takes of
    about 1.0 s and 0.6 s, timed by the joint states' stamps."""
    demos = Path(workdir) / "demos.npz"
    driver = subprocess.Popen([sys.executable, __file__, "moving_katana", "30"])
    rec = subprocess.Popen(
        [sys.executable, "-m", "pbdkit", "ros", "record", "--out", str(demos), "--takes", "2",
         "--object", "glass=0.4,0.1,0.1", "--timeout", "15"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert rec.stdin is not None
    lines: list[str] = []
    for seconds in (1.0, 0.6):
        _wait_for_text(rec, "Enter starts a take", lines)
        rec.stdin.write("\n")
        rec.stdin.flush()
        _wait_for_text(rec, "recording (Enter stops it)", lines)
        time.sleep(seconds)
        rec.stdin.write("\n")
        rec.stdin.flush()
    out, err = rec.communicate(timeout=30)
    driver.terminate()
    driver.wait(timeout=10)
    said = "".join(lines) + out
    assert rec.returncode == 0 and "2 take(s) recorded" in said, (rec.returncode, said, err)
    from pbdkit import load_demonstrations

    takes = load_demonstrations(demos)
    durations = [float(d.t[-1] - d.t[0]) for d in takes]
    assert len(takes) == 2 and abs(durations[0] - 1.0) < 0.3 and abs(durations[1] - 0.6) < 0.3, (
        durations
    )
    for d in takes:  # the pan joint sweeps at 0.1 rad/s: the samples are the driver's
        pan_speed = np.polyfit(d.t, d.joints[:, 0], 1)[0]
        assert abs(pan_speed - 0.1) < 0.01, pan_speed
        np.testing.assert_allclose(d.objects["glass"], [0.4, 0.1, 0.1])
    print(f"OK: 2 takes of {durations[0]:.2f} s and {durations[1]:.2f} s")


def record_suggest_poses(skill_file: str, workdir: str) -> None:
    """`pbdkit ros record --suggest SKILL --takes 1` (Enter starts and stops the take), the
    glass on a PoseStamped topic: it says where to put the glass, turned (the skill's
    demonstrations hold it as a pose), and learns the take. The files: the caller's."""
    demos = Path(workdir) / "demos.npz"
    driver = subprocess.Popen([sys.executable, __file__, "moving_katana", "30"])
    glass = subprocess.Popen([sys.executable, __file__, "publish_pose", "/objects/glass",
                              "0.4,0.1,0.1", "0.4,0.1,0.1"])  # fmt: skip
    rec = subprocess.Popen(
        [sys.executable, "-m", "pbdkit", "ros", "record", "--out", str(demos), "--takes", "1",
         "--object", "glass=/objects/glass", "--suggest", skill_file, "--timeout", "15"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert rec.stdin is not None
    lines: list[str] = []
    for wait_for in ("Enter starts a take", "recording (Enter stops it)"):
        _wait_for_text(rec, wait_for, lines)
        time.sleep(0.5)
        rec.stdin.write("\n")
        rec.stdin.flush()
    out, err = rec.communicate(timeout=30)
    for proc in (driver, glass):
        proc.terminate()
        proc.wait(timeout=10)
    said = "".join(lines) + out
    assert rec.returncode == 0, (rec.returncode, said, err)
    assert "learned from 6 demonstrations" in said, said
    assert said.startswith("put glass at (") and " yaw " in said.splitlines()[0], said
    print("OK: 1 take, learned")


def sim_cameras() -> None:
    """`pbdkit ros sim --cameras` publishes the stereo tracker's estimates on /objects/NAME:
    within 3 mm of the placement, not the placement itself."""
    import rclpy
    from geometry_msgs.msg import PoseStamped

    from pbdkit.ros._task_world import placement_objects
    from pbdkit.sim import get_task

    sim = _pbdkit("ros", "sim", "--task", "coaster", "--placement", "3", "--cameras")
    rclpy.init()
    node = rclpy.create_node("object_listener")
    seen: dict[str, np.ndarray] = {}
    for name in ("glass", "coaster"):
        node.create_subscription(
            PoseStamped,
            f"/objects/{name}",
            lambda msg, name=name: seen.__setitem__(
                name, np.array([msg.pose.position.x, msg.pose.position.y, msg.pose.position.z])
            ),
            10,
        )
    start = time.monotonic()
    while len(seen) < 2 and time.monotonic() - start < 60.0:
        rclpy.spin_once(node, timeout_sec=0.05)
    sim.terminate()
    out, err = sim.communicate(timeout=20)
    node.destroy_node()
    rclpy.shutdown()
    assert len(seen) == 2, (seen, out, err)
    truth = placement_objects(get_task("coaster"), 0, 3)
    errors = {k: float(np.linalg.norm(seen[k] - truth[k])) for k in seen}
    assert all(0.0 < e < 3e-3 for e in errors.values()), errors
    print(f"OK: tracked within {max(errors.values()) * 1e3:.2f} mm")


CASES["moving_katana"] = moving_katana
CASES["sim_cameras"] = sim_cameras
CASES["record_on_enter"] = record_on_enter
CASES["record_suggest_poses"] = record_suggest_poses


if __name__ == "__main__":
    case, *rest = sys.argv[1:]
    CASES[case](*rest)
