"""Checking a trajectory against a scene and the arm itself (issue 38, item 3): the clearance
against a brute-force computation through pinocchio's own geometry placements, the grasps,
the allowed contacts, and the bad inputs."""

from __future__ import annotations

import itertools
import re
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from pbdkit.collision import Box, CollisionChecker, Cylinder, Scene, Sphere
from pbdkit.collision._checker import CHUNK
from pbdkit.data._demonstration import Demonstration
from pbdkit.datasets import reach_grasp_return
from pbdkit.motion import motion_peaks
from pbdkit.motion._limits import MotionLimits
from pbdkit.reproduction import _avoid as avoid_module
from pbdkit.reproduction._avoid import (
    ACROSS_SIGMA,
    ALONG_MIN,
    SIGMA,
    STEEP,
    TAPER,
    TAPER_DECADES,
    TAPER_MIN,
    TOLERANCE,
    Avoidance,
    _Encounter,
    _meetings,
)
from pbdkit.reproduction._controller import PlanFailedWarning
from pbdkit.reproduction._probabilistic_ik import CollisionWarning
from pbdkit.reproduction._result import ReproductionResult
from pbdkit.robots import katana, panda, urdf_from_dh
from pbdkit.robots._chain import _chain_frames
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill


def _scene() -> Scene:
    return Scene(
        [
            Box((1.3, 1.5, 0.04), (0.25, 0.0, -0.02), name="table"),
            Sphere(0.05, (0.3, 0.0, 0.25), name="ball"),
            Box((0.1, 0.2, 0.3), (0.2, 0.25, 0.15, 0.9238795, 0.0, 0.0, 0.3826834), name="crate"),
            Cylinder(0.03, 0.5, (0.0, -0.3, 0.25), name="post"),
        ]
    )


def _brute_force(
    robot: Robot, scene: Scene, joints: np.ndarray, *, self_pairs: bool = True
) -> np.ndarray:
    """The clearance through pinocchio: geometry placed by pin.updateGeometryPlacements, every
    pair measured (no bound, no culling), the same pairs the checker means (without the arm's
    pairs with itself: the scene clearance)."""
    cm = robot.collision_model
    assert cm is not None
    model, geom = cm.model, cm.geometry.copy()
    n_arm = len(geom.geometryObjects)
    for shape in scene.shapes:
        placement = pin.SE3(shape.pose[:3, :3].copy(), shape.pose[:3, 3].copy())
        geom.addGeometryObject(pin.GeometryObject(str(shape.name), 0, placement, shape.geometry()))
    pairs = [tuple(p) for p in cm.self_pairs] if self_pairs else []
    for a in range(n_arm):
        if geom.geometryObjects[a].parentJoint == 0:
            continue
        pairs += [(a, b) for b in range(n_arm, n_arm + len(scene.shapes))]
    for a, b in pairs:
        geom.addCollisionPair(pin.CollisionPair(a, b))
    data, gdata = model.createData(), pin.GeometryData(geom)
    out = np.empty(joints.shape[0])
    for t, q in enumerate(joints):
        pin.updateGeometryPlacements(model, data, geom, gdata, q)
        pin.computeDistances(geom, gdata)
        out[t] = min(r.min_distance for r in gdata.distanceResults)
    return out


@pytest.mark.parametrize("make", [katana, panda], ids=["katana", "panda"])
def test_the_clearance_is_pinocchios_over_every_pair(make: object) -> None:
    robot = make()  # type: ignore[operator]
    rng = np.random.default_rng(7)
    joints = rng.uniform(robot.lower, robot.upper, (300, robot.n_joints))
    scene = _scene()
    report = CollisionChecker(robot, scene).check(joints)
    expected = _brute_force(robot, scene, joints)
    np.testing.assert_allclose(report.clearance, expected, atol=1e-6)
    # Random postures hit the table, the post or the arm itself: there is something to find.
    colliding = np.flatnonzero(expected < 0.0)
    assert colliding.size > 10
    assert {c[0] for c in report.collisions} == set(colliding.tolist())


@pytest.mark.parametrize("margin", [0.0, 0.05])
def test_the_scene_clearance_is_exact_under_the_margin_and_a_bound_above(margin: float) -> None:
    # Against pinocchio over the scene's pairs alone (the arm's pairs with itself left out):
    # equal where under the margin or where the scene is the nearest, never above elsewhere.
    robot = katana()
    rng = np.random.default_rng(11)
    joints = rng.uniform(robot.lower, robot.upper, (300, robot.n_joints))
    scene = _scene()
    report = CollisionChecker(robot, scene).check(joints, margin=margin)
    both = _brute_force(robot, scene, joints)
    alone = _brute_force(robot, scene, joints, self_pairs=False)
    assert report.scene_clearance is not None
    # GJK's tolerance: coal's cached pair solver and pinocchio's differ by up to ~1e-6 m.
    np.testing.assert_allclose(report.clearance, both, atol=1e-5)
    exact = (alone < margin) | np.isclose(alone, both, atol=1e-9)
    assert exact.sum() > 20 and (~exact).sum() > 20  # both cases are met
    np.testing.assert_allclose(report.scene_clearance[exact], alone[exact], atol=1e-5)
    assert np.all(report.scene_clearance <= alone + 1e-5)


@pytest.mark.parametrize("make", [katana, panda], ids=["katana", "panda"])
def test_a_smooth_path_is_checked_as_pinocchio_checks_every_pair(make: object) -> None:
    # Along a smooth path the check leaves out, stretch by stretch, the pairs whose swept
    # spheres keep them apart (CHUNK postures): the clearance is still every pair's minimum,
    # the scene clearance exact under the margin and a bound above.
    robot = make()  # type: ignore[operator]
    rng = np.random.default_rng(3)
    corners = rng.uniform(robot.lower, robot.upper, (4, robot.n_joints))
    joints = np.concatenate([np.linspace(a, b, 300) for a, b in itertools.pairwise(corners)])
    scene = _scene()
    checker = CollisionChecker(robot, scene)
    report = checker.check(joints, margin=0.03)
    np.testing.assert_allclose(report.clearance, _brute_force(robot, scene, joints), atol=1e-5)
    alone = _brute_force(robot, scene, joints, self_pairs=False)
    assert report.scene_clearance is not None
    under = alone < 0.03
    np.testing.assert_allclose(report.scene_clearance[under], alone[under], atol=1e-5)
    assert np.all(report.scene_clearance <= alone + 1e-5)
    # Pairs were left out: a stretch of CHUNK postures of a smooth path keeps some pairs
    # apart (what the check above did, stretch by stretch).
    stretch = joints[:CHUNK]
    rots, origins = checker._frames(stretch)
    rot, pos = checker._poses(rots, origins, {}, {})
    state = checker._segments(len(stretch), checker.hand_frames(stretch))[0][2]
    pairs = checker._state_pairs(state)
    kept, _ = checker._chunk_pairs(pairs, checker._table.centres(rot, pos), 0.03)
    assert 0 < kept.sum() < len(pairs)


def test_a_collision_names_its_step_and_bodies_sorted() -> None:
    robot = katana()
    q = np.zeros((3, robot.n_joints))
    hand = robot.fk(q[0])
    # A ball at the tool point, 2 cm past the end of the gripper's box: a 3 cm ball reaches in.
    scene = Scene([Sphere(0.03, hand, name="ball")])
    report = CollisionChecker(robot, scene).check(q)
    assert report.collisions == [(t, "ball", "gripper") for t in range(3)]
    assert not report.free and report.min_clearance < 0.0
    far = CollisionChecker(robot, Scene([Sphere(0.02, hand + np.array([0.0, 0.0, 2.0]))])).check(q)
    alone = CollisionChecker(robot, Scene()).check(q)  # the arm against itself
    assert far.free and alone.free
    np.testing.assert_array_equal(far.clearance, alone.clearance)


def test_the_base_on_its_table_is_not_a_collision() -> None:
    robot = katana()
    table = Scene([Box((1.0, 1.0, 0.04), (0.0, 0.0, -0.02), name="table")])
    q = np.zeros((1, robot.n_joints))
    report = CollisionChecker(robot, table).check(q)
    assert report.free, report.collisions


def test_a_grasped_object_moves_with_the_hand_and_may_touch_its_support() -> None:
    robot = katana()
    rng = np.random.default_rng(2)
    start = (robot.lower + robot.upper) / 2
    end = start + rng.uniform(-0.3, 0.3, robot.n_joints)
    joints = np.linspace(start, end, 50)
    glass_at = robot.fk(start)
    # The glass stands on a stand, the hand closes on it at step 10 and opens at step 40.
    scene = Scene(
        [Box((0.1, 0.1, 0.02), glass_at - [0.0, 0.0, 0.06], name="stand")],
        objects={"glass": Cylinder(0.03, 0.1, (0.0, 0.0, 0.0))},
    )
    gripper = np.zeros(50)
    gripper[10:40] = 1.0
    joints[:10] = start  # the hand waits at the glass until it closes
    checker = CollisionChecker(robot, scene, {"glass": glass_at})
    report = checker.check(joints, gripper)
    assert checker.grasps == [("glass", 10, 40)]
    # The hand holds the glass (allowed), the glass rests on the stand at the grasp (allowed).
    assert not any("glass" in c and "gripper" in c for c in report.collisions)
    assert not any(c[1:] == ("glass", "stand") for c in report.collisions)
    # After the release the glass stays where the hand left it: the arm is near it at step 40.
    tips = checker.tip_poses(joints)
    left_at = tips[40, :3, 3]
    assert np.linalg.norm(left_at - glass_at) > 0.02  # it was carried away


def test_a_robot_without_a_collision_model_is_refused() -> None:
    robot = Robot.from_urdf(
        urdf_from_dh([(0.0, 0.0, 0.3, 0.0), (0.2, 0.0, 0.0, 0.0)], lower=[-1, -1], upper=[1, 1])
    )
    with pytest.raises(ValueError, match="has no collision model"):
        CollisionChecker(robot, Scene())


# ----------------------------------------------------------------------------- avoidance
def _mid_carry(res: ReproductionResult) -> np.ndarray:
    """The hand where it moves fastest while it holds the glass."""
    speed = np.linalg.norm(np.diff(res.positions, axis=0), axis=1)
    closed = np.flatnonzero(res.gripper[:-1])
    return np.asarray(res.positions[closed[np.argmax(speed[closed])]])


@pytest.fixture(scope="module")
def plain(skill: Skill, demos: list[Demonstration]) -> tuple[dict[str, np.ndarray], object]:
    objects = {"glass": np.mean([d.objects["glass"] for d in demos], axis=0)}
    return objects, skill.reproduce(objects)


def test_a_box_far_from_the_path_changes_no_joint(skill: Skill, plain: tuple) -> None:
    objects, res = plain
    far = Scene([Box((0.06, 0.06, 0.06), _mid_carry(res) + np.array([0.0, 0.0, 0.6]), name="far")])
    with_scene = skill.reproduce(objects, scene=far)
    assert np.max(np.abs(with_scene.joints - res.joints)) <= 1e-9
    assert with_scene.collisions == [] and with_scene.infeasible is None
    assert with_scene.clearance is not None and with_scene.clearance.shape == res.t.shape
    assert not np.any(with_scene.influence["clearance"])
    assert res.clearance is None and "clearance" not in res.influence


def test_a_box_in_the_carry_is_avoided_within_the_limits(
    skill: Skill, plain: tuple, limits: MotionLimits
) -> None:
    objects, res = plain
    box = Scene([Box((0.06, 0.06, 0.06), _mid_carry(res), name="box")])
    checked = skill.reproduce(objects, scene=box, avoid=False)
    np.testing.assert_array_equal(checked.joints, res.joints)  # check only
    assert any("box" in c for c in checked.collisions)
    avoided = skill.reproduce(objects, scene=box)
    assert avoided.collisions == [] and avoided.infeasible is None
    assert avoided.clearance is not None and avoided.clearance.min() > 0.005
    # The skill's own constraint still holds where it is tight: the grasp and the end.
    grasp = int(np.flatnonzero(res.gripper)[0])
    for k in (grasp, -1):
        err, err0 = avoided.task_errors["glass"][k], res.task_errors["glass"][k]
        assert err <= err0 + 1e-3, (k, err, err0)
    # The clearance took a share where it pushed; it is not a constraint of the skill.
    assert avoided.influence["clearance"].max() > 0.05
    assert "clearance" not in avoided.used and "clearance" not in skill.constraint_names
    total = sum(avoided.influence.values())
    np.testing.assert_allclose(total, 1.0, atol=1e-9)
    # Timed within the arm's limits, as any reproduction (by divided differences).
    assert avoided.times is not None
    assert motion_peaks(avoided.times, avoided.joints, limits).worst <= 1.0 + 1e-9
    report = skill.check(avoided.joints, box)
    np.testing.assert_allclose(report.clearance, avoided.clearance)
    # Continuous: no step jumps past the box between two clear samples (the joints
    # interpolated 10 times finer are clear of it too).
    assert np.abs(np.diff(avoided.joints, axis=0)).max() < 0.1
    fine = np.linspace(0.0, len(avoided.t) - 1.0, 10 * (len(avoided.t) - 1) + 1)
    between = np.stack([np.interp(fine, np.arange(len(avoided.t)), q) for q in avoided.joints.T], 1)
    held = avoided.gripper_signal[np.floor(fine).astype(int)]
    assert skill.check(between, box, gripper=held).min_clearance > 0.005


def test_a_glass_inside_a_box_is_reported_infeasible(skill: Skill, plain: tuple) -> None:
    objects, _ = plain
    inside = Scene([Box((0.12, 0.12, 0.12), objects["glass"], name="crate")])
    with pytest.warns(CollisionWarning, match=r"crate and gripper collide from sample \d+"):
        out = skill.reproduce(objects, scene=inside)
    assert out.infeasible is not None and "crate" in out.infeasible
    # Why: keeping clear would leave the grasp, where the glass constraint is tight.
    assert re.search(
        r"\d+ mm from the glass constraint at sample \d+, where it is tight", out.infeasible
    )
    assert any("crate" in c for c in out.collisions)


def _through_the_box(skill: Skill, plain: tuple) -> tuple[CollisionChecker, np.ndarray, object]:
    """A checker of a box at mid-carry, its grasps planned for the plain path (the path's
    joints and gripper signal without the lead-in)."""
    objects, res = plain
    box = Scene([Box((0.06, 0.06, 0.06), _mid_carry(res), name="box")])
    checker = CollisionChecker(skill.robot, box, objects)
    own = ~res.lead_in
    joints, signal = res.joints[own], res.gripper_signal[own]
    checker.plan_grasps(joints, signal)
    return checker, joints, signal


def test_the_clearance_gaussian_is_the_bumps_linearization(skill: Skill, plain: tuple) -> None:
    # One encounter with the box: at step k, r = e^T J_p for the point fixed in its body,
    # against central differences of e . p(theta); the Gaussian is
    # r theta ~ N(r q + ref_k + a w_k - e . p(q), SIGMA^2 / rho_k):
    # Lambda = rho_k r^T r / SIGMA^2, information Lambda q + rho_k r (ref_k + a w_k - e . p(q))
    # / SIGMA^2.
    checker, joints, signal = _through_the_box(skill, plain)
    avoid = Avoidance(checker, margin=0.02)
    assert avoid.update(joints, signal) > 0
    (enc,) = avoid.encounters
    assert enc.body == "box" and enc.amplitude > 0.02  # the path goes through it
    # Passed over, not backed away from: up, without the component along the path.
    assert enc.escape[2] > 0.7
    np.testing.assert_allclose(np.linalg.norm(enc.escape), 1.0)

    def point(q: np.ndarray) -> np.ndarray:
        rots, origins = _chain_frames(q[None], checker._consts, checker._revolute)
        return np.asarray(rots[0, enc.joint].dot(enc.local) + origins[0, enc.joint])

    taper = enc.taper
    assert taper == max(TAPER_MIN, round(TAPER * joints.shape[0]))
    # Each moving body is moved around its own steps within the margin; together they are the
    # encounter's.
    assert set(enc.spans) == {enc.moving, *enc.others}
    assert min(lo for lo, _ in enc.spans.values()) == enc.lo
    assert max(hi for _, hi in enc.spans.values()) == enc.hi
    assert enc.others == {}, "one body met: the Gaussian below is its alone"
    checked = 0
    for k in (enc.lo - taper // 2, (enc.lo + enc.hi) // 2, enc.hi + taper // 3):
        q = joints[k]
        terms = avoid.terms(k)
        assert terms is not None
        lam, info = terms
        h = 1e-6
        r = np.array(
            [
                enc.escape.dot(point(q + h * e) - point(q - h * e)) / (2 * h)
                for e in np.eye(q.shape[0])
            ]
        )
        w = enc.weight(k, enc.moving)
        rho = 10.0 ** (-TAPER_DECADES * (1.0 - w)) / SIGMA**2
        np.testing.assert_allclose(lam, rho * np.outer(r, r), rtol=1e-5, atol=1e-6 * rho * r @ r)
        push = enc.ref[k] + enc.lift(k)[0] * w - enc.escape.dot(point(q))
        expected = lam @ q + rho * r * push
        np.testing.assert_allclose(info, expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
        checked += 1
    assert checked == 3
    # The bump: whole over the encounter, a raised cosine to nothing `taper` steps away.
    assert enc.weight(enc.lo) == enc.weight(enc.hi) == 1.0
    np.testing.assert_allclose(enc.weight(enc.lo - taper / 2), 0.5, atol=1e-12)
    assert enc.weight(enc.hi + taper) == 0.0 and avoid.terms(enc.hi + taper + 1) is None


def test_a_path_that_dwells_by_the_box_is_passed_over_along_its_way(
    skill: Skill, plain: tuple, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The path's direction at an encounter is the point's motion over the steps around its
    # nearest one, widened until it moves ALONG_MIN. Here the path dwells in the box where it
    # came nearest: 20 samples that go 4 mm down and out, then part of the way back. Over one
    # step either side the hand moved 0.2 mm, down and out, and "up without the motion along
    # the path" tilted the bump 55 degrees outward (a coaster plan so lifted the glass 14 cm
    # and did not come back to the coaster); widened, the bump is the one of the path alone.
    checker, joints, signal = _through_the_box(skill, plain)
    alone = Avoidance(checker, margin=0.02)
    alone.update(joints, signal)
    report = checker.check(joints, signal, margin=0.02)
    assert report.scene_clearance is not None
    j = int(np.argmin(report.scene_clearance))
    q = joints[j]
    dq = np.linalg.lstsq(skill.robot.jacobian(q), np.array([0.6, 0.0, -0.8]) * 2e-4, rcond=None)[0]
    depth = np.r_[2.0 * np.arange(10), 18.0 - np.arange(10)]  # 0.4 mm a sample, back at 0.2
    path = np.concatenate([joints[:j], q + depth[:, None] * dq, joints[j + 1 :]])
    held = np.concatenate([signal[:j], np.repeat(signal[j], depth.size), signal[j + 1 :]])
    checker.plan_grasps(path, held)
    escapes = {}
    for along in (ALONG_MIN, 0.0):
        monkeypatch.setattr(avoid_module, "ALONG_MIN", along)
        dwell = Avoidance(checker, margin=0.02)
        dwell.update(path, held)
        escapes[along] = dwell.encounters[0].escape
    (enc,) = alone.encounters
    assert escapes[ALONG_MIN].dot(enc.escape) > 0.99  # measured: 0.9997
    assert escapes[0.0].dot(enc.escape) < 0.7  # one step either side: 0.55


@pytest.mark.parametrize("slope_deg", [10.0, 25.0, 40.0, 70.0])
def test_a_path_less_steep_than_steep_is_passed_straight_up(
    skill: Skill, plain: tuple, slope_deg: float
) -> None:
    # A point going down at slope_deg onto a box below it (the normal pointing up and back):
    # less steep than STEEP (30 degrees), the bump goes straight up; steeper, up without the
    # path's component, which tilts forward, into the direction of the motion, by the slope.
    checker, _, _ = _through_the_box(skill, plain)
    avoidance = Avoidance(checker, margin=0.02)
    slope = np.radians(slope_deg)
    along = np.array([np.cos(slope), 0.0, -np.sin(slope)])
    points = np.outer(np.linspace(-0.1, 0.1, 41), along)
    away = np.array([-0.3, 0.0, 0.95]) / np.linalg.norm([-0.3, 0.0, 0.95])
    # The moving body first (its joint > 0); the pair's normal points from it to the box.
    prox = type("Prox", (), {"joints": (3, 0), "normal": -away})()
    e = avoidance._escape(points, 20, prox)
    up = np.array([0.0, 0.0, 1.0])
    if np.sin(slope) < STEEP:
        np.testing.assert_allclose(e, up, atol=1e-12)
    else:
        tilted = up - up.dot(along) * along
        np.testing.assert_allclose(e, tilted / np.linalg.norm(tilted), atol=1e-12)
        assert e.dot(along) == pytest.approx(0.0, abs=1e-12) and e[0] > 0.3  # forward


def test_the_hold_keeps_the_point_where_it_was_across_the_bump(skill: Skill, plain: tuple) -> None:
    # hold=True adds, at step k, P J_p theta ~ N(P (J_p q + q_k - p(q)), ACROSS_SIGMA^2 / rho_k)
    # with P = I - e e^T and q_k the point on the path the encounter started on: against
    # central differences of p, on top of the lift's Gaussian of the test above.
    checker, joints, signal = _through_the_box(skill, plain)
    lift, held = Avoidance(checker, margin=0.02), Avoidance(checker, margin=0.02, hold=True)
    assert lift.update(joints, signal) == held.update(joints, signal) > 0
    (enc,) = held.encounters
    assert enc.held is not None and lift.encounters[0].held is None  # its point alone

    def point(q: np.ndarray) -> np.ndarray:
        rots, origins = _chain_frames(q[None], checker._consts, checker._revolute)
        return np.asarray(rots[0, enc.joint].dot(enc.local) + origins[0, enc.joint])

    across = np.eye(3) - np.outer(enc.escape, enc.escape)
    steps = (enc.lo - enc.taper // 2, (enc.lo + enc.hi) // 2, enc.hi + enc.taper // 3)
    for k in steps:
        np.testing.assert_allclose(enc.held[k], point(joints[k]), atol=1e-12)
    # Linearized at another posture (the fused step's theta_{k-1} of the next pass): the
    # point is asked back to q_k. The same Gaussians as the pass's, made at that path.
    moved = joints + 0.02
    at_moved = {k: (lift.terms(k, moved[k]), held.terms(k, moved[k])) for k in steps}
    for avoid in (lift, held):
        avoid._linearize(moved, _chain_frames(moved, checker._consts, checker._revolute))
    h = 1e-6
    for k in steps:
        q = moved[k]
        jac = np.stack([(point(q + h * e) - point(q - h * e)) / (2 * h) for e in np.eye(len(q))], 1)
        rho = 10.0 ** (-TAPER_DECADES * (1.0 - enc.weight(k, enc.moving))) / ACROSS_SIGMA**2
        lam_lift, info_lift = lift.terms(k)  # type: ignore[misc]
        lam, info = held.terms(k)  # type: ignore[misc]
        for got, want in zip(at_moved[k], ((lam_lift, info_lift), (lam, info)), strict=True):
            assert got is not None
            np.testing.assert_allclose(
                got[0], want[0], rtol=1e-12, atol=1e-9 * np.abs(want[0]).max()
            )
            np.testing.assert_allclose(
                got[1], want[1], rtol=1e-12, atol=1e-9 * np.abs(want[1]).max()
            )
        extra = rho * jac.T @ across @ jac
        np.testing.assert_allclose(
            lam - lam_lift, extra, rtol=1e-5, atol=1e-6 * np.abs(extra).max()
        )
        want = extra @ q + rho * jac.T @ across @ (enc.held[k] - point(q))
        np.testing.assert_allclose(
            info - info_lift, want, rtol=1e-5, atol=1e-6 * np.abs(want).max()
        )


def test_a_bump_has_fallen_to_nothing_where_the_skill_is_tight(skill: Skill, plain: tuple) -> None:
    # Tight steps up to 4 steps before the encounter (and none after it): the bump rises from
    # there, over 4 steps instead of a taper (8), and asks nothing at it or before; after the
    # encounter it falls over the whole taper.
    checker, joints, signal = _through_the_box(skill, plain)
    free = Avoidance(checker, margin=0.02)
    free.update(joints, signal)
    (enc,) = free.encounters
    assert enc.lo > enc.taper > 5 and enc.before == enc.after == enc.taper
    tight = np.zeros(joints.shape[0], dtype=bool)
    tight[: enc.lo - 4 + 1] = True
    cut = Avoidance(checker, margin=0.02, tight=tight)
    cut.update(joints, signal)
    (near,) = cut.encounters
    assert (near.lo, near.hi, near.needs) == (enc.lo, enc.hi, enc.needs)
    assert near.before == 4 and near.after == enc.taper
    assert near.lift(enc.lo - 4)[0] == 0.0 and near.weight(enc.lo - 4) == 0.0
    np.testing.assert_allclose(near.weight(enc.lo - 2), 0.5, atol=1e-12)
    assert cut.terms(enc.lo - 5) is None and free.terms(enc.lo - 5) is not None
    for k in (enc.hi + 1, enc.hi + enc.taper // 2, enc.hi + enc.taper - 1):
        assert near.weight(k) == enc.weight(k) and near.lift(k)[0] == enc.lift(k)[0]
        np.testing.assert_array_equal(cut.terms(k)[0], free.terms(k)[0])  # type: ignore[index]


def test_the_passes_look_only_where_the_check_finds_the_scene_near(
    skill: Skill, plain: tuple
) -> None:
    # A pass asks for nearest points only at the samples where the path's check found the
    # scene within the margin: the encounters and their Gaussians are those of a look at
    # every sample.
    objects, res = plain
    box = Scene([Box((0.06, 0.06, 0.06), _mid_carry(res), name="box")])
    checker = CollisionChecker(skill.robot, box, objects)
    own = ~res.lead_in
    joints, signal = res.joints[own], res.gripper_signal[own]
    report = checker.check(joints, signal, margin=0.02)
    assert report.scene_clearance is not None
    near = np.flatnonzero(report.scene_clearance < 0.02)
    assert 0 < near.size < joints.shape[0] // 2
    out = []
    for where in (None, near):
        checker.plan_grasps(joints, signal)
        avoid = Avoidance(checker, margin=0.02)
        caught = avoid.update(joints, signal, near=where)
        out.append((caught, avoid))
    assert out[0][0] == out[1][0] > 0
    every, some = out[0][1], out[1][1]
    assert len(every.encounters) == len(some.encounters) == 1
    a, b = every.encounters[0], some.encounters[0]
    assert (a.lo, a.hi, a.needs, a.moving) == (b.lo, b.hi, b.needs, b.moving)
    assert a.others.keys() == b.others.keys()
    assert every.precisions.keys() == some.precisions.keys()
    for step, (lam, info) in every._terms.items():
        np.testing.assert_array_equal(lam, some._terms[step][0])
        np.testing.assert_array_equal(info, some._terms[step][1])


def test_a_bumps_lift_is_the_envelope_of_its_steps_needs() -> None:
    # a_k = max_j need_j c(k - j), c a raised cosine over `taper` steps, by brute force: each
    # step lifted by what it and its neighbours need, a step far from every need not at all.
    rng = np.random.default_rng(5)
    at, need = rng.choice(80, 12, replace=False), rng.uniform(0.01, 0.2, 12)
    needs = {int(j): float(v) for j, v in zip(at, need, strict=True)}
    enc = _Encounter(
        body="box",
        lo=0,
        hi=79,
        joint=1,
        local=np.zeros(3),
        escape=np.array([0.0, 0.0, 1.0]),
        needs=needs,
        ref=np.zeros(200),
        taper=9,
    )
    steps = np.arange(-20, 120)
    expected = [
        max(v * (0.5 + 0.5 * np.cos(np.pi * min(abs(k - j) / 9, 1.0))) for j, v in needs.items())
        for k in steps
    ]
    np.testing.assert_allclose(enc.lift(steps), expected, rtol=0, atol=1e-15)
    for j, v in needs.items():
        assert enc.lift(j)[0] >= v  # every step gets at least its own need
    assert enc.amplitude == max(needs.values()) == enc.lift(steps).max()
    far = steps[np.all(np.abs(steps[:, None] - np.array(list(needs))[None]) >= 9, axis=1)]
    assert far.size and not enc.lift(far).any()


def test_a_body_met_twice_is_bent_around_twice() -> None:
    # Hits on one body, 300 steps apart (on the way there and back), are two meetings; hits
    # closer than the gap are one.
    hits = {"box": [(510, "d"), (100, "a"), (101, "b"), (130, "c"), (511, "e")], "wall": [(7, "w")]}
    groups = _meetings(hits, gap=80)  # type: ignore[arg-type]
    assert [(body, [s for s, _ in g]) for body, g in groups] == [
        ("box", [100, 101, 130]),
        ("box", [510, 511]),
        ("wall", [7]),
    ]
    assert [len(g) for _, g in _meetings(hits, gap=500)] == [5, 1]  # type: ignore[arg-type]


def test_a_seven_joint_arm_bends_around_a_box_on_its_way_down() -> None:
    # The Panda reaches down to a box: a 5 cm box in its way, beside the path, is met by the
    # hand, the fingers and the wrist at once. Each is moved along the encounter's direction
    # (one point alone lets the redundant arm swing another link in: 16 mm, under the
    # margin), and the run keeps the margin where the plain run goes 35 mm into the box.
    robot = panda()
    home = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    data = reach_grasp_return(robot, (0.5, 0.0, 0.1), home, n_demos=5, seed=0)
    skill = Skill.learn(data.demos, robot, n_components=8, n_steps=300)
    told = {"box": np.asarray(data.boxes, dtype=np.float64).mean(axis=0)}
    plain = skill.reproduce(told)
    own = np.flatnonzero(~plain.lead_in)
    closes = np.flatnonzero(plain.gripper & ~plain.lead_in)[0]
    box = {"box": Box((0.04, 0.04, 0.04), (0.0, 0.0, -0.02))}
    centre = plain.positions[(own[0] + closes) // 2] - np.array([0.10, 0.0, 0.0])
    scene = Scene([Box((0.05, 0.05, 0.05), centre, name="obstacle")], objects=box)
    through = skill.reproduce(told, scene=scene, avoid=False)
    assert through.clearance is not None and through.clearance.min() < -0.02
    met = {c[2] for c in through.collisions if "obstacle" in c}
    assert "panda_hand" in met and len(met) >= 3, met
    around = skill.reproduce(told, scene=scene, margin=0.02)
    assert around.infeasible is None and not around.collisions
    assert around.clearance is not None and around.clearance.min() >= 0.02 - TOLERANCE
    # The grasp is kept: the hand meets the box where the plain run does.
    grasp = np.flatnonzero(around.gripper & ~around.lead_in)[0]
    assert np.linalg.norm(around.positions[grasp] - plain.positions[closes]) < 0.005
    # Lower down (0.6 of the way), 6 cm behind the path: keeping clear took the hand 35 cm off
    # the grasp, where the skill's box constraint is 7 mm loose (over TIGHT), and that run was
    # kept, unreported. Now it is reported, and the plain run comes back, its contact listed.
    lower = plain.positions[own[0] + int(0.6 * (closes - own[0]))] - np.array([0.06, 0.0, 0.0])
    behind = Scene([Box((0.05, 0.05, 0.05), lower, name="obstacle")], objects=box)
    with pytest.warns(CollisionWarning, match=r"mm from the box constraint at sample \d+"):
        out = skill.reproduce(told, scene=behind, margin=0.02)
    assert out.infeasible is not None and any("obstacle" in c for c in out.collisions)
    blind = skill.reproduce(told, scene=behind, avoid=False)
    np.testing.assert_array_equal(out.joints, blind.joints)


def test_capsule_bounds_bracket_coals_cylinder_distance() -> None:
    # Two cylinders at random poses: the capsules' distance <= coal's <= the distance of the
    # two side points, and equal to coal's where the axes' closest points are inside both.
    import coal
    from scipy.spatial.transform import Rotation

    from pbdkit.collision._bounds import ShapeTable, _capsules

    rng = np.random.default_rng(11)
    inside_seen = 0
    request = coal.DistanceRequest()
    for _ in range(400):
        ra, rb = rng.uniform(0.01, 0.08, 2)
        ha, hb = rng.uniform(0.02, 0.2, 2)
        shapes = [coal.Cylinder(ra, 2 * ha), coal.Cylinder(rb, 2 * hb)]
        table = ShapeTable(shapes)
        rot = Rotation.random(2, random_state=int(rng.integers(2**31))).as_matrix()
        pos = rng.uniform(-0.2, 0.2, (2, 3))
        d = coal.distance(
            shapes[0],
            coal.Transform3s(rot[0], pos[0]),
            shapes[1],
            coal.Transform3s(rot[1], pos[1]),
            request,
            coal.DistanceResult(),
        )
        low, inside, high = _capsules(
            table, np.array([0]), np.array([1]), rot[:1], rot[1:], pos[:1], pos[1:]
        )
        assert low[0] <= d + 1e-6
        if d > 0:
            assert high[0] >= d - 1e-6
        if inside[0]:
            inside_seen += 1
            assert low[0] == pytest.approx(d, abs=1e-6)
    assert inside_seen > 20


def test_a_result_with_a_scene_round_trips(skill: Skill, plain: tuple, tmp_path: Path) -> None:
    objects, res = plain
    box = Scene([Box((0.06, 0.06, 0.06), _mid_carry(res), name="box")])
    checked = skill.reproduce(objects, scene=box, avoid=False)
    path = tmp_path / "res.npz"
    checked.save(path)
    back = ReproductionResult.load(path)
    assert back.clearance is not None
    np.testing.assert_array_equal(back.clearance, checked.clearance)
    assert back.collisions == checked.collisions and back.used == checked.used


# ----------------------------------------------------------------------------- online
def _commands(ctrl: object, q: np.ndarray, move: dict | None = None, at: int = -1) -> tuple:
    """Fed its own commands from ``q`` (``move`` told at command ``at``): postures, gripper."""
    joints, held = [q], [False]
    k = 0
    while not ctrl.done:  # type: ignore[attr-defined]
        cmd = ctrl.step(q, move if k == at else None)  # type: ignore[attr-defined]
        q = cmd.q
        joints.append(q)
        held.append(cmd.gripper)
        k += 1
    return np.array(joints), np.array(held)


def test_the_controller_keeps_clear_of_a_scene_and_replans_for_a_moved_object(
    skill: Skill, plain: tuple
) -> None:
    objects, res = plain
    box = Scene([Box((0.06, 0.06, 0.06), _mid_carry(res), name="box")])
    q0 = res.joints[0]
    # Without the scene the commands go through the box; with it they keep clear of it,
    # through a re-plan for a glass that moved by 5 mm too.
    blind, g_blind = _commands(skill.controller(objects), q0)
    assert skill.check(blind, box, gripper=g_blind).min_clearance < 0.0
    ctrl = skill.controller(objects, scene=box)
    moved = {"glass": objects["glass"] + np.array([0.005, 0.0, 0.0])}
    clear, g_clear = _commands(ctrl, q0, moved, at=len(blind) // 3)
    assert ctrl.replans >= 1 and ctrl.fault is None
    assert skill.check(clear, box, gripper=g_clear).min_clearance > 0.005
    # The skill is still done: the hand ends where the skill ends for the moved glass.
    end = skill.reproduce(moved)
    np.testing.assert_allclose(skill.robot.fk(clear[-1]), end.positions[-1], atol=2e-3)


def test_a_plan_that_would_collide_is_not_followed(skill: Skill, plain: tuple) -> None:
    objects, res = plain
    inside = Scene([Box((0.12, 0.12, 0.12), objects["glass"], name="crate")])
    ctrl = skill.controller(objects, scene=inside)
    q0 = res.joints[0]
    with pytest.warns(PlanFailedWarning, match="the plan would collide: .*crate"):
        joints, _ = _commands(ctrl, q0)
    assert ctrl.fault is not None and "crate" in ctrl.fault
    np.testing.assert_allclose(joints, q0[None].repeat(len(joints), axis=0), atol=1e-12)


def test_a_controller_without_limits_does_not_take_a_scene(skill: Skill, plain: tuple) -> None:
    objects, _ = plain
    none = {"velocity_limit": None, "acceleration_limit": None, "jerk_limit": None}
    with pytest.raises(ValueError, match="keeps clear of a scene with motion limits"):
        skill.controller(objects, scene=Scene([]), **none)


def test_a_stream_never_streams_a_colliding_plan(skill: Skill, plain: tuple) -> None:
    # The 1 kHz stream, its plans made in the planner process: the first plan would take the
    # gripper into the crate, so none is streamed; the setpoints stay at rest and say why.
    objects, res = plain
    inside = Scene([Box((0.12, 0.12, 0.12), objects["glass"], name="crate")])
    q0 = res.joints[0]

    def run(stream: object) -> list[np.ndarray]:
        setpoints = []
        # A refused plan runs every pass of every fallback first (3.6 s on this test's skill).
        deadline = time.monotonic() + 60.0
        while not stream.done and time.monotonic() < deadline:  # type: ignore[attr-defined]
            setpoints.append(stream.step(q0))  # type: ignore[attr-defined]
            if stream.fault is None:  # type: ignore[attr-defined]
                time.sleep(1e-4)  # the planner process takes a while
        return setpoints

    with skill.controller(objects, scene=inside).stream(1000) as stream:
        with pytest.warns(PlanFailedWarning, match="the plan would collide"):
            setpoints = run(stream)
        assert stream.done and stream.fault is not None and "crate" in stream.fault
    np.testing.assert_allclose(np.array(setpoints), q0[None].repeat(len(setpoints), 0), atol=1e-12)


def test_a_replan_that_would_collide_keeps_the_plan_in_use(skill: Skill, plain: tuple) -> None:
    # The glass is told to have moved 10 cm, into a crate: the re-plan would take the
    # gripper into it. The plan in use (checked, clear) is kept, and the controller says so.
    objects, res = plain
    moved = objects["glass"] + np.array([0.0, 0.1, 0.0])
    crate = Scene([Box((0.12, 0.12, 0.12), moved, name="crate")])
    ctrl = skill.controller(objects, scene=crate)
    with pytest.warns(CollisionWarning, match="the controller keeps its plan: .*crate"):
        joints, held = _commands(ctrl, res.joints[0], {"glass": moved}, at=5)
    assert ctrl.fault is None and ctrl.replans == 0 and ctrl._timed.refused >= 1
    assert skill.check(joints, crate, gripper=held).min_clearance > 0.0
    np.testing.assert_allclose(skill.robot.fk(joints[-1]), res.positions[-1], atol=2e-3)


def test_the_lower_bounds_never_exceed_coal_and_are_tight_for_spheres_and_capsules() -> None:
    # Random poses of boxes, cylinders and spheres: every positive bound is at most coal's
    # distance, and a pair in contact has a bound of at most 0 (the checker measures every
    # such pair: a penetration's depth is coal's); for a sphere against a primitive, and for
    # two cylinders' capsules along one line, it is the distance itself where they are apart.
    import coal

    from pbdkit.collision._bounds import ShapeTable, lower_bounds

    rng = np.random.default_rng(5)
    geoms = [coal.Box(0.1, 0.2, 0.05), coal.Cylinder(0.03, 0.3), coal.Cylinder(0.05, 0.2)]
    geoms += [coal.Sphere(0.04), coal.Cylinder(0.02, 0.4)]
    table = ShapeTable(geoms)
    pairs = np.array([(i, j) for i in range(5) for j in range(i + 1, 5)])
    m = 400
    rot = np.stack([[_random_rotation(rng) for _ in geoms] for _ in range(m)])
    pos = rng.uniform(-0.3, 0.3, (m, len(geoms), 3))
    bounds = lower_bounds(table, pairs, rot, pos).lower
    exact = table.exact(pairs)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    for t in range(m):
        for k, (a, b) in enumerate(pairs):
            result.clear()
            d = coal.distance(
                geoms[a], coal.Transform3s(rot[t, a], pos[t, a]),
                geoms[b], coal.Transform3s(rot[t, b], pos[t, b]), request, result,
            )  # fmt: skip
            assert bounds[t, k] <= max(d, 0.0) + 1e-7, (t, a, b, bounds[t, k], d)
            if exact[k] and bounds[t, k] > 0.0:
                assert bounds[t, k] == pytest.approx(d, abs=1e-6)
    assert exact.tolist() == [a == 3 or b == 3 for a, b in pairs]
    # Two parallel cylinders side by side along x: the capsules' bound is their distance.
    side = np.broadcast_to(np.eye(3), (1, 5, 3, 3)).copy()
    apart = np.zeros((1, 5, 3))
    apart[0, 2] = (0.2, 0.0, 0.0)
    (k,) = np.flatnonzero((pairs[:, 0] == 1) & (pairs[:, 1] == 2))
    assert lower_bounds(table, pairs, side, apart).lower[0, k] == pytest.approx(0.2 - 0.03 - 0.05)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_a_tight_constraint_is_left_by_more_than_5_mm_and_three_deviations() -> None:
    # pik._leaves_tight on a made-up run of 100 steps: the glass constraint 1 mm wide at step
    # 30 (the grasp), 4.7 mm just after it (40-60: under TIGHT), 30 mm elsewhere. The avoided
    # run's hand error grows at one step; left where it grows by more than CONFLICT (5 mm) and
    # more than LEFT_SIGMAS (3) deviations, at a tight step.
    from types import SimpleNamespace

    import pbdkit.reproduction._probabilistic_ik as pik

    sd = np.full(100, 0.03)
    sd[30], sd[40:61] = 0.001, 0.0047
    cov = np.zeros((100, 3, 3))
    cov[:, 0, 0] = cov[:, 1, 1] = cov[:, 2, 2] = sd**2
    run = SimpleNamespace(tasks=["glass"], constraints=SimpleNamespace(task_cov={"glass": cov}))
    t = np.arange(100, dtype=float)

    def result(errors: np.ndarray) -> SimpleNamespace:
        return SimpleNamespace(lead_in=None, t=t, task_errors={"glass": errors})

    plain = result(np.full(100, 0.001))

    def left(step: int, grown: float) -> object:
        errors = np.full(100, 0.001)
        errors[step] += grown
        return pik._leaves_tight(run, plain, result(errors))  # type: ignore[arg-type]

    assert left(50, 0.0058) is None  # 1.2 deviations of a 4.7 mm constraint
    assert left(50, 0.0150) == (50, "glass", pytest.approx(0.016))  # 3.2 of them
    assert left(30, 0.0045) is None  # 4.5 deviations, but under 5 mm
    assert left(30, 0.0055) == (30, "glass", pytest.approx(0.0065))
    assert left(80, 0.1) is None  # loose there
    assert left(80, 0.0) is None and left(50, -0.001) is None
