"""A Franka Panda skill from ROS 2 bags, reproduced for a new glass, written back as a bag.

Run:  python examples/panda_from_bags.py [OUTPUT_FOLDER]   (default: a temporary folder)

What a session on a real Panda looks like, without the robot: five kinesthetic demonstrations of
"reach for the glass, grasp it, lift it" are recorded as rosbag2 bags (joint states from the
driver, with the two finger joints and a new joint order in every message; the glass pose from
perception at 30 Hz; the gripper as std_msgs/Bool), then:

    bags -> pbdkit.read_bag -> Skill.learn -> skill.reproduce(new glass) -> write_trajectory_bag

The trajectory bag holds one trajectory_msgs/msg/JointTrajectory on /joint_trajectory, which
`ros2 bag play` sends to a ros2_control joint trajectory controller (remap the topic to
/<controller>/joint_trajectory), and the gripper command on /gripper.

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
from pbdkit.bags import write_demonstration_bag

RATE = 100.0  # Hz, the joint state rate of the driver
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

    # 3. Learn, and reproduce for a glass placed where no demonstration had it.
    skill = pbdkit.Skill.learn(demos, robot, max_components=15)
    new_grasp = GRASP + np.array([0.2, 0.05, 0.0, -0.05, 0.0, 0.05, 0.0])
    glass = robot.fk(new_grasp)
    res = skill.reproduce({"glass": glass})
    closest = float(res.task_errors["glass"].min())
    joint_only = float(skill.reproduce({"glass": glass}, use=["joint"]).task_errors["glass"].min())

    # 4. Write the trajectory for a joint trajectory controller.
    trajectory = out / "trajectory"
    t = skill.times(res)
    pbdkit.write_trajectory_bag(trajectory, t, res.joints, robot.joint_names, gripper=res.gripper)

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
    print(f"gripper closes at {t[int(np.argmax(res.gripper))]:.2f} s of {t[-1]:.2f} s")
    print(f"wrote {trajectory}: /joint_trajectory, {len(t)} points over {t[-1]:.2f} s")
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
