"""The online controller: one implementation of the Table II loop with Skill.reproduce, limits,
objects that move, an arm held back."""

from __future__ import annotations

import numpy as np
import pytest
from test_skill import N_STEPS, REACH_STEP, synthetic_demos, unseen_glass

from pbdkit import Controller, Skill
from pbdkit.demos import Demonstration
from pbdkit.robot import Robot
from pbdkit.robots import katana


@pytest.fixture(scope="module")
def robot() -> Robot:
    return katana()


@pytest.fixture(scope="module")
def demos(robot: Robot) -> list[Demonstration]:
    return synthetic_demos(robot, np.random.default_rng(0))


@pytest.fixture(scope="module")
def skill(robot: Robot, demos: list[Demonstration]) -> Skill:
    return Skill.learn(demos, robot, n_steps=N_STEPS, random_state=0)


def _run(ctrl: Controller) -> tuple[np.ndarray, list[object]]:
    q = ctrl._last.q.copy()
    joints, cmds = [q], []
    while not ctrl.done:
        cmd = ctrl.step(q)
        q = cmd.q
        joints.append(q)
        cmds.append(cmd)
    return np.array(joints), cmds


@pytest.mark.parametrize("use", [None, ["joint"], ["glass"]])
@pytest.mark.parametrize("start", ["mean", "demo"])
def test_fed_its_own_targets_it_equals_reproduce(
    skill: Skill, demos: list[Demonstration], use: list[str] | None, start: str
) -> None:
    glass, _ = unseen_glass(demos)
    q0 = None if start == "mean" else demos[2].joints[0]
    offline = skill.reproduce({"glass": glass}, q0=q0, use=use)
    ctrl = skill.controller({"glass": glass}, q0=q0, use=use)
    assert ctrl.dt == pytest.approx(skill.duration / (N_STEPS - 1))
    joints, cmds = _run(ctrl)
    assert joints.shape == offline.joints.shape
    np.testing.assert_allclose(joints, offline.joints, rtol=0, atol=1e-9)
    assert [c.index for c in cmds] == list(range(1, N_STEPS))  # the phase never held
    assert np.array_equal([c.limited for c in cmds], offline.limited[1:])
    for j in (1, REACH_STEP, N_STEPS - 1):
        cmd = cmds[j - 1]
        np.testing.assert_allclose(cmd.covariance, offline.covariances[j], rtol=1e-8, atol=1e-14)
        for k, share in cmd.influence.items():
            assert share == pytest.approx(float(offline.influence[k][j]), abs=1e-9)
        assert cmd.gripper == bool(offline.gripper[j])
    with pytest.raises(ValueError, match="the run is done"):
        ctrl.step(joints[-1])


def test_commands_respect_velocity_and_joint_limits_under_noisy_measurements(
    skill: Skill, demos: list[Demonstration], robot: Robot
) -> None:
    rng = np.random.default_rng(5)
    glass, _ = unseen_glass(demos)
    ctrl = skill.controller({"glass": glass}, q0=demos[0].joints[0])
    vmax = np.asarray(robot.velocity_limit)
    q = demos[0].joints[0].copy()
    last = ctrl.target
    while not ctrl.done:
        cmd = ctrl.step(q)
        # Never faster than the limit from where the arm is, never beyond the joint limits.
        assert np.all(np.abs(cmd.q - q) / ctrl.dt <= vmax * (1 + 1e-9))
        assert np.all(cmd.q >= robot.lower) and np.all(cmd.q <= robot.upper)
        # The arm follows (2 mrad off): consecutive commands keep the bound too (a servo
        # reference through them never runs faster than the limits).
        assert not cmd.held
        assert np.all(np.abs(cmd.q - last) / ctrl.dt <= vmax * (1 + 1e-9))
        last = cmd.q
        # The arm follows imperfectly: servo error and encoder noise.
        q = np.clip(cmd.q + rng.normal(0.0, 2e-3, 5), robot.lower, robot.upper)


def test_a_moved_object_is_reached_as_if_known_from_the_start(
    skill: Skill, demos: list[Demonstration]
) -> None:
    glass, _ = unseen_glass(demos)
    moved = glass + np.array([0.03, 0.04, 0.0])  # the glass slides 5 cm before the grasp
    knew = skill.reproduce({"glass": moved})
    stale = skill.reproduce({"glass": glass})
    ctrl = skill.controller({"glass": glass})
    q = ctrl._last.q.copy()
    positions = []
    while not ctrl.done:
        objects = {"glass": moved} if ctrl.index == 40 else None  # seen at step 41
        q = ctrl.step(q, objects=objects).q
        positions.append(skill.robot.fk(q))
    hand = np.array(positions)[REACH_STEP - 1]
    assert np.linalg.norm(hand - knew.positions[REACH_STEP]) < 0.003
    assert np.linalg.norm(stale.positions[REACH_STEP] - moved) > 0.04  # offline misses it
    np.testing.assert_allclose(ctrl.objects["glass"], moved)


def test_a_pushed_arm_holds_the_phase_and_returns_to_the_constraints(
    skill: Skill, demos: list[Demonstration], robot: Robot
) -> None:
    glass, _ = unseen_glass(demos)
    offline = skill.reproduce({"glass": glass})
    ctrl = skill.controller({"glass": glass})
    q = ctrl._last.q.copy()
    push = np.array([0.0, 0.15, -0.1, 0.0, 0.0])  # 0.3 s of an external force, before the grasp
    pushed_at, indices, hand = 30, [], {}
    bound = np.asarray(robot.velocity_limit) * ctrl.dt * (1 + 1e-9)
    while not ctrl.done:
        cmd = ctrl.step(q)
        indices.append(cmd.index)
        hand[cmd.index] = robot.fk(cmd.q)
        if len(indices) == pushed_at + 1:
            # Held back: the command re-targets from where the push left the arm, within the
            # speed bound from there (no snap back to where it was).
            assert cmd.held and np.all(np.abs(cmd.q - q) <= bound)
        q = cmd.q + (push if len(indices) == pushed_at else 0.0)
        q = np.clip(q, robot.lower, robot.upper)
    indices_arr = np.array(indices)
    # While the arm was far behind its target the phase held, then it resumed one per step.
    held = np.flatnonzero(np.diff(indices_arr) == 0)
    assert held.size > 0 and held[0] == pushed_at - 1
    assert np.all(np.diff(indices_arr) >= 0) and indices_arr[-1] == N_STEPS - 1
    # Back on the constraints by the next tight step (early in the hold on the glass, where the
    # glass constraint is a few mm wide): the hand where the undisturbed run has it. The push
    # moved it by far more.
    tight = round(0.40 * (N_STEPS - 1))
    assert np.linalg.norm(hand[tight] - offline.positions[tight]) < 0.003
    pushed = robot.fk(np.clip(offline.joints[pushed_at] + push, robot.lower, robot.upper))
    assert np.linalg.norm(pushed - offline.positions[pushed_at]) > 0.03
    final = ctrl._last.q
    assert np.linalg.norm(robot.fk(final) - offline.positions[-1]) < 0.01


def test_controller_bad_input(skill: Skill, demos: list[Demonstration]) -> None:
    glass, _ = unseen_glass(demos)
    ctrl = skill.controller({"glass": glass})
    with pytest.raises(ValueError, match=r"q_measured must have shape \(5,\)"):
        ctrl.step([0.0, 0.0])
    with pytest.raises(ValueError, match="q_measured must be finite"):
        ctrl.step([0.0, np.nan, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"unknown object name\(s\) \['cup'\]"):
        ctrl.step(demos[0].joints[0], objects={"cup": [0.4, 0.0, 0.1]})
    with pytest.raises(ValueError, match="max_lag must be > 0"):
        skill.controller({"glass": glass}, max_lag=0.0)
    with pytest.raises(ValueError, match=r"missing position\(s\) for \['glass'\]"):
        skill.controller({})
