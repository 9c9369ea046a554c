"""``pbdkit ros``: a skill on a live ROS 2 graph (issue 37). ``pbdkit ros run`` runs a skill
file on an arm behind a joint_trajectory_controller (:func:`pbdkit.ros._run.run_skill`); it
needs the ``ros`` extra (:func:`pbdkit._defaults.install_hint`)."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from .._defaults import install_hint
from .._validation import short
from ._cli_options import RegistryHelp, SuggestRangeOption, parse_objects
from ._cli_output import fail, reports_errors
from ._cli_ros_node import run_node
from ._cli_ros_sim import sim_command

ros_app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="A skill on a live ROS 2 graph: run it on an arm (needs the ros extra: "
    "pip install -e '.\\[ros]' in the pbdkit checkout).",
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
            "--object",
            help="NAME=SOURCE: a PoseStamped or PointStamped topic (/NAME), or x,y,z or "
            "x,y,z,qw,qx,qy,qz; in the robot's base frame (tf:FRAME is refused: no tf2_msgs).",
        ),
    ] = None,
    grasped: Annotated[
        str | None,
        typer.Option(help="The object the gripper takes: its topic is ignored once it closes."),
    ] = None,
    gripper_controller: Annotated[
        str | None, typer.Option(help="The gripper's joint_trajectory_controller.")
    ] = None,
    gripper_joint: Annotated[
        str | None, typer.Option(help="NAME:OPEN:CLOSED, the gripper joint and its positions.")
    ] = None,
    gripper_seconds: Annotated[
        float, typer.Option(help="Seconds each gripper command takes.")
    ] = 0.3,
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
    scene: Annotated[
        Path | None,
        typer.Option(
            help="A scene file (YAML, docs: collisions): the plan is checked against it before "
            "anything is sent, and every plan keeps clear of it."
        ),
    ] = None,
    latency: Annotated[
        float | None,
        typer.Option(
            help="The longest (s) the arm's controller takes to take a message: each arm "
            "trajectory is stamped with this machine's clock, its first point at least this "
            "far ahead, and the controller starts it where the run planned it (a re-plan's "
            "splice keeps the limits; it reacts this much later). Needs the controller's clock "
            "within a millisecond of this machine's (the same machine, or chrony). Default: "
            "stamp 0, each starts when the controller takes it (docs: ros2).",
            max=0.5,
        ),
    ] = None,
) -> None:
    """Run a skill on an arm behind a joint_trajectory_controller. Exit codes: 0 ran to its end,
    at rest; 2 usage or refused; 3 stale joint states; 4 no or inactive controller; 5 following
    error; 6 a plan would collide with --scene (nothing sent, or brought to rest) or could not
    be made; 130 SIGINT or SIGTERM (brought to rest first)."""
    from ..ros._graph import ros_available

    if not ros_available():
        fail(f"pbdkit ros needs the ros extra: {install_hint('ros')}")
    from ..collision import Scene
    from ..ros._joints import parse_joint_map
    from ..ros._objects import check_sources
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
        gripper_controller=gripper_controller,
        gripper_joint=None if gripper_joint is None else parse_gripper_joint(gripper_joint),
        gripper_seconds=gripper_seconds,
        grasped=grasped,
        scene=None if scene is None else Scene.load(scene),
        latency=latency,
    )
    if not skill_path.is_file():
        raise FileNotFoundError(2, "No such file", str(skill_path))
    skill = Skill.load(skill_path)
    objects = parse_objects(obj or [], sources=True)
    check_sources(objects)
    missing = [k for k in skill.object_names if k not in objects]
    if missing:
        fail(f"--object: give {missing} (a topic or coordinates)")
    if grasped is not None and grasped not in objects:
        fail(f"--grasped {short(grasped)} is none of the objects {sorted(objects)}")
    code = run_node(
        lambda node, stop: run_skill(node, skill, objects, settings, stop=stop, log=_say)
    )
    if isinstance(code, RunFailed):
        typer.echo(f"error: {code}", err=True)
        raise typer.Exit(code.code)
    raise typer.Exit(code)


ros_app.command("sim", cls=RegistryHelp)(reports_errors(sim_command))


@ros_app.command()
@reports_errors
def record(
    out: Annotated[
        Path, typer.Option(help="Demonstrations file (.npz): each take is appended to it.")
    ],
    robot: Annotated[str, typer.Option(help="katana, panda, or a URDF file.")] = "katana",
    tip: Annotated[str | None, typer.Option(help="Tip frame (URDF robots).")] = None,
    obj: Annotated[
        list[str] | None,
        typer.Option(
            "--object",
            help="NAME=SOURCE, as for pbdkit ros run; its pose at each take's start is kept.",
        ),
    ] = None,
    joint_states: Annotated[str, typer.Option(help="sensor_msgs/JointState topic.")] = (
        "/joint_states"
    ),
    joint_map: Annotated[
        list[str] | None,
        typer.Option(help="ROBOT_JOINT=GRAPH_JOINT, for joints named otherwise on the graph."),
    ] = None,
    gripper_joint: Annotated[
        str | None,
        typer.Option(help="NAME:OPEN:CLOSED: the gripper's joint state, recorded 0..1."),
    ] = None,
    takes: Annotated[
        int | None, typer.Option(help="Stop after this many takes (default: at Ctrl-C).")
    ] = None,
    auto: Annotated[
        bool, typer.Option(help="Start a take on motion, stop it after --rest s at rest.")
    ] = False,
    rest: Annotated[float, typer.Option(help="--auto: seconds at rest that end a take.")] = 1.0,
    timeout: Annotated[
        float, typer.Option(help="Seconds to wait for joint states and the objects.")
    ] = 5.0,
    suggest: Annotated[
        Path | None,
        typer.Option(
            help="A skill file (version 3): before each take, print where to put the objects "
            "(Skill.suggest); after it, update the skill with the take and write it back.",
        ),
    ] = None,
    ranges: SuggestRangeOption = None,
    view: Annotated[
        bool,
        typer.Option(
            help="With --suggest: also show, in a browser on 127.0.0.1 (--port), where the "
            "next take's objects go, as ghosts that turn when an object is in place, with "
            "the arm and the objects live (needs the view extra).",
        ),
    ] = False,
    port: Annotated[int, typer.Option(help="With --view: the page's port.")] = 8080,
) -> None:
    """Record demonstrations on a live arm (kinesthetic teaching: putting the arm in its
    hand-guiding mode is yours). A take starts and stops on Enter, or with --takes N --auto on
    motion; each is appended to --out, which pbdkit learn reads. With --suggest, the skill
    says where each take should put the objects, and learns each take at once."""
    from ..ros._graph import ros_available
    from ._cli_suggest import SuggestingTeacher, parse_range, ranges_from_options

    if ranges and suggest is None:
        fail("--range goes with --suggest SKILL")
    if view and suggest is None:
        fail("--view goes with --suggest SKILL")
    teacher = None
    if suggest is not None:
        parsed = [parse_range(r) for r in ranges or []]
        teacher = SuggestingTeacher(suggest)
        if parsed:
            teacher.ranges = ranges_from_options(teacher.skill, parsed)
    if not ros_available():
        fail(f"pbdkit ros needs the ros extra: {install_hint('ros')}")
    from ..data._demonstration import load_demonstrations, save_demonstrations
    from ..ros._joints import parse_joint_map
    from ..ros._objects import ObjectSources, check_sources
    from ..ros._record import RecordSettings, record_takes

    settings = RecordSettings(
        joint_states=joint_states,
        joint_map=parse_joint_map(joint_map or []),
        takes=takes,
        auto=auto,
        rest=rest,
        gripper_joint=None if gripper_joint is None else parse_gripper_joint(gripper_joint),
        timeout=timeout,
    )
    objects = parse_objects(obj or [], sources=True)
    check_sources(objects)
    names = _robot_joint_names(robot, tip)
    if teacher is not None:
        teacher.check_takes(names, objects, gripper=gripper_joint is not None)
    demos = load_demonstrations(out) if out.exists() else []
    if demos and (
        demos[0].n_joints != len(names)
        or set(demos[0].object_names) != set(objects)
        or (demos[0].gripper is None) != (gripper_joint is None)
    ):
        fail(
            f"{out} holds demonstrations of {demos[0].n_joints} joints with objects "
            f"{list(demos[0].object_names)}, {'without' if demos[0].gripper is None else 'with'}"
            " a gripper; record into another file"
        )
    page = None if teacher is None or not view else _record_view(teacher, robot, port)

    def save(demo: Any) -> None:
        demos.append(demo)
        save_demonstrations(demos, out)
        if teacher is not None:
            _say(teacher.took(demo))
            announce()

    def announce() -> None:
        assert teacher is not None
        found = teacher.suggest()
        _say(teacher.next_text(found))
        if page is not None:
            page.show(found)

    pressed = _enter_presses() if not auto else (lambda: False)

    def body(node: Any, stop: Any) -> int:
        if teacher is not None:
            announce()
        sources = ObjectSources(node, objects, [] if teacher is None else teacher.posed, log=_say)
        n = record_takes(
            node,
            names,
            sources,
            settings,
            save=save,
            toggled=pressed,
            log=_say,
            stop=stop,
            on_sample=None if page is None else page.sample,
        )
        _say(f"{n} take(s) recorded; {out} holds {len(demos)} demonstration(s)")
        return 0

    try:
        code = run_node(body, "pbdkit_ros_record")
    finally:
        if page is not None:
            page.close()
    if isinstance(code, Exception):
        typer.echo(f"error: {code}", err=True)
        raise typer.Exit(3)
    raise typer.Exit(code)


def _record_view(teacher: Any, robot: str, port: int) -> Any:
    """``--view``: the page (:class:`pbdkit.apps._view_record.RecordView`), served."""
    try:
        import viser  # noqa: F401
        import yourdfpy  # noqa: F401
    except ImportError as exc:
        fail(f"--view needs the view extra ({install_hint('view')}): {exc}")
    from ._view_record import RecordView
    from ._view_urdf import arm_urdf

    urdf = arm_urdf(robot, teacher.skill.robot)
    page = RecordView(teacher.skill, port, urdf=urdf, ranges=teacher.ranges)
    _say(f"view: serving {page.url}")
    return page


def _robot_joint_names(robot: str, tip: str | None) -> list[str]:
    from .. import robots
    from ..robots._robot import Robot

    if robot in robots.available():
        return list(robots.load(robot).joint_names)
    if Path(robot).is_file():
        return list(Robot.from_urdf(Path(robot), tip=tip).joint_names)
    raise typer.BadParameter(
        f"robot must be one of {robots.available()} or a URDF file, got {short(robot)}",
        param_hint="--robot",
    )


def _enter_presses() -> Any:
    """A function telling whether Enter was pressed since its last call (stdin read on a
    thread of its own)."""
    import threading

    presses: list[int] = []

    def read() -> None:
        for _ in sys.stdin:
            presses.append(1)

    threading.Thread(target=read, daemon=True).start()

    def pressed() -> bool:
        if presses:
            presses.clear()
            return True
        return False

    return pressed


def _say(line: str) -> None:
    """One console line of a run, flushed (a log read live, or through a pipe)."""
    print(line, flush=True)


def parse_gripper_joint(text: str) -> tuple[str, float, float]:
    """``--gripper-joint NAME:OPEN:CLOSED``."""
    name, _, rest = text.partition(":")
    try:
        open_, closed = (float(v) for v in rest.split(":"))
    except ValueError:
        raise typer.BadParameter(
            f"expected NAME:OPEN:CLOSED (e.g. gripper:0.0:1.0), got {short(text)}",
            param_hint="--gripper-joint",
        ) from None
    if not name or not (math.isfinite(open_) and math.isfinite(closed)) or open_ == closed:
        raise typer.BadParameter(
            f"expected NAME:OPEN:CLOSED with two different finite positions, got {short(text)}",
            param_hint="--gripper-joint",
        )
    return name, open_, closed
