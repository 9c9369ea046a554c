"""The ``pbdkit`` command's options: their shared types and help, and the checks and parsing
of their values (each failure a one-line usage error, before any work).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, cast, overload

import numpy as np
import typer
from typer.core import TyperCommand

from .._validation import short
from ._cli_output import console, fail

if TYPE_CHECKING:
    from ..sim._tasks import TaskSpec

__all__ = [
    "BAG_SUFFIXES",
    "PERTURBATIONS",
    "TASKS",
    "TASK_HELP",
    "ConstrainFixedOption",
    "GroundTruthOption",
    "OnlineOption",
    "PerturbOption",
    "RegistryHelp",
    "SuggestRangeOption",
    "check_bag_output",
    "check_lasa_shape",
    "check_output",
    "check_perturb",
    "check_seed",
    "check_workers",
    "is_bag",
    "parse_objects",
    "robot_task",
    "start_workers_early",
]


# ----------------------------------------------------------------------------- paths
def check_output(
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
        if source is not None and same_file(path, source):
            fail(
                f"{option} {path}: is also {label} {source}, which the command reads; give "
                f"{option} another path"
            )
    for label, other in also:
        if other is not None and same_file(path, other):
            fail(f"{option} {path}: is also {label} {other}; give each output its own path")
    real = Path(os.path.realpath(path))
    if folder and real.exists():
        if not real.is_dir():
            fail(f"{option} {path}: exists and is not a directory; give a directory")
        if not os.access(real, os.W_OK | os.X_OK):
            fail(f"{option} {path}: the directory is not writable")
        return
    if real.is_dir():
        fail(f"{option} {path}: is a directory; give a file path")
    parent = real.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        fail(f"{option} {path}: the directory {parent} {what}")
    if not os.access(parent, os.W_OK | os.X_OK):
        fail(f"{option} {path}: the directory {parent} is not writable")


def same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name the same file: the same path once links are resolved, or
    (both existing) the same file on disk (a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): different files
        return False


# Suffixes of the files `learn` reads: a pbdkit archive, or a bag (a rosbag2 bag is usually a
# directory holding metadata.yaml; its storage file, or a ROS 1 bag, works too).
BAG_SUFFIXES = (".db3", ".mcap", ".bag")


def is_bag(path: Path) -> bool:
    """Whether ``path`` is a ROS bag (a rosbag2 directory or a bag's storage file)."""
    return path.is_dir() or path.suffix in BAG_SUFFIXES


def check_bag_output(bag: Path) -> None:
    """Fail unless a new bag (a directory) can be created at ``bag`` (that it is not ``--out``
    is :func:`check_output`'s check)."""
    if bag.exists() or bag.is_symlink():
        fail(f"--bag {bag}: exists; give a new path (a bag is a directory, never overwritten)")
    check_output(bag, "--bag")


# ----------------------------------------------------------------------------- values
def check_seed(seed: int) -> None:
    """Fail unless ``seed`` can seed NumPy's generators (an integer >= 0)."""
    if seed < 0:
        fail(f"--seed must be an integer >= 0, got {seed}")


def robot_task(task: str, *, also: tuple[str, ...] = ()) -> TaskSpec:
    """The registered robot task named ``task``, or a usage error listing the choices (the
    registered tasks, then ``also``).

    Imports the simulator (MuJoCo): call it after the cheap checks of a command's options.
    """
    from ..sim._task_registry import get_task, task_names

    try:
        return get_task(task)
    except ValueError:
        choices = ", ".join([*task_names(), *also])
        raise typer.BadParameter(
            f"task must be one of {choices}; got {short(task)}", param_hint="--task"
        ) from None


# Placeholders of a help text that :class:`RegistryHelp` fills from the simulator's registries
# when the help is shown: the registered tasks, and the perturbations with their help texts.
TASKS = "{tasks}"
PERTURBATIONS = "{perturbations}"
TASK_HELP = f"A robot task: {TASKS} (more with pbdkit.sim.register_task)"

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
# Shared by `view` and `ros record` (each with --suggest).
SuggestRangeOption = Annotated[
    list[str] | None,
    typer.Option(
        "--range",
        help="With --suggest: NAME=x0:x1,y0:y1[,yaw0:yaw1], where NAME may be put (as for "
        "pbdkit suggest); default: each object's demonstrated box widened to twice its "
        "half-width on each side.",
    ),
]
PerturbOption = Annotated[str, typer.Option(help=f"Disturbance: {PERTURBATIONS}.")]


class RegistryHelp(TyperCommand):
    """A command whose options' help lists what is registered: :data:`TASKS` becomes the
    registered tasks (:func:`pbdkit.sim.task_names`), :data:`PERTURBATIONS` the perturbations
    with their help texts (:func:`pbdkit.sim._perturb.perturbation_help`). They are read when
    the help is shown: the registries live with the simulator, which the command line imports
    only to run a command."""

    def format_help(self, ctx: Any, formatter: Any) -> None:
        from ..sim._perturb import perturbation_help
        from ..sim._task_registry import task_names

        fill = {TASKS: lambda: ", ".join(task_names()), PERTURBATIONS: perturbation_help}
        for param in self.params:
            text = getattr(param, "help", None)
            if isinstance(text, str):
                for key, value in fill.items():
                    if key in text:
                        text = text.replace(key, value())
                cast(Any, param).help = text
        super().format_help(ctx, formatter)


def check_perturb(perturb: str) -> None:
    """A usage error unless ``perturb`` is a registered perturbation (imports the simulation;
    whether the task has it is the library's check)."""
    from ..sim._perturb import perturbation_names

    if perturb not in perturbation_names():
        raise typer.BadParameter(
            f"must be one of {', '.join(perturbation_names())}, got {short(perturb)}",
            param_hint="--perturb",
        )


def check_workers(
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


def start_workers_early(workers: int | None) -> None:
    """Local workers fork from a server that imports the simulation once: start it before this
    process imports the simulation itself, so that the two imports overlap (call it after the
    cheap checks of the options)."""
    if workers is not None:
        from ..sim import _forkserver

        _forkserver.start()


def check_lasa_shape(shape: str) -> None:
    from ..datasets import lasa_names

    try:
        names = lasa_names()
    except (ModuleNotFoundError, FileNotFoundError) as exc:  # the data are an optional extra
        fail(f"--task lasa: {exc}")
    if shape not in names:
        fail(f"--shape must be a LASA shape, one of {', '.join(names)}; got {short(shape)}")


# ----------------------------------------------------------------------------- objects
@overload
def parse_objects(texts: list[str]) -> dict[str, np.ndarray]: ...


@overload
def parse_objects(texts: list[str], *, sources: Literal[True]) -> dict[str, str | np.ndarray]: ...


def parse_objects(texts: list[str], *, sources: bool = False) -> dict[str, Any]:
    """The --object NAME=VALUE options as a dict; an object given twice is an error.

    VALUE is a position x,y,z (metres), or a pose x,y,z,qw,qx,qy,qz with the quaternion **w
    first** (pytransform3d's convention; ROS messages hold x,y,z,w), passed on as a 7-vector;
    with ``sources`` (`learn`'s bags), also where to read it: a topic or tf:FRAME (any VALUE
    that is not numbers).
    """
    objects: dict[str, Any] = {}
    for text in texts:
        name, value = parse_object(text, sources=sources)
        if name in objects:
            fail(f"--object {name} is given twice; give each object once")
        objects[name] = value
    return objects


def parse_object(text: str, *, sources: bool) -> tuple[str, str | np.ndarray]:
    """One --object NAME=VALUE option (see :func:`parse_objects`)."""
    name, sep, rest = text.partition("=")
    forms = "NAME=x,y,z (metres) or NAME=x,y,z,qw,qx,qy,qz (a pose, quaternion w first)"
    if not sep or not name or not rest:
        want = "NAME=SOURCE (a topic, tf:frame, x,y,z or x,y,z,qw,qx,qy,qz)" if sources else forms
        raise typer.BadParameter(f"expected {want}, got {short(text)}", param_hint="--object")
    try:
        values = [float(v) for v in rest.split(",")]
    except ValueError:
        if sources:
            return name, rest
        values = []
    if len(values) not in (3, 7):
        got = f"{len(values)} numbers" if values else "not numbers"
        raise typer.BadParameter(
            f"expected {forms}, got {short(text)} ({got})", param_hint="--object"
        )
    return name, np.array(values)
