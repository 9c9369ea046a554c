"""Which uncertainty predicts where a skill fails (issue 39, item 2): the ROC AUC of each
candidate of ``Skill.uncertainty`` against the fused controller's failures under physics, on
the study's ``--full`` wide grids (11 x 11 placements per moving object, twice the demonstrated
range on each side; the other objects at their nominal place) of the three tasks.

The physics runs are what ``pbdkit study --full`` runs for its maps (the skill of 5
demonstrations of the task's teacher, seed ``--seed``, told the true positions); they are kept in
``--cache`` (JSON) so that the AUC can be computed again without them. A placement's failure is
the positive class; an AUC of 1 ranks every failure above every success, 0.5 is chance.

    .venv/bin/python benchmarks/uncertainty_auc.py [--seed 0] [--workers 2] [--grid 11]
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np
from _common import print_table
from sklearn.metrics import roc_auc_score

from pbdkit.apps._study import grid_placements
from pbdkit.sim import get_task
from pbdkit.sim._active import SPREAD_DEMOS, spread_placements, task_skill, teach_at
from pbdkit.sim._task_skill import learn_task
from pbdkit.sim._trials import TrialConditions, run_trials
from pbdkit.skill._uncertainty import PARTS, SCORE_PART

TASKS = ("coaster", "basin", "slot")


def _auc(y: np.ndarray, score: np.ndarray) -> str:
    return f"{roc_auc_score(y, score):.3f}" if 0 < y.sum() < y.size else "n/a"


def _successes(task: str, seed: int, grid: int, workers: int, cache: Path) -> dict:
    """The wide grids' placements and the fused controller's success at each (cached)."""
    path = cache / f"{task}_seed{seed}_grid{grid}.json"
    if path.exists():
        return json.loads(path.read_text())
    spec = get_task(task)
    ts = learn_task(spec, n_demos=5, seed=seed)
    out: dict = {"task": task, "seed": seed, "grid": grid, "points": []}
    for obj in spec.tracked_objects:
        _, _, placements = grid_placements(spec, obj, grid)
        trials = run_trials(
            ts,
            placements,
            ["fused"],
            TrialConditions(ground_truth=True, seed=seed),
            workers=workers,
        )
        for p, t in zip(placements, trials, strict=True):
            out["points"].append(
                {
                    "map": obj,
                    "objects": {k: np.asarray(v).tolist() for k, v in p.items()},
                    "success": bool(t.runs["fused"]["success"]),
                }
            )
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out))
    return out


def _excluded(task: str, seed: int, grid: int, workers: int, cache: Path) -> list[bool]:
    """Per grid point: does a skill of SPREAD_DEMOS demonstrations spread over the wide
    ranges fail there too (geometry no teacher fixes; cached)?"""
    path = cache / f"{task}_seed{seed}_grid{grid}_excluded.json"
    if path.exists():
        return list(json.loads(path.read_text())["excluded"])
    spec = get_task(task)
    demos = [d for d in teach_at(spec, spread_placements(spec, SPREAD_DEMOS, seed), seed) if d]
    ts = task_skill(spec, demos)
    out: list[bool] = []
    for obj in spec.tracked_objects:
        _, _, placements = grid_placements(spec, obj, grid)
        trials = run_trials(
            ts, placements, ["fused"], TrialConditions(ground_truth=True, seed=seed),
            workers=workers,
        )  # fmt: skip
        out += [not bool(t.runs["fused"]["success"]) for t in trials]
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"excluded": out, "n_demos": len(demos)}))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--grid", type=int, default=11)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--tasks", default=",".join(TASKS))
    parser.add_argument("--cache", type=Path, default=Path("benchmarks/.cache/uncertainty"))
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    rows = []
    for task in args.tasks.split(","):
        data = _successes(task, args.seed, args.grid, args.workers, args.cache)
        excluded = np.array(_excluded(task, args.seed, args.grid, args.workers, args.cache))
        spec = get_task(task)
        ts = learn_task(spec, n_demos=5, seed=args.seed)
        skill = ts.skill
        failed, scores = [], {p: [] for p in PARTS}
        t0 = time.perf_counter()
        for point in data["points"]:
            objects = {k: np.asarray(v) for k, v in point["objects"].items()}
            told = {k: objects[k] for k in skill.object_names}
            u = skill.uncertainty(told)
            failed.append(not point["success"])
            for p in PARTS:
                v = u.parts[p]
                scores[p].append(1e9 if math.isinf(v) else v)
        seconds = (time.perf_counter() - t0) / len(data["points"])
        parts_path = args.cache / f"{task}_seed{args.seed}_grid{args.grid}_parts.json"
        parts_path.write_text(json.dumps({"failed": failed, "parts": scores}))
        y = np.array(failed)
        kept = ~excluded
        aucs = [_auc(y[kept], np.array(scores[p])[kept]) for p in PARTS]
        every = [_auc(y, np.array(scores[p])) for p in PARTS]
        rows.append(
            [
                task,
                f"{int(kept.sum())} ({int(excluded.sum())} left out)",
                f"{int(y[kept].sum())} ({int(y.sum())})",
                *(f"{a} ({b})" for a, b in zip(aucs, every, strict=True)),
                f"{seconds * 1000:.0f} ms",
            ]
        )
    print(
        f"ROC AUC of each uncertainty against the fused controller's failures, wide grids "
        f"{args.grid} x {args.grid} per moving object, teach seed {args.seed} "
        f"(the score is {SCORE_PART!r}); the grid's points where a skill of {SPREAD_DEMOS} "
        "demonstrations spread over it fails too are left out (in brackets: with them)"
    )
    print_table(["task", "placements", "failures", *PARTS, "per placement"], rows)


if __name__ == "__main__":
    main()
