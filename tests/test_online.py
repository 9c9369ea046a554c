"""Skills run online in the simulated world: the controller in the physics loop, objects that
slide, an arm that gets pushed, the cameras at 15 Hz (issue 12)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

pytest.importorskip("mujoco")

from typer.testing import CliRunner

from pbdkit.apps._cli import app
from pbdkit.motion._limits import MotionLimits, motion_peaks
from pbdkit.sim import _perturb as P
from pbdkit.sim._evaluation import evaluate
from pbdkit.sim._metrics import peak_speed_ratio
from pbdkit.sim._online import OnlineRun, TruthObserver, execute_online
from pbdkit.sim._perturb import Disturbance, DisturbanceSetup, PushArm, SlideObject, grasp_time
from pbdkit.sim._runs import run_controller, run_online
from pbdkit.sim._scene import Simulation
from pbdkit.sim._sensing import calibrate_tracker, observe
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import TaskSkill
from pbdkit.sim._tasks import TaskSpec
from pbdkit.sim._trials import TrialConditions, trial_disturbance
from pbdkit.sim._world import TIMESTEP


@pytest.fixture(scope="module")
def coaster(small_task_skill: Callable[..., TaskSkill]) -> TaskSkill:
    # Small: 3 fast demonstrations, a coarse time grid (test_parallel.py's too).
    return small_task_skill("coaster", 3, seed=1, n_steps=150)


@pytest.fixture(scope="module")
def placement(coaster: TaskSkill) -> dict[str, np.ndarray]:
    return coaster.task.sample_objects(np.random.default_rng(0))


def _disturbance(ts: TaskSkill, name: str, truth: dict[str, np.ndarray]) -> Disturbance:
    return trial_disturbance(ts, TrialConditions(perturb=name, seed=0), truth)


def test_online_run_equals_the_offline_one_and_keeps_the_limits(
    coaster: TaskSkill, placement: dict[str, np.ndarray]
) -> None:
    ts = coaster
    offline = run_controller(ts, placement, "fused")
    ctrl = ts.skill.controller({k: placement[k] for k in ts.skill.object_names})
    sim = Simulation.from_task(ts.task, placement)
    run = execute_online(sim, ctrl, observer=TruthObserver(ts.skill.object_names))
    assert run.execution.outcome.success and offline.success
    # One command per step of the controller, at its pace, the skill's time stretched where the
    # limits need it as offline; nothing held, no re-plan (the objects do not move).
    np.testing.assert_allclose(np.diff(run.tick_times), ctrl.dt, atol=TIMESTEP + 1e-9)
    # Online, the plans keep the arm within its joint limits where the offline motion passes
    # lift3's (the path brakes onto it harder than the jerk limit lets a motion follow): the
    # steps around it take longer (1.1 s in all; pbdkit.reproduction._planner.make_plan).
    t_offline = ts.skill.times(offline.reproduction)[-1]
    assert abs(len(run.tick_times) * ctrl.dt - t_offline) < 1.5
    # No push is seen. The calibrated skill's hand meets the glass on its shelf such that the
    # glass wobbles by 1.5-3 mm as the gripper closes, and each wobble past REPLAN_DISTANCE
    # (1 mm) is a re-plan (3 measured, 4 before the joints were calibrated against the objects;
    # 0 with calibrate=False): the threshold does not know a grasp from a moved object (issue
    # 35).
    assert run.held_steps == 0 and run.replans <= 4
    assert run.index[-1] == ts.skill.n_steps - 1 and np.all(np.diff(run.index) >= 0)
    # Placed about as well as the offline reproduction: both within a third of the task's 15
    # mm (measured 0.09 mm online, 0.05 offline; 3.6 and 0.1 before the joints were
    # calibrated against the objects, 3.2 and 3.0 before the hand's speed entered the
    # alignment).
    on = run.execution.outcome.metrics["placement_error_mm"]
    assert on < 5.0 and offline.execution.outcome.metrics["placement_error_mm"] < 5.0
    # Consecutive commands within every limit at dt (from the start posture, at rest), and
    # what the servos were sent at 500 Hz too; the measured arm speed within 5 % of the limit.
    limits = MotionLimits.from_robot(ts.skill.robot, 5)
    q = np.vstack([sim_start(run), run.commands])
    assert motion_peaks(ctrl.dt * np.arange(len(q)), q, limits).worst <= 1.0 + 1e-9
    assert run.execution.servo_peaks.worst <= 1.0
    assert peak_speed_ratio(run.execution, limits.velocity) < 1.05


def sim_start(run: OnlineRun) -> np.ndarray:
    """The posture the run started from (its first recorded servo target), (1, n)."""
    return np.asarray(run.execution.servo_targets[:1])


@pytest.mark.slow
def test_a_sliding_coaster_is_followed_online_and_missed_offline(
    coaster: TaskSkill, placement: dict[str, np.ndarray]
) -> None:
    ts = coaster
    move = _disturbance(ts, "move", placement)
    assert isinstance(move, SlideObject) and move.obj == "coaster"
    assert np.linalg.norm(move.displacement) == pytest.approx(0.05)
    t_grasp = grasp_time(
        np.arange(ts.skill.n_steps) * ts.skill.step_seconds, ts.skill.constraints().gripper
    )
    assert move.start == pytest.approx(t_grasp + 0.5)
    online = run_online(ts, placement, "fused", disturbance=move)
    final = move.as_dict()["final_position"]
    np.testing.assert_allclose(online.execution.objects["coaster"][-1], final, atol=1e-12)
    offline = run_controller(
        ts, placement, "fused", disturbance=_disturbance(ts, "move", placement)
    )
    # An offline reproduction that knew the final place from the start, for reference.
    knew = {**placement, "coaster": np.array(final)}
    reference = run_controller(ts, knew, "fused")
    err = {
        k: r.execution.outcome.metrics["placement_error_mm"]
        for k, r in {"online": online, "offline": offline, "knew": reference}.items()
    }
    assert online.success and reference.success and not offline.success
    # Measured: 3.5 mm (0.1 and 3.6 mm; under 3 before the gripper was scored in the joint
    # space's K).
    assert abs(err["online"] - err["knew"]) < 4.5
    assert err["offline"] == pytest.approx(50.0, abs=10.0)  # missed by the displacement
    # The controller was told where the coaster went: its last position is the final one.
    np.testing.assert_allclose(online.online.objects["coaster"][-1], final, atol=1e-9)


@pytest.mark.slow
def test_a_pushed_arm_yields_and_is_steered_back_while_offline_snaps_back(
    coaster: TaskSkill, placement: dict[str, np.ndarray]
) -> None:
    ts = coaster
    push = _disturbance(ts, "push", placement)
    assert isinstance(push, PushArm)
    assert np.linalg.norm(push.force) == pytest.approx(40.0) and push.force[2] == 0.0
    online = run_online(ts, placement, "fused", disturbance=push)
    offline = run_controller(
        ts, placement, "fused", disturbance=_disturbance(ts, "push", placement)
    )
    assert online.success
    on, off = online.as_dict(), offline.as_dict()
    # The push was felt: the phase held while the arm was shoved, and the plan restarted.
    assert on["phase_held_steps"] > 0 and online.online.replans > 0
    # Outside the push, online: within the velocity limits (5 % for the servos), a small
    # following error, the servo stream within every limit. Offline the servos snap the arm
    # back to its old reference: several times the limits, a following error a real drive
    # would fault on.
    assert on["peak_speed_ratio"] < 1.05 and on["following_error_rad"] < 0.15
    assert max(on[f"peak_{k}_ratio"] for k in ("velocity", "acceleration", "jerk")) <= 1.0
    assert off["peak_speed_ratio"] > 3.0 and off["following_error_rad"] > 0.3
    assert online.execution.t[-1] > offline.execution.t[-1]  # the held phase took time


@pytest.mark.slow
def test_online_with_the_cameras_holds_the_grasped_glass_and_the_hidden_coaster(
    coaster: TaskSkill, placement: dict[str, np.ndarray]
) -> None:
    ts = coaster
    tracker = calibrate_tracker(ts)
    seen = observe(ts.task, placement, tracker, arm=ts.start_posture)
    run = run_online(
        ts,
        seen,
        "fused",
        tracker=tracker,
        sim_objects=placement,
        disturbance=_disturbance(ts, "move", placement),
    )
    assert run.success
    tracking = run.online.tracking
    assert tracking is not None
    frames = tracking["frames"]
    # The glass is held from the grasp on; the arm hides the coaster while placing.
    assert frames["glass"]["held"] > 0 and frames["glass"]["ok"] > 0
    assert frames["coaster"].get("occluded", 0) > 0
    # The glass position the controller used is constant from the grasp on.
    grasp_tick = int(np.argmax(run.online.index >= ts.skill.constraints().gripper.argmax()))
    glass_used = run.online.objects["glass"][grasp_tick:]
    assert np.ptp(glass_used, axis=0).max() == 0.0
    # Accepted estimates are good ones.
    for stats in tracking["accepted_error_mm"].values():
        assert stats["max"] < 5.0


def test_evaluate_records_the_perturbation(
    coaster: TaskSkill,
) -> None:
    ev = evaluate(
        "coaster",
        1,
        0,
        task_skill=coaster,
        controllers=["fused"],
        ground_truth=True,
        online=True,
        perturb="move",
    )
    data = ev.as_dict()
    assert data["online"] is True and data["perturb"] == "move"
    (p,) = data["perturbations"]
    assert p["name"] == "move" and p["object"] == "coaster"
    assert np.linalg.norm(p["displacement_m"]) == pytest.approx(0.05)
    r = coaster.task.ranges["coaster"]
    assert np.all(np.array(p["final_position"][:2]) >= r.low[:2] - 1e-9)
    assert np.all(np.array(p["final_position"][:2]) <= r.high[:2] + 1e-9)
    (row,) = data["runs"]["fused"]
    assert {"phase_held_steps", "peak_speed_ratio", "following_error_rad"} <= set(row)
    with pytest.raises(ValueError, match="perturb must be one of"):
        evaluate("coaster", 1, 0, task_skill=coaster, perturb="shake")


class Tap(Disturbance):
    """A test's own disturbance: a light horizontal force on the gripper, from the grasp on."""

    name = "tap"

    def __init__(self, force: np.ndarray, start: float) -> None:
        self.force, self.start = force, start

    def apply(self, sim: Simulation, t: float) -> None:
        bid = sim.model.body("gripper").id
        sim.data.xfrc_applied[bid, :3] = self.force if self.start <= t < self.start + 0.1 else 0.0

    def as_dict(self) -> dict[str, object]:
        return {"name": self.name, "force_n": self.force.tolist(), "start_s": self.start}


def _tap(setup: DisturbanceSetup) -> Disturbance:
    seen.append(setup)
    return Tap(setup.rng.normal(0.0, 1.0, 3) * [1.0, 1.0, 0.0], setup.grasp_time())


seen: list[DisturbanceSetup] = []


def _refuse_basin(task: TaskSpec) -> None:
    if task.name == "basin":
        raise ValueError("tap: the basin task is not tapped")


def test_a_perturbation_is_one_registry_entry(coaster: TaskSkill) -> None:
    assert P.perturbation_names()[:3] == ("none", "move", "push")
    assert list(P.PERTURBATIONS) == list(P.perturbation_names())
    tap = P.Perturbation("tap", "a 1 N tap on the gripper at the grasp", _tap, check=_refuse_basin)
    with pytest.raises(ValueError, match="perturb must be one of \\['none', 'move', 'push'"):
        P.get_perturbation("tap")
    with pytest.raises(ValueError, match="'push' is already registered"):
        P.register_perturbation(P.Perturbation("push", "again", _tap))
    with pytest.raises(ValueError, match="help of perturbation 'x' must be a non-empty string"):
        P.Perturbation("x", " ", _tap)
    P.register_perturbation(tap)
    try:
        assert P.get_perturbation("tap") is tap and "tap" in P.PERTURBATIONS
        # The command line's choices and help come from the registry.
        r = CliRunner().invoke(app, ["evaluate", "--perturb", "shake"])
        said = " ".join(r.output.replace("│", " ").split())  # the error box's lines wrap
        assert r.exit_code == 2 and "must be one of none, move, push, rotate, obstacle, tap" in said
        r = CliRunner().invoke(app, ["evaluate", "--help"])
        words = " ".join(r.output.replace("│", " ").split())  # the help's lines wrap
        assert "or tap (a 1 N tap on the gripper at the grasp)." in words
        assert "push (a 0.3 s shove on the arm halfway to the grasp)" in words
        assert "{perturbations}" not in words
        # The demo's report says what a user's perturbation did (a KeyError before).
        from pbdkit.apps._demo import _perturbation_words

        words_tap = _perturbation_words({"name": "tap", "force_n": [1.0, 0.0, 0.0]})
        assert words_tap == "tap: a 1 N tap on the gripper at the grasp"
        # A trial runs it, drawn from the trial's own stream, with what it needs to know.
        ev = evaluate("coaster", 1, 0, task_skill=coaster, controllers=["fused"],
                        ground_truth=True, perturb="tap")  # fmt: skip
        (p,) = ev.as_dict()["perturbations"]
        assert p["name"] == "tap" and ev.conditions.perturb == "tap"
        setup = seen[-1]
        assert setup.task is coaster.task and set(setup.objects) == {"glass", "coaster"}
        assert p["start_s"] == pytest.approx(setup.grasp_time())
        again = trial_disturbance(coaster, ev.conditions, ev.trials[0].truth).as_dict()
        assert again == p
        with pytest.raises(ValueError, match="the basin task is not tapped"):
            evaluate("basin", 1, 0, perturb="tap")
    finally:
        assert P.unregister_perturbation("tap") is tap
    assert "tap" not in P.perturbation_names()


def test_objects_slide_and_static_ones_refuse() -> None:
    sim = Simulation.from_task(get_task("coaster"))
    start = sim.object_positions()
    d = np.array([0.03, -0.04, 0.0])
    glass = SlideObject("glass", d, start=0.1, duration=0.5)
    mat = SlideObject("coaster", -d, start=0.1, duration=0.5)
    for k in range(round(1.0 / TIMESTEP)):
        glass.apply(sim, k * TIMESTEP)
        mat.apply(sim, k * TIMESTEP)
        sim.step()
    sim.refresh()
    now = sim.object_positions()
    np.testing.assert_allclose(now["coaster"], start["coaster"] - d, atol=1e-12)
    np.testing.assert_allclose(now["glass"], start["glass"] + d, atol=1e-3)  # stays where it slid
    assert sim.grasped_tilt() < 0.02
    with pytest.raises(ValueError, match="cannot move"):
        Simulation.from_task(get_task("basin")).place_object("basin", [0.3, 0.0, 0.0])
    with pytest.raises(ValueError, match="finite"):
        sim.place_object("coaster", [0.3, np.nan, 0.0])


def test_execute_online_refuses_a_used_controller(coaster: TaskSkill, placement: dict) -> None:
    ctrl = coaster.skill.controller({k: placement[k] for k in coaster.skill.object_names})
    ctrl.step(ctrl.target)
    with pytest.raises(ValueError, match="already run"):
        execute_online(Simulation.from_task(get_task("coaster"), placement), ctrl)
