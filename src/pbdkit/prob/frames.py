"""Frames (A, b): data seen from a frame, Gaussians mapped back to the world.

A frame is an invertible matrix A (D, D) (a rotation, a scaling, a reflection or any
combination) and an origin b (D,). A point x of the world is A^-1 (x - b) in the frame; a
Gaussian N(m, S) learned in the frame is, in the world, N(A m + b, A S A^T), with precision
A^-T L A^-1 (L = S^-1). For an orthogonal A (a rotation or a reflection) A^-1 = A^T and the
precision maps as A L A^T, but only then: for a scaled or sheared frame it does not (pbdlib's
``GMM.lintrans`` maps the precision as A L A^T).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

__all__ = ["covariance_to_world", "precision_to_world", "to_local", "to_world"]

Float = NDArray[np.float64]


def to_local(a: npt.ArrayLike, b: npt.ArrayLike, x: npt.ArrayLike) -> Float:
    """A^-1 (x - b): world points x (..., D) seen from the frame (A (D, D), b (D,)); batched
    frames (..., D, D) and (..., D) broadcast against x."""
    am = np.asarray(a, dtype=np.float64)
    d = np.asarray(x, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return np.asarray(np.linalg.solve(am, d[..., None])[..., 0], dtype=np.float64)


def covariance_to_world(a: npt.ArrayLike, cov: npt.ArrayLike) -> Float:
    """A S A^T for covariances S (..., D, D) and frames A (..., D, D)."""
    am = np.asarray(a, dtype=np.float64)
    return np.asarray(am @ np.asarray(cov, dtype=np.float64) @ np.swapaxes(am, -1, -2))


def precision_to_world(a: npt.ArrayLike, prec: npt.ArrayLike) -> Float:
    """A^-T L A^-1 for precisions L (..., D, D) and frames A (..., D, D): the inverse of
    A S A^T. Equal to A L A^T only when A is orthogonal (a rotation or a reflection)."""
    ainv = np.linalg.inv(np.asarray(a, dtype=np.float64))
    return np.asarray(np.swapaxes(ainv, -1, -2) @ np.asarray(prec, dtype=np.float64) @ ainv)


def to_world(
    a: npt.ArrayLike, b: npt.ArrayLike, mean: npt.ArrayLike, cov: npt.ArrayLike
) -> tuple[Float, Float]:
    """A Gaussian of the frame (A, b) in the world: mean A m + b (..., D), covariance
    A S A^T (..., D, D)."""
    am = np.asarray(a, dtype=np.float64)
    m = np.einsum("...ij,...j->...i", am, np.asarray(mean, dtype=np.float64))
    return m + np.asarray(b, dtype=np.float64), covariance_to_world(am, cov)
