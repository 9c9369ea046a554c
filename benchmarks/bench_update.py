"""Learning one more demonstration (issue 39): ``Skill.update`` against a refit
(``Skill.learn`` on all the demonstrations, the peer) and against Calinon & Billard's
incremental GMM (the direct update from the old model's sufficient statistics,
:func:`pbdkit.prob._incremental.direct_update`), in the same run.

The coaster task's simulated teacher, 10 demonstrations (``--seed``): a skill learned from the
first 5 takes the others one at a time. At each size:

- **time**: median of ``--repeat`` calls (BLAS one thread) of the update, the refit and the
  direct update (the direct update is given the new demonstration's rows as the update encodes
  them: aligned, at the fit steps; its time is the GMMs' alone);
- **reproductions**: at ``--placements`` random placements inside the demonstrated range, the
  hand's path of each against the refit's, on the skill's time grid: the median and largest
  distance over the path, and the largest at the steps where each object's constraint is
  tightest in the refit (the grasp, the placement);
- **K**: the update's and the refit's (``*``: the update chose K again).

    .venv/bin/python benchmarks/bench_update.py [--repeat 5] [--placements 5] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from _common import fmt_time, print_table

from pbdkit import Skill
from pbdkit.data._demonstration import Demonstration
from pbdkit.prob._incremental import direct_update
from pbdkit.robots import katana
from pbdkit.sim import get_task
from pbdkit.sim._task_skill import teach
from pbdkit.skill._spaces import space_floors, variability_floor
from pbdkit.skill._uncertainty import _hands_at, _model


def _timed(fn, repeat: int):  # type: ignore[no-untyped-def]
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def _direct(skill: Skill, new_rows: dict[str, np.ndarray]) -> Skill:
    """The skill's GMMs updated by the direct method with a new demonstration's rows."""
    options = skill.learn_options_
    assert options is not None and skill.n_samples_ is not None
    floors = space_floors(
        variability_floor(options["reg_covar"]),
        skill.n_joints,
        skill.has_gripper,
        skill.object_names,
        skill.rotation_base,
    )
    gmms = {
        k: direct_update(gmm, new_rows[k], skill.n_samples_[k], reg_covar=floors[k])
        for k, gmm in skill.gmms.items()
    }
    return Skill(
        skill.robot,
        gmms,
        n_steps=skill.n_steps,
        object_names=skill.object_names,
        has_gripper=skill.has_gripper,
        reach=skill.reach,
        duration=skill.duration,
        calibration=skill.calibration_,
        demonstrations=skill.demonstrations_,
        learn_options=skill.learn_options_,
        n_samples={k: v + len(new_rows[k]) for k, v in skill.n_samples_.items()},
    )


def _rows(skill: Skill, items: list[Demonstration]) -> dict[str, np.ndarray]:
    """Each space's rows as learning encodes the demonstrations (aligned, at the fit steps)."""
    from pbdkit.skill._spaces import aligned_demonstrations, fit_steps, space_data

    options = skill.learn_options_
    assert options is not None
    aligned, _ = aligned_demonstrations(items, skill.robot, options["align"])
    steps = fit_steps(skill.n_steps, options["fit_samples"])
    spaces = space_data(aligned, skill.robot, skill.object_names, skill.n_steps, steps)
    return {k: v.reshape(-1, v.shape[2]) for k, v in spaces.items()}


def _apart(a: Skill, b: Skill, placements: list[dict[str, np.ndarray]]) -> tuple[float, ...]:
    """Median and largest distance of the hand paths (mm), and the largest at the steps
    where each object's constraint is tightest in ``b`` (the grasp, the placement)."""
    tightest = [_model(b).tight[k] for k in b.object_names]
    med, big, at_tight = [], [], []
    for objects in placements:
        pa = _hands_at(a.reproduce(objects), list(range(a.n_steps)))
        pb = _hands_at(b.reproduce(objects), list(range(b.n_steps)))
        d = np.linalg.norm(pa - pb, axis=1) * 1000
        med.append(np.median(d))
        big.append(d.max())
        at_tight.append(d[tightest].max())
    return float(np.median(med)), float(np.max(big)), float(np.max(at_tight))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--placements", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    spec = get_task("coaster")
    demos = teach(spec, 10, seed=args.seed)
    robot = katana()
    rng = np.random.default_rng(args.seed)
    placements = [
        {k: v for k, v in spec.sample_objects(rng).items() if k in ("glass", "coaster")}
        for _ in range(args.placements)
    ]
    skill = Skill.learn(demos[:5], robot)
    direct = skill
    rows = []
    for n in range(6, 11):
        items = demos[:n]
        t_refit, refit = _timed(lambda items=items: Skill.learn(items, robot), args.repeat)
        t_up, updated = _timed(lambda s=skill, d=items[-1]: s.update(d), args.repeat)
        data = _rows(skill, items)
        per = data["joint"].shape[0] // n  # rows per demonstration
        new_rows = {k: v[-per:] for k, v in data.items()}
        t_direct, direct_next = _timed(lambda s=direct, r=new_rows: _direct(s, r), args.repeat)
        again = {k for k, g in updated.gmms.items() if g.selection_.n_folds == n}
        k_up = ", ".join(
            f"{updated.n_components_[k]}{'*' if k in again else ''}" for k in updated.gmms
        )
        k_ref = ", ".join(str(refit.n_components_[k]) for k in refit.gmms)
        up_med, up_max, up_tight = _apart(updated, refit, placements)
        direct = direct_next
        di_med, di_max, di_tight = _apart(direct, refit, placements)
        rows.append(
            [
                str(n),
                fmt_time(t_refit),
                f"{fmt_time(t_up)} ({t_up / t_refit:.2f}x)",
                f"{fmt_time(t_direct)} ({t_direct / t_refit:.2f}x)",
                f"{up_med:.1f} / {up_max:.1f} / {up_tight:.2f}",
                f"{di_med:.1f} / {di_max:.1f} / {di_tight:.2f}",
                k_up,
                k_ref,
            ]
        )
        skill = updated
    print(
        f"coaster, teacher seed {args.seed}: learned from 5, then one demonstration at a time; "
        f"median of {args.repeat}; hand paths against the refit's at {args.placements} "
        "placements (mm: median / largest / largest at the tightest steps)"
    )
    print_table(
        [
            "demos",
            "refit (peer)",
            "update",
            "direct update",
            "update vs refit",
            "direct update vs refit",
            "K update (joint, glass, coaster)",
            "K refit",
        ],
        rows,
    )


if __name__ == "__main__":
    main()
