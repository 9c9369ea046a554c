"""End to end through the command line: pbdkit demo / evaluate / teach / learn / reproduce on the
simulated Katana. Few trials, but every artefact is checked."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("mujoco")

from pbdkit.cli import app

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def coaster_demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("demo")
    result = CliRunner().invoke(
        app, ["demo", "--task", "coaster", "--out", str(out), "--seed", "0"]
    )
    assert result.exit_code == 0, result.output
    return out


def test_demo_writes_every_artefact(coaster_demo: Path) -> None:
    for name in ("fig3_cartesian.png", "fig45_constraints.png", "fig6_controllers.png"):
        assert (coaster_demo / name).read_bytes()[:8] == PNG_MAGIC, name
    video = (coaster_demo / "reproduction.mp4").read_bytes()
    assert len(video) > 10_000
    assert video[4:8] == b"ftyp"  # an MP4 container
    assert (coaster_demo / "demos.npz").exists()
    assert (coaster_demo / "skill.npz").exists()


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
    assert all(1 <= k <= 10 for k in m["n_components"].values())
    shares = m["mean_influence_fused"]
    assert sum(shares.values()) == pytest.approx(1.0, abs=1e-9)


def test_report_has_every_section_and_embedded_figures(coaster_demo: Path) -> None:
    html = (coaster_demo / "report.html").read_text(encoding="utf-8")
    for anchor in ("summary", "learned", "cartesian", "controllers", "video", "timings"):
        assert f'id="{anchor}"' in html, anchor
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(images) == 3
    assert 'src="reproduction.mp4"' in html


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
    for row in data["controllers"].values():
        assert 0.0 <= row["success_rate"] <= 1.0


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
        assert data["joints"].shape == (200, 5)
        total = data["influence_joint"] + data["influence_glass"] + data["influence_coaster"]
        np.testing.assert_allclose(total, 1.0, atol=1e-9)


def test_cli_bad_input_is_reported_clearly(tmp_path: Path) -> None:
    runner = CliRunner()
    r = runner.invoke(app, ["reproduce", str(tmp_path / "missing.npz"), "--object", "glass=1,2"])
    assert r.exit_code != 0
    r = runner.invoke(app, ["evaluate", "--task", "juggle"])
    assert r.exit_code != 0
    assert "--task" in r.output
    r = runner.invoke(app, ["learn", str(tmp_path / "d.npz"), "--robot", "r2d2"])
    assert r.exit_code != 0
