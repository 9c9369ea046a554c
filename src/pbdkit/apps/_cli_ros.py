"""``pbdkit ros``: a skill on a live ROS 2 graph (issue 37). ``pbdkit ros run`` runs a skill
file on an arm behind a joint_trajectory_controller (:func:`pbdkit.ros._run.run_skill`); it
needs the ``ros`` extra (``pip install 'pbdkit[ros]'``)."""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from ._cli_options import parse_objects
from ._cli_output import fail, reports_errors

ros_app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="A skill on a live ROS 2 graph: run it on an arm (pip install 'pbdkit[ros]').",
)


@ros_app.command()
@reports_errors
def run(
    skill_path: Annotated[Path, typer.Argument(metavar="SKILL", help="A skill file (.npz).")],
    controller: Annotated[
        str, typer.Option(help="The joint_trajectory_controller's name (e.g. arm_controller).")
    ],
    obj: Annotated[
        list[str] | None,
        typer.Option(
            "--object", help="NAME=x,y,z or NAME=x,y,z,qw,qx,qy,qz in the robot's base frame."
        ),
    ] = None,
    joint_states: Annotated[str, typer.Option(help="sensor_msgs/JointState topic.")] = (
        "/joint_states"
    ),
    joint_map: Annotated[
        list[str] | None,
        typer.Option(help="SKILL_JOINT=GRAPH_JOINT, for joints named otherwise on the graph."),
    ] = None,
    speed: Annotated[float, typer.Option(help="Time scale, 0.1 to 1 (slower below 1).")] = 1.0,
    dry_run: Annotated[bool, typer.Option(help="Plan and print; send nothing.")] = False,
    stale: Annotated[float, typer.Option(help="Joint states older than this (s) stop it.")] = 0.2,
    max_following_error: Annotated[
        float, typer.Option(help="Stop beyond this following error (rad).")
    ] = 0.05,
    timeout: Annotated[
        float, typer.Option(help="Seconds to wait for joint states, a controller and motion.")
    ] = 5.0,
    assume_limits: Annotated[
        bool,
        typer.Option(help="An arm without acceleration or jerk limits: a = v/0.25 s, j = a/0.1 s."),
    ] = False,
) -> None:
    """Run a skill on an arm behind a joint_trajectory_controller. Exit codes: 0 ran to its end,
    at rest; 2 usage or refused; 3 stale joint states; 4 no or inactive controller; 5 following
    error; 130 SIGINT or SIGTERM (brought to rest first)."""
    from ..ros._graph import ros_available

    if not ros_available():
        fail("pbdkit ros needs the ros extra: pip install 'pbdkit[ros]'")
    from ..ros._joints import parse_joint_map
    from ..ros._run import RunFailed, RunSettings, run_skill
    from ..skill._skill import Skill

    settings = RunSettings(
        controller=controller,
        joint_states=joint_states,
        joint_map=parse_joint_map(joint_map or []),
        speed=speed,
        stale=stale,
        max_following_error=max_following_error,
        timeout=timeout,
        dry_run=dry_run,
        assume_limits=assume_limits,
    )
    if not skill_path.is_file():
        raise FileNotFoundError(2, "No such file", str(skill_path))
    skill = Skill.load(skill_path)
    objects = parse_objects(obj or [])
    missing = [k for k in skill.object_names if k not in objects]
    if missing:
        fail(f"--object: give {missing} (fixed coordinates; object topics are not read yet)")
    code = _run_node(lambda node, stop: run_skill(node, skill, objects, settings, stop=stop))
    if isinstance(code, RunFailed):
        typer.echo(f"error: {code}", err=True)
        raise typer.Exit(code.code)
    raise typer.Exit(code)


def _run_node(body: Any) -> Any:
    """``body(node, stop)`` on a node of its own; SIGINT and SIGTERM set ``stop`` (the body
    brakes and returns 130). Returns the body's exit code, or the RunFailed it raised."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from ..ros._run import RunFailed

    stopped: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stopped.append(1))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node: Any = rclpy.create_node("pbdkit_ros_run")
    try:
        return body(node, lambda: bool(stopped))
    except RunFailed as err:
        return err
    finally:
        node.destroy_node()
        rclpy.shutdown()
        sys.stdout.flush()
