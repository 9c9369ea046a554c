"""Gaussian mixture models over trajectories: time-based EM, and K chosen by cross-validation.

The estimator is a scikit-learn estimator (``BaseEstimator``: ``get_params``, ``clone``, ...):
``__init__`` only stores its arguments, ``fit`` sets every learned attribute (names ending in
``_``), and ``score_samples``, ``predict_proba``, ``bic``, ``aic``, ``sample`` are
``GaussianMixture``'s, computed with the log-density EM uses (:func:`_weighted_log_prob`).

EM (full covariances, log-domain responsibilities) starts from a *time-based* initialisation:
the data are cut into K consecutive bins along the time column and each bin gives one
component's weight, mean and covariance. On trajectory data this start is already close to the
optimum, so EM needs few iterations and the result does not depend on a random seed. EM is a
vectorized loop over the private functions below (one product with precomputed x x^T rows gives
every Mahalanobis distance): a K sweep fits about 50 mixtures, and scikit-learn's per-component
loops cost 1-3 ms per iteration on these tiny problems. ``reg_covar`` (one value or one per
dimension) is added to every covariance's diagonal: in the data's units squared, a floor on the
variability a component can claim.

Floors and scale. A floor in the data's units suits one scale of data only: scikit-learn's 1e-6 is
larger than the whole variance of time over 2 ms (3.3e-7 s^2: one component, a flat GMR) and
1e12 times that of positions in nanometres. The default ``reg_covar=None`` is therefore relative,
:data:`REG_COVAR` (1e-6) times each column's variance, and at most 1e-6 in the data's units
(:func:`scale_aware_floor`): scikit-learn's 1e-6 for every column of variance 1 or more, a floor
of 0.1 % of the standard deviation for smaller ones, so that the mixture and its regression scale
with the data (tested to 1e-3 of the motion on LASA, time times 1e-3 and positions times 1e-9). A
floor given explicitly is kept as given, in the data's units (a still joint under its floor is
data: a skill may hold it still), except that a time floor above :data:`MAX_TIME_FLOOR_FRACTION`
of the time's variance is refused with a ValueError: it would blur every phase of the motion.

Time floor (``min_time_spread``). EM on trajectories has degenerate optima along time: the
demonstrations are sampled on one shared grid of steps, so a component can take the samples of a
single step (of one demonstration, or a few) and shrink its time variance to ``reg_covar``'s
jitter; its density there gains several nats per sample in time alone. This happens where each
demonstration holds still at its own place (the basin task once the glass is carried away: every
demonstration gets a tight component of its own) and one demonstration's last moving sample is
explained by none of them. GMR weighs the components by their time marginals only, so at that one
step the collapsed component takes all the weight and the generalized trajectory (and its
covariance) leaps to one sample and back: a one-step jump no arm can follow. A component narrower
in time than a fraction of the spacing of K components models no structure of the motion, so every
component's time standard deviation is held at ``min_time_spread * span / K`` or more (span: the
time column's range; the K fitted, also in the folds of the cross-validation). The floor widens
only the time marginal p(t) and keeps the component's regression p(x | t), its gain and conditional
covariance (:func:`_floor_time_variance`): the Gaussian log-likelihood splits into the two, so this
is the exact M-step under the constraint and EM stays monotone; flooring Sigma_tt alone would also
flatten the component's slope (the gain Sigma_xt / Sigma_tt). GMR's weight then passes from one
component to the next over at least that fraction of their spacing, never within one step. The
default, :data:`MIN_TIME_SPREAD`, is below the 1/sqrt(12) of the time bins EM starts from and below
the time spread of 95 % of the components plain EM finds on the teacher's tasks: it removes the
collapsed components and leaves the generalized trajectories otherwise about unchanged
(``benchmarks/README.md``, "GMR mean jumps"). ``min_time_spread=0`` gives plain EM; without a time
column there is no floor.

Choosing K (``n_components="auto"``). The unit of independent evidence is the demonstration,
not the sample: 1000 steps of one smooth motion are not 1000 independent draws, so the
Bayesian information criterion, which counts samples, keeps decreasing up to any cap on dense
trajectories (LASA, 7 x 1000 points: minimum at K = 27-30). pbdkit therefore leaves one
demonstration (sequence) out at a time and asks how well the GMR mean of the others, the
generalized trajectory, predicts it:

    score(K) = mean over left-out m of  mean over scored dims d and times t of
               (xi_m,d(t) - mu_K^(-m)_d(t))^2 / s_d(t)^2

with s_d(t)^2 the spread of dimension d across the demonstrations at time t
(:func:`local_spread`; at least ``reg_covar`` and :data:`LOCAL_SPREAD_FLOOR` of the spread
pooled over time): the squared error of their pointwise mean, the floor no time-indexed model
beats (1 = as good as that, at every moment). Dividing by the
spread *at each time* is what keeps a skill's tight phases: where the demonstrations agree
(the hand at the object it grasps) a miss of a few millimetres weighs as much as a miss of
decimetres where they differ, so a K that loses the tight phase scores far worse, whatever the
demonstrations do elsewhere. Pooled over time (``cv_scale="pooled"``, pbdkit's earlier
default, :func:`pooled_spread`) the loose phases dominate: where the demonstrations agree only
briefly and differ by decimetres elsewhere (objects anywhere on a wide table), no K predicts a
left-out demonstration's loose phases, the smallest K wins and the tight phase is lost (on
third-party arms, K = 2-6 for the object's space and a hand that missed the object by 16 mm,
median, up to 94 mm; ``benchmarks/README.md``, "Your own arm").

The left-out model is the fitted one with m's sufficient statistics removed and one EM
iteration on the rest (:func:`_cv_errors`; close to exact refits at a fraction of their
cost). The score falls steeply while components add real structure and then flattens, slowly
still where tight phases gain from narrower components; K is the smallest whose score is within
:data:`CV_TOLERANCE` (3 %, about the resolution of the approximation against exact refits) of
the best K's (:func:`_select_by_cv`), searched on 1..8 and then steps of about 20 % up to
``max_components``. Scores of every K tried, per fold, are in ``selection_``.

Why not a likelihood criterion (``benchmarks/README.md``, "Choosing K", measures them on the
same demonstrations): the BIC with an effective sample size, constant or estimated from the
autocorrelation, and the held-out log-likelihood lose the basin task's pouring gesture: a tight
component is penalized for a left-out demonstration that reaches the same place a few steps
earlier or later, so they prefer few broad components. Plain BIC counts every sample and nears
the cap. The cross-validated regression error measures what the skill uses, the generalized
trajectory, with the demonstration as the unit of evidence.

``n_components="bic"`` scores BIC_eff(K) = -2 (n_eff / N) log L + p(K) log n_eff, the expected
BIC of a subsample of n_eff points (``bic_samples_per_sequence`` per sequence, default 20, or
``bic_samples``), with p(K) = (K - 1) + K D + K D (D + 1) / 2 free parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray
from sklearn.base import BaseEstimator, DensityMixin
from sklearn.exceptions import NotFittedError
from threadpoolctl import threadpool_limits

from .._defaults import MAX_COMPONENTS
from .._validation import check_array, check_int, check_positive_float
from ._gmr import CovarianceMode, GMRModel, gmr_batch, gmr_precompute, gmr_step, gmr_step_1d
from .gaussian import inverse_cholesky_factor

__all__ = [
    "GMM",
    "ModelSelection",
    "effective_bic",
    "local_spread",
    "n_parameters",
    "pooled_spread",
    "scale_aware_floor",
    "sequences_from_time",
    "time_based_init",
]

Float = NDArray[np.float64]


def n_parameters(n_components: int, n_dims: int) -> int:
    """Number of free parameters of a full-covariance GMM: (K-1) + K D + K D (D+1)/2."""
    k, d = n_components, n_dims
    return (k - 1) + k * d + k * d * (d + 1) // 2


def effective_bic(log_likelihood: float, n_samples: int, n_eff: float, n_params: int) -> float:
    """BIC of a subsample of ``n_eff`` points: -2 (n_eff / N) log L + p log n_eff."""
    return float(-2.0 * (n_eff / n_samples) * log_likelihood + n_params * np.log(n_eff))


def count_sequences(t: Float) -> int:
    """Number of sequences stacked in a time column: one plus the number of times it decreases."""
    return int(1 + np.count_nonzero(np.diff(t) < 0))


def sequences_from_time(t: Float) -> NDArray[np.intp]:
    """Sequence label of every row of a stacked time column: a new sequence where time decreases.

    Parameters
    ----------
    t : ndarray, shape (N,)

    Returns
    -------
    groups : ndarray of int, shape (N,)
        0 for the first sequence, 1 for the second, ...
    """
    return np.concatenate([[0], np.cumsum(np.diff(t) < 0)]).astype(np.intp)


# ----------------------------------------------------------------------------- EM core
# Pure functions on float64 arrays; the estimator below is a thin shell around them.
# Parameters travel as (weights (K,), means (K, D), covariances (K, D, D)); precisions as upper
# factors U_k with Sigma_k^-1 = U_k U_k^T (scikit-learn's precisions_cholesky_ convention).
Params = tuple[Float, Float, Float]


def _outer_rows(x: Float) -> Float:
    """x_j x_j^T of every row, flattened: (N, D) -> (N, D*D); precomputed once per fit."""
    n, d = x.shape
    return (x[:, :, None] * x[:, None, :]).reshape(n, d * d)


def _sufficient_stats(x: Float, x2: Float, resp: Float) -> tuple[Float, Float, Float]:
    """sum_j r_jk, sum_j r_jk x_j and sum_j r_jk x_j x_j^T: (K,), (K, D), (K, D, D)."""
    d = x.shape[1]
    return resp.sum(axis=0), resp.T @ x, (resp.T @ x2).reshape(-1, d, d)


@dataclass(frozen=True)
class _Floor:
    """What an M-step may not go below.

    diag : (D,) added to every covariance's diagonal (``reg_covar``).
    time_dim : the time column, or None.
    time_spread : the time standard deviation of every component of a K-component mixture is at
        least ``time_spread / K`` (``min_time_spread`` times the time span: a fraction of the
        components' spacing); 0 for none.
    """

    diag: Float
    time_dim: int | None = None
    time_spread: float = 0.0


def _floor_time_variance(cov: Float, time_dim: int, var_min: float) -> None:
    """Raise every component's time variance s below v = ``var_min`` to v, keeping p(x | t).

    ``cov`` (K, D, D) is changed in place.

    With Sigma = [[s, b^T], [b, S]] (time first), p(x | t) has the gain A = b / s and the
    covariance C = S - b b^T / s; s' = v, b' = A v and S' = C + A A^T v keep both. A Gaussian's
    log-likelihood is log p(t) + log p(x | t) with separate parameters, so this is the exact
    maximum of the M-step under the constraint s >= v, and EM stays monotone.
    """
    s = cov[:, time_dim, time_dim]
    short = np.flatnonzero(s < var_min)
    if short.size == 0:
        return
    c = cov[short]
    s_k = s[short]
    b = c[:, :, time_dim].copy()
    b[:, time_dim] = 0.0
    # A = b / s; s = 0 (no reg_covar on time, one time value) has b = 0 and no gain.
    gain = np.divide(b, s_k[:, None], out=np.zeros_like(b), where=s_k[:, None] > 0.0)
    c += (var_min - s_k)[:, None, None] * (gain[:, :, None] * gain[:, None, :])
    c[:, :, time_dim] = var_min * gain
    c[:, time_dim, :] = var_min * gain
    c[:, time_dim, time_dim] = var_min
    cov[short] = c


def _params_from_stats(
    s0: Float, s1: Float, s2: Float, floor: _Floor, n_components: int | None = None
) -> Params:
    """M-step: weights, means and covariances (+ the floors: on the diagonal, on time).

    ``n_components`` is the K of the time floor (default: the number of components given); a
    cross-validation fold that drops components keeps the floor of the model it comes from.
    """
    nk = s0 + 10.0 * np.finfo(np.float64).eps  # scikit-learn's guard against empty components
    means = s1 / nk[:, None]
    cov = s2 / nk[:, None, None] - means[:, :, None] * means[:, None, :]
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    idx = np.arange(cov.shape[-1])
    cov[:, idx, idx] += floor.diag
    if floor.time_dim is not None and floor.time_spread > 0.0:
        k = cov.shape[0] if n_components is None else n_components
        _floor_time_variance(cov, floor.time_dim, (floor.time_spread / k) ** 2)
    return nk / nk.sum(), means, cov


def _precision_factors(covariances: Float) -> Float:
    """U_k with Sigma_k^-1 = U_k U_k^T (U_k = L_k^-T for Sigma_k = L_k L_k^T), batched."""
    linv = inverse_cholesky_factor(covariances, "covariances", message=_not_positive_definite)
    return np.swapaxes(linv, -1, -2)


def _not_positive_definite(covariances: Float) -> str:
    """Error message naming the first component whose covariance has no Cholesky factor."""
    k = 0
    for k in range(covariances.shape[0]):
        try:
            np.linalg.cholesky(covariances[k])
        except np.linalg.LinAlgError:
            break
    cov = covariances[k]
    var = np.diagonal(cov)
    j = int(np.argmin(var))
    if var[j] <= 1e-12 * max(float(var.max()), np.finfo(np.float64).tiny):
        what = f"component {k} has variance {var[j]:.3g} in dimension {j}"
    else:
        what = (
            f"component {k} has a covariance that is not positive definite (smallest "
            f"eigenvalue {np.linalg.eigvalsh(cov).min():.3g}: its data lie on a lower-"
            "dimensional subspace)"
        )
    return f"{what} (degenerate data); increase reg_covar, or scale the input data"


def _log_gauss(x: Float, x2: Float, means: Float, factors: Float) -> Float:
    """log N(x_j; mu_k, Sigma_k) for every row and component: (N, K).

    Mahalanobis terms from one product with the precomputed x x^T rows:
    (x - mu)^T P (x - mu) = vec(x x^T) . vec(P) - 2 x . P mu + mu^T P mu, P = U U^T.
    Callers centre x (a shift of every mean leaves the mixture unchanged), which keeps the
    expansion free of cancellation.
    """
    k, d = means.shape
    prec = factors @ np.swapaxes(factors, -1, -2)  # (K, D, D)
    p_mu = np.einsum("kij,kj->ki", prec, means)
    maha = x2 @ prec.reshape(k, d * d).T - 2.0 * (x @ p_mu.T) + np.einsum("ki,ki->k", means, p_mu)
    # log|Sigma|^(-1/2) = sum log diag(U)
    half_log_det = np.log(np.diagonal(factors, axis1=1, axis2=2)).sum(axis=1)
    return np.asarray(half_log_det - 0.5 * (d * np.log(2.0 * np.pi) + np.maximum(maha, 0.0)))


def _weighted_log_prob(x: Float, x2: Float, weights: Float, means: Float, factors: Float) -> Float:
    """log pi_k + log N(x_j; mu_k, Sigma_k) for every row and component: (N, K).

    The one log-density of the mixture: EM and the estimator's ``score_samples``,
    ``predict_proba``, ``bic``, ... all call it (x and means centred, see :func:`_log_gauss`).
    """
    with np.errstate(divide="ignore"):  # a component of weight 0 has log pi = -inf
        return _log_gauss(x, x2, means, factors) + np.log(weights)


def _log_resp(lp: Float) -> tuple[Float, Float]:
    """p(k | x_j) (N, K) and log p(x_j) (N,) from the weighted log-probabilities (N, K).

    log p(x) = m + log sum_k exp(lp_k - m), m = max_k lp_k (log-sum-exp, no overflow).
    """
    top = lp.max(axis=1, keepdims=True)
    e = np.exp(lp - top)
    total = e.sum(axis=1, keepdims=True)
    return e / total, top[:, 0] + np.log(total[:, 0])


def _e_step(x: Float, x2: Float, params: Params) -> tuple[Float, float]:
    """Responsibilities (N, K) in the log domain, and the mean log-likelihood per sample."""
    weights, means, cov = params
    resp, log_density = _log_resp(
        _weighted_log_prob(x, x2, weights, means, _precision_factors(cov))
    )
    return resp, float(np.mean(log_density))


def _em(
    x: Float, resp: Float, floor: _Floor, max_iter: int, tol: float
) -> tuple[Params, Float, int, bool, float]:
    """EM for a full-covariance GMM from initial responsibilities (N, K).

    Stops when the mean log-likelihood per sample gains less than ``tol`` (scikit-learn's rule).

    Returns
    -------
    params, resp, n_iter, converged, log_likelihood (total over the rows)
    """
    x2 = _outer_rows(x)
    params = _params_from_stats(*_sufficient_stats(x, x2, resp), floor)
    prev = -np.inf
    converged = False
    n_iter = 0
    for n_iter in range(1, max_iter + 1):  # noqa: B007 (n_iter is reported)
        resp, ll = _e_step(x, x2, params)
        params = _params_from_stats(*_sufficient_stats(x, x2, resp), floor)
        if abs(ll - prev) < tol:
            converged = True
            break
        prev = ll
    resp, ll = _e_step(x, x2, params)
    return params, resp, n_iter, converged, ll * x.shape[0]


def _time_bins_resp(x: Float, n_components: int, time_dim: int) -> Float:
    """Hard responsibilities of K consecutive bins of equal count along time: (N, K)."""
    n = x.shape[0]
    order = np.argsort(x[:, time_dim], kind="stable")
    resp = np.zeros((n, n_components))
    for k, b in enumerate(np.array_split(order, n_components)):
        resp[b, k] = 1.0
    return resp


def time_based_init(
    X: Float, n_components: int, time_dim: int, reg_covar: float
) -> tuple[Float, Float, Float]:
    """Weights, means and precisions of K components from K consecutive bins along time.

    The samples are ordered by ``X[:, time_dim]`` and split into K bins of equal count; each bin
    gives a component (its share of samples, its mean, its covariance plus ``reg_covar``).

    Parameters
    ----------
    X : ndarray, shape (N, D)
    n_components : int
    time_dim : int
    reg_covar : float

    Returns
    -------
    weights : ndarray, shape (K,)
    means : ndarray, shape (K, D)
    precisions : ndarray, shape (K, D, D)
    """
    x = np.asarray(X, dtype=np.float64)
    resp = _time_bins_resp(x, n_components, time_dim)
    # Floor each bin's covariance with a fraction of the global variance so that a bin of
    # (nearly) constant data still gives a usable start.
    floor = _Floor(1e-3 * np.var(x, axis=0) + reg_covar)
    w, m, cov = _params_from_stats(*_sufficient_stats(x, _outer_rows(x), resp), floor)
    u = _precision_factors(cov)
    prec = u @ np.swapaxes(u, -1, -2)
    return w, m, 0.5 * (prec + np.swapaxes(prec, -1, -2))


def _check_rng(
    random_state: int | np.random.Generator | np.random.RandomState | None,
) -> np.random.Generator | np.random.RandomState:
    """A numpy generator from a seed (``default_rng``), or the generator given."""
    if isinstance(random_state, (np.random.Generator, np.random.RandomState)):
        return random_state
    if random_state is None or (
        isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool)
    ):
        return np.random.default_rng(random_state)
    raise ValueError(
        "random_state must be None, an integer, a numpy Generator or a numpy RandomState, "
        f"got {random_state!r}"
    )


def _check_covariances(covariances: Float, name: str) -> Float:
    """Cholesky factors of each covariance, or a ValueError naming the singular component."""
    chol = np.empty_like(covariances)
    for k, cov in enumerate(covariances):
        if not np.allclose(cov, cov.T, rtol=1e-8, atol=1e-12 * max(1.0, np.abs(cov).max())):
            raise ValueError(f"{name}[{k}] must be symmetric")
        try:
            chol[k] = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            w = np.linalg.eigvalsh(cov)
            raise ValueError(
                f"{name}[{k}] must be positive definite, got smallest eigenvalue {w.min():.3g}; "
                "add a small value to its diagonal (pbdkit.prob.gaussian.regularize_covariance)"
            ) from None
    return chol


# ----------------------------------------------------------------------------- choosing K
def _bin_variances(
    x: Float, groups: NDArray[np.intp], time_dim: int
) -> tuple[list[NDArray[np.intp]], Float]:
    """The rows sorted by time and cut into bins of as many rows as there are sequences, and
    the variance of every column within each bin: (rows of each bin, (n_bins, D))."""
    n_groups = int(groups.max()) + 1
    order = np.argsort(x[:, time_dim], kind="stable")
    bins = np.array_split(order, max(1, x.shape[0] // n_groups))
    return bins, np.stack([x[b].var(axis=0) for b in bins])


def _pooled(bins: list[NDArray[np.intp]], variances: Float) -> Float:
    return np.asarray(np.average(variances, axis=0, weights=[len(b) for b in bins]))


def _local(bins: list[NDArray[np.intp]], variances: Float, n_rows: int) -> Float:
    out = np.empty((n_rows, variances.shape[1]))
    for b, v in zip(bins, variances, strict=True):
        out[b] = v
    return out


def pooled_spread(x: Float, groups: NDArray[np.intp], time_dim: int) -> Float:
    """Variance of every column across sequences at equal times, pooled over time: (D,).

    The rows are sorted by time and cut into bins of as many rows as there are sequences (on a
    shared time grid, one bin per time step holding one sample of every sequence); the
    within-bin variances are averaged. It is the squared error of the pointwise mean of the
    sequences: the floor no time-indexed model can go below (the demonstrations' variability).
    """
    return _pooled(*_bin_variances(x, groups, time_dim))


def local_spread(x: Float, groups: NDArray[np.intp], time_dim: int) -> Float:
    """Variance of every column across sequences at each row's time: (N, D).

    The bins of :func:`pooled_spread` (one per time step on a shared grid), not pooled: each
    row gets the variance of its own bin, the demonstrations' variability at that moment.
    """
    return _local(*_bin_variances(x, groups, time_dim), x.shape[0])


@dataclass(frozen=True)
class ModelSelection:
    """How K was chosen for one GMM (see the module docstring, "Choosing K").

    Attributes
    ----------
    method : str
        ``"cv"``: cross-validation over left-out sequences; ``"bic"``: effective-sample-size BIC;
        ``"fixed"``: K given.
    candidates : tuple of int
        The K tried, ascending.
    scores : ndarray, shape (len(candidates),)
        ``"cv"``: mean over left-out sequences of the normalized squared error of the GMR mean
        (1 = the demonstrations' own variability); ``"bic"``: BIC_eff. Lower is better.
    fold_scores : ndarray, shape (len(candidates), n_folds)
        ``"cv"``: the error of each left-out sequence (``scores`` is their mean); empty for
        other methods.
    best : int
        K with the lowest score.
    chosen : int
        The K kept: for ``"cv"`` the smallest K whose score is within :data:`CV_TOLERANCE` of
        the best's; otherwise the best.
    n_folds : int
        Sequences left out one at a time (``"cv"``), else 0.
    """

    method: str
    candidates: tuple[int, ...]
    scores: Float
    fold_scores: Float
    best: int
    chosen: int
    n_folds: int

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready copy."""
        return {
            "method": self.method,
            "candidates": list(self.candidates),
            "scores": [float(v) for v in self.scores],
            "fold_scores": self.fold_scores.tolist(),
            "best": self.best,
            "chosen": self.chosen,
            "n_folds": self.n_folds,
        }


_Fit = tuple[Params, Float, int, bool, float]  # params, resp, n_iter, converged, log L


def candidate_grid(max_components: int) -> list[int]:
    """The K that ``"auto"`` tries first: every K up to 8, then steps of about 20 %, and the cap.

    Between the chosen grid point and the one below it every K is tried too (see
    :func:`_select_by_cv`), so the grid only saves the fits far from the choice.
    """
    grid = list(range(1, min(8, max_components) + 1))
    while grid[-1] < max_components:
        grid.append(min(max_components, max(grid[-1] + 1, round(grid[-1] * 1.2))))
    return grid


#: EM tolerance of the fits screened while choosing K (the kept fit is refined to ``tol``).
SWEEP_TOL = 1e-2
#: "auto": a K whose cross-validated error is within this fraction of the best K's is as good
#: as the best. It is about the accuracy of the approximate leave-one-out of :func:`_cv_errors`
#: against exact refits near the chosen K (``benchmarks/bench_selection.py``): smaller
#: differences are not resolved by it.
CV_TOLERANCE = 0.03
#: "auto" with ``cv_scale="local"``: the spread at a moment is at least this fraction of the
#: spread pooled over time (a phase weighs at most 100 times the average): one time step where
#: every demonstration is exactly alike (LASA's shared end point) would otherwise decide K alone.
LOCAL_SPREAD_FLOOR = 0.01
#: Default ``min_time_spread``: every component's time standard deviation is at least this
#: fraction of the components' spacing (the time span over K); module docstring, "Time floor".
MIN_TIME_SPREAD = 0.2
#: ``reg_covar=None``: the floor of a column is this fraction of its variance, and at most this
#: value in the data's units (scikit-learn's default ``reg_covar``).
REG_COVAR = 1e-6
#: A time floor (``reg_covar`` of the time column) above this fraction of the time column's
#: variance is refused: every component would be at least a third of the time's standard
#: deviation (9 % of the span) wide, too wide for more than about five components to be told
#: apart along time (LASA's G drawn in 2 ms under a floor of 1e-6 s^2, 3 times the time's
#: variance: one component, a GMR mean 0.95 of the shape's spread off the demonstrations' mean).
MAX_TIME_FLOOR_FRACTION = 0.1


def scale_aware_floor(X: npt.ArrayLike) -> Float:
    """The floor of ``reg_covar=None``: per column, REG_COVAR min(1, var), var its variance.

    A constant column takes the largest column variance as its scale (its floor only needs to
    be positive: every component has the same variance there); all-constant data take
    :data:`REG_COVAR`.

    Parameters
    ----------
    X : array-like, shape (N, D)

    Returns
    -------
    reg_covar : ndarray, shape (D,)
    """
    var = check_array(X, "X", ndim=2).var(axis=0)
    scale = np.where(var > 0.0, var, var.max(initial=0.0))
    floor = REG_COVAR * np.minimum(1.0, scale)
    return np.where(floor > 0.0, floor, REG_COVAR)


def _check_time_floor(x: Float, floor: Float, time_dim: int | None) -> None:
    """Refuse a time floor that would hide the motion (module docstring, "Floors and scale").

    Only time: a still joint under its floor is data (a skill may hold a joint still).
    """
    if time_dim is None:
        return
    v, f = float(x[:, time_dim].var()), float(floor[time_dim])
    if v > 0.0 and f > MAX_TIME_FLOOR_FRACTION * v:
        raise ValueError(
            f"reg_covar of the time column X[:, {time_dim}] is {f:.3g}, {f / v:.3g} times "
            f"its variance ({v:.3g}; at most {MAX_TIME_FLOOR_FRACTION:g} times is allowed): "
            "no component could be narrower in time than the motion; pass reg_covar=None "
            f"(scale-aware), a time floor of at most {MAX_TIME_FLOOR_FRACTION * v:.3g}, or "
            "time in longer units"
        )


def _select_by_cv(
    candidates: Sequence[int], cv: Callable[[int], Float], n_folds: int
) -> ModelSelection:
    """The smallest K whose cross-validated error is within :data:`CV_TOLERANCE` of the best.

    ``cv(k)`` gives the error of every left-out sequence, (n_folds,). K is searched on
    :func:`candidate_grid` of ``max(candidates)``; then every K between the grid point chosen
    and the one below it is tried, in increasing order, against the same best.
    """
    errors: dict[int, Float] = {k: cv(k) for k in candidate_grid(max(candidates))}
    best = min(errors, key=lambda k: float(errors[k].mean()))
    bound = (1.0 + CV_TOLERANCE) * float(errors[best].mean())

    def good(k: int) -> bool:
        return float(errors[k].mean()) <= bound

    grid = sorted(errors)
    chosen = next(k for k in grid if good(k))
    below = max([k for k in grid if k < chosen], default=chosen)
    for k in range(below + 1, chosen):
        errors[k] = cv(k)
        if good(k):
            chosen = k
            break
    tried = sorted(errors)
    return ModelSelection(
        "cv",
        tuple(tried),
        np.array([errors[k].mean() for k in tried]),
        np.stack([errors[k] for k in tried]),
        best,
        chosen,
        n_folds,
    )


def _drop_empty(params: Params, min_weight: float) -> Params:
    w, m, c = params
    keep = w > min_weight
    if keep.all():
        return params
    return w[keep] / w[keep].sum(), m[keep], c[keep]


def _cv_errors(
    x: Float,
    x2: Float,
    resp: Float,
    groups: NDArray[np.intp],
    floor: _Floor,
    time_dim: int,
    score_dims: Sequence[int],
    scale: Float,
) -> Float:
    """Leave-one-sequence-out error of the GMR mean for one K: (n_groups,).

    For the fold without sequence m the model is the fitted one with m's contributions removed
    from the sufficient statistics, followed by one EM iteration on the remaining rows (exact
    refits move the errors by a few percent and cost 5-10 times more). The error of fold m is
    the mean over ``score_dims`` of the squared difference between sequence m and the fold's
    GMR mean at m's times, divided by ``scale``: (N, S), every row's own (the local spread
    of each scored dimension), or (S,), one per dimension (the pooled spread).
    """
    stats = _sufficient_stats(x, x2, resp)
    n_components = resp.shape[1]  # the fit's K: its time floor holds in every fold
    n_groups = int(groups.max()) + 1
    out_dims = [i for i in range(x.shape[1]) if i != time_dim]
    pos = [out_dims.index(i) for i in score_dims]
    errors = np.empty(n_groups)
    for m in range(n_groups):
        held = groups == m
        rest = ~held
        own = _sufficient_stats(x[held], x2[held], resp[held])
        s0 = stats[0] - own[0]
        # A component (nearly) made of sequence m alone has no support left in the fold: drop
        # it (its downdated moments are rounding noise).
        keep = s0 >= 1.0
        params = _params_from_stats(
            s0[keep], (stats[1] - own[1])[keep], (stats[2] - own[2])[keep], floor, n_components
        )
        n_rest = float(np.count_nonzero(rest))
        r, _ = _e_step(x[rest], x2[rest], params)
        params = _drop_empty(
            _params_from_stats(*_sufficient_stats(x[rest], x2[rest], r), floor, n_components),
            0.5 / n_rest,
        )
        model = gmr_precompute(*params, (time_dim,))
        mean, _ = gmr_batch(model, x[held][:, [time_dim]], None)
        err = (x[held][:, score_dims] - mean[:, pos]) ** 2
        errors[m] = float(np.mean(err / (scale[held] if scale.ndim == 2 else scale)))
    return errors


class GMM(DensityMixin, BaseEstimator):  # type: ignore[misc]  # scikit-learn is untyped
    """Gaussian mixture model with time-based EM initialisation and a choice of K.

    A scikit-learn estimator (``get_params``, ``set_params``, ``sklearn.base.clone``, its repr;
    :class:`sklearn.exceptions.NotFittedError` before ``fit``) with the methods of
    ``GaussianMixture`` (``score_samples``, ``score``, ``predict_proba``, ``predict``, ``bic``,
    ``aic``, ``sample``), all from the log-density EM maximizes. EM is pbdkit's own
    (module docstring), not scikit-learn's loop.

    Parameters
    ----------
    n_components : int, "auto" or "bic"
        Number of components K; ``"auto"`` chooses K in 1..``max_components`` by
        cross-validation over the sequences (module docstring, "Choosing K"; needs a time
        column and at least 2 sequences); ``"bic"`` by the effective-sample-size BIC.
    max_components : int or None
        Largest K tried when K is chosen. None (default): :data:`MAX_COMPONENTS`, the cap
        :class:`pbdkit.Skill` and the command line use too.
    reg_covar : float, array-like of shape (D,), or None
        Added to the diagonal of every covariance: one value for every dimension, or one per
        dimension. In the units of the data squared, it is a floor on the variability a
        component can claim (scikit-learn's ``reg_covar``, per dimension). None (default):
        scale-aware, :data:`REG_COVAR` (1e-6) times each column's variance and at most 1e-6
        (module docstring, "Floors and scale"): scikit-learn's 1e-6 for columns of variance 1
        or more, 0.1 % of the standard deviation at smaller scales, so the fit scales with the
        data (milliseconds, nanometres). A given value is taken as is, in the data's units; a
        time floor above :data:`MAX_TIME_FLOOR_FRACTION` of the time column's variance is
        refused (it would blur every phase of the motion).
    max_iter : int
        Maximum number of EM iterations per fit.
    tol : float
        EM convergence threshold on the per-sample log-likelihood gain.
    random_state : int, numpy RandomState or None
        Seed of the k-means initialisation (``init="kmeans"``; time-based EM is deterministic)
        and of ``sample`` when it is given none.
    time_dim : int or None
        Column holding time; used for the time-based initialisation, to find the sequences and
        as the input of the GMR that ``"auto"`` cross-validates. ``None`` falls back to k-means
        initialisation.
    init : {"time", "kmeans"}
        Initialisation of EM.
    score_dims : sequence of int, optional
        Dimensions whose GMR error ``"auto"`` scores (default: every dimension but time).
    bic_samples_per_sequence : float
        ``"bic"`` only: effective number of samples per sequence (default 20).
    bic_samples : int, optional
        ``"bic"`` only: total effective sample size; overrides ``bic_samples_per_sequence``.
    min_time_spread : float
        With a time column: every component's time standard deviation is at least this
        fraction of the components' spacing, ``min_time_spread * span / K`` (span: the range of
        the time column), which keeps EM from collapsing a component onto the samples of one
        time step (module docstring, "Time floor"). Only the time marginal of a component is
        widened; its regression p(x | t) is kept. 0 disables it. Default
        :data:`MIN_TIME_SPREAD`.
    cv_scale : {"local", "pooled"}
        ``"auto"`` only: what a left-out demonstration's squared error is divided by. ``"local"``
        (default): the demonstrations' variance at that time (:func:`local_spread`, at least
        :data:`LOCAL_SPREAD_FLOOR` of the pooled one), so a phase where they agree weighs as
        much as it is tight; ``"pooled"``: their variance pooled over time
        (:func:`pooled_spread`; pbdkit's earlier default, which lost such phases where the
        demonstrations differ elsewhere). Module docstring, "Choosing K".

    Attributes
    ----------
    weights_ : ndarray, shape (K,)
    means_ : ndarray, shape (K, D)
    covariances_ : ndarray, shape (K, D, D)
    n_components_ : int
        K (chosen when ``n_components`` is ``"auto"`` or ``"bic"``). The repr shows the
        constructor's arguments only (scikit-learn's), so K is read here.
    n_features_in_ : int
        D, the number of columns of X (scikit-learn's name; also ``n_dims_``).
    converged_ : bool
        Whether EM converged for the kept model.
    n_iter_ : int
        EM iterations for the kept model.
    selection_ : ModelSelection
        The K tried, their scores and the K kept.
    bic_scores_ : dict of int to float
        ``"bic"``: effective BIC of every K tried; empty otherwise.
    bic_effective_samples_ : float
        ``"bic"``: n_eff used in the BIC; NaN otherwise.
    """

    def __init__(
        self,
        n_components: int | Literal["auto", "bic"] = 5,
        *,
        max_components: int | None = None,
        reg_covar: float | npt.ArrayLike | None = None,
        max_iter: int = 100,
        tol: float = 1e-3,
        random_state: int | np.random.RandomState | None = None,
        time_dim: int | None = 0,
        init: Literal["time", "kmeans"] = "time",
        score_dims: Sequence[int] | None = None,
        bic_samples_per_sequence: float = 20.0,
        bic_samples: int | None = None,
        min_time_spread: float = MIN_TIME_SPREAD,
        cv_scale: Literal["local", "pooled"] = "local",
    ) -> None:
        self.n_components = n_components
        self.max_components = max_components
        self.reg_covar = reg_covar
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.time_dim = time_dim
        self.init = init
        self.score_dims = score_dims
        self.bic_samples_per_sequence = bic_samples_per_sequence
        self.bic_samples = bic_samples
        self.min_time_spread = min_time_spread
        self.cv_scale = cv_scale

    # ------------------------------------------------------------------ fitting
    def _check_params(self, x: Float) -> tuple[str, list[int], Float]:
        """Validated (method, candidate Ks, per-dimension floor) for the data x (N, D)."""
        n_samples, n_dims = x.shape
        reg = self.reg_covar
        if reg is None:
            floor = scale_aware_floor(x)
        elif np.ndim(reg) == 0:
            floor = np.full(n_dims, check_positive_float(reg, "reg_covar", allow_zero=True))
        else:
            floor = check_array(reg, "reg_covar", shape=(n_dims,))
            if np.any(floor < 0):
                raise ValueError(f"reg_covar must be >= 0 in every dimension, got {floor.tolist()}")
        check_int(self.max_iter, "max_iter", minimum=1)
        check_positive_float(self.tol, "tol", allow_zero=True)
        if self.cv_scale not in ("local", "pooled"):
            raise ValueError(f"cv_scale must be 'local' or 'pooled', got {self.cv_scale!r}")
        if self.init not in ("time", "kmeans"):
            raise ValueError(f"init must be 'time' or 'kmeans', got {self.init!r}")
        if self.time_dim is not None:
            td = check_int(self.time_dim, "time_dim", minimum=0)
            if td >= n_dims:
                raise ValueError(f"time_dim must be in [0, {n_dims}) for X with {n_dims} columns")
        _check_time_floor(x, floor, None if self.time_dim is None else int(self.time_dim))
        if isinstance(self.n_components, str):
            if self.n_components not in ("auto", "bic"):
                raise ValueError(
                    "n_components must be a positive integer, 'auto' or 'bic', "
                    f"got {self.n_components!r}"
                )
            if self.n_components == "auto" and self.time_dim is None:
                raise ValueError(
                    "n_components='auto' cross-validates a regression on time and needs "
                    "time_dim; use n_components='bic' or an integer"
                )
            kmax = MAX_COMPONENTS if self.max_components is None else self.max_components
            kmax = check_int(kmax, "max_components", minimum=1)
            kmax = min(kmax, n_samples)
            return self.n_components, list(range(1, kmax + 1)), floor
        k = check_int(self.n_components, "n_components", minimum=1)
        if k > n_samples:
            raise ValueError(
                f"X has too few samples for n_components={k}: need at least {k} rows, "
                f"got {n_samples}; lower n_components or give more data"
            )
        return "fixed", [k], floor

    def _n_eff(self, n: int, n_seq: int) -> float:
        if self.bic_samples is not None:
            return float(min(check_int(self.bic_samples, "bic_samples", minimum=1), n))
        per = check_positive_float(self.bic_samples_per_sequence, "bic_samples_per_sequence")
        return float(min(n, per * n_seq))

    def _check_groups(self, groups: npt.ArrayLike | None, x: Float) -> NDArray[np.intp]:
        if groups is None:
            if self.time_dim is None:
                return np.zeros(x.shape[0], dtype=np.intp)
            return sequences_from_time(x[:, self.time_dim])
        g = np.asarray(groups)
        if g.shape != (x.shape[0],):
            raise ValueError(f"groups must have shape ({x.shape[0]},), got {g.shape}")
        _, labels = np.unique(g, return_inverse=True)
        return np.asarray(labels, dtype=np.intp).reshape(-1)

    def _initial_resp(self, x: Float, k: int) -> Float:
        if self.init == "time" and self.time_dim is not None:
            return _time_bins_resp(x, k, self.time_dim)
        from sklearn.cluster import KMeans

        labels = KMeans(n_clusters=k, n_init=1, random_state=self.random_state).fit(x).labels_
        resp = np.zeros((x.shape[0], k))
        resp[np.arange(x.shape[0]), labels] = 1.0
        return resp

    def fit(
        self, X: npt.ArrayLike, y: object = None, *, groups: npt.ArrayLike | None = None
    ) -> GMM:
        """Fit the mixture to X by EM (choosing K if asked).

        Parameters
        ----------
        X : array-like, shape (N, D)
            Samples in rows; column ``time_dim`` (0 by default) holds time.
        y : ignored
            Ignored, present for API consistency by convention (scikit-learn's
            ``fit(X, y)``: a Pipeline passes its targets here).
        groups : array-like, shape (N,), optional
            Keyword-only. Sequence (demonstration) of every row. Default: a new sequence
            wherever the time column decreases (stacked demonstrations), or one sequence
            without a time column.

        Returns
        -------
        self : GMM
        """
        x_raw = check_array(X, "X", ndim=2, min_rows=2)
        n, d = x_raw.shape
        method, candidates, diag = self._check_params(x_raw)
        spread = check_positive_float(self.min_time_spread, "min_time_spread", allow_zero=True)
        # A constant column with no floor gives every component a zero variance there.
        flat = np.flatnonzero((np.ptp(x_raw, axis=0) == 0.0) & (diag <= 0.0))
        if flat.size:
            j = int(flat[0])
            also = f" (so are dimensions {flat[1:].tolist()})" if flat.size > 1 else ""
            raise ValueError(
                f"X[:, {j}] is constant ({float(x_raw[0, j])!r}) and reg_covar is 0 there"
                f"{also}: every component would have zero variance in that dimension; "
                "increase reg_covar (e.g. 1e-6, or one value per dimension), or drop the column"
            )
        grp = self._check_groups(groups, x_raw)
        n_seq = int(grp.max()) + 1
        if method == "auto" and n_seq < 2:
            raise ValueError(
                "n_components='auto' leaves one sequence out at a time and needs at least 2 "
                f"sequences, got {n_seq}; pass groups=, or use n_components='bic' or an integer"
            )
        # One canonical row order (by sequence, then time): the fit does not depend on how the
        # rows were given. A shift of every mean leaves the mixture unchanged; centring keeps
        # the Mahalanobis expansion of _log_gauss free of cancellation.
        order = np.lexsort((x_raw[:, self.time_dim], grp)) if self.time_dim is not None else None
        if order is not None:
            x_raw, grp = x_raw[order], grp[order]
        center = x_raw.mean(axis=0)
        x = x_raw - center
        x2 = _outer_rows(x)
        max_iter, tol = int(self.max_iter), float(self.tol)
        fits: dict[int, _Fit] = {}
        if self.time_dim is None:
            floor = _Floor(diag)
        else:
            # The smallest time standard deviation of K components: spread * span / K.
            floor = _Floor(diag, int(self.time_dim), spread * float(np.ptp(x[:, self.time_dim])))

        # Screening fits of a sweep stop at a looser tolerance; the kept one is refined below.
        sweep_tol = tol if method == "fixed" else max(tol, SWEEP_TOL)

        def fit_k(k: int) -> _Fit:
            if k not in fits:
                fits[k] = _em(x, self._initial_resp(x, k), floor, max_iter, sweep_tol)
            return fits[k]

        n_eff = float("nan")
        with threadpool_limits(limits=1, user_api="blas"):
            if method == "auto":
                assert self.time_dim is not None
                td = int(self.time_dim)
                score_dims = self._check_score_dims(d, td)
                bins, variances = _bin_variances(x, grp, td)
                spread_ = _pooled(bins, variances)[score_dims]
                if self.cv_scale == "local":
                    local = _local(bins, variances, n)[:, score_dims]
                    spread_ = np.maximum(local, LOCAL_SPREAD_FLOOR * spread_)
                scale = np.maximum(spread_, diag[score_dims])
                scale = np.where(scale > 0, scale, 1.0)

                def cv(k: int) -> Float:
                    return _cv_errors(x, x2, fit_k(k)[1], grp, floor, td, score_dims, scale)

                self.selection_ = _select_by_cv(candidates, cv, n_seq)
            else:
                if method == "bic":
                    n_eff = self._n_eff(n, n_seq)
                    scores = [
                        effective_bic(fit_k(k)[4], n, n_eff, n_parameters(k, d)) for k in candidates
                    ]
                    best = candidates[int(np.argmin(scores))]
                else:
                    fit_k(candidates[0])
                    scores, best = [float("nan")], candidates[0]
                self.selection_ = ModelSelection(
                    method, tuple(candidates), np.asarray(scores), np.zeros((0, 0)), best, best, 0
                )
        chosen = self.selection_.chosen
        fit = fits[chosen]
        if sweep_tol > tol:
            with threadpool_limits(limits=1, user_api="blas"):
                more = _em(x, fit[1], floor, max_iter, tol)
            fit = (more[0], more[1], fit[2] + more[2], more[3], more[4])
        (weights, means, cov), _, n_iter, converged, _ = fit
        self.weights_ = np.asarray(weights, dtype=np.float64)
        self.means_ = np.asarray(means + center, dtype=np.float64)
        self.covariances_ = 0.5 * (cov + np.swapaxes(cov, -1, -2))
        self.n_components_ = int(self.weights_.shape[0])
        self.converged_ = bool(converged)
        self.n_iter_ = int(n_iter)
        sel = self.selection_
        self.bic_scores_ = (
            dict(zip(sel.candidates, sel.scores.tolist(), strict=True)) if method == "bic" else {}
        )
        self.bic_effective_samples_ = n_eff
        self._finalize()
        return self

    def _check_score_dims(self, n_dims: int, time_dim: int) -> list[int]:
        if self.score_dims is None:
            return [i for i in range(n_dims) if i != time_dim]
        dims = [check_int(i, "score_dims", minimum=0) for i in self.score_dims]
        if (
            not dims
            or any(i >= n_dims or i == time_dim for i in dims)
            or len(set(dims)) < len(dims)
        ):
            raise ValueError(
                f"score_dims must be distinct dimensions in [0, {n_dims}) other than time "
                f"({time_dim}), got {list(self.score_dims)}"
            )
        return dims

    @classmethod
    def from_params(
        cls, weights: npt.ArrayLike, means: npt.ArrayLike, covariances: npt.ArrayLike
    ) -> GMM:
        """A fitted GMM from given parameters, without EM.

        Parameters
        ----------
        weights : array-like, shape (K,)
            Non-negative, summing to 1.
        means : array-like, shape (K, D)
        covariances : array-like, shape (K, D, D)
            Symmetric positive definite.

        Returns
        -------
        gmm : GMM
        """
        w = check_array(weights, "weights", ndim=1, min_rows=1)
        k = w.shape[0]
        m = check_array(means, "means", shape=(k, None))
        d = m.shape[1]
        c = check_array(covariances, "covariances", shape=(k, d, d))
        if np.any(w < 0):
            raise ValueError(f"weights must be >= 0, got min {w.min():.3g}")
        if not np.isclose(w.sum(), 1.0, rtol=0, atol=1e-8):
            raise ValueError(f"weights must sum to 1, got {w.sum():.12g}")
        _check_covariances(c, "covariances")
        gmm = cls(n_components=k)
        gmm.weights_ = w.copy()
        gmm.means_ = m.copy()
        gmm.covariances_ = c.copy()
        gmm.n_components_ = k
        gmm.converged_ = True
        gmm.n_iter_ = 0
        gmm.bic_scores_ = {}
        gmm.bic_effective_samples_ = float("nan")
        gmm.selection_ = ModelSelection(
            "fixed", (k,), np.full(1, np.nan), np.zeros((0, 0)), k, k, 0
        )
        gmm._finalize()
        return gmm

    def _finalize(self) -> None:
        # What every density needs, computed once: the upper precision factors, and the centre
        # (sum_k pi_k mu_k: after an M-step the data mean that fit centres by, up to rounding)
        # that keeps the expansion of _log_gauss free of cancellation.
        self.n_features_in_ = int(self.means_.shape[1])
        self._prec_factors = _precision_factors(self.covariances_)
        self._center = np.asarray(self.weights_ @ self.means_, dtype=np.float64)
        self._gmr_cache: dict[tuple[int, ...], GMRModel] = {}

    def __sklearn_is_fitted__(self) -> bool:
        return hasattr(self, "covariances_")

    def _check_fitted(self) -> None:
        if not hasattr(self, "covariances_"):
            raise NotFittedError(
                "this GMM is not fitted yet: call fit(X) or build it with GMM.from_params(...)"
            )

    # --------------------------------------------------------------- densities
    @property
    def n_dims_(self) -> int:
        self._check_fitted()
        return int(self.means_.shape[1])

    def _check_X(self, X: npt.ArrayLike, name: str = "X") -> Float:
        self._check_fitted()
        return check_array(X, name, shape=(None, self.n_dims_))

    def _densities(self, X: npt.ArrayLike) -> tuple[Float, Float]:
        """p(k | x) (N, K) and log p(x) (N,): the density EM maximizes (_weighted_log_prob)."""
        x = self._check_X(X) - self._center
        lp = _weighted_log_prob(
            x, _outer_rows(x), self.weights_, self.means_ - self._center, self._prec_factors
        )
        return _log_resp(lp)

    def score_samples(self, X: npt.ArrayLike) -> Float:
        """Log-density of the mixture at each sample.

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        log_density : ndarray, shape (N,)
        """
        return self._densities(X)[1]

    def score(self, X: npt.ArrayLike, y: object = None) -> float:
        """Mean log-likelihood per sample of X (scikit-learn's ``score``; higher is better).

        Parameters
        ----------
        X : array-like, shape (N, D)
        y : ignored
            For scikit-learn's API (model selection tools pass it).

        Returns
        -------
        score : float
        """
        return float(np.mean(self.score_samples(X)))

    def _information_criterion(self, X: npt.ArrayLike, penalty: Callable[[int], float]) -> float:
        log_density = self.score_samples(X)
        p = n_parameters(self.n_components_, self.n_dims_)
        return float(-2.0 * log_density.sum() + p * penalty(log_density.shape[0]))

    def bic(self, X: npt.ArrayLike) -> float:
        """Standard Bayesian information criterion on X: -2 log L(X) + p log N (lower is better).

        p = (K - 1) + K D + K D (D + 1) / 2 free parameters (:func:`n_parameters`).

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        bic : float
        """
        return self._information_criterion(X, lambda n: float(np.log(n)))

    def aic(self, X: npt.ArrayLike) -> float:
        """Akaike information criterion on X: -2 log L(X) + 2 p (lower is better).

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        aic : float
        """
        return self._information_criterion(X, lambda n: 2.0)

    def predict_proba(self, X: npt.ArrayLike) -> Float:
        """Responsibilities p(k | x) of each component for each sample.

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        resp : ndarray, shape (N, K)
        """
        return self._densities(X)[0]

    def predict(self, X: npt.ArrayLike) -> NDArray[np.intp]:
        """The most probable component of each sample, argmax_k p(k | x).

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        labels : ndarray of int, shape (N,)
        """
        return np.asarray(np.argmax(self.predict_proba(X), axis=1), dtype=np.intp)

    def sample(
        self,
        n_samples: int = 1,
        random_state: int | np.random.Generator | np.random.RandomState | None = None,
    ) -> tuple[Float, NDArray[np.intp]]:
        """Draw samples from the mixture (as scikit-learn's ``GaussianMixture.sample``).

        The number of samples of each component is multinomial with the weights; each sample is
        mu_k + L_k z with Sigma_k = L_k L_k^T (Cholesky) and z standard normal. As in
        scikit-learn, the rows are grouped by component (all of component 0 first).

        Parameters
        ----------
        n_samples : int
            Number of samples, >= 1.
        random_state : int, numpy Generator, numpy RandomState or None
            Source of randomness: an integer seeds ``numpy.random.default_rng``; ``None``
            uses the estimator's ``random_state`` (as scikit-learn does), and without one,
            fresh entropy.

        Returns
        -------
        X : ndarray, shape (n_samples, D)
        labels : ndarray of int, shape (n_samples,)
            Component of each sample.
        """
        self._check_fitted()
        n = check_int(n_samples, "n_samples", minimum=1)
        rng = _check_rng(self.random_state if random_state is None else random_state)
        w = self.weights_ / self.weights_.sum()  # from_params allows a sum 1e-8 off 1
        counts = rng.multinomial(n, w)
        chol = np.linalg.cholesky(self.covariances_)
        z = rng.standard_normal((n, self.n_dims_))
        labels = np.repeat(np.arange(self.n_components_, dtype=np.intp), counts)
        x = np.empty_like(z)
        stop = np.cumsum(counts)
        for k, (a, b) in enumerate(zip(stop - counts, stop, strict=True)):
            x[a:b] = self.means_[k] + z[a:b] @ chol[k].T
        return x, labels

    # --------------------------------------------------------------- regression
    def _gmr_model(self, in_dims: Sequence[int] | int) -> GMRModel:
        self._check_fitted()
        d = self.n_dims_
        dims_seq = [in_dims] if isinstance(in_dims, (int, np.integer)) else list(in_dims)
        dims: list[int] = []
        for i in dims_seq:
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
                raise ValueError(f"in_dims must hold integers, got {i!r}")
            dims.append(int(i))
        if not dims:
            raise ValueError("in_dims must hold at least one dimension, got []")
        if any(i < 0 or i >= d for i in dims):
            raise ValueError(f"in_dims must be in [0, {d}) for a GMM of {d} dimensions, got {dims}")
        if len(set(dims)) != len(dims):
            raise ValueError(f"in_dims must be distinct, got {dims}")
        if len(dims) == d:
            raise ValueError(
                f"in_dims must leave at least one output dimension, got all {d} dimensions"
            )
        key = tuple(dims)
        model = self._gmr_cache.get(key)
        if model is None:
            model = gmr_precompute(self.weights_, self.means_, self.covariances_, key)
            self._gmr_cache[key] = model
        return model

    @staticmethod
    def _check_covariance_mode(covariance: str) -> CovarianceMode:
        if covariance not in ("exact", "paper"):
            raise ValueError(f"covariance must be 'exact' or 'paper', got {covariance!r}")
        return covariance  # type: ignore[return-value]

    def regress(
        self,
        X_in: npt.ArrayLike,
        in_dims: Sequence[int] | int = (0,),
        covariance: CovarianceMode = "exact",
    ) -> tuple[Float, Float]:
        """Gaussian mixture regression: p(xi^O | xi^I = x) for every row of X_in (paper Table I).

        Parameters
        ----------
        X_in : array-like, shape (T, len(in_dims))
            Query values of the input dimensions (shape (T,) is accepted for one input).
        in_dims : sequence of int
            Input dimensions; the outputs are all the other dimensions, in order.
        covariance : {"exact", "paper"}
            ``"exact"``: the covariance of the conditional mixture,
            sum_k beta_k (C_k + m_k m_k^T) - m m^T. ``"paper"``: sum_k beta_k^2 C_k.

        Returns
        -------
        mean : ndarray, shape (T, D_out)
        cov : ndarray, shape (T, D_out, D_out)
        """
        model = self._gmr_model(in_dims)
        mode = self._check_covariance_mode(covariance)
        d_in = len(model.in_dims)
        x = check_array(X_in, "X_in", ndim=(1, 2))
        if x.ndim == 1 and d_in == 1:
            x = x[:, None]
        if x.ndim != 2 or x.shape[1] != d_in:
            raise ValueError(
                f"X_in must have shape (T, {d_in}) for in_dims={list(model.in_dims)}, got {x.shape}"
            )
        mean, cov = gmr_batch(model, x, mode)
        assert cov is not None
        return mean, cov

    def regress_one(
        self,
        x_in: npt.ArrayLike,
        in_dims: Sequence[int] | int = (0,),
        covariance: CovarianceMode = "exact",
    ) -> tuple[Float, Float]:
        """GMR at a single query, with minimal overhead (for a control loop).

        Parameters
        ----------
        x_in : array-like, shape (len(in_dims),) or scalar for one input
        in_dims : sequence of int
        covariance : {"exact", "paper"}

        Returns
        -------
        mean : ndarray, shape (D_out,)
        cov : ndarray, shape (D_out, D_out)
        """
        try:
            model = self._gmr_cache[in_dims]  # type: ignore[index]
        except (KeyError, TypeError, AttributeError):
            model = self._gmr_model(in_dims)
        mode: str = covariance
        if mode != "exact" and mode != "paper":
            self._check_covariance_mode(mode)
        d_in = len(model.in_dims)
        query: object = x_in
        if d_in == 1 and mode == "exact" and isinstance(query, float) and math.isfinite(query):
            mean, cov = gmr_step_1d(model, query)  # the control-loop fast path
        else:
            x = np.asarray(x_in, dtype=np.float64).reshape(-1)
            if x.shape[0] != d_in or not np.isfinite(x).all():
                raise ValueError(
                    f"x_in must be {d_in} finite value(s) for in_dims={list(model.in_dims)}, "
                    f"got {np.asarray(x_in)!r}"
                )
            mean, cov = gmr_step(model, x, covariance)
        assert cov is not None
        return mean, cov
