"""Physics playback speed: how much faster than real time a run plays, and where its time goes.

For the fused reproduction of each task's skill (teach seed 0) at a few new placements, the
wall time of one offline playback (:func:`pbdkit.sim.execute`: 0.3 s settling, the
trajectory over the demonstrations' duration, 1 s of settling; no camera), against:

- the playback loop as it was before it was tuned (servo targets written by index arrays at
  every physics step, the glass's tilt through ``grasped_frame()`` and numpy), replicated here
  and measured in the same run: the "current one" the issue compares with;
- the same number of bare ``mj_step`` calls with the arm following the same targets set once
  per segment (no Python per physics step beyond the call): the floor MuJoCo itself sets;
- the online loop (:func:`pbdkit.sim.execute_online`, truth at 15 Hz), which also runs
  one controller step per skill step.

Real-time factor = simulated seconds / wall seconds, medians over placements x repeats. The
basin task's 40 liquid spheres add contacts: its bare ``mj_step`` is the slower floor.

Run: .venv/bin/python benchmarks/bench_physics.py [--placements N] [--repeat N]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from _common import print_table
from threadpoolctl import threadpool_limits

from pbdkit.sim._execute import Recorder, execute, start_at
from pbdkit.sim._online import TruthObserver, execute_online
from pbdkit.sim._scene import Simulation
from pbdkit.sim._task_skill import learn_task
from pbdkit.sim._world import TIMESTEP

TARGET = 20.0  # design.md: >= 20x real time per core (coaster task)


def legacy_execute(sim: Simulation, t: np.ndarray, q: np.ndarray, g: np.ndarray) -> bool:
    """The playback loop before tuning (same physics, same result; slower Python per step)."""
    start_at(sim, q[0], bool(g[0] > 0.5))
    n_play = math.ceil((t[-1] - t[0]) / TIMESTEP)
    s = t[0] + TIMESTEP * np.arange(n_play + round(1.0 / TIMESTEP) + 1)
    seg = np.clip(np.searchsorted(t, s, side="right") - 1, 0, t.shape[0] - 2)
    slope = np.diff(q, axis=0) / np.diff(t)[:, None]
    qt = np.stack([np.interp(s, t, q[:, j]) for j in range(q.shape[1])], axis=1)
    dqt = slope[seg]
    dqt[s >= t[-1]] = 0.0
    gt = g[np.clip(np.searchsorted(t, s, side="right") - 1, 0, t.shape[0] - 1)] > 0.5
    rec = Recorder(sim, 50.0, None, 15.0)
    ctrl = sim.data.ctrl
    for k in range(s.shape[0]):
        ctrl[sim._pos_act] = qt[k]
        ctrl[sim._vel_act] = dqt[k]
        ctrl[sim._finger_act] = 0.0 if gt[k] else 0.04
        rec.record(k, s[k], qt[k], bool(gt[k]))
        _, rot = sim.grasped_frame()
        rec.max_tilt = max(rec.max_tilt, float(np.arccos(np.clip(rot[2, 2], -1.0, 1.0))))
        if k == n_play:
            rec.end_of_trajectory()
        if k < s.shape[0] - 1:
            sim.step()
    return bool(rec.result().outcome.success)


def bare_steps(sim: Simulation, t: np.ndarray, q: np.ndarray) -> None:
    """mj_step over the same span, targets set once per trajectory segment (no per-step work)."""
    start_at(sim, q[0], False)
    per = max(1, round(float(np.mean(np.diff(t))) / TIMESTEP))
    total = math.ceil((t[-1] - t[0]) / TIMESTEP) + round(1.0 / TIMESTEP)
    done, j = 0, 0
    while done < total:
        row = q[min(j, q.shape[0] - 1)]
        sim.set_targets(row, np.zeros_like(row))
        n = min(per, total - done)
        sim.step(n)
        done += n
        j += 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--placements", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        for task in ("coaster", "basin"):
            ts = learn_task(task, seed=0)
            rng = np.random.default_rng([0, 1])
            runs: dict[str, list[float]] = {"now": [], "before": [], "bare": [], "online": []}
            ok = {"now": 0, "before": 0}
            simulated = 0.0
            for _ in range(args.placements):
                truth = ts.task.sample_objects(rng)
                told = {k: truth[k] for k in ts.skill.object_names}
                res = ts.skill.reproduce(told)
                t = ts.skill.times(res)
                simulated = float(t[-1] - t[0]) + 1.0 + 0.3
                for _ in range(args.repeat):
                    sim = Simulation.from_task(ts.task, truth)
                    start = time.perf_counter()
                    ok["now"] += execute(sim, t, res.joints, res.gripper).outcome.success
                    runs["now"].append(simulated / (time.perf_counter() - start))
                    sim = Simulation.from_task(ts.task, truth)
                    start = time.perf_counter()
                    ok["before"] += legacy_execute(sim, t, res.joints, res.gripper)
                    runs["before"].append(simulated / (time.perf_counter() - start))
                    sim = Simulation.from_task(ts.task, truth)
                    start = time.perf_counter()
                    bare_steps(sim, t, res.joints)
                    runs["bare"].append(simulated / (time.perf_counter() - start))
                    sim = Simulation.from_task(ts.task, truth)
                    ctrl = ts.skill.controller(told)
                    start = time.perf_counter()
                    execute_online(sim, ctrl, observer=TruthObserver(ts.skill.object_names))
                    runs["online"].append(simulated / (time.perf_counter() - start))
            n = args.placements * args.repeat
            med = {k: float(np.median(v)) for k, v in runs.items()}
            target = f">= {TARGET:g}x" if task == "coaster" else ""
            rows += [
                [task, "execute (now)", f"{med['now']:.1f}x", target,
                 f"{med['now'] / med['before']:.2f}x", f"{ok['now']}/{n}"],
                [task, "execute before tuning (same run)", f"{med['before']:.1f}x", "",
                 "1.00x", f"{ok['before']}/{n}"],
                [task, "bare mj_step, same span (floor)", f"{med['bare']:.1f}x", "",
                 f"{med['bare'] / med['before']:.2f}x", "-"],
                [task, "execute_online (controller + truth at 15 Hz)", f"{med['online']:.1f}x",
                 "", f"{med['online'] / med['before']:.2f}x", "-"],
            ]  # fmt: skip
            print(f"{task}: {simulated:.1f} s simulated per run, {n} runs per row")
    print_table(
        ["task", "loop", "real-time factor (median)", "target", "vs before", "successes"], rows
    )


if __name__ == "__main__":
    main()
