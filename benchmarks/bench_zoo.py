"""Benchmark: skills on arms no one here wrote, over a narrow and a wide table (issue 21).

The arm zoo (``tests/arm_zoo.py``: UR5, Panda, Kinova JACO2 6-DOF, xArm7, SO-100, vendored
from example-robot-data): for each arm, each placement square it reaches (15 cm: boxes 5-20
cm apart; 40 cm: 20-56 cm apart) and teach seeds 0-4, five reach-grasp-return demonstrations
(``pbdkit.datasets.reach_grasp_return``: they agree only at the grasp) and five new box
placements inside their hull. The measure: the fused hand's distance to the box at the first
gripper close.

Methods, measured in the same run on the same demonstrations:

- ``auto``: ``Skill.learn``'s default, K by leaving one demonstration out, each moment's error
  against the demonstrations' spread at that moment (``cv_scale="local"``);
- ``auto-pooled``: the same against their spread pooled over time (pbdkit's earlier default);
- ``bic``: the effective-sample-size BIC (the paper picks K by BIC).

Per (arm, spread): the K chosen per space (range over the seeds) and why (for ``auto``, on
seed 0: the best K's score and the chosen one's), the grasp error (median, 90th percentile,
worst over 25 placements), the fused reproduction's stretch (``res.stretch``: how much longer
than demonstrated the motion limits make it, median over the seeds) and the learning time.

Run: ``.venv/bin/python benchmarks/bench_zoo.py [--seeds N]`` (about 4 minutes).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from unittest import mock

import numpy as np
from _common import print_table

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from arm_zoo import ARMS, grasp_errors

from pbdkit import Skill
from pbdkit.prob import GMM
from pbdkit.prob._selection import CV_TOLERANCE

METHODS = ("auto", "auto-pooled", "bic")


def learn(method: str, demos: list, robot: object) -> Skill:
    if method == "auto":
        return Skill.learn(demos, robot)  # type: ignore[arg-type]
    if method == "bic":
        return Skill.learn(demos, robot, n_components="bic")  # type: ignore[arg-type]
    with mock.patch.dict(GMM.__init__.__kwdefaults__, {"cv_scale": "pooled"}):
        return Skill.learn(demos, robot)  # type: ignore[arg-type]


def why(skill: Skill) -> str:
    """The chosen K per space, and the best K's score against the chosen one's."""
    parts = []
    for name, sel in skill.selection_.items():
        best = float(sel.scores[sel.candidates.index(sel.best)])
        chosen = float(sel.scores[sel.candidates.index(sel.chosen)])
        parts.append(f"{name} {sel.chosen}: {chosen:.2f} vs best K {sel.best}: {best:.2f}")
    return "; ".join(parts)


def k_range(values: list[dict[str, int]]) -> str:
    names = list(values[0])
    return " / ".join(f"{n} {min(v[n] for v in values)}-{max(v[n] for v in values)}" for n in names)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    rows, why_rows, summary = [], [], {m: [] for m in METHODS}
    for name, arm in ARMS.items():
        robot = arm.robot()
        for spread in arm.spreads:
            ks = {m: [] for m in METHODS}
            errs = {m: [] for m in METHODS}
            stretch, secs = [], []
            for seed in range(args.seeds):
                data = arm.demos(robot, spread, seed)
                boxes = data.placements(5, seed=seed)
                for method in METHODS:
                    start = time.perf_counter()
                    skill = learn(method, data.demos, robot)
                    if method == "auto":
                        secs.append(time.perf_counter() - start)
                        if seed == 0:
                            why_rows.append([name, f"{100 * spread:.0f} cm", why(skill)])
                        for box in boxes[:1]:
                            res = skill.reproduce({data.object_name: box})
                            stretch.append(float(res.stretch))
                    ks[method].append(skill.n_components)
                    errs[method].extend(grasp_errors(skill, robot, data, boxes))
            for method in METHODS:
                e = 1e3 * np.array(errs[method])
                summary[method].append(e)
                rows.append(
                    [
                        name,
                        f"{100 * spread:.0f} cm",
                        method,
                        k_range(ks[method]),
                        f"{np.median(e):.2f}",
                        f"{np.percentile(e, 90):.2f}",
                        f"{e.max():.1f}",
                        f"{np.median(stretch):.2f}" if method == "auto" else "",
                        f"{np.median(secs):.2f} s" if method == "auto" else "",
                    ]
                )
            print(f"{name} {spread} done", file=sys.stderr, flush=True)
    print(
        f"\nReach-grasp-return on third-party arms, seeds 0-{args.seeds - 1}, 5 placements "
        f"each inside the demonstrated hull (CV tolerance {CV_TOLERANCE:g}):"
    )
    print_table(
        [
            "arm",
            "square",
            "method",
            "K per space (seeds)",
            "grasp error median (mm)",
            "90th pct",
            "worst",
            "stretch",
            "learn",
        ],
        rows,
    )
    print("\nWhy (auto, seed 0): each space's chosen K and score, against the best K's")
    print_table(["arm", "square", "selection_"], why_rows)
    print("\nAll arms and squares:")
    base = np.median(np.concatenate(summary["auto"]))
    print_table(
        ["method", "median (mm)", "x auto's", "90th pct", "worst", "placements within 5 mm"],
        [
            [
                m,
                f"{np.median(np.concatenate(v)):.2f}",
                f"{np.median(np.concatenate(v)) / base:.1f}",
                f"{np.percentile(np.concatenate(v), 90):.2f}",
                f"{np.concatenate(v).max():.1f}",
                f"{100 * np.mean(np.concatenate(v) <= 5.0):.0f} %",
            ]
            for m, v in summary.items()
        ],
    )


if __name__ == "__main__":
    main()
