"""The time segments EM starts from when equal counts leave the score falling at the cap."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import numpy as np
import pytest

import pbdkit.prob._gmm as gmm_module
from pbdkit import Skill
from pbdkit.prob import SelectionWarning
from pbdkit.prob._em import _time_bins_resp
from pbdkit.prob._segments import TimeSegments
from pbdkit.robots import katana


def _brute_force(x: np.ndarray, bins: list[np.ndarray], k: int) -> tuple[float, tuple[int, ...]]:
    """Every way of cutting the bins into k consecutive segments; the least sum of squares of
    the samples, each at its bin's mean, about their segment's mean."""
    z = x[:, 1:] / x[:, 1:].std(axis=0)
    at_bin_mean = np.empty_like(z)
    for b in bins:
        at_bin_mean[b] = z[b].mean(axis=0)

    def cost(rows: np.ndarray) -> float:
        r = at_bin_mean[rows]
        return float(np.square(r - r.mean(axis=0)).sum())

    n = len(bins)
    return min(
        (
            sum(cost(np.concatenate(bins[a:b])) for a, b in itertools.pairwise([0, *cuts, n])),
            cuts,
        )
        for cuts in itertools.combinations(range(1, n), k - 1)
    )


def test_the_segments_are_the_least_squares_cut_found_by_trying_every_cut() -> None:
    rng = np.random.default_rng(0)
    t = np.repeat(np.linspace(0.0, 1.0, 30), 2)
    path = np.where(t < 0.3, 0.0, np.where(t < 0.6, t, 1.0))
    x = np.column_stack([t, path + 0.01 * rng.standard_normal(60), 0.01 * rng.standard_normal(60)])
    segments = TimeSegments(x, time_dim=0, bins=12)
    assert segments.n_bins == 12
    for k in range(1, 6):
        cost, cuts = _brute_force(x, segments._bins, k)
        assert segments.edges(k) == [0, *cuts, 12]
        resp = segments.resp(k)
        # Hard, one segment per row, every segment used and consecutive in time.
        assert resp.shape == (60, k) and np.all(resp.sum(axis=1) == 1.0)
        label = resp.argmax(axis=1)[np.argsort(t, kind="stable")]
        assert np.all(np.diff(label) >= 0) and set(label) == set(range(k))
        assert segments._best[k - 1][12] == pytest.approx(cost, rel=1e-9)
    with pytest.raises(ValueError, match=r"k must be in \[1, 12\], got 13"):
        segments.resp(13)


def test_a_hold_is_one_segment_where_equal_counts_give_it_many() -> None:
    # Still for 70 % of the time, then a zigzag: equal counts put 5 of 8 components on the
    # hold; the segments one, and the other seven on the motion.
    rng = np.random.default_rng(1)
    t = np.tile(np.linspace(0.0, 1.0, 200), 5)
    knots = ([0.0, 0.7, 0.76, 0.82, 0.88, 0.94, 1.0], [0.0, 0.0, 1.0, -1.0, 1.0, -1.0, 0.0])
    x = np.column_stack([t, np.interp(t, *knots) + 0.01 * rng.standard_normal(t.size)])
    hold = t < 0.69

    def on_the_hold(resp: np.ndarray) -> int:
        return int(np.sum(resp[hold].sum(axis=0) > 0.9 * resp.sum(axis=0)))

    assert on_the_hold(_time_bins_resp(x, 8, 0)) == 5
    assert on_the_hold(TimeSegments(x, 0).resp(8)) == 1


@pytest.mark.slow
def test_a_sweep_still_falling_at_the_cap_runs_again_from_the_segments(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # The paper's coaster task, teach seed 3 (one of the 7 of 60 teach seeds of both tasks
    # where it happens): from equal counts the glass space's score still falls at K = 30; from
    # the segments K = 21 is as good, and nothing warns. With the second sweep also from equal
    # counts, the cap's warning says what to do.
    from pbdkit.sim import teach

    demos = teach("coaster", 5, seed=3)
    robot = katana()
    starts: list[int] = []

    class Counted(TimeSegments):
        def __init__(self, x: np.ndarray, time_dim: int) -> None:
            starts.append(x.shape[0])
            super().__init__(x, time_dim)

    monkeypatch.setattr(gmm_module, "TimeSegments", Counted)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SelectionWarning)
        skill = Skill.learn(demos, robot, task_objects=["glass", "coaster"])
    assert len(starts) == 1
    chosen = {name: s.chosen for name, s in skill.selection_.items()}
    assert chosen["glass"] == 21 and max(chosen.values()) < 30, chosen
    starts_of = {name: s.start for name, s in skill.selection_.items()}
    assert starts_of == {"joint": "equal counts", "glass": "segments", "coaster": "equal counts"}
    skill.save(tmp_path / "skill.npz")
    loaded = Skill.load(tmp_path / "skill.npz")
    assert {name: s.start for name, s in loaded.selection_.items()} == starts_of

    class EqualCounts(TimeSegments):
        def resp(self, k: int) -> np.ndarray:
            return _time_bins_resp(self._x, k, 0)

        def __init__(self, x: np.ndarray, time_dim: int) -> None:
            self._x = x
            super().__init__(x, time_dim)

    monkeypatch.setattr(gmm_module, "TimeSegments", EqualCounts)
    with pytest.warns(SelectionWarning, match="K is at the cap, max_components=30") as record:
        capped = Skill.learn(demos, robot, task_objects=["glass", "coaster"])
    assert len(record) == 1 and "space 'glass'" in str(record[0].message)
    assert capped.selection_["glass"].chosen == 30
