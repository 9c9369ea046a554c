"""What the ``pbdkit`` command prints: the console, one-line errors, the progress bar, and the
tables and summaries of the commands' results.
"""

from __future__ import annotations

import functools
import inspect
import math
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar, cast

import typer
from rich.console import Console
from rich.table import Table
from rich.text import Text

if TYPE_CHECKING:
    from ..data._demonstration import Demonstration
    from ..reproduction._result import ReproductionResult
    from ..sim._evaluation import Evaluation
    from ..sim._tasks import TaskSpec
    from ..skill._skill import Skill

__all__ = [
    "HIDDEN_METRICS",
    "METRIC_COLUMNS",
    "MOTION_COLUMNS",
    "NOT_A_NUMBER",
    "USER_ERRORS",
    "closest_approach_text",
    "console",
    "error_message",
    "fail",
    "metric_cell",
    "metric_column",
    "metric_text",
    "metrics_text",
    "print_components",
    "print_evaluation",
    "print_lasa_demo",
    "print_oriented",
    "print_robot_demo",
    "print_study",
    "print_tracking",
    "progress_bar",
    "reports_errors",
    "run_metric_text",
    "unwrap_help",
]

#: The console of every message (standard error: standard output stays for data).
console = Console(stderr=True)
if not console.is_terminal and "COLUMNS" not in os.environ:
    # Piped or redirected: rich would fit every table into 80 columns and cut its headers
    # ("controll…"); a log file has no width to fit.
    console = Console(stderr=True, width=200)

# Errors a command reports in one line with exit status 2 (bad input from the library, and the
# file-system and memory failures a user can fix), instead of a traceback.
USER_ERRORS = (
    ValueError,
    FileNotFoundError,
    PermissionError,
    IsADirectoryError,
    NotADirectoryError,
    FileExistsError,
    MemoryError,
)
_Command = TypeVar("_Command", bound=Callable[..., Any])


def fail(message: str) -> NoReturn:
    """Print ``error: message`` on one line (no wrapping, no markup) and exit with status 2."""
    console.print(Text.assemble(("error: ", "bold red"), message), soft_wrap=True)
    raise typer.Exit(2)


def error_message(exc: BaseException) -> str:
    """One line for a user error, naming the path of an OS error when it has one."""
    if isinstance(exc, MemoryError):
        return f"out of memory: {exc}" if str(exc) else "out of memory"
    if isinstance(exc, OSError) and exc.filename is not None:
        where = f"{exc.filename} -> {exc.filename2}" if exc.filename2 is not None else exc.filename
        return f"{exc.strerror or type(exc).__name__}: {where}"
    return " ".join(str(exc).split())


def reports_errors(command: _Command) -> _Command:
    """Run a command body; a user error (:data:`USER_ERRORS`) becomes a one-line message."""

    @functools.wraps(command)
    def run(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except USER_ERRORS as exc:
            fail(error_message(exc))

    return cast(_Command, run)


def progress_bar() -> Any:
    """The progress bar of the long commands (evaluate, study): task, bar, count, time left."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    return Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=console,
    )


def print_lasa_demo(shape: str, metrics: dict[str, Any], out: Path) -> None:
    """The table of ``pbdkit demo --task lasa``."""
    table = Table(title=f"pbdkit demo: LASA {shape}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key in ("n_components", "rmse_gmr_to_demos", "rmse_pointwise_mean_to_demos"):
        value = metrics[key]
        table.add_row(key, f"{value:.3f}" if isinstance(value, float) else str(value))
    table.add_row("learn time", f"{metrics['learn_seconds']:.2f} s")
    console.print(table)
    console.print(f"wrote {out / f'lasa_{shape}.png'} and {out / 'metrics.json'}")


def run_metric_text(value: Any, key: str) -> str:
    """A metric of one run (the demo's table, the view's run line): :func:`metric_text` in its
    kind (:func:`metric_column`), but a 0/1 share or a bool as yes/no, and a value the run has
    none of (NaN or infinite: the basin's pour error when nothing was poured) as
    :data:`NOT_A_NUMBER`, never ``nan``."""
    kind = metric_column(key)[1]
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if not math.isfinite(value):
        return NOT_A_NUMBER
    if kind == "share":
        return "yes" if value else "no"
    return metric_text(float(value), kind)


def print_robot_demo(spec: TaskSpec, metrics: dict[str, Any], seed: int, out: Path) -> None:
    """The tables and lines of ``pbdkit demo`` for a robot task (``metrics``: its
    metrics.json)."""
    table = Table(title=f"pbdkit demo: {spec.name} task, new situation (seed {seed})")
    table.add_column("controller")
    table.add_column("success")
    # In metrics.json and the report: the motion's metrics (here one column: the worst of the
    # servo stream's three ratios to the limits).
    extra = ("success", "contacts", *MOTION_COLUMNS, *HIDDEN_METRICS)
    keys = [k for k in metrics["controllers"]["fused"] if k not in extra]
    for k in keys:
        table.add_column(metric_column(k)[0], justify="right")
    table.add_column("limits used", justify="right")
    for name, row in metrics["controllers"].items():
        cells = [("[green]yes" if row["success"] else "[red]no")]
        cells += [run_metric_text(row[k], k) for k in keys]
        worst = max(
            (row.get(f"peak_{k}_ratio") or 0.0) for k in ("velocity", "acceleration", "jerk")
        )
        cells.append(metric_text(worst, "worst"))
        table.add_row(name, *cells)
    console.print(table)
    console.print(
        "limits used: the largest of the servo stream's peak velocity, acceleration and jerk "
        "over the arm's limits (<= 1: a real drive accepts it)"
    )
    if metrics["online"] is not None:
        on = metrics["online"]
        t2 = Table(title=f"the fused controller under perturb {on['perturb']['name']}")
        t2.add_column("run")
        t2.add_column("success")
        first = next(iter(k for k in on["online"] if k not in extra))
        t2.add_column(metric_column(first)[0], justify="right")
        t2.add_column(metric_column("peak_speed_ratio")[0], justify="right")
        t2.add_column(metric_column("following_error_rad")[0], justify="right")
        for label in ("online", "offline"):
            row = on[label]
            t2.add_row(
                label,
                "[green]yes" if row["success"] else "[red]no",
                run_metric_text(row[first], first),
                metric_text(row["peak_speed_ratio"], "worst"),
                metric_text(row["following_error_rad"], "rad"),
            )
        console.print(t2)
    print_components(spec, metrics["n_components"])
    tracking = metrics["tracking"]
    deg = tracking.get("tracking_error_deg") if tracking else None
    print_tracking(
        metrics["vision"],
        tracking["tracking_error_mm"] if tracking else None,
        None if deg is None else {"mean": deg["mean"], "sd": deg["std"]},
    )
    secs = metrics["seconds"]
    console.print(
        f"teach {secs['teach']:.1f} s, learn {secs['learn']:.2f} s, reproduce "
        f"{1000 * secs['reproduce_fused']:.0f} ms, whole demo {secs['total']:.1f} s"
    )
    console.print(f"open {out / 'report.html'} (video: {out / 'reproduction.mp4'})")


#: How ``pbdkit evaluate``'s tables show a metric of the runs (:class:`pbdkit.sim.Evaluation`'s
#: keys, which stay as they are in its JSON): the column's header, with its unit, and what is
#: shown: the median over the trials in the key's unit, scaled ("m" to mm, "rad" to mrad), as a
#: share of the trials ("share": the mean of a 0/1 metric, or the median of a fraction), or the
#: worst trial ("worst": a peak over a limit, <= 1 within it). The task's own metrics go in the
#: first table, the motion's in the second; a metric not named here (a registered task's own)
#: shows as its key, median to 3 significant digits.
METRIC_COLUMNS: dict[str, tuple[str, str]] = {
    "placement_error_mm": ("placement (mm)", "mm"),
    "pour_error_mm": ("pour from centre (mm)", "mm"),
    "height_error_mm": ("height (mm)", "mm"),
    "margin_mm": ("margin (mm)", "mm"),
    "tilt_deg": ("tilt (deg)", "deg"),
    "yaw_error_deg": ("yaw (deg)", "deg"),
    "liquid_fraction": ("liquid in basin", "fraction"),
    "held": ("held", "share"),
    "released": ("released", "share"),
    "min_clearance_m": ("clearance (mm)", "m"),
}
MOTION_COLUMNS: dict[str, tuple[str, str]] = {
    "peak_speed_ratio": ("arm speed / limit", "worst"),
    "following_error_rad": ("following error (mrad)", "rad"),
    "peak_velocity_ratio": ("setpoint velocity / limit", "worst"),
    "peak_acceleration_ratio": ("setpoint accel. / limit", "worst"),
    "peak_jerk_ratio": ("setpoint jerk / limit", "worst"),
}
#: Shown in the JSON only: the setpoints' absolute peaks (rad/s, rad/s^2, rad/s^3).
HIDDEN_METRICS = frozenset({"peak_velocity", "peak_acceleration", "peak_jerk"})


def unwrap_help(app: typer.Typer) -> None:
    """Join the lines of each paragraph of every command's docstring (``app``'s and its
    groups'), in place. Typer's help keeps a docstring's single line breaks (in the list of
    commands, and after a command's first paragraph), so the help showed the source's
    100-column lines cut again at the terminal's width."""
    for info in app.registered_commands:
        callback = info.callback
        if callback is not None and callback.__doc__:
            paragraphs = inspect.cleandoc(callback.__doc__).split("\n\n")
            callback.__doc__ = "\n\n".join(" ".join(p.split()) for p in paragraphs)
    for group in app.registered_groups:
        if group.typer_instance is not None:
            unwrap_help(group.typer_instance)


def metric_text(value: float | None, kind: str) -> str:
    """One value of a metric as a table shows it (:data:`METRIC_COLUMNS`' kinds): "-" where
    undefined, a percentage, a ratio to 2 decimals, a length or angle to 0.1 (mm, mrad, deg),
    or 3 significant digits."""
    if value is None:
        return "-"
    if kind in ("share", "fraction"):
        return f"{100 * value:.0f}%"
    if kind == "worst":
        return f"{value:.2f}"
    if kind in ("m", "rad"):
        value *= 1e3
    if kind in ("m", "rad", "mm", "deg"):
        text = f"{value:.1f}"
        return "0.0" if text == "-0.0" else text
    return f"{value:.3g}"


def metric_column(key: str) -> tuple[str, str]:
    """A metric's column header (with its unit) and kind: :data:`METRIC_COLUMNS`,
    :data:`MOTION_COLUMNS`, or the key itself for a metric they do not name."""
    return METRIC_COLUMNS.get(key) or MOTION_COLUMNS.get(key) or (key, "")


def metric_cell(stats: dict[str, float] | None, kind: str) -> str:
    """A metric's statistics over trials (``{"mean", "median", "max"}``, or None where no
    trial defines it) as a table shows it: the mean of a share, the worst of a peak ratio,
    else the median (:data:`METRIC_COLUMNS`)."""
    if stats is None:
        return "-"
    pick = {"share": "mean", "worst": "max"}.get(kind, "median")
    return metric_text(stats[pick], kind)


def print_evaluation(spec: TaskSpec, result: Evaluation) -> None:
    """The tables and lines of ``pbdkit evaluate`` for the task ``spec``: the outcome (success
    and the task's metrics, medians over the trials) and the motion (the worst trial's peaks
    over the arm's limits, the median following error)."""
    conditions = result.conditions
    task, trials = result.task, len(result.trials)
    seed, online, perturb = conditions.seed, conditions.online, conditions.perturb
    how = "online" if online else "offline"
    rows = result.controllers
    keys = [k for row in rows.values() for k in row.metrics]
    outcome = [
        k for k in dict.fromkeys(keys) if k not in MOTION_COLUMNS and k not in HIDDEN_METRICS
    ]
    motion = [k for k in MOTION_COLUMNS if k in keys]
    title = f"{task}: {trials} new placements (seed {seed}), {how}, perturb {perturb}"
    scene = any(row.collision_rate is not None for row in rows.values())
    for heading, columns, first in (
        (title, outcome, ["success", "touched"] if scene else ["success"]),
        ("motion (worst trial over the limits; median following error)", motion, []),
    ):
        table = Table(title=heading)
        table.add_column("controller")
        for header in first:
            table.add_column(header, justify="right")
        for k in columns:
            table.add_column(metric_column(k)[0], justify="right")
        for name, row in rows.items():
            cells = [f"{100 * row.success_rate:.0f}%"] if first else []
            if first and scene:  # the share of trials that touched what they may not
                rate = row.collision_rate
                cells.append("-" if rate is None else f"{100 * rate:.0f}%")
            for k in columns:
                cells.append(metric_cell(row.metrics.get(k), metric_column(k)[1]))
            table.add_row(name, *cells)
        console.print(table)
    print_components(spec, result.n_components)
    print_tracking(result.vision, result.tracking_error_mm, result.tracking_error_deg)
    if result.tracking_failures:
        console.print(
            f"[red]{result.tracking_failures} placement(s) where the cameras did not locate "
            "every object (counted as failures)"
        )


def print_study(result: dict[str, Any], out: Path) -> None:
    """The lines of ``pbdkit study`` (``result``: its study.json)."""
    for obj, m in result["maps"].items():
        rates = ", ".join(f"{k} {100 * v:.0f}%" for k, v in m["overall"].items())
        console.print(f"map of the {obj} (grid twice the demonstrated range): {rates}")
    curve = ", ".join(
        f"{c['n_demos']}: {100 * c['success_rate']:.0f}%" for c in result["learning_curve"]
    )
    console.print(f"fused success by number of demonstrations: {curve}")
    noise = ", ".join(
        f"{c['noise_mm']:g} mm: {100 * c['success_rate']:.0f}%" for c in result["noise"]
    )
    console.print(f"fused success by tracking noise: {noise}")
    console.print(f"open {out / 'report.html'} ({result['seconds']:.0f} s)")


def print_components(spec: TaskSpec, n_components: dict[str, int]) -> None:
    """K per space, the fixed objects of ``spec`` marked (learned with --constrain-fixed)."""
    ks = ", ".join(f"{k}: {v}" for k, v in n_components.items())
    fixed = [k for k in n_components if k in spec.fixed_objects]
    note = f" ({', '.join(fixed)}: fixed, learned with --constrain-fixed)" if fixed else ""
    console.print(f"K per space (chosen by leaving one demonstration out): {ks}{note}")


def print_tracking(
    vision: bool, stats: dict[str, Any] | None, yaw: dict[str, Any] | None = None
) -> None:
    """Where the object positions came from, and the cameras' error (``stats``: mean and std
    in mm; ``yaw``: mean and sd in degrees, for objects placed as poses)."""
    if not vision:
        console.print("object positions: ground truth (--ground-truth)")
        return
    if stats is None:
        console.print("object positions: stereo cameras, no object located")
        return
    # The yaw of the objects placed as poses (evaluate's "tracking_error_deg"), when there are.
    turn = "" if yaw is None else f", yaw {yaw['mean']:.2f} +- {yaw['sd']:.2f} deg"
    console.print(
        f"object positions: stereo cameras, error {stats['mean']:.1f} +- {stats['std']:.1f} mm"
        f"{turn} (paper: 5.9 +- 2.8 mm)"
    )


def print_oriented(skill: Skill, demos: Sequence[Demonstration]) -> None:
    """Say which objects the skill learned with orientation (those the demonstrations give as
    poses, unless --no-orientation); nothing when every object is a position (the paper's)."""
    from ..data._placement import is_pose

    posed = [k for k in skill.object_names if is_pose(demos[0].objects[k])]
    if not posed:
        return
    if skill.oriented:
        console.print(
            f"oriented (the hand's position in the object's frame and its orientation "
            f"relative to it): {', '.join(skill.oriented)}",
            soft_wrap=True,
        )
    flat = [k for k in posed if k not in skill.oriented]
    if flat:
        console.print(
            f"given as poses, learned as positions only (--no-orientation): {', '.join(flat)}",
            soft_wrap=True,
        )


def closest_approach_text(res: ReproductionResult) -> str:
    """How close the hand came to where each object's constraint expects it: the smallest
    distance (mm) and, for an oriented object, the angle (degrees) to the orientation it
    expects at that sample."""
    from ._report import closest_approach

    parts = []
    for k, (mm, deg) in closest_approach(res).items():
        parts.append(f"{k} {mm:.1f} mm" + ("" if deg is None else f" and {deg:.1f} deg"))
    what = "closest approach"
    if res.orientation_errors:
        what += " (distance, and the angle to the expected orientation there)"
    return f"{what}: {', '.join(parts)}"


#: Shown for a value a run has none of (a NaN or an infinity), instead of a number.
NOT_A_NUMBER = "n/a"


def metrics_text(metrics: Mapping[str, Any]) -> str:
    """A run's numeric metrics as ``"name value, ..."``, with the names and formats of
    ``pbdkit evaluate``'s tables (:func:`metric_column`: the unit in
    the name, a 0/1 share as yes/no); a value the run has none of (NaN or infinite: the basin's
    pour error when nothing was poured) reads :data:`NOT_A_NUMBER`, never ``nan``."""
    return ", ".join(
        f"{metric_column(key)[0]} {run_metric_text(value, key)}"
        for key, value in metrics.items()
        if isinstance(value, (int, float))
    )
