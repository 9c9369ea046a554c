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

import functools
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


class _Upper(NamedTuple):
    """The upper triangle (with the diagonal) of a D x D matrix."""

    rows: NDArray[np.intp]
    cols: NDArray[np.intp]
    flat: NDArray[np.intp]  # rows * D + cols: into the flattened matrix
    quad: Float  # -1/2 on the diagonal, -1 off it: the coefficients of x^T P x / -2


@functools.cache
def _upper(d: int) -> _Upper:
    iu, ju = np.triu_indices(d)
    return _Upper(iu, ju, iu * d + ju, np.where(iu == ju, -0.5, -1.0))


def _features(x: Float) -> Float:
    """Every row's features, (N, D(D+1)/2 + D + 1): x_i x_j (i <= j), x, 1.

    One product of responsibilities with them gives all sufficient statistics
    (:func:`_sufficient_stats`), and one product of them with a row of coefficients per component
    gives the log-densities (:func:`_weighted_log_prob`). Precomputed once per fit.
    """
    upper = _upper(x.shape[1])
    return np.hstack([x[:, upper.rows] * x[:, upper.cols], x, np.ones((x.shape[0], 1))])


def _sufficient_stats(feats: Float, resp: Float) -> tuple[Float, Float, Float]:
    """sum_j r_jk, sum_j r_jk x_j and sum_j r_jk x_j x_j^T: (K,), (K, D), (K, D, D).

    ``feats`` are the rows' :func:`_features`: (D + 1)(D + 2) / 2 columns.
    """
    d = round((np.sqrt(8 * feats.shape[1] + 1) - 3) / 2)
    upper = _upper(d)
    m = upper.flat.size
    s = resp.T @ feats
    s2 = np.empty((s.shape[0], d, d))
    s2[:, upper.rows, upper.cols] = s[:, :m]
    s2[:, upper.cols, upper.rows] = s[:, :m]
    return s[:, -1], s[:, m : m + d], s2


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
    # Symmetric as computed: s2 is (both triangles from one value) and so is mu mu^T.
    cov = s2 / nk[:, None, None] - means[:, :, None] * means[:, None, :]
    d = cov.shape[-1]
    cov.reshape(-1, d * d)[:, :: d + 1] += floor.diag  # the diagonals
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


def _weighted_log_prob(feats: Float, weights: Float, means: Float, factors: Float) -> Float:
    """log pi_k + log N(x_j; mu_k, Sigma_k) for every component and row: (K, N).

    The one log-density of the mixture: EM and the estimator's ``score_samples``,
    ``predict_proba``, ``bic``, ... all call it, on the rows' :func:`_features`. One product::

        log pi_k N(x; mu_k, Sigma_k) = c_k - 1/2 vec(x x^T) . vec(P_k) + x . P_k mu_k,
        c_k = log pi_k + sum log diag(U_k) - D/2 log(2 pi) - 1/2 mu_k^T P_k mu_k,  P_k = U_k U_k^T

    (the upper triangle of x x^T, its off-diagonal coefficients doubled). Callers centre x (a
    shift of every mean leaves the mixture unchanged), which keeps the expansion free of
    cancellation; the Mahalanobis term is kept >= 0 (the density at most c_k + its quadratic
    term at the mean). Components first: the reductions over them in :func:`_log_resp` then run
    along contiguous rows.
    """
    k, d = means.shape
    upper = _upper(d)
    m = upper.flat.size
    prec = factors @ np.swapaxes(factors, -1, -2)  # (K, D, D)
    coef = np.empty((k, m + d + 1))  # [quadratic | linear | constant] per component
    np.multiply(prec.reshape(k, d * d)[:, upper.flat], upper.quad, out=coef[:, :m])
    p_mu = coef[:, m : m + d]
    np.matmul(prec, means[:, :, None], out=p_mu[:, :, None])
    # log|Sigma|^(-1/2) = sum log diag(U)
    half_log_det = np.log(np.diagonal(factors, axis1=1, axis2=2)).sum(axis=1)
    with np.errstate(divide="ignore"):  # a component of weight 0 has log pi = -inf
        top = np.log(weights) + half_log_det - 0.5 * d * np.log(2.0 * np.pi)
    coef[:, -1] = top - 0.5 * (means * p_mu).sum(axis=1)
    lp: Float = coef @ feats.T
    np.minimum(lp, top[:, None], out=lp)
    return lp


#: EM's E-step: a component more than this far below the most likely one at a row (in log
#: density) is given exp(-EM_LOG_FLOOR) ~ 4e-44 of that row, not less. Nothing visible changes
#: (the sum over the components is the largest term plus at most 30 such: it does not move in
#: float64), and exp stays on its fast path: 80 % of the entries of a 30-component fit lie
#: below -700, and exp of a number whose result is subnormal, 0 or of -inf costs 4-45 times
#: one whose result is normal (Skill.learn on the coaster workload: 0.31 -> 0.29 s).
EM_LOG_FLOOR = 100.0


def _log_resp(lp: Float, floor: float | None = None) -> tuple[Float, Float]:
    """p(k | x_j) (N, K) and log p(x_j) (N,) from the weighted log-probabilities (K, N).

    log p(x) = m + log sum_k exp(lp_k - m), m = max_k lp_k (log-sum-exp, no overflow).
    ``lp`` is overwritten; the responsibilities are its transposed view. With ``floor``,
    lp_k - m is taken as at least -floor (:data:`EM_LOG_FLOOR`; EM only: a component of weight
    0 then gets a responsibility of exp(-floor)).
    """
    top = lp.max(axis=0)
    lp -= top
    if floor is not None:
        np.maximum(lp, -floor, out=lp)
    np.exp(lp, out=lp)
    total = lp.sum(axis=0)
    lp /= total
    return lp.T, top + np.log(total)


def _e_step(feats: Float, params: Params) -> tuple[Float, float]:
    """Responsibilities (N, K) in the log domain, and the mean log-likelihood per sample, from
    the rows' :func:`_features`."""
    weights, means, cov = params
    lp = _weighted_log_prob(feats, weights, means, _precision_factors(cov))
    resp, log_density = _log_resp(lp, EM_LOG_FLOOR)
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
    feats = _features(x)
    params = _params_from_stats(*_sufficient_stats(feats, resp), floor)
    prev = -np.inf
    converged = False
    n_iter = 0
    for n_iter in range(1, max_iter + 1):  # noqa: B007 (n_iter is reported)
        resp, ll = _e_step(feats, params)
        params = _params_from_stats(*_sufficient_stats(feats, resp), floor)
        if abs(ll - prev) < tol:
            converged = True
            break
        prev = ll
    resp, ll = _e_step(feats, params)
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
    w, m, cov = _params_from_stats(*_sufficient_stats(_features(x), resp), floor)
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
