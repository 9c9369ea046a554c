"""How far left-out demonstrations fall outside a time-indexed GMM's regression.

A mixture fitted to a few demonstrations can be confident where they were not: where they take
different paths (other postures, other timings) the fit's covariance holds their scatter about
its own mean, not how far a new demonstration falls from it. For the fold without sequence m
(:func:`~pbdkit.prob._selection.fold_residuals`, the folds that choose K), GMR at m's times gives
the mean mu(t) and covariance S(t) of the scored dimensions; each row of m gets

    z(t) = r^T S(t)^-1 r / S,    r = xi_m(t) - mu(t),  S the number of scored dimensions,

whose expectation is 1 where the model's covariance describes demonstrations it has not seen.
``GMM(loo_residuals=True)`` keeps them (``loo_residuals_``); :meth:`pbdkit.Skill.learn` widens
the spaces' covariances, moment by moment, by the joints' z against the best object's
(``docs/math.md``, "Calibration").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ._selection import FitRows, fold_residuals

__all__ = ["normalized_residuals"]

Float = NDArray[np.float64]


def normalized_residuals(rows: FitRows, score_dims: Sequence[int]) -> Float:
    """z of every row against the GMR of the fold that left its sequence out (module
    docstring): (N,)."""
    z = np.empty(rows.x.shape[0])
    for held, r, s in fold_residuals(rows, score_dims, covariance=True):
        assert s is not None
        z[held] = np.einsum("ti,ti->t", r, np.linalg.solve(s, r[:, :, None])[:, :, 0])
    return z / len(score_dims)
