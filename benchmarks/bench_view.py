"""Benchmark: ``pbdkit view`` keeps up. From a drag arriving at the server to the updated scene
sent to the browser (issue 25: within 100 ms at the 95th percentile).

Workload: each task's skill as ``pbdkit view --task T`` learns it (5 demonstrations, 1000
steps), served on 127.0.0.1 with one headless Chromium page connected (Debian's chromium,
software WebGL: the page renders every update on this machine's CPU too). The dragged object
(the glass; the slot's block) is moved with :meth:`ViewApp.move_object`, the call a drag
handler makes, to placements drawn in its demonstrated range (seed 0):

- full plans one at a time (a placement typed in the panel, a handle let go): each move waits
  until its scene has been sent (``server.flush``) before the next; latency = arrival to sent;
- a drag at 20 Hz (viser's client sends drag updates about that often) with the handle held:
  moves 50 ms apart along a line across the range, each planned as a preview on a grid of
  ``PREVIEW_STEPS`` steps (:func:`pbdkit.apps._view_plan.coarse_skill`); a move that arrives while
  another is planned replaces the one waiting (latest wins), and the latency of each planned
  move is counted; then the release and its full plan.

Peers, measured in the same run: ``skill.reproduce`` alone for the same placements, of the full
skill and of the preview skill (the floor: the page adds the path, the ellipsoids, the arm and
the panel); and how far the preview's hand path is from the full plan's (the Hausdorff
distance between the two sampled paths: the page draws paths, not their timing).
Times are medians and 95th percentiles.

Run: ``MUJOCO_GL=egl .venv/bin/python benchmarks/bench_view.py [--moves N] [--tasks ...]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from _common import print_table

from pbdkit.apps._view import ViewApp
from pbdkit.apps._view_serve import HOST, served
from pbdkit.sim._task_skill import learn_task

# Headless Chromium as the tests launch it.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from browser import free_port, launch


def _ms(values: list[float], q: float) -> str:
    return f"{1e3 * float(np.percentile(values, q)):.1f}"


def _hausdorff(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Hausdorff distance between two sampled paths (m): how far the drawn preview
    path is from the full one, whatever their timings."""
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return float(max(d.min(axis=1).max(), d.min(axis=0).max()))


def _kind(placement: Any) -> str:
    return "pose" if np.shape(placement) == (4, 4) else "position"


def run_task(task: str, moves: int, browser: Any) -> tuple[list[list[str]], list[str]]:
    ts = learn_task(task, n_demos=5, seed=0)
    spec = ts.task
    name = next(k for k in ts.skill.object_names if k not in spec.fixed_objects)
    rng = np.random.default_rng(0)
    placements = [spec.sample_objects(rng)[name] for _ in range(moves)]
    start = spec.nominal_objects()
    port = free_port()
    with served(lambda srv: ViewApp(ts.skill, start, srv, task_skill=ts), port=port) as app:
        return _measure(app, ts, name, placements, start, moves, browser, port)


def _measure(
    app: ViewApp,
    ts: Any,
    name: str,
    placements: list[Any],
    start: dict[str, Any],
    moves: int,
    browser: Any,
    port: int,
) -> tuple[list[list[str]], list[str]]:
    spec = ts.task
    page = browser.new_page(viewport={"width": 1200, "height": 800})
    page.goto(f"http://{HOST}:{port}")
    page.wait_for_selector("canvas", timeout=60_000)
    time.sleep(3.0)
    app.wait_idle(60)
    lat, kinds = app.planner.latencies, app.planner.kinds
    try:
        # Full plans one at a time (a typed placement, a handle let go).
        n0 = len(lat)
        for p in placements:
            app.move_object(name, p)
            app.wait_idle(60)
        single = list(lat)[n0:]
        # A drag at 20 Hz along a line across the range: previews while held, then the full
        # plan at the release.
        a, b = spec.ranges[name].low, spec.ranges[name].high
        n0, s0 = len(lat), app.planner.superseded
        base = np.array(placements[0])
        app.hold(name, True)
        for i in range(moves):
            p = base.copy()
            xy = a[:2] + (b[:2] - a[:2]) * (i / max(moves - 1, 1))
            if p.shape == (4, 4):
                p[:2, 3] = xy
            else:
                p[:2] = xy
            t0 = time.perf_counter()
            app.move_object(name, p, arrived=t0, preview=True)
            time.sleep(max(0.0, 0.05 - (time.perf_counter() - t0)))
        app.wait_idle(60)
        superseded = app.planner.superseded - s0
        previews = [x for x, k in list(zip(lat, kinds, strict=True))[n0:] if k == "preview"]
        app.hold(name, False)
        n1 = len(lat)
        app.move_object(name, p)
        app.wait_idle(60)
        release = list(lat)[n1:]
        # Peers: reproduce alone, same placements, full and coarse; and the preview's path
        # against the full plan's at the same moments.
        skill, coarse = ts.skill, app.preview_skill(ts.skill)
        rep, rep_coarse, path_dev, end_dev = [], [], [], []
        told = dict(start)
        for p in placements:
            told[name] = p
            objs = {k: told[k] for k in skill.object_names}
            t0 = time.perf_counter()
            full = skill.reproduce(objs)
            rep.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            rough = coarse.reproduce(objs)
            rep_coarse.append(time.perf_counter() - t0)
            path_dev.append(1e3 * _hausdorff(rough.positions, full.positions))
            end_dev.append(1e3 * np.linalg.norm(rough.positions[-1] - full.positions[-1]))
    finally:
        page.close()
    label = f"{spec.name} ({name}, {_kind(placements[0])})"

    def row(kind: str, values: list[float], peer: list[float], note: str) -> list[str]:
        return [
            label,
            kind,
            _ms(values, 50),
            _ms(values, 95),
            _ms(peer, 50),
            f"{np.median(values) / np.median(peer):.2f}",
            "yes" if np.percentile(values, 95) <= 0.1 else "no",
            note,
        ]

    rows = [
        row("full plan, one at a time", single, rep, f"{len(single)} plans"),
        row(
            f"preview ({app.preview_steps} steps), drag at 20 Hz",
            previews,
            rep_coarse,
            f"{len(previews)} planned, {superseded} replaced",
        ),
        row("full plan at the release", release, rep, "1 plan"),
    ]
    accuracy = (
        f"{label}: preview ({app.preview_steps} of {skill.n_steps} steps) against the full "
        f"plan over {moves} placements: hand path within {np.median(path_dev):.1f} mm "
        "(Hausdorff distance between the two paths, "
        f"median; worst {np.max(path_dev):.1f} mm), end point {np.median(end_dev):.1f} mm "
        f"(worst {np.max(end_dev):.1f} mm)"
    )
    return rows, [accuracy]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--moves", type=int, default=60)
    parser.add_argument("--tasks", nargs="+", default=["coaster", "basin", "slot"])
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    rows: list[list[str]] = []
    notes: list[str] = []
    with sync_playwright() as p:
        browser = launch(p)
        try:
            for task in args.tasks:
                more, said = run_task(task, args.moves, browser)
                rows += more
                notes += said
        finally:
            browser.close()
    print_table(
        [
            "task (dragged object)",
            "plan",
            "move to scene sent, median (ms)",
            "p95 (ms)",
            "reproduce alone, median (ms)",
            "ratio (median)",
            "p95 <= 100 ms",
            "latest wins",
        ],
        rows,
    )
    print()
    for line in notes:
        print(line)


if __name__ == "__main__":
    main()
