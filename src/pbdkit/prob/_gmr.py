"""Gaussian mixture regression (GMR, paper Table I), batched and single-step.

Given a GMM over xi = {xi^I, xi^O} (input dims I, output dims O), GMR returns the conditional
distribution p(xi^O | xi^I) = sum_k beta_k N(xi^O; m_k, C_k), summarized by one Gaussian:

    beta_k = pi_k N(x; mu_k^I, Sigma_k^II) / sum_i pi_i N(x; mu_i^I, Sigma_i^II)    (Table I)
    m_k    = mu_k^O + Sigma_k^OI (Sigma_k^II)^-1 (x - mu_k^I)                         (Table I)
    C_k    = Sigma_k^OO - Sigma_k^OI (Sigma_k^II)^-1 Sigma_k^IO                         (Table I)
    m      = sum_k beta_k m_k
    Sigma  = sum_k beta_k (C_k + m_k m_k^T) - m m^T      ("exact": law of total covariance)
    Sigma  = sum_k beta_k^2 C_k                          ("paper": the paper's approximation)

(Calinon & Billard, IROS 2008, Table I.) The query-independent terms are computed once
(:func:`gmr_precompute`); :func:`gmr_batch` evaluates T queries, :func:`gmr_step` one (a
control loop); responsibilities in the log domain. Exact against paper covariance, and the
centred formulation far from the data: ``docs/math.md``, "Gaussian mixture regression".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .gaussian import _cholesky_with_inverse

__all__ = [
    "FAR_SIGMAS",
    "CovarianceMode",
    "GMRModel",
    "gmr_batch",
    "gmr_precompute",
    "gmr_step",
    "gmr_step_1d",
]

Float = NDArray[np.float64]
CovarianceMode = Literal["exact", "paper"]
#: One input: a query more than this many standard deviations beyond every component is "far"
#: and takes the centred formulation (``docs/math.md``, "Far queries"). At the switch the fast
#: path's cancellation error is about eps * FAR_SIGMAS^2 ~ 2e-13 of the output variances.
FAR_SIGMAS = 30.0


@dataclass(frozen=True)
class GMRModel:
    """Query-independent quantities for conditioning a GMM on fixed input dimensions.

    Attributes
    ----------
    in_dims : tuple of int
        Input dimensions I.
    out_dims : tuple of int
        Output dimensions O (every other dimension, in order).
    log_weights : ndarray, shape (K,)
        log pi_k.
    mu_in : ndarray, shape (K, D_in)
    mu_out : ndarray, shape (K, D_out)
    prec_chol_in : ndarray, shape (K, D_in, D_in)
        Upper factor U_k with (Sigma_k^II)^-1 = U_k U_k^T, so the Mahalanobis distance is
        ||(x - mu_k^I) U_k||^2.
    log_norm : ndarray, shape (K,)
        log pi_k - 0.5 (D_in log 2 pi + log|Sigma_k^II|).
    gain : ndarray, shape (K, D_out, D_in)
        A_k = Sigma_k^OI (Sigma_k^II)^-1.
    cond_cov : ndarray, shape (K, D_out, D_out)
        C_k, the conditional covariance of each component.
    center : ndarray, shape (D_out,)
        A constant subtracted from the outputs before forming second moments (covariances are
        shift-invariant; centring keeps the moment formula free of cancellation).
    half_prec : ndarray, shape (K,)
        For one input dimension: 0.5 / Sigma_k^II.
    table : ndarray, shape (3 K, D_out + D_out^2 + 1)
        For one input dimension, with s_k = x - mu_k^I and c_k = mu_k^O - center:
        [w | w s | w s^2] @ table = [sum w m_k, sum w (C_k + m_k m_k^T), sum w] (centred),
        i.e. rows [c_k, C_k + c_k c_k^T, 1], [A_k, c_k A_k^T + A_k c_k^T, 0], [0, A_k A_k^T, 0],
        so that unnormalized weights w give every moment and their normalizer in one product.
    log_norm_shifted : ndarray, shape (K,)
        log_norm - max(log_norm): exp(log_norm_shifted - s^2 / (2 var)) <= 1 never overflows.
    near_lo, near_hi : float
        For one input dimension: queries in [near_lo, near_hi] (within :data:`FAR_SIGMAS`
        standard deviations of some component's reach) take the fast path, the others the
        centred formulation. -inf and inf for several inputs.
    """

    in_dims: tuple[int, ...]
    out_dims: tuple[int, ...]
    log_weights: Float
    mu_in: Float
    mu_out: Float
    prec_chol_in: Float
    log_norm: Float
    gain: Float
    cond_cov: Float
    center: Float
    half_prec: Float
    table: Float
    log_norm_shifted: Float
    near_lo: float
    near_hi: float

    @property
    def n_components(self) -> int:
        return int(self.mu_in.shape[0])


def gmr_precompute(
    weights: Float, means: Float, covariances: Float, in_dims: tuple[int, ...]
) -> GMRModel:
    """Precompute the conditioning of a GMM on ``in_dims``.

    Parameters
    ----------
    weights : ndarray, shape (K,)
    means : ndarray, shape (K, D)
    covariances : ndarray, shape (K, D, D)
    in_dims : tuple of int
        Distinct input dimensions, each in [0, D); the others are outputs.

    Returns
    -------
    model : GMRModel
    """
    d = means.shape[1]
    i_idx = np.asarray(in_dims, dtype=np.intp)
    o_idx = np.asarray([j for j in range(d) if j not in set(in_dims)], dtype=np.intp)
    s_ii = covariances[:, i_idx[:, None], i_idx[None, :]]
    s_oi = covariances[:, o_idx[:, None], i_idx[None, :]]
    s_oo = covariances[:, o_idx[:, None], o_idx[None, :]]
    if len(in_dims) == 1 and np.all(s_ii > 0.0):  # Sigma^II = s: L = sqrt(s), no solve
        chol = np.sqrt(s_ii)
        prec_chol = 1.0 / chol
        gain = s_oi / s_ii
    else:
        chol, chol_inv = _cholesky_with_inverse(s_ii, "Sigma^II")  # Sigma^II = L L^T, and L^-1
        prec_chol = np.swapaxes(chol_inv, -1, -2)  # U = L^-T: (x-mu) U = (L^-1 (x-mu))^T
        # A_k = S_oi S_ii^-1 = S_oi L^-T L^-1
        gain = s_oi @ prec_chol @ chol_inv
    cond = s_oo - gain @ np.swapaxes(s_oi, -1, -2)
    cond = 0.5 * (cond + np.swapaxes(cond, -1, -2))
    log_det = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    with np.errstate(divide="ignore"):
        log_w = np.log(weights)
    log_norm = log_w - 0.5 * (len(in_dims) * np.log(2.0 * np.pi) + log_det)
    mu_out = means[:, o_idx]
    center = mu_out.mean(axis=0)
    k, d_out = mu_out.shape
    half_prec = np.zeros(k)
    table = np.zeros((3 * k, d_out + d_out * d_out + 1))
    near_lo, near_hi = -np.inf, np.inf
    if len(in_dims) == 1:
        half_prec = 0.5 / s_ii[:, 0, 0]
        used = np.isfinite(log_norm)  # components of weight 0 never take a query
        reach = FAR_SIGMAS * np.sqrt(s_ii[used, 0, 0])
        near_lo = float(np.min(means[used, i_idx[0]] - reach))
        near_hi = float(np.max(means[used, i_idx[0]] + reach))
        c = mu_out - center
        a = gain[:, :, 0]
        table[:k, :d_out] = c
        table[:k, d_out:-1] = (cond + c[:, :, None] * c[:, None, :]).reshape(k, -1)
        table[:k, -1] = 1.0
        table[k : 2 * k, :d_out] = a
        table[k : 2 * k, d_out:-1] = (
            c[:, :, None] * a[:, None, :] + a[:, :, None] * c[:, None, :]
        ).reshape(k, -1)
        table[2 * k :, d_out:-1] = (a[:, :, None] * a[:, None, :]).reshape(k, -1)
    return GMRModel(
        in_dims=tuple(int(i) for i in i_idx),
        out_dims=tuple(int(o) for o in o_idx),
        log_weights=log_w,
        mu_in=np.ascontiguousarray(means[:, i_idx]),
        mu_out=np.ascontiguousarray(means[:, o_idx]),
        prec_chol_in=np.ascontiguousarray(prec_chol),
        log_norm=log_norm,
        gain=np.ascontiguousarray(gain),
        cond_cov=np.ascontiguousarray(cond),
        center=center,
        half_prec=half_prec,
        table=table,
        log_norm_shifted=log_norm - np.max(log_norm[np.isfinite(log_norm)], initial=0.0),
        near_lo=near_lo,
        near_hi=near_hi,
    )


def _log_p_scaled(model: GMRModel, diff: Float) -> Float:
    """log p_k - max_i log p_i for queries where (x - mu)^T Sigma^-1 (x - mu) overflows.

    diff = x - mu^I of shape (..., K, D_in). With r = max |x - mu| and u_k = (x - mu_k) / r:
    log p_k = r^2 (log_norm_k / r^2 - 0.5 |u_k U_k|^2); the difference to the largest is formed
    before multiplying by r, twice (r^2 may overflow), so no inf - inf arises.
    """
    r = np.abs(diff).max(axis=(-2, -1), keepdims=True)  # (..., 1, 1), > 0 here
    z = np.einsum("...ki,kij->...kj", diff / r, model.prec_chol_in)
    r1 = r[..., 0]
    q = model.log_norm / r1 / r1 - 0.5 * np.einsum("...kj,...kj->...k", z, z)
    q -= q.max(axis=-1, keepdims=True)
    with np.errstate(over="ignore"):  # -inf: a component infinitely less likely than the best
        out: Float = r1 * (r1 * q)
    return out


def _responsibilities(model: GMRModel, diff: Float) -> Float:
    """beta (T, K) from diff = x - mu^I of shape (T, K, D_in), by log-sum-exp."""
    with np.errstate(over="ignore", invalid="ignore"):  # a far query: handled below
        if diff.shape[-1] == 1:
            z = diff[..., 0] * model.prec_chol_in[:, 0, 0]
            log_p = model.log_norm - 0.5 * z * z
        else:
            z = np.einsum("tki,kij->tkj", diff, model.prec_chol_in)
            log_p = model.log_norm - 0.5 * np.einsum("tkj,tkj->tk", z, z)
    top = log_p.max(axis=1, keepdims=True)
    if not np.isfinite(top).all():  # every Mahalanobis distance of a query overflowed
        bad = ~np.isfinite(top[:, 0])
        log_p[bad] = _log_p_scaled(model, diff[bad])
        top[bad] = 0.0
    log_p -= top
    beta = np.exp(log_p)
    beta /= beta.sum(axis=1, keepdims=True)
    return beta


def gmr_batch(
    model: GMRModel, X_in: Float, covariance: CovarianceMode | None = "exact"
) -> tuple[Float, Float | None]:
    """Conditional mean and covariance at T queries.

    Parameters
    ----------
    model : GMRModel
    X_in : ndarray, shape (T, D_in)
        Queries (already validated, float64).
    covariance : {"exact", "paper", None}
        Which covariance to return; ``None`` skips it.

    Returns
    -------
    mean : ndarray, shape (T, D_out)
    cov : ndarray, shape (T, D_out, D_out), or None
    """
    if X_in.shape[1] == 1:
        return _gmr_batch_1d(model, X_in[:, 0], covariance)
    return _gmr_batch_centred(model, X_in, covariance)


def _gmr_batch_centred(
    model: GMRModel, X_in: Float, covariance: CovarianceMode | None
) -> tuple[Float, Float | None]:
    """The reference formulation: any number of inputs, covariance about the mean."""
    diff = X_in[:, None, :] - model.mu_in[None, :, :]  # (T, K, D_in)
    beta = _responsibilities(model, diff)
    with np.errstate(over="ignore", invalid="ignore"):
        if diff.shape[-1] == 1:
            means_k = model.mu_out[None] + diff * model.gain[None, :, :, 0]  # (T, K, D_out)
        else:
            means_k = model.mu_out[None] + np.einsum("koi,tki->tko", model.gain, diff)
    if not np.isfinite(means_k).all():  # far away: only components with beta > 0 count
        means_k = np.where(beta[:, :, None] > 0.0, means_k, 0.0)
    mean = np.einsum("tk,tko->to", beta, means_k)
    if covariance is None:
        return mean, None
    t, k = beta.shape
    d_out = mean.shape[1]
    c_flat = model.cond_cov.reshape(k, d_out * d_out)
    if covariance == "paper":
        cov = ((beta * beta) @ c_flat).reshape(t, d_out, d_out)
        return mean, cov
    # sum_k beta_k (C_k + m_k m_k^T) - m m^T = sum_k beta_k C_k + sum_k beta_k d_k d_k^T,
    # with d_k = m_k - m (centred form: no cancellation between two large terms).
    dev = means_k - mean[:, None, :]
    cov = (beta @ c_flat).reshape(t, d_out, d_out)
    cov += np.matmul(np.swapaxes(dev * beta[:, :, None], 1, 2), dev)
    return mean, cov


def _gmr_batch_1d(
    model: GMRModel, x: Float, covariance: CovarianceMode | None
) -> tuple[Float, Float | None]:
    """One input dimension: the fast path, and the centred one for far queries."""
    lo, hi = model.near_lo, model.near_hi
    if x.shape[0] == 0 or (lo <= x.min() and x.max() <= hi):
        return _gmr_batch_1d_near(model, x, covariance)
    far = (x < lo) | (x > hi)
    mean_far, cov_far = _gmr_batch_centred(model, x[far, None], covariance)
    if far.all():
        return mean_far, cov_far
    mean_near, cov_near = _gmr_batch_1d_near(model, x[~far], covariance)
    mean = np.empty((x.shape[0], mean_near.shape[1]))
    mean[far], mean[~far] = mean_far, mean_near
    if cov_near is None or cov_far is None:
        return mean, None
    cov = np.empty((x.shape[0], *cov_near.shape[1:]))
    cov[far], cov[~far] = cov_far, cov_near
    return mean, cov


def _gmr_batch_1d_near(
    model: GMRModel, x: Float, covariance: CovarianceMode | None
) -> tuple[Float, Float | None]:
    """One input dimension near the data: every moment from one GEMM with the precomputed table.

    Works in (K, T) layout: reductions over the K components then run across contiguous rows of
    length T, which numpy vectorizes (a (T, K) reduction over short rows is several times slower).
    """
    k = model.half_prec.shape[0]
    d_out = model.center.shape[0]
    s = x[None, :] - model.mu_in[:, :1]  # s_k = x - mu_k^I, (K, T)
    w = np.empty((3 * k, x.shape[0]))
    log_p = w[2 * k :]
    np.multiply(s, s, out=log_p)
    log_p *= -model.half_prec[:, None]
    log_p += model.log_norm[:, None]
    log_p -= log_p.max(axis=0)
    beta = np.exp(log_p, out=w[:k])
    beta /= beta.sum(axis=0)
    np.multiply(beta, s, out=w[k : 2 * k])  # beta s
    if covariance != "exact":
        mean = w[: 2 * k].T @ model.table[: 2 * k, :d_out] + model.center
        if covariance is None:
            return mean, None
        c_flat = model.cond_cov.reshape(k, d_out * d_out)
        return mean, ((beta * beta).T @ c_flat).reshape(-1, d_out, d_out)
    np.multiply(w[k : 2 * k], s, out=w[2 * k :])  # beta s^2
    out = w.T @ model.table[:, :-1]  # (T, D_out + D_out^2)
    mean_c = out[:, :d_out]
    cov = out[:, d_out:].reshape(-1, d_out, d_out)
    cov -= np.einsum("ti,tj->tij", mean_c, mean_c)
    return mean_c + model.center, cov


def gmr_step_1d(model: GMRModel, x: float, with_cov: bool = True) -> tuple[Float, Float | None]:
    """Exact GMR at one scalar query (one input dimension), in about a dozen numpy calls.

    Unnormalized weights w_k = exp(log_norm_k - max_i log_norm_i - s_k^2 / (2 var_k)) cannot
    overflow; if they all underflow the weights are recomputed relative to their maximum in the
    log domain, so the result is never NaN. A query beyond ``[near_lo, near_hi]`` takes the
    centred formulation (``docs/math.md``, "Far queries").

    Parameters
    ----------
    model : GMRModel
        Conditioned on one input dimension.
    x : float
    with_cov : bool

    Returns
    -------
    mean : ndarray, shape (D_out,)
    cov : ndarray, shape (D_out, D_out), or None
    """
    if not model.near_lo <= x <= model.near_hi:
        return _gmr_step_centred(model, np.array([x]), "exact" if with_cov else None)
    s = x - model.mu_in[:, 0]
    log_w = model.log_norm_shifted - model.half_prec * s * s
    w = np.exp(log_w)
    ws = w * s
    out = np.concatenate((w, ws, ws * s)) @ model.table
    total = out[-1]
    if not total > 1e-250:  # every weight underflowed: renormalize in the log domain
        w = np.exp(log_w - log_w.max())
        ws = w * s
        out = np.concatenate((w, ws, ws * s)) @ model.table
        total = out[-1]
    d_out = model.center.shape[0]
    mean_c = out[:d_out] / total
    if not with_cov:
        return mean_c + model.center, None
    cov = out[d_out:-1].reshape(d_out, d_out) / total
    cov -= mean_c[:, None] * mean_c
    return mean_c + model.center, cov


def gmr_step(
    model: GMRModel, x_in: Float, covariance: CovarianceMode | None = "exact"
) -> tuple[Float, Float | None]:
    """Conditional mean and covariance at one query (the control-loop path).

    Parameters
    ----------
    model : GMRModel
    x_in : ndarray, shape (D_in,)
    covariance : {"exact", "paper", None}

    Returns
    -------
    mean : ndarray, shape (D_out,)
    cov : ndarray, shape (D_out, D_out), or None
    """
    if x_in.shape[0] == 1 and covariance != "paper":
        return gmr_step_1d(model, float(x_in[0]), covariance is not None)
    return _gmr_step_centred(model, x_in, covariance)


def _gmr_step_centred(
    model: GMRModel, x_in: Float, covariance: CovarianceMode | None
) -> tuple[Float, Float | None]:
    """:func:`gmr_step` in the reference formulation (any number of inputs)."""
    diff = x_in - model.mu_in  # (K, D_in)
    with np.errstate(over="ignore", invalid="ignore"):  # a far query: handled below
        if diff.shape[1] == 1:
            z = diff[:, 0] * model.prec_chol_in[:, 0, 0]
            log_p = model.log_norm - 0.5 * z * z
            means_k = model.mu_out + diff * model.gain[:, :, 0]
        else:
            z = np.einsum("ki,kij->kj", diff, model.prec_chol_in)
            log_p = model.log_norm - 0.5 * np.einsum("kj,kj->k", z, z)
            means_k = model.mu_out + np.einsum("koi,ki->ko", model.gain, diff)
    top = log_p.max()
    if not np.isfinite(top):  # every Mahalanobis distance overflowed
        log_p, top = _log_p_scaled(model, diff), 0.0
    beta = np.exp(log_p - top)
    beta /= beta.sum()
    if not np.isfinite(means_k).all():  # far away: only components with beta > 0 count
        means_k = np.where(beta[:, None] > 0.0, means_k, 0.0)
    mean = beta @ means_k
    if covariance is None:
        return mean, None
    k, d_out = means_k.shape
    if covariance == "paper":
        cov = ((beta * beta) @ model.cond_cov.reshape(k, -1)).reshape(d_out, d_out)
        return mean, cov
    dev = means_k - mean
    cov = (beta @ model.cond_cov.reshape(k, -1)).reshape(d_out, d_out)
    cov += (dev.T * beta) @ dev
    return mean, cov
