"""Benchmark: Skill.learn and Skill.reproduce on the Katana, against peers measured in the same run.

Workload (design.md, performance targets): 5 synthetic demonstrations (about 1000 samples each,
irregular time stamps) of a glass-to-coaster task, rescaled to 1000 steps; 3 constraint spaces
(joint + glass + coaster); K chosen in 1..30 for every space by leaving one demonstration out
(pbdkit's default; the peer sweeps BIC over K = 1..10); reproduction of 1000 steps with
the 3 constraints fused (default settings: the Katana's velocity limits and max_step bound the
steps; the comparison with the naive loop turns both off).

The reproduction is within the Katana's velocity, acceleration and jerk limits (the default):
Table II with Newton's term, a lead-in and the timing (docs/reproduction.md, "Motion limits and
lead-in").

Peers:
- learning: scikit-learn ``GaussianMixture`` with its default (k-means) initialisation, a BIC sweep
  over K = 1..10 per space on the same data (what one would write without pbdkit);
- reproduction: a naive loop as the paper's Matlab would run it: at every step GMR of every space
  for that step (``GMM.regress_one``), Table II with explicit inverses (J+ from np.linalg.pinv,
  eq. (1) with the pseudo-inverse of the rank-deficient J+ Sigma J+^T and np.linalg.inv), with
  the same line search written out (docs/reproduction.md, "Stability");
- the paper: "the whole computation (using Matlab) took less than one minute".

BLAS is limited to one thread (threadpoolctl): these matrices are tiny. Times are medians.

Run: ``.venv/bin/python benchmarks/bench_skill.py [--repeat N]``
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from _common import fmt_time, median_time, print_table
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from pbdkit.data._demonstration import Demonstration
from pbdkit.prob._gmm import GMM
from pbdkit.robots import katana
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill

Float = NDArray[np.float64]

Q_START = np.array([0.0, 1.2, -1.8, -1.4, 0.0])
Q_REACH = np.array([0.5, 0.8, -1.8, -1.0, 0.0])
Q_PLACE = np.array([-0.6, 1.0, -1.5, -1.2, 0.0])


def _ik(robot: Robot, target: Float, preferred: Float) -> Float:
    q = preferred.copy()
    for _ in range(300):
        x, jac = robot.fk_jacobian(q)
        jp = jac.T @ np.linalg.inv(jac @ jac.T + 1e-4 * np.eye(3))
        q = np.clip(q + jp @ (target - x) + 0.1 * (np.eye(5) - jp @ jac) @ (preferred - q),
                    robot.lower, robot.upper)  # fmt: skip
    return q


def _min_jerk(s: Float) -> Float:
    return np.asarray(10 * s**3 - 15 * s**4 + 6 * s**5)


def make_demos(robot: Robot, rng: np.random.Generator, n_demos: int = 5) -> list[Demonstration]:
    """Rest, reach the glass and hold it, carry it above the coaster, rest (synthetic teacher)."""
    demos = []
    for _ in range(n_demos):
        glass = robot.fk(Q_REACH) + np.r_[rng.uniform(-0.06, 0.06, 2), 0.0]
        place = robot.fk(Q_PLACE) + np.r_[rng.uniform(-0.06, 0.06, 2), 0.0]
        q_reach = _ik(robot, glass, Q_REACH + np.r_[0.0, rng.normal(0.0, 0.25, 3), 0.0])
        q_place = _ik(robot, place, Q_PLACE + np.r_[0.0, rng.normal(0.0, 0.2, 3), 0.0])
        q_start = Q_START + rng.normal(0.0, 0.02, 5)
        t = np.unique(np.r_[0.0, np.sort(rng.uniform(0.0, 1.0, 998)), 1.0]) * rng.uniform(8, 12)
        s = (t / t[-1])[:, None]
        a = q_start + (q_reach - q_start) * _min_jerk(np.clip((s - 0.1) / 0.25, 0, 1))
        b = q_reach + (q_place - q_reach) * _min_jerk(np.clip((s - 0.55) / 0.3, 0, 1))
        q = np.where(s < 0.35, a, np.where(s < 0.55, q_reach, b))
        objects = {"glass": glass, "coaster": place - np.array([0.0, 0.0, 0.08])}
        demos.append(Demonstration(t, q, objects, (s[:, 0] > 0.45).astype(float)))
    return demos


def sklearn_bic_sweep(data: dict[str, Float], max_components: int = 10) -> dict[str, int]:
    """The peer for learning: default GaussianMixture, BIC on all points, K = 1..max."""
    from sklearn.mixture import GaussianMixture

    chosen = {}
    for name, X in data.items():
        bics = [
            GaussianMixture(k, covariance_type="full", reg_covar=1e-6, random_state=0).fit(X).bic(X)
            for k in range(1, max_components + 1)
        ]
        chosen[name] = int(np.argmin(bics)) + 1
    return chosen


def _energy(robot: Robot, q: Float, terms: list[tuple[Float, Float, str | None]]) -> float:
    """Fused energy of one step: 1/2 |q - theta_hat|^2 + 1/2 sum_n |f(q) - target_n|^2."""
    xq = robot.fk(q)
    total = 0.0
    for prec, mean, name in terms:
        r = (q if name is None else xq) - mean
        total += 0.5 * float(r @ prec @ r)
    return total


def naive_reproduce(skill: Skill, objects: dict[str, Float], alpha: float = 0.5) -> Float:
    """The peer for reproduction: per-step GMR and Table II with explicit inverses."""
    robot = skill.robot
    n = robot.n_joints
    names = skill.object_names
    theta = skill.gmms["joint"].regress_one([0.0])[0][:n]
    joints = [theta]
    for j in range(1, skill.n_steps):
        mean, cov = skill.gmms["joint"].regress_one([float(j)])
        theta_hat, sigma_theta = mean[:n], cov[:n, :n]
        x, jac = robot.fk_jacobian(theta)
        jp = np.linalg.pinv(jac)
        null = np.eye(n) - jp @ jac
        precisions = [np.linalg.inv(sigma_theta)]
        steps = [theta_hat - theta]
        for k in names:
            x_hat, sigma_x = skill.gmms[k].regress_one([float(j)])
            steps.append(jp @ (objects[k] + x_hat - x) + alpha * null @ (theta_hat - theta))
            precisions.append(np.linalg.pinv(jp @ sigma_x @ jp.T, hermitian=True))
        sigma = np.linalg.inv(sum(precisions))
        new = np.clip(
            theta + sigma @ sum(p @ d for p, d in zip(precisions, steps, strict=True)),
            robot.lower,
            robot.upper,
        )
        # The same line search as pbdkit's (docs/reproduction.md, "Stability"), written
        # out: halve a step while it raises the fused energy of step j.
        terms = [(np.linalg.inv(sigma_theta), theta_hat, None)]
        for k in names:
            x_hat, sigma_x = skill.gmms[k].regress_one([float(j)])
            terms.append((np.linalg.inv(sigma_x), objects[k] + x_hat, k))
        e0 = _energy(robot, theta, terms)
        for _ in range(8):
            if _energy(robot, new, terms) <= e0:
                break
            new = theta + 0.5 * (new - theta)
        theta = new
        joints.append(theta)
    return np.array(joints)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs per measurement (median)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    robot = katana()
    demos = make_demos(robot, rng)
    shift = np.array([0.03, -0.04, 0.0])  # a new situation
    objects = {k: np.mean([d.objects[k] for d in demos], axis=0) + shift
               for k in ("glass", "coaster")}  # fmt: skip

    few = max(1, args.repeat // 2)
    with threadpool_limits(limits=1, user_api="blas"):
        skill = Skill.learn(demos, robot, n_steps=1000)
        t_learn = median_time(lambda: Skill.learn(demos, robot, n_steps=1000), repeat=args.repeat)

        # The same data spaces for the peer.
        n_steps = 1000
        rs = [d.rescaled(n_steps) for d in demos]
        t_col = np.tile(np.arange(float(n_steps)), len(rs))[:, None]
        theta = np.concatenate([d.joints for d in rs])
        grip = np.concatenate([d.gripper for d in rs if d.gripper is not None])[:, None]
        x = robot.fk(theta)
        data = {"joint": np.hstack([t_col, theta, grip])}
        for k in skill.object_names:
            data[k] = np.hstack([t_col, x - np.repeat([d.objects[k] for d in demos], n_steps, 0)])
        # pbdkit gives EM 100 evenly spaced steps per demonstration (fit_samples): the peer
        # is timed on the same points, and on all of them.
        steps = np.unique(np.round(np.linspace(0, n_steps - 1, 100)).astype(int))
        subset = {k: X.reshape(len(rs), n_steps, -1)[:, steps].reshape(-1, X.shape[1])
                  for k, X in data.items()}  # fmt: skip
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            k_sklearn = sklearn_bic_sweep(data)
            t_sklearn = median_time(lambda: sklearn_bic_sweep(data), repeat=few, warmup=0)
            t_sklearn_sub = median_time(lambda: sklearn_bic_sweep(subset), repeat=few)
        full = Skill.learn(demos, robot, n_steps=1000, fit_samples=None)
        t_full = median_time(
            lambda: Skill.learn(demos, robot, n_steps=1000, fit_samples=None), repeat=1, warmup=0
        )

        skill.reproduce(objects)  # GMR computed and cached
        t_repro = median_time(lambda: skill.reproduce(objects), repeat=5 * args.repeat)

        # The online controller fed its own commands (one step per call), timed interleaved
        # with reproduce: this machine's speed changes between phases of a run. Its first
        # step plans the run (a reproduction and its motion); the others sample the motion.
        step_times, plan_times, repro_times = [], [], []
        for _ in range(5 * args.repeat):
            ctrl = skill.controller(objects)
            q = ctrl.target
            times = []
            while not ctrl.done:
                start = time.perf_counter()
                q = ctrl.step(q).q
                times.append(time.perf_counter() - start)
            plan_times.append(times[0])
            step_times.append(float(np.median(times[1:])))
            start = time.perf_counter()
            skill.reproduce(objects)
            repro_times.append((time.perf_counter() - start) / 1000)
        t_step, t_repro_step = float(np.median(step_times)), float(np.median(repro_times))
        t_plan = float(np.median(plan_times))

        def cold() -> None:
            skill._constraints.clear()  # force the batched GMR + precisions again
            skill.reproduce(objects)

        t_cold = median_time(cold, repeat=5 * args.repeat)
        t_naive = median_time(lambda: naive_reproduce(skill, objects), repeat=few)
        # The naive loop takes the paper's full step, Gauss-Newton: no trust region, no limits,
        # and the GMMs' own covariances: compared on a skill learned without calibration (which
        # scales the constraints' covariances, issue 34: 0.21 rad apart with it).
        free = {"velocity_limit": None, "acceleration_limit": None, "jerk_limit": None}
        plain = Skill.learn(demos, robot, n_steps=1000, calibrate=False)
        fast = plain.reproduce(objects, max_step=None, newton=False, **free).joints
        naive = naive_reproduce(plain, objects)
        agree = float(np.abs(fast - naive).max())
        t_gmr = median_time(lambda: GMM.from_params(
            skill.gmms["joint"].weights_, skill.gmms["joint"].means_,
            skill.gmms["joint"].covariances_).regress(np.arange(1000.0)), repeat=5)  # fmt: skip

    errors = {}
    for name, sk in (("fit_samples=100", skill), ("all 1000 steps", full)):
        res = sk.reproduce(objects)
        lead = int(np.count_nonzero(res.lead_in))  # the lead-in's samples come first
        errors[name] = (
            1e3 * res.task_errors["glass"][lead + 450],
            1e3 * res.task_errors["coaster"][-1],
        )
    paper = 60.0
    rows = [
        ("Skill.learn: 5 x 1000 steps, 3 spaces, K in 1..30", t_learn, "<= 1 s", t_sklearn_sub,
         "sklearn GaussianMixture BIC sweep, same 100 steps/demo"),
        ("Skill.learn (same)", t_learn, "<= 1 s", t_sklearn,
         "sklearn BIC sweep, all 5 x 1000 points"),
        ("Skill.learn, fit_samples=None (EM on all points)", t_full, "", t_sklearn,
         "sklearn BIC sweep, all 5 x 1000 points"),
        ("Skill.reproduce: 1000 steps, 3 constraints", t_repro, "<= 30 ms", t_naive,
         "naive loop: per-step GMR + eq. (1), explicit inverses"),
        ("Skill.reproduce, GMR not cached (first call)", t_cold, "", t_naive,
         "naive loop: per-step GMR + eq. (1), explicit inverses"),
        ("learn + reproduce", t_learn + t_repro, "", paper,
         "paper: whole computation in Matlab < 1 min"),
        ("Controller.step, median per step over the run", t_step, "<= 20 us",
         t_repro_step, "Skill.reproduce per step, interleaved (target: <= 1.5x it)"),
        ("Controller.step, the first (plans the run)", t_plan, "",
         t_repro, "Skill.reproduce"),
    ]  # fmt: skip
    print(f"BLAS 1 thread; medians of {args.repeat} runs ({few} for the peers' learning, "
          f"{5 * args.repeat} for reproduction)")  # fmt: skip
    print(f"K chosen: pbdkit {skill.n_components} (fit_samples=None: {full.n_components}), "
          f"scikit-learn BIC on all points {k_sklearn}")  # fmt: skip
    print_table(
        ["measurement", "pbdkit", "target", "peer", "peer / pbdkit", "peer"],
        [[m, fmt_time(t), tgt, fmt_time(p), f"{p / t:.1f}x", pn] for m, t, tgt, p, pn in rows],
    )
    print(
        f"max |fused - naive| joint difference over 1000 steps: {agree:.2e} rad "
        "(a skill learned with calibrate=False)"
    )
    for name, (eg, ec) in errors.items():
        print(f"fused reproduction, skill learned with {name}: glass error {eg:.2f} mm at step "
              f"450, coaster error {ec:.2f} mm at step 999")  # fmt: skip
    print(f"batched GMR of the joint GMM over 1000 steps: {1e3 * t_gmr:.2f} ms")


if __name__ == "__main__":
    main()
