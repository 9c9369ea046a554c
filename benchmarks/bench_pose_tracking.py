"""Pose tracking in the simulated world: position (mm) and yaw (degrees) of turned objects.

(a) The slot task's block and tray (two marks each, ``pbdkit.sim._parts``) over random placements
    (``sample_objects``: positions and yaws -60..60 degrees), the arm at a start posture of the
    teacher drawn per placement, as in ``pbdkit evaluate``; trackers calibrated at the nominal
    placement (``SimTracker.from_simulation``): raw (the marks' midpoint and heading), the
    position offset in the world frame or in the object's, measured in 1 view (the nominal
    placement) or 5 (the objects turned across their yaw range, ``pose_views``).
(b) An object whose point is 30 mm off its marks' line (a plate, built here): calibrated at yaw 0
    (1 view), tracked turned to yaws across -60..60 degrees; the world offset against the
    object-frame offset.
(c) One tracker cycle of the slot scene (2 renders + 4 patches + the poses, ``SimTracker.locate``).

Run: .venv/bin/python benchmarks/bench_pose_tracking.py [--placements N] [--repeat N]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from _common import fmt_time, print_table, tracker_cycle
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from pbdkit.robots import katana
from pbdkit.sim import Simulation, get_task
from pbdkit.sim._gl import BACKEND
from pbdkit.sim._tasks import TaskSpec, yaw_of, yaw_pose
from pbdkit.sim._teacher import random_start_posture
from pbdkit.sim._tracking import SimTracker
from pbdkit.vision import PoseTrack

# The plate of (b), shared with the tests.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from plate_task import PLATE_SIDE, plate_task

Float = NDArray[np.float64]


def slot_errors(
    spec: TaskSpec, trackers: dict[str, SimTracker], n: int, seed: int
) -> tuple[dict[str, dict[str, Float]], dict[str, int]]:
    """Per tracker and object: rows (dx, dy, dz mm, yaw error deg) over ``n`` placements."""
    robot = katana()
    rng = np.random.default_rng(seed)
    out: dict[str, dict[str, list[list[float]]]] = {
        k: {o: [] for o in spec.tracked_objects} for k in trackers
    }
    failures = dict.fromkeys(trackers, 0)
    for _ in range(n):
        sim = Simulation.from_task(spec, spec.sample_objects(rng))
        try:
            sim.set_joints(random_start_posture(robot, rng))
            truth = sim.object_poses()
            for key, tr in trackers.items():
                for name, track in tr.locate(sim).items():
                    if not isinstance(track, PoseTrack) or track.pose is None:
                        failures[key] += 1
                        continue
                    e = 1e3 * (track.pose[:3, 3] - truth[name][:3, 3])
                    dyaw = math.remainder(yaw_of(track.pose) - yaw_of(truth[name]), 2 * math.pi)
                    out[key][name].append([*e.tolist(), math.degrees(dyaw)])
        finally:
            sim.close()
    return {k: {o: np.array(v) for o, v in d.items()} for k, d in out.items()}, failures


def calibrate(spec: TaskSpec, seed: int, **options: Any) -> SimTracker:
    calib = Simulation.from_task(spec, spec.nominal_objects())
    try:
        calib.set_joints(random_start_posture(katana(), np.random.default_rng(seed)))
        return SimTracker.from_simulation(calib, at_nominal=False, **options)
    finally:
        calib.close()


def fmt(rows: Float) -> list[str]:
    d = np.linalg.norm(rows[:, :3], axis=1)
    y = np.abs(rows[:, 3])
    sd = ", ".join(f"{v:.2f}" for v in rows[:, :3].std(axis=0))
    return [
        f"{d.mean():.2f} +- {d.std():.2f}",
        f"{np.median(d):.2f}",
        f"{d.max():.2f}",
        f"({sd})",
        f"{y.mean():.2f} +- {y.std():.2f}",
        f"{np.median(y):.2f}",
        f"{y.max():.2f}",
    ]


HEADERS = [
    "object",
    "tracker",
    "position error mean +- sd (mm)",
    "median",
    "max",
    "sd x, y, z (mm)",
    "yaw error mean +- sd (deg)",
    "median",
    "max",
    "not seen",
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--placements", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=100, help="tracker cycles timed")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"MUJOCO_GL={BACKEND}, load average {os.getloadavg()[0]:.2f}")
    slot = get_task("slot")
    with threadpool_limits(1):
        # (a) the slot's block and tray
        trackers = {
            "raw (midpoint, heading)": calibrate(slot, args.seed, correct_bias=False),
            "world offset, 1 view": calibrate(slot, args.seed, offset_frame="world", pose_views=1),
            "object offset, 1 view": calibrate(slot, args.seed, pose_views=1),
            "world offset, 5 views": calibrate(slot, args.seed, offset_frame="world"),
            "object offset, 5 views (default)": calibrate(slot, args.seed),
        }
        pix = trackers["raw (midpoint, heading)"].calibration
        assert pix is not None
        print("mark pixels (cam_left, cam_right) at the calibration:", pix.pixels)
        errs, fails = slot_errors(slot, trackers, args.placements, args.seed + 1)
        rows = [
            [name, key, *fmt(e), str(fails[key])]
            for key, per in errs.items()
            for name, e in per.items()
        ]
        print(f"\n(a) slot, {args.placements} placements\n")
        print_table(HEADERS, rows)

        # (b) a plate whose point is off its marks' line
        plate = plate_task()
        ptrack = {
            "world offset, 1 view": calibrate(plate, args.seed, offset_frame="world", pose_views=1),
            "object offset, 1 view": calibrate(plate, args.seed, pose_views=1),
        }
        rows = []
        robot = katana()
        for key, tr in ptrack.items():
            by_yaw = []
            for deg in (-60, -40, -20, 0, 20, 40, 60):
                objs = plate.nominal_objects()
                objs["tray"] = yaw_pose(objs["tray"][:3, 3], math.radians(deg))
                with Simulation.from_task(plate, objs) as sim:
                    sim.set_joints(random_start_posture(robot, np.random.default_rng(deg + 100)))
                    track = tr.locate(sim)["tray"]
                    truth = sim.object_poses()["tray"]
                assert isinstance(track, PoseTrack) and track.pose is not None
                by_yaw.append(1e3 * float(np.linalg.norm(track.pose[:3, 3] - truth[:3, 3])))
            rows.append([key, *(f"{v:.1f}" for v in by_yaw)])
        side = 1e3 * PLATE_SIDE
        print(f"\n(b) plate, point {side:.0f} mm off its marks' line, calibrated at yaw 0\n")
        print_table(["tracker", *(f"{d} deg (mm)" for d in (-60, -40, -20, 0, 20, 40, 60))], rows)

        # (c) cycle time
        tracker = trackers["object offset, 5 views (default)"]
        rng = np.random.default_rng(args.seed)
        sim = Simulation.from_task(slot, slot.sample_objects(rng))
        sim.set_joints(random_start_posture(robot, rng))
        try:
            cycle, renders, track_s = tracker_cycle(
                tracker, sim, tracker.tracker.track_objects, repeat=args.repeat
            )
        finally:
            sim.close()
    print()
    print_table(
        ["measurement", "time"],
        [
            ["tracker cycle: 2 renders + 4 patches + 2 poses", fmt_time(cycle)],
            ["  of which 2 renders", fmt_time(renders)],
            ["  of which track_objects", fmt_time(track_s)],
        ],
    )
    print(f"(load average {os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M')})")


if __name__ == "__main__":
    main()
