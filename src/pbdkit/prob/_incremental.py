"""Calinon & Billard's incremental GMM: the direct update (private; what
:meth:`pbdkit.Skill.update` is measured against, ``benchmarks/bench_update.py``).

S. Calinon and A. Billard, "Incremental Learning of Gestures by Imitation in a Humanoid Robot",
HRI 2007, Sec. 4 ("direct update"): the old model stands for the N_old points it was fitted on
through its sufficient statistics, E_k = N_old pi_k, mu_k and Sigma_k, and EM runs on the new
points x_j alone::

    E-step:  h_jk = pi_k N(x_j; mu_k, Sigma_k) / sum_i pi_i N(x_j; mu_i, Sigma_i)
    M-step:  s0_k = E_k + sum_j h_jk
             s1_k = E_k mu_k_old + sum_j h_jk x_j
             s2_k = E_k (Sigma_k_old + mu_k_old mu_k_old^T) + sum_j h_jk x_j x_j^T
             pi_k = s0_k / (N_old + N_new),  mu_k = s1_k / s0_k,
             Sigma_k = s2_k / s0_k - mu_k mu_k^T (+ the floors)

The old points' responsibilities stay those of the old model: nothing of them is needed but
the model. The floor on the diagonal is taken out of Sigma_k_old before it is used as a
statistic (it is added again by the M-step), and the time bounds of :mod:`._em` apply.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_int
from ._em import (
    MAX_TIME_SPREAD,
    MIN_TIME_SPREAD,
    _e_step,
    _features,
    _Floor,
    _params_from_stats,
    _sufficient_stats,
)
from ._gmm import GMM

__all__ = ["direct_update"]

Float = NDArray[np.float64]


def direct_update(
    gmm: GMM,
    x_new: npt.ArrayLike,
    n_old: int,
    *,
    reg_covar: npt.ArrayLike,
    time_dim: int = 0,
    max_iter: int = 100,
    tol: float = 1e-3,
) -> GMM:
    """The mixture ``gmm`` (fitted on ``n_old`` points) updated with the points ``x_new``
    (N, D), K kept (see the module docstring).

    ``reg_covar`` (D,) is the floor the old fit added to every diagonal; ``max_iter`` and
    ``tol`` are EM's (the gain of the new points' mean log-likelihood).
    """
    x_raw = check_array(x_new, "x_new", ndim=2, min_rows=1)
    n_old = check_int(n_old, "n_old", minimum=1)
    k, d = gmm.means_.shape
    if x_raw.shape[1] != d:
        raise ValueError(f"x_new must have {d} columns (the mixture's), got {x_raw.shape[1]}")
    diag = check_array(reg_covar, "reg_covar", shape=(d,))
    center = np.asarray(gmm.weights_ @ gmm.means_, dtype=np.float64)
    x = x_raw - center
    old_count = n_old * gmm.weights_
    old_means = gmm.means_ - center
    old_cov = gmm.covariances_.copy()
    old_cov.reshape(k, d * d)[:, :: d + 1] -= diag  # the floor is the M-step's to add
    old_s1 = old_count[:, None] * old_means
    old_s2 = old_count[:, None, None] * (old_cov + old_means[:, :, None] * old_means[:, None, :])
    span = float(np.ptp(x[:, time_dim]))
    floor = _Floor(diag, time_dim, MIN_TIME_SPREAD * span, MAX_TIME_SPREAD * span)
    feats = _features(x)
    params = (gmm.weights_.copy(), old_means, gmm.covariances_.copy())
    prev = -np.inf
    for _ in range(int(max_iter)):
        resp, ll = _e_step(feats, params)
        s0, s1, s2 = _sufficient_stats(feats, resp)
        params = _params_from_stats(s0 + old_count, s1 + old_s1, s2 + old_s2, floor)
        if abs(ll - prev) < tol:
            break
        prev = ll
    weights, means, cov = params
    return GMM.from_params(weights, means + center, 0.5 * (cov + np.swapaxes(cov, -1, -2)))
