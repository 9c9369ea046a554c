"""Benchmark: Skill.learn with its defaults (issue 34), against scikit-learn's BIC sweep.

Workloads:

- ``coaster``: the demonstrations of ``benchmarks/bench_skill.py`` (5 synthetic glass-to-coaster
  demonstrations of about 1000 samples on the Katana, 3 spaces), the workload of design.md's
  learning target;
- ``coaster (simulated teacher)``: the simulated teacher's 5 demonstrations of the paper's
  coaster task (``pbdkit.sim.learn_task("coaster", seed=0).demos``);
- ``Panda 15 x 900``: ``pbdkit.datasets.reach_grasp_return`` on the Franka Panda of the arm zoo
  at 100 Hz, 15 demonstrations of up to 900 samples, 2 objects (the box, and a place to put it).

Rows per workload: ``Skill.learn``'s defaults (aligned in time, K by leaving one demonstration
out, calibrated covariances), and the same without alignment and calibration (the defaults
before issue 34), with a fixed K = 20 for every space. The peer, measured in the same run on
the same spaces and the same 100 steps per demonstration that pbdkit's EM is given: scikit-
learn ``GaussianMixture`` (default k-means initialisation), BIC over K = 1..10 per space.

BLAS on one thread; medians of ``--repeat`` runs.

Run: ``.venv/bin/python benchmarks/bench_learn.py [--repeat N]`` (about a minute).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
from _common import fmt_time, median_time, print_table
from bench_skill import make_demos, sklearn_bic_sweep
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from arm_zoo import ARMS

from pbdkit import Skill
from pbdkit.datasets import reach_grasp_return
from pbdkit.robots import katana

STEPS_PER_DEMO = 100  # Skill.learn's fit_samples


def peer_spaces(skill: Skill, demos: list) -> dict[str, np.ndarray]:
    """The spaces the skill fitted, at 100 evenly spaced steps per demonstration."""
    data = skill.training_data(demos)
    steps = np.unique(np.round(np.linspace(0, skill.n_steps - 1, STEPS_PER_DEMO)).astype(int))
    return {k: v[:, steps].reshape(-1, v.shape[2]) for k, v in data.items()}


def workloads() -> list[tuple[str, list, object]]:
    out: list[tuple[str, list, object]] = []
    robot = katana()
    out.append(("coaster (bench_skill's teacher)", make_demos(robot, np.random.default_rng(0)),
                robot))  # fmt: skip
    from pbdkit.sim import learn_task

    out.append(("coaster (simulated teacher)", learn_task("coaster", seed=0).demos, robot))
    arm = ARMS["panda"]
    panda = arm.robot()
    data = reach_grasp_return(panda, arm.center, arm.home, rate=100.0, n_demos=15, seed=0,
                              place_center=(0.45, 0.25, 0.1))  # fmt: skip
    longest = max(d.n_steps for d in data.demos)
    out.append((f"Panda 15 x {longest} samples, 2 objects", data.demos, panda))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7, help="runs per measurement (median)")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    rows = []
    for name, demos, robot in workloads():
        variants = {
            "defaults": {},
            "no alignment, no calibration": {"align": False, "calibrate": False},
            "fixed K = 20": {"n_components": 20},
        }
        with threadpool_limits(limits=1, user_api="blas"):
            skill = Skill.learn(demos, robot)
            data = peer_spaces(skill, demos)
            t_peer = median_time(
                lambda d=data: sklearn_bic_sweep(d), repeat=max(1, args.repeat // 2)
            )
            k_peer = sklearn_bic_sweep(data)
            for label, kw in variants.items():
                t = median_time(
                    lambda d=demos, r=robot, kw=kw: Skill.learn(d, r, **kw), repeat=args.repeat
                )
                k = Skill.learn(demos, robot, **kw).n_components_
                rows.append([
                    name, label, "/".join(str(v) for v in k.values()), fmt_time(t),
                    fmt_time(t_peer), "/".join(str(v) for v in k_peer.values()),
                    f"{t_peer / t:.1f}x",
                ])  # fmt: skip
        print(f"{name} done", file=sys.stderr, flush=True)
    print(f"\nSkill.learn, medians of {args.repeat} runs (the peer: {max(1, args.repeat // 2)}); "
          "BLAS 1 thread")  # fmt: skip
    print_table(
        ["workload", "Skill.learn", "K per space", "time", "sklearn BIC sweep 1..10",
         "its K", "peer / pbdkit"],
        rows,
    )  # fmt: skip


if __name__ == "__main__":
    main()
