"""How far left-out demonstrations fall outside a time-indexed GMM's regression.

A mixture fitted to a few demonstrations can be confident where they were not: where they take
different paths (other postures, other timings) the fit's covariance holds their scatter about
its own mean, not how far a new demonstration falls from it. For the fold without sequence m
(:func:`~pbdkit.prob._selection.fold_models`, the folds that choose K), GMR at m's times gives
the mean mu(t) and covariance S(t) of the scored dimensions; each row of m gets

    z(t) = r^T S(t)^-1 r / S,    r = xi_m(t) - mu(t),  S the number of scored dimensions,

whose expectation is 1 where the model's covariance describes demonstrations it has not seen.
``GMM(loo_residuals=True)`` keeps them (``loo_residuals_``); :meth:`pbdkit.Skill.learn` widens
each space's covariance by them, moment by moment (``docs/math.md``, "Calibration").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ._gmr import gmr_batch
from ._selection import FitRows, fold_models

__all__ = ["normalized_residuals"]

Float = NDArray[np.float64]


def normalized_residuals(rows: FitRows, score_dims: Sequence[int]) -> Float:
    """z of every row against the GMR of the fold that left its sequence out (module
    docstring): (N,)."""
    x, time_dim = rows.x, rows.time_dim
    out_dims = [i for i in range(x.shape[1]) if i != time_dim]
    pos = np.asarray([out_dims.index(i) for i in score_dims], dtype=np.intp)
    z = np.empty(x.shape[0])
    for held, model in fold_models(rows):
        mean, cov = gmr_batch(model, x[held][:, [time_dim]], "exact")
        assert cov is not None
        r = x[held][:, score_dims] - mean[:, pos]
        s = cov[:, pos[:, None], pos[None, :]]
        z[held] = np.einsum("ti,ti->t", r, np.linalg.solve(s, r[:, :, None])[:, :, 0])
    return z / len(score_dims)
