"""``--perturb rotate`` on the slot task (issue 24): the tray turns by 20-30 degrees about its
centre, its yaw staying in the range, while the block is carried; the online controller follows
it, the trajectory planned offline for the first yaw cannot."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

pytest.importorskip("mujoco")

from typer.testing import CliRunner

from pbdkit.apps._cli import app
from pbdkit.sim import _perturb as P
from pbdkit.sim._evaluation import evaluate
from pbdkit.sim._runs import run_controller, run_online
from pbdkit.sim._scene import Simulation
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import TaskSkill
from pbdkit.sim._taskdefs import slot
from pbdkit.sim._tasks import ObjectTurn, PlacementRange, TaskSpec, yaw_of, yaw_pose
from pbdkit.sim._trials import TrialConditions, trial_disturbance

SLOT = get_task("slot")
#: The trials of the rotate disturbance (seed 0).
ROTATE = TrialConditions(perturb="rotate", seed=0)
YAW_LOW, YAW_HIGH = (math.degrees(v) for v in slot.YAW_RANGE)


def _setup(objects: dict[str, np.ndarray], seed: int) -> P.DisturbanceSetup:
    """A trial of the slot task whose skill closes its gripper at 4 s (step 40 of 0.1 s)."""
    times = 0.1 * np.arange(100, dtype=np.float64)
    gripper = np.where((times >= 4.0) & (times < 8.0), 1.0, 0.0)
    return P.DisturbanceSetup(
        task=SLOT,
        objects=objects,
        times=times,
        gripper=gripper,
        rng=np.random.default_rng(seed),
    )


def _turn(objects: dict[str, np.ndarray], seed: int = 0) -> P.TurnObject:
    act = P.make_disturbance("rotate", _setup(objects, seed))
    assert isinstance(act, P.TurnObject)
    return act


# ------------------------------------------------------------------------------------- the spec
def test_object_turn_refuses_what_it_cannot_do() -> None:
    assert ObjectTurn("tray", (20, 30)).degrees == (20.0, 30.0)
    assert ObjectTurn("tray", (20, 30)).when == "while_carried"
    for degrees in [(0.0, 10.0), (30.0, 20.0), (-5.0, 5.0), (10.0, math.inf), (1.0,), "ab"]:
        with pytest.raises(ValueError, match="degrees must be"):
            ObjectTurn("tray", degrees)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="when must be 'before_grasp' or 'while_carried'"):
        ObjectTurn("tray", (20.0, 30.0), "later")


def _spec(**options: object) -> TaskSpec:
    return TaskSpec(
        name="turn_test",
        description="A block and a tray.",
        ranges={
            "block": PlacementRange.box((0.1, 0.1, 0.0), (0.1, 0.1, 0.0)),
            "tray": PlacementRange.box(
                (0.1, -0.1, 0.0), (0.1, -0.1, 0.0), (-math.pi / 3, math.pi / 3)
            ),
        },
        add_objects=lambda world, objects, rng: None,
        via_points=lambda objects, rng, speed: [],
        judge=SLOT.judge,
        grasped="block",
        **options,  # type: ignore[arg-type]
    )


def test_a_task_turns_an_object_placed_as_a_pose_by_at_most_half_its_yaw_range() -> None:
    assert _spec().rotate is None
    assert _spec(rotate=ObjectTurn("tray", (20.0, 60.0))).rotate is not None
    with pytest.raises(ValueError, match="must be an ObjectTurn of one of its objects"):
        _spec(rotate=ObjectTurn("lid", (20.0, 30.0)))
    with pytest.raises(ValueError, match="must be an ObjectTurn"):
        _spec(rotate=("tray", (20.0, 30.0)))
    with pytest.raises(ValueError, match="'block', which is placed as a position: it needs a yaw"):
        _spec(rotate=ObjectTurn("block", (20.0, 30.0)))
    with pytest.raises(ValueError, match=r"up to 61 degrees does not fit .* half its width, 60"):
        _spec(rotate=ObjectTurn("tray", (20.0, 61.0)))


def test_the_slot_task_turns_its_tray_and_the_other_tasks_turn_nothing() -> None:
    assert SLOT.rotate == ObjectTurn("tray", (20.0, 30.0), "while_carried")
    assert get_task("coaster").rotate is None and get_task("basin").rotate is None
    assert "rotate" in P.perturbation_names()


@pytest.mark.parametrize("task", ["coaster", "basin"])
def test_rotate_refuses_a_task_without_a_turn_in_one_line(task: str) -> None:
    msg = f"task {task!r} has no 'rotate' disturbance (TaskSpec.rotate)"
    with pytest.raises(ValueError, match=msg.replace("(", r"\(").replace(")", r"\)")) as err:
        P.check_perturb("rotate", get_task(task))
    assert "\n" not in str(err.value)
    # Before any teaching: the evaluation and the command line refuse it at once.
    with pytest.raises(ValueError, match="has no 'rotate' disturbance"):
        evaluate(task, 1, 0, perturb="rotate")
    r = CliRunner().invoke(
        app, ["evaluate", "--task", task, "--trials", "1", "--perturb", "rotate"]
    )
    assert r.exit_code != 0 and msg in " ".join(r.output.replace("│", " ").split())


def test_the_command_line_lists_rotate_with_its_help() -> None:
    r = CliRunner().invoke(app, ["evaluate", "--help"])
    words = " ".join(r.output.replace("│", " ").split())
    assert "rotate (an object turns about its centre, the task's TaskSpec.rotate" in words


# ------------------------------------------------------------------------------ the disturbance
def test_the_turn_is_20_to_30_degrees_keeps_the_yaw_in_range_and_starts_when_carried() -> None:
    rng = np.random.default_rng(5)
    signs = set()
    for seed in range(300):
        objects = SLOT.sample_objects(rng)
        yaw0 = math.degrees(yaw_of(objects["tray"]))
        act = _turn(objects, seed)
        size = abs(math.degrees(act.angle))
        assert 20.0 <= size <= 30.0
        assert YAW_LOW - 1e-9 <= yaw0 + math.degrees(act.angle) <= YAW_HIGH + 1e-9
        signs.add(math.copysign(1.0, act.angle))
        # While carried: 1 s after the skill closes its gripper (4 s), for 1 s, well before it
        # opens again (8 s).
        assert act.obj == "tray" and act.grasp_s == pytest.approx(4.0)
        assert act.start == pytest.approx(4.0 + P.TURN_DELAY) and act.duration == 1.0
        assert act.start + act.duration < 8.0
        # The same trial, the same turn.
        assert _turn(objects, seed).angle == act.angle
    assert signs == {1.0, -1.0}
    # Near an end of the range the direction is forced back into it.
    base = SLOT.sample_objects(np.random.default_rng(0))
    for yaw, sign in [(55.0, -1.0), (-55.0, 1.0)]:
        objects = {**base, "tray": yaw_pose(base["tray"][:3, 3], math.radians(yaw))}
        assert all(math.copysign(1.0, _turn(objects, s).angle) == sign for s in range(20))


def test_the_tray_turns_about_its_centre_at_constant_speed() -> None:
    objects = SLOT.sample_objects(np.random.default_rng(3))
    objects["tray"] = yaw_pose(objects["tray"][:3, 3], math.radians(50.0))
    act = P.TurnObject("tray", math.radians(-25.0), start=0.2, duration=0.5)
    with Simulation.from_task(SLOT, objects) as sim:
        sim.refresh()
        centre = sim.object_positions()["tray"]
        tray = sim.model.body("tray").id
        geoms = np.flatnonzero(sim.model.geom_bodyid == tray)
        before = np.array(sim.data.geom_xpos[geoms])

        def yaw_at(t: float) -> float:
            act.apply(sim, t)
            return math.degrees(yaw_of(sim.object_poses()["tray"]))

        assert yaw_at(0.1) == pytest.approx(50.0)
        assert act.as_dict()["initial_yaw_deg"] is None  # not started yet
        assert yaw_at(0.2) == pytest.approx(50.0)
        assert yaw_at(0.45) == pytest.approx(50.0 - 12.5)
        np.testing.assert_allclose(sim.object_positions()["tray"], centre, atol=1e-12)
        assert yaw_at(0.8) == pytest.approx(25.0)
        assert yaw_at(2.0) == pytest.approx(25.0)  # it stays turned
        np.testing.assert_allclose(sim.object_positions()["tray"], centre, atol=1e-12)
        # Every part of the tray turned about the vertical through its centre.
        c, s = math.cos(act.angle), math.sin(act.angle)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        after = np.array(sim.data.geom_xpos[geoms])
        np.testing.assert_allclose(after, (before - centre) @ rot.T + centre, atol=1e-9)
    d = act.as_dict()
    assert d["name"] == "rotate" and d["object"] == "tray"
    assert d["angle_deg"] == pytest.approx(-25.0)
    assert d["initial_yaw_deg"] == pytest.approx(50.0)
    assert d["final_yaw_deg"] == pytest.approx(25.0)


# ------------------------------------------------------------------------- online and offline
@pytest.mark.slow
def test_online_follows_the_turned_tray_where_the_offline_trajectory_misses_it(
    small_task_skill: Callable[..., TaskSkill],
) -> None:
    ts = small_task_skill("slot", 5, seed=1, n_steps=150)
    placement = ts.task.sample_objects(np.random.default_rng(0))
    act = trial_disturbance(ts, ROTATE, placement)
    assert isinstance(act, P.TurnObject)
    grid = np.arange(ts.skill.n_steps) * ts.skill.step_seconds
    t_grasp = P.grasp_time(grid, ts.skill.constraints().gripper)
    assert act.start == pytest.approx(t_grasp + P.TURN_DELAY)
    online = run_online(ts, placement, "fused", disturbance=act)
    offline = run_controller(
        ts, placement, "fused", disturbance=trial_disturbance(ts, ROTATE, placement)
    )
    size = abs(math.degrees(act.angle))
    assert 20.0 <= size <= 30.0
    for run in (online, offline):
        # The block is held all through the turn (carried), and let go after it.
        ex = run.execution
        during = (ex.t >= act.start) & (ex.t <= act.start + act.duration)
        assert during.any() and ex.grasped[during].all()
        assert not ex.gripper[-1]
    yaw = {k: r.execution.outcome.metrics["yaw_error_deg"] for k, r in
           {"online": online, "offline": offline}.items()}  # fmt: skip
    assert online.success and not offline.success
    assert yaw["online"] < 2.0
    assert yaw["offline"] == pytest.approx(size, abs=2.0)  # put in at the tray's first yaw
    # The controller was told the turned tray and planned again for it.
    final = act.as_dict()["final_yaw_deg"]
    told = online.online.objects["tray"][-1]
    assert math.degrees(yaw_of(told)) == pytest.approx(final, abs=1e-6)
    assert online.online.replans > 0
    assert online.online.execution.servo_peaks.worst <= 1.0
