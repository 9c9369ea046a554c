"""A Franka Panda skill from ROS 2 bags, reproduced for a new glass, written back as a bag, and
run online at 1 kHz within Franka's limits.

Run:  python examples/panda_from_bags.py [OUTPUT_FOLDER]   (default: a temporary folder)

What a session on a real Panda looks like, without the robot: five kinesthetic demonstrations of
"reach for the glass, grasp it, lift it" are recorded as rosbag2 bags (joint states from the
driver, with the two finger joints and a new joint order in every message; the glass pose from
perception at 30 Hz; the gripper as std_msgs/Bool), then:

    bags -> pbdkit.read_bag -> Skill.learn -> skill.reproduce(new glass) -> write_trajectory_bag
                                           -> skill.controller(new glass).stream(1000)

Offline, the reproduction is timed within Franka's velocity, acceleration and jerk limits
(pbdkit.robots.panda() declares them): a lead-in from the arm's posture to the skill's first
posture, then the skill's steps, slowed where the arm could not follow them. The trajectory bag
holds it as one trajectory_msgs/msg/JointTrajectory on /joint_trajectory, every point with its
velocities and accelerations, which `ros2 bag play` sends to a ros2_control joint trajectory
controller (remap the topic to /<controller>/joint_trajectory), and the gripper command on
/gripper.

Online, the skill runs in the arm's 1 kHz loop (libfranka, franka_ros2): every millisecond,
read the joints, send the next setpoint. A Panda checks every setpoint against the last ones and
stops on one that needs more velocity, acceleration or jerk than its limits; a
pbdkit.motion.limits.StreamMonitor checks the stream the same way. ``SimulatedPanda`` stands in for
the arm (the joints follow the setpoints, the encoders read them with a little noise).

The output folder gets the demonstration bags, the trajectory bag, the skill (skill.npz) and the
online run's setpoints (stream.npz: t, q, gripper, and the glass).

Here the demonstrations are synthesized: joint-space via points (start, pre-grasp, grasp,
lift, retreat) interpolated with minimum-jerk profiles, the teacher's postures and timing
varying from one demonstration to the next; the glass is where the hand is at the grasp
posture (forward kinematics), seen by perception with 1 mm noise.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import pbdkit
from pbdkit.learning.bags import write_demonstration_bag
from pbdkit.motion.limits import MotionLimits, MotionPeaks, StreamMonitor, motion_peaks

RATE = 100.0  # Hz, the joint state rate of the driver
LOOP_HZ = 1000.0  # the Panda's control loop: one setpoint per millisecond
START = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])  # Panda "ready"
GRASP = np.array([0.0, 0.35, 0.0, -2.0, 0.0, 2.35, 0.785])  # hand low in front of the base
FINGERS = {"panda_finger_joint1": 0.04, "panda_finger_joint2": 0.04}


def min_jerk(q_from: np.ndarray, q_to: np.ndarray, n: int) -> np.ndarray:
    """n postures from q_from to q_to with a minimum-jerk profile (rest to rest)."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    return q_from + (q_to - q_from) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def demonstration(
    robot: pbdkit.Robot, grasp: np.ndarray, rng: np.random.Generator
) -> pbdkit.Demonstration:
    """One demonstration reaching the grasp posture: via points, durations and the glass."""
    start = START + rng.normal(0.0, 0.02, 7)
    pre = grasp + np.array([0.0, -0.15, 0.0, -0.15, 0.0, 0.0, 0.0]) + rng.normal(0.0, 0.01, 7)
    lift = grasp + np.array([0.0, -0.2, 0.0, 0.1, 0.0, -0.2, 0.0]) + rng.normal(0.0, 0.01, 7)
    vias = [start, pre, grasp, grasp, lift, START + rng.normal(0.0, 0.02, 7)]
    seconds = np.array([1.5, 1.0, 0.5, 1.2, 1.3]) * rng.uniform(0.85, 1.15, 5)
    parts = [
        min_jerk(a, b, max(2, round(s * RATE)))[1:]
        for a, b, s in zip(vias[:-1], vias[1:], seconds, strict=True)
    ]
    joints = np.vstack([vias[0][None], *parts])
    t = np.arange(joints.shape[0]) / RATE
    at_grasp = 1 + parts[0].shape[0] + parts[1].shape[0]  # the first sample of the hold
    closed_from = at_grasp + parts[2].shape[0] // 2  # the fingers close during the hold
    gripper = (np.arange(joints.shape[0]) >= closed_from).astype(float)
    glass = robot.fk(grasp) + rng.normal(0.0, 0.001, 3)  # perception noise
    return pbdkit.Demonstration(t, robot.clip(joints), {"glass": glass}, gripper=gripper)


class SimulatedPanda:
    """Stands in for the arm and its 1 kHz driver: the joints follow the setpoints, the encoders
    read them with 0.01 mrad of noise."""

    def __init__(self, q: np.ndarray, rng: np.random.Generator) -> None:
        self.setpoint = np.array(q, dtype=float)  # where the drive holds the arm
        self.rng = rng

    def read_joints(self) -> np.ndarray:
        return self.setpoint + self.rng.normal(0.0, 1e-5, self.setpoint.shape)

    def send(self, q: np.ndarray) -> None:
        self.setpoint = np.array(q, dtype=float)


def run_online(
    skill: pbdkit.Skill, objects: dict[str, np.ndarray], arm: SimulatedPanda, limits: MotionLimits
) -> tuple[np.ndarray, np.ndarray, MotionPeaks]:
    """The skill in the arm's 1 kHz loop: the setpoints sent (the first is where the arm
    started), the gripper command at each, and the stream's peaks over ``limits``."""
    stream = skill.controller(objects).stream(LOOP_HZ)
    monitor = StreamMonitor(limits, 1.0 / LOOP_HZ)
    # The stream starts at rest from the first posture it is given. Give it the drive's last
    # setpoint (on a Panda, robot_state.q_d), not a reading: that is off by the encoder noise,
    # and 0.01 mrad in one millisecond is a jerk of 10^4 rad/s^3 (Franka allows 3750 to 10^4).
    q_measured = arm.setpoint.copy()
    monitor.update(q_measured)  # the drive holds the arm there before the stream begins
    setpoints, closed = [q_measured], [False]
    while not stream.done:
        q_set = stream.step(q_measured)
        arm.send(q_set)
        monitor.update(q_set)
        setpoints.append(q_set)
        closed.append(stream.command is not None and stream.command.gripper)
        q_measured = arm.read_joints()
    return np.array(setpoints), np.array(closed), monitor.finish()


def main(out: Path) -> None:
    began = time.perf_counter()
    robot = pbdkit.robots.panda()
    rng = np.random.default_rng(0)

    # 1. Record five demonstrations as bags (both rosbag2 storages), as a real driver would.
    bags = []
    for i in range(5):
        grasp = GRASP + rng.uniform(-1, 1, 7) * np.array([0.35, 0.1, 0.1, 0.12, 0.1, 0.1, 0.2])
        demo = demonstration(robot, grasp, rng)
        bag = out / f"demo_{i}"
        write_demonstration_bag(
            bag,
            demo,
            robot.joint_names,
            storage="mcap" if i % 2 else "sqlite3",
            frame_id=robot.base,
            extra_joints=FINGERS,
            shuffle=rng,
        )
        bags.append(bag)

    # 2. Read them back: joints in the robot's order, the glass from its topic, the gripper.
    demos = [
        pbdkit.read_bag(b, robot=robot, objects={"glass": "/glass/pose"}, gripper_topic="/gripper")
        for b in bags
    ]

    # 3. Learn, and reproduce for a glass placed where no demonstration had it, the arm at
    #    "ready": a lead-in to the skill's first posture, then its steps, within the limits.
    skill = pbdkit.Skill.learn(demos, robot, max_components=15)
    skill.save(out / "skill.npz")
    new_grasp = GRASP + np.array([0.2, 0.05, 0.0, -0.05, 0.0, 0.05, 0.0])
    glass = robot.fk(new_grasp)
    res = skill.reproduce({"glass": glass}, q0=START)
    closest = float(np.linalg.norm(res.positions - glass, axis=1).min())
    joint_res = skill.reproduce({"glass": glass}, use=["joint"])
    joint_only = float(np.linalg.norm(joint_res.positions - glass, axis=1).min())

    # 4. Write the trajectory for a joint trajectory controller, with the velocities and
    #    accelerations of its timing (the controller's splines then follow the timed motion).
    trajectory = out / "trajectory"
    t = skill.times(res)
    pbdkit.write_trajectory_bag(
        trajectory,
        t,
        res.joints,
        robot.joint_names,
        gripper=res.gripper,
        velocities=res.velocities,
        accelerations=res.accelerations,
    )
    limits = MotionLimits.from_robot(robot, robot.n_joints)  # Franka's published limits
    offline = motion_peaks(t, res.joints, limits)

    # 5. Online: the skill in the arm's 1 kHz loop, from "ready", every setpoint checked.
    setpoints, closed, online = run_online(
        skill, {"glass": glass}, SimulatedPanda(START, rng), limits
    )
    np.savez(
        out / "stream.npz",
        t=np.arange(len(setpoints)) / LOOP_HZ,
        q=setpoints,
        gripper=closed,
        glass=glass,
    )
    grasp_offline = np.linalg.norm(robot.fk(res.joints[np.argmax(res.gripper)]) - glass)
    grasp_online = np.linalg.norm(robot.fk(setpoints[np.argmax(closed)]) - glass)

    seen = [d.objects["glass"] for d in demos]
    print(f"recorded {len(bags)} demonstration bags in {out}")
    print(
        f"read {len(demos)} demonstrations: {[d.n_steps for d in demos]} joint states, "
        f"glass x {min(p[0] for p in seen):.3f}..{max(p[0] for p in seen):.3f} m, "
        f"y {min(p[1] for p in seen):.3f}..{max(p[1] for p in seen):.3f} m"
    )
    print(f"learned K per space: {skill.n_components}")
    print(f"new glass at {np.round(glass, 4).tolist()} m")
    print(
        f"closest approach to the glass: {1000 * closest:.1f} mm "
        f"(joint space only, the demonstrated postures: {1000 * joint_only:.1f} mm)"
    )
    n_lead = int(np.count_nonzero(res.lead_in))
    print(
        f"offline: {n_lead} lead-in points from ready + {skill.n_steps} steps, over "
        f"{t[-1]:.2f} s (the steps {res.stretch:.2f}x their demonstrated pace); "
        f"gripper closes at {t[int(np.argmax(res.gripper))]:.2f} s"
    )
    print(f"wrote {trajectory}: /joint_trajectory, {len(t)} points over {t[-1]:.2f} s")
    n_set = len(setpoints) - 1  # after the start posture
    print(f"streamed at 1 kHz from ready: {n_set} setpoints over {n_set / LOOP_HZ:.2f} s")
    for name, peaks in (("trajectory points", offline), ("1 kHz stream", online)):
        print(
            f"peak / Franka's limit, {name}: velocity {peaks.velocity:.3f}, "
            f"acceleration {peaks.acceleration:.3f}, jerk {peaks.jerk:.3f}"
        )
    print(
        f"hand when the gripper closes: {1000 * grasp_online:.1f} mm from the glass online "
        f"({1000 * grasp_offline:.1f} mm offline)"
    )
    print(f"done in {time.perf_counter() - began:.1f} s")


if __name__ == "__main__":
    if len(sys.argv) > 2:
        sys.exit("usage: python examples/panda_from_bags.py [OUTPUT_FOLDER]")
    if len(sys.argv) == 2:
        folder = Path(sys.argv[1])
        folder.mkdir(parents=True, exist_ok=True)
        main(folder)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            main(Path(tmp))
