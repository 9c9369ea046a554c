"""The pbdkit command line: the LASA demo writes a valid figure and consistent metrics."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from pbdkit.cli import app
from pbdkit.gmm import CV_TOLERANCE

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_demo_lasa_writes_figure_and_metrics(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app, ["demo", "--task", "lasa", "--shape", "Angle", "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    png = tmp_path / "lasa_Angle.png"
    assert png.read_bytes()[:8] == PNG_MAGIC
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["shape"] == "Angle"
    sel = metrics["selection"]
    k = metrics["n_components"]
    assert sel["method"] == "cv" and sel["chosen"] == k
    assert 2 <= k < sel["candidates"][-1]  # an interior K, not the cap
    # The smallest K whose left-out-demonstration error is within the tolerance of the best.
    scores = dict(zip(sel["candidates"], sel["scores"], strict=True))
    bound = (1 + CV_TOLERANCE) * scores[sel["best"]]
    assert scores[k] <= bound and all(scores[j] > bound for j in scores if j < k)
    # The generalized trajectory is a faithful summary of the demonstrations.
    assert metrics["rmse_gmr_to_demos"] < 1.5 * metrics["rmse_pointwise_mean_to_demos"]
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary file


def test_demo_unknown_task_is_a_clear_error(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["demo", "--task", "juggling", "--out", str(tmp_path)])
    assert result.exit_code != 0
    assert "--task" in result.output
