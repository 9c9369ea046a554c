"""Alignment in time: demonstrations warped onto one reference by dynamic time warping (DTW).

DTW (Sakoe & Chiba, 1978) pairs the samples of a demonstration with the instants of a reference,
both in order, so that the summed cost of the pairs is least: the cumulative cost

    D(i, j) = c(i, j) + min(D(i-1, j), D(i, j-1), D(i-1, j-1)),   D(0, 0) = c(0, 0),

c(i, j) the squared Euclidean distance between reference instant i and sample j in normalized
features, is read back from D(n-1, m-1) into the pairing (the path). A Sakoe-Chiba band keeps
the pairs within ``band`` of each other in normalized time u = (t - t0) / (t_end - t0); where it
leaves no path (a band narrower than the step between two samples), it is widened to the
diagonal's staircase. The rows are computed one after the other for all pairs at once, the
moves along a row as one running minimum: D(i, j) = S(j) + min_{k <= j} (A(k) - S(k)), S the
row's cumulative cost and A(k) = c(i, k) + min(D(i-1, k-1), D(i-1, k)).

What is kept (:func:`align`, :func:`align_trajectories`): every sample, its data, and the
demonstration's start t0 and end t_end. Only the time stamps change: a sample takes the
normalized time of the first reference instant it is paired with, mapped onto its own
[t0, t_end]; samples paired with one reference instant are spread evenly up to the next, so that
the time stays strictly increasing, and the last sample ends at t_end. A pause (repeated
samples) is paired with one instant of the reference and squeezed into its interval: it does
not stretch the rest. The reference (:data:`REFERENCES`): the medoid (the demonstration of least
total DTW cost to the others; it keeps its own time), or a mean refined on the medoid's time
grid.

A series longer than :data:`MAX_SAMPLES` is decimated for the DTW, the warped times of the
samples in between interpolated. Measurements on real recordings: :doc:`/alignment`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._threads import one_blas_thread
from .._validation import check_trajectories, short
from ..robots._protocols import KinematicModel, check_robot
from ._demonstration import Demonstration, check_demonstrations
from ._placement import position_of

__all__ = [
    "MAX_SAMPLES",
    "MEAN_ITERATIONS",
    "MEAN_TOLERANCE",
    "MEDOID_POINTS",
    "NEAR_SCALE",
    "REFERENCES",
    "SPEED_WEIGHT",
    "SPREAD_FLOOR",
    "align",
    "align_trajectories",
    "alignment_spreads",
]

Float = NDArray[np.float64]
Index = NDArray[np.intp]
#: A reference's warp: (features, normalized times, band) -> warped normalized times.
Warp = Callable[[list[Float], list[Float], float], list[Float]]

#: A feature is divided by its spread (standard deviation over all samples of all
#: demonstrations), but by no less than this fraction of the largest spread in its group (the
#: joints, the gripper, the hand relative to one object, a trajectory's columns): a coordinate
#: that barely moves (a hand sliding on a table, a wrist held still) is not blown up into noise.
SPREAD_FLOOR = 0.1
#: None: the hand relative to an object enters the features in metres. A length (m): as
#: p / (|p| + NEAR_SCALE), near the object a millimetre counting as much as a centimetre does
#: 10 cm away. In metres, a hand 5 mm short of a box looks like one on it, and the DTW puts the
#: arrival anywhere in the dwell before the grasp (the xArm7's pauses teacher: arrivals over
#: 4.3 % of the duration; 1.3 % with 0.05). Not the default yet: the sharper phases it gives
#: changed which obstacles the avoidance can keep clear of (docs/alignment.md).
NEAR_SCALE: float | None = None
#: With a robot, the hand's speed (|d fk / du|, u the normalized time) is one more group of the
#: features, weighed by this fraction of the others (0: left out): a pause ends where the speed
#: rises, and an arrival is where it falls, wherever the hand is. In metres alone, a hand 5 mm
#: short of a box looks like one on it, and the xArm7's pausing teacher on the 40 cm table lost
#: its grasp (the fused hand's median at the box up to 4.5 mm over teach seeds 0-4). At a full
#: weight the speed outvotes the positions where a teacher merely slows down; a quarter keeps
#: the arrivals and leaves the rest to the positions (docs/alignment.md).
SPEED_WEIGHT = 0.25
#: At most this many samples of a series enter the DTW; a longer one is decimated (evenly, its
#: first and last samples kept) and the warped times of the samples in between are interpolated.
#: The DTW's cost grows with the square of it: 500 aligns five demonstrations of 1000 samples in
#: a third of the time 1000 took, at 0.2 % of the duration per sample.
MAX_SAMPLES = 500
#: The medoid is chosen on the series resampled at this many uniform normalized times.
MEDOID_POINTS = 128
#: The mean reference: at most this many refinements, stopping earlier when the mean moves by
#: less than MEAN_TOLERANCE (RMS, in normalized feature units).
MEAN_ITERATIONS = 5
MEAN_TOLERANCE = 1e-3
#: Bytes of DTW back-pointers held at once (pairs are batched within it).
_POINTER_BUDGET = 64 * 2**20
#: Rows of the local cost computed at once.
_BLOCK = 64


# ----------------------------------------------------------------------------- public functions
def align(
    demos: Sequence[Demonstration],
    robot: KinematicModel | None = None,
    *,
    band: float = 0.3,
    reference: str = "medoid",
) -> list[Demonstration]:
    """Demonstrations aligned in time onto one reference by DTW; their data as recorded.

    Parameters
    ----------
    demos : sequence of Demonstration
        At least 2, with the same joint count, object names and gripper presence.
    robot : KinematicModel, optional
        With a robot, the hand relative to each object, fk(joints) - o(n), is a feature too.
    band : float
        Half-width of the Sakoe-Chiba band, as a fraction of the duration, in (0, 1].
    reference : str
        ``"medoid"`` (the demonstration of least total DTW cost to the others) or ``"mean"``
        (a mean refined by iteration on the medoid's time grid).

    Returns
    -------
    demos : list of Demonstration
        In the order given. Each has the same joints, objects and gripper arrays (values), the
        same number of samples, the same t[0] and t[-1]; only its ``t`` is warped (strictly
        increasing).

    Raises
    ------
    ValueError
        Fewer than 2 demonstrations, different joint counts or object names, a robot whose
        joint count differs, ``band`` outside (0, 1], an unknown ``reference``.
    """
    items = check_demonstrations(demos)
    band_ = _check_band(band)
    warp = _check_reference(reference)
    features = _demo_features(items, robot)
    us = _warped_times(warp, features, [_normalized(d.t) for d in items], band_)
    out = []
    for d, u in zip(items, us, strict=True):
        out.append(
            Demonstration(
                t=_seconds(d.t, u), joints=d.joints, objects=dict(d.objects), gripper=d.gripper
            )
        )
    return out


def align_trajectories(
    trajs: Sequence[npt.ArrayLike], *, band: float = 0.3, reference: str = "medoid"
) -> list[Float]:
    """Trajectories aligned in time onto one reference by DTW (:func:`align` without a robot).

    Parameters
    ----------
    trajs : sequence of array-like, shape (T_i, 1 + D)
        At least 2; time in column 0 (finite, strictly increasing), then the same D >= 1
        coordinates in each. The features are the D columns, each divided by its spread.
    band : float
        Half-width of the Sakoe-Chiba band, as a fraction of the duration, in (0, 1].
    reference : str
        ``"medoid"`` or ``"mean"`` (:func:`align`).

    Returns
    -------
    trajs : list of ndarray, shape (T_i, 1 + D)
        New arrays in the order given: column 0 the warped time (same first and last value,
        strictly increasing), the other columns as given.

    Raises
    ------
    ValueError
        Fewer than 2 trajectories, a shape other than (T_i, 1 + D) with T_i >= 2 and D >= 1, a
        different D, NaN or infinite values, a time column that is not strictly increasing,
        ``band`` outside (0, 1], an unknown ``reference``.
    """
    xs = check_trajectories(trajs, "trajs", what="trajectory", increasing_time=True)
    band_ = _check_band(band)
    warp = _check_reference(reference)
    features = _normalize([x[:, 1:] for x in xs], [xs[0].shape[1] - 1])
    us = _warped_times(warp, features, [_normalized(x[:, 0]) for x in xs], band_)
    out = []
    for x, u in zip(xs, us, strict=True):
        y = x.copy()
        y[:, 0] = _seconds(x[:, 0], u)
        out.append(y)
    return out


# ----------------------------------------------------------------------------- validation
def _check_band(band: object) -> float:
    if isinstance(band, bool) or not isinstance(band, (int, float, np.integer, np.floating)):
        raise ValueError(
            "band must be a number in (0, 1] (the half-width of the DTW band as a fraction of "
            f"the duration), got {short(band)}"
        )
    b = float(band)
    if not 0.0 < b <= 1.0:  # also rejects NaN
        raise ValueError(
            "band must be in (0, 1] (the half-width of the DTW band as a fraction of the "
            f"duration), got {short(band)}"
        )
    return b


def _check_reference(reference: object) -> Warp:
    if not isinstance(reference, str) or reference not in REFERENCES:
        raise ValueError(f"reference must be one of {sorted(REFERENCES)}, got {short(reference)}")
    return REFERENCES[reference]


# ----------------------------------------------------------------------------- features and time
def _demo_features(demos: list[Demonstration], robot: KinematicModel | None) -> list[Float]:
    """Normalized features per demonstration (T_i, F): joints, gripper, and with a robot the
    hand relative to each object."""
    n = demos[0].n_joints
    names = demos[0].object_names
    if robot is not None:
        check_robot(robot, KinematicModel)
        if robot.n_joints != n:
            raise ValueError(
                f"robot has {robot.n_joints} joints, expected {n} like the demonstrations"
            )
    parts: list[Float] = []
    groups = [n]
    if demos[0].gripper is not None:
        groups.append(1)
    speed_group = robot is not None and SPEED_WEIGHT > 0.0
    if robot is not None:
        groups += [3] * len(names) + ([1] if speed_group else [])
    weights = [1.0] * (len(groups) - 1) + [SPEED_WEIGHT if speed_group else 1.0]
    for d in demos:
        cols = [d.joints]
        if d.gripper is not None:
            cols.append(d.gripper[:, None])
        if robot is not None:
            hand = np.asarray(robot.fk(d.joints), dtype=np.float64).reshape(d.n_steps, 3)
            cols += [_near(hand - position_of(d.objects[k])) for k in names]
            if speed_group:
                speed = np.gradient(hand, _normalized(d.t), axis=0)
                cols.append(np.linalg.norm(speed, axis=1)[:, None])
        parts.append(np.hstack(cols))
    return _normalize(parts, groups, weights)


def _near(p: Float) -> Float:
    """The hand's offset from an object, stretched near it (:data:`NEAR_SCALE`; None: in
    metres)."""
    if NEAR_SCALE is None:
        return p
    out: Float = p / (np.linalg.norm(p, axis=1, keepdims=True) + NEAR_SCALE)
    return out


def _normalize(
    parts: list[Float], groups: list[int], weights: list[float] | None = None
) -> list[Float]:
    """Each feature centred and divided by its spread over all samples of all series, floored
    at SPREAD_FLOOR times the largest spread of its group (and at a tiny absolute value), and
    by the square root of its group's size: each group (the joints, the gripper, the hand
    relative to one object) weighs in the distance as much as one feature, times its weight in
    ``weights`` (one per group; default 1: the hand's speed weighs :data:`SPEED_WEIGHT`)."""
    stacked = np.concatenate(parts)
    mean = stacked.mean(axis=0)
    spread = stacked.std(axis=0)
    floor = np.empty_like(spread)
    start = 0
    for size in groups:
        floor[start : start + size] = SPREAD_FLOOR * spread[start : start + size].max()
        start += size
    scale = np.maximum(np.maximum(spread, floor), 1e-12)
    # Every group weighs as one feature: seven joints would otherwise outvote the hand's
    # position relative to the box, and postures that differ would be matched instead of
    # phases.
    start = 0
    for size in groups:
        scale[start : start + size] *= np.sqrt(size)
        start += size
    out = [np.ascontiguousarray((p - mean) / scale) for p in parts]
    if weights is not None and any(w != 1.0 for w in weights):
        column = np.repeat(np.asarray(weights, dtype=np.float64), groups)
        for p in out:
            p *= column
    return out


def _normalized(t: Float) -> Float:
    """u = (t - t0) / (t_end - t0), exactly 0 and 1 at the ends."""
    u: Float = (t - t[0]) / (t[-1] - t[0])
    u[0], u[-1] = 0.0, 1.0
    return u


def _seconds(t: Float, u: Float) -> Float:
    """Normalized time u mapped onto [t[0], t[-1]], the ends exact."""
    out: Float = t[0] + u * (t[-1] - t[0])
    out[0], out[-1] = t[0], t[-1]
    return out


def _resampled(x: Float, u: Float, grid: Float) -> Float:
    """x (T, F) at normalized times u, linearly interpolated at ``grid``."""
    idx = np.clip(np.searchsorted(u, grid, side="right") - 1, 0, u.shape[0] - 2)
    w = ((grid - u[idx]) / (u[idx + 1] - u[idx]))[:, None]
    return x[idx] * (1.0 - w) + x[idx + 1] * w


# ----------------------------------------------------------------------------- references
def _medoid_index(features: list[Float], us: list[Float], band: float) -> int:
    """The series of least total DTW cost to the others (the first of equals), computed on the
    series resampled at MEDOID_POINTS uniform normalized times."""
    n_series = len(features)
    if n_series == 2:
        return 0  # one cost, shared
    n_points = MEDOID_POINTS
    grid = np.linspace(0.0, 1.0, n_points)
    coarse = np.stack([_resampled(x, u, grid) for x, u in zip(features, us, strict=True)])
    a, b = np.triu_indices(n_series, k=1)
    lo, hi = _band_limits(grid, grid, band)
    cost, _ = _dtw(
        coarse[a],
        coarse[b],
        np.broadcast_to(lo, (a.size, n_points)),
        np.broadcast_to(hi, (a.size, n_points)),
        np.full(a.size, n_points - 1),
    )
    total = np.zeros(n_series)
    np.add.at(total, a, cost)
    np.add.at(total, b, cost)
    return int(np.argmin(total))


def _medoid_warp(features: list[Float], us: list[Float], band: float) -> list[Float]:
    """Warped normalized times of every series against the medoid (which keeps its own)."""
    r = _medoid_index(features, us, band)
    others = [k for k in range(len(features)) if k != r]
    warped = _warp_onto(
        features[r], us[r], [features[k] for k in others], [us[k] for k in others], band
    )
    out = [us[r]] * len(features)
    for k, w in zip(others, warped, strict=True):
        out[k] = w
    return out


def _mean_warp(features: list[Float], us: list[Float], band: float) -> list[Float]:
    """Warped normalized times of every series against a mean on the medoid's time grid: the
    mean of the samples paired with each instant, refined until it stops changing."""
    r = _medoid_index(features, us, band)
    ref, ref_u = features[r], us[r]
    paths = _paths_onto(ref, ref_u, features, us, band)
    for _ in range(MEAN_ITERATIONS):
        new = np.mean(
            [_mean_per_instant(x, p, ref.shape[0]) for x, p in zip(features, paths, strict=True)],
            axis=0,
        )
        change = float(np.sqrt(np.mean((new - ref) ** 2)))
        ref = new
        paths = _paths_onto(ref, ref_u, features, us, band)
        if change < MEAN_TOLERANCE:
            break
    return _times_from_paths(paths, ref_u)


#: The references of :func:`align`: name -> the warped normalized times of every series.
REFERENCES: dict[str, Warp] = {
    "medoid": _medoid_warp,
    "mean": _mean_warp,
}


def _mean_per_instant(x: Float, path: tuple[Index, Index], n: int) -> Float:
    """The mean of the samples x (m, F) paired with each reference instant 0..n-1."""
    pi, pj = path
    starts = np.flatnonzero(np.r_[True, pi[1:] != pi[:-1]])  # every instant is on the path
    sums = np.add.reduceat(x[pj], starts, axis=0)
    counts = np.diff(np.r_[starts, pi.size])
    mean: Float = sums / counts[:, None]
    return mean


# ----------------------------------------------------------------------------- warping
def _warped_times(warp: Warp, features: list[Float], us: list[Float], band: float) -> list[Float]:
    """Warped normalized times of every series: ``warp`` on the series decimated to at most
    MAX_SAMPLES samples, the skipped samples interpolated in their own time."""

    keeps = [_decimation(u.size, MAX_SAMPLES) for u in us]
    # Many small products: BLAS threads only contend (design.md, "Threads")
    with one_blas_thread():
        warped = warp(
            [x[k] for x, k in zip(features, keeps, strict=True)],
            [u[k] for u, k in zip(us, keeps, strict=True)],
            band,
        )
    return [
        w if k.size == u.size else np.interp(u, u[k], w)
        for w, u, k in zip(warped, us, keeps, strict=True)
    ]


def _decimation(m: int, cap: int) -> Index:
    """Samples of a series of m: all, or ``cap`` evenly spread (the first and the last kept)."""
    if m <= cap:
        return np.arange(m)
    return np.unique(np.round(np.linspace(0, m - 1, cap)).astype(np.intp))


def _warp_onto(
    ref: Float, ref_u: Float, xs: list[Float], us: list[Float], band: float
) -> list[Float]:
    return _times_from_paths(_paths_onto(ref, ref_u, xs, us, band), ref_u)


def _paths_onto(
    ref: Float, ref_u: Float, xs: list[Float], us: list[Float], band: float
) -> list[tuple[Index, Index]]:
    """DTW paths (reference instants, samples) of each series onto the reference."""
    limits = [_band_limits(ref_u, u, band) for u in us]
    return _banded_paths(ref, xs, limits)


def _banded_paths(
    ref: Float, xs: list[Float], limits: list[tuple[Index, Index]]
) -> list[tuple[Index, Index]]:
    """DTW paths of each series onto the reference within the given limits (lo, hi) per
    reference instant, the pairs batched within _POINTER_BUDGET."""
    n = ref.shape[0]
    lengths = np.array([x.shape[0] for x in xs])
    widths = np.array([int((hi - lo).max()) + 1 for lo, hi in limits])
    per_batch = max(1, _POINTER_BUDGET // (2 * n * int(widths.max())))
    paths: list[tuple[Index, Index]] = []
    for s in range(0, len(xs), per_batch):
        batch = list(range(s, min(s + per_batch, len(xs))))
        cols = np.zeros((len(batch), int(lengths[batch].max()), ref.shape[1]))
        for p, k in enumerate(batch):
            cols[p, : lengths[k]] = xs[k]
        lo = np.stack([limits[k][0] for k in batch])
        hi = np.stack([limits[k][1] for k in batch])
        _, ptr = _dtw(ref[None], cols, lo, hi, lengths[batch] - 1, pointers=True)
        assert ptr is not None
        paths += [_backtrack(ptr, p, n - 1, int(lengths[k]) - 1) for p, k in enumerate(batch)]
    return paths


def _band_limits(ref_u: Float, u: Float, band: float) -> tuple[Index, Index]:
    """First and last sample (inclusive) of u within ``band`` of each reference instant,
    widened to the diagonal's staircase so that a path from (0, 0) to (n-1, m-1) exists."""
    lo = np.searchsorted(u, ref_u - band, side="left")
    hi = np.searchsorted(u, ref_u + band, side="right") - 1
    diag = np.minimum(np.searchsorted(u, ref_u, side="left"), u.shape[0] - 1)
    lo = np.minimum(lo, np.r_[0, diag[:-1]])
    hi = np.maximum(hi, diag)
    return lo.astype(np.intp), hi.astype(np.intp)


class _Pointers(NamedTuple):
    """Back-pointers of a banded DTW, at (i, j - lo[i]): ``left`` (from (i, j-1)), else ``up``
    (from (i-1, j)), else from (i-1, j-1)."""

    left: NDArray[np.bool_]  # (P, n, W)
    up: NDArray[np.bool_]  # (P, n, W)
    lo: Index  # (P, n)


def _dtw(
    rows: Float,
    cols: Float,
    lo: Index,
    hi: Index,
    last: Index,
    *,
    pointers: bool = False,
) -> tuple[Float, _Pointers | None]:
    """Banded DTW of P pairs at once, row by row, each row stored from its band's start.

    Parameters
    ----------
    rows : ndarray, shape (P or 1, n, F)
        The reference of each pair (one shared reference: leading size 1).
    cols : ndarray, shape (P, M, F)
        The other series, padded to M samples.
    lo, hi : ndarray of intp, shape (P, n)
        The band: samples lo..hi (inclusive) of row i, both nondecreasing in i, lo[:, 0] = 0.
    last : ndarray of intp, shape (P,)
        The last sample of each series (m_p - 1), within the last row's band.
    pointers : bool
        Keep the back-pointers.

    Returns
    -------
    cost : ndarray, shape (P,)
        D(n-1, m_p - 1), the local cost c the squared Euclidean distance.
    pointers : _Pointers or None
    """
    n_pairs, m_max, _ = cols.shape
    n = rows.shape[1]
    width = int((hi - lo).max()) + 1
    shift = np.diff(lo, axis=1, prepend=lo[:, :1])  # lo[i] - lo[i-1] >= 0
    stride = width + 1 + int(shift.max())
    ptr = None
    if pointers:
        shape = (n_pairs, n, width)
        ptr = _Pointers(np.zeros(shape, dtype=np.bool_), np.zeros(shape, dtype=np.bool_), lo)
    span = np.arange(width)
    # The previous row, per pair: [inf, D(i-1, lo[i-1] + s) for s < width, inf...]: the window
    # at offset shift[i] holds D(i-1, j-1) and D(i-1, j) for the columns j of row i.
    prev = np.full((n_pairs, stride), np.inf)
    body, flat = prev[:, 1 : width + 1], prev.reshape(-1)
    window = (np.arange(n_pairs) * stride)[:, None, None] + np.arange(width + 1)
    # c(i, j) = |r_i - q_j|^2 = [r_i, |r_i|^2, 1] . [-2 q_j, 1, |q_j|^2]: one product
    sq_rows = np.einsum("pif,pif->pi", rows, rows)[..., None]
    sq_cols = np.einsum("pjf,pjf->pj", cols, cols)[..., None]
    rows_aug = np.concatenate([rows, sq_rows, np.ones_like(sq_rows)], axis=2)
    cols_aug = np.concatenate([-2.0 * cols, np.ones_like(sq_cols), sq_cols], axis=2)
    cols_aug_t = np.ascontiguousarray(cols_aug.transpose(0, 2, 1))
    offsets = (np.arange(n_pairs) * m_max)[:, None, None]
    for i0 in range(0, n, _BLOCK):
        i1 = min(i0 + _BLOCK, n)
        size = i1 - i0
        j = lo[:, i0:i1, None] + span  # (P, B, W)
        inside = j <= hi[:, i0:i1, None]
        np.minimum(j, m_max - 1, out=j)
        j += offsets * size + np.arange(size)[:, None] * m_max
        cost = np.matmul(rows_aug[:, i0:i1], cols_aug_t).reshape(-1).take(j)
        np.maximum(cost, 0.0, out=cost)  # rounding
        # S(j) along the row (the samples beyond the band come after it: they change nothing)
        total = np.cumsum(cost, axis=2)
        capped = np.where(inside, total, np.inf)
        gather = window + shift[:, i0:i1, None]
        for b in range(size):
            i = i0 + b
            if i == 0:  # D(0, j) = S(j): the first row is reached from the left only
                body[:] = capped[:, 0]
                if ptr is not None:
                    ptr.left[:, 0, 1:] = True
                continue
            near = flat.take(gather[:, b])  # D(i-1, j-1) and D(i-1, j)
            diag, up = near[:, :-1], near[:, 1:]
            if ptr is not None:
                np.less(up, diag, out=ptr.up[:, i])  # ties go to the diagonal
            # D(i, j) = S(j) + min_{k <= j} (c(i, k) + min(D(i-1, k-1), D(i-1, k)) - S(k)):
            # the moves along the row as one running minimum
            x = np.minimum(up, diag)
            x += cost[:, b]
            x -= total[:, b]
            run = np.minimum.accumulate(x, axis=1)
            if ptr is not None:
                np.less(run, x, out=ptr.left[:, i])
            np.add(capped[:, b], run, out=body)
    return body[np.arange(n_pairs), last - lo[:, -1]].copy(), ptr


def _backtrack(ptr: _Pointers, p: int, i: int, j: int) -> tuple[Index, Index]:
    """The path of pair p from (0, 0) to (i, j), in order, read back from the pointers."""
    left, up, lo = ptr.left[p], ptr.up[p], ptr.lo[p].tolist()
    is_left, is_up = left.item, up.item
    pi, pj = [i], [j]
    while i or j:
        s = j - lo[i]
        if i == 0 or is_left(i, s):
            j -= 1
        elif is_up(i, s):
            i -= 1
        else:
            i, j = i - 1, j - 1
        pi.append(i)
        pj.append(j)
    return np.array(pi[::-1], dtype=np.intp), np.array(pj[::-1], dtype=np.intp)


def _times_from_paths(paths: list[tuple[Index, Index]], ref_u: Float) -> list[Float]:
    return [_times_from_path(p, ref_u) for p in paths]


def _times_from_path(path: tuple[Index, Index], ref_u: Float) -> Float:
    """Warped normalized times of a series from its path onto the reference (normalized
    times ref_u).

    A sample takes the time of the first instant it is paired with; the samples that share it
    are spread evenly up to the next instant; the last group ends at 1."""
    pi, pj = path
    m = int(pj[-1]) + 1
    inst = pi[np.searchsorted(pj, np.arange(m), side="left")]  # first instants, nondecreasing
    new = np.r_[True, inst[1:] != inst[:-1]]
    start = np.flatnonzero(new)
    count = np.diff(np.r_[start, m])
    group = np.cumsum(new) - 1
    rank = np.arange(m) - start[group]
    n_ref = ref_u.size
    nxt = ref_u[np.minimum(inst + 1, n_ref - 1)]
    w: Float = ref_u[inst] + rank / count[group] * (nxt - ref_u[inst])
    # The last group ends at 1: from its instant (or, when that is the last instant, from the
    # sample before it) to 1, the last sample at 1.
    s, c = int(start[-1]), int(count[-1])
    if c == 1:
        w[-1] = 1.0
    elif inst[-1] < n_ref - 1:
        w[s:] = ref_u[inst[-1]] + np.arange(c) / (c - 1) * (1.0 - ref_u[inst[-1]])
    else:
        tau = float(w[s - 1]) if s > 0 else 0.0
        w[s:] = tau + np.arange(1, c + 1) / c * (1.0 - tau)
    w[0] = 0.0
    return w


def alignment_spreads(
    demos: Sequence[Demonstration],
    aligned: Sequence[Demonstration],
    robot: KinematicModel | None = None,
) -> tuple[float, float]:
    """How much aligning helped: the demonstrations' spread in linear time and in warped time.

    The spread is the mean over MEDOID_POINTS uniform normalized times and over the normalized
    features (those :func:`align` pairs on) of their variance across the demonstrations: 1 is
    as spread as the features are over the whole motion, 0 all alike at every moment.

    Parameters
    ----------
    demos : sequence of Demonstration
        As recorded.
    aligned : sequence of Demonstration
        The same, aligned (:func:`align`): only their ``t`` differs.
    robot : KinematicModel, optional
        As given to :func:`align`.

    Returns
    -------
    linear, warped : float
    """
    items = check_demonstrations(demos)
    features = _demo_features(items, robot)
    grid = np.linspace(0.0, 1.0, MEDOID_POINTS)

    def spread(times: Sequence[Float]) -> float:
        at = np.stack(
            [_resampled(x, _normalized(t), grid) for x, t in zip(features, times, strict=True)]
        )
        return float(at.var(axis=0).mean())

    return spread([d.t for d in items]), spread([d.t for d in aligned])
