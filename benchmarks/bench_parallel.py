"""Trials in parallel: wall time of ``pbdkit evaluate --trials 20`` serially, with 1 and 2 workers.

The same evaluation (coaster task, teach seed 0, every controller, the cameras in the loop)
three ways: serial (no Dask), ``--workers 1`` and ``--workers 2`` (a Dask ``LocalCluster`` of
single-threaded processes, started inside the timing, as the command line does). The skill is
learned once, outside the timings. The results must be identical (checked); the target is
2 workers <= 0.6x the serial wall time on this 2-core machine.

Run: .venv/bin/python benchmarks/bench_parallel.py [--trials N] [--task T]
"""

from __future__ import annotations

import argparse
import json
import time

from _common import print_table

from pbdkit.sim import experiment as E

TARGET = 0.6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--task", default="coaster")
    args = ap.parse_args()
    ts = E.learn_task(args.task, seed=0)
    results, walls = {}, {}
    for label, workers in (("serial", None), ("1 worker", 1), ("2 workers", 2)):
        start = time.perf_counter()
        ev = E.evaluate(args.task, args.trials, 0, task_skill=ts, workers=workers)
        walls[label] = time.perf_counter() - start
        data = ev.as_dict()
        data.pop("learn_seconds")
        results[label] = json.dumps(data, sort_keys=True)
    same = len(set(results.values())) == 1
    runs = args.trials * len(E.controller_names(ts.skill.object_names))
    rows = [
        [label, f"{w:.1f} s", f"{w / walls['serial']:.2f}", f"{runs / w:.2f}",
         f"<= {TARGET}" if label == "2 workers" else ""]
        for label, w in walls.items()
    ]  # fmt: skip
    print(f"{args.task}: {args.trials} trials x {runs // args.trials} controllers, cameras")
    print_table(["run", "wall time", "vs serial", "runs per second", "target"], rows)
    print(f"results identical to the serial run: {same}")


if __name__ == "__main__":
    main()
