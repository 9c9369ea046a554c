"""pbdkit study: the placement grid, the observation noise, and a tiny study end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from typer.testing import CliRunner

from pbdkit import Skill
from pbdkit.apps import study as S
from pbdkit.apps.cli import app
from pbdkit.robots import katana
from pbdkit.sim import experiment as E
from pbdkit.sim.tasks import get_task
from pbdkit.sim.teacher import teach

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


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


def test_observation_noise_has_the_asked_mean_error_on_moving_objects_only() -> None:
    spec = get_task("basin")
    truth = spec.nominal_objects()
    draws = [E.observation_noise(spec, truth, 6.0, seed=1, index=i) for i in range(4000)]
    err = np.array([1e3 * np.linalg.norm(d["glass"] - truth["glass"]) for d in draws])
    assert err.mean() == pytest.approx(6.0, rel=0.03)  # the 3-D length's mean, by construction
    # Isotropic: each axis' standard deviation is 6 / sqrt(8 / pi) mm.
    per_axis = np.std([1e3 * (d["glass"] - truth["glass"]) for d in draws], axis=0)
    np.testing.assert_allclose(per_axis, 6.0 / math.sqrt(8 / math.pi), rtol=0.05)
    assert all(np.array_equal(d["basin"], truth["basin"]) for d in draws)  # fixed: known
    same = E.observation_noise(spec, truth, 6.0, seed=1, index=3)
    np.testing.assert_array_equal(same["glass"], draws[3]["glass"])
    with pytest.raises(ValueError, match="noise_mm"):
        E.observation_noise(spec, truth, -1.0, seed=0, index=0)


@pytest.fixture
def fast_learning(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """learn_task on fast demonstrations and a coarse grid; records the numbers of demos."""
    asked: list[int] = []
    taught = teach("coaster", 5, seed=1, speed=2.0)

    def learn_task(task: object, *, n_demos: int = 5, seed: int = 0, **_: object) -> E.TaskSkill:
        asked.append(n_demos)
        spec = get_task(task)  # type: ignore[arg-type]
        demos = taught[:n_demos]
        objects = E.constrained_objects(spec)
        skill = Skill.learn(demos, katana(), n_steps=100, max_components=3, objects=objects)
        return E.TaskSkill(spec, demos, skill, 0.0, 0.0)

    monkeypatch.setattr(S, "learn_task", learn_task)
    return asked


def test_a_tiny_study_writes_its_report(fast_learning: list[int], tmp_path: Path) -> None:
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
        "coaster", tmp_path, size=size, progress=lambda s, d, t: stages.append(f"{s} {d}/{t}")
    )
    assert fast_learning == [5, 2, 3]  # the study's skill, then the curve's
    total = size.runs(2, 4)
    assert total == 2 * (2 * 2 * 2) + 2 + 2 and stages[-1].endswith(f"{total}/{total}")
    assert set(result["maps"]) == {"glass", "coaster"}
    m = result["maps"]["coaster"]
    assert set(m["success"]) == {"fused", "joint"}
    assert np.array(m["success"]["fused"]).shape == (2, 2)
    # Inside the demonstrated range is a subset of the grid: its rate is defined only there.
    assert m["range"][0] == get_task("coaster").ranges["coaster"].low[:2].tolist()
    assert [c["n_demos"] for c in result["learning_curve"]] == [2, 3]
    assert [c["noise_mm"] for c in result["noise"]] == [0.0, 10.0]
    saved = json.loads((tmp_path / "study.json").read_text())
    assert saved["maps"]["coaster"]["success"] == m["success"]
    for name in ("map_glass.png", "map_coaster.png", "learning_curve.png", "noise.png"):
        assert (tmp_path / name).read_bytes().startswith(PNG_MAGIC)
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    for title in ("Where the skill works", "How many demonstrations", "How much tracking error"):
        assert title in html


def test_study_command_line_errors(tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["study", "--out", str(tmp_path), "--workers", "0"])
    assert r.exit_code != 0 and "must be >= 1" in r.output
    r = CliRunner().invoke(
        app, ["study", "--out", str(tmp_path), "--workers", "2", "--scheduler", "tcp://x:1"]
    )
    assert r.exit_code != 0 and "not both" in r.output
