"""TrackFilter: the positions a running controller may trust from a stream of stereo tracks."""

from __future__ import annotations

import numpy as np
import pytest

from pbdkit.vision import TrackFilter
from pbdkit.vision._blobs import Blob
from pbdkit.vision._stereo import Track

RATE = 15.0


def _track(name: str, pos: np.ndarray | None, area: tuple[int, int] = (400, 380)) -> Track:
    def blob(a: int) -> Blob:
        if pos is None:
            return Blob("not_visible", None, 0, 0, (0, 0, 0, 0))
        return Blob("ok", np.array([100.0, 80.0]), a, 0, (90, 70, 20, 20))

    if pos is None:
        return Track(name, "not_visible_a", None, None, blob(0), blob(area[1]))
    return Track(name, "ok", np.asarray(pos, dtype=float), 0.5, blob(area[0]), blob(area[1]))


def test_a_slow_move_is_followed_and_an_occlusion_a_jump_and_a_grasp_are_held() -> None:
    rng = np.random.default_rng(3)
    f = TrackFilter(["glass", "coaster"])
    glass = np.array([0.47, 0.18, 0.175])
    coaster = np.array([0.48, -0.17, 0.006])
    n = 60
    for i in range(n):
        t = i / RATE
        # The coaster slides 5 cm over 1 s (from frame 10), tracked with 1 mm noise.
        slide = np.clip((t - 10 / RATE) / 1.0, 0.0, 1.0) * np.array([0.05, 0.0, 0.0])
        tracks = {
            "glass": _track("glass", glass + rng.normal(0, 1e-3, 3)),
            "coaster": _track("coaster", coaster + slide + rng.normal(0, 1e-3, 3)),
        }
        if 30 <= i < 35:  # the arm hides half of the coaster's patch in camera b: biased 2 cm
            tracks["coaster"] = _track("coaster", coaster + slide + 0.02, area=(400, 150))
        if i == 40:  # one frame 4 cm off with a full blob (a reflection): a jump
            tracks["coaster"] = _track("coaster", coaster + slide + np.array([0, 0.04, 0]))
        if 42 <= i < 45:  # the coaster leaves camera a's view altogether
            tracks["coaster"] = _track("coaster", None)
        held = ("glass",) if i >= 20 else ()
        accepted = f.update(t, tracks, held=held)
        if i >= 20:
            assert "glass" not in accepted
        if 30 <= i < 35 or i == 40 or 42 <= i < 45:
            assert "coaster" not in accepted
        else:
            assert "coaster" in accepted
    # The estimates: the glass where it was before the grasp, the coaster where it slid to.
    assert np.linalg.norm(f.estimates["glass"] - glass) < 4e-3
    assert np.linalg.norm(f.estimates["coaster"] - (coaster + np.array([0.05, 0.0, 0.0]))) < 4e-3
    frames = f.as_dict()["frames"]
    assert frames["glass"] == {"ok": 20, "held": 40}
    assert frames["coaster"] == {"ok": n - 9, "occluded": 5, "jump": 1, "not_visible_a": 3}
    # Events are status changes, in order, with the reason.
    coaster_events = [(round(e.time * RATE), e.status) for e in f.events if e.name == "coaster"]
    assert coaster_events == [
        (0, "ok"),
        (30, "occluded"),
        (35, "ok"),
        (40, "jump"),
        (41, "ok"),
        (42, "not_visible_a"),
        (45, "ok"),
    ]
    jump = next(e for e in f.events if e.status == "jump")
    assert float(jump.detail.split(" mm")[0]) == pytest.approx(40.0, abs=5.0)
    assert f.status == {"glass": "held", "coaster": "ok"}


def test_after_a_long_hold_a_moved_object_is_accepted() -> None:
    # Hidden for 2 s while it moved 10 cm: the allowance grows with the time since the last
    # good frame (0.25 m/s), so the new place is accepted when it reappears.
    f = TrackFilter(["coaster"])
    p = np.array([0.48, -0.17, 0.006])
    f.update(0.0, {"coaster": _track("coaster", p)})
    for i in range(1, 30):
        f.update(i / RATE, {"coaster": _track("coaster", None)})
    moved = p + np.array([0.1, 0.0, 0.0])
    assert "coaster" in f.update(2.0, {"coaster": _track("coaster", moved)})
    np.testing.assert_allclose(f.estimates["coaster"], moved)
    # A missing object counts as such.
    assert f.update(2.1, {}) == {}
    assert f.status["coaster"] == "missing"


def test_track_filter_bad_input() -> None:
    with pytest.raises(ValueError, match="distinct object names"):
        TrackFilter([])
    with pytest.raises(ValueError, match="distinct object names"):
        TrackFilter(["glass", "glass"])
    with pytest.raises(ValueError, match="max_speed"):
        TrackFilter(["glass"], max_speed=0.0)
    with pytest.raises(ValueError, match="min_area_ratio must be < 1"):
        TrackFilter(["glass"], min_area_ratio=1.5)
