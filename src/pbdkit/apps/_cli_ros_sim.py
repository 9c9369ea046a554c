"""``pbdkit ros sim``: the MuJoCo world of a task as a ROS 2 robot (issue 37;
:class:`pbdkit.ros._sim_world.SimWorld`). Registered in the ``ros`` group by
:mod:`pbdkit.apps._cli_ros`; needs the ``ros`` extra."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from .._defaults import install_hint
from ._cli_options import TASK_HELP, PerturbOption, check_output, check_perturb, check_seed
from ._cli_output import fail
from ._cli_ros_node import run_node

__all__ = ["sim_command"]

#: The node's name on the graph.
NODE_NAME = "pbdkit_ros_sim"
#: Exit codes: the run succeeded (or the teacher's takes are done), it failed, a signal.
EXIT_SUCCESS, EXIT_FAILURE, EXIT_SIGNAL = 0, 1, 130


def sim_command(
    task: Annotated[str, typer.Option(help=f"{TASK_HELP}.")] = "coaster",
    seed: Annotated[int, typer.Option(help="pbdkit evaluate's --seed: its placements.")] = 0,
    placement: Annotated[
        int,
        typer.Option(
            help="The objects of pbdkit evaluate's trial PLACEMENT (from 0): --placement 0..19 "
            "are evaluate --trials 20's."
        ),
    ] = 0,
    interpolate_from_desired_state: Annotated[
        bool,
        typer.Option(
            "--interpolate-from-desired-state",
            help="The JTC's option: a message's first segment starts from the last command "
            "(default: from the measured state).",
        ),
    ] = False,
    cameras: Annotated[
        bool,
        typer.Option(
            "--cameras",
            help="Publish the objects as the stereo cameras see them (default: true poses).",
        ),
    ] = False,
    perturb: PerturbOption = "none",
    skill_path: Annotated[
        Path | None,
        typer.Option(
            "--skill",
            help="A skill file (.npz): the arm starts at its start posture; a disturbance "
            "before the grasp (push) is timed on its grasp.",
        ),
    ] = None,
    teach: Annotated[
        bool,
        typer.Option(
            "--teach",
            help="Replay the simulated teacher (for pbdkit ros record): --takes demonstrations, "
            "each at placement i with 1.5 s at rest before and 2.5 s after; no trajectory is "
            "followed.",
        ),
    ] = False,
    takes: Annotated[int, typer.Option(help="Demonstrations with --teach.")] = 5,
    teach_speed: Annotated[
        float,
        typer.Option(help="The teacher's speed (the Katana's velocity limits cap it)."),
    ] = 1.0,
    time_scale: Annotated[
        float,
        typer.Option(
            help="World seconds per second, up to 20 (default 1: real time; more for tests). "
            "Header stamps are the world's time."
        ),
    ] = 1.0,
    exit_after_run: Annotated[
        bool,
        typer.Option(
            "--exit-after-run",
            help="Exit once the run is judged (0 success, 1 failure), or with --teach after "
            "the last take (0).",
        ),
    ] = False,
    report: Annotated[
        Path | None,
        typer.Option("--report", help="Write the run's report (JSON) here when it is judged."),
    ] = None,
) -> None:
    """The MuJoCo world of a task as a ROS 2 robot: joint states, the objects' poses, an arm
    and a gripper behind joint_trajectory_controllers; the run (from the first arm
    trajectory to 1 s after the last one's end) judged as pbdkit evaluate judges a trial.
    Needs the ros extra. Exit codes: 0 success (or the takes done), 1 failure (with
    --exit-after-run), 2 usage, 130 SIGINT or SIGTERM."""
    from ..ros._graph import ros_available

    if not ros_available():
        fail(f"pbdkit ros needs the ros extra: {install_hint('ros')}")
    check_seed(seed)
    check_perturb(perturb)
    if report is not None:
        check_output(report, "--report", inputs=[("--skill", skill_path)])
    from ..ros._task_world import WorldSettings, check_world

    settings = WorldSettings(
        task=task,
        seed=seed,
        placement=placement,
        interpolate_from_desired_state=interpolate_from_desired_state,
        cameras=cameras,
        perturb=perturb,
        teach=teach,
        takes=takes,
        teach_speed=teach_speed,
        time_scale=time_scale,
        exit_after_run=exit_after_run,
    )
    skill = None
    if skill_path is not None:
        from ..skill._skill import Skill

        if not skill_path.is_file():
            raise FileNotFoundError(2, "No such file", str(skill_path))
        skill = Skill.load(skill_path)
    check_world(settings, skill)  # before the node: a usage error in one line
    code = run_node(lambda node, stop: _serve(node, stop, settings, skill, report), NODE_NAME)
    raise typer.Exit(code)


def _serve(
    node: Any,
    stop: Callable[[], bool],
    settings: Any,
    skill: Any,
    report: Path | None,
) -> int:
    """The world on ``node`` until a signal, or with ``exit_after_run`` its judgement."""
    import rclpy

    from .._io import write_json
    from ..ros._sim_world import SimWorld

    world = SimWorld(node, settings, skill=skill, log=_say)
    reported = False
    try:
        _say(_up_line(world))
        while not stop():
            rclpy.spin_once(node, timeout_sec=0.05)
            done = world.report()
            if done is None or reported:
                continue
            reported = True
            _say(_summary(done))
            if report is not None:
                write_json(report, done)
            if settings.exit_after_run:
                ok = bool(done.get("teach_done") or done.get("success"))
                return EXIT_SUCCESS if ok else EXIT_FAILURE
        return EXIT_SIGNAL
    finally:
        world.close()


def _say(line: str) -> None:
    typer.echo(line)
    sys.stdout.flush()


def _up_line(world: Any) -> str:
    """``ros sim: coaster placement 0 (seed 0) ...; publishing ...; following ...``."""
    s = world.settings
    what = (
        f"teaching {s.takes} take{'s' if s.takes > 1 else ''} (seed {s.seed}, speed "
        f"{s.teach_speed:g}; they begin when /joint_states has a subscriber)"
        if s.teach
        else f"placement {s.placement} (seed {s.seed}), perturb {s.perturb}"
    )
    if s.cameras:
        what += ", cameras"
    if s.time_scale != 1.0:
        what += f", {s.time_scale:g}x real time"
    following = ", ".join(world.following) or "nothing (--teach)"
    return f"ros sim: {s.task} {what}; publishing {', '.join(world.topics)}; following {following}"


def _summary(report: dict[str, Any]) -> str:
    """One line: the run's success, its task metrics, the servo targets' worst v/a/j."""
    if report.get("teach_done"):
        return f"teach: done, {len(report['takes'])} takes"
    metrics = [
        f"{k} {'?' if v is None else format(v, '.1f')}" for k, v in report["metrics"].items()
    ]
    ratios = [report.get(f"peak_{k}_ratio") for k in ("velocity", "acceleration", "jerk")]
    vaj = "/".join("?" if r is None else f"{r:.2f}" for r in ratios)
    arm = report["messages"]["arm"]
    return (
        f"run: {'success' if report['success'] else 'failure'}"
        f"{' (' + ', '.join(metrics) + ')' if metrics else ''}; servo v/a/j {vaj} of the "
        f"limits; arm trajectories {arm['accepted']} accepted, {arm['rejected']} rejected"
    )
