"""Choosing K for a GMM of trajectories: cross-validation over left-out demonstrations, and BIC.

``n_components="auto"`` leaves one sequence (demonstration) m out at a time and scores the GMR
mean of the others at m's times against the demonstrations' own spread s_d(t)^2:

    score(K) = mean over m of  mean over scored dims d and times t of
               (xi_m,d(t) - mu_K^(-m)_d(t))^2 / s_d(t)^2
    K        = the smallest K with score(K) <= (1 + CV_TOLERANCE) min_K' score(K')

``n_components="bic"`` scores the BIC of an effective sample of n_eff points (Schwarz, 1978):

    BIC_eff(K) = -2 (n_eff / N) log L + p(K) log n_eff,  p(K) = (K - 1) + K D + K D (D + 1) / 2

Why the demonstration is the unit of evidence, the local spread, the approximate leave-one-out
and why not a likelihood criterion: ``docs/math.md``, "Choosing K" (measured in
``benchmarks/README.md``, "Choosing K").
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ._em import Params, _e_step, _Floor, _params_from_stats, _sufficient_stats
from ._gmr import GMRModel, gmr_batch, gmr_precompute

__all__ = [
    "CV_TOLERANCE",
    "FALLING_STEPS",
    "LOCAL_SPREAD_FLOOR",
    "MIN_COMPONENTS",
    "SWEEP_TOL",
    "FitRows",
    "ModelSelection",
    "SelectionWarning",
    "candidate_grid",
    "count_sequences",
    "effective_bic",
    "fold_models",
    "fold_residuals",
    "local_spread",
    "n_parameters",
    "pooled_spread",
    "reached_level",
    "sequences_from_time",
]

Float = NDArray[np.float64]


#: EM tolerance of the fits screened while choosing K (the kept fit is refined to ``tol``).
SWEEP_TOL = 1e-2
#: "auto": a K whose cross-validated error is within this fraction of the best K's is as good
#: as the best. It is about the accuracy of the approximate leave-one-out of :func:`_cv_errors`
#: against exact refits near the chosen K (``benchmarks/bench_selection.py``): smaller
#: differences are not resolved by it.
CV_TOLERANCE = 0.03
#: "auto": the smallest K tried (or the cap, if smaller). On a trajectory the cross-validated
#: score flattens once the tight phases are held, while the motion between them still gains
#: from more components: on LASA's 26 shapes the GMR mean was 1.24 % further from the
#: demonstrations than their pointwise mean with K 7-16 chosen, 1.04 % from 12 on (1.16 % from
#: 10). The paper's tasks choose 17-27 either way (teach seeds 0-9), and the arm zoo's fused
#: hand is as close to the box (its joint spaces chose 6-13).
MIN_COMPONENTS = 12
#: "auto": the scores still fall at the cap when each of this many last steps of the grid
#: falls by more than CV_TOLERANCE (:func:`reached_level`). With two (24 -> 29 -> 30), one
#: lucky fit at 30 took the cap on 4 of 20 teach seeds of the paper's tasks (the glass space;
#: 3 before the time ceiling); with four (17 -> 20 -> 24 -> 29 -> 30) they choose 19-25.
FALLING_STEPS = 4
#: "auto" with ``cv_scale="local"``: the spread at a moment is at least this fraction of the
#: spread pooled over time (a phase weighs at most 1000 times the average): one time step where
#: every demonstration is exactly alike (LASA's shared end point) would otherwise decide K alone.
#: 0.01 (100 times) let a grasp held for 2 % of the motion weigh too little to be kept when the
#: demonstrations differ by decimetres elsewhere (issue 34: the box missed by 3-7 mm).
LOCAL_SPREAD_FLOOR = 0.001


class SelectionWarning(UserWarning):
    """K was chosen at the cap (``max_components``): every smaller K scored worse by more than
    :data:`CV_TOLERANCE`, so the error may still fall beyond the cap."""


def cap_warning(selection: ModelSelection, max_components: int) -> str | None:
    """The message of a :class:`SelectionWarning` for ``selection``, or None: the K chosen by
    cross-validation is the cap itself."""
    top = max(selection.candidates)
    if selection.method != "cv" or selection.chosen != top or top < max_components:
        return None
    scores = dict(zip(selection.candidates, selection.scores.tolist(), strict=True))
    below = max((k for k in scores if k < top), default=top)
    both = ", from both starts of EM" if selection.start == "segments" else ""
    return (
        f"K is at the cap, max_components={top}: the cross-validated error is still falling "
        f"there (K={below}: {scores[below]:.3g}, K={top}: {scores[top]:.3g}, more than "
        f"{CV_TOLERANCE:.0%} apart{both}), so a larger K may model the demonstrations better: "
        "pass a larger max_components, or, if the demonstrations differ in timing, align them "
        "(pbdkit.align)"
    )


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


def _cv_scale(
    x: Float,
    groups: NDArray[np.intp],
    time_dim: int,
    score_dims: Sequence[int],
    floor: Float,
    how: str,
) -> Float:
    """What ``"auto"`` divides a squared error by: (N, S) for ``"local"``, (S,) for ``"pooled"``.

    The spread of the scored dimensions (:func:`local_spread`, at least
    :data:`LOCAL_SPREAD_FLOOR` of :func:`pooled_spread`; or :func:`pooled_spread`), at least
    ``floor`` (the diagonal floor (D,), ``reg_covar``); 1 where it is 0.
    """
    bins, variances = _bin_variances(x, groups, time_dim)
    spread_ = _pooled(bins, variances)[score_dims]
    if how == "local":
        local = _local(bins, variances, x.shape[0])[:, score_dims]
        spread_ = np.maximum(local, LOCAL_SPREAD_FLOOR * spread_)
    scale = np.maximum(spread_, floor[score_dims])
    return np.where(scale > 0, scale, 1.0)


@dataclass(frozen=True)
class ModelSelection:
    """How K was chosen for one GMM (``docs/math.md``, "Choosing K").

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
    start : {"equal counts", "segments"}
        Where EM started each K's fit: K bins of equal count along time, or (``"cv"`` only,
        after a sweep from equal counts ended at the cap with the score still falling) the K
        segments the data change least within (:class:`pbdkit.prob._segments.TimeSegments`).
    """

    method: str
    candidates: tuple[int, ...]
    scores: Float
    fold_scores: Float
    best: int
    chosen: int
    n_folds: int
    start: str = "equal counts"

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
            "start": self.start,
        }


def candidate_grid(max_components: int) -> list[int]:
    """The K that ``"auto"`` tries first: every K up to 8, then steps of about 20 %, and the cap
    (1-8, 10, 12, 14, 17, 20, 24, 29, 30), from :data:`MIN_COMPONENTS` on where the cap is above
    it (12, 14, 17, 20, 24, 29, 30 with the default cap of 30).

    Between the chosen grid point and the one below it every K is tried too (see
    :func:`_select_by_cv`), so the grid only saves the fits far from the choice. (Steps of
    25 % save a fifth of the sweep, and chose K worse: the scores of single EM runs are noisy,
    and the fewer the K tried, the more one run decides.)
    """
    grid = list(range(1, min(8, max_components) + 1))
    while grid[-1] < max_components:
        grid.append(min(max_components, max(grid[-1] + 1, round(grid[-1] * 1.2))))
    if max_components > MIN_COMPONENTS:
        grid = [k for k in grid if k >= MIN_COMPONENTS]
    return grid


def reached_level(scores: Sequence[float]) -> float:
    """The score a K must come within :data:`CV_TOLERANCE` of, from the scores of the grid in
    increasing K: the second lowest, the level at least two K reach; the last score where the
    scores still fall, by more than the tolerance at each of the last :data:`FALLING_STEPS`
    steps of the grid (all its steps when it has fewer; the choice then lands at the cap, and
    :func:`cap_warning` says so).

    Each K's fit is one run of EM, and one run can land in a better optimum than the others (on
    the coaster task, K = 30 scored 3.5 % below K = 24 and K = 29, which scored alike; on a
    Panda teacher who pauses, K = 14, 16 and 17 scored 1.42, 1.43, 1.26 and K = 15 1.75): a K
    is as good as the best when it is as good as what two fits reach, not one lucky fit. With
    fewer than three scores, the lowest.
    """
    s = [float(v) for v in scores]
    if len(s) < 3:  # no second fit to corroborate a score: the best
        return min(s)
    grow = 1.0 + CV_TOLERANCE
    tail = s[-min(FALLING_STEPS, len(s) - 1) - 1 :]
    if all(a > grow * b for a, b in itertools.pairwise(tail)):
        return s[-1]
    return sorted(s)[1]


def _select_by_cv(
    candidates: Sequence[int], cv: Callable[[int], Float], n_folds: int
) -> ModelSelection:
    """The smallest K whose cross-validated error is within :data:`CV_TOLERANCE` of the level
    the grid reaches (:func:`reached_level`).

    ``cv(k)`` gives the error of every left-out sequence, (n_folds,). K is searched on
    :func:`candidate_grid` of ``max(candidates)``; then every K between the grid point chosen
    and the one below it is tried, in increasing order, against the same bound.
    """
    errors: dict[int, Float] = {k: cv(k) for k in candidate_grid(max(candidates))}
    best = min(errors, key=lambda k: float(errors[k].mean()))
    bound = (1.0 + CV_TOLERANCE) * reached_level([float(errors[k].mean()) for k in sorted(errors)])

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


def _select_by_bic(
    candidates: Sequence[int],
    log_likelihood: Callable[[int], float],
    n_samples: int,
    n_eff: float,
    n_dims: int,
) -> ModelSelection:
    """The K of lowest :func:`effective_bic`; ``log_likelihood(k)`` is the K-component fit's
    log-likelihood summed over the ``n_samples`` rows."""
    scores = [
        effective_bic(log_likelihood(k), n_samples, n_eff, n_parameters(k, n_dims))
        for k in candidates
    ]
    best = candidates[int(np.argmin(scores))]
    return ModelSelection(
        "bic", tuple(candidates), np.asarray(scores), np.zeros((0, 0)), best, best, 0
    )


def _drop_empty(params: Params, min_weight: float) -> Params:
    w, m, c = params
    keep = w > min_weight
    if keep.all():
        return params
    return w[keep] / w[keep].sum(), m[keep], c[keep]


class FitRows(NamedTuple):
    """One fit of a time-indexed mixture and the rows it was fitted on: what its folds need."""

    x: Float  # (N, D), centred
    feats: Float  # (N, P), the rows' features (pbdkit.prob._em._features)
    resp: Float  # (N, K), the fit's responsibilities
    groups: NDArray[np.intp]  # (N,), the sequence of every row
    floor: _Floor
    time_dim: int


def fold_models(rows: FitRows) -> Iterator[tuple[NDArray[np.bool_], GMRModel]]:
    """The approximate leave-one-sequence-out models of one fit: (rows of m, GMR of the rest).

    For the fold without sequence m the model is the fitted one with m's contributions removed
    from the sufficient statistics, followed by one EM iteration on the remaining rows (exact
    refits move the errors by a few percent and cost 5-10 times more), conditioned on time.
    """
    _, feats, resp, groups, floor, time_dim = rows
    stats = _sufficient_stats(feats, resp)
    n_components = resp.shape[1]  # the fit's K: its time floor holds in every fold
    for m in range(int(groups.max()) + 1):
        held = groups == m
        rest = ~held
        own = _sufficient_stats(feats[held], resp[held])
        s0 = stats[0] - own[0]
        # A component (nearly) made of sequence m alone has no support left in the fold: drop
        # it (its downdated moments are rounding noise).
        keep = s0 >= 1.0
        params = _params_from_stats(
            s0[keep], (stats[1] - own[1])[keep], (stats[2] - own[2])[keep], floor, n_components
        )
        n_rest = float(np.count_nonzero(rest))
        feats_rest = feats[rest]
        r, _ = _e_step(feats_rest, params)
        params = _drop_empty(
            _params_from_stats(*_sufficient_stats(feats_rest, r), floor, n_components),
            0.5 / n_rest,
        )
        yield held, gmr_precompute(*params, (time_dim,))


def fold_residuals(
    rows: FitRows, score_dims: Sequence[int], covariance: bool
) -> Iterator[tuple[NDArray[np.bool_], Float, Float | None]]:
    """Per fold of :func:`fold_models`: the rows of sequence m, their residuals on
    ``score_dims`` against the fold's GMR mean at m's times (len(m), S), and with
    ``covariance`` the fold's GMR covariance of those dimensions there (len(m), S, S)."""
    x, time_dim = rows.x, rows.time_dim
    out_dims = [i for i in range(x.shape[1]) if i != time_dim]
    pos = np.asarray([out_dims.index(i) for i in score_dims], dtype=np.intp)
    for held, model in fold_models(rows):
        mean, cov = gmr_batch(model, x[held][:, [time_dim]], "exact" if covariance else None)
        r = x[held][:, score_dims] - mean[:, pos]
        yield held, r, None if cov is None else cov[:, pos[:, None], pos[None, :]]


def _cv_errors(rows: FitRows, score_dims: Sequence[int], scale: Float) -> Float:
    """Leave-one-sequence-out error of the GMR mean for one K: (n_groups,).

    The folds are :func:`fold_residuals`. The error of fold m is the mean over ``score_dims`` of
    the squared difference between sequence m and the fold's GMR mean at m's times, divided by
    ``scale``: (N, S), every row's own (the local spread of each scored dimension), or (S,),
    one per dimension (the pooled spread).
    """
    errors = np.empty(int(rows.groups.max()) + 1)
    for m, (held, r, _) in enumerate(fold_residuals(rows, score_dims, covariance=False)):
        errors[m] = float(np.mean(r**2 / (scale[held] if scale.ndim == 2 else scale)))
    return errors
