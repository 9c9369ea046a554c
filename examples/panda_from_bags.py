"""A Franka Panda grasping a mug by its handle, whatever way the mug is turned: a pose skill
from ROS 2 bags, reproduced for new mug poses, written back as a bag, and run online at 1 kHz
within Franka's limits.

Run:  python examples/panda_from_bags.py [OUTPUT_FOLDER]   (default: a temporary folder)

What a session on a real Panda looks like, without the robot: five kinesthetic demonstrations of
"reach for the mug, grasp it by its handle, lift it", the mug at a new place and a new yaw each
time (-90 to 90 degrees), are recorded as rosbag2 bags (joint states from the driver, with the
two finger joints and a new joint order in every message; the mug's pose from perception at
30 Hz as geometry_msgs/PoseStamped, position and orientation; the gripper as std_msgs/Bool),
then:

    bags -> pbdkit.read_bag -> Skill.learn -> skill.reproduce(new mug pose) -> write_trajectory_bag
                                           -> skill.controller(new mug pose).stream(1000)

The mug is a pose: read_bag gives it as a 4x4 transform, and ``Skill.learn(...,
orientation=True)`` (the default) learns the hand's position and orientation in the mug's frame,
so the grasp turns with the mug. ``orientation=False`` learns the paper's position-only skill
from the same bags: the hand relative to the mug's position, in the robot's axes. The handle's
offset turns with the mug, so over the demonstrations' yaws it averages towards the mug's axis,
and nothing constrains the hand's turn but the averaged postures: for a new yaw it misses the
handle by centimetres and the grasp's orientation by tens of degrees. The script prints both
skills over 20 new mug poses (seeded): the grasp's position and orientation errors, and how many
are within 5 mm and 3 degrees.

Frames and conventions (all poses in the robot's base frame, panda_link0, m):
- The mug's frame: origin at the centre of its base, z up, x through the handle.
- The grasp is measured at the Franka Hand's fingertip centre (the TCP: 0.1034 m beyond the
  flange along its z, turned -45 degrees about it), the flange being pbdkit.robots.panda()'s
  tip. The teacher grasps the top of the handle from above, the fingers closing across it.
- The demonstrated grasp is the fingertips' pose in the mug's frame at the sample where the
  gripper closes, averaged over the five bags as read back (positions: mean; orientations:
  Karcher mean). A reproduction's grasp is the fingertips' pose in the new mug's frame at the
  first step where the reproduced gripper is closed (the hand holds still over the closing).
  Position error: the distance between the two, mm; orientation error: the angle of the
  rotation between them, degrees.
- Quaternions: the PoseStamped messages hold x, y, z, w (ROS's order); pbdkit writes them w
  first, (x, y, z, qw, qx, qy, qz) as pytransform3d does, where the script prints a pose.

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
pbdkit.motion._limits.StreamMonitor checks the stream the same way. ``SimulatedPanda`` stands in for
the arm (the joints follow the setpoints, the encoders read them with a little noise).

The output folder gets the demonstration bags, the trajectory bag, both skills (skill.npz, the
pose skill; skill_position_only.npz), the 20 new mug poses with both skills' errors
(grasps.npz) and the online run's setpoints (stream.npz: t, q, gripper, and the mug's pose).

Here the demonstrations are synthesized: the teacher's hand goes from the "ready" posture to
12 cm above the handle, down to the grasp, holds while the gripper closes, and lifts the mug
15 cm; joint-space via points (inverse kinematics of those poses, from the teacher's last
posture) interpolated with minimum-jerk profiles, the start posture and timing varying from one
demonstration to the next. Perception sees the mug with 1 mm and 0.3 degrees (per axis) of
noise.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import pbdkit
from pbdkit._rotations import exp_map, log_map, mean_rotation, pose_matrix, quaternion_from_matrix
from pbdkit.data._bag_write import write_demonstration_bag
from pbdkit.motion._limits import MotionLimits, MotionPeaks, StreamMonitor, motion_peaks

RATE = 100.0  # Hz, the joint state rate of the driver
LOOP_HZ = 1000.0  # the Panda's control loop: one setpoint per millisecond
START = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])  # Panda "ready"
FINGERS = {"panda_finger_joint1": 0.04, "panda_finger_joint2": 0.04}


def rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# The Franka Hand's fingertip centre (TCP) in the flange frame.
TCP = pose_matrix([0.0, 0.0, 0.1034], rot_z(-np.pi / 4))
# The teacher's grasp, the fingertips in the mug's frame: 7 cm out on the handle, 8 cm up,
# pointing down (hand z = -mug z), closing across the handle (hand y = -mug y). At mug yaw 0 this
# is the hand's orientation at "ready" (joint 7 at 0.785 rad), so the yaws of +-90 degrees turn
# joint 7 by about as much, within its +-2.90 rad; at yaw -90, where it turns furthest, the
# handle is on the mug's right (y < 0), where joint 1 turns the arm the other way. Measured:
# joint 7 from -1.0 to 2.7 rad at the demonstrations' grasps (2.71 at the worst corner of the
# mugs' range), no wrist flip. Turned 90 degrees about the vertical either way, the grasp would
# drive joint 7 to its limit near one end of the yaws, or flip the wrist between two
# demonstrations: new mugs between them would get an average of two postures that fit neither.
GRASP = pose_matrix([0.07, 0.0, 0.08], np.diag([1.0, -1.0, -1.0]))
PRE_GRASP, LIFT = 0.12, 0.15  # m above the grasp
# Where the mugs are: the centre of the base in these ranges (m), yaw in [-90, 90] degrees.
MUG_X, MUG_Y, MUG_YAW = (0.5, 0.65), (-0.12, 0.12), np.pi / 2
# The demonstrations' mugs (x m, y m, yaw deg): the yaws span the range, the places the table.
DEMO_MUGS = [
    (0.55, 0.1, -90),
    (0.62, -0.12, -45),
    (0.5, 0.0, 0),
    (0.6, 0.12, 45),
    (0.56, -0.08, 90),
]
N_NEW = 20  # new mug poses the skills are measured on
TOLERANCE_MM, TOLERANCE_DEG = 5.0, 3.0


def mug_pose(x: float, y: float, yaw: float) -> np.ndarray:
    """The mug standing on the table (z = 0) at (x, y), turned by yaw (rad) about z."""
    return pose_matrix([x, y, 0.0], rot_z(yaw))


def xyz_wxyz(pose: np.ndarray) -> list[float]:
    """A pose as x, y, z, qw, qx, qy, qz (quaternion w first: pbdkit's and pytransform3d's)."""
    return [*pose[:3, 3].tolist(), *quaternion_from_matrix(pose[:3, :3]).tolist()]


def inverse_kinematics(robot: pbdkit.Robot, target: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The teacher's posture for a flange pose, from the posture q (damped least squares)."""
    for _ in range(200):
        pose = robot.fk_pose(q)
        error = np.r_[target[:3, 3] - pose[:3, 3], log_map(target[:3, :3] @ pose[:3, :3].T)]
        if np.linalg.norm(error) < 1e-12:
            break
        jac = robot.jacobian6(q)
        q = robot.clip(q + jac.T @ np.linalg.solve(jac @ jac.T + 1e-9 * np.eye(6), error))
    if np.linalg.norm(error) > 1e-9:
        raise RuntimeError(f"no posture reaches {np.round(target, 3).tolist()}")
    return q


def min_jerk(q_from: np.ndarray, q_to: np.ndarray, n: int) -> np.ndarray:
    """n postures from q_from to q_to with a minimum-jerk profile (rest to rest)."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    return q_from + (q_to - q_from) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def demonstration(
    robot: pbdkit.Robot, mug: np.ndarray, rng: np.random.Generator
) -> pbdkit.Demonstration:
    """One demonstration of grasping the mug (a 4x4 pose) by its handle and lifting it."""
    flange = mug @ GRASP @ np.linalg.inv(TCP)  # where the flange is at the grasp

    def above(height: float) -> np.ndarray:
        return pose_matrix(flange[:3, 3] + [0.0, 0.0, height], flange[:3, :3])

    start = START + rng.normal(0.0, 0.02, 7)
    pre = inverse_kinematics(robot, above(PRE_GRASP), start)
    grasp = inverse_kinematics(robot, flange, pre)
    lift = inverse_kinematics(robot, above(LIFT), grasp)
    vias = [start, pre, grasp, grasp, lift]
    seconds = np.array([1.8, 0.8, 0.8, 1.0]) * rng.uniform(0.85, 1.15, 4)
    parts = [
        min_jerk(a, b, max(2, round(s * RATE)))[1:]
        for a, b, s in zip(vias[:-1], vias[1:], seconds, strict=True)
    ]
    joints = np.vstack([vias[0][None], *parts])
    t = np.arange(joints.shape[0]) / RATE
    at_grasp = 1 + parts[0].shape[0] + parts[1].shape[0]  # the first sample of the hold
    closed_from = at_grasp + parts[2].shape[0] // 2  # the fingers close during the hold
    gripper = (np.arange(joints.shape[0]) >= closed_from).astype(float)
    noise = pose_matrix(rng.normal(0.0, 0.001, 3), exp_map(rng.normal(0.0, np.radians(0.3), 3)))
    seen = mug @ noise  # the mug as perception sees it
    return pbdkit.Demonstration(t, joints, {"mug": seen}, gripper=gripper)


def grasp_in_mug(robot: pbdkit.Robot, q: np.ndarray, mug: np.ndarray) -> np.ndarray:
    """The fingertips' pose in the mug's frame with the arm at q."""
    return np.linalg.inv(mug) @ robot.fk_pose(q) @ TCP


def grasp_error(grasp: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """(position error in mm, orientation error in degrees) of a grasp, both in the mug's frame."""
    distance = np.linalg.norm(grasp[:3, 3] - reference[:3, 3])
    angle = np.linalg.norm(log_map(grasp[:3, :3] @ reference[:3, :3].T))
    return 1000 * float(distance), float(np.degrees(angle))


def closing_sample(demo: pbdkit.Demonstration) -> int:
    """The sample where the demonstration's gripper closes."""
    if demo.gripper is None:
        raise ValueError("the demonstration has no gripper signal")
    return int(np.argmax(demo.gripper > 0.5))


def demonstrated_grasp(robot: pbdkit.Robot, demos: list[pbdkit.Demonstration]) -> np.ndarray:
    """The fingertips in the mug's frame where each demonstration's gripper closes, averaged:
    positions by their mean, orientations by their Karcher mean."""
    grasps = np.stack(
        [grasp_in_mug(robot, d.joints[closing_sample(d)], d.objects["mug"]) for d in demos]
    )
    return pose_matrix(grasps[:, :3, 3].mean(axis=0), mean_rotation(grasps[:, :3, :3]))


def new_mugs(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """n mug poses drawn uniformly over the table's range and the yaws."""
    return [
        mug_pose(rng.uniform(*MUG_X), rng.uniform(*MUG_Y), rng.uniform(-MUG_YAW, MUG_YAW))
        for _ in range(n)
    ]


def grasp_errors(
    skill: pbdkit.Skill, robot: pbdkit.Robot, mugs: list[np.ndarray], reference: np.ndarray
) -> np.ndarray:
    """(len(mugs), 2): each reproduction's grasp error (mm, degrees), from "ready", at the first
    step where its gripper is closed."""
    errors = []
    for mug in mugs:
        res = skill.reproduce({"mug": mug}, q0=START)
        closing = int(np.argmax(res.gripper))
        errors.append(grasp_error(grasp_in_mug(robot, res.joints[closing], mug), reference))
    return np.array(errors)


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
    # The simulated arm runs faster than real time: its plans are made inline, in the call that
    # needs them. On the real arm (a loop at the drive's pace) keep the default,
    # planner="process": no call waits for a plan.
    stream = skill.controller(objects).stream(LOOP_HZ, planner="inline")
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

    # 1. Record five demonstrations as bags (both rosbag2 storages), as a real driver would:
    #    the mug's PoseStamped carries its orientation (quaternion x, y, z, w, ROS's order).
    bags = []
    for i, (x, y, yaw) in enumerate(DEMO_MUGS):
        demo = demonstration(robot, mug_pose(x, y, np.radians(yaw)), rng)
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

    # 2. Read them back: joints in the robot's order, the mug's pose (4x4) from its topic, the
    #    gripper.
    demos = [
        pbdkit.read_bag(b, robot=robot, objects={"mug": "/mug/pose"}, gripper_topic="/gripper")
        for b in bags
    ]
    reference = demonstrated_grasp(robot, demos)
    spread = np.array(
        [
            grasp_error(
                grasp_in_mug(robot, d.joints[closing_sample(d)], d.objects["mug"]), reference
            )
            for d in demos
        ]
    )

    # 3. Learn the pose skill and, from the same bags, the position-only skill.
    skill = pbdkit.Skill.learn(demos, robot, max_components=15)
    position_only = pbdkit.Skill.learn(demos, robot, max_components=15, orientation=False)
    skill.save(out / "skill.npz")
    position_only.save(out / "skill_position_only.npz")

    # 4. Both over 20 new mug poses, each reproduced from "ready" within Franka's limits.
    mugs = new_mugs(np.random.default_rng(1), N_NEW)
    errors = {
        "pose (orientation=True)": grasp_errors(skill, robot, mugs, reference),
        "position only (False)": grasp_errors(position_only, robot, mugs, reference),
    }
    np.savez(
        out / "grasps.npz",
        mugs=np.stack(mugs),
        demonstrated=reference,
        pose=errors["pose (orientation=True)"],
        position_only=errors["position only (False)"],
    )

    # 5. The first new mug again: the trajectory for a joint trajectory controller, with the
    #    velocities and accelerations of its timing (the controller's splines then follow the
    #    timed motion).
    mug = mugs[0]
    res = skill.reproduce({"mug": mug}, q0=START)
    trajectory = out / "trajectory"
    t = skill.times(res)
    limits = MotionLimits.from_robot(robot, robot.n_joints)  # Franka's published limits
    pbdkit.write_trajectory_bag(
        trajectory,
        t,
        res.joints,
        robot.joint_names,
        gripper=res.gripper,
        velocities=res.velocities,
        accelerations=res.accelerations,
        limits=limits,  # checked as the arm checks its stream: refused rather than written
    )
    offline = motion_peaks(t, res.joints, limits)

    # 6. Online: the skill in the arm's 1 kHz loop, from "ready", every setpoint checked.
    setpoints, closed, online = run_online(skill, {"mug": mug}, SimulatedPanda(START, rng), limits)
    np.savez(
        out / "stream.npz",
        t=np.arange(len(setpoints)) / LOOP_HZ,
        q=setpoints,
        gripper=closed,
        mug=mug,
    )
    grasp_offline = grasp_error(
        grasp_in_mug(robot, res.joints[np.argmax(res.gripper)], mug), reference
    )
    grasp_online = grasp_error(grasp_in_mug(robot, setpoints[np.argmax(closed)], mug), reference)

    seen = np.array([d.objects["mug"] for d in demos])
    yaws = np.degrees(np.arctan2(seen[:, 1, 0], seen[:, 0, 0]))
    print(f"recorded {len(bags)} demonstration bags in {out}")
    print(
        f"read {len(demos)} demonstrations: {[d.n_steps for d in demos]} joint states, "
        f"mug x {seen[:, 0, 3].min():.3f}..{seen[:, 0, 3].max():.3f} m, "
        f"y {seen[:, 1, 3].min():.3f}..{seen[:, 1, 3].max():.3f} m, "
        f"yaw {yaws.min():.1f}..{yaws.max():.1f} deg"
    )
    print(
        "demonstrated grasp (fingertips in the mug's frame when the gripper closes, mean of the "
        f"bags): x, y, z, qw, qx, qy, qz = {np.round(xyz_wxyz(reference), 4).tolist()} "
        f"(quaternion w first); the bags within {spread[:, 0].max():.1f} mm and "
        f"{spread[:, 1].max():.2f} deg of it"
    )
    print(f"learned K per space: pose skill {skill.n_components}, position only ", end="")
    print(position_only.n_components)
    print(
        f"grasp over {N_NEW} new mug poses (x {MUG_X[0]}..{MUG_X[1]} m, y {MUG_Y[0]}..{MUG_Y[1]}"
        " m, yaw -90..90 deg; seeded), at the first step the gripper is closed, vs the "
        "demonstrated grasp in the mug's frame:"
    )
    print(f"  {'skill':<24}{'position mm':>16}{'orientation deg':>19}{'within':>10}{'within':>9}")
    print(
        f"  {'':<24}{'median':>9}{'max':>7}{'median':>11}{'max':>8}{'5 mm':>10}{'3 deg':>9}"
        f"{'both':>8}"
    )
    for name, e in errors.items():
        within_mm, within_deg = e[:, 0] <= TOLERANCE_MM, e[:, 1] <= TOLERANCE_DEG
        print(
            f"  {name:<24}{np.median(e[:, 0]):9.1f}{e[:, 0].max():7.1f}"
            f"{np.median(e[:, 1]):11.2f}{e[:, 1].max():8.2f}"
            f"{np.count_nonzero(within_mm):7d}/{N_NEW}{np.count_nonzero(within_deg):6d}/{N_NEW}"
            f"{np.count_nonzero(within_mm & within_deg):5d}/{N_NEW}"
        )
    print(
        f"new mug at x, y, z, qw, qx, qy, qz = {np.round(xyz_wxyz(mug), 4).tolist()} "
        "(m; quaternion w first)"
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
        f"grasp when the gripper closes: {grasp_online[0]:.1f} mm and {grasp_online[1]:.2f} deg "
        f"from the demonstrated grasp online ({grasp_offline[0]:.1f} mm, "
        f"{grasp_offline[1]:.2f} deg offline)"
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
