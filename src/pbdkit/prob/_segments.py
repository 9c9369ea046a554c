"""Consecutive segments of time that the mean path changes least within: a start for EM.

EM starts from K consecutive bins of equal count along time (``_time_bins_resp`` in ``_em``).
Where the demonstrations hold still for long and move fast in between, equal counts put many
components on the hold and few on the motion; the cross-validated score can then still fall at
the cap (30). :class:`TimeSegments` gives the other start: the samples, ordered by time, are
cut into short bins of equal count, and the bins into the K consecutive segments whose bin
means lie closest to their segment's mean (the least sum of squares, each bin weighing its
count, every dimension but time divided by its spread), found exactly by dynamic programming.
A hold is one segment; the motion is cut where it turns.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

__all__ = ["SEGMENT_BINS", "TimeSegments"]

Float = NDArray[np.float64]

#: The samples, ordered by time, are cut into at most this many bins of equal count; segments
#: begin and end at their edges. The dynamic programme costs K * SEGMENT_BINS**2 operations.
SEGMENT_BINS = 200


class TimeSegments:
    """The best K consecutive segments of ``x`` along ``x[:, time_dim]``, for any K.

    Parameters
    ----------
    x : ndarray, shape (N, D)
    time_dim : int
    bins : int
        At most this many bins of equal count along time (:data:`SEGMENT_BINS`).
    """

    def __init__(self, x: Float, time_dim: int, bins: int = SEGMENT_BINS) -> None:
        n = x.shape[0]
        self._order = np.argsort(x[:, time_dim], kind="stable")
        self._bins = np.array_split(self._order, max(1, min(bins, n)))
        others = np.delete(x, time_dim, axis=1)
        spread = others.std(axis=0)
        z = others / np.where(spread > 0.0, spread, 1.0)
        count = np.array([b.size for b in self._bins], dtype=np.float64)
        sums = np.stack([z[b].sum(axis=0) for b in self._bins])
        # Each bin's samples counted at the bin's mean: the spread within a bin adds the same
        # to every cut, so the cut is that of the samples themselves.
        squares = np.square(sums).sum(axis=1) / count
        zero = np.zeros((1, z.shape[1]))
        c = np.concatenate(([0.0], np.cumsum(count)))
        s = np.concatenate((zero, np.cumsum(sums, axis=0)))
        q = np.concatenate(([0.0], np.cumsum(squares)))
        # cost[i, j]: the sum of squares of the means of bins i..j-1 about theirs (j > i).
        dc = c[None, :] - c[:, None]
        ds = s[None, :, :] - s[:, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            cost = (q[None, :] - q[:, None]) - np.einsum("ijd,ijd->ij", ds, ds) / dc
        upper = np.triu(np.ones_like(cost, dtype=bool), k=1)
        self._cost = np.where(upper, np.maximum(cost, 0.0), np.inf)
        # _best[k - 1][j]: the least cost of bins 0..j-1 in k segments; _cut: where the last
        # one begins.
        self._best: list[Float] = [self._cost[0].copy()]
        self._cut: list[NDArray[np.intp]] = [np.zeros(self._cost.shape[0], dtype=np.intp)]

    @property
    def n_bins(self) -> int:
        return len(self._bins)

    def edges(self, k: int) -> list[int]:
        """The bin indices where each of the K segments begins, then the number of bins."""
        while len(self._best) < k:
            total = self._best[-1][:, None] + self._cost
            self._cut.append(np.argmin(total, axis=0).astype(np.intp))
            self._best.append(total[self._cut[-1], np.arange(total.shape[1])])
        edges = [self.n_bins]
        for level in range(k - 1, 0, -1):
            edges.append(int(self._cut[level][edges[-1]]))
        edges.append(0)
        return edges[::-1]

    def resp(self, k: int) -> Float:
        """Hard responsibilities of the K segments, (N, K); K at most :attr:`n_bins`."""
        if not 1 <= k <= self.n_bins:
            raise ValueError(f"k must be in [1, {self.n_bins}], got {k}")
        resp = np.zeros((self._order.size, k))
        for j, (a, b) in enumerate(itertools.pairwise(self.edges(k))):
            resp[np.concatenate(self._bins[a:b]), j] = 1.0
        return resp
