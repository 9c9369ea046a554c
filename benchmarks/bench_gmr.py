"""GMR, EM and EM+BIC speed against the gmr library and scikit-learn, measured in the same run.

Run: .venv/bin/python benchmarks/bench_gmr.py
"""

from __future__ import annotations

import platform

import numpy as np
from _common import fmt_time, median_time, print_table
from gmr import GMM as GmrGMM
from sklearn.mixture import GaussianMixture
from threadpoolctl import threadpool_limits

from pbdkit import GMM
from pbdkit.prob._em import time_based_init


def random_time_gmm(rng: np.random.Generator, k: int, d: int) -> GMM:
    w = rng.dirichlet(np.ones(k) * 5)
    m = rng.normal(size=(k, d))
    m[:, 0] = np.linspace(0.0, 1.0, k)
    a = rng.normal(size=(k, d, d)) * 0.3
    c = a @ np.swapaxes(a, 1, 2) + 0.01 * np.eye(d)
    c[:, 0, 0] += 0.01
    return GMM.from_params(w, m, c)


def trajectories(rng: np.random.Generator, n_demos: int, n_steps: int, d: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n_steps)
    rows = []
    for _ in range(n_demos):
        phase = rng.normal(0.0, 0.05, d - 1)
        amp = 1.0 + rng.normal(0.0, 0.1, d - 1)
        freq = 0.5 * np.arange(1, d)
        y = amp * np.sin(2 * np.pi * (t[:, None] * freq + phase))
        rows.append(np.column_stack([t, y + rng.normal(0.0, 0.01, y.shape)]))
    return np.vstack(rows)


def main() -> None:
    rng = np.random.default_rng(0)
    t_steps, d, k = 1000, 7, 10
    gmm = random_time_gmm(rng, k, d)
    ref = GmrGMM(
        n_components=k, priors=gmm.weights_, means=gmm.means_, covariances=gmm.covariances_
    )
    t = np.linspace(0.0, 1.0, t_steps)[:, None]
    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        ours = median_time(lambda: gmm.regress(t), repeat=200)

        def peer_loop() -> None:
            for ti in t:
                mvn = ref.condition([0], ti).to_mvn()
                _ = (mvn.mean, mvn.covariance)

        peer = median_time(peer_loop, repeat=5)
        rows.append(
            [
                f"GMR batch T={t_steps} D={d} K={k}, mean+cov",
                fmt_time(ours),
                "gmr condition() loop",
                fmt_time(peer),
                f"{peer / ours:.0f}x",
                "<= 0.5 ms, >= 1000x",
            ]
        )
        ours1 = median_time(lambda: gmm.regress_one(0.5), repeat=5000)
        peer1 = median_time(lambda: ref.condition([0], np.array([0.5])).to_mvn(), repeat=500)
        rows.append(
            [
                "GMR single step",
                fmt_time(ours1),
                "gmr condition()",
                fmt_time(peer1),
                f"{peer1 / ours1:.0f}x",
                "<= 15 us",
            ]
        )
        x = trajectories(rng, 5, 1000, d)
        ours_em = median_time(lambda: GMM("bic", max_components=10).fit(x), repeat=5)

        def sk_sweep() -> None:
            models = [GaussianMixture(kk, random_state=0).fit(x) for kk in range(1, 11)]
            min(models, key=lambda g: g.bic(x))

        peer_em = median_time(sk_sweep, repeat=3, warmup=0)
        chosen = GMM("bic", max_components=10).fit(x).n_components_
        rows.append(
            [
                f"EM+BIC K=1..10, 5x1000 samples D={d} (K*={chosen})",
                fmt_time(ours_em),
                "scikit-learn default-init sweep",
                fmt_time(peer_em),
                f"{peer_em / ours_em:.1f}x",
                "<= 1 s",
            ]
        )
        # One EM fit from the same time-based start: pbdkit's vectorized EM against
        # scikit-learn's GaussianMixture (per-component loops).
        w0, m0, p0 = time_based_init(x, 10, 0, 1e-6)
        ours_fit = median_time(lambda: GMM(10).fit(x), repeat=5)

        def sk_fit() -> None:
            GaussianMixture(
                10, reg_covar=1e-6, weights_init=w0, means_init=m0, precisions_init=p0
            ).fit(x)

        peer_fit = median_time(sk_fit, repeat=5)
        rows.append(
            [
                f"EM, one fit K=10, 5x1000 samples D={d}, time-based start",
                fmt_time(ours_fit),
                "scikit-learn GaussianMixture, same start",
                fmt_time(peer_fit),
                f"{peer_fit / ours_fit:.1f}x",
                "",
            ]
        )
    print(f"# bench_gmr on {platform.machine()}, numpy {np.__version__}, BLAS threads = 1")
    print_table(["operation", "pbdkit (median)", "peer", "peer (median)", "ratio", "target"], rows)


if __name__ == "__main__":
    main()
