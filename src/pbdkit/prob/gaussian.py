"""Pure functions on Gaussian distributions: products in information form, linear maps, densities.

A Gaussian N(mu, Sigma) is carried as its precision Lambda = Sigma^-1 and information vector
eta = Lambda mu; precisions add under a product (paper eq. (1) in information form)::

    prod_i N(mu_i, Lambda_i^-1)  ~  N(mu, Sigma),   Sigma = (sum_i Lambda_i)^-1,
                                                      mu = Sigma sum_i eta_i
    y = A x + b,  x ~ N(mu, Sigma)  =>  y ~ N(A mu + b, A Sigma A^T)

A factor may be rank-deficient as long as the sum of the precisions is positive definite. Every
function works on a single Gaussian or on a leading batch axis; shapes are stated per argument.
Nothing here calls ``inv`` on a covariance: Cholesky factors and solves only. The derivation, and
why a task-space constraint needs the information form: ``docs/math.md``, "Products of Gaussians
in information form".
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array

__all__ = [
    "gaussian_log_density",
    "gaussian_product",
    "information_from_gaussian",
    "inverse_cholesky_factor",
    "linear_transform",
    "precision_from_covariance",
    "product_information",
    "regularize_covariance",
]

Float = NDArray[np.float64]


def _cholesky(a: Float, name: str, message: Callable[[Float], str] | None = None) -> Float:
    """Lower Cholesky factor L of a = L L^T (batched), or a ValueError: ``message(a)`` if given."""
    try:
        return np.asarray(np.linalg.cholesky(a), dtype=np.float64)
    except np.linalg.LinAlgError as exc:
        if message is not None:
            raise ValueError(message(a)) from None
        raise ValueError(
            f"{name} is not positive definite; add regularization "
            "(regularize_covariance) or check that the constraints together cover every dimension"
        ) from exc


def inverse_cholesky_factor(
    covariance: Float, name: str = "covariance", *, message: Callable[[Float], str] | None = None
) -> Float:
    """L^-1 for covariance = L L^T (Cholesky), batched over the leading axes.

    The one route from a covariance to its precision in pbdkit: Sigma^-1 = L^-T L^-1, and the
    Mahalanobis distance of d is ||L^-1 d||^2 (scikit-learn's ``precisions_cholesky_`` is
    L^-T). A hot-path helper: the input is not validated (callers pass float64 arrays).

    Parameters
    ----------
    covariance : ndarray, shape (..., D, D)
        Symmetric positive-definite matrices, float64.
    name : str
        Names ``covariance`` in the default error message.
    message : callable, optional
        ``message(covariance)`` gives the error message instead (to name a step, a component).

    Returns
    -------
    inverse_factor : ndarray, shape (..., D, D)
        Lower triangular L^-1.

    Raises
    ------
    ValueError
        If a matrix is not positive definite.
    """
    return _cholesky_with_inverse(covariance, name, message)[1]


def _cholesky_with_inverse(
    covariance: Float, name: str = "covariance", message: Callable[[Float], str] | None = None
) -> tuple[Float, Float]:
    """L and L^-1 for covariance = L L^T: :func:`inverse_cholesky_factor` and the factor."""
    chol = _cholesky(covariance, name, message)
    eye = np.broadcast_to(np.eye(covariance.shape[-1]), covariance.shape)
    return chol, np.asarray(np.linalg.solve(chol, eye))


def _spd_solve(a: Float, b: Float, name: str) -> Float:
    """Solve a x = b for symmetric positive-definite a (batched over leading axes)."""
    chol = _cholesky(a, name)
    y = np.linalg.solve(chol, b)
    return np.asarray(np.linalg.solve(np.swapaxes(chol, -1, -2), y))


def precision_from_covariance(covariance: npt.ArrayLike) -> Float:
    """Inverse of a covariance through its Cholesky factor: L^-T L^-1.

    L^-1 comes from :func:`inverse_cholesky_factor`. (pbdkit 0.1.0 solved L^T P = L^-1 instead:
    the results differ in the last bits only.)

    Parameters
    ----------
    covariance : array-like, shape (..., D, D)
        Symmetric positive-definite matrices.

    Returns
    -------
    precision : ndarray, shape (..., D, D)
        Symmetric inverse.
    """
    cov = check_array(covariance, "covariance", ndim=(2, 3, 4))
    linv = inverse_cholesky_factor(cov, "covariance")
    prec = np.swapaxes(linv, -1, -2) @ linv  # Sigma^-1 = L^-T L^-1
    return 0.5 * (prec + np.swapaxes(prec, -1, -2))


def information_from_gaussian(
    mean: npt.ArrayLike, covariance: npt.ArrayLike
) -> tuple[Float, Float]:
    """Information form (eta, Lambda) = (Sigma^-1 mu, Sigma^-1) of N(mu, Sigma).

    Parameters
    ----------
    mean : array-like, shape (..., D)
    covariance : array-like, shape (..., D, D)

    Returns
    -------
    eta : ndarray, shape (..., D)
    precision : ndarray, shape (..., D, D)
    """
    mu = check_array(mean, "mean", ndim=(1, 2, 3))
    prec = precision_from_covariance(covariance)
    return np.einsum("...ij,...j->...i", prec, mu), prec


def product_information(
    means: npt.ArrayLike, precisions: npt.ArrayLike, *, check: bool = True
) -> tuple[Float, Float]:
    """Product of N Gaussians given by their means and (possibly singular) precisions.

    The normalised product of N(mu_i, Lambda_i^-1) is N(mu, Sigma) with
    Sigma = (sum_i Lambda_i)^-1 and mu = Sigma sum_i Lambda_i mu_i (paper eq. (1) in
    information form). Each Lambda_i may be rank-deficient; their sum must be positive definite.

    Parameters
    ----------
    means : array-like, shape (N, D) or (M, N, D)
        Means of the N factors (optionally for a batch of M products).
    precisions : array-like, shape (N, D, D) or (M, N, D, D)
        Symmetric positive semi-definite precision matrices of the factors.
    check : bool
        Validate the inputs (turn off in a hot loop whose inputs are known to be clean).

    Returns
    -------
    mean : ndarray, shape (D,) or (M, D)
    covariance : ndarray, shape (D, D) or (M, D, D)
    """
    if check:
        mu = check_array(means, "means", ndim=(2, 3))
        lam = check_array(precisions, "precisions", ndim=(3, 4))
        if lam.shape[:-1] != mu.shape or lam.shape[-1] != lam.shape[-2]:
            raise ValueError(
                f"precisions must have shape {(*mu.shape, mu.shape[-1])} to match means "
                f"of shape {mu.shape}, got {lam.shape}"
            )
    else:
        mu = np.asarray(means, dtype=np.float64)
        lam = np.asarray(precisions, dtype=np.float64)
    lam_sum = lam.sum(axis=-3)
    eta_sum = np.einsum("...nij,...nj->...i", lam, mu)
    d = lam_sum.shape[-1]
    eye = np.broadcast_to(np.eye(d), lam_sum.shape)
    rhs = np.concatenate([eta_sum[..., None], eye], axis=-1)
    sol = _spd_solve(lam_sum, rhs, "the sum of the precisions")
    cov = sol[..., 1:]
    return sol[..., 0], 0.5 * (cov + np.swapaxes(cov, -1, -2))


def gaussian_product(means: npt.ArrayLike, covariances: npt.ArrayLike) -> tuple[Float, Float]:
    """Product of N Gaussians given in covariance form (each covariance must be invertible).

    Parameters
    ----------
    means : array-like, shape (N, D)
    covariances : array-like, shape (N, D, D)

    Returns
    -------
    mean : ndarray, shape (D,)
    covariance : ndarray, shape (D, D)
    """
    mu = check_array(means, "means", ndim=2)
    cov = check_array(covariances, "covariances", shape=(mu.shape[0], mu.shape[1], mu.shape[1]))
    return product_information(mu, precision_from_covariance(cov), check=False)


def linear_transform(
    mean: npt.ArrayLike,
    covariance: npt.ArrayLike,
    A: npt.ArrayLike,
    b: npt.ArrayLike | None = None,
) -> tuple[Float, Float]:
    """Distribution of y = A x + b for x ~ N(mean, covariance): N(A mu + b, A Sigma A^T).

    Parameters
    ----------
    mean : array-like, shape (..., D)
    covariance : array-like, shape (..., D, D)
    A : array-like, shape (..., E, D)
    b : array-like, shape (..., E), optional

    Returns
    -------
    mean : ndarray, shape (..., E)
    covariance : ndarray, shape (..., E, E)
    """
    mu = check_array(mean, "mean", ndim=(1, 2, 3))
    cov = check_array(covariance, "covariance", ndim=(2, 3, 4))
    a = check_array(A, "A", ndim=(2, 3, 4))
    if a.shape[-1] != mu.shape[-1] or cov.shape[-2:] != (mu.shape[-1], mu.shape[-1]):
        raise ValueError(
            f"A must have {mu.shape[-1]} columns and covariance shape (..., {mu.shape[-1]}, "
            f"{mu.shape[-1]}); got A {a.shape}, mean {mu.shape}, covariance {cov.shape}"
        )
    out_mean = np.einsum("...ij,...j->...i", a, mu)
    if b is not None:
        out_mean = out_mean + check_array(b, "b", ndim=(1, 2, 3))
    out_cov = a @ cov @ np.swapaxes(a, -1, -2)
    return out_mean, 0.5 * (out_cov + np.swapaxes(out_cov, -1, -2))


def regularize_covariance(
    covariance: npt.ArrayLike, reg: float = 1e-6, *, min_eigenvalue: float | None = None
) -> Float:
    """Make covariance matrices safely positive definite.

    Adds ``reg`` to the diagonal; with ``min_eigenvalue``, also raises every eigenvalue below that
    floor to it (eigendecomposition; the eigenvectors are kept), which bounds the condition number
    without inflating well-determined directions.

    Parameters
    ----------
    covariance : array-like, shape (..., D, D)
    reg : float
        Added to the diagonal (>= 0).
    min_eigenvalue : float, optional
        Floor for the eigenvalues.

    Returns
    -------
    covariance : ndarray, shape (..., D, D)
    """
    cov = check_array(covariance, "covariance", ndim=(2, 3, 4))
    if reg < 0 or not np.isfinite(reg):
        raise ValueError(f"reg must be finite and >= 0, got {reg}")
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    if min_eigenvalue is not None:
        w, v = np.linalg.eigh(cov)
        w = np.maximum(w, min_eigenvalue)
        cov = (v * w[..., None, :]) @ np.swapaxes(v, -1, -2)
        cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    return cov + reg * np.eye(cov.shape[-1])


def gaussian_log_density(X: npt.ArrayLike, mean: npt.ArrayLike, covariance: npt.ArrayLike) -> Float:
    """Log-density of N(mean, covariance) at each row of X.

    log N(x; mu, Sigma) = -0.5 (D log 2 pi + log|Sigma| + ||L^-1 (x - mu)||^2), Sigma = L L^T.

    Parameters
    ----------
    X : array-like, shape (N, D)
    mean : array-like, shape (D,)
    covariance : array-like, shape (D, D)

    Returns
    -------
    log_density : ndarray, shape (N,)
    """
    x = check_array(X, "X", ndim=2)
    d = x.shape[1]
    mu = check_array(mean, "mean", shape=(d,))
    cov = check_array(covariance, "covariance", shape=(d, d))
    chol = _cholesky(cov, "covariance")
    z = np.linalg.solve(chol, (x - mu).T)
    log_det = 2.0 * np.sum(np.log(np.diag(chol)))
    return np.asarray(-0.5 * (d * np.log(2 * np.pi) + log_det + np.sum(z * z, axis=0)))
