"""`pbdkit ros sim` + `pbdkit ros run` on the coaster task over a real ROS 2 graph (issue 37):
N placements with `--perturb move`, each in its own private network namespace (root) or on a
localhost graph; success as the sim judges it (`pbdkit evaluate --online`'s judge) and the worst
v/a/j the sim's controller received, beside `pbdkit evaluate --online --perturb move` of the
same skill on the same placements (the simulator's own loop, no graph).

    .venv/bin/python benchmarks/ros_coaster.py --placements 20

The skill: `pbdkit teach --task coaster` (5 demonstrations, seed 0) and `pbdkit learn`.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pbdkit.ros._graph import private_graph_env

HERE = Path(__file__).resolve().parent
OBJECTS = ["--object", "glass=/objects/glass", "--object", "coaster=/objects/coaster"]


def _pbdkit(*args: str) -> list[str]:
    return [sys.executable, "-m", "pbdkit", *args]


def one(skill: Path, placement: int, work: Path, latency: float | None = None) -> dict:
    """One placement: the sim and the run (``--latency``: stamped) in two processes on a
    private graph."""
    report = work / f"report_{placement}.json"
    sim_cmd = _pbdkit("ros", "sim", "--task", "coaster", "--placement", str(placement),
                      "--perturb", "move", "--skill", str(skill), "--exit-after-run",
                      "--report", str(report), "--interpolate-from-desired-state")  # fmt: skip
    run_cmd = _pbdkit("ros", "run", str(skill), "--controller", "arm_controller", *OBJECTS,
                      "--grasped", "glass", "--gripper-controller", "gripper_controller",
                      "--gripper-joint", "gripper:0:1", "--timeout", "15")  # fmt: skip
    if latency is not None:
        run_cmd += ["--latency", str(latency)]
    script = (
        "import subprocess\n"
        f"sim = subprocess.Popen({sim_cmd!r}, stdout=subprocess.PIPE, text=True)\n"
        "for line in sim.stdout:\n"
        "    if line.startswith('ros sim:'):\n"
        "        break\n"
        f"run = subprocess.run({run_cmd!r}, capture_output=True, text=True)\n"
        "sim.communicate(timeout=60)\n"
        "print('RUN', run.returncode, run.stdout.count('re-planned'))\n"
    )
    env = private_graph_env(f"ros_coaster_{placement}")
    cmd = [sys.executable, "-c", script]
    if os.geteuid() == 0 and shutil.which("unshare"):
        cmd = ["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$0" "$@"', *cmd]
    start = time.monotonic()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    line = [x for x in done.stdout.splitlines() if x.startswith("RUN")]
    got = json.loads(report.read_text()) if report.exists() else {"success": False}
    got["run_exit"] = int(line[0].split()[1]) if line else None
    got["replans"] = int(line[0].split()[2]) if line else None
    got["wall_s"] = time.monotonic() - start
    return got


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--placements", type=int, default=20)
    parser.add_argument("--out", type=Path, default=None, help="Write the rows as JSON.")
    parser.add_argument(
        "--latency", type=float, default=None, help="pbdkit ros run --latency (default: none)."
    )
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="ros_coaster_"))
    demos, skill = work / "demos.npz", work / "skill.npz"
    subprocess.run(_pbdkit("teach", "--task", "coaster", "--out", str(demos)), check=True,
                   capture_output=True)  # fmt: skip
    subprocess.run(_pbdkit("learn", str(demos), "--out", str(skill)), check=True,
                   capture_output=True)  # fmt: skip
    rows = []
    for p in range(args.placements):
        got = one(skill, p, work, args.latency)
        rows.append(got)
        print(
            f"placement {p:2d}: success {got['success']!s:5}  run exit {got['run_exit']}  "
            f"re-plans {got['replans']}  received v/a/j "
            f"{got.get('peak_velocity_ratio', float('nan')):.3f}/"
            f"{got.get('peak_acceleration_ratio', float('nan')):.3f}/"
            f"{got.get('peak_jerk_ratio', float('nan')):.3f}  "
            f"following {got.get('following_error_rad', float('nan')):.4f} rad  "
            f"{got['wall_s']:.1f} s",
            flush=True,
        )
    ok = sum(bool(r["success"]) for r in rows)
    worst = {
        k: max(r.get(f"peak_{k}_ratio", np.nan) for r in rows)
        for k in ("velocity", "acceleration", "jerk")
    }
    evaluated = subprocess.run(
        _pbdkit("evaluate", "--task", "coaster", "--trials", str(args.placements), "--online",
                "--perturb", "move", "--ground-truth", "--controller", "fused", "--json"),
        capture_output=True, text=True,
    )  # fmt: skip
    print()
    stamped = "" if args.latency is None else f", --latency {args.latency:g}"
    print("| chain | success | worst v / a / j received (of the limits) |")
    print("| --- | --- | --- |")
    print(
        f"| `ros sim` + `ros run{stamped}` (graph) | {ok}/{len(rows)} | "
        f"{worst['velocity']:.3f} / {worst['acceleration']:.3f} / {worst['jerk']:.3f} |"
    )
    print(f"| `evaluate --online` (no graph) | see below | |\n{evaluated.stdout[-400:]}")
    if args.out is not None:
        args.out.write_text(json.dumps(rows, indent=1, default=str))


if __name__ == "__main__":
    main()
