"""pbdkit study: the placement grid, the observation noise, and a tiny study end to end."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from typer.testing import CliRunner

from pbdkit import Skill
from pbdkit.apps import _study as S
from pbdkit.apps._cli import app
from pbdkit.robots import katana
from pbdkit.sim._sensing import observation_noise
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import TaskSkill, constrained_objects
from pbdkit.sim._tasks import TaskSpec

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _not_json(name: str) -> object:
    """json.loads accepts NaN and Infinity, which strict JSON (RFC 8259) does not."""
    raise ValueError(f"{name} is not JSON")


def test_grid_spans_twice_the_range_with_the_others_nominal() -> None:
    spec = get_task("coaster")
    xs, ys, places = S.grid_placements(spec, "coaster", 5)
    r = spec.ranges["coaster"]
    c, h = r.center, (r.high - r.low) / 2
    np.testing.assert_allclose([xs[0], xs[-1]], [c[0] - 2 * h[0], c[0] + 2 * h[0]])
    np.testing.assert_allclose([ys[0], ys[-1]], [c[1] - 2 * h[1], c[1] + 2 * h[1]])
    assert len(places) == 25
    np.testing.assert_allclose(places[7]["coaster"], [xs[2], ys[1], c[2]])  # row-major
    for p in places:
        np.testing.assert_array_equal(p["glass"], spec.ranges["glass"].center)
    with pytest.raises(ValueError, match="fixed"):
        S.grid_placements(get_task("basin"), "basin", 3)


def test_a_posed_objects_grid_spans_x_and_twice_its_yaw_range() -> None:
    """The slot's tray is mapped over x and yaw (y at the range's centre), the yaw from -120 to
    120 degrees for a -60..60 range; the block stays at its nominal pose."""
    from pbdkit.sim._tasks import yaw_of

    spec = get_task("slot")
    xs, yaws, places = S.grid_placements(spec, "tray", 5)
    r = spec.ranges["tray"]
    np.testing.assert_allclose(np.degrees([yaws[0], yaws[-1]]), [-120.0, 120.0])
    assert len(places) == 25
    tray = places[7]["tray"]  # row-major: x index 2, yaw index 1
    assert tray.shape == (4, 4)
    np.testing.assert_allclose(tray[:3, 3], [xs[2], r.center[1], r.center[2]])
    assert yaw_of(tray) == pytest.approx(yaws[1])
    for p in places:
        np.testing.assert_array_equal(p["block"], spec.ranges["block"].nominal())


def test_observation_noise_has_the_asked_mean_error_on_moving_objects_only() -> None:
    spec = get_task("basin")
    truth = spec.nominal_objects()
    draws = [observation_noise(spec, truth, 6.0, seed=1, index=i) for i in range(4000)]
    err = np.array([1e3 * np.linalg.norm(d["glass"] - truth["glass"]) for d in draws])
    assert err.mean() == pytest.approx(6.0, rel=0.03)  # the 3-D length's mean, by construction
    # Isotropic: each axis' standard deviation is 6 / sqrt(8 / pi) mm.
    per_axis = np.std([1e3 * (d["glass"] - truth["glass"]) for d in draws], axis=0)
    np.testing.assert_allclose(per_axis, 6.0 / math.sqrt(8 / math.pi), rtol=0.05)
    assert all(np.array_equal(d["basin"], truth["basin"]) for d in draws)  # fixed: known
    same = observation_noise(spec, truth, 6.0, seed=1, index=3)
    np.testing.assert_array_equal(same["glass"], draws[3]["glass"])
    with pytest.raises(ValueError, match="noise_mm"):
        observation_noise(spec, truth, -1.0, seed=0, index=0)


@pytest.fixture(scope="module")
def taught(fast_demos: Callable[..., list]) -> list:
    """Five fast demonstrations of the coaster task (durations halved)."""
    return fast_demos("coaster", 5, seed=1)


class FastLearning:
    """A learner injected into run_study: the first n of :func:`taught` on a coarse grid.
    Records the numbers of demonstrations asked; fails on the call number ``fail_at``."""

    def __init__(self, taught: list, fail_at: int | None = None) -> None:
        self.taught = taught
        self.fail_at = fail_at
        self.asked: list[int] = []

    def __call__(self, spec: TaskSpec, *, n_demos: int, seed: int) -> TaskSkill:
        self.asked.append(n_demos)
        if len(self.asked) == self.fail_at:
            raise RuntimeError("the teacher dropped the glass")
        demos = self.taught[:n_demos]
        objects = constrained_objects(spec)
        skill = Skill.learn(demos, katana(), n_steps=100, max_components=3, task_objects=objects)
        return TaskSkill(task=spec, demos=demos, skill=skill, learn_seconds=0.0, teach_seconds=0.0)


@pytest.fixture
def fast_learning(taught: list) -> FastLearning:
    return FastLearning(taught)


@pytest.mark.slow
def test_a_tiny_study_writes_its_report(fast_learning: FastLearning, tmp_path: Path) -> None:
    size = S.StudySize(
        grid=2,
        demos=(2, 3),
        curve_trials=1,
        noise_mm=(0.0, 10.0),
        noise_trials=1,
        map_controllers=("fused", "joint"),
    )
    stages: list[str] = []
    result = S.run_study(
        get_task("coaster"),
        tmp_path,
        size=size,
        progress=lambda s, d, t: stages.append(f"{s} {d}/{t}"),
        learn=fast_learning,
    )
    assert fast_learning.asked == [5, 2, 3]  # the study's skill, then the curve's
    total = size.runs(2, 4)
    assert total == 2 * (2 * 2 * 2) + 2 + 2 and stages[-1].endswith(f"{total}/{total}")
    assert set(result["maps"]) == {"glass", "coaster"}
    m = result["maps"]["coaster"]
    assert set(m["success"]) == {"fused", "joint"}
    assert np.array(m["success"]["fused"]).shape == (2, 2)
    # Inside the demonstrated range is a subset of the grid: its rate is defined only there.
    assert m["range"][0] == get_task("coaster").ranges["coaster"].low[:2].tolist()
    # A 2 x 2 grid spanning twice the range has no point inside it: no rate (null, not NaN).
    assert m["inside_range"] == {"fused": None, "joint": None}
    assert [c["n_demos"] for c in result["learning_curve"]] == [2, 3]
    assert [c["noise_mm"] for c in result["noise"]] == [0.0, 10.0]
    saved = json.loads((tmp_path / "study.json").read_text(), parse_constant=_not_json)
    assert not list(tmp_path.glob(".partial-*"))  # the staging folder is gone
    assert saved["maps"]["coaster"]["success"] == m["success"]
    for name in ("map_glass.png", "map_coaster.png", "learning_curve.png", "noise.png"):
        assert (tmp_path / name).read_bytes().startswith(PNG_MAGIC)
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    for title in ("Where the skill works", "How many demonstrations", "How much tracking error"):
        assert title in html


@pytest.mark.slow
def test_a_tiny_study_of_the_slot_maps_position_and_yaw(
    fast_demos: Callable[..., list], tmp_path: Path
) -> None:
    """The slot's objects are poses: each map is over x and the yaw, and its report says so
    (the study ran end to end on the posed task)."""
    size = S.StudySize(
        grid=2,
        demos=(3,),
        curve_trials=1,
        noise_mm=(0.0,),
        noise_trials=1,
        map_controllers=("fused",),
    )
    result = S.run_study(
        get_task("slot"), tmp_path, size=size, learn=FastLearning(fast_demos("slot", 5, 1))
    )
    assert set(result["maps"]) == {"block", "tray"}
    for name, m in result["maps"].items():
        assert set(m) >= {"x", "yaw"} and "y" not in m
        r = get_task("slot").ranges[name]
        assert r.yaw is not None
        assert min(m["yaw"]) < r.yaw[0] and max(m["yaw"]) > r.yaw[1]  # twice the range
        assert np.array(m["success"]["fused"]).shape == (2, 2)
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert "the block placed and turned" in html and "x and yaw (2 x 2" in html
    assert (tmp_path / "map_tray.png").read_bytes().startswith(PNG_MAGIC)


def test_study_command_line_errors(tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["study", "--out", str(tmp_path), "--workers", "0"])
    assert r.exit_code != 0 and "must be >= 1" in r.output
    r = CliRunner().invoke(
        app, ["study", "--out", str(tmp_path), "--workers", "2", "--scheduler", "tcp://x:1"]
    )
    assert r.exit_code != 0 and "not both" in r.output


SIZE = {
    "grid": 2,
    "demos": (2, 3),
    "curve_trials": 1,
    "noise_mm": (0.0, 10.0),
    "noise_trials": 1,
}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"noise_mm": (0.0, -5.0)}, r"StudySize.noise_mm\[1\] must be finite and >= 0, got -5.0"),
        ({"noise_mm": (math.nan,)}, r"StudySize.noise_mm\[0\] must be finite and >= 0, got nan"),
        ({"noise_mm": (2.0, math.inf)}, r"StudySize.noise_mm\[1\] must be finite .* got inf"),
        ({"noise_mm": (True,)}, r"StudySize.noise_mm\[0\] must be a number, got True"),
        ({"noise_mm": ()}, r"StudySize.noise_mm must not be empty, got \(\)"),
        ({"grid": 0}, r"StudySize.grid must be >= 2, got 0"),
        ({"grid": 1}, r"StudySize.grid must be >= 2, got 1"),
        ({"grid": 2.5}, r"StudySize.grid must be an integer, got 2.5"),
        ({"grid": True}, r"StudySize.grid must be an integer, got True"),
        ({"demos": (1,)}, r"StudySize.demos\[0\] must be >= 2, got 1"),
        ({"demos": (2, 2)}, r"StudySize.demos must not repeat a value, got \(2, 2\)"),
        ({"demos": 5}, r"StudySize.demos must be a tuple, got 5"),
        ({"curve_trials": 0}, r"StudySize.curve_trials must be >= 1, got 0"),
        ({"noise_trials": -1}, r"StudySize.noise_trials must be >= 1, got -1"),
        ({"map_controllers": ()}, r"StudySize.map_controllers must not be empty "
         r"\(None: every controller\), got \(\)"),
        ({"map_controllers": ("fused", "fused")}, r"map_controllers must not repeat a value"),
        ({"map_controllers": "fused"}, r"StudySize.map_controllers must be a tuple, got 'fused'"),
    ],
)  # fmt: skip
def test_a_size_no_study_can_run_is_refused_on_construction(
    change: dict[str, object], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        S.StudySize(**{**SIZE, **change})  # type: ignore[arg-type]


def test_sizes_are_kept_as_tuples() -> None:
    lists = {"demos": [2, np.int64(3)], "map_controllers": ["fused"]}
    size = S.StudySize(**{**SIZE, **lists})  # type: ignore[arg-type]
    assert size.demos == (2, 3) and size.map_controllers == ("fused",)
    assert size.runs(2, 4) == 2 * 4 * 1 + 2 + 2
    assert S.SMALL.runs(1, 3) == 25 * 3 + 5 * 6 + 6 * 6  # the shipped sizes are valid


def _never(*args: object, **kwargs: object) -> TaskSkill:
    raise AssertionError("the study taught or learned before checking its arguments")


@pytest.mark.parametrize(
    ("task", "kwargs", "message"),
    [
        # The basin is fixed: the paper's skill (the default learner) has no constraint on it.
        ("basin", {"size": S.StudySize(**SIZE, map_controllers=("task:basin",))},
         r"StudySize.map_controllers must name controllers of \['fused', 'joint', "
         r"'task:glass'\], got 'task:basin'"),
        ("coaster", {"size": S.StudySize(**SIZE, map_controllers=("fused", "task:cup")),
                     "learn": _never}, r"got 'task:cup'"),
        ("coaster", {"seed": -1, "learn": _never}, r"seed must be >= 0, got -1"),
        ("coaster", {"size": SIZE, "learn": _never}, r"size must be a StudySize"),
        ("juggle", {"learn": _never}, r"spec must be a TaskSpec .*got 'juggle'"),
    ],
)  # fmt: skip
def test_run_study_checks_its_arguments_before_any_physics(
    tmp_path: Path, task: str, kwargs: dict[str, object], message: str
) -> None:
    out = tmp_path / "study"
    spec = get_task(task) if task != "juggle" else task  # a name is refused
    with pytest.raises(ValueError, match=message):
        S.run_study(spec, out, **kwargs)  # type: ignore[arg-type]
    assert not out.exists()


def test_a_failed_study_leaves_the_output_as_it_found_it(tmp_path: Path) -> None:
    size = S.StudySize(**SIZE)
    # A folder the study creates (and its missing parent) is removed again.
    out = tmp_path / "new" / "study"
    with pytest.raises(RuntimeError, match="dropped the glass"):
        S.run_study(get_task("coaster"), out, size=size, learn=FastLearning([], fail_at=1))
    assert not (tmp_path / "new").exists()
    # A folder the user made is kept, with what it held and nothing more.
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    with pytest.raises(RuntimeError, match="dropped the glass"):
        S.run_study(get_task("coaster"), mine, size=size, learn=FastLearning([], fail_at=1))
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    # Not a folder: refused before anything is created.
    with pytest.raises(ValueError, match=r"out must be a directory, got .*notes.txt"):
        S.run_study(get_task("coaster"), mine / "notes.txt" / "x", size=size, learn=_never)


@pytest.mark.slow
def test_a_study_failing_after_its_maps_writes_nothing(taught: list, tmp_path: Path) -> None:
    # The maps run and are drawn, then learning the curve's first skill fails: the map's
    # figure was written to the staging folder only.
    size = S.StudySize(**SIZE, map_controllers=("joint",))
    (tmp_path / "study.json").write_text("{}")  # an earlier study's, kept as it was
    learn = FastLearning(taught, fail_at=2)
    with pytest.raises(RuntimeError, match="dropped the glass"):
        S.run_study(get_task("coaster"), tmp_path, size=size, learn=learn)
    assert learn.asked == [5, 2]
    assert [p.name for p in tmp_path.iterdir()] == ["study.json"]
    assert (tmp_path / "study.json").read_text() == "{}"


def test_study_command_line_reports_bad_input_without_creating_the_folder(
    tmp_path: Path,
) -> None:
    out = tmp_path / "study"
    r = CliRunner().invoke(app, ["study", "--out", str(out), "--seed", "-1"])
    assert r.exit_code == 2 and "seed" in r.output and ">= 0" in r.output, r.output
    assert "Traceback" not in r.output and len(r.output.strip().splitlines()) == 1
    assert not out.exists()
