"""What checking and avoiding cost (issue 38): per posture and per reproduction, on the Katana
coaster skill and a Franka Panda reach-grasp-return skill, against ``Skill.reproduce`` without a
scene measured in the same run (the ratio).

- **Check**: ``skill.check(joints, scene)`` of the plain reproduction's joints (a lead-in plus
  the skill's steps), per run and per posture.
- **Scene, nothing near**: ``skill.reproduce(objects, scene=...)`` where the run keeps the
  margin: the plain run plus its check (the path is the same to the bit).
- **Obstacle avoided**: the same with a 5 cm box in the plain path's way (the passes of
  ``pbdkit.reproduction._avoid``), and the clearance they reach: on the Katana at mid-carry
  (``--perturb obstacle``'s), on the Panda at mid-reach, 10 cm nearer the base (on the path
  itself it would also sit in the forearm at the grasp, which comes down from above: no path
  that grasps the box keeps clear of it, and the run reports it infeasible).

Scenes: the Katana's is the coaster task's (table, shelf board and legs, the glass and the
coaster); the Panda's a table and the box it grasps. Medians of ``--repeat`` runs (quiet
machine, BLAS one thread).

    .venv/bin/python benchmarks/bench_collision.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import os
import warnings

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from _common import fmt_time, median_time, print_table

from pbdkit import Skill
from pbdkit.collision import Box, Scene
from pbdkit.datasets import reach_grasp_return
from pbdkit.robots import katana, panda
from pbdkit.sim import get_task
from pbdkit.sim._task_skill import teach


def _mid_carry(res: object) -> np.ndarray:
    own = ~res.lead_in  # type: ignore[attr-defined]
    closed = np.flatnonzero(res.gripper & own)  # type: ignore[attr-defined]
    return np.asarray(res.positions[(closed[0] + closed[-1]) // 2])  # type: ignore[attr-defined]


def _in_the_way(name: str, res: object) -> np.ndarray:
    """Where the obstacle goes (see the module docstring)."""
    if name.startswith("Katana"):
        return _mid_carry(res)
    own = np.flatnonzero(~res.lead_in)  # type: ignore[attr-defined]
    closes = np.flatnonzero(res.gripper & ~res.lead_in)[0]  # type: ignore[attr-defined]
    reach = np.asarray(res.positions[(own[0] + closes) // 2])  # type: ignore[attr-defined]
    return reach - np.array([0.10, 0.0, 0.0])


def cases() -> list[tuple[str, Skill, dict[str, np.ndarray], Scene]]:
    """(name, skill, objects, scene)."""
    spec = get_task("coaster")
    demos = teach(spec, 5, seed=0)
    katana_skill = Skill.learn(demos, katana())
    objects = {k: np.mean([d.objects[k] for d in demos], axis=0) for k in demos[0].objects}
    katana_scene = spec.scene(spec.full_placement(objects))
    robot = panda()
    home = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    data = reach_grasp_return(robot, (0.5, 0.0, 0.1), home, n_demos=5, seed=0)
    panda_skill = Skill.learn(data.demos, robot)
    box = np.asarray(data.boxes, dtype=np.float64).mean(axis=0)
    panda_scene = Scene(
        [Box((1.2, 1.2, 0.04), (0.4, 0.0, -0.12), name="table")],
        objects={"box": Box((0.04, 0.04, 0.04), (0.0, 0.0, -0.02))},
    )
    return [
        ("Katana coaster", katana_skill, objects, katana_scene),
        ("Panda reach-grasp-return", panda_skill, {"box": box}, panda_scene),
    ]


def measure(
    name: str, skill: Skill, objects: dict[str, np.ndarray], scene: Scene, repeat: int
) -> tuple[list[str], list[str]]:
    """One skill's row of each table."""
    told = {k: objects[k] for k in skill.object_names}
    plain = skill.reproduce(told)
    n = len(plain.t)
    t_check = median_time(lambda: skill.check(plain.joints, scene, objects=told), repeat=repeat)
    check_row = [name, str(n), fmt_time(t_check), fmt_time(t_check / n), str(len(scene.shapes))]
    t_plain = median_time(lambda: skill.reproduce(told), repeat=repeat)
    far = Scene(
        [Box((0.05, 0.05, 0.05), _mid_carry(plain) + np.array([0.0, 1.5, 0.0]), name="far")]
    )
    near = skill.reproduce(told, scene=far)
    t_near = median_time(lambda: skill.reproduce(told, scene=far), repeat=repeat)
    same = bool(np.array_equal(near.joints, plain.joints))
    blocked = Scene(
        [Box((0.05, 0.05, 0.05), _in_the_way(name, plain), name="obstacle")],
        objects=scene.objects,
    )
    avoided = skill.reproduce(told, scene=blocked)
    t_avoid = median_time(lambda: skill.reproduce(told, scene=blocked), repeat=repeat)
    assert avoided.clearance is not None
    run_row = [
        name,
        fmt_time(t_plain),
        f"{fmt_time(t_near)} ({t_near / t_plain:.2f}x, same path: {same})",
        f"{fmt_time(t_avoid)} ({t_avoid / t_plain:.2f}x)",
        f"{avoided.clearance.min() * 1000:.1f} mm, {len(avoided.collisions)} contacts",
    ]
    return check_row, run_row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    rows_check, rows_run = [], []
    for name, skill, objects, scene in cases():
        check_row, run_row = measure(name, skill, objects, scene, args.repeat)
        rows_check.append(check_row)
        rows_run.append(run_row)
    print("skill.check of a reproduction's joints, median of", args.repeat)
    print_table(["skill", "postures", "per run", "per posture", "obstacles"], rows_check)
    print()
    print("Skill.reproduce, median of", args.repeat, "(ratio to the plain run, measured here)")
    print_table(
        [
            "skill",
            "no scene (peer)",
            "a box 1.5 m away (nothing near)",
            "obstacle in the way, avoided",
            "its smallest clearance",
        ],
        rows_run,
    )


if __name__ == "__main__":
    main()
