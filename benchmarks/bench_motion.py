"""Benchmark: motion a real arm accepts (issue 20), against the code before it, in the same run.

Workload: the simulated teacher's skills, both tasks, teach seeds 0-9 (5 demonstrations each,
``Skill.learn``'s defaults), the demonstrations' mean placement and three placements 4 cm from
it (80 reproductions). For every reproduction, played over ``skill.times(res)``:

- peak velocity, acceleration and jerk over the Katana's limits (1.19 rad/s, 6 rad/s^2,
  60 rad/s^3): divided differences at the trajectory's own samples, padded with rest at both
  ends (``pbdkit.motion.motion_peaks``);
- reversals: a joint reversing between two consecutive steps each faster than 25 % of its
  velocity limit (``pbdkit.motion._limits.count_reversals``);
- the hand's distance to o + x_hat at each object's tightest step (mm);
- the cost of ``Skill.reproduce`` per step (BLAS on one thread, median of 5 calls).

Peer, measured in the same run: the code before this change (``--baseline``, default the commit
before it, 8aa78c9), checked out into a temporary git worktree and run in a subprocess on the
same demonstrations (written to a file by this process): its ``Skill.learn`` and
``Skill.reproduce`` with their defaults (velocity-bounded Table II, Gauss-Newton with the line
search, steps spread over the skill's duration). The baseline and the new code are timed
alternately, ``--rounds`` times, and the medians compared.

Then the online controller (new code only): commands fed back with 1e-5 rad of encoder noise
and the 1 kHz stream at the mean placement (peaks, reversals, the cost of ``Controller.step``:
median, and the largest, a plan).

Run: ``.venv/bin/python benchmarks/bench_motion.py [--seeds N] [--baseline COMMIT]`` (about 6
minutes; needs git and the repository's history).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from _common import print_table
from threadpoolctl import threadpool_limits

from pbdkit import Skill
from pbdkit.data._demonstration import save_demonstrations
from pbdkit.motion._limits import MotionLimits, count_reversals, motion_peaks
from pbdkit.robots import katana
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import constrained_objects, teach

ROOT = Path(__file__).resolve().parent.parent
TASKS = ("coaster", "basin")

# Run in the baseline's worktree (its own pbdkit first on sys.path): learn, reproduce, time, and
# return the joint trajectories with their times. Uses nothing of the new code.
PEER = r"""
import json, sys, time, warnings
import numpy as np
from threadpoolctl import threadpool_limits
warnings.simplefilter("ignore")
from pbdkit import Skill
try:  # the baseline's layout (8aa78c9); the house's restructuring moved it
    from pbdkit.demos import load_demonstrations
except ImportError:
    from pbdkit.data._demonstration import load_demonstrations
from pbdkit.robots import katana
import inspect
# Skill.learn's objects= was renamed task_objects= after the baseline.
KEY = "task_objects" if "task_objects" in inspect.signature(Skill.learn).parameters else "objects"
job = json.loads(sys.argv[1])
out = {}
with threadpool_limits(1):
    for case in job["cases"]:
        demos = load_demonstrations(case["demos"])
        skill = Skill.learn(demos, katana(), **{KEY: case["objects"]})
        runs = []
        for placement in case["placements"]:
            objects = {k: np.array(v) for k, v in placement.items()}
            res = skill.reproduce(objects)
            times = []
            for _ in range(job["repeat"]):
                start = time.perf_counter()
                skill.reproduce(objects)
                times.append(time.perf_counter() - start)
            runs.append({"joints": res.joints.tolist(), "t": skill.times(res).tolist(),
                         "steps": res.t.tolist(), "positions": res.positions.tolist(),
                         "seconds": float(np.median(times)), "n_steps": skill.n_steps})
        out[case["name"]] = runs
print(json.dumps(out))
"""


def placements(skill: Skill, demos: list) -> list[dict[str, np.ndarray]]:
    mean = {k: np.mean([d.objects[k] for d in demos], axis=0) for k in skill.object_names}
    off = [0.04 * np.array([np.cos(a), np.sin(a), 0.0]) for a in (0.3, 2.4, 4.5)]
    return [mean, *({k: v + o for k, v in mean.items()} for o in off)]


def tight_error(skill: Skill, positions: np.ndarray, steps: np.ndarray, objects: dict) -> float:
    """The hand's largest distance (mm) from o + x_hat at each object's tightest step."""
    c = skill.constraints()
    errs = []
    for k in skill.object_names:
        tight = int(np.argmin(np.trace(c.task_cov[k], axis1=1, axis2=2)))
        i = int(np.flatnonzero(np.asarray(steps) == tight)[-1])
        errs.append(np.linalg.norm(positions[i] - objects[k] - c.task_mean[k][tight]))
    return 1e3 * float(max(errs))


def baseline_worktree(commit: str, where: Path) -> Path:
    path = where / "baseline"
    subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(path), commit],
        check=True,
        capture_output=True,
    )
    return path


def run_peer(src: Path, job: dict) -> dict:
    env = {"PYTHONPATH": str(src / "src"), "PATH": "/usr/bin:/bin"}
    out = subprocess.run(
        [sys.executable, "-c", PEER, json.dumps(job)],
        check=True,
        capture_output=True,
        text=True,
        env=env,
        cwd=str(src),
    )
    return dict(json.loads(out.stdout))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--baseline", default="8aa78c9")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    robot = katana()
    limits = MotionLimits.from_robot(robot, 5)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        cases, skills = [], {}
        for task in TASKS:
            for seed in range(args.seeds):
                demos = teach(task, 5, seed=seed)
                path = tmp / f"{task}{seed}.npz"
                save_demonstrations(demos, path)
                objects = constrained_objects(get_task(task))
                skill = Skill.learn(demos, robot, task_objects=objects)
                pls = placements(skill, demos)
                name = f"{task} {seed}"
                skills[name] = (skill, pls)
                cases.append(
                    {
                        "name": name,
                        "demos": str(path),
                        "objects": list(skill.object_names),
                        "placements": [{k: v.tolist() for k, v in p.items()} for p in pls],
                    }
                )
        src = baseline_worktree(args.baseline, tmp)
        try:
            job = {"cases": cases, "repeat": args.repeat}
            peer_rounds, new_rounds, peer = [], [], {}
            for _ in range(args.rounds):
                peer = run_peer(src, job)
                peer_rounds.append(
                    [r["seconds"] / r["n_steps"] for rs in peer.values() for r in rs]
                )
                times = []
                with threadpool_limits(1):
                    for skill, pls in skills.values():
                        for objects in pls:
                            skill.reproduce(objects)
                            t = []
                            for _ in range(args.repeat):
                                start = time.perf_counter()
                                skill.reproduce(objects)
                                t.append(time.perf_counter() - start)
                            times.append(float(np.median(t)) / skill.n_steps)
                new_rounds.append(times)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(src)],
                check=False,
                capture_output=True,
            )
    rows = []
    summary: dict[str, dict[str, list[float]]] = {}
    for name, (skill, pls) in skills.items():
        task = name.split()[0]
        for i, objects in enumerate(pls):
            res = skill.reproduce(objects)
            t = skill.times(res)
            new = motion_peaks(t, res.joints, limits)
            before = peer[name][i]
            bq, bt = np.array(before["joints"]), np.array(before["t"])
            old = motion_peaks(bt, bq, limits)
            rev_new = count_reversals(res.joints, np.diff(t), limits.velocity)
            rev_old = count_reversals(bq, np.diff(bt), limits.velocity)
            err_new = tight_error(skill, res.positions, res.t, objects)
            err_old = tight_error(
                skill, np.array(before["positions"]), np.array(before["steps"]), objects
            )
            s = summary.setdefault(task, {})
            for key, value in (
                ("acc_old", old.acceleration_abs),
                ("acc_new", new.acceleration_abs),
                ("jerk_old", old.jerk_abs),
                ("jerk_new", new.jerk_abs),
                ("worst_new", new.worst),
                ("rev_old", rev_old),
                ("rev_new", rev_new),
                ("err_old", err_old),
                ("err_new", err_new),
                ("stretch", res.stretch),
            ):
                s.setdefault(key, []).append(float(value))
    for task, s in summary.items():

        def rng(key: str, fmt: str = ".1f", s: dict[str, list[float]] = s) -> str:
            v = np.array(s[key])
            return f"{np.median(v):{fmt}} ({v.min():{fmt}}-{v.max():{fmt}})"

        rows.append(
            [
                task,
                rng("acc_old"),
                rng("acc_new", ".2f"),
                rng("jerk_old", ".0f"),
                rng("jerk_new", ".1f"),
                f"{max(s['worst_new']):.3f}",
                f"{sum(r > 0 for r in s['rev_old'])} / {int(sum(s['rev_old']))}",
                f"{sum(r > 0 for r in s['rev_new'])} / {int(sum(s['rev_new']))}",
                rng("err_old", ".2f"),
                rng("err_new", ".2f"),
                rng("stretch", ".3f"),
            ]
        )
    n = len(next(iter(skills.values()))[1])
    print(f"\nReproductions: {len(skills)} skills x {n} placements, played over skill.times(res)")
    print_table(
        [
            "task",
            "peak acc. before (rad/s^2), median (range)",
            "after",
            "peak jerk before (rad/s^3)",
            "after",
            "worst ratio to a limit, after",
            "runs with reversals / reversals, before",
            "after",
            "tight-step error before (mm)",
            "after",
            "stretch of the skill's timing",
        ],
        rows,
    )
    peer_med = [float(np.median(r)) for r in peer_rounds]
    new_med = [float(np.median(r)) for r in new_rounds]
    ratio = [a / b for a, b in zip(new_med, peer_med, strict=True)]
    n_runs = sum(len(p) for _, p in skills.values())
    print(
        f"\nSkill.reproduce per step, median over the {n_runs} reproductions, {args.rounds} "
        "rounds interleaved:"
    )
    print_table(
        ["round", "before (baseline)", "after", "after / before (target <= 1.5)"],
        [
            [str(k + 1), f"{1e6 * b:.1f} us", f"{1e6 * a:.1f} us", f"{r:.2f}"]
            for k, (b, a, r) in enumerate(zip(peer_med, new_med, ratio, strict=True))
        ]
        + [
            [
                "median",
                f"{1e6 * np.median(peer_med):.1f} us",
                f"{1e6 * np.median(new_med):.1f} us",
                f"{np.median(ratio):.2f}",
            ]
        ],
    )

    # Online: commands under encoder noise, and the 1 kHz stream at the mean placement.
    rng_noise = np.random.default_rng(0)
    worst_cmd = worst_stream = 0.0
    reversals = 0
    step_costs: list[float] = []
    with_objects: list[float] = []
    plan_costs: list[float] = []
    for skill, pls in skills.values():
        for i, objects in enumerate(pls):
            ctrl = skill.controller(objects)
            q = skill.constraints().joint_mean[0] + rng_noise.normal(0.0, 0.02, 5)
            measured = q + rng_noise.normal(0.0, 1e-5, 5)
            rows_q = [measured]
            first = True
            while not ctrl.done:
                start = time.perf_counter()
                cmd = ctrl.step(measured)
                (plan_costs if first else step_costs).append(time.perf_counter() - start)
                first = False
                rows_q.append(cmd.q)
                measured = cmd.q + rng_noise.normal(0.0, 1e-5, 5)
            cmds = np.array(rows_q)
            worst_cmd = max(
                worst_cmd, motion_peaks(ctrl.dt * np.arange(len(cmds)), cmds, limits).worst
            )
            reversals += count_reversals(cmds, ctrl.dt, limits.velocity)
            if i == 0:
                # The README's loop: the objects passed on every call, unchanged.
                ctrl = skill.controller(objects)
                given = {k: np.asarray(v, dtype=np.float64) for k, v in objects.items()}
                measured = q + rng_noise.normal(0.0, 1e-5, 5)
                first = True
                while not ctrl.done:
                    start = time.perf_counter()
                    cmd = ctrl.step(measured, objects=given)
                    if not first:
                        with_objects.append(time.perf_counter() - start)
                    first = False
                    measured = cmd.q + rng_noise.normal(0.0, 1e-5, 5)
                ctrl = skill.controller(objects)
                stream = ctrl.stream(1000.0)
                measured = q + rng_noise.normal(0.0, 1e-5, 5)
                sp = [measured]
                while not stream.done:
                    sp.append(stream.step(measured))
                    measured = sp[-1] + rng_noise.normal(0.0, 1e-5, 5)
                s_arr = np.array(sp)
                worst_stream = max(
                    worst_stream, motion_peaks(1e-3 * np.arange(len(s_arr)), s_arr, limits).worst
                )
                reversals += count_reversals(s_arr, 1e-3, limits.velocity)
    print(
        "\nOnline (new code): commands fed back with 1e-5 rad of noise, 1 kHz stream at the "
        "mean placement"
    )
    print_table(
        ["measurement", "value"],
        [
            ["worst ratio to a limit, commands at ctrl.dt", f"{worst_cmd:.3f}"],
            ["worst ratio to a limit, 1 kHz stream", f"{worst_stream:.3f}"],
            ["reversals between fast steps", str(reversals)],
            ["Controller.step, median (between plans)", f"{1e6 * np.median(step_costs):.1f} us"],
            [
                "Controller.step with the unchanged objects on every call",
                f"{1e6 * np.median(with_objects):.1f} us "
                f"({np.median(with_objects) / np.median(step_costs):.2f}x; issue 35: <= 1.2x)",
            ],
            [
                "Controller.step, first call (plans the run)",
                f"{1e3 * np.median(plan_costs):.1f} ms median",
            ],
        ],
    )


if __name__ == "__main__":
    main()
