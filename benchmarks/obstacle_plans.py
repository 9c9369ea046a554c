"""Avoidance at the level of the plans (issue 38): for the placements and obstacles of
``pbdkit evaluate --task coaster --trials N --perturb obstacle`` (seed 0, the true placements),
the fused controller's plan without and with avoidance: how many touch the box, their smallest
clearance at the samples and between them (the joints interpolated 10 times finer: what a drive
following the samples sweeps), the largest joint step, where the glass is released, and how much
longer the avoided plan takes. No physics (``pbdkit evaluate`` runs the plans under physics).

    .venv/bin/python benchmarks/obstacle_plans.py [--trials 50]   # about 1 minute
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from pbdkit.sim import get_task
from pbdkit.sim._obstacle import avoided_scene
from pbdkit.sim._task_skill import learn_task
from pbdkit.sim._trials import TrialConditions, trial_disturbance


def _release(res: object) -> int:
    g = res.gripper  # type: ignore[attr-defined]
    return int(np.flatnonzero(g[:-1] & ~g[1:])[0])


def _between(skill: object, res: object, scene: object, objects: dict) -> float:
    """The smallest clearance of the plan's joints interpolated 10 times finer (linearly)."""
    q = res.joints  # type: ignore[attr-defined]
    steps = np.arange(q.shape[0])
    fine = np.linspace(0.0, q.shape[0] - 1.0, 10 * (q.shape[0] - 1) + 1)
    between = np.stack([np.interp(fine, steps, column) for column in q.T], axis=1)
    held = res.gripper_signal[np.floor(fine).astype(int)]  # type: ignore[attr-defined]
    report = skill.check(between, scene, objects=objects, gripper=held)  # type: ignore[attr-defined]
    return float(report.min_clearance)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--teach-seed", type=int, default=0, help="the skill's teacher's seed")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    spec = get_task("coaster")
    ts = learn_task(spec, n_demos=5, seed=args.teach_seed)
    rng = np.random.default_rng([0, 1])  # evaluate's placements
    placements = [spec.sample_objects(rng) for _ in range(args.trials)]
    conditions = TrialConditions(perturb="obstacle")
    plain_min, plain_hit, avoided_min, avoided_hit, shift, stretch = [], 0, [], 0, [], []
    between_min, jump = [], []
    for i, truth in enumerate(placements):
        act = trial_disturbance(ts, conditions, truth, index=i)
        told = {k: truth[k] for k in ts.skill.object_names}
        scene = avoided_scene(spec, spec.full_placement(truth), act, whole=False)
        plain = ts.skill.reproduce(told, scene=scene, avoid=False, on_unreachable="warn")
        res = ts.skill.reproduce(told, scene=scene, on_unreachable="warn")
        assert plain.clearance is not None and res.clearance is not None
        plain_min.append(plain.clearance.min())
        plain_hit += bool(plain.collisions)
        avoided_min.append(res.clearance.min())
        avoided_hit += bool(res.collisions)
        between_min.append(_between(ts.skill, res, scene, spec.full_placement(truth)))
        jump.append(float(np.abs(np.diff(res.joints, axis=0)).max()))
        moved = res.positions[_release(res)] - plain.positions[_release(plain)]
        shift.append(float(np.linalg.norm(moved)))
        assert plain.times is not None and res.times is not None
        stretch.append(float(res.times[-1] / plain.times[-1]))
    n = args.trials
    print(
        f"coaster, --perturb obstacle, {n} placements (seed 0), teach seed {args.teach_seed}, "
        "the fused controller's plans:"
    )
    print(
        "| plans | touching the box | smallest clearance, min / median | between samples, "
        "min / median | largest joint step |"
    )
    print("|---|---|---|---|---|")
    print(
        f"| without avoidance | {plain_hit} / {n} | {min(plain_min) * 1e3:.1f} / "
        f"{np.median(plain_min) * 1e3:.1f} mm | | |"
    )
    print(
        f"| with avoidance | {avoided_hit} / {n} | {min(avoided_min) * 1e3:.1f} / "
        f"{np.median(avoided_min) * 1e3:.1f} mm | {min(between_min) * 1e3:.1f} / "
        f"{np.median(between_min) * 1e3:.1f} mm | {max(jump):.3f} rad |"
    )
    print(
        f"release moved by at most {max(shift) * 1e3:.2f} mm; avoided plans take "
        f"{np.median(stretch):.2f}x the plain plan's duration (median)"
    )


if __name__ == "__main__":
    main()
