"""Poses from two patches (pbdkit.vision._pose): the model, the tracker's poses, the filter.

Synthetic scenes as in ``test_vision.py``: a stereo pair 0.4 m apart looking at a table-top
region, colored discs lying flat at the two ends of an object.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from numpy.typing import NDArray
from test_vision import COLORS, TARGET, calibrated_models, stereo_pair

from pbdkit.vision import PoseModel, PoseTrack, StereoTracker, TrackFilter
from pbdkit.vision._blobs import Blob
from pbdkit.vision._pose import yaw_matrix
from pbdkit.vision._stereo import Track
from pbdkit.vision._synthetic import Disc, render_discs

Float = NDArray[np.float64]

HALF = 0.04  # m, the ends' distance from the object's point along its x axis


def pose(p: Float, yaw: float) -> Float:
    out = np.eye(4)
    out[:3, :3] = yaw_matrix(yaw)
    out[:3, 3] = p
    return out


def ends(p: Float, yaw: float, side: Float | None = None) -> tuple[Float, Float]:
    """End points of an object at ``p`` turned by ``yaw`` whose ends sit at x = -+HALF, offset by
    ``side`` (object frame, default none) from its point."""
    rot = yaw_matrix(yaw)
    side = np.zeros(3) if side is None else side
    return p + rot @ (np.array([-HALF, 0.0, 0.0]) + side), p + rot @ (
        np.array([HALF, 0.0, 0.0]) + side
    )


def test_pose_model_object_frame_offset_turns_with_the_object() -> None:
    side = np.array([0.0, 0.02, -0.003])  # the point is 20 mm off the ends' line
    p0 = np.array([0.1, 0.2, 0.03])
    truth0 = pose(p0, 0.3)
    local = PoseModel.calibrate(("a", "b"), *ends(p0, 0.3, side), truth0)
    world = PoseModel.calibrate(("a", "b"), *ends(p0, 0.3, side), truth0, frame="world")
    np.testing.assert_allclose(local.offset, -side, atol=1e-12)
    assert local.yaw_offset == pytest.approx(0.0, abs=1e-12)
    assert local.span == pytest.approx(2 * HALF)
    for yaw in (-1.0, -0.4, 0.3, 0.9):
        p = np.array([0.05, -0.1, 0.03])
        got = local.pose(*ends(p, yaw, side))
        np.testing.assert_allclose(got, pose(p, yaw), atol=1e-12)
        # A world offset is off by 2 |offset_xy| sin(delta / 2), delta the turn since.
        bad = world.pose(*ends(p, yaw, side))
        err = float(np.linalg.norm(bad[:3, 3] - p))
        assert err == pytest.approx(2 * 0.02 * abs(math.sin((yaw - 0.3) / 2)), abs=1e-12)


def test_pose_model_yaw_offset_and_averaged_views() -> None:
    # Ends along the object's y axis: its yaw is the ends' heading minus 90 degrees.
    rng = np.random.default_rng(0)
    rows = []
    for yaw in np.linspace(-1.0, 1.0, 5):
        p = rng.uniform(-0.1, 0.1, 3)
        rot = yaw_matrix(yaw)
        a = p + rot @ [0.0, -HALF, 0.0] + rng.normal(0.0, 1e-4, 3)
        b = p + rot @ [0.0, HALF, 0.0] + rng.normal(0.0, 1e-4, 3)
        rows.append((a, b, pose(p, yaw)))
    model = PoseModel.calibrate(("a", "b"), *(np.array([r[i] for r in rows]) for i in range(3)))
    assert math.degrees(model.yaw_offset) == pytest.approx(-90.0, abs=0.5)
    assert np.linalg.norm(model.offset) < 2e-4  # the views' noise averages out
    p = np.array([0.0, 0.0, 0.02])
    got = model.pose(p + yaw_matrix(2.0) @ [0, -HALF, 0], p + yaw_matrix(2.0) @ [0, HALF, 0])
    yaw = math.atan2(got[1, 0], got[0, 0])
    assert math.degrees(yaw) == pytest.approx(math.degrees(2.0), abs=0.5)
    # Plain data round trip.
    again = PoseModel.from_dict(json.loads(json.dumps(model.as_dict())))
    assert again.as_dict() == model.as_dict()


def test_pose_model_errors() -> None:
    with pytest.raises(ValueError, match="two different patch names"):
        PoseModel(("a", "a"))
    with pytest.raises(ValueError, match="frame"):
        PoseModel(("a", "b"), frame="camera")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="span"):
        PoseModel(("a", "b"), span=-1.0)
    with pytest.raises(ValueError, match="same number of views"):
        PoseModel.calibrate(("a", "b"), np.zeros((2, 3)), np.ones((2, 3)), np.eye(4))


def _blob(ok: bool, area: int = 300) -> Blob:
    if not ok:
        return Blob("not_visible", None, 0, 0, (0, 0, 0, 0))
    return Blob("ok", np.array([100.0, 80.0]), area, 0, (90, 70, 20, 20))


def _end(name: str, pos: Float | None, areas: tuple[int, int] = (300, 280)) -> Track:
    if pos is None:
        return Track(name, "not_visible_ab", None, None, _blob(False), _blob(False))
    return Track(name, "ok", pos, 0.3, _blob(True, areas[0]), _blob(True, areas[1]))


def test_pose_track_refuses_a_missing_end_and_a_wrong_span() -> None:
    p = np.array([0.1, 0.0, 0.02])
    a, b = ends(p, 0.5)
    model = PoseModel(("obj:a", "obj:b"), span=2 * HALF, max_span_error=0.005)
    ok = model.track("obj", _end("obj:a", a), _end("obj:b", b))
    assert ok.ok and ok.failed_end is None
    np.testing.assert_allclose(ok.pose, pose(p, 0.5), atol=1e-12)
    assert ok.yaw == pytest.approx(0.5)
    hidden = model.track("obj", _end("obj:a", a), _end("obj:b", None))
    assert not hidden.ok and hidden.pose is None and hidden.position is None
    assert hidden.status == "not_visible_ab" and hidden.failed_end == "b"
    assert "end b (obj:b)" in hidden.describe()
    # An end 10 mm further out than calibrated: one blob is not that end.
    far = model.track("obj", _end("obj:a", a), _end("obj:b", b + yaw_matrix(0.5) @ [0.01, 0, 0]))
    assert far.status == "inconsistent" and far.span is not None


def _disc_scene(rng: np.random.Generator, p: Float, yaw: float) -> tuple[list[Disc], Float]:
    a, b = ends(p, yaw)
    up = (0.0, 0.0, 1.0)
    lone = TARGET + np.array([0.0, 0.1, 0.0])
    discs = [
        Disc(a, up, 0.015, COLORS["red"]),
        Disc(b, up, 0.015, COLORS["blue"]),
        Disc(lone, up, 0.015, COLORS["green"]),
    ]
    return discs, lone


def test_tracker_gives_a_pose_from_two_discs() -> None:
    rng = np.random.default_rng(4)
    cams = stereo_pair()
    models = calibrated_models(rng, cams[0])
    poses = {"obj": PoseModel(("red", "blue"), span=2 * HALF)}
    tracker = StereoTracker(*cams, models, poses=poses)
    assert tracker.objects == ("obj", "green")
    yaw_err, pos_err = [], []
    for yaw in (-1.0, -0.5, 0.0, 0.5, 1.0):
        p = TARGET + np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.06, 0.0), 0.0])
        discs, lone = _disc_scene(rng, p, yaw)
        img_a, _ = render_discs(cams[0], discs, rng, brightness=rng.uniform(-30.0, 30.0))
        img_b, _ = render_discs(cams[1], discs, rng, brightness=rng.uniform(-30.0, 30.0))
        tracks = tracker.track_objects(img_a, img_b)
        assert list(tracks) == ["obj", "green"]
        obj, green = tracks["obj"], tracks["green"]
        assert isinstance(obj, PoseTrack) and isinstance(green, Track)
        assert obj.ok and green.ok and obj.pose is not None and obj.yaw is not None
        pos_err.append(np.linalg.norm(obj.pose[:3, 3] - p))
        yaw_err.append(abs(math.degrees(math.remainder(obj.yaw - yaw, 2 * math.pi))))
        assert green.position is not None
        assert np.linalg.norm(green.position - lone) < 3e-3
        # The patches' own tracks are what track() gives.
        assert set(tracker.track(img_a, img_b)) == {"red", "green", "blue"}
    assert max(pos_err) < 3e-3 and max(yaw_err) < 3.0
    # Without poses, track_objects is track.
    plain = StereoTracker(*cams, models)
    assert plain.objects == tuple(models)
    data = tracker.as_dict()
    assert "poses" in data and "poses" not in plain.as_dict()
    again = StereoTracker.from_dict(json.loads(json.dumps(data)))
    assert again.objects == tracker.objects
    assert again.poses["obj"].ends == ("red", "blue")


def test_tracker_pose_arguments_are_checked() -> None:
    cams = stereo_pair()
    models = calibrated_models(np.random.default_rng(1), cams[0], n_frames=1)
    with pytest.raises(ValueError, match="not a color model"):
        StereoTracker(*cams, models, poses={"obj": PoseModel(("red", "pink"))})
    with pytest.raises(ValueError, match="name of a color model"):
        StereoTracker(*cams, models, poses={"red": PoseModel(("green", "blue"))})
    with pytest.raises(ValueError, match="already an end"):
        StereoTracker(
            *cams,
            models,
            poses={"x": PoseModel(("red", "blue")), "y": PoseModel(("blue", "green"))},
        )


def _pose_track(
    p: Float, yaw: float, areas: tuple[int, int] = (300, 280), hide_b: bool = False
) -> PoseTrack:
    a, b = ends(p, yaw)
    model = PoseModel(("obj:a", "obj:b"))
    return model.track("obj", _end("obj:a", a, areas), _end("obj:b", None if hide_b else b, areas))


def test_filter_holds_poses_like_positions() -> None:
    f = TrackFilter(["obj"])
    p = np.array([0.15, -0.12, 0.02])
    got = f.update(0.0, {"obj": _pose_track(p, 0.2)})
    assert got["obj"].shape == (4, 4) and f.status["obj"] == "ok"
    np.testing.assert_allclose(got["obj"], pose(p, 0.2), atol=1e-12)
    # A slow turn is followed.
    got = f.update(0.1, {"obj": _pose_track(p, 0.25)})
    assert math.atan2(got["obj"][1, 0], got["obj"][0, 0]) == pytest.approx(0.25)
    # A turned mark's blob changes a little (0.93 of its first area): still the object.
    assert "obj" in f.update(0.15, {"obj": _pose_track(p, 0.25, areas=(280, 262))})
    # One end hidden: no pose, the last one holds.
    assert f.update(0.2, {"obj": _pose_track(p, 0.25, hide_b=True)}) == {}
    assert f.status["obj"] == "not_visible_ab"
    np.testing.assert_allclose(f.estimates["obj"], pose(p, 0.25), atol=1e-12)
    # One end's blob shrunk (partly hidden): occluded.
    assert f.update(0.3, {"obj": _pose_track(p, 0.25, areas=(150, 280))}) == {}
    assert f.status["obj"] == "occluded"
    # A turn faster than max_turn_rate: a jump.
    assert f.update(0.35, {"obj": _pose_track(p, 1.5)}) == {}
    assert f.status["obj"] == "jump" and "turned" in f.events[-1].detail
    # Held: refused whatever the cameras say.
    assert f.update(0.4, {"obj": _pose_track(p, 0.25)}, held=["obj"]) == {}
    assert f.status["obj"] == "held"
    moved = p + np.array([0.01, 0.0, 0.0])
    got = f.update(0.5, {"obj": _pose_track(moved, 0.3)})
    np.testing.assert_allclose(got["obj"][:3, 3], moved, atol=1e-12)
