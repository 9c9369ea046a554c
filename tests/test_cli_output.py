"""The command line's output as a user reads it (issue 40): tables whose cells carry units and
one name per metric, headers that are not cut when the output is piped, help whose paragraphs
are not broken at the source's line ends, and every registered task named in ``--task``'s help.
"""

from __future__ import annotations

import io
import re
from types import SimpleNamespace
from typing import Any

import pytest
from rich.console import Console
from typer.testing import CliRunner

from pbdkit.apps import _cli_output
from pbdkit.apps._cli import app
from pbdkit.apps._cli_output import (
    METRIC_COLUMNS,
    MOTION_COLUMNS,
    metric_cell,
    metric_text,
    print_evaluation,
)
from pbdkit.sim._task_registry import task_names


def _stats(mean: float, median: float, worst: float) -> dict[str, float]:
    return {"mean": mean, "median": median, "max": worst}


def test_a_metric_is_shown_in_its_unit_and_a_share_as_a_percentage() -> None:
    assert metric_text(0.0123, "m") == "12.3"  # a clearance in metres, shown in mm
    assert metric_text(-0.00004, "mm") == "0.0"  # never "-0.0"
    assert metric_text(0.0036, "rad") == "3.6"  # mrad
    assert metric_text(None, "mm") == "-"
    assert metric_cell(_stats(0.75, 1.0, 1.0), "share") == "75%"  # released in 3 of 4 trials
    assert metric_cell(_stats(0.9, 0.95, 1.234), "worst") == "1.23"  # the worst trial's peak
    assert metric_cell(_stats(9.0, 2.25, 40.0), "mm") == "2.2"  # the median (2.25 rounds even)
    assert metric_cell(None, "mm") == "-"


def test_the_json_keys_of_the_speed_and_the_setpoints_have_distinct_headers() -> None:
    # Two metrics once read "peak_speed_ratio" and "peak_velocity_ratio" side by side.
    headers = [h for h, _ in (*METRIC_COLUMNS.values(), *MOTION_COLUMNS.values())]
    assert len(headers) == len(set(headers))
    assert MOTION_COLUMNS["peak_speed_ratio"][0] != MOTION_COLUMNS["peak_velocity_ratio"][0]


def _evaluation() -> Any:
    metrics = {
        "placement_error_mm": _stats(3.0, 2.3, 9.0),
        "height_error_mm": _stats(-0.00002, -0.00001, 0.0),
        "released": _stats(1.0, 1.0, 1.0),
        "a_metric_of_my_own": _stats(0.5, 0.000128571, 1.0),
        "peak_speed_ratio": _stats(0.9, 0.95, 0.98),
        "following_error_rad": _stats(0.004, 0.0036, 0.01),
        "peak_velocity_ratio": _stats(0.9, 0.95, 1.0),
        "peak_velocity": _stats(1.1, 1.2, 1.3),
    }
    row = SimpleNamespace(success_rate=1.0, collision_rate=None, metrics=metrics)
    return SimpleNamespace(
        task="coaster",
        trials=[None] * 4,
        conditions=SimpleNamespace(seed=0, online=False, perturb="none"),
        controllers={"fused": row, "task:controller_with_a_long_name": row},
        n_components={"joint": 17},
        vision=False,
        tracking_error_mm=None,
        tracking_error_deg=None,
        tracking_failures=0,
    )


def test_the_evaluate_tables_name_each_metric_once_with_its_unit_and_no_raw_floats(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    out = io.StringIO()
    # As when piped: not a terminal, rich's default width (80) unless widened.
    monkeypatch.setattr(_cli_output, "console", Console(file=out, width=200))
    print_evaluation(SimpleNamespace(fixed_objects=()), _evaluation())
    text = out.getvalue()
    for header in ("placement (mm)", "height (mm)", "released", "arm speed / limit"):
        assert text.count(header) == 1, header
    assert "following error (mrad)" in text and "setpoint velocity / limit" in text
    assert "peak_velocity " not in text  # the absolute peak: in the JSON only
    assert "…" not in text  # no header or cell cut
    assert "-0.0" not in text and "0.000128571" not in text  # 3 significant digits: 0.000129
    assert "0.000129" in text
    assert re.search(r"fused\s*│\s*100%\s*│\s*2\.3\s*│\s*0\.0\s*│\s*100%", text), text


def test_piped_output_is_not_fitted_into_80_columns() -> None:
    # The module's console when standard error is not a terminal (pytest captures it).
    assert not _cli_output.console.is_terminal
    assert _cli_output.console.width >= 160


def test_the_help_joins_a_paragraph_s_lines_and_lists_every_registered_task() -> None:
    # Wide enough that a paragraph fits on one line: a line break inside one is the
    # docstring's, not the terminal's.
    runner = CliRunner()
    done = runner.invoke(app, ["--help"], terminal_width=400, env={"COLUMNS": "400"})
    assert done.exit_code == 0, done.output
    line = next(x for x in done.output.splitlines() if re.search(r"│ demo\s", x))
    assert "a video, report.html and metrics.json" in line, done.output
    for command in ("demo", "teach", "evaluate", "study", "view"):
        done = runner.invoke(app, [command, "--help"], terminal_width=400, env={"COLUMNS": "400"})
        assert done.exit_code == 0, done.output
        flat = " ".join(done.output.split())
        assert "{tasks}" not in flat
        assert f"A robot task: {', '.join(task_names())}" in flat, (command, flat)
    assert "slot" in task_names()
