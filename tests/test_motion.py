"""Motion a real arm accepts (issue 20), on the simulated teacher's skills: for teach seeds 0-9
of both tasks, the mean placement and three placements 4 cm from it, the default reproduction,
the online command stream under encoder noise and the 1 kHz setpoint stream are within the
Katana's velocity, acceleration and jerk limits (divided differences at their own samples,
padded with rest at both ends), with no joint reversing between two fast steps; the Newton
term removes the limit cycle Gauss-Newton falls into; placement accuracy is kept."""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np
import pytest

pytest.importorskip("mujoco")

from pbdkit import Skill
from pbdkit.motion._limits import MotionLimits, count_reversals, motion_peaks
from pbdkit.reproduction import _steps
from pbdkit.reproduction._probabilistic_ik import solve
from pbdkit.reproduction._result import ReproductionResult
from pbdkit.reproduction._setup import RunOptions, step_limit_from_velocity
from pbdkit.robots import katana
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import constrained_objects, teach

pytestmark = pytest.mark.slow

SEEDS = range(10)
TASKS = ("coaster", "basin")
NOISE = 1e-5  # rad: encoder-level noise on the measured posture


@functools.cache
def _skill(task: str, seed: int) -> tuple[Skill, list[dict[str, np.ndarray]]]:
    """The skill of teach seed ``seed`` (5 demonstrations, Skill.learn's defaults) and its
    placements: the demonstrations' mean, and three 4 cm from it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        demos = teach(task, 5, seed=seed)
        skill = Skill.learn(demos, katana(), task_objects=constrained_objects(get_task(task)))
    mean = {k: np.mean([d.objects[k] for d in demos], axis=0) for k in skill.object_names}
    off = [0.04 * np.array([np.cos(a), np.sin(a), 0.0]) for a in (0.3, 2.4, 4.5)]
    return skill, [mean, *({k: v + o for k, v in mean.items()} for o in off)]


def _tight_error(skill: Skill, res: ReproductionResult, objects: dict[str, np.ndarray]) -> float:
    """The hand's largest distance (m) from o + x_hat at each object's tightest step."""
    c = skill.constraints()
    errs = []
    for k in skill.object_names:
        tight = int(np.argmin(np.trace(c.task_cov[k], axis1=1, axis2=2)))
        i = int(np.flatnonzero(res.t == tight)[-1])
        errs.append(float(np.linalg.norm(res.positions[i] - objects[k] - c.task_mean[k][tight])))
    return max(errs)


@pytest.mark.parametrize("task", TASKS)
def test_reproductions_are_within_the_limits_without_reversals(task: str) -> None:
    limits = MotionLimits.from_robot(katana(), 5)
    worst, reversals, errors, stretch = 0.0, 0, [], []
    for seed in SEEDS:
        skill, placements = _skill(task, seed)
        for objects in placements:
            res = skill.reproduce(objects)
            t = skill.times(res)
            worst = max(worst, motion_peaks(t, res.joints, limits).worst)
            reversals += count_reversals(res.joints, np.diff(t), limits.velocity)
            errors.append(_tight_error(skill, res, objects))
            stretch.append(res.stretch)
    assert worst <= 1.0 + 1e-9  # measured: 0.995 (the limits times LIMIT_SAFETY)
    # Measured: 0 on the basin; 1 on the coaster since calibration (issue 34), a one-step
    # excursion of the fused loop and back at the end of one of the 40 reproductions, not a
    # limit cycle (before the limits: reversals on 19 of 80 runs).
    assert reversals <= 2
    # The hand where the constraints ask at their tightest (measured: median 0.9 / 2.3 mm on
    # coaster / basin, as before the limits (0.9 / 2.7 mm), worst 11 mm where a placement 4 cm
    # off lies outside the demonstrated range), and the skill's pace kept but where the limits
    # bind (stretch 1.00-1.51).
    assert np.median(errors) < 3e-3 and max(errors) < 0.02
    assert min(stretch) >= 1.0 and np.median(stretch) < 1.1 and max(stretch) < 2.0


@pytest.mark.parametrize("task", TASKS)
def test_online_commands_and_the_1khz_stream_are_within_the_limits(task: str) -> None:
    limits = MotionLimits.from_robot(katana(), 5)
    rng = np.random.default_rng(20 + TASKS.index(task))
    worst_cmd = worst_stream = 0.0
    reversals, replans, held = 0, 0, 0
    for seed in SEEDS:
        skill, placements = _skill(task, seed)
        for i, objects in enumerate(placements):
            ctrl = skill.controller(objects)
            q = skill.constraints().joint_mean[0] + rng.normal(0.0, 0.02, 5)  # the arm's start
            measured = q + rng.normal(0.0, NOISE, 5)
            rows = [measured]
            while not ctrl.done:
                cmd = ctrl.step(measured)
                held += cmd.held
                rows.append(cmd.q)
                measured = cmd.q + rng.normal(0.0, NOISE, 5)
            cmds = np.array(rows)
            worst_cmd = max(
                worst_cmd, motion_peaks(ctrl.dt * np.arange(len(cmds)), cmds, limits).worst
            )
            reversals += count_reversals(cmds, ctrl.dt, limits.velocity)
            replans += ctrl.replans
            if i == 0:  # the 1 kHz stream, at the mean placement
                ctrl = skill.controller(objects)
                stream = ctrl.stream(1000.0)
                measured = q + rng.normal(0.0, NOISE, 5)
                setpoints = [measured]
                while not stream.done:
                    setpoints.append(stream.step(measured))
                    measured = setpoints[-1] + rng.normal(0.0, NOISE, 5)
                s = np.array(setpoints)
                worst_stream = max(
                    worst_stream, motion_peaks(1e-3 * np.arange(len(s)), s, limits).worst
                )
                reversals += count_reversals(s, 1e-3, limits.velocity)
    assert worst_cmd <= 1.0 + 1e-9 and worst_stream <= 1.0 + 1e-9  # measured: 0.995, 0.995
    assert reversals == 0 and replans == 0 and held == 0


def test_the_newton_term_removes_the_limit_cycle_of_gauss_newton(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Issue 20: where a tight task constraint meets a loose joint constraint, Gauss-Newton
    # (with its line search) settles into a limit cycle at the velocity bound: a joint
    # reverses between consecutive fast steps. Measured over teach seeds 0-9 and 4 placements:
    # 35-128 reversals in 6 of the 40 coaster reproductions, none with the Newton term (issue
    # 20's skills). With the reversal damping (issue 34) both make the default.
    skill, placements = _skill("coaster", 0)
    robot = skill.robot
    bound = step_limit_from_velocity("robot", robot, skill.step_seconds)
    vmax = np.asarray(robot.velocity_limit)
    objects = placements[1]
    runs = {}
    for newton, damped in ((False, False), (True, False), (True, True)):
        monkeypatch.setattr(_steps, "REVERSAL_FRACTION", 0.25 if damped else math.inf)
        runs[newton, damped] = solve(
            robot,
            skill.constraints(),
            objects,
            RunOptions(newton=newton),
            step_limit=bound,
            reach=skill.reach,
        )
    flips = {k: count_reversals(r.joints, skill.step_seconds, vmax) for k, r in runs.items()}
    # Measured: 230 (Gauss-Newton), 0 (Newton), 0 (Newton and the damping). With the joints
    # widened by their own z, before they were calibrated against the objects: 363, 78, 7
    # (single reversals of joint 4, and one of joint 2, 4-11 steps apart: no cycle).
    assert flips[False, False] > 50 and flips[True, False] < 0.25 * flips[False, False]
    assert flips[True, True] <= 10
    q = runs[True, True].joints
    speed = np.diff(q, axis=0) / skill.step_seconds
    fast = np.abs(speed) > 0.25 * vmax
    reversed_ = (np.sign(speed[1:]) * np.sign(speed[:-1]) < 0) & fast[1:] & fast[:-1]
    for j in range(q.shape[1]):  # no cycle: a joint's reversals at least 3 steps apart
        assert np.all(np.diff(np.flatnonzero(reversed_[:, j])) >= 3)
    runs = {newton: runs[newton, newton] for newton in (False, True)}
    # ... and it does not cost accuracy: the hand at least as close at the tight steps.
    assert (
        _tight_error(skill, runs[True], objects) <= _tight_error(skill, runs[False], objects) + 1e-4
    )


def test_the_reversal_damping_breaks_the_cycle_of_conflicting_constraints(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Issue 34: the placement 4 cm off at 0.3 rad, the skill aligned with the hand's offset
    # stretched near the objects (NEAR_SCALE 5 cm). There the glass's constraint (2-3.5 mm
    # off) and the coaster's pull apart on bounded steps, and the fused loop (with the Newton
    # term) fell into a period-2 cycle of joints 2 and 4 (+-55-62 mrad a step, 16 reversals,
    # on teach seed 7). A fast step in which a joint reverses now lands between the two
    # postures. With the joints calibrated against the objects, teach seed 7 no longer cycles
    # (2 reversals); of teach seeds 0-9 at four such placements, 3 cycle undamped (20-42
    # reversals), none damped: seed 2 here. (With the default alignment none of the 80
    # reproductions above cycles, damped or not.)
    from pbdkit.data import _align

    monkeypatch.setattr(_align, "NEAR_SCALE", 0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        demos = teach("coaster", 5, seed=2)
        skill = Skill.learn(demos, katana(), task_objects=constrained_objects(get_task("coaster")))
    mean = {k: np.mean([d.objects[k] for d in demos], axis=0) for k in skill.object_names}
    objects = {k: v + 0.04 * np.array([np.cos(0.3), np.sin(0.3), 0.0]) for k, v in mean.items()}
    limits = MotionLimits.from_robot(katana(), 5)

    def reproduce() -> tuple[int, float]:
        res = skill.reproduce(objects)
        t = skill.times(res)
        return count_reversals(res.joints, np.diff(t), limits.velocity), _tight_error(
            skill, res, objects
        )

    damped, damped_error = reproduce()
    monkeypatch.setattr(_steps, "REVERSAL_FRACTION", math.inf)
    cycling, cycling_error = reproduce()
    assert cycling > 10 and damped == 0  # measured: 42 and 0
    assert damped_error <= cycling_error + 1e-4
