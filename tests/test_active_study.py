"""Teaching where it fails, in simulation (issue 39, item 5): the teachers of
``pbdkit study --active`` and the comparison's record."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pbdkit.apps._study_active import (
    ActiveSize,
    _features,
    _median_needed,
    _Teacher,
    needed,
    run_active,
    split_grid,
)
from pbdkit.sim import get_task
from pbdkit.sim._active import spread_placements, wide_ranges


def test_needed_is_the_first_size_at_the_target_and_its_median_over_seeds() -> None:
    n = [2, 3, 4, 5]
    assert needed([0.5, 0.96, 0.9, 1.0], n) == 3
    assert needed([0.5, 0.6, 0.9, 0.94], n) is None
    assert _median_needed([3, 4, 5]) == 4.0
    assert _median_needed([3, None, None]) is None  # most seeds never reach it
    assert _median_needed([3, 5, None]) == 5.0


def test_the_grid_keeps_where_the_spread_skill_works_and_lists_the_rest() -> None:
    grid = [{"glass": np.array([float(i), 0.0, 0.1])} for i in range(5)]
    kept, excluded = split_grid(grid, [True, False, True, True, False])
    assert [p["glass"][0] for p in kept] == [0.0, 2.0, 3.0]
    assert excluded == [{"glass": [1.0, 0.0, 0.1]}, {"glass": [4.0, 0.0, 0.1]}]


def test_the_wide_ranges_are_twice_the_demonstrated_half_width_on_each_side() -> None:
    for task in ("coaster", "slot"):
        spec = get_task(task)
        wide = wide_ranges(spec)
        assert set(wide) == set(spec.tracked_objects)
        for k, r in wide.items():
            d = spec.ranges[k]
            np.testing.assert_allclose(r.high - r.low, 2 * (d.high - d.low))
            np.testing.assert_allclose(r.low + r.high, d.low + d.high)
            if d.yaw is not None:
                assert r.yaw is not None
                assert r.yaw[1] - r.yaw[0] == pytest.approx(2 * (d.yaw[1] - d.yaw[0]))


def test_the_random_teacher_stays_in_the_ranges_and_the_filling_one_goes_farthest() -> None:
    spec = get_task("coaster")
    wide = wide_ranges(spec)
    teacher = _Teacher("random", spec, seed=4)
    for objects in teacher.choices(None, []):
        for k, r in wide.items():
            assert np.all(objects[k] >= r.low - 1e-12) and np.all(objects[k] <= r.high + 1e-12)
    done = spread_placements(spec, 3, seed=9)
    filling = _Teacher("space_filling", spec, seed=4)
    best = filling.choices(None, done)[0]
    # Brute force over the same candidates: the one whose nearest demonstration is farthest,
    # each axis scaled by its range.
    have = np.array([_features(spec, d, wide) for d in done])
    cands = spread_placements(spec, 256, 4 + len(done))
    gaps = [np.min(np.linalg.norm(have - _features(spec, c, wide), axis=1)) for c in cands]
    expected = cands[int(np.argmax(gaps))]
    for k in wide:
        np.testing.assert_array_equal(best[k], expected[k])


def _reach_of_demonstrations(ts, places, controllers, conditions, client=None):  # type: ignore[no-untyped-def]
    """A stand-in for the trials' physics (3.3 s a basin trial; the real ones are the study's
    and evaluate's tests): a placement succeeds where every moving object lies within
    REACHED of its place in one demonstration the skill learned from. It records what it
    was asked."""
    del controllers, conditions, client
    shown = ts.skill.demonstrations_
    assert shown is not None
    out = []
    for p in places:
        gaps = [
            max(
                float(np.linalg.norm(_xy(p[k]) - _xy(d.objects[k])))
                for k in ts.task.tracked_objects
            )
            for d in shown
        ]
        out.append(SimpleNamespace(runs={"fused": {"success": min(gaps) <= REACHED}}))
    ASKED.append((len(shown), len(places), [bool(o.runs["fused"]["success"]) for o in out]))
    return out


def _xy(value: object) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    return a[:2, 3] if a.shape == (4, 4) else a[:2]


REACHED = 0.06
ASKED: list[tuple[int, int, list[bool]]] = []


@pytest.mark.slow
def test_the_active_comparison_records_every_teachers_curve(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The smallest comparison (the basin: one moving object, a 2 x 2 grid, one seed, one more
    # demonstration per teacher): the record's shape and consistency, not its figures. The real
    # teacher, skills and updates; the trials' physics stood in for (the CI budget: 73 s with
    # it), and 4 spread demonstrations for the 20 that find the points no teacher fixes.
    import pbdkit.apps._study_active as study_active

    monkeypatch.setattr(study_active, "run_trials", _reach_of_demonstrations)
    monkeypatch.setattr(study_active, "SPREAD_DEMOS", 4)
    ASKED.clear()
    spec = get_task("basin")
    size = ActiveSize(grid=2, seeds=1, max_demos=3)
    active = run_active(spec, size=size, seed=0)
    # The spread skill (the placements the teacher could show of 4), the start, then each
    # teacher's skill of 3, on the kept points.
    assert 2 <= ASKED[0][0] <= 4 and [n for n, _, _ in ASKED[1:]] == [2, 3, 3, 3]
    assert ASKED[0][1] == 4 and all(m == 4 - len(active["excluded"]) for _, m, _ in ASKED[1:])
    assert len(active["excluded"]) == ASKED[0][2].count(False)
    for (_, _, ok), kind in zip(ASKED[2:], ("suggested", "random", "space_filling"), strict=True):
        assert active["per_seed"]["0"][kind][1] == pytest.approx(np.mean(ok))
    assert active["n_demos"] == [2, 3]
    assert active["grid_points"] == 4
    for kind in ("suggested", "random", "space_filling"):
        curve = active["per_seed"]["0"][kind]
        assert len(curve) == 2 and all(0.0 <= v <= 1.0 for v in curve)
        assert active[kind] == curve  # one seed: its own median
        assert active["needed"][kind] == needed(curve, [2, 3])
    firsts = {active["per_seed"]["0"][k][0] for k in ("suggested", "random", "space_filling")}
    assert len(firsts) == 1  # the same 2 demonstrations to start from
    kept = 4 - len(active["excluded"])
    assert kept > 0
    for v in active["suggested"]:
        assert round(v * kept) == pytest.approx(v * kept)  # a share of the kept points


def test_seeds_go_with_active(tmp_path: object) -> None:
    from typer.testing import CliRunner

    from pbdkit.apps._cli import app

    out = f"{tmp_path}/study"
    result = CliRunner().invoke(app, ["study", "--task", "basin", "--seeds", "2", "--out", out])
    assert result.exit_code == 2 and "--seeds goes with --active" in result.output
    bad = CliRunner().invoke(app, ["study", "--active", "--seeds", "0", "--out", out])
    assert bad.exit_code == 2 and "--seeds" in bad.output
