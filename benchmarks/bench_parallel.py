"""Trials in parallel: wall time of ``pbdkit evaluate --trials 20`` serially, with 1 and 2 workers.

Two measurements of the same evaluation (coaster task, seed 0, every controller, the cameras
in the loop), each serial (no Dask), ``--workers 1`` and ``--workers 2`` (a Dask
``LocalCluster`` of single-threaded processes on this machine):

1. the command, end to end: ``pbdkit evaluate --task coaster --trials 20 --seed 0 --json F
   [--workers N]`` timed as a new process (imports, teaching and learning, the trials, the
   cluster's start and close). This is the figure of the target, 2 workers <= 0.6x;
2. the trials alone: :func:`pbdkit.sim.evaluate` in this process with the skill
   learned once beforehand, so the cluster's start and the workers' imports are not hidden
   behind the learning.

The results must be identical to the serial run's (checked, both ways). Medians of
``--repeat`` runs (default 1; the machine is noisy).

Run: .venv/bin/python benchmarks/bench_parallel.py [--trials N] [--task T] [--repeat R]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import print_table

from pbdkit.sim._evaluation import evaluate
from pbdkit.sim._task_skill import TaskSkill, learn_task
from pbdkit.skill._naming import controller_names

TARGET = 0.6
RUNS = (("serial", None), ("1 worker", 1), ("2 workers", 2))


def _comparable(data: dict[str, object]) -> str:
    data = dict(data)
    data.pop("learn_seconds", None)
    return json.dumps(data, sort_keys=True)


def _command(task: str, trials: int, workers: int | None, out: Path) -> tuple[float, str]:
    pbdkit = Path(sys.executable).with_name("pbdkit")
    cmd = [str(pbdkit), "evaluate", "--task", task, "--trials", str(trials), "--seed", "0"]
    cmd += ["--json", str(out)] + ([] if workers is None else ["--workers", str(workers)])
    out.unlink(missing_ok=True)
    start = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    return wall, _comparable(json.loads(out.read_text()))


def _in_process(ts: TaskSkill, task: str, trials: int, workers: int | None) -> tuple[float, str]:
    start = time.perf_counter()
    ev = evaluate(task, trials, 0, task_skill=ts, workers=workers)
    return time.perf_counter() - start, _comparable(ev.as_dict())


def _table(title: str, walls: dict[str, list[float]], runs: int, results: set[str]) -> None:
    med = {label: statistics.median(w) for label, w in walls.items()}
    rows = [
        [label, f"{m:.1f} s", f"{m / med['serial']:.2f}",
         f"{m / med['1 worker']:.2f}" if label != "serial" else "", f"{runs / m:.2f}",
         f"<= {TARGET}" if label == "2 workers" else ""]
        for label, m in med.items()
    ]  # fmt: skip
    print(title)
    print_table(["run", "wall time", "vs serial", "vs 1 worker", "runs per second", "target"], rows)
    # The runs of a repeat follow each other: their ratio is less exposed to the machine's
    # drift (its speed moved by 30 % within an hour) than the ratio of the medians.
    pairs = [p / s for p, s in zip(walls["2 workers"], walls["serial"], strict=True)]
    print(
        f"2 workers / serial, repeat by repeat: {', '.join(f'{r:.2f}' for r in pairs)} "
        f"(median {statistics.median(pairs):.2f})"
    )
    print(f"results identical to the serial run: {len(results) == 1}\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--task", default="coaster")
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    ts = learn_task(args.task, seed=0)
    runs = args.trials * len(controller_names(ts.skill.object_names))
    print(f"{args.task}: {args.trials} trials x {runs // args.trials} controllers, cameras\n")
    with tempfile.TemporaryDirectory() as tmp:
        walls: dict[str, list[float]] = {label: [] for label, _ in RUNS}
        results: set[str] = set()
        for _ in range(args.repeat):
            for label, workers in RUNS:
                wall, result = _command(args.task, args.trials, workers, Path(tmp) / "ev.json")
                walls[label].append(wall)
                results.add(result)
        _table("1. `pbdkit evaluate`, end to end (a new process)", walls, runs, results)
    walls = {label: [] for label, _ in RUNS}
    results = set()
    for _ in range(args.repeat):
        for label, workers in RUNS:
            wall, result = _in_process(ts, args.task, args.trials, workers)
            walls[label].append(wall)
            results.add(result)
    _table("2. the trials alone (skill learned beforehand, in this process)", walls, runs, results)


if __name__ == "__main__":
    main()
