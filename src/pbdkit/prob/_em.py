"""EM for full-covariance Gaussian mixtures: sufficient statistics, floors, bounds, E- and M-steps.

Pure functions on float64 arrays; :class:`pbdkit.GMM` is a thin shell over them. Parameters
travel as (weights (K,), means (K, D), covariances (K, D, D)); precisions as upper factors U_k
with Sigma_k^-1 = U_k U_k^T (scikit-learn's ``precisions_cholesky_`` convention).

    E-step:  r_jk = pi_k N(x_j; mu_k, Sigma_k) / sum_i pi_i N(x_j; mu_i, Sigma_i)  (log domain)
    M-step:  N_k = sum_j r_jk,  pi_k = N_k / N,  mu_k = sum_j r_jk x_j / N_k,
             Sigma_k = sum_j r_jk x_j x_j^T / N_k - mu_k mu_k^T + diag(reg_covar)
    time bounds: (min_time_spread * span / K)^2 <= Sigma_k,tt <= (max_time_spread * span / K)^2,
                 with p(x | t) kept

(Bishop, *Pattern Recognition and Machine Learning*, 2006, sec. 9.2.2; the floor on the
diagonal is scikit-learn's ``reg_covar``.) EM starts from K consecutive bins along time
(:func:`time_based_init`). Why these floors, their scale and the time floor's derivation:
``docs/math.md``, "Gaussian mixtures and EM".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array
from .gaussian import inverse_cholesky_factor

__all__ = [
    "MAX_TIME_FLOOR_FRACTION",
    "MAX_TIME_SPREAD",
    "MIN_TIME_SPREAD",
    "REG_COVAR",
    "scale_aware_floor",
    "time_based_init",
]

Float = NDArray[np.float64]
# (weights (K,), means (K, D), covariances (K, D, D))
Params = tuple[Float, Float, Float]


#: Default ``min_time_spread``: every component's time standard deviation is at least this
#: fraction of the components' spacing (the time span over K); ``docs/math.md``, "Time floor".
MIN_TIME_SPREAD = 0.2
#: Default ``max_time_spread``: every component's time standard deviation is at most this
#: fraction of the components' spacing; ``docs/math.md``, "Time ceiling". A component wider in
#: time lends its regression to its neighbours' phases: on an SO-100 teacher, the one that held
#: the hand 10 cm above the box (time SD 1.7 spacings) put the grasp 2.5 mm above it.
MAX_TIME_SPREAD = 1.0
#: ``reg_covar=None``: the floor of a column is this fraction of its variance, and at most this
#: value in the data's units (scikit-learn's default ``reg_covar``).
REG_COVAR = 1e-6
#: A time floor (``reg_covar`` of the time column) above this fraction of the time column's
#: variance is refused: every component would be at least a third of the time's standard
#: deviation (9 % of the span) wide, too wide for more than about five components to be told
#: apart along time (LASA's G drawn in 2 ms under a floor of 1e-6 s^2, 3 times the time's
#: variance: one component, a GMR mean 0.95 of the shape's spread off the demonstrations' mean).
MAX_TIME_FLOOR_FRACTION = 0.1


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
    time_ceiling : and at most ``time_ceiling / K`` (``max_time_spread`` times the span); inf
        for none.
    """

    diag: Float
    time_dim: int | None = None
    time_spread: float = 0.0
    time_ceiling: float = float("inf")


def _bound_time_variance(cov: Float, time_dim: int, var_min: float, var_max: float) -> None:
    """Bring every component's time variance s into [v_min, v_max], keeping p(x | t).

    ``cov`` (K, D, D) is changed in place.

    With Sigma = [[s, b^T], [b, S]] (time first), p(x | t) has the gain A = b / s and the
    covariance C = S - b b^T / s; s' = v, b' = A v and S' = C + A A^T v keep both. A Gaussian's
    log-likelihood is log p(t) + log p(x | t) with separate parameters, and the maximum of
    log p(t) under v_min <= s <= v_max is s clipped to the interval, so this is the exact
    maximum of the M-step under the bounds, and EM stays monotone.
    """
    s = cov[:, time_dim, time_dim]
    out = np.flatnonzero((s < var_min) | (s > var_max))
    if out.size == 0:
        return
    c = cov[out]
    s_k = s[out]
    v = np.clip(s_k, var_min, var_max)
    b = c[:, :, time_dim].copy()
    b[:, time_dim] = 0.0
    # A = b / s; s = 0 (no reg_covar on time, one time value) has b = 0 and no gain.
    gain = np.divide(b, s_k[:, None], out=np.zeros_like(b), where=s_k[:, None] > 0.0)
    c += (v - s_k)[:, None, None] * (gain[:, :, None] * gain[:, None, :])
    c[:, :, time_dim] = v[:, None] * gain
    c[:, time_dim, :] = v[:, None] * gain
    c[:, time_dim, time_dim] = v
    cov[out] = c


def _params_from_stats(
    s0: Float, s1: Float, s2: Float, floor: _Floor, n_components: int | None = None
) -> Params:
    """M-step: weights, means and covariances (+ the floors: on the diagonal; the bounds on time).

    ``n_components`` is the K of the time bounds (default: the number of components given); a
    cross-validation fold that drops components keeps the floor of the model it comes from.
    """
    nk = s0 + 10.0 * np.finfo(np.float64).eps  # scikit-learn's guard against empty components
    means = s1 / nk[:, None]
    cov = s2 / nk[:, None, None] - means[:, :, None] * means[:, None, :]
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    idx = np.arange(cov.shape[-1])
    cov[:, idx, idx] += floor.diag
    if floor.time_dim is not None and (floor.time_spread > 0.0 or floor.time_ceiling < np.inf):
        k = cov.shape[0] if n_components is None else n_components
        _bound_time_variance(
            cov, floor.time_dim, (floor.time_spread / k) ** 2, (floor.time_ceiling / k) ** 2
        )
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


class _Fit(NamedTuple):
    """One EM run (:func:`_em`)."""

    params: Params
    #: Responsibilities of the last E-step, (N, K).
    resp: Float
    n_iter: int
    converged: bool
    #: Log-likelihood summed over the rows.
    log_likelihood: float


def _em(x: Float, resp: Float, floor: _Floor, max_iter: int, tol: float) -> _Fit:
    """EM for a full-covariance GMM from initial responsibilities (N, K).

    Stops when the mean log-likelihood per sample gains less than ``tol`` (scikit-learn's rule).

    Returns
    -------
    fit : _Fit
        params, resp, n_iter, converged, log_likelihood (total over the rows).
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
    return _Fit(params, resp, n_iter, converged, ll * x.shape[0])


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
    """Refuse a time floor that would hide the motion (``docs/math.md``, "Floors and scale").

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
