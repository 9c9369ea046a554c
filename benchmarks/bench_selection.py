"""Benchmark: how K is chosen, measured on the simulated teacher's tasks and on LASA.

The evidence behind ``n_components="auto"`` (pbdkit.prob._gmm, "Choosing K"). For both tasks and
teach seeds 0-9 (5 demonstrations each, the paper's configuration: the basin task has no
basin-relative constraint), with ``Skill.learn``'s defaults, it prints per seed:

- the K kept per space (and the cap, ``max_components``);
- the joint-space GMR mean's RMSE to the demonstrations over the pointwise mean's (the floor no
  time-indexed model beats), worst joint;
- basin task: the wrist roll at the end against the demonstrations' mean, and its overshoot over
  the largest demonstrated roll;
- the largest one-step change of each space's GMR mean over the time grid (joints in mrad, the
  largest over the joints; task spaces in mm, the norm of the 3-D step), and its ratio to the
  demonstrations' own largest one-step change (rescaled to the same grid; for a task space the
  hand position f(theta) minus the object's): a ratio well above 1 is a jump of the
  generalized trajectory (pbdkit.prob._gmm, "Time floor");
- the fused reproduction's peak joint speed over the URDF limit, played over ``skill.times()``,
  from q0 = None and from every demonstration's first posture (worst);
- learning time.

Then the alternatives, on the same data (peers measured in the same run):

- ``bic20``: the effective-sample-size BIC with 20 samples per demonstration (pbdkit <= 0.1);
- ``bic-plain``: plain BIC on the points EM sees (every sample independent);
- ``bic-acf``: the effective sample size estimated from the autocorrelation of the
  demonstrations' deviations from their pointwise mean (integrated autocorrelation time,
  Geyer's initial positive sequence);
- ``loo-lik``: held-out-demonstration log-likelihood (exact refits), K of the best mean;
- ``auto``: leave-one-demonstration-out error of the GMR mean (approximate refits), each
  moment's error against the demonstrations' spread at that moment, smallest K within
  CV_TOLERANCE of the best (the default);
- ``auto-pooled``: the same against their spread pooled over time (the earlier default, which
  loses a tight phase where the demonstrations differ elsewhere: ``bench_zoo.py``).
- ``K=15``, ``K=20``, ``K=30``: a fixed K for every space (issue 34: "15-20 may simply be
  right for 5 demonstrations").

and on LASA (26 shapes, 7 demonstrations): K range and the GMR mean's RMSE over the pointwise
mean's. Last, the accuracy of the approximate leave-one-out against exact refits.

Run: ``.venv/bin/python benchmarks/bench_selection.py [--seeds N]`` (about 6 minutes);
``--min-time-spread 0 --skip-alternatives`` gives the plain EM, before the time floor (about 2
minutes).
"""

from __future__ import annotations

import argparse
import time
import warnings
from unittest import mock

import numpy as np
from _common import print_table
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from pbdkit._defaults import MAX_COMPONENTS
from pbdkit.data._demonstration import Demonstration
from pbdkit.datasets import lasa, lasa_names
from pbdkit.prob import GMM
from pbdkit.prob._em import MIN_TIME_SPREAD
from pbdkit.prob._selection import (
    CV_TOLERANCE,
    LOCAL_SPREAD_FLOOR,
    local_spread,
    pooled_spread,
    sequences_from_time,
)
from pbdkit.reproduction._constraints import JOINT
from pbdkit.robots import katana
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import constrained_objects, teach
from pbdkit.skill._skill import Skill

Float = NDArray[np.float64]
ROLL = 4  # the Katana's wrist roll


def joint_quality(skill: Skill, demos: list[Demonstration]) -> dict[str, float]:
    """Worst joint's RMSE ratio; wrist roll at the end and overshoot (rad)."""
    rescaled = np.stack([d.rescaled(skill.n_steps).joints for d in demos])  # (M, T, n)
    mean = skill.constraints().joint_mean
    floor = np.sqrt(((rescaled - rescaled.mean(axis=0)) ** 2).mean(axis=(0, 1)))
    rmse = np.sqrt(((rescaled - mean) ** 2).mean(axis=(0, 1)))
    return {
        "ratio": float(np.max(rmse / floor)),
        "roll_end": float(abs(mean[-1, ROLL] - rescaled[:, -1, ROLL].mean())),
        "overshoot": float(mean[:, ROLL].max() - rescaled[:, :, ROLL].max()),
    }


def mean_jumps(skill: Skill, demos: list[Demonstration]) -> dict[str, tuple[float, float]]:
    """Per space: the GMR mean's largest one-step change (rad or m) and its ratio to the
    demonstrations' own (rescaled to the skill's grid; task spaces: f(theta) - o)."""
    c = skill.constraints()
    rescaled = [d.rescaled(skill.n_steps) for d in demos]
    joints = np.stack([d.joints for d in rescaled])  # (M, T, n)
    own = float(np.abs(np.diff(joints, axis=1)).max())
    step = float(np.abs(np.diff(c.joint_mean, axis=0)).max())
    out = {JOINT: (step, step / own)}
    hand = [np.asarray(skill.robot.fk(d.joints), dtype=np.float64) for d in rescaled]
    for name in skill.object_names:
        rel = np.stack([x - d.objects[name] for x, d in zip(hand, rescaled, strict=True)])
        own = float(np.linalg.norm(np.diff(rel, axis=1), axis=2).max())
        step = float(np.linalg.norm(np.diff(c.task_mean[name], axis=0), axis=1).max())
        out[name] = (step, step / own)
    return out


def format_jumps(jumps: dict[str, tuple[float, float]]) -> str:
    """``joint 21.3 mrad (1.0x) / glass 3.7 mm (0.6x)``."""
    unit = {JOINT: "mrad"}
    return " / ".join(
        f"{k} {1e3 * v:.1f} {unit.get(k, 'mm')} ({r:.1f}x)" for k, (v, r) in jumps.items()
    )


def peak_speed_ratio(skill: Skill, demos: list[Demonstration]) -> tuple[float, float, float]:
    """Largest joint speed of the fused reproduction over the URDF limit, over several q0; and
    the largest joint second difference (rad/step^2) after step 20, of the reproduction from
    q0 = None and of the demonstrations (rescaled), as a smoothness check."""
    vmax = np.asarray(skill.robot.velocity_limit, dtype=np.float64)  # type: ignore[attr-defined]
    objects = {k: np.mean([d.objects[k] for d in demos], axis=0) for k in skill.object_names}
    worst = 0.0
    jerk = 0.0
    for q0 in [None, *(d.joints[0] for d in demos)]:
        res = skill.reproduce(objects, q0=q0)
        speed = np.abs(np.diff(res.joints, axis=0)) / np.diff(skill.times(res))[:, None]
        worst = max(worst, float(np.max(speed / vmax)))
        if q0 is None:
            jerk = float(np.abs(np.diff(res.joints[20:], 2, axis=0)).max())
    demo_jerk = max(
        float(np.abs(np.diff(d.rescaled(skill.n_steps).joints, 2, axis=0)).max()) for d in demos
    )
    return worst, jerk, demo_jerk


# ----------------------------------------------------------------------------- alternatives
def _acf_tau(dev: Float) -> float:
    """Integrated autocorrelation time (samples) of deviations (M, T, D), Geyer's sequence."""
    m, t, d = dev.shape
    taus = []
    for j in range(d):
        x = dev[:, :, j] - dev[:, :, j].mean(axis=1, keepdims=True)
        var = float((x * x).mean())
        if var <= 0:
            continue
        ac = np.array([(x[:, : t - k] * x[:, k:]).sum() / (m * t) / var for k in range(t)])
        tau = -1.0
        for k in range(0, t - 1, 2):
            pair = ac[k] + ac[k + 1]
            if pair <= 0:
                break
            tau += 2 * pair
        taus.append(tau)
    return float(np.mean(taus)) if taus else 1.0


def _loo_loglik_k(x: Float, groups: NDArray[np.intp], floor: Float, kmax: int) -> int:
    scores = []
    for k in range(1, kmax + 1):
        vals = []
        for m in range(int(groups.max()) + 1):
            fit = GMM(k, reg_covar=floor).fit(x[groups != m])
            vals.append(float(fit.score_samples(x[groups == m]).mean()))
        scores.append(np.mean(vals))
    return int(np.argmax(scores)) + 1


def choose(method: str, x: Float, floor: Float, kmax: int, score_dims: list[int] | None) -> GMM:
    """Fit with the K a method chooses (x: stacked sequences, time in column 0)."""
    groups = sequences_from_time(x[:, 0])
    n_seq = int(groups.max()) + 1
    if method in ("auto", "auto-pooled"):
        scale = "local" if method == "auto" else "pooled"
        return GMM(
            "auto", max_components=kmax, reg_covar=floor, score_dims=score_dims, cv_scale=scale
        ).fit(x)
    if method == "bic20":
        return GMM("bic", max_components=kmax, reg_covar=floor).fit(x)
    if method == "bic-plain":
        return GMM("bic", max_components=kmax, reg_covar=floor, bic_samples=len(x)).fit(x)
    if method == "bic-acf":
        seqs = np.stack([x[groups == m] for m in range(n_seq)])
        tau = _acf_tau(seqs[:, :, 1:] - seqs[:, :, 1:].mean(axis=0))
        n_eff = max(2, round(len(x) / max(tau, 1.0)))
        return GMM("bic", max_components=kmax, reg_covar=floor, bic_samples=n_eff).fit(x)
    if method == "loo-lik":
        return GMM(_loo_loglik_k(x, groups, floor, min(kmax, 12)), reg_covar=floor).fit(x)
    if method.startswith("K="):
        return GMM(int(method[2:]), reg_covar=floor).fit(x)
    raise ValueError(method)


METHODS = [
    "auto",
    "auto-pooled",
    "bic20",
    "bic-plain",
    "bic-acf",
    "loo-lik",
    "K=15",
    "K=20",
    "K=30",
]


def training_sets(skill: Skill, demos: list[Demonstration]) -> dict[str, Float]:
    """The rows each GMM of ``skill`` was fitted on (100 steps per demonstration)."""
    from pbdkit.skill._spaces import space_data

    steps = np.unique(np.round(np.linspace(0, skill.n_steps - 1, 100)).astype(int))
    data = space_data(demos, skill.robot, skill.object_names, skill.n_steps, steps)
    return {k: v.reshape(-1, v.shape[2]) for k, v in data.items()}


def lasa_row(method: str) -> tuple[str, str]:
    rows, ks = [], []
    for name in lasa_names(single_mode=True):
        demos = lasa(name)
        t = np.linspace(0.0, 1.0, 1000)
        x = np.vstack([np.column_stack([t[::10], d.pos[::10]]) for d in demos])
        gmm = choose(method, x, np.full(3, 1e-6), MAX_COMPONENTS, None)
        mean, _ = gmm.regress(t[:, None])
        pos = np.stack([d.pos for d in demos])

        def rmse(traj: Float, pos: Float = pos) -> float:
            return float(np.mean([np.sqrt(np.mean(np.sum((traj - p) ** 2, axis=1))) for p in pos]))

        rows.append((rmse(mean), rmse(pos.mean(axis=0))))
        ks.append(gmm.n_components_)
    g, f = np.mean(rows, axis=0)
    return f"{min(ks)}-{max(ks)}", f"{g / f:.4f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--skip-alternatives", action="store_true")
    parser.add_argument(
        "--min-time-spread",
        type=float,
        default=MIN_TIME_SPREAD,
        help="GMM's min_time_spread in every fit of the run (0: plain EM, before the time floor)",
    )
    args = parser.parse_args()
    # Skill.learn builds its GMMs with the defaults: the run changes the default.
    with mock.patch.dict(GMM.__init__.__kwdefaults__, {"min_time_spread": args.min_time_spread}):
        run(args)


def run(args: argparse.Namespace) -> None:
    warnings.simplefilter("ignore")
    robot = katana()
    cases = []
    rows = []
    for task in ("coaster", "basin"):
        for seed in range(args.seeds):
            demos = teach(task, 5, seed=seed)
            start = time.perf_counter()
            skill = Skill.learn(demos, robot, task_objects=constrained_objects(get_task(task)))
            learn_s = time.perf_counter() - start
            q = joint_quality(skill, demos)
            jumps = mean_jumps(skill, demos)
            v, jerk, demo_jerk = peak_speed_ratio(skill, demos)
            ks = " / ".join(f"{k} {n}" for k, n in skill.n_components.items())
            roll = f"{q['roll_end']:.3f} / {q['overshoot']:+.3f}" if task == "basin" else "-"
            rows.append(
                [
                    task,
                    str(seed),
                    ks,
                    f"{q['ratio']:.2f}",
                    roll,
                    format_jumps(jumps),
                    f"{v:.3f}",
                    f"{1e3 * jerk:.1f} / {1e3 * demo_jerk:.1f}",
                    f"{learn_s:.2f} s",
                ]
            )
            cases.append((task, seed, demos, skill, q, v, learn_s, jumps))
    print(f"\nDefaults (max_components = {MAX_COMPONENTS}, CV tolerance {CV_TOLERANCE:g}):")
    print_table(
        [
            "task",
            "seed",
            "K per space",
            "joint RMSE / floor (worst joint)",
            "roll end error / overshoot (rad)",
            "largest one-step change of the GMR mean (x demos')",
            "peak speed / limit",
            "max 2nd difference, fused / demos (mrad)",
            "learn",
        ],
        rows,
    )
    all_k = [k for c in cases for k in c[3].n_components.values()]
    ratios = [c[4]["ratio"] for c in cases]
    speeds = [c[5] for c in cases]
    learn = [c[6] for c in cases]
    basin = [c[4] for c in cases if c[0] == "basin"]
    joint_jump = max(c[7][JOINT][1] for c in cases)
    task_jump = max(r for c in cases for k, (_, r) in c[7].items() if k != JOINT)
    print(
        f"\nSummary: K {min(all_k)}-{max(all_k)} (cap {MAX_COMPONENTS}); worst joint ratio "
        f"{max(ratios):.2f}; basin roll end error <= {max(q['roll_end'] for q in basin):.3f} rad, "
        f"overshoot <= {max(q['overshoot'] for q in basin):+.3f} rad; largest one-step change of "
        f"the GMR mean <= {joint_jump:.2f} x the demonstrations' (joints), {task_jump:.2f} x "
        f"(task spaces); peak speed <= {max(speeds):.3f} x limit; learn median "
        f"{np.median(learn):.2f} s (max {max(learn):.2f})"
    )
    if args.skip_alternatives:
        return

    # The same demonstrations and rows, every method; floors as Skill.learn's defaults.
    print("\nAlternatives on the same data (joint space scored on the joints, as Skill.learn):")
    alt_rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        for method in METHODS:
            ks_all, worst, roll_end, over, caps, secs = [], [], [], [], 0, []
            for task, _seed, demos, skill, *_ in cases:
                data = training_sets(skill, demos)
                n = skill.n_joints
                gmms = {}
                start = time.perf_counter()
                for name, x in data.items():
                    floor = _floor_of(skill, name)
                    dims = list(range(1, n + 1)) if name == JOINT else None
                    gmms[name] = choose(method, x, floor, MAX_COMPONENTS, dims)
                secs.append(time.perf_counter() - start)
                alt = Skill(
                    skill.robot,
                    gmms,
                    n_steps=skill.n_steps,
                    object_names=skill.object_names,
                    has_gripper=skill.has_gripper,
                    reach=skill.reach,
                    duration=skill.duration,
                )
                q = joint_quality(alt, demos)
                ks_all += list(alt.n_components.values())
                if not method.startswith("K="):  # a fixed K chooses nothing
                    caps += sum(k >= MAX_COMPONENTS for k in alt.n_components.values())
                worst.append(q["ratio"])
                if task == "basin":
                    roll_end.append(q["roll_end"])
                    over.append(q["overshoot"])
            lasa_k, lasa_ratio = lasa_row(method) if method != "loo-lik" else ("-", "-")
            alt_rows.append(
                [
                    method,
                    f"{min(ks_all)}-{max(ks_all)}",
                    str(caps),
                    f"{max(worst):.2f}",
                    f"{max(roll_end):.3f} / {max(over):+.3f}",
                    lasa_k,
                    lasa_ratio,
                    f"{np.median(secs):.2f} s",
                ]
            )
    print_table(
        [
            "method",
            "K (tasks)",
            "spaces at the cap",
            "worst joint RMSE / floor",
            "basin roll end / overshoot (rad)",
            "K (LASA)",
            "LASA RMSE / floor",
            "fit, median per skill",
        ],
        alt_rows,
    )

    # Accuracy of the approximate leave-one-out against exact refits.
    print("\nApproximate leave-one-out (auto) against exact refits, mean error over the folds:")
    diffs = []
    for _task, _seed, demos, skill, *_ in cases[:: max(1, len(cases) // 6)]:
        data = training_sets(skill, demos)
        for name, x in data.items():
            floor = _floor_of(skill, name)
            dims = list(range(1, skill.n_joints + 1)) if name == JOINT else None
            sel = GMM("auto", max_components=MAX_COMPONENTS, reg_covar=floor, score_dims=dims)
            sel = sel.fit(x).selection_
            groups = sequences_from_time(x[:, 0])
            sdims = dims or [1, 2, 3]
            pooled = pooled_spread(x, groups, 0)[sdims]
            least = np.maximum(floor[sdims], LOCAL_SPREAD_FLOOR * pooled)
            scale = np.maximum(local_spread(x, groups, 0)[:, sdims], least)
            for k in (4, 8, sel.chosen):
                if k not in sel.candidates:
                    continue
                exact = []
                for m in range(int(groups.max()) + 1):
                    fit = GMM(k, reg_covar=floor).fit(x[groups != m])
                    held = x[groups == m]
                    mean, _ = fit.regress(held[:, :1])
                    err = (held[:, sdims] - mean[:, [d - 1 for d in sdims]]) ** 2
                    exact.append(float(np.mean(err / scale[groups == m])))
                approx = float(sel.scores[sel.candidates.index(k)])
                diffs.append(abs(approx - np.mean(exact)) / np.mean(exact))
    d = np.array(diffs)
    print(
        f"relative difference: median {100 * np.median(d):.2f} %, 90th percentile "
        f"{100 * np.percentile(d, 90):.2f} %, max {100 * d.max():.2f} % over {len(d)} (space, K)"
    )


def _floor_of(skill: Skill, name: str) -> Float:
    """Skill.learn's default per-dimension floor of a space."""
    from pbdkit.skill._spaces import TIME_FLOOR, VARIABILITY_FLOOR

    if name == JOINT:
        n = skill.n_joints
        tail = [VARIABILITY_FLOOR["gripper"]] if skill.has_gripper else []
        return np.array([TIME_FLOOR, *([VARIABILITY_FLOOR["joint"]] * n), *tail])
    return np.array([TIME_FLOOR, *([VARIABILITY_FLOOR["task"]] * 3)])


if __name__ == "__main__":
    main()
