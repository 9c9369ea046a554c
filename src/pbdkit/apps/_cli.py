"""The ``pbdkit`` command: a thin layer over the library.

``pbdkit demo`` runs the main job end to end and writes its results to a folder. The other
commands expose one step each. Each command checks its options first
(:mod:`pbdkit.apps._cli_options`), turns a task's name into its spec and its run options into
one :class:`pbdkit.sim.TrialConditions`, once, then calls the library and prints what it
returns (:mod:`pbdkit.apps._cli_output`).
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.text import Text

from .._defaults import MAX_COMPONENTS, MAX_TRIALS, install_hint
from .._io import write_json
from .._validation import check_int, short
from ._cli_files import bag_extras, bag_timing, load_demos, timing_text
from ._cli_options import (
    PERTURBATIONS,
    TASK_HELP,
    ConstrainFixedOption,
    GroundTruthOption,
    OnlineOption,
    PerturbOption,
    RegistryHelp,
    SuggestRangeOption,
    check_bag_output,
    check_lasa_shape,
    check_output,
    check_perturb,
    check_seed,
    check_workers,
    is_bag,
    parse_objects,
    robot_task,
    start_workers_early,
)
from ._cli_output import (
    USER_ERRORS,
    closest_approach_text,
    console,
    error_message,
    fail,
    print_evaluation,
    print_lasa_demo,
    print_oriented,
    print_robot_demo,
    print_study,
    progress_bar,
    reports_errors,
    unwrap_help,
)

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Teach a robot arm a skill from a few demonstrations (Calinon & Billard, IROS 2008).",
)


def _add_ros() -> None:
    from ._cli_ros import ros_app

    app.add_typer(ros_app, name="ros")


_add_ros()


def _add_suggest() -> None:
    from ._cli_suggest import suggest_command

    app.command("suggest")(suggest_command)


_add_suggest()


@app.callback()
def _root() -> None:
    """Teach a robot arm a skill from a few demonstrations (Calinon & Billard, IROS 2008)."""


# ----------------------------------------------------------------------------- commands
@app.command(cls=RegistryHelp)
@reports_errors
def demo(
    out: Annotated[Path, typer.Option(help="Folder for the results.")] = Path("demo-output"),
    task: Annotated[str, typer.Option(help=f"{TASK_HELP}, or lasa.")] = "coaster",
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
            help=f"Disturbance of the online run (with --online): {PERTURBATIONS}; default move.",
        ),
    ] = "move",
) -> None:
    """Run the main job: demonstrations -> skill -> new situation -> physics, with figures,
    a video, report.html and metrics.json in OUT. With --online, the fused controller also
    runs in the physics loop under a disturbance, beside the offline run."""
    check_output(out, "--out", folder=True)
    check_seed(seed)
    check_perturb(perturb)
    if task == "lasa":
        check_lasa_shape(shape)
        from ._demo import run_lasa_demo

        with console.status(f"learning LASA shape {shape} ..."):
            lasa_metrics = run_lasa_demo(out, shape)
        print_lasa_demo(shape, lasa_metrics, out)
        return
    spec = robot_task(task, also=("lasa",))
    from ..sim._tracking import ObjectNotSeenError
    from ..sim._trials import TrialConditions
    from ._demo import run_robot_demo

    # --perturb (default move) disturbs the online run only.
    conditions = TrialConditions(
        online=online,
        perturb=perturb if online else "none",
        ground_truth=ground_truth,
        seed=seed,
    )
    try:
        with console.status("starting ...") as st:
            robot_metrics = run_robot_demo(
                spec,
                out,
                conditions=conditions,
                status=lambda m: st.update(m),
                constrain_fixed=constrain_fixed,
            )
    except ObjectNotSeenError as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(1) from None
    print_robot_demo(spec, robot_metrics, seed, out)


@app.command(cls=RegistryHelp)
@reports_errors
def teach(
    task: Annotated[str, typer.Option(help=f"{TASK_HELP}.")] = "coaster",
    demos: Annotated[int, typer.Option(help="Number of demonstrations.")] = 5,
    out: Annotated[Path, typer.Option(help="Output .npz file.")] = Path("demos.npz"),
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Record simulated kinesthetic demonstrations of a task."""
    if demos < 2:
        raise typer.BadParameter(
            f"need at least 2 demonstrations, got {demos}", param_hint="--demos"
        )
    check_output(out, "--out")
    check_seed(seed)
    spec = robot_task(task)
    from ..data._demonstration import save_demonstrations
    from ..sim._task_skill import teach as sim_teach

    with console.status(f"teaching {demos} demonstrations ..."):
        items = sim_teach(spec, demos, seed=seed)
    save_demonstrations(items, out)
    console.print(f"wrote {len(items)} demonstrations to {out}")


@app.command()
@reports_errors
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
    an .npz file, or ROS bags (see docs/reproduction.md, "ROS bags", for the topics and
    conventions)."""
    from .. import robots
    from ..robots._robot import Robot
    from ..skill._skill import Skill

    shipped = robot in robots.available()
    if shipped and tip is not None:
        fail(f"--tip applies to a URDF robot; the shipped {robot} has a fixed tool frame")
    if shipped and joint_limits is not None:
        fail(
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
        fail(f"give one .npz file of demonstrations, or bags only; got {len(demos)} paths")
    if npz:
        given = [k for k, v in bag_options.items() if v is not None]
        if given:
            fail(f"{', '.join(given)} apply to bags; {npz[0]} is an .npz file")
    else:
        unknown = [p for p in demos if p.exists() and not is_bag(p)]
        if unknown:
            fail(
                f"{unknown[0]}: not an .npz file of demonstrations nor a ROS bag (a rosbag2 "
                "directory, .db3, .mcap or .bag file)"
            )
    sources = parse_objects(obj or [], sources=True)
    read: list[tuple[str, Path | None]] = [("DEMOS", d) for d in demos]
    read += [("--robot", None if shipped else Path(robot)), ("--joint-limits", joint_limits)]
    check_output(out, "--out", inputs=read)
    if shipped:
        arm = robots.load(robot)
    elif Path(robot).is_file():
        arm = Robot.from_urdf(Path(robot), tip=tip, joint_limits=joint_limits)
    else:
        raise typer.BadParameter(
            f"robot must be one of {robots.available()} or a URDF file, got {short(robot)}",
            param_hint="--robot",
        )
    items = load_demos(demos, arm, sources, joint_topic, gripper_topic, start, end)
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
    ks = ", ".join(f"{k}: {v}" for k, v in skill.n_components_.items())
    console.print(f"learned in {seconds:.2f} s; K per space: {ks}; wrote {out}")
    print_oriented(skill, items)


@app.command()
@reports_errors
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
            help="Output .npz file (format pbdkit-reproduction, version 1; "
            "ReproductionResult.load reads it): t, joints, positions, gripper, covariances, "
            "influence_NAME, joint_space_influence_NAME, task_error_NAME (m), limited, "
            "nominal_dt, gripper_signal (a skill with a gripper) and, with the robot's limits, "
            "times, velocities, accelerations, lead_in; for a skill with oriented constraints "
            "also orientations (T, 3, 3: the hand's axes in the base frame) and "
            "orientation_error_NAME (rad) per oriented object.",
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
    from ..skill._skill import Skill

    objects = parse_objects(obj)
    # The bag too is written (after the .npz): --out may not be where it goes.
    check_output(out, "--out", inputs=[("SKILL", skill_path)], also=[("--bag", bag)])
    if bag is not None:
        check_bag_output(bag)
    skill = Skill.load(skill_path)
    res = skill.reproduce(objects, use=use or None)
    # Before writing anything: the bag's content is checked (a skill without a duration or
    # joint names, times beyond what a bag holds), so that an error leaves no --out behind.
    timing = None if bag is None else bag_timing(skill, res, bag)
    res.save(out)
    console.print(
        f"wrote {out} ({len(res.t)} samples{timing_text(res)}); {closest_approach_text(res)}"
    )
    if bag is not None and timing is not None:
        from ..data._bag_write import write_trajectory_bag

        write_trajectory_bag(
            bag, timing.t, res.joints, timing.joint_names, **bag_extras(skill, res)
        )
        console.print(
            f"wrote {bag}: /joint_trajectory, {len(timing.t)} points over {timing.t[-1]:.2f} s"
        )


@app.command(cls=RegistryHelp)
@reports_errors
def evaluate(
    task: Annotated[str, typer.Option(help=f"{TASK_HELP}.")] = "coaster",
    trials: Annotated[int, typer.Option(help=f"Number of new placements, 1 to {MAX_TRIALS}.")] = 50,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    json_path: Annotated[Path | None, typer.Option("--json", help="Write results here.")] = None,
    ground_truth: GroundTruthOption = False,
    constrain_fixed: ConstrainFixedOption = False,
    online: OnlineOption = False,
    perturb: PerturbOption = "none",
    avoid_scene: Annotated[
        bool,
        typer.Option(
            "--avoid-scene",
            help="The fused controller keeps clear of the task's whole scene (the table, the "
            "shelf, the walls), not only --perturb obstacle's box. Every run is checked "
            "against the scene either way (collision_rate, min_clearance_m). Offline only.",
        ),
    ] = False,
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
    if not 1 <= trials <= MAX_TRIALS:
        fail(f"--trials must be an integer in [1, {MAX_TRIALS}] (MAX_TRIALS), got {trials}")
    check_seed(seed)
    # The trials' controller runs are the work items (a trial observes once, then runs its
    # controllers at once); without --controller their number is known after the learning.
    workers = check_workers(
        workers, scheduler, work=trials * len(controller) if controller else None
    )
    if controller and len(set(controller)) != len(controller):
        raise typer.BadParameter("a controller is named twice", param_hint="--controller")
    if json_path is not None:
        check_output(json_path, "--json")
    start_workers_early(workers)
    check_perturb(perturb)  # imports the simulation
    spec = robot_task(task)
    from ..sim._evaluation import evaluate as sim_evaluate

    with progress_bar() as bar:
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
            avoid_scene=avoid_scene,
        )
    if json_path is not None:
        write_json(json_path, result.as_dict())
    print_evaluation(spec, result)


@app.command(cls=RegistryHelp)
@reports_errors
def study(
    task: Annotated[str, typer.Option(help=f"{TASK_HELP}.")] = "coaster",
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
    active: Annotated[
        bool,
        typer.Option(
            "--active",
            help="Instead: three teachers from the same 2 demonstrations (where the skill "
            "suggests, at random, farthest from the demonstrated), the fused success over the "
            "wide grids after each demonstration (2 seeds, 4 x 4 grids, up to 5 "
            'demonstrations; --full: 5 seeds, 11 x 11, up to 12); study.json\'s "active".',
        ),
    ] = False,
    seeds: Annotated[
        int | None,
        typer.Option(help="With --active: compare the teachers at this many seeds instead."),
    ] = None,
) -> None:
    """Where a skill works: a map of the table per object, a learning curve (2-10
    demonstrations) and the tolerance to tracking noise (0-10 mm), with report.html in OUT;
    with --active, where to demonstrate next."""
    check_output(out, "--out", folder=True)
    check_seed(seed)
    workers = check_workers(workers, scheduler)
    start_workers_early(workers)
    spec = robot_task(task)
    if active:
        _study_active(spec, out, seed, full, workers, scheduler, seeds)
        return
    if seeds is not None:
        fail("--seeds goes with --active")
    from ._study import FULL, SMALL, check_study, run_study

    size = FULL if full else SMALL
    check_study(spec, size=size, seed=seed)  # before the progress bar shows
    result = _with_progress(
        task,
        "teaching and learning",
        lambda tick: run_study(
            spec, out, size=size, seed=seed, workers=workers, scheduler=scheduler, progress=tick
        ),
    )
    print_study(result, out)


def _with_progress(label: str, first: str, run: Callable[[Any], Any]) -> Any:
    """``run(tick)`` under a progress bar; ``tick(stage, done, total)`` moves it."""
    with progress_bar() as bar:
        job = bar.add_task(f"{label}: {first}", total=None)

        def tick(stage: str, done: int, total: int) -> None:
            bar.update(job, description=f"{label}: {stage}", completed=done, total=total)

        return run(tick)


def _study_active(
    spec: Any,
    out: Path,
    seed: int,
    full: bool,
    workers: int | None,
    scheduler: str | None,
    seeds: int | None,
) -> None:
    from dataclasses import replace

    from ._study_active import ACTIVE_FULL, ACTIVE_SMALL, TEACHERS, run_active_study

    size = ACTIVE_FULL if full else ACTIVE_SMALL
    if seeds is not None:
        size = replace(size, seeds=check_int(seeds, "--seeds", minimum=1))

    result = _with_progress(
        spec.name,
        "teaching",
        lambda tick: run_active_study(
            spec, out, size=size, seed=seed, workers=workers, scheduler=scheduler, progress=tick
        ),
    )
    act = result["active"]
    for kind in TEACHERS:
        got = act["needed"][kind]
        rates = ", ".join(f"{100 * v:.0f}" for v in act[kind])
        console.print(
            f"{kind}: success {rates} % at {act['n_demos'][0]}..{act['n_demos'][-1]} "
            f"demonstrations; 95 % with {'-' if got is None else f'{got:g}'}"
        )
    console.print(f"wrote {out / 'study.json'} and {out / 'active.png'}")


@app.command(cls=RegistryHelp)
@reports_errors
def view(
    task: Annotated[
        str | None,
        typer.Option(help=f"{TASK_HELP}: teach and learn it as `pbdkit demo` does."),
    ] = None,
    skill_path: Annotated[
        Path | None, typer.Option("--skill", help="A skill file (.npz) instead of a task.")
    ] = None,
    robot: Annotated[
        str | None,
        typer.Option(
            help="With --skill: the URDF to draw the arm from (meshes are looked up beside "
            "it), or a shipped robot (katana, panda), with the skill's arm's joints; default: "
            "the URDF stored in the skill file.",
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
    scene: Annotated[
        Path | None,
        typer.Option(
            help="With --skill: a scene file (YAML, docs: collisions), drawn; the fused plan "
            "keeps clear of it, and the arm is marked where it comes within 2 cm."
        ),
    ] = None,
    suggest: Annotated[
        int,
        typer.Option(
            "--suggest",
            help="With --skill: show the N placements (0..100) where a demonstration would "
            "help most (pbdkit suggest; a skill file of version 3) as ghosts of the objects, "
            "to drag the objects to.",
        ),
    ] = 0,
    ranges: SuggestRangeOption = None,
) -> None:
    """Serve a live 3-D view on http://127.0.0.1:PORT: drag an object and the plan follows
    (the hand path, the arm over time, the constraints' Gaussians and which one drives), run
    it in physics, or online while you drag (needs the view extra: make test installs it)."""
    from ._cli_suggest import parse_range
    from ._view_serve import check_port, sigint_deferred

    if (task is None) == (skill_path is None):
        fail("give --task or --skill (one of them)")
    if task is not None and (robot is not None or obj or scene is not None):
        fail(
            "--robot, --object and --scene apply to --skill; a task has its own arm, objects "
            "and scene"
        )
    if task is not None and (suggest or ranges):
        fail("--suggest and --range apply to --skill (a skill file)")
    if ranges and not suggest:
        fail("--range goes with --suggest N")
    check_int(suggest, "--suggest", minimum=0, maximum=100)
    parsed = [parse_range(r) for r in ranges or []]
    check_seed(seed)
    check_port(port)  # before the teaching and learning; serve checks again as it binds
    with sigint_deferred():  # a Ctrl+C in these imports ends the command after them
        try:
            import viser  # noqa: F401
            import yourdfpy  # noqa: F401
        except ImportError as exc:
            fail(f"pbdkit view needs the view extra ({install_hint('view')}): {exc}")
    from ._view import ViewApp
    from ._view_serve import serve

    if skill_path is not None:
        from ..skill._skill import Skill
        from ._view_plan import check_view_objects, typical_placements
        from ._view_suggest import suggest_settings
        from ._view_urdf import arm_urdf

        if not skill_path.is_file():
            raise FileNotFoundError(2, "No such file", str(skill_path))
        skill = Skill.load(skill_path)
        urdf = arm_urdf(robot, skill.robot)
        objects = typical_placements(skill)
        objects.update(check_view_objects(parse_objects(obj or []), skill))
        suggesting = suggest_settings(
            skill, suggest, parsed, say=lambda line: console.print(line, soft_wrap=True)
        )
        title = f"skill {skill_path.name}"
        obstacles = None
        if scene is not None:
            from ..collision import Scene

            obstacles = Scene.load(scene)
            skill.check(skill.reproduce(objects).joints[:1], obstacles, objects=objects)

        def factory(server: Any) -> ViewApp:
            return ViewApp(
                skill,
                objects,
                server,
                urdf=urdf,
                title=title,
                scene=obstacles,
                suggest=suggesting,
            )

    else:
        assert task is not None
        spec = robot_task(task)
        from ..sim._task_skill import learn_task

        with console.status(f"teaching and learning the {spec.name} task ..."):
            ts = learn_task(spec, n_demos=5, seed=seed)
        placement = spec.nominal_objects()

        def factory(server: Any) -> ViewApp:
            return ViewApp(ts.skill, placement, server, task_skill=ts, title=f"task {spec.name}")

    serve(factory, port=port, open_browser=not no_browser, say=console.print)


unwrap_help(app)


def main() -> None:
    """Entry point of the ``pbdkit`` console script.

    Bad input (a ValueError or a missing file from the library), an output path that cannot be
    written, a file-system error or exhausted memory end with a one-line message and exit
    status 2, not a traceback (each command reports its own; this catches the rest).
    """
    try:
        app()
    except USER_ERRORS as exc:
        console.print(Text.assemble(("error: ", "bold red"), error_message(exc)), soft_wrap=True)
        raise SystemExit(2) from None
    finally:
        # The process ends here: the interpreter's last collection would walk every object
        # the command loaded (0.3-0.5 s after a simulation; benchmarks/README.md), only for the
        # operating system to free them. Frozen objects are left out of it.
        gc.freeze()
