"""Benchmark: the cost of orientation. A pose skill against the position-only skill of the same
demonstrations, measured in the same run (issue 23).

Workload: the mug grasp of ``tests/pose_teacher.py`` on the 7-joint Panda: 5 demonstrations
(mug yaws -80 .. 80 degrees, 60 samples each, through 6-D inverse kinematics), one object
given as a pose, rescaled to 1000 steps; K chosen in 1..30 per space by leaving one
demonstration out (the default). Peers:

- ``Skill.learn(..., orientation=False)`` on the same demonstrations: the paper's skill (the
  mug's frame translates only; its task space {t, x - p} is 4-D against 7-D);
- ``Skill.reproduce`` of that skill for the same mug pose (the position-only fused loop, with
  Newton's term), against the oriented fused loop (:class:`PoseFusedStep`);
- the paper's bars for its own tasks: learn <= 1 s, reproduce <= 30 ms (design.md).

Both reproductions are within the Panda's velocity, acceleration and jerk limits (the default).
BLAS is limited to one thread (threadpoolctl). Times are medians.

Run: ``.venv/bin/python benchmarks/bench_pose.py [--repeat N]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from _common import fmt_time, median_time, print_table
from threadpoolctl import threadpool_limits

import pbdkit

# The pose teacher of the tests: one generator of mug grasps for tests and benchmark.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from pose_teacher import demonstrations, mug_pose


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    robot = pbdkit.robots.panda()
    demos = demonstrations(robot, seed=0)
    mug = mug_pose(0.5, 0.5, 0.03)
    with threadpool_limits(1):
        pose = pbdkit.Skill.learn(demos, robot)
        flat = pbdkit.Skill.learn(demos, robot, orientation=False)
        t_learn = median_time(lambda: pbdkit.Skill.learn(demos, robot), repeat=args.repeat)
        t_learn_flat = median_time(
            lambda: pbdkit.Skill.learn(demos, robot, orientation=False), repeat=args.repeat
        )
        t_rep = median_time(lambda: pose.reproduce({"mug": mug}), repeat=args.repeat * 3)
        t_rep_flat = median_time(lambda: flat.reproduce({"mug": mug}), repeat=args.repeat * 3)
        ctrl_opts = {"velocity_limit": None, "acceleration_limit": None, "jerk_limit": None}
        res = pose.reproduce({"mug": mug}, **ctrl_opts)

        def run_controller(skill: pbdkit.Skill) -> None:
            ctrl = skill.controller({"mug": mug}, **ctrl_opts)
            q = res.joints[0]
            while not ctrl.done:
                q = ctrl.step(q).q

        t_ctrl = median_time(lambda: run_controller(pose), repeat=args.repeat) / pose.n_steps
        t_ctrl_flat = median_time(lambda: run_controller(flat), repeat=args.repeat) / flat.n_steps
    print(f"K: pose skill {pose.n_components}, position-only {flat.n_components}")
    rows = [
        [
            "Skill.learn, 5 demos x 1000 steps, mug as a pose",
            fmt_time(t_learn),
            fmt_time(t_learn_flat),
            f"{t_learn / t_learn_flat:.2f}x",
            "orientation=False, same data",
        ],
        [
            "Skill.reproduce, 1000 steps, fused (6-D mug)",
            fmt_time(t_rep),
            fmt_time(t_rep_flat),
            f"{t_rep / t_rep_flat:.2f}x",
            "position-only skill, same pose",
        ],
        [
            "Controller.step, per step (no limits)",
            fmt_time(t_ctrl),
            fmt_time(t_ctrl_flat),
            f"{t_ctrl / t_ctrl_flat:.2f}x",
            "position-only skill",
        ],
    ]
    print_table(["workload", "pose", "peer", "pose / peer", "peer is"], rows)
    print(
        f"\nbars of the paper's tasks: learn <= 1 s ({np.round(t_learn, 3)} s here), "
        f"reproduce <= 30 ms ({t_rep * 1e3:.1f} ms here)"
    )


if __name__ == "__main__":
    main()
