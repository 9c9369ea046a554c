"""Arms no one here wrote (``arm_zoo.py``): forward kinematics against an independent engine,
and a reach-grasp-return skill that generalizes on each, over a narrow and a wide table.

The measure is the fused hand's distance to the box at the first gripper close, for box
placements inside the hull of the demonstrated ones (issue 21: at most 2 mm median, 5 mm 90th
percentile; ``benchmarks/bench_zoo.py`` runs five seeds of every arm and spread).
"""

from __future__ import annotations

import re
from unittest import mock

import numpy as np
import pytest
from arm_zoo import ARMS, ARMS_DIR, NARROW, WIDE, grasp_errors

from pbdkit import Robot, Skill
from pbdkit.datasets import reach_grasp_return
from pbdkit.prob import _selection
from pbdkit.prob._gmm import GMM

mujoco = pytest.importorskip("mujoco")


def _mujoco_model(urdf: str) -> object:
    """MuJoCo's own URDF import of the same file, keeping every link (fusestatic off)."""
    text = re.sub(
        r"(<robot[^>]*>)",
        r'\1<mujoco><compiler fusestatic="false" discardvisual="true"/></mujoco>',
        urdf,
        count=1,
    )
    return mujoco.MjModel.from_xml_string(text)


@pytest.mark.parametrize("name", sorted(ARMS))
def test_fk_agrees_with_mujoco(name: str) -> None:
    arm = ARMS[name]
    robot = arm.robot()
    model = _mujoco_model((ARMS_DIR / arm.urdf).read_text(encoding="utf-8"))
    data = mujoco.MjData(model)
    names = [model.joint(i).name for i in range(model.njnt)]
    adr = [int(model.jnt_qposadr[names.index(j)]) for j in robot.joint_names]
    tip = model.body(arm.tip).id
    rng = np.random.default_rng(0)
    lo, hi = np.maximum(robot.lower, -np.pi), np.minimum(robot.upper, np.pi)
    for q in rng.uniform(lo, hi, (20, robot.n_joints)):
        data.qpos[:] = 0.0
        data.qpos[adr] = q
        mujoco.mj_kinematics(model, data)
        np.testing.assert_allclose(data.xpos[tip], robot.fk(q), rtol=0, atol=1e-12)


def test_a_joint_named_like_a_link_loads() -> None:
    """The SO-100's gripper joint shares its link's name; pinocchio then found two frames of
    that name and refused to lock the joint (it is off the chain to the tip)."""
    robot = Robot.from_urdf(ARMS_DIR / "so100.urdf", tip="gripper")
    assert robot.joint_names == [
        "shoulder_pan",
        "shoulder_lift",
        "elbow_flex",
        "wrist_flex",
        "wrist_roll",
    ]
    assert "gripper" in Robot.from_urdf(ARMS_DIR / "so100.urdf", tip="jaw").joint_names


def test_reach_grasp_return_demonstrations() -> None:
    arm = ARMS["panda"]
    robot = arm.robot()
    data = reach_grasp_return(robot, arm.center, arm.home, spread=WIDE, seed=3)
    assert len(data.demos) == 5 and data.boxes.shape == (5, 3)
    for demo, box in zip(data.demos, data.boxes, strict=True):
        assert demo.gripper is not None
        first = int(np.argmax(demo.gripper > 0.5))
        # the hand is at the box when the gripper closes, and at rest at both ends
        assert np.linalg.norm(robot.fk(demo.joints[first]) - box) < 1e-5
        np.testing.assert_allclose(demo.joints[0], demo.joints[-1], atol=1e-12)
        assert robot.within_limits(demo.joints).all()
        np.testing.assert_allclose(demo.objects["box"], box)
    # the placements spread over the square; the new ones inside their hull
    assert np.all(np.ptp(data.boxes[:, :2], axis=0) > 0.15)
    new = data.placements(50, seed=1)
    lo, hi = data.boxes.min(axis=0), data.boxes.max(axis=0)
    assert np.all((new >= lo - 1e-12) & (new <= hi + 1e-12))
    # seeded
    again = reach_grasp_return(robot, arm.center, arm.home, spread=WIDE, seed=3)
    np.testing.assert_array_equal(again.demos[2].joints, data.demos[2].joints)
    with pytest.raises(ValueError, match="center: a demonstration failed 20 times"):
        reach_grasp_return(robot, [3.0, 0.0, 0.0], arm.home)


CASES = [(name, spread) for name, arm in sorted(ARMS.items()) for spread in arm.spreads]


@pytest.mark.slow
@pytest.mark.parametrize(("name", "spread"), CASES)
def test_the_hand_reaches_the_box_on_every_arm(name: str, spread: float) -> None:
    """Skill.learn's defaults, five demonstrations that agree only at the grasp, five new
    placements inside their hull: the fused hand within 2 mm (median) and 5 mm (worst)."""
    arm = ARMS[name]
    robot = arm.robot()
    data = arm.demos(robot, spread, seed=0)
    skill = Skill.learn(data.demos, robot)
    errors = grasp_errors(skill, robot, data, data.placements(5, seed=0))
    assert np.median(errors) <= 2e-3, (skill.n_components, errors)
    assert errors.max() <= 5e-3, (skill.n_components, errors)


def test_pooled_scoring_loses_the_grasp_the_local_one_keeps(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The defect this zoo found: scored against the demonstrations' spread pooled over time,
    K for the box collapses where they differ by decimetres except at the grasp. (K searched
    from 1, as when it was found; from MIN_COMPONENTS, 12, the collapse stops there.)"""
    monkeypatch.setattr(_selection, "MIN_COMPONENTS", 1)
    arm = ARMS["xarm7"]
    robot = arm.robot()
    data = arm.demos(robot, WIDE, seed=1)
    boxes = data.placements(3, seed=0)
    default = Skill.learn(data.demos, robot)
    with mock.patch.dict(GMM.__init__.__kwdefaults__, {"cv_scale": "pooled"}):
        pooled = Skill.learn(data.demos, robot)
    assert pooled.n_components["box"] <= 4 < default.n_components["box"]
    assert grasp_errors(pooled, robot, data, boxes).min() > 10e-3
    assert grasp_errors(default, robot, data, boxes).max() < 2e-3


def test_a_box_out_of_reach_is_refused_before_running() -> None:
    arm = ARMS["xarm7"]
    robot = arm.robot()
    data = arm.demos(robot, WIDE, seed=0)
    skill = Skill.learn(data.demos, robot)
    far = np.array([1.2, 0.0, 0.05])  # the xArm7 reaches about 0.77 m
    with pytest.raises(
        ValueError, match=r"objects\['box'\]: the hand must be at .* beyond the arm's reach"
    ):
        skill.reproduce({"box": far})


def test_reach_grasp_return_refuses_bad_input() -> None:
    arm = ARMS["ur5"]
    robot = arm.robot()
    with pytest.raises(ValueError, match=r"home must have shape \(6,\)"):
        reach_grasp_return(robot, arm.center, [0.0, 0.0])
    with pytest.raises(ValueError, match=r"center must have shape \(3,\)"):
        reach_grasp_return(robot, [0.4, 0.1], arm.home)
    with pytest.raises(ValueError, match="spread"):
        reach_grasp_return(robot, arm.center, arm.home, spread=-0.1)
    with pytest.raises(ValueError, match="n_demos"):
        reach_grasp_return(robot, arm.center, arm.home, n_demos=1)
    x = np.column_stack([np.tile(np.arange(10.0), 2), np.arange(20.0)])
    with pytest.raises(ValueError, match="cv_scale must be 'local' or 'pooled'"):
        GMM("auto", cv_scale="median").fit(x)  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- harder teachers
_UP2 = np.array([0.0, 0.0, 0.02])


def _grasp_postures(data: object, robot: Robot) -> np.ndarray:
    demos = data.demos  # type: ignore[attr-defined]
    return np.array([d.joints[int(np.argmax(d.gripper > 0.5))] for d in demos])


def test_a_wider_posture_spread_varies_the_grasp_posture_not_the_grasp() -> None:
    arm = ARMS["panda"]
    robot = arm.robot()
    plain = reach_grasp_return(robot, arm.center, arm.home, seed=2, n_demos=6)
    wide = reach_grasp_return(robot, arm.center, arm.home, seed=2, n_demos=6, posture_spread=0.35)
    np.testing.assert_array_equal(wide.boxes, plain.boxes)  # the default draws are untouched
    # The same boxes, reached with other postures: each demonstration's grasp posture moved by
    # up to about posture_spread on its joints.
    moved = np.abs(_grasp_postures(wide, robot) - _grasp_postures(plain, robot))
    assert np.all(moved.max(axis=1) > 0.1) and 0.2 < moved.max() < 0.6
    for demo, box in zip(wide.demos, wide.boxes, strict=True):
        first = int(np.argmax(demo.gripper > 0.5))
        assert np.linalg.norm(robot.fk(demo.joints[first]) - box) < 1e-5
        assert robot.within_limits(demo.joints).all()


def test_segment_timing_moves_the_phases_on_their_own() -> None:
    arm = ARMS["ur5"]
    robot = arm.robot()
    plain = reach_grasp_return(robot, arm.center, arm.home, seed=4)
    timed = reach_grasp_return(robot, arm.center, arm.home, seed=4, segment_timing=0.3)
    for a, b in zip(plain.demos, timed.demos, strict=True):
        np.testing.assert_array_equal(a.joints[0], b.joints[0])
        # the grasp comes at another fraction of the demonstration
        assert a.gripper is not None and b.gripper is not None
        fa = np.argmax(a.gripper > 0.5) / len(a.t)
        fb = np.argmax(b.gripper > 0.5) / len(b.t)
        assert abs(fa - fb) > 1e-3
    fractions = [np.argmax(d.gripper > 0.5) / len(d.t) for d in timed.demos]  # type: ignore[operator]
    assert np.ptp(fractions) > np.ptp(
        [np.argmax(d.gripper > 0.5) / len(d.t) for d in plain.demos]  # type: ignore[operator]
    )


def test_a_pause_holds_the_arm_still() -> None:
    arm = ARMS["ur5"]
    robot = arm.robot()
    plain = reach_grasp_return(robot, arm.center, arm.home, seed=5, rate=50.0)
    paused = reach_grasp_return(
        robot, arm.center, arm.home, seed=5, rate=50.0, pauses=1.0, pause_seconds=(0.5, 1.0)
    )
    for a, b in zip(plain.demos, paused.demos, strict=True):
        extra = len(b.t) - len(a.t)
        assert 25 <= extra <= 50  # 0.5-1 s at 50 Hz
        still = np.all(np.diff(b.joints, axis=0) == 0.0, axis=1)
        assert np.count_nonzero(still) >= extra
    with pytest.raises(ValueError, match=r"pauses must be a probability in \[0, 1\]"):
        reach_grasp_return(robot, arm.center, arm.home, pauses=1.5)
    with pytest.raises(ValueError, match="pause_seconds must be"):
        reach_grasp_return(robot, arm.center, arm.home, pause_seconds=(1.0, 0.5))
    with pytest.raises(ValueError, match=r"segment_timing must be in \[0, 1\)"):
        reach_grasp_return(robot, arm.center, arm.home, segment_timing=1.0)


def test_pick_and_place_puts_the_box_down_at_the_place() -> None:
    arm = ARMS["panda"]
    robot = arm.robot()
    place = (0.45, -0.25, 0.1)
    data = reach_grasp_return(
        robot, arm.center, arm.home, seed=1, place_center=place, place_name="tray"
    )
    assert data.places is not None and data.place_name == "tray"
    for demo, box, spot in zip(data.demos, data.boxes, data.places, strict=True):
        assert demo.gripper is not None
        closed = demo.gripper > 0.5
        grasp, release = int(np.argmax(closed)), int(len(closed) - np.argmax(closed[::-1]))
        np.testing.assert_allclose(robot.fk(demo.joints[grasp]), box, atol=1e-5)
        np.testing.assert_allclose(robot.fk(demo.joints[release]), spot + _UP2, atol=1e-5)
        np.testing.assert_array_equal(demo.objects["tray"], spot)
        assert abs(spot[2] - place[2]) < 1e-12
    scenes = data.scenes(4, seed=0)
    np.testing.assert_array_equal([s["box"] for s in scenes], data.placements(4, seed=0))
    assert all(set(s) == {"box", "tray"} for s in scenes)
    with pytest.raises(ValueError, match="place_name must differ from object_name"):
        reach_grasp_return(robot, arm.center, arm.home, place_center=place, place_name="box")


@pytest.mark.slow
def test_aligned_in_time_the_skill_keeps_the_grasp_a_pause_blurs() -> None:
    """A teacher who pauses once (half of the demonstrations, 0.5-1 s at a random via point):
    rescaled linearly the grasp comes at other fractions of the demonstrations and the fused
    hand misses the box by about a centimetre (12 mm median measured); aligned in time
    (pbdkit.align, DTW onto the medoid) it is at the box again (0.1 mm measured)."""
    arm = ARMS["panda"]
    robot = arm.robot()
    data = reach_grasp_return(robot, arm.center, arm.home, seed=0, pauses=0.5)
    boxes = data.placements(5, seed=0)
    linear = Skill.learn(data.demos, robot, align=False)
    aligned = Skill.learn(data.demos, robot, align=True)
    assert np.median(grasp_errors(linear, robot, data, boxes)) > 5e-3
    assert np.median(grasp_errors(aligned, robot, data, boxes)) < 1e-3


def test_calibrated_the_fused_hand_is_where_the_box_alone_puts_it() -> None:
    """Issue 34's defect: grasp postures up to 0.35 rad apart per joint on a 7-joint arm, and
    segments +-30 % on their own. The joint model, confident where the five postures were not,
    pulled the fused hand off the box (4.5-5.6 mm measured) where the box's constraint alone
    put it (1.4 mm); calibrated (the default), the fusion yields to the box there. Since the
    time ceiling (GMM's max_time_spread) both are within 0.1 mm here, uncalibrated too (0.01-0.02 mm
    measured): the widening is then a safeguard, and the fused hand must stay with the box."""
    arm = ARMS["xarm7"]
    robot = arm.robot()
    data = reach_grasp_return(robot, arm.center, arm.home, spread=NARROW, seed=0,
                              posture_spread=0.35, segment_timing=0.3)  # fmt: skip
    boxes = data.placements(3, seed=0)
    skill = Skill.learn(data.demos, robot)
    fused = grasp_errors(skill, robot, data, boxes)
    alone = grasp_errors(skill, robot, data, boxes, use=[data.object_name])
    assert np.all(fused <= alone + 0.1e-3), (fused, alone)
    assert fused.max() < 1e-3, fused
    assert np.all(skill.calibration_["joint"] >= 1.0)
    assert skill.calibration_["joint"].max() > 10.0
