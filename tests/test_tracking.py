"""The stereo tracker in the simulated world (pbdkit.sim._tracking) and vision in the loop of
``pbdkit demo`` / ``pbdkit evaluate``."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("mujoco")

from pbdkit.apps._cli import app
from pbdkit.robots import katana
from pbdkit.sim import Simulation, get_task, nominal_objects, sample_objects
from pbdkit.sim import _evaluation as evaluation
from pbdkit.sim import _task_skill as task_skill
from pbdkit.sim._evaluation import evaluate
from pbdkit.sim._sensing import observe
from pbdkit.sim._task_skill import TaskSkill
from pbdkit.sim._teacher import random_start_posture
from pbdkit.sim._tracking import (
    ObjectNotSeenError,
    SimTracker,
    label_patches,
    observed_objects,
    patch_geom_ids,
)
from pbdkit.vision import StereoTracker

# Measured by benchmarks/bench_tracking.py over 100 placements per task: largest corrected error
# 2.4 mm (mean 0.5-1.0 mm); the bound leaves margin for other renderers.
MAX_ERROR_MM = 4.0


def _arm(seed: int) -> np.ndarray:
    """A start posture of the teacher (hand raised, out of the cameras' way)."""
    return random_start_posture(katana(), np.random.default_rng(seed))


@pytest.fixture(scope="module")
def coaster_tracker() -> SimTracker:
    with Simulation.from_task(get_task("coaster"), nominal_objects("coaster")) as sim:
        return SimTracker.from_simulation(sim, at_nominal=False, arm=_arm(0))


def test_segmentation_labels_calibrate_both_objects() -> None:
    with Simulation.from_task(get_task("coaster"), nominal_objects("coaster")) as sim:
        sim.set_joints(_arm(0))
        for camera in sim.info.cameras:
            masks = label_patches(sim, camera, ["glass", "coaster"])
            image = sim.render(camera)
            assert set(masks) == {"glass", "coaster"}
            for name, mask in masks.items():
                assert mask.shape == (240, 320) and mask.dtype == np.bool_
                assert mask.sum() > 100, (camera, name)
            assert not np.any(masks["glass"] & masks["coaster"])
            # The labels are the patches' colors: red band, blue coaster.
            red, blue = image[masks["glass"]].mean(axis=0), image[masks["coaster"]].mean(axis=0)
            assert red[0] > 2 * max(red[1], red[2])
            assert blue[2] > 2 * max(blue[0], blue[1])
        tracker = SimTracker.from_simulation(sim, at_nominal=False)
    models = tracker.tracker.models
    assert set(models) == {"glass", "coaster"}
    # Cr (red) high for the glass's band, Cb (blue) high for the coaster.
    assert models["glass"].mean[1] > 150 > models["glass"].mean[0]
    assert models["coaster"].mean[0] > 180 > models["coaster"].mean[1]
    assert tracker.calibration is not None
    assert all(min(n) > 100 for n in tracker.calibration.pixels.values())
    # The cameras come from the simulator, not from constants.
    for cam, name in ((tracker.tracker.cam_a, "cam_left"), (tracker.tracker.cam_b, "cam_right")):
        K, R, t, _, _ = sim.camera_parameters(name)
        np.testing.assert_allclose(cam.K, K, rtol=0, atol=1e-12)
        np.testing.assert_allclose(cam.R, R, rtol=0, atol=1e-12)
        np.testing.assert_allclose(cam.t, t, rtol=0, atol=1e-12)


def test_tracked_positions_match_the_truth(coaster_tracker: SimTracker) -> None:
    rng = np.random.default_rng(7)
    for _ in range(4):
        with Simulation.from_task(get_task("coaster"), sample_objects("coaster", rng)) as sim:
            sim.set_joints(random_start_posture(katana(), rng))
            truth = sim.object_positions()
            tracks = coaster_tracker.locate(sim)
        assert list(tracks) == ["glass", "coaster"]
        for name, track in tracks.items():
            assert track.ok and track.position is not None, track.status
            err_mm = 1e3 * np.linalg.norm(track.position - truth[name])
            assert err_mm < MAX_ERROR_MM, (name, err_mm)


def test_offset_removes_the_visible_patch_bias(coaster_tracker: SimTracker) -> None:
    # The cameras see the front half of the band: its centroid triangulates ~12 mm below the
    # glass's axis point; the calibrated offset holds that bias.
    offsets = coaster_tracker.offsets
    assert 9.0 < 1e3 * offsets["glass"][2] < 15.0
    assert np.all(np.abs(1e3 * offsets["glass"][:2]) < 3.0)
    assert 1e3 * np.linalg.norm(offsets["coaster"]) < 8.0
    calib = coaster_tracker.calibration
    assert calib is not None
    for name, raw in calib.raw_positions.items():
        np.testing.assert_allclose(raw + offsets[name], calib.placement[name], atol=1e-12)


def _glass_seen_by_left_only(sim: Simulation, tracker: SimTracker) -> np.ndarray:
    """A glass bottom position on the table whose band only the left camera sees."""
    cam_a, cam_b = tracker.tracker.cam_a, tracker.tracker.cam_b
    band = 0.075
    for x in np.linspace(0.0, 1.0, 51):
        for y in np.linspace(-0.8, 0.8, 81):
            p = np.array([[x, y, band]])
            ua, ub = cam_a.project(p)[0], cam_b.project(p)[0]
            inside_a = 30 < ua[0] < 290 and 30 < ua[1] < 210
            outside_b = not (-40 < ub[0] < 360 and -40 < ub[1] < 280)
            if inside_a and outside_b:
                return np.array([x, y, 0.0])
    raise AssertionError("no position seen by the left camera only")


def test_object_out_of_one_view_is_refused_not_guessed(coaster_tracker: SimTracker) -> None:
    with Simulation.from_task(get_task("coaster"), nominal_objects("coaster")) as sim:
        sim.set_joints(_arm(0))
        bottom = _glass_seen_by_left_only(sim, coaster_tracker)
        adr = sim.model.jnt_qposadr[sim.model.joint("glass_free").id]
        sim.data.qpos[adr : adr + 7] = [*bottom, 1.0, 0.0, 0.0, 0.0]
        sim.refresh()
        tracks = coaster_tracker.locate(sim)
        assert tracks["glass"].status == "not_visible_b"
        assert tracks["glass"].position is None
        assert tracks["glass"].blob_a.ok  # the left camera does see it
        assert tracks["coaster"].ok
        with pytest.raises(ObjectNotSeenError, match="glass: not_visible_b") as info:
            observed_objects(sim, coaster_tracker)
    assert info.value.missing == ["glass"]
    assert set(info.value.tracks) == {"glass", "coaster"}


def test_observed_objects_passes_fixed_objects_through() -> None:
    assert get_task("basin").tracked_objects == ("glass",)
    assert get_task("coaster").tracked_objects == ("glass", "coaster")
    rng = np.random.default_rng(3)
    truth = sample_objects("basin", rng)
    with Simulation.from_task(get_task("basin"), truth) as sim:
        sim.set_joints(_arm(1))
        tracker = SimTracker.from_simulation(sim, arm=_arm(1))
        seen = observed_objects(sim, tracker, fixed={"basin": truth["basin"]})
        assert list(seen) == ["glass", "basin"]
        np.testing.assert_array_equal(seen["basin"], truth["basin"])
        assert 1e3 * np.linalg.norm(seen["glass"] - truth["glass"]) < MAX_ERROR_MM
        with pytest.raises(ValueError, match=r"fixed\['glass'\]"):
            observed_objects(sim, tracker, fixed={"glass": truth["glass"]})
        with pytest.raises(ValueError, match=r"fixed\['basin'\] must be finite"):
            observed_objects(sim, tracker, fixed={"basin": [0.0, np.nan, 0.0]})
    # The experiment's observe(): given the glass only, the scene still has the basin at its
    # fixed place and the robot knows it (a skill without a basin constraint ignores it).
    told = observe(get_task("basin"), {"glass": truth["glass"]}, tracker, arm=_arm(1))
    assert list(told) == ["glass", "basin"]
    np.testing.assert_array_equal(told["basin"], truth["basin"])
    np.testing.assert_allclose(told["glass"], seen["glass"], rtol=0, atol=1e-12)


def test_bad_objects_are_named() -> None:
    with Simulation.from_task(get_task("basin")) as sim:
        with pytest.raises(ValueError, match=r"\['coaster'\] are not objects of the 'basin'"):
            SimTracker.from_simulation(sim, ["coaster"])
        with pytest.raises(ValueError, match="no colored patch is known for 'basin'"):
            patch_geom_ids(sim, "basin")
        with pytest.raises(ValueError, match=r"arm must have shape \(5,\)"):
            SimTracker.from_simulation(sim, arm=[0.0, 0.0])


@pytest.fixture(scope="module")
def small_skill(small_task_skill: Callable[..., TaskSkill]) -> TaskSkill:
    # A fast teacher (durations halved), 3 demonstrations, a coarse time grid: the CLI paths
    # run in seconds instead of a minute; the full demo is tested in test_demo.py.
    return small_task_skill("coaster", 3, seed=0, n_steps=200, max_components=5)


@pytest.fixture
def fast_cli(monkeypatch: pytest.MonkeyPatch, small_skill: TaskSkill) -> None:
    # Where pbdkit evaluate and pbdkit demo find it.
    monkeypatch.setattr(evaluation, "learn_task", lambda task, **kwargs: small_skill)
    monkeypatch.setattr(task_skill, "learn_task", lambda task, **kwargs: small_skill)


@pytest.mark.slow
def test_evaluate_with_vision_reports_tracking_error(
    fast_cli: None, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    path = tmp_path / "eval.json"
    args = ["evaluate", "--task", "coaster", "--trials", "1", "--seed", "3", "--json", str(path)]
    r = CliRunner().invoke(app, [*args, "--controller", "fused"])
    assert r.exit_code == 0, r.output
    data = json.loads(path.read_text())
    assert data["vision"] is True
    stats = data["tracking_error_mm"]
    assert set(stats) >= {"mean", "std"}
    assert 0.0 < stats["mean"] < MAX_ERROR_MM
    assert stats["n"] == 2  # glass and coaster of one placement
    assert set(stats["per_object"]) == {"glass", "coaster"}
    assert data["tracking_failures"] == 0
    # The skill was told the tracked positions, the world kept the true ones.
    told, truth = data["observed"][0], data["placements"][0]
    for name in ("glass", "coaster"):
        d = 1e3 * np.linalg.norm(np.subtract(told[name], truth[name]))
        assert 0.0 < d < MAX_ERROR_MM

    path_gt = tmp_path / "eval_gt.json"
    r = CliRunner().invoke(
        app,
        ["evaluate", "--trials", "1", "--seed", "3", "--json", str(path_gt), "--ground-truth"],
    )
    assert r.exit_code == 0, r.output
    gt = json.loads(path_gt.read_text())
    assert gt["vision"] is False and gt["tracking_error_mm"] is None
    assert gt["observed"] == gt["placements"]


def test_evaluate_counts_unseen_placements_as_failures(
    coaster_tracker: SimTracker, small_skill: TaskSkill
) -> None:
    # A tracker that refuses every blob: no execution, no ground-truth fallback.
    blind = SimTracker(
        StereoTracker(
            coaster_tracker.tracker.cam_a,
            coaster_tracker.tracker.cam_b,
            coaster_tracker.tracker.models,
            min_area=10**6,
        )
    )
    evaluation = evaluate(
        "coaster", 2, 0, task_skill=small_skill, tracker=blind, controllers=["fused"]
    )
    assert evaluation.tracking_failures == 2
    assert all(t.observed is None for t in evaluation.trials)
    res = evaluation.as_dict()
    assert res["vision"] is True
    assert res["tracking_failures"] == 2
    assert res["tracking_error_mm"] is None
    assert res["observed"] == [None, None]
    assert res["controllers"]["fused"]["success_rate"] == 0.0
    assert res["runs"]["fused"][0]["tracking_status"] == {
        "glass": "not_visible_ab",
        "coaster": "not_visible_ab",
    }


@pytest.mark.slow
@pytest.mark.parametrize("ground_truth", [False, True])
def test_demo_with_and_without_vision(fast_cli: None, tmp_path: Path, ground_truth: bool) -> None:
    args = ["demo", "--task", "coaster", "--out", str(tmp_path), "--seed", "1"]
    r = CliRunner().invoke(app, args + (["--ground-truth"] if ground_truth else []))
    assert r.exit_code == 0, r.output
    m = json.loads((tmp_path / "metrics.json").read_text())
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert 'id="vision"' in html
    assert m["vision"] is not ground_truth
    if ground_truth:
        assert m["tracking"] is None
        assert m["observed_objects"] == m["objects"]
        assert "--ground-truth" in html
    else:
        errors = m["tracking"]["error_mm"]
        assert set(errors) == {"glass", "coaster"}
        assert all(0.0 < e < MAX_ERROR_MM for e in errors.values())
        assert m["tracking"]["tracking_error_mm"]["mean"] == pytest.approx(
            np.mean(list(errors.values()))
        )
        assert "True and tracked positions" in html
        assert "stereo cameras, error" in r.output
