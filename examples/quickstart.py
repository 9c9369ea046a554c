"""Quickstart: the library on your own arm, from its URDF to a trajectory its controller plays.

Run:  python examples/quickstart.py [OUTPUT_FOLDER]   (default: a temporary folder)

Replace the URDF by your robot's and the synthesized demonstrations by your recordings
(``pbdkit.read_bag`` for ROS 2 bags, ``pbdkit.demonstration_from_csv`` for CSV logs); the rest
stays as it is. ``your_arm.py`` goes further (CSV logs, the online loop), ``docs/ros2.md`` runs
a skill live.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pbdkit
from pbdkit.datasets import reach_grasp_return


def main(out: Path) -> None:
    # Your arm: its URDF, the link the skill moves, its joint limits.
    robot = pbdkit.Robot.from_urdf(
        pbdkit.robots.katana_urdf_path(),
        tip="tool",
        joint_limits=pbdkit.robots.katana_joint_limits_path(),
    )
    # Five demonstrations: reach a box, grasp it, bring it back.
    home = [0.0, 1.7, -1.9, -1.2, 0.0]
    data = reach_grasp_return(robot, center=[0.3, 0.0, 0.05], home=home)
    # K per space chosen by cross-validation.
    skill = pbdkit.Skill.learn(data.demos, robot)
    skill.save(out / "skill.npz")
    # The box somewhere new: the trajectory, within the arm's limits.
    box = data.placements(1, seed=1)[0]
    result = skill.reproduce({"box": box})
    # For a ros2_control joint_trajectory_controller:
    pbdkit.write_trajectory_bag(
        out / "trajectory",
        skill.times(result),
        result.joints,
        robot.joint_names,
        gripper=result.gripper,
        velocities=result.velocities,
        accelerations=result.accelerations,
        limits=skill.motion_limits(),
    )
    # Live on the arm (docs/ros2.md):
    #   pbdkit ros run OUT/skill.npz --controller arm_controller \
    #       --object box=/box/pose
    closest = 1000 * float(result.task_errors["box"].min())
    print(f"K per space: {skill.n_components}")
    print(f"the hand comes within {closest:.2f} mm of the new box")
    print(f"wrote {out / 'skill.npz'} and {out / 'trajectory'}")


if __name__ == "__main__":
    if len(sys.argv) > 2:
        sys.exit("usage: python examples/quickstart.py [OUTPUT_FOLDER]")
    if len(sys.argv) == 2:
        folder = Path(sys.argv[1])
        folder.mkdir(parents=True, exist_ok=True)
        main(folder)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            main(Path(tmp))
