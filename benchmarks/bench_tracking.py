"""The stereo tracker in the simulated world: accuracy over random placements, and cycle time.

(a) 3-D error of every tracked object over random placements per task (``sample_objects``),
    raw (centroid of the visible patch) and with the per-object offset calibrated once at the
    nominal placement (``SimTracker.from_simulation``), against the paper's 5.9 +- 2.8 mm;
(b) the same with a deliberate calibration error: camera b's pose off by 1 mm and 0.1 degree
    (``PinholeCamera.perturbed``, random directions), with the offsets measured with that camera
    (as a real calibration session would), and with the offsets measured before the camera
    moved (the pose error then shows in full);
The arm waits at a start posture (the teacher's, hand raised in front of the robot, drawn per
placement) while the cameras look, as in ``pbdkit evaluate``; one extra row shows the arm at rest
(q = 0), whose fingers hide part of a coaster placed near the robot in the left camera.
(c) one tracker cycle (two 320x240 renders + tracking + triangulation, ``SimTracker.locate``):
    median time against the 15 ms target and the paper's 15 Hz frame period (66.7 ms), with the
    share of the renders.

Run: .venv/bin/python benchmarks/bench_tracking.py [--placements N] [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from _common import fmt_time, print_table, tracker_cycle
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from pbdkit.robots import katana
from pbdkit.sim import Simulation, get_task, nominal_objects, sample_objects
from pbdkit.sim._gl import BACKEND
from pbdkit.sim._teacher import random_start_posture
from pbdkit.sim._tracking import SimTracker
from pbdkit.vision import PinholeCamera, StereoTracker

PAPER_MEAN, PAPER_STD = 5.9, 2.8  # mm, paper Sec. III
TARGET_S = 0.015  # design.md: tracker cycle <= 15 ms
PAPER_PERIOD_S = 1.0 / 15.0  # the paper's cameras: 15 Hz


def calibrate(task: str, perturb: bool, seed: int) -> tuple[SimTracker, SimTracker]:
    """Trackers (raw, corrected) calibrated at the nominal placement of ``task``."""
    calib = Simulation.from_task(get_task(task), nominal_objects(task))
    calib.set_joints(random_start_posture(katana(), np.random.default_rng(seed)))
    try:
        cams: tuple[PinholeCamera, PinholeCamera] | None = None
        if perturb:
            a = PinholeCamera(*calib.camera_parameters("cam_left"))
            b = PinholeCamera(*calib.camera_parameters("cam_right"))
            cams = (a, b.perturbed(translation=0.001, rotation_deg=0.1, rng=seed))
        raw = SimTracker.from_simulation(
            calib, at_nominal=False, calibrated_cameras=cams, correct_bias=False
        )
        corrected = SimTracker.from_simulation(calib, at_nominal=False, calibrated_cameras=cams)
    finally:
        calib.close()
    return raw, corrected


def errors(
    task: str, n: int, seed: int, trackers: dict[str, SimTracker]
) -> tuple[dict[str, dict[str, NDArray[np.float64]]], dict[str, int]]:
    """Error vectors (mm) per tracker and object over ``n`` placements; failures per tracker."""
    rng = np.random.default_rng(seed)
    out: dict[str, dict[str, list[NDArray[np.float64]]]] = {
        k: {o: [] for o in get_task(task).tracked_objects} for k in trackers
    }
    out["arm at rest"] = {o: [] for o in get_task(task).tracked_objects}
    failures = dict.fromkeys(out, 0)
    robot = katana()
    for _ in range(n):
        sim = Simulation.from_task(get_task(task), sample_objects(task, rng))
        try:
            truth = sim.object_positions()
            sim.set_joints(random_start_posture(robot, rng))
            for key, tr in [*trackers.items(), ("arm at rest", trackers["corrected"])]:
                if key == "arm at rest":
                    sim.set_joints(np.zeros(sim.n_joints))
                for name, track in tr.locate(sim).items():
                    if track.position is None:
                        failures[key] += 1
                        continue
                    out[key][name].append(1e3 * (track.position - truth[name]))
        finally:
            sim.close()
    return {k: {o: np.array(v) for o, v in d.items()} for k, d in out.items()}, failures


def fmt_err(e: NDArray[np.float64]) -> tuple[str, str, str]:
    d = np.linalg.norm(e, axis=1)
    mean = ", ".join(f"{v:+.1f}" for v in e.mean(axis=0))
    std = ", ".join(f"{v:.1f}" for v in e.std(axis=0))
    return f"{d.mean():.2f} +- {d.std():.2f} mm", f"{d.max():.1f} mm", f"({mean}) +- ({std})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--placements", type=int, default=100, help="per task; 0: the cycle time only"
    )
    parser.add_argument("--repeat", type=int, default=200, help="tracker cycles timed")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(
        f"MUJOCO_GL={BACKEND}, load average {os.getloadavg()[0]:.2f}, "
        f"{args.placements} placements per task"
    )
    rows = []
    pooled: dict[str, list[NDArray[np.float64]]] = {
        "raw": [],
        "corrected": [],
        "perturbed": [],
        "stale": [],
    }
    with threadpool_limits(1):
        for task in ("coaster", "basin") if args.placements > 0 else ():
            raw, corrected = calibrate(task, perturb=False, seed=args.seed)
            _, perturbed = calibrate(task, perturb=True, seed=args.seed)
            # The same pose error after the offsets were measured with the exact cameras.
            stale = SimTracker(
                StereoTracker(
                    corrected.tracker.cam_a,
                    perturbed.tracker.cam_b,
                    corrected.tracker.models,
                    offsets=corrected.offsets,
                ),
                corrected.cameras,
            )
            trackers = {
                "raw": raw,
                "corrected": corrected,
                "perturbed": perturbed,
                "stale": stale,
            }
            errs, fails = errors(task, args.placements, args.seed, trackers)
            labels = {
                "raw": "raw centroid",
                "corrected": "offset-corrected",
                "perturbed": "corrected, cam b off 1 mm + 0.1 deg",
                "stale": "cam b off 1 mm + 0.1 deg after offsets",
                "arm at rest": "corrected, arm at rest (q = 0)",
            }
            for key, label in labels.items():
                for name, e in errs[key].items():
                    if key in pooled:
                        pooled[key].append(np.linalg.norm(e, axis=1))
                    rows.append([task, name, label, *fmt_err(e), str(fails[key])])
            offs = ", ".join(
                f"{k} ({', '.join(f'{1e3 * v:+.1f}' for v in o)})"
                for k, o in corrected.offsets.items()
            )
            print(f"{task}: offsets (mm) {offs}")
    for key, label in (
        ()
        if args.placements <= 0
        else (
            ("raw", "raw centroid"),
            ("corrected", "offset-corrected"),
            ("perturbed", "cam b off, offsets measured with it"),
            ("stale", "cam b off after offsets"),
        )
    ):
        d = np.concatenate(pooled[key])
        rows.append(["all", "all", label, f"{d.mean():.2f} +- {d.std():.2f} mm", "", "", ""])
    rows.append(["paper", "", "real webcams", f"{PAPER_MEAN} +- {PAPER_STD} mm", "", "", ""])
    if rows[:-1]:
        print()
        print_table(
            [
                "task",
                "object",
                "tracker",
                "3-D error mean +- std",
                "max",
                "error vector x, y, z mean +- std (mm)",
                "not seen",
            ],
            rows,
        )

    # (c) cycle time on the coaster scene (2 tracked objects), the arm at a start posture.
    task = "coaster"
    _, tracker = calibrate(task, perturb=False, seed=args.seed)
    rng = np.random.default_rng(args.seed)
    sim = Simulation.from_task(get_task(task), sample_objects(task, rng))
    sim.set_joints(random_start_posture(katana(), rng))
    try:
        with threadpool_limits(1):
            cycle, renders, track = tracker_cycle(
                tracker, sim, tracker.tracker.track, repeat=args.repeat
            )
    finally:
        sim.close()
    load = os.getloadavg()[0]
    print()
    print_table(
        ["measurement", "time", "time / cycle", "target", "cycle / target"],
        [
            ["tracker cycle: 2 renders + track", fmt_time(cycle), "1.00", "<= 15 ms",
             f"{cycle / TARGET_S:.2f}"],
            ["  of which 2 renders", fmt_time(renders), f"{renders / cycle:.2f}", "", ""],
            ["  of which track + triangulate", fmt_time(track), f"{track / cycle:.2f}", "", ""],
            ["peer: paper's frame period (15 Hz)", fmt_time(PAPER_PERIOD_S),
             f"{PAPER_PERIOD_S / cycle:.1f}x cycle", "", ""],
        ],
    )  # fmt: skip
    print(f"(load average {load:.2f}; {time.strftime('%Y-%m-%d %H:%M')})")


if __name__ == "__main__":
    main()
