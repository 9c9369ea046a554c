"""Damped pseudo-inverse of a Jacobian and its null-space projector.

The paper writes J+ = (J^T J)^-1 J^T, which is singular for a 3 x n position Jacobian with n > 3.
We use the right inverse J+ = J^T (J J^T + lambda^2 I)^-1, damped only near singularities with the
schedule of Nakamura & Hanafusa (1986) / Maciejewski & Klein (1988):

    lambda^2 = 0                                          if sigma_min >= eps
    lambda^2 = lambda_max^2 (1 - (sigma_min / eps)^2)     otherwise,

where sigma_min is the smallest singular value of J. Far from singularities J+ is the exact
Moore-Penrose pseudo-inverse (J J+ = I); at a singularity the gain 1 / sigma of the lost direction
is replaced by sigma / (sigma^2 + lambda^2), so J+ stays finite and bounded. Position Jacobians are
in m/rad, so ``eps`` and ``lambda_max`` are too: the defaults (0.03 and 0.05) damp the Katana in
about 7% of random configurations and bound the joint-space gain by 1/eps = 33 rad/m.

All functions take batches: leading axes of J are batch axes.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_positive_float

__all__ = ["damped_pinv", "damping_schedule", "nullspace_projector"]

_RCOND = 1e-15  # as np.linalg.pinv: singular values below rcond * sigma_max count as zero


def damping_schedule(
    sigma_min: npt.ArrayLike, eps: float = 0.03, lambda_max: float = 0.05
) -> NDArray[np.float64]:
    """Squared damping lambda^2 for a given smallest singular value (Nakamura / Maciejewski).

    Parameters
    ----------
    sigma_min : array-like, shape (...)
        Smallest singular value(s) of the Jacobian(s).
    eps : float
        Size of the singular region: no damping when ``sigma_min >= eps``.
    lambda_max : float
        Damping at the singularity (``sigma_min = 0``).

    Returns
    -------
    lambda2 : ndarray, shape (...)
        lambda^2 = lambda_max^2 (1 - (sigma_min/eps)^2) inside the region, 0 outside.
    """
    s = np.asarray(sigma_min, dtype=np.float64)
    if eps == 0.0:
        return np.zeros_like(s)
    return np.where(s < eps, lambda_max**2 * (1.0 - (s / eps) ** 2), 0.0)


def damped_pinv(
    J: npt.ArrayLike,
    *,
    eps: float = 0.03,
    lambda_max: float = 0.05,
    damping: float | None = None,
) -> NDArray[np.float64]:
    """Damped right pseudo-inverse J^T (J J^T + lambda^2 I)^-1, batched over leading axes.

    Parameters
    ----------
    J : array-like, shape (..., m, n)
        Jacobian(s). For m > n the left form (J^T J + lambda^2 I)^-1 J^T is used (the same
        matrix).
    eps : float
        Damping starts when the smallest singular value sigma_min of J falls below ``eps``
        (same unit as J; m/rad for a position Jacobian). ``eps=0`` disables the schedule.
    lambda_max : float
        Damping at an exact singularity; lambda^2 = lambda_max^2 (1 - (sigma_min/eps)^2).
    damping : float, optional
        A constant lambda instead of the schedule (``damping=0`` gives np.linalg.pinv).

    Returns
    -------
    J_pinv : ndarray, shape (..., n, m)
    """
    jac = _check_jacobian(J)
    eps = _check_nonneg(eps, "eps")
    lambda_max = _check_nonneg(lambda_max, "lambda_max")
    if damping is not None:
        damping = _check_nonneg(damping, "damping")
    m, n = jac.shape[-2:]
    jt = np.swapaxes(jac, -1, -2)
    wide = m <= n
    gram = jac @ jt if wide else jt @ jac  # (..., k, k), k = min(m, n)
    if jac.ndim == 2 and m == 3 and n >= 3:
        # one position Jacobian (the reproduction loop): closed form, 3x faster than eigh
        gram_inv_3 = _damped_inverse_3x3(gram.tolist(), eps, lambda_max, damping)
        if gram_inv_3 is not None:
            single: NDArray[np.float64] = jt @ np.array(gram_inv_3)
            return single
    w, u = np.linalg.eigh(gram)  # eigenvalues = sigma^2, ascending
    w = np.maximum(w, 0.0)
    if damping is not None:
        lam2_b = np.full(w.shape[:-1], damping * damping)
    else:
        lam2_b = damping_schedule(np.sqrt(w[..., 0]), eps, lambda_max)
    denom_b = w + lam2_b[..., None]
    keep = denom_b > (_RCOND**2) * w[..., -1:]
    inv = np.where(keep, 1.0 / np.where(keep, denom_b, 1.0), 0.0)
    gram_inv_b = (u * inv[..., None, :]) @ np.swapaxes(u, -1, -2)
    result: NDArray[np.float64] = jt @ gram_inv_b if wide else gram_inv_b @ jt
    return result


def _damped_inverse_3x3(
    g: list[list[float]], eps: float, lambda_max: float, damping: float | None
) -> list[list[float]] | None:
    """(G + lambda^2 I)^-1 for a symmetric positive semi-definite 3x3 G, or None if singular.

    The smallest eigenvalue of G (= sigma_min^2) is found with the trigonometric formula for
    symmetric 3x3 matrices (Smith 1961); the inverse by cofactors.
    """
    a, b, c = g[0][0], g[1][1], g[2][2]
    d, e, f = g[0][1], g[1][2], g[0][2]
    if damping is not None:
        lam2 = damping * damping
    else:
        p1 = d * d + e * e + f * f
        mean = (a + b + c) / 3.0
        p2 = (a - mean) ** 2 + (b - mean) ** 2 + (c - mean) ** 2 + 2.0 * p1
        if p2 <= 1e-300:
            w_min = mean
        else:
            p = math.sqrt(p2 / 6.0)
            ba, bb, bc, bd, be, bf = (
                (a - mean) / p,
                (b - mean) / p,
                (c - mean) / p,
                d / p,
                e / p,
                f / p,
            )
            det_b = ba * (bb * bc - be * be) - bd * (bd * bc - be * bf) + bf * (bd * be - bb * bf)
            r = min(max(det_b / 2.0, -1.0), 1.0)
            w_min = mean + 2.0 * p * math.cos(math.acos(r) / 3.0 + 2.0 * math.pi / 3.0)
        s_min = math.sqrt(max(w_min, 0.0))
        lam2 = lambda_max * lambda_max * (1.0 - (s_min / eps) ** 2) if s_min < eps else 0.0
    a, b, c = a + lam2, b + lam2, c + lam2
    c00, c01, c02 = b * c - e * e, f * e - d * c, d * e - b * f
    c11, c12, c22 = a * c - f * f, d * f - a * e, a * b - d * d
    det = a * c00 + d * c01 + f * c02
    if not det > 1e-12 * max(a, b, c) ** 3:  # near-singular and undamped: use the eigh path
        return None
    k = 1.0 / det
    return [
        [c00 * k, c01 * k, c02 * k],
        [c01 * k, c11 * k, c12 * k],
        [c02 * k, c12 * k, c22 * k],
    ]


def _check_nonneg(value: object, name: str) -> float:
    if type(value) is float and 0.0 <= value < math.inf:
        return value
    return check_positive_float(value, name, allow_zero=True)


def _check_jacobian(J: npt.ArrayLike) -> NDArray[np.float64]:
    if (
        type(J) is np.ndarray
        and J.dtype == np.float64
        and J.ndim >= 2
        and J.size > 0
        and math.isfinite(J.sum())
    ):
        return J
    jac = check_array(J, "J")
    if jac.ndim < 2 or 0 in jac.shape[-2:]:
        raise ValueError(f"J must have shape (..., m, n) with m, n >= 1, got {jac.shape}")
    return jac


def nullspace_projector(
    J: npt.ArrayLike, J_pinv: npt.ArrayLike | None = None
) -> NDArray[np.float64]:
    """Null-space projector N = I - J+ J, batched over leading axes.

    Parameters
    ----------
    J : array-like, shape (..., m, n)
    J_pinv : array-like, shape (..., n, m), optional
        The pseudo-inverse to use; default :func:`damped_pinv` ``(J)``. J N = 0 holds exactly
        when J+ is undamped (far from singularities).

    Returns
    -------
    N : ndarray, shape (..., n, n)
    """
    jac = _check_jacobian(J)
    if J_pinv is None:
        jp = damped_pinv(jac)
    else:
        want = (*jac.shape[:-2], jac.shape[-1], jac.shape[-2])
        jp = check_array(J_pinv, "J_pinv", shape=want)
    projector: NDArray[np.float64] = np.eye(jac.shape[-1]) - jp @ jac
    return projector
