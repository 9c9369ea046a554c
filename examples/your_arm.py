"""pbdkit on an arm you bring: your URDF, your logs, your control loop.

Run:  python examples/your_arm.py [OUTPUT_FOLDER]   (default: a temporary folder)

Every step a user of another arm takes, on a 4-DOF arm this script describes itself:

1. the arm's URDF (here a string written to ``my_arm.urdf``; use your robot's file), loaded
   with ``pbdkit.Robot.from_urdf(path, tip="tool0")``;
2. demonstrations logged as CSV files, one per demonstration (columns ``t``, the joint names,
   ``gripper``), read with ``pbdkit.demonstration_from_csv`` and the object positions your
   perception measured (from a ROS 2 bag instead: ``pbdkit.read_bag``, see
   ``panda_from_bags.py``);
3. ``Skill.learn``, then ``skill.reproduce`` for new object positions (offline, a trajectory
   within the arm's limits: a lead-in from where the arm is to the skill's first posture, then
   the skill's steps), saved as ``skill.npz`` and as a trajectory bag for a ``ros2_control``
   controller;
4. the online controller, closed on the arm: every ``ctrl.dt`` seconds, read the joints,
   send the next target. Your driver replaces ``ServoArm`` (a simulated arm whose servos lag
   behind their references).

The limits the skill keeps are the arm's: here the URDF's velocity limits, and, as a URDF has
no field for them, acceleration and jerk limits pbdkit derives from those (a = v / 0.25 s,
j = a / 0.1 s; a ``DefaultLimitsWarning`` says so). Give ``Robot.from_urdf`` your arm's own
(``joint_limits=`` a MoveIt / ros2_control ``joint_limits.yaml``) and the trajectory and the
commands keep those instead (``panda_from_bags.py`` runs a Panda within Franka's, streamed at
1 kHz).

The task: pick a cup and put it into a bin; cup and bin are somewhere else each time.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

import pbdkit

MY_ARM_URDF = """<?xml version="1.0"?>
<robot name="my_arm">
  <link name="base_link"/>
  <link name="link1"/> <link name="link2"/> <link name="link3"/> <link name="link4"/>
  <link name="tool0"/>
  <joint name="yaw" type="revolute">
    <parent link="base_link"/> <child link="link1"/>
    <origin xyz="0 0 0.10"/> <axis xyz="0 0 1"/>
    <limit lower="-2.8" upper="2.8" velocity="1.5" effort="20"/>
  </joint>
  <joint name="shoulder" type="revolute">
    <parent link="link1"/> <child link="link2"/>
    <origin xyz="0 0 0.10"/> <axis xyz="0 1 0"/>
    <limit lower="-1.9" upper="1.9" velocity="1.5" effort="20"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="link2"/> <child link="link3"/>
    <origin xyz="0 0 0.30"/> <axis xyz="0 1 0"/>
    <limit lower="-2.4" upper="2.4" velocity="1.5" effort="10"/>
  </joint>
  <joint name="wrist" type="revolute">
    <parent link="link3"/> <child link="link4"/>
    <origin xyz="0 0 0.25"/> <axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" velocity="2.0" effort="5"/>
  </joint>
  <joint name="tool" type="fixed">
    <parent link="link4"/> <child link="tool0"/> <origin xyz="0 0 0.10"/>
  </joint>
</robot>
"""
RATE = 50.0  # Hz of the logs
HOME = np.array([0.0, 0.0, 0.3, 0.3])
PICK = np.array([0.5, 0.9, 0.9, 0.9])  # hand low, to the left
PLACE = np.array([-0.6, 0.6, 0.8, 0.7])  # above the bin, to the right
ABOVE_BIN = np.array([0.0, 0.0, 0.08])  # the cup is released this far above the bin's centre


def min_jerk(q_from: np.ndarray, q_to: np.ndarray, n: int) -> np.ndarray:
    """n postures from q_from to q_to with a minimum-jerk profile (rest to rest)."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    return q_from + (q_to - q_from) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def record_demonstration(
    robot: pbdkit.Robot, path: Path, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """Log one demonstration to a CSV file as a real arm's logger would; returns the cup and
    bin positions measured for it."""
    pick = PICK + rng.uniform(-1, 1, 4) * np.array([0.3, 0.1, 0.1, 0.1])
    place = PLACE + rng.uniform(-1, 1, 4) * np.array([0.3, 0.1, 0.1, 0.1])
    vias = [HOME + rng.normal(0, 0.02, 4), pick, pick, place, place, HOME]
    seconds = np.array([2.0, 1.0, 2.0, 1.0, 1.6]) * rng.uniform(0.85, 1.15, 5)
    segments = [
        min_jerk(a, b, max(2, round(s * RATE)))[1:]
        for a, b, s in zip(vias[:-1], vias[1:], seconds, strict=True)
    ]
    joints = np.vstack([vias[0][None], *segments])
    lengths = np.cumsum([1, *(len(s) for s in segments)])
    gripper = np.zeros(len(joints))
    gripper[lengths[1] + len(segments[1]) // 2 : lengths[3] + len(segments[3]) // 2] = 1.0
    t = np.arange(len(joints)) / RATE
    header = ",".join(["t", *robot.joint_names, "gripper"])
    table = np.column_stack([t, joints, gripper])
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.6f")
    return {
        "cup": robot.fk(pick) + rng.normal(0, 0.001, 3),
        "bin": robot.fk(place) - ABOVE_BIN + rng.normal(0, 0.001, 3),
    }


def new_places(robot: pbdkit.Robot) -> dict[str, np.ndarray]:
    """Where the cup and the bin are this time: inside the demonstrated places, at none of them."""
    pick = PICK + np.array([0.1, 0.0, 0.05, 0.0])
    place = PLACE + np.array([0.1, 0.05, 0.0, 0.0])
    return {"cup": robot.fk(pick), "bin": robot.fk(place) - ABOVE_BIN}


class ServoArm:
    """Stands in for your driver: servos that cover 60 % of the way to their reference per
    cycle, and encoders with 0.1 mrad of noise."""

    def __init__(self, q0: np.ndarray, rng: np.random.Generator) -> None:
        self.q = np.array(q0, dtype=float)
        self.rng = rng

    def read_joints(self) -> np.ndarray:
        return self.q + self.rng.normal(0.0, 1e-4, self.q.shape)

    def send(self, q: np.ndarray, gripper: bool) -> None:
        self.q += 0.6 * (q - self.q)
        self.gripper = gripper


def main(out: Path) -> None:
    rng = np.random.default_rng(0)
    urdf = out / "my_arm.urdf"
    urdf.write_text(MY_ARM_URDF)
    robot = pbdkit.Robot.from_urdf(urdf, tip="tool0")  # limits: see the module docstring

    demos = []
    for i in range(5):
        csv = out / f"demo{i}.csv"
        objects = record_demonstration(robot, csv, rng)
        demos.append(pbdkit.demonstration_from_csv(csv, objects=objects))

    skill = pbdkit.Skill.learn(demos, robot, max_components=15)
    skill.save(out / "skill.npz")

    objects = new_places(robot)
    res = skill.reproduce(objects)
    t = skill.times(res)  # the reproduction's timing, within the arm's velocity limits
    trajectory = out / "trajectory"
    pbdkit.write_trajectory_bag(
        trajectory,
        t,
        res.joints,
        robot.joint_names,
        gripper=res.gripper,
        velocities=res.velocities,
        accelerations=res.accelerations,
        limits=skill.motion_limits(),  # checked against the limits it was timed within
    )

    # Online: one command per ctrl.dt from the measured joints (your loop runs at that rate).
    # The first measured posture is where the commands start, at rest.
    arm = ServoArm(res.joints[0], rng)
    ctrl = skill.controller(objects)
    hand_to_cup, hand_to_bin, commands = [], [], 0
    while not ctrl.done:
        cmd = ctrl.step(arm.read_joints())
        arm.send(cmd.q, cmd.gripper)
        commands += 1
        x = robot.fk(arm.q)
        if cmd.gripper and not hand_to_bin:
            hand_to_cup.append(np.linalg.norm(x - objects["cup"]))
        elif not cmd.gripper and hand_to_cup:
            hand_to_bin.append(np.linalg.norm(x - objects["bin"] - ABOVE_BIN))

    offline = {k: 1000 * float(v.min()) for k, v in res.task_errors.items()}
    print(f"robot {robot.name}: joints {robot.joint_names}, tip {robot.tip}, base {robot.base}")
    print(f"read {len(demos)} CSV demonstrations ({[d.n_steps for d in demos]} samples)")
    print(f"learned K per space: {skill.n_components}; wrote {out / 'skill.npz'}")
    print(
        "offline reproduction, closest approach: "
        + ", ".join(f"{k} {v:.1f} mm" for k, v in offline.items())
    )
    n_lead = int(np.count_nonzero(res.lead_in))
    print(
        f"wrote {trajectory}: {len(t)} points ({n_lead} lead-in + {skill.n_steps} steps) "
        f"over {t[-1]:.2f} s"
    )
    print(
        f"online: {commands} commands every {1000 * ctrl.dt:.1f} ms "
        f"({commands * ctrl.dt:.2f} s); hand at grasp "
        f"{1000 * hand_to_cup[0]:.1f} mm from the cup, at release "
        f"{1000 * hand_to_bin[0]:.1f} mm from the release point above the bin"
    )


if __name__ == "__main__":
    if len(sys.argv) > 2:
        sys.exit("usage: python examples/your_arm.py [OUTPUT_FOLDER]")
    if len(sys.argv) == 2:
        folder = Path(sys.argv[1])
        folder.mkdir(parents=True, exist_ok=True)
        main(folder)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            main(Path(tmp))
