"""The ``pbdkit`` command: a thin layer over the library.

``pbdkit demo`` runs the main job end to end and writes its results to a folder. The other
commands expose one step each.
"""

from __future__ import annotations

import functools
import gc
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, NoReturn, TypeVar, cast, overload

import numpy as np
import typer
from rich.console import Console
from rich.table import Table
from rich.text import Text
from typer.core import TyperCommand

from .._defaults import MAX_COMPONENTS
from .._io import write_json

if TYPE_CHECKING:
    from ..data._demonstration import Demonstration
    from ..reproduction._result import ReproductionResult
    from ..robots._robot import Robot
    from ..sim._tasks import TaskSpec
    from ..skill._skill import Skill

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Teach a robot arm a skill from a few demonstrations (Calinon & Billard, IROS 2008).",
)
console = Console(stderr=True)

#: The ``format`` and ``version`` of the file `pbdkit reproduce` writes (see its --out help).
#: Version 1 is the layout the command always wrote, now labelled; the keys of oriented
#: constraints (orientations, orientation_error_NAME) and task_error_NAME are optional within
#: it: a reader that looks keys up by name reads every file.
REPRODUCTION_FORMAT = "pbdkit-reproduction"
REPRODUCTION_VERSION = 1


@app.callback()
def _root() -> None:
    """Teach a robot arm a skill from a few demonstrations (Calinon & Billard, IROS 2008)."""


# ----------------------------------------------------------------------------- errors
# Errors a command reports in one line with exit status 2 (bad input from the library, and the
# file-system and memory failures a user can fix), instead of a traceback.
_USER_ERRORS = (
    ValueError,
    FileNotFoundError,
    PermissionError,
    IsADirectoryError,
    NotADirectoryError,
    FileExistsError,
    MemoryError,
)
_Command = TypeVar("_Command", bound=Callable[..., Any])


def _fail(message: str) -> NoReturn:
    """Print ``error: message`` on one line (no wrapping, no markup) and exit with status 2."""
    console.print(Text.assemble(("error: ", "bold red"), message), soft_wrap=True)
    raise typer.Exit(2)


def _error_message(exc: BaseException) -> str:
    """One line for a user error, naming the path of an OS error when it has one."""
    if isinstance(exc, MemoryError):
        return f"out of memory: {exc}" if str(exc) else "out of memory"
    if isinstance(exc, OSError) and exc.filename is not None:
        where = f"{exc.filename} -> {exc.filename2}" if exc.filename2 is not None else exc.filename
        return f"{exc.strerror or type(exc).__name__}: {where}"
    return " ".join(str(exc).split())


def _reports_errors(command: _Command) -> _Command:
    """Run a command body; a user error (:data:`_USER_ERRORS`) becomes a one-line message."""

    @functools.wraps(command)
    def run(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except _USER_ERRORS as exc:
            _fail(_error_message(exc))

    return cast(_Command, run)


def _check_output(
    path: Path,
    option: str,
    *,
    folder: bool = False,
    inputs: Sequence[tuple[str, Path | None]] = (),
    also: Sequence[tuple[str, Path | None]] = (),
) -> None:
    """Fail unless ``path`` can be written: a file (its directory exists and is writable), or
    with ``folder`` a directory to write into (existing, or to be created in a writable one).

    ``inputs`` are the files the command reads, each with the name the command gives it
    (``("SKILL", path)``, ``("--robot", path)``; a path None: not given): ``path`` may be none
    of them (writing it would destroy the input). ``also`` are the other outputs of the
    command, named so too: ``path`` may be none of them (the first written would be lost, or
    make the second fail after it).

    Called before any work, so that a long run does not end on a path it cannot write. A
    symbolic link is judged by the file it points to (that file is what gets written).
    """
    for label, source in inputs:
        if source is not None and _same_file(path, source):
            _fail(
                f"{option} {path}: is also {label} {source}, which the command reads; give "
                f"{option} another path"
            )
    for label, other in also:
        if other is not None and _same_file(path, other):
            _fail(f"{option} {path}: is also {label} {other}; give each output its own path")
    real = Path(os.path.realpath(path))
    if folder and real.exists():
        if not real.is_dir():
            _fail(f"{option} {path}: exists and is not a directory; give a directory")
        if not os.access(real, os.W_OK | os.X_OK):
            _fail(f"{option} {path}: the directory is not writable")
        return
    if real.is_dir():
        _fail(f"{option} {path}: is a directory; give a file path")
    parent = real.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        _fail(f"{option} {path}: the directory {parent} {what}")
    if not os.access(parent, os.W_OK | os.X_OK):
        _fail(f"{option} {path}: the directory {parent} is not writable")


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name the same file: the same path once links are resolved, or
    (both existing) the same file on disk (a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): different files
        return False


def _check_seed(seed: int) -> None:
    """Fail unless ``seed`` can seed NumPy's generators (an integer >= 0)."""
    if seed < 0:
        _fail(f"--seed must be an integer >= 0, got {seed}")


# ----------------------------------------------------------------------------- commands
def _robot_task(task: str, *, also: tuple[str, ...] = ()) -> TaskSpec:
    """The registered robot task named ``task``, or a usage error listing the choices (the
    registered tasks, then ``also``).

    Imports the simulator (MuJoCo): call it after the cheap checks of a command's options.
    """
    from ..sim._tasks import get_task, task_names

    try:
        return get_task(task)
    except ValueError:
        choices = ", ".join([*task_names(), *also])
        raise typer.BadParameter(
            f"task must be one of {choices}; got {task!r}", param_hint="--task"
        ) from None


_TASK_HELP = "A robot task (coaster, basin, or any registered with pbdkit.sim.register_task)"

# Shared by `demo` and `evaluate`.
GroundTruthOption = Annotated[
    bool,
    typer.Option(
        "--ground-truth",
        help="Tell the skill the true object positions (default: the stereo cameras').",
    ),
]
ConstrainFixedOption = Annotated[
    bool,
    typer.Option(
        "--constrain-fixed",
        help="Also learn a task-space constraint relative to fixed objects (the basin), which "
        "the paper does not (default: joint space and the moving objects only).",
    ),
]


OnlineOption = Annotated[
    bool,
    typer.Option(
        "--online",
        help="Run the controllers in the physics loop, step by step from the measured joint "
        "angles, told the object positions at 15 Hz (default: reproduce once, play the "
        "trajectory).",
    ),
]
# Where a --perturb help lists the registered perturbations (pbdkit.sim.register_perturbation).
_PERTURBATIONS = "{perturbations}"
PerturbOption = Annotated[str, typer.Option(help=f"Disturbance: {_PERTURBATIONS}.")]


class _PerturbHelp(TyperCommand):
    """A command whose ``--perturb`` help lists the registered perturbations with their help
    texts (:func:`pbdkit.sim._perturb.perturbation_help`). They are read when the help is shown:
    the registry lives with the simulator, which the command line imports only to run a
    command."""

    def format_help(self, ctx: Any, formatter: Any) -> None:
        from ..sim._perturb import perturbation_help

        for param in self.params:
            text = getattr(param, "help", None)
            if param.name == "perturb" and isinstance(text, str):
                cast(Any, param).help = text.replace(_PERTURBATIONS, perturbation_help())
        super().format_help(ctx, formatter)


def _check_perturb(perturb: str) -> None:
    from ..sim._perturb import perturbation_names

    if perturb not in perturbation_names():
        raise typer.BadParameter(
            f"must be one of {', '.join(perturbation_names())}, got {perturb!r}",
            param_hint="--perturb",
        )


def _check_workers(
    workers: int | None, scheduler: str | None, *, work: int | None = None
) -> int | None:
    """The local workers to start for ``--workers``, None for a serial run or ``--scheduler``.

    The count is the library's (:func:`pbdkit.sim._forkserver.local_workers`): at most one per
    core, and one per item of ``work`` when it is known; a capped count is said on the console.
    Refuses both options at once, and a count < 1.
    """
    if workers is not None and scheduler is not None:
        raise typer.BadParameter("give --workers or --scheduler, not both", param_hint="--workers")
    if workers is None:
        return None
    from ..sim._forkserver import local_workers

    try:
        local = local_workers(workers, work)
    except ValueError:
        raise typer.BadParameter(f"must be >= 1, got {workers}", param_hint="--workers") from None
    if local < workers:
        why = "one per core" if work is None or local < work else "one per trial and controller"
        console.print(
            f"--workers {workers}: starting {local} ({why}; more would have nothing to do "
            "but compete for the cores)",
            soft_wrap=True,  # one line, as the errors
        )
    return local


def _start_workers_early(workers: int | None) -> None:
    """Local workers fork from a server that imports the simulation once: start it before this
    process imports the simulation itself, so that the two imports overlap (call it after the
    cheap checks of the options)."""
    if workers is not None:
        from ..sim import _forkserver

        _forkserver.start()


def _progress() -> Any:
    """The progress bar of the long commands (evaluate, study): task, bar, count, time left."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    return Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=console,
    )


def _check_lasa_shape(shape: str) -> None:
    from ..datasets import lasa_names

    try:
        names = lasa_names()
    except (ModuleNotFoundError, FileNotFoundError) as exc:  # the data are an optional extra
        _fail(f"--task lasa: {exc}")
    if shape not in names:
        _fail(f"--shape must be a LASA shape, one of {', '.join(names)}; got {shape!r}")


@app.command(cls=_PerturbHelp)
@_reports_errors
def demo(
    out: Annotated[Path, typer.Option(help="Folder for the results.")] = Path("demo-output"),
    task: Annotated[str, typer.Option(help=f"{_TASK_HELP}, or lasa.")] = "coaster",
    seed: Annotated[
        int, typer.Option(help="Seed of the demonstrations and the new situation.")
    ] = 0,
    shape: Annotated[str, typer.Option(help="LASA shape (task lasa only).")] = "GShape",
    ground_truth: GroundTruthOption = False,
    constrain_fixed: ConstrainFixedOption = False,
    online: OnlineOption = False,
    perturb: Annotated[
        str,
        typer.Option(
            help=f"Disturbance of the online run (with --online): {_PERTURBATIONS}; default move.",
        ),
    ] = "move",
) -> None:
    """Run the main job: demonstrations -> skill -> new situation -> physics, with figures,
    a video, report.html and metrics.json in OUT. With --online, the fused controller also
    runs in the physics loop under a disturbance, beside the offline run."""
    _check_output(out, "--out", folder=True)
    _check_seed(seed)
    _check_perturb(perturb)
    if task == "lasa":
        _check_lasa_shape(shape)
        from ._demo import run_lasa_demo

        with console.status(f"learning LASA shape {shape} ..."):
            lasa_metrics = run_lasa_demo(out, shape)
        table = Table(title=f"pbdkit demo: LASA {shape}")
        table.add_column("metric")
        table.add_column("value", justify="right")
        for key in ("n_components", "rmse_gmr_to_demos", "rmse_pointwise_mean_to_demos"):
            value = lasa_metrics[key]
            table.add_row(key, f"{value:.3f}" if isinstance(value, float) else str(value))
        table.add_row("learn time", f"{lasa_metrics['learn_seconds']:.2f} s")
        console.print(table)
        console.print(f"wrote {out / f'lasa_{shape}.png'} and {out / 'metrics.json'}")
        return
    spec = _robot_task(task, also=("lasa",))
    from ..sim._tracking import ObjectNotSeenError
    from ._demo import run_robot_demo

    try:
        with console.status("starting ...") as st:
            robot_metrics = run_robot_demo(
                spec,
                out,
                seed=seed,
                status=lambda m: st.update(m),
                ground_truth=ground_truth,
                constrain_fixed=constrain_fixed,
                online=online,
                perturb=perturb if online else "none",
            )
    except ObjectNotSeenError as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(1) from None
    metrics: dict[str, Any] = robot_metrics
    table = Table(title=f"pbdkit demo: {spec.name} task, new situation (seed {seed})")
    table.add_column("controller")
    table.add_column("success")
    # In metrics.json and the report: the measured speed and following error, and the servo
    # stream's peaks (here one column: the worst of the three ratios to the limits).
    peaks = tuple(
        f"peak_{k}{s}" for k in ("velocity", "acceleration", "jerk") for s in ("", "_ratio")
    )
    extra = ("success", "peak_speed_ratio", "following_error_rad", *peaks)
    keys = [k for k in metrics["controllers"]["fused"] if k not in extra]
    for k in keys:
        table.add_column(k, justify="right")
    table.add_column("limits used", justify="right")
    for name, row in metrics["controllers"].items():
        cells = [("[green]yes" if row["success"] else "[red]no")]
        cells += ["-" if row[k] is None else f"{row[k]:.1f}" for k in keys]
        worst = max(
            (row.get(f"peak_{k}_ratio") or 0.0) for k in ("velocity", "acceleration", "jerk")
        )
        cells.append(f"{worst:.3f}")
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
        t2.add_column(first, justify="right")
        t2.add_column("peak speed / limit", justify="right")
        t2.add_column("following error (rad)", justify="right")
        for label in ("online", "offline"):
            row = on[label]
            t2.add_row(
                label,
                "[green]yes" if row["success"] else "[red]no",
                "-" if row[first] is None else f"{row[first]:.1f}",
                f"{row['peak_speed_ratio']:.2f}",
                f"{row['following_error_rad']:.3f}",
            )
        console.print(t2)
    _print_components(spec, metrics["n_components"])
    tracking = metrics["tracking"]
    deg = tracking.get("tracking_error_deg") if tracking else None
    _print_tracking(
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


@app.command()
@_reports_errors
def teach(
    task: Annotated[str, typer.Option(help=f"{_TASK_HELP}.")] = "coaster",
    demos: Annotated[int, typer.Option(help="Number of demonstrations.")] = 5,
    out: Annotated[Path, typer.Option(help="Output .npz file.")] = Path("demos.npz"),
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Record simulated kinesthetic demonstrations of a task."""
    if demos < 2:
        raise typer.BadParameter(
            f"need at least 2 demonstrations, got {demos}", param_hint="--demos"
        )
    _check_output(out, "--out")
    _check_seed(seed)
    spec = _robot_task(task)
    from ..data._demonstration import save_demonstrations
    from ..sim._teacher import teach as sim_teach

    with console.status(f"teaching {demos} demonstrations ..."):
        items = sim_teach(spec, demos, seed=seed)
    save_demonstrations(items, out)
    console.print(f"wrote {len(items)} demonstrations to {out}")


# Suffixes of the files `learn` reads: a pbdkit archive, or a bag (a rosbag2 bag is usually a
# directory holding metadata.yaml; its storage file, or a ROS 1 bag, works too).
_BAG_SUFFIXES = (".db3", ".mcap", ".bag")


def _is_bag(path: Path) -> bool:
    return path.is_dir() or path.suffix in _BAG_SUFFIXES


@app.command()
@_reports_errors
def learn(
    demos: Annotated[
        list[Path],
        typer.Argument(
            metavar="DEMOS",
            help="Demonstrations: one .npz from `pbdkit teach`, or ROS bags, one demonstration "
            "each (rosbag2 directories, .db3 or .mcap files, ROS 1 .bag files).",
        ),
    ],
    robot: Annotated[str, typer.Option(help="katana, panda, or a URDF file.")] = "katana",
    tip: Annotated[str | None, typer.Option(help="Tip frame (URDF robots).")] = None,
    joint_limits: Annotated[
        Path | None,
        typer.Option(
            "--joint-limits",
            metavar="YAML",
            help="URDF robots: a joint_limits.yaml (MoveIt / ros2_control format) with the "
            "velocity, acceleration and jerk limits; its velocities win over the URDF's.",
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="Output skill file.")] = Path("skill.npz"),
    n_steps: Annotated[int, typer.Option(help="Steps of the time grid.")] = 1000,
    max_components: Annotated[
        int, typer.Option(help="Largest K tried (K is chosen per space by cross-validation).")
    ] = MAX_COMPONENTS,
    task_space: Annotated[
        list[str] | None,
        typer.Option(
            "--task-space",
            help="An object that gets a task-space constraint (repeat for several; default: "
            "every recorded object). The paper's basin task: --task-space glass (the basin is "
            "fixed).",
        ),
    ] = None,
    joint_topic: Annotated[
        str | None,
        typer.Option(help="Bags: topic of sensor_msgs/msg/JointState (default /joint_states)."),
    ] = None,
    obj: Annotated[
        list[str] | None,
        typer.Option(
            "--object",
            help="Bags: NAME=SOURCE, where the object is (repeat for several): a topic of "
            "PoseStamped or TransformStamped (a pose: median position and mean orientation over "
            "the first second), of PointStamped (a position), tf:FRAME (a /tf frame's pose), "
            "x,y,z (a position) or x,y,z,qw,qx,qy,qz (a pose, quaternion w first; ROS orders "
            "x,y,z,w) in the robot's base frame (m).",
        ),
    ] = None,
    gripper_topic: Annotated[
        str | None, typer.Option(help="Bags: topic of std_msgs/msg/Bool or Float64.")
    ] = None,
    start: Annotated[
        float | None,
        typer.Option(
            help="Bags: seconds after the first joint state where a demonstration starts."
        ),
    ] = None,
    end: Annotated[
        float | None,
        typer.Option(help="Bags: seconds after the first joint state where it ends."),
    ] = None,
    orientation: Annotated[
        bool,
        typer.Option(
            "--orientation/--no-orientation",
            help="For objects the demonstrations give as poses: also learn the hand's "
            "orientation relative to each, with its position in the object's frame (default); "
            "--no-orientation learns the paper's position-only skill from the same data, for "
            "comparison.",
        ),
    ] = True,
) -> None:
    """Learn a skill (one GMM per space, K chosen by cross-validation) from demonstrations:
    an .npz file, or ROS bags (see pbdkit.data._bags for the topics and conventions)."""
    from .. import robots
    from ..robots._robot import Robot
    from ..skill._skill import Skill

    shipped = robot in robots.available()
    if shipped and tip is not None:
        _fail(f"--tip applies to a URDF robot; the shipped {robot} has a fixed tool frame")
    if shipped and joint_limits is not None:
        _fail(
            f"--joint-limits applies to a URDF robot; the shipped {robot} has its own limits "
            "(pass its URDF file to --robot to use other limits)"
        )
    bag_options = {
        "--joint-topic": joint_topic,
        "--object": obj,
        "--gripper-topic": gripper_topic,
        "--start": start,
        "--end": end,
    }
    npz = [p for p in demos if p.suffix == ".npz"]
    if npz and len(demos) > 1:
        _fail(f"give one .npz file of demonstrations, or bags only; got {len(demos)} paths")
    if npz:
        given = [k for k, v in bag_options.items() if v is not None]
        if given:
            _fail(f"{', '.join(given)} apply to bags; {npz[0]} is an .npz file")
    else:
        unknown = [p for p in demos if p.exists() and not _is_bag(p)]
        if unknown:
            _fail(
                f"{unknown[0]}: not an .npz file of demonstrations nor a ROS bag (a rosbag2 "
                "directory, .db3, .mcap or .bag file)"
            )
    sources = _parse_objects(obj or [], sources=True)
    read: list[tuple[str, Path | None]] = [("DEMOS", d) for d in demos]
    read += [("--robot", None if shipped else Path(robot)), ("--joint-limits", joint_limits)]
    _check_output(out, "--out", inputs=read)
    if shipped:
        arm = robots.load(robot)
    elif Path(robot).is_file():
        arm = Robot.from_urdf(Path(robot), tip=tip, joint_limits=joint_limits)
    else:
        raise typer.BadParameter(
            f"robot must be one of {robots.available()} or a URDF file, got {robot!r}",
            param_hint="--robot",
        )
    items = _load_demos(demos, arm, sources, joint_topic, gripper_topic, start, end)
    with console.status("learning ..."):
        t_start = time.perf_counter()
        skill = Skill.learn(
            items,
            arm,
            n_steps=n_steps,
            max_components=max_components,
            task_objects=task_space or None,
            orientation=orientation,
        )
        seconds = time.perf_counter() - t_start
    skill.save(out)
    ks = ", ".join(f"{k}: {v}" for k, v in skill.n_components.items())
    console.print(f"learned in {seconds:.2f} s; K per space: {ks}; wrote {out}")
    _print_oriented(skill, items)


def _print_oriented(skill: Skill, demos: Sequence[Demonstration]) -> None:
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


def _load_demos(
    paths: list[Path],
    arm: Robot,
    sources: dict[str, str | np.ndarray],
    joint_topic: str | None,
    gripper_topic: str | None,
    start: float | None,
    end: float | None,
) -> list[Demonstration]:
    """The demonstrations of `learn`: an .npz file's, or one per bag (errors name the bag)."""
    if len(paths) == 1 and paths[0].suffix == ".npz":
        from ..data._demonstration import load_demonstrations

        return load_demonstrations(paths[0])
    from ..data._bag_read import read_bag

    items = []
    for path in paths:
        try:
            items.append(
                read_bag(
                    path,
                    robot=arm,
                    joint_topic=joint_topic or "/joint_states",
                    objects=sources,
                    gripper_topic=gripper_topic,
                    start=start,
                    end=end,
                )
            )
        except ValueError as exc:
            text = str(exc)
            raise ValueError(text if str(path) in text else f"{path}: {text}") from exc
    return items


@overload
def _parse_objects(texts: list[str]) -> dict[str, np.ndarray]: ...


@overload
def _parse_objects(texts: list[str], *, sources: Literal[True]) -> dict[str, str | np.ndarray]: ...


def _parse_objects(texts: list[str], *, sources: bool = False) -> dict[str, Any]:
    """The --object NAME=VALUE options as a dict; an object given twice is an error.

    VALUE is a position x,y,z (metres), or a pose x,y,z,qw,qx,qy,qz with the quaternion **w
    first** (pytransform3d's convention; ROS messages hold x,y,z,w), passed on as a 7-vector;
    with ``sources`` (`learn`'s bags), also where to read it: a topic or tf:FRAME (any VALUE
    that is not numbers).
    """
    objects: dict[str, Any] = {}
    for text in texts:
        name, value = _parse_object(text, sources=sources)
        if name in objects:
            _fail(f"--object {name} is given twice; give each object once")
        objects[name] = value
    return objects


def _parse_object(text: str, *, sources: bool) -> tuple[str, str | np.ndarray]:
    """One --object NAME=VALUE option (see :func:`_parse_objects`)."""
    name, sep, rest = text.partition("=")
    forms = "NAME=x,y,z (metres) or NAME=x,y,z,qw,qx,qy,qz (a pose, quaternion w first)"
    if not sep or not name or not rest:
        want = "NAME=SOURCE (a topic, tf:frame, x,y,z or x,y,z,qw,qx,qy,qz)" if sources else forms
        raise typer.BadParameter(f"expected {want}, got {text!r}", param_hint="--object")
    try:
        values = [float(v) for v in rest.split(",")]
    except ValueError:
        if sources:
            return name, rest
        values = []
    if len(values) not in (3, 7):
        got = f"{len(values)} numbers" if values else "not numbers"
        raise typer.BadParameter(f"expected {forms}, got {text!r} ({got})", param_hint="--object")
    return name, np.array(values)


@app.command()
@_reports_errors
def reproduce(
    skill_path: Annotated[Path, typer.Argument(metavar="SKILL", help="Skill file (.npz).")],
    obj: Annotated[
        list[str],
        typer.Option(
            "--object",
            help="NAME=x,y,z (a position) or NAME=x,y,z,qw,qx,qy,qz (a pose, quaternion w "
            "first; ROS orders x,y,z,w) in the robot's base frame (m). An object the skill "
            "learned with orientation needs a pose.",
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            help="Output .npz file (format pbdkit-reproduction, version 1): t, joints, "
            "positions, gripper, covariances, influence_NAME, task_error_NAME (m) and, with "
            "the robot's limits, times, velocities, accelerations, lead_in; for a skill with "
            "oriented constraints also orientations (T, 3, 3: the hand's axes in the base "
            "frame) and orientation_error_NAME (rad) per oriented object.",
        ),
    ] = Path("repro.npz"),
    use: Annotated[
        list[str] | None, typer.Option(help="Constraints to use (default: all, fused).")
    ] = None,
    bag: Annotated[
        Path | None,
        typer.Option(
            help="Also write a rosbag2 bag (a new directory) with the trajectory as one "
            "trajectory_msgs/msg/JointTrajectory on /joint_trajectory (and the gripper as "
            "std_msgs/msg/Bool on /gripper), timed as the reproduction (skill.times), its "
            "points with the timing's velocities and accelerations when it has them.",
        ),
    ] = None,
) -> None:
    """Reproduce a skill for new object positions or poses (paper Table II)."""
    from .._io import save_npz_atomic
    from ..skill._skill import Skill

    objects = _parse_objects(obj)
    # The bag too is written (after the .npz): --out may not be where it goes.
    _check_output(out, "--out", inputs=[("SKILL", skill_path)], also=[("--bag", bag)])
    if bag is not None:
        _check_bag_output(bag)
    skill = Skill.load(skill_path)
    res = skill.reproduce(objects, use=use or None)
    # Before writing anything: the bag's content is checked (a skill without a duration or
    # joint names, times beyond what a bag holds), so that an error leaves no --out behind.
    timing = None if bag is None else _bag_timing(skill, res, bag)
    arrays = {
        "format": np.array(REPRODUCTION_FORMAT),
        "version": np.array(REPRODUCTION_VERSION, dtype=np.int64),
        "t": res.t,
        "joints": res.joints,
        "positions": res.positions,
        "gripper": res.gripper,
        "covariances": res.covariances,
    }
    arrays.update({f"influence_{k}": v for k, v in res.influence.items()})
    arrays.update({f"task_error_{k}": v for k, v in res.task_errors.items()})
    if res.orientations is not None:
        arrays["orientations"] = res.orientations
    arrays.update({f"orientation_error_{k}": v for k, v in res.orientation_errors.items()})
    timed = ""
    if res.times is not None and res.lead_in is not None:
        # Within the robot's motion limits: the timing (s), its derivatives, the lead-in.
        assert res.velocities is not None and res.accelerations is not None
        arrays.update(
            times=res.times,
            velocities=res.velocities,
            accelerations=res.accelerations,
            lead_in=res.lead_in,
        )
        lead = int(np.count_nonzero(res.lead_in))
        timed = (
            f", {lead} of them a lead-in from the start posture; {res.times[-1]:.2f} s within "
            f"the robot's limits, the skill's steps {res.stretch:.2f}x their demonstrated pace"
        )
    save_npz_atomic(out, arrays)
    console.print(f"wrote {out} ({len(res.t)} samples{timed}); {_closest_approach(res)}")
    if bag is not None and timing is not None:
        from ..data._bag_write import write_trajectory_bag

        t, names = timing
        write_trajectory_bag(bag, t, res.joints, names, **_bag_extras(skill, res))
        console.print(f"wrote {bag}: /joint_trajectory, {len(t)} points over {t[-1]:.2f} s")


def _closest_approach(res: ReproductionResult) -> str:
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


def _check_bag_output(bag: Path) -> None:
    """Fail unless a new bag (a directory) can be created at ``bag`` (that it is not ``--out``
    is :func:`_check_output`'s check)."""
    if bag.exists() or bag.is_symlink():
        _fail(f"--bag {bag}: exists; give a new path (a bag is a directory, never overwritten)")
    _check_output(bag, "--bag")


def _bag_extras(skill: Skill, res: ReproductionResult) -> dict[str, Any]:
    """The gripper, velocities and accelerations of the trajectory bag of `reproduce`."""
    return {
        "gripper": res.gripper if skill.has_gripper else None,
        # Velocities and accelerations of the timing (None without limits: positions only).
        "velocities": res.velocities,
        "accelerations": res.accelerations if res.velocities is not None else None,
    }


def _bag_timing(skill: Skill, res: ReproductionResult, bag: Path) -> tuple[np.ndarray, list[str]]:
    """Times (s, from :meth:`pbdkit.Skill.times`) and joint names (the skill's robot's) of the
    trajectory bag of `reproduce`, its whole content checked (nothing is written)."""
    from ..data._bag_write import _trajectory_messages

    names = getattr(skill.robot, "joint_names", None)
    if names is None:
        _fail("--bag: the skill's robot has no joint names; load it with a pbdkit.Robot")
    try:
        t = skill.times(res)
        names = [str(n) for n in names]
        _trajectory_messages(t, res.joints, names, **_bag_extras(skill, res))
    except ValueError as exc:
        _fail(f"--bag {bag}: {exc}")
    return t, names


@app.command(cls=_PerturbHelp)
@_reports_errors
def evaluate(
    task: Annotated[str, typer.Option(help=f"{_TASK_HELP}.")] = "coaster",
    trials: Annotated[int, typer.Option(help="Number of new placements.")] = 50,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    json_path: Annotated[Path | None, typer.Option("--json", help="Write results here.")] = None,
    ground_truth: GroundTruthOption = False,
    constrain_fixed: ConstrainFixedOption = False,
    online: OnlineOption = False,
    perturb: PerturbOption = "none",
    controller: Annotated[
        list[str] | None,
        typer.Option(
            "--controller",
            help="Run only this controller (repeatable): fused, joint or task:OBJECT. "
            "Default: every one.",
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Run the trials in N local worker processes (a Dask LocalCluster); the results "
            "are those of the serial run. At most one per core (and, with --controller, one "
            "per trial and controller): a larger N is capped, with a notice.",
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Run the trials on the Dask cluster at this address (tcp://HOST:PORT; start "
            "it with `dask scheduler` and `dask worker tcp://HOST:PORT`).",
        ),
    ] = None,
) -> None:
    """Success rate of every controller (fused, joint, task:OBJECT) over new placements."""
    if trials < 1:
        raise typer.BadParameter(f"trials must be >= 1, got {trials}", param_hint="--trials")
    _check_seed(seed)
    # The trials' controller runs are the work items (a trial observes once, then runs its
    # controllers at once); without --controller their number is known after the learning.
    workers = _check_workers(
        workers, scheduler, work=trials * len(controller) if controller else None
    )
    if controller and len(set(controller)) != len(controller):
        raise typer.BadParameter("a controller is named twice", param_hint="--controller")
    if json_path is not None:
        _check_output(json_path, "--json")
    _start_workers_early(workers)
    _check_perturb(perturb)  # imports the simulation
    spec = _robot_task(task)
    from ..sim._evaluation import evaluate as sim_evaluate

    with _progress() as bar:
        job = bar.add_task(f"{task}: teaching and learning", total=None)

        def tick(done: int, total: int) -> None:
            bar.update(job, description=f"{task}: executing", completed=done, total=total)

        result = sim_evaluate(
            spec,
            trials,
            seed,
            progress=tick,
            ground_truth=ground_truth,
            constrain_fixed=constrain_fixed,
            online=online,
            perturb=perturb,
            controllers=controller or None,
            workers=workers,
            scheduler=scheduler,
        )
    if json_path is not None:
        write_json(json_path, result.as_dict())
    how = "online" if online else "offline"
    title = f"{task}: {trials} new placements (seed {seed}), {how}, perturb {perturb}"
    table = Table(title=title)
    table.add_column("controller")
    table.add_column("success rate", justify="right")
    table.add_column("median errors", justify="left")
    for name, row in result.controllers.items():
        med = ", ".join(f"{k} {v['median']:.1f}" for k, v in row.metrics.items() if v is not None)
        table.add_row(name, f"{100 * row.success_rate:.0f}%", med)
    console.print(table)
    _print_components(spec, result.n_components)
    _print_tracking(result.vision, result.tracking_error_mm, result.tracking_error_deg)
    if result.tracking_failures:
        console.print(
            f"[red]{result.tracking_failures} placement(s) where the cameras did not locate "
            "every object (counted as failures)"
        )


@app.command()
@_reports_errors
def study(
    task: Annotated[str, typer.Option(help=f"{_TASK_HELP}.")] = "coaster",
    out: Annotated[Path, typer.Option(help="Folder for the report.")] = Path("study-output"),
    seed: Annotated[int, typer.Option(help="Seed of the demonstrations and placements.")] = 0,
    full: Annotated[
        bool, typer.Option("--full", help="The full size (11 x 11 maps, 40 trials per point).")
    ] = False,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Run the trials in N local worker processes, at most one per core (a larger "
            "N is capped, with a notice)."
        ),
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Run the trials on the Dask cluster at this address.")
    ] = None,
) -> None:
    """Where a skill works: a map of the table per object, a learning curve (2-10
    demonstrations) and the tolerance to tracking noise (0-10 mm), with report.html in OUT."""
    _check_output(out, "--out", folder=True)
    _check_seed(seed)
    workers = _check_workers(workers, scheduler)
    _start_workers_early(workers)
    spec = _robot_task(task)
    from ._study import FULL, SMALL, check_study, run_study

    size = FULL if full else SMALL
    check_study(spec, size=size, seed=seed)  # before the progress bar shows
    with _progress() as bar:
        job = bar.add_task(f"{task}: teaching and learning", total=None)

        def tick(stage: str, done: int, total: int) -> None:
            bar.update(job, description=f"{task}: {stage}", completed=done, total=total)

        result = run_study(
            spec,
            out,
            size=size,
            seed=seed,
            workers=workers,
            scheduler=scheduler,
            progress=tick,
        )
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


@app.command()
@_reports_errors
def view(
    task: Annotated[
        str | None,
        typer.Option(help=f"{_TASK_HELP}: teach and learn it as `pbdkit demo` does."),
    ] = None,
    skill_path: Annotated[
        Path | None, typer.Option("--skill", help="A skill file (.npz) instead of a task.")
    ] = None,
    robot: Annotated[
        str | None,
        typer.Option(
            help="With --skill: the URDF to draw the arm from (meshes are looked up beside "
            "it), or katana; default: the URDF stored in the skill file.",
        ),
    ] = None,
    obj: Annotated[
        list[str] | None,
        typer.Option(
            "--object",
            help="With --skill: where an object starts, NAME=x,y,z or NAME=x,y,z,qw,qx,qy,qz "
            "(default: where the demonstrations had it on average, "
            "pbdkit.apps._view_plan.typical_placements).",
        ),
    ] = None,
    port: Annotated[int, typer.Option(help="Port on 127.0.0.1.")] = 8080,
    no_browser: Annotated[
        bool, typer.Option("--no-browser", help="Do not open a browser; print the URL.")
    ] = False,
    seed: Annotated[int, typer.Option(help="With --task: seed of the demonstrations.")] = 0,
) -> None:
    """Serve a live 3-D view on http://127.0.0.1:PORT: drag an object and the plan follows
    (the hand path, the arm over time, the constraints' Gaussians and which one drives), run
    it in physics, or online while you drag (needs the view extra: pip install pbdkit[view])."""
    from ._view import check_port

    if (task is None) == (skill_path is None):
        _fail("give --task or --skill (one of them)")
    if task is not None and (robot is not None or obj):
        _fail("--robot and --object apply to --skill; a task has its own arm and objects")
    _check_seed(seed)
    check_port(port)  # before the teaching and learning; serve checks again as it binds
    try:
        import viser  # noqa: F401
        import yourdfpy  # noqa: F401
    except ImportError as exc:
        _fail(f"pbdkit view needs the view extra (pip install 'pbdkit[view]'): {exc}")
    from ._view import ViewApp, serve

    if skill_path is not None:
        from .. import robots
        from ..skill._skill import Skill
        from ._view_plan import typical_placements

        if not skill_path.is_file():
            raise FileNotFoundError(2, "No such file", str(skill_path))
        skill = Skill.load(skill_path)
        urdf: Path | None = None
        if robot is not None and robot in robots.available():
            urdf = robots.katana_urdf_path() if robot == "katana" else None
        elif robot is not None:
            urdf = Path(robot)
            if not urdf.is_file():
                raise FileNotFoundError(2, "No such file", str(urdf))
        objects = typical_placements(skill)
        given = _parse_objects(obj or [])
        unknown = [k for k in given if k not in skill.object_names]
        if unknown:
            _fail(f"--object: {unknown} are not objects of the skill ({skill.object_names})")
        objects.update(given)
        title = f"skill {skill_path.name}"

        def factory(server: Any) -> ViewApp:
            return ViewApp(skill, objects, server, urdf=urdf, title=title)

    else:
        assert task is not None
        spec = _robot_task(task)
        from ..sim._task_skill import learn_task

        with console.status(f"teaching and learning the {spec.name} task ..."):
            ts = learn_task(spec, n_demos=5, seed=seed)
        placement = spec.nominal_objects()

        def factory(server: Any) -> ViewApp:
            return ViewApp(ts.skill, placement, server, task_skill=ts, title=f"task {spec.name}")

    serve(factory, port=port, open_browser=not no_browser, say=console.print)


def _print_components(spec: TaskSpec, n_components: dict[str, int]) -> None:
    ks = ", ".join(f"{k}: {v}" for k, v in n_components.items())
    fixed = [k for k in n_components if k in spec.fixed_objects]
    note = f" ({', '.join(fixed)}: fixed, learned with --constrain-fixed)" if fixed else ""
    console.print(f"K per space (chosen by leaving one demonstration out): {ks}{note}")


def _print_tracking(
    vision: bool, stats: dict[str, Any] | None, yaw: dict[str, Any] | None = None
) -> None:
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


def main() -> None:
    """Entry point of the ``pbdkit`` console script.

    Bad input (a ValueError or a missing file from the library), an output path that cannot be
    written, a file-system error or exhausted memory end with a one-line message and exit
    status 2, not a traceback (each command reports its own; this catches the rest).
    """
    try:
        app()
    except _USER_ERRORS as exc:
        console.print(Text.assemble(("error: ", "bold red"), _error_message(exc)), soft_wrap=True)
        raise SystemExit(2) from None
    finally:
        # The process ends here: the interpreter's last collection would walk every object
        # the command loaded (0.3-0.5 s after a simulation; benchmarks/README.md), only for the
        # operating system to free them. Frozen objects are left out of it.
        gc.freeze()
