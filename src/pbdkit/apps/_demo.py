"""``pbdkit demo`` for the robot tasks: demonstrations -> skill -> new situation -> physics,
with the paper's figures, a video, report.html and metrics.json.

This module sits at the top of the layers (it uses the simulator, the plots and the report) and
is imported only by the command line.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._defaults import MAX_COMPONENTS
from .._io import atomic_write_bytes, write_json
from .._validation import check_int
from ..data._demonstration import save_demonstrations
from ..data._placement import position_of
from ..prob._selection import CV_TOLERANCE
from ..sim._video import beside_caption, verdict_label, video_partner
from ._plots import (
    figure_png,
    plot_constraints,
    plot_demonstrations_3d,
    plot_reproductions,
    plot_selection,
)
from ._plots_motion import plot_motion_limits, plot_online_run
from ._report import Figure, Section, orientation_section, write_report
from ._staging import staged_output

if TYPE_CHECKING:
    from ..sim._task_skill import TaskSkill
    from ..sim._tasks import TaskSpec
    from ..sim._trials import TrialConditions

__all__ = ["run_lasa_demo", "run_robot_demo"]


def run_lasa_demo(
    out: Path, shape: str = "GShape", max_components: int = MAX_COMPONENTS
) -> dict[str, object]:
    """Learn a LASA handwriting shape with GMM/GMR and write a figure and metrics.json.

    Returns the metrics written. An unknown ``shape`` is refused (ValueError) before ``out``
    is created; the files are written at once at the end.
    """
    from ..datasets import lasa
    from ..prob._gmm import GMM
    from ..skill._spaces import fit_steps
    from ._plots import plot_lasa_summary, save_figure

    demos = lasa(shape)  # an unknown shape is refused before the folder is made
    n_steps = demos[0].pos.shape[0]
    t = np.linspace(0.0, 1.0, n_steps)
    # EM sees 100 evenly spaced steps per demonstration, as Skill.learn (fit_samples).
    steps = fit_steps(n_steps, 100)
    x = np.vstack([np.column_stack([t[steps], d.pos[steps]]) for d in demos])
    start = time.perf_counter()
    gmm = GMM("auto", max_components=max_components).fit(x)
    learn_s = time.perf_counter() - start
    start = time.perf_counter()
    mean, cov = gmm.regress(t[:, None])
    regress_s = time.perf_counter() - start
    positions = np.stack([d.pos for d in demos])

    def rmse(traj: np.ndarray) -> float:
        return float(
            np.mean([np.sqrt(np.mean(np.sum((traj - p) ** 2, axis=1))) for p in positions])
        )

    metrics: dict[str, object] = {
        "task": "lasa",
        "shape": shape,
        "n_demonstrations": len(demos),
        "n_steps": n_steps,
        "n_components": gmm.n_components_,
        "selection": gmm.selection_.as_dict(),
        "rmse_gmr_to_demos": rmse(mean),
        "rmse_pointwise_mean_to_demos": rmse(positions.mean(axis=0)),
        "final_point_error": float(np.linalg.norm(mean[-1] - positions[:, -1].mean(axis=0))),
        "learn_seconds": learn_s,
        "regress_seconds": regress_s,
    }
    fig = plot_lasa_summary(shape, t, list(positions), gmm, mean, cov)
    with staged_output(out, last="metrics.json") as stage:
        save_figure(fig, stage / f"lasa_{shape}.png")
        write_json(stage / "metrics.json", metrics, sort_keys=True)
    return metrics


def run_robot_demo(
    spec: TaskSpec,
    out: Path,
    *,
    conditions: TrialConditions | None = None,
    n_demos: int = 5,
    status: Callable[[str], None] | None = None,
    constrain_fixed: bool = False,
    learn: Callable[..., TaskSkill] | None = None,
) -> dict[str, Any]:
    """Run the paper's experiment for the task ``spec`` and write its results to ``out``.

    ``conditions`` (:class:`pbdkit.sim.TrialConditions`; default: offline, no disturbance,
    the cameras, seed 0): ``seed`` seeds the demonstrations and the new situation.
    ``learn(spec, n_demos=n_demos, seed=seed, constrain_fixed=constrain_fixed)`` teaches and
    learns the skill, a ``TaskSkill`` (default: :func:`pbdkit.sim.learn_task`, the simulated
    teacher and the full time grid); inject a faster or a different learner.

    With ``conditions.online``, the fused controller also runs online, in the physics loop
    (told the cameras' positions at 15 Hz, or the true ones with ``ground_truth``), under the
    disturbance ``conditions.perturb`` (:mod:`pbdkit.sim._perturb`); beside it the offline
    fused reproduction plays under the same disturbance. They add ``fig_online.png``,
    ``online.mp4``, a report section and ``metrics.json["online"]``.

    Writes ``demos.npz``, ``skill.npz``, ``fig3_cartesian.png``, ``fig45_constraints.png``,
    ``fig6_controllers.png``, ``fig_limits.png`` (one joint of the fused run's servo stream
    against the arm's velocity, acceleration and jerk limits), ``reproduction.mp4`` (the left
    camera: the fused run beside the first single-space run that fails),
    ``report.html`` and ``metrics.json`` (with the arm's ``"motion_limits"``; every
    controller's summary has the servo stream's peaks over them).

    The skill is told the object positions the stereo tracker measures in the new situation
    (:mod:`pbdkit.sim._tracking`, calibrated at the nominal placement); the simulated world keeps
    the true ones. ``conditions.ground_truth`` tells the skill the true positions instead.

    The skill has a task-space constraint per moving object, as in the paper (the basin task:
    joint space and glass); ``constrain_fixed=True`` also learns one relative to the fixed basin
    (:func:`pbdkit.sim.learn_task`). ``metrics.json`` records ``"constraints"`` and
    ``"constrain_fixed"``.

    The arguments are checked before any physics runs. The files are written to a hidden
    folder inside ``out`` and moved into ``out`` at the end, so that a demo that fails leaves
    ``out`` as it found it: without new files, and removed if the demo created it.

    Raises
    ------
    ValueError
        Before any physics: ``spec`` not a TaskSpec, an unknown perturbation or one without
        ``online``, ``n_demos`` not an integer >= 2, ``out`` not a directory.
    pbdkit.sim._tracking.ObjectNotSeenError
        With vision, if the cameras cannot locate an object of the new situation.

    Returns
    -------
    metrics : dict
        What ``metrics.json`` holds.
    """
    from ..sim._perturb import check_perturb
    from ..sim._task_skill import learn_task
    from ..sim._tasks import check_task
    from ..sim._trials import TrialConditions

    def say(msg: str) -> None:
        if status is not None:
            status(msg)

    spec = check_task(spec, "spec")
    conditions = TrialConditions() if conditions is None else conditions
    check_perturb(conditions.perturb, spec)
    if conditions.perturb != "none" and not conditions.online:
        raise ValueError("perturb applies to the online run: give online=True (--online) too")
    check_int(n_demos, "n_demos", minimum=2)  # a skill needs two demonstrations
    if learn is None:
        learn = learn_task
    t_start = time.perf_counter()
    with staged_output(Path(out), last="metrics.json") as stage:
        return _run_robot_demo(
            spec,
            stage,
            conditions,
            n_demos=n_demos,
            say=say,
            constrain_fixed=constrain_fixed,
            learn=learn,
            t_start=t_start,
        )


def _run_robot_demo(
    spec: TaskSpec,
    out: Path,
    conditions: TrialConditions,
    *,
    n_demos: int,
    say: Callable[[str], None],
    constrain_fixed: bool,
    learn: Callable[..., TaskSkill],
    t_start: float,
) -> dict[str, Any]:
    """:func:`run_robot_demo` once its arguments are checked, writing to ``out``."""
    from ..sim._metrics import tracking_errors, yaw_errors
    from ..sim._runs import run_controller, run_online
    from ..sim._sensing import calibrate_tracker, observe
    from ..sim._trials import trial_disturbance
    from ..sim._video import save_video, side_by_side

    seed, perturb = conditions.seed, conditions.perturb

    say(f"teaching {n_demos} demonstrations of the {spec.name} task ...")
    ts = learn(spec, n_demos=n_demos, seed=seed, constrain_fixed=constrain_fixed)
    save_demonstrations(ts.demos, out / "demos.npz")
    ts.skill.save(out / "skill.npz")
    rng = np.random.default_rng([seed, 2])
    truth = spec.sample_objects(rng)
    vision: dict[str, Any] | None = None
    objects = truth
    tracker = None
    if conditions.vision:
        say("calibrating the cameras and locating the objects ...")
        start = time.perf_counter()
        tracker = calibrate_tracker(ts)
        calib_s = time.perf_counter() - start
        objects = observe(spec, truth, tracker, arm=ts.start_posture)
        errors = tracking_errors(objects, truth, tracker.objects)
        vals = np.array(list(errors.values()))
        vision = {
            "objects": list(tracker.objects),
            "error_mm": errors,
            "tracking_error_mm": {"mean": float(vals.mean()), "std": float(vals.std())},
            # Patch offsets of the objects tracked by one patch; a posed object's ends have
            # none: its offset is in its own frame, with a yaw offset (its PoseModel).
            "offsets_mm": {
                k: (1e3 * v).tolist()
                for k, v in tracker.offsets.items()
                if not any(k.startswith(f"{p}:") for p in tracker.pose_models)
            },
            "pose_offsets": {
                k: {"offset_mm": (1e3 * m.offset).tolist(), "yaw_deg": math.degrees(m.yaw_offset)}
                for k, m in tracker.pose_models.items()
            },
            "calibration_seconds": calib_s,
        }
        yaw = yaw_errors(objects, truth, tracker.objects)
        if yaw:
            degs = np.array(list(yaw.values()))
            vision["error_deg"] = yaw
            vision["tracking_error_deg"] = {"mean": float(degs.mean()), "std": float(degs.std())}
    runs = {}
    for name in ts.controllers:
        say(f"reproducing and executing the {name} controller ...")
        runs[name] = run_controller(ts, objects, name, camera="cam_left", sim_objects=truth)
    fused = runs["fused"]
    video_path = out / "reproduction.mp4"
    beside = video_partner(runs)
    if fused.execution.frames is not None and len(fused.execution.frames):
        frames = fused.execution.frames
        other = None if beside is None else runs[beside].execution.frames
        if beside is not None and other is not None:
            # The paper's point: where a single-space controller fails.
            labels = (
                verdict_label("fused", fused.success),
                verdict_label(beside, runs[beside].success),
            )
            frames = side_by_side(frames, other, labels)
        save_video(frames, video_path, fps=15.0)
    online_runs: dict[str, Any] = {}
    if conditions.online:
        say(f"running the fused controller online (perturb: {perturb}) ...")
        online_runs["online"] = run_online(
            ts,
            objects,
            "fused",
            tracker=tracker,
            camera="cam_left",
            sim_objects=truth,
            disturbance=trial_disturbance(ts, conditions, truth),
        )
        frames = online_runs["online"].execution.frames
        if frames is not None and len(frames):
            save_video(frames, out / "online.mp4", fps=15.0)
        say(f"playing the offline reproduction under the same disturbance ({perturb}) ...")
        online_runs["offline"] = run_controller(
            ts,
            objects,
            "fused",
            sim_objects=truth,
            disturbance=trial_disturbance(ts, conditions, truth),
        )

    say("drawing the figures ...")
    fig3 = figure_png(
        plot_demonstrations_3d(ts.skill, ts.demos, objects=objects, reproduction=fused.reproduction)
    )
    fig45 = figure_png(plot_constraints(ts.skill, ts.demos))
    by_name = {"fused": fused.reproduction, "joint": runs["joint"].reproduction}
    for k in ts.skill.object_names:
        by_name[k] = runs[f"task:{k}"].reproduction
    fig6 = figure_png(plot_reproductions(ts.skill, by_name))
    ex = fused.execution
    robot = ts.skill.robot
    fig_limits = plot_motion_limits(
        ex.servo_period * np.arange(ex.servo_targets.shape[0]),
        ex.servo_targets,
        ex.servo_limits,
        joint_names=robot.joint_names,
        position_limits=(robot.lower, robot.upper),
        title="The fused run's servo stream (500 Hz) against the arm's limits: the joint "
        "closest to its acceleration limit",
    )
    figures = {
        "fig3_cartesian.png": fig3,
        "fig45_constraints.png": fig45,
        "fig_selection.png": figure_png(plot_selection(ts.skill)),
        "fig6_controllers.png": fig6,
        "fig_limits.png": figure_png(fig_limits),
    }
    if online_runs:
        fig_online = plot_online_run(
            online_runs["online"].online,
            online_runs["online"].velocity_limit,
            online_runs["offline"].execution,
            title=f"The fused controller online, perturb: {perturb}",
        )
        figures["fig_online.png"] = figure_png(fig_online)
    for name, png in figures.items():
        atomic_write_bytes(out / name, png)

    total_s = time.perf_counter() - t_start
    influence = {k: float(v.mean()) for k, v in fused.reproduction.influence.items()}
    metrics: dict[str, Any] = {
        "task": spec.name,
        "seed": seed,
        "n_demos": n_demos,
        "objects": {k: v.tolist() for k, v in truth.items()},
        "vision": vision is not None,
        "observed_objects": {k: v.tolist() for k, v in objects.items()},
        "tracking": vision,
        "n_components": ts.skill.n_components_,
        "selection": {k: s.as_dict() for k, s in ts.skill.selection_.items()},
        "constraints": list(ts.skill.constraint_names),
        "constrain_fixed": ts.constrain_fixed,
        "success": fused.success,
        "controllers": {name: run.as_dict() for name, run in runs.items()},
        "motion_limits": fused.execution.servo_limits.as_dict(),
        "mean_influence_fused": influence,
        "online": None
        if not online_runs
        else {
            "perturb": online_runs["online"].online.disturbance,
            "online": online_runs["online"].as_dict(),
            "offline": online_runs["offline"].as_dict(),
            "tracking": online_runs["online"].online.tracking,
        },
        "seconds": {
            "teach": ts.teach_seconds,
            "learn": ts.learn_seconds,
            "reproduce_fused": fused.reproduce_seconds,
            "total": total_s,
        },
    }
    write_json(out / "metrics.json", metrics)
    _write_html(
        DemoRun(
            out=out,
            spec=spec,
            ts=ts,
            truth=truth,
            objects=objects,
            runs=runs,
            metrics=metrics,
            figures=figures,
            video=video_path,
            online=online_runs,
        )
    )
    return metrics


def _perturbation_words(perturb: dict[str, Any]) -> str:
    """What the run's perturbation did, in words: the built-in ones with their numbers, any
    other registered one by its help text."""
    name = perturb["name"]
    if name == "none":
        return "no disturbance"
    if name == "move":
        return (
            f"the {perturb.get('object')} slides "
            f"{1e3 * float(np.linalg.norm(perturb.get('displacement_m', [0.0]))):.0f} mm from "
            f"t = {perturb.get('start_s', 0.0):.1f} s"
        )
    if name == "push":
        return (
            f"a {float(np.linalg.norm(perturb.get('force_n', [0.0]))):.0f} N shove on the "
            f"{perturb.get('body')} for {perturb.get('duration_s', 0.0):.1f} s from "
            f"t = {perturb.get('start_s', 0.0):.1f} s"
        )
    from ..sim._perturb import PERTURBATIONS

    entry = PERTURBATIONS.get(name)
    return f"{name}: {entry.help}" if entry is not None else str(name)


def _online_sections(demo: DemoRun) -> list[Section]:
    """The report's section on the online run (none without ``--online``)."""
    if not demo.online:
        return []
    on, off = demo.online["online"], demo.online["offline"]
    info = demo.metrics["online"]
    perturb = info["perturb"]
    what = _perturbation_words(perturb)
    absolute = ("peak_velocity", "peak_acceleration", "peak_jerk")  # the limits section has them
    keys = [k for k in on.as_dict() if k not in ("success", "tracking", *absolute)]
    rows = [
        [label, run.success, *(run.as_dict().get(k, "-") for k in keys)]
        for label, run in (("online (in the loop)", on), ("offline (played open loop)", off))
    ]
    fig = demo.figures["fig_online.png"]
    sensing = (
        "the positions the cameras measured at 15 Hz, filtered (the last good estimate is "
        "held while the arm hides a patch or holds the glass; jumps are refused)"
        if demo.metrics["vision"]
        else "the true positions at 15 Hz (--ground-truth)"
    )
    video = (
        '<video controls width="640" src="online.mp4"></video>'
        '<p>File: <a href="online.mp4">online.mp4</a> (online run, left camera).</p>'
        if (demo.out / "online.mp4").exists()
        else "<p>No video was recorded.</p>"
    )
    return [
        Section(
            "The skill online: the controller in the robot's loop",
            paragraphs=[
                f"Disturbance: {what}. Online, the fused controller ran step by step at the "
                f"skill's rate from the measured joint angles, told {sensing}. Offline, the "
                "trajectory reproduced once from the positions seen at the start was played "
                "under the same disturbance.",
                "peak_speed_ratio: the fastest measured joint speed over its velocity limit, "
                "and following_error_rad: the largest distance from the servo reference, both "
                "outside the push (a real drive faults on either); peak_*_ratio: the servo "
                "stream's peak velocity, acceleration and jerk over the arm's limits.",
            ],
            tables={
                "Online and offline under the same disturbance": (["run", "success", *keys], rows)
            },
            figures=[Figure(fig, "The online run: phase, joint speed, objects, cameras.")],
            html_paragraphs=[video],
            anchor="online",
        )
    ]


_PEAK_KINDS = ("velocity", "acceleration", "jerk")


def _limits_section(demo: DemoRun) -> Section:
    """What the servos were sent against the arm's limits: every run's peaks and a figure."""
    runs: list[tuple[str, dict[str, Any]]] = [
        (name, run.as_dict()) for name, run in demo.runs.items()
    ]
    if demo.online:
        runs += [
            (f"fused, {label} ({demo.metrics['online']['perturb']['name']})", run.as_dict())
            for label, run in (
                ("online", demo.online["online"]),
                ("offline", demo.online["offline"]),
            )
        ]
    rows = [
        [
            label,
            *(row.get(f"peak_{k}_ratio", "-") for k in _PEAK_KINDS),
            *(row.get(f"peak_{k}", "-") for k in _PEAK_KINDS),
        ]
        for label, row in runs
    ]
    limits = demo.metrics["motion_limits"]

    def values(kind: str) -> str:
        got = sorted({v for v in limits[kind] if v is not None})
        return "none" if not got else ", ".join(f"{v:g}" for v in got)

    return Section(
        "What the drives were sent: the arm's motion limits",
        paragraphs=[
            "A real arm's drives check the setpoints they are sent: a Franka Panda stops on a "
            "single one whose acceleration or jerk exceeds its limits. The reproduction is timed "
            "within the arm's velocity, acceleration and jerk limits (steps stretched where "
            "needed), and the servos follow it through a jerk-limited stream (Ruckig) at the "
            "physics rate, each sample aimed for with its velocity and acceleration at its time.",
            f"Limits of the arm (per joint): velocity {values('velocity')} rad/s, acceleration "
            f"{values('acceleration')} rad/s^2, jerk {values('jerk')} rad/s^3. The table gives, "
            "per run, the peaks of the servo targets by divided differences at 500 Hz from the "
            "trajectory's start to the end of the settling time (leaving out a push), as "
            "ratios to the limits (<= 1: the drives accept the stream) and in rad/s, rad/s^2, "
            "rad/s^3.",
        ],
        tables={
            "Servo stream peaks over the limits": (
                [
                    "run",
                    *(f"{k} / limit" for k in _PEAK_KINDS),
                    "velocity (rad/s)",
                    "acceleration (rad/s^2)",
                    "jerk (rad/s^3)",
                ],
                rows,
            )
        },
        figures=[
            Figure(
                demo.figures["fig_limits.png"],
                "The fused run's servo targets for the joint closest to its acceleration limit: "
                "position, velocity, acceleration and jerk (divided differences at 500 Hz), "
                "dashed at +- the limits.",
                "motion limits",
            )
        ],
        anchor="limits",
    )


def _constraints_text(spec: TaskSpec, ts: Any) -> str:
    """Which constraints the skill has, and why the fixed objects have (or lack) one."""
    spaces = ["joint space" + (" (with the gripper)" if ts.skill.has_gripper else "")]
    spaces += [f"the hand relative to the {k}" for k in ts.skill.object_names]
    text = f"Constraints learned: {', '.join(spaces)}."
    fixed = list(spec.fixed_objects)
    if not fixed:
        return text
    names = " and ".join(f"the {k}" for k in fixed)
    if ts.constrain_fixed:
        return (
            f"{text} {names[0].upper()}{names[1:]} never moves; its task-space constraint was "
            "added on request (--constrain-fixed): the paper has none."
        )
    return (
        f"{text} {names[0].upper()}{names[1:]} never moves, so, as in the paper (Sec. III), "
        "it has no task-space constraint: it is neither tracked nor learned, and the motion "
        "relative to it is the joint-space constraint (--constrain-fixed adds one)."
    )


def _vision_section(
    truth: dict[str, Any], objects: dict[str, Any], metrics: dict[str, Any]
) -> Section:
    tracking = metrics["tracking"]
    if tracking is None:
        return Section(
            "Where the objects are (vision)",
            paragraphs=[
                "Vision was switched off (--ground-truth): the skill was told the true object "
                "positions."
            ],
            anchor="vision",
        )
    yaw = tracking.get("error_deg", {})
    rows = []
    for name, p in truth.items():
        q = objects[name]
        err = tracking["error_mm"].get(name)
        row = [
            name,
            _placement_text(p, mm=True),
            _placement_text(q, mm=True) if err is not None else "(fixed, known)",
            err if err is not None else "-",
        ]
        if yaw:
            row.append(yaw.get(name, "-"))
        rows.append(row)
    header = ["object", "true", "tracked", "error (mm)"] + (["yaw error (deg)"] if yaw else [])
    stats = tracking["tracking_error_mm"]
    n_tracked = len(tracking["error_mm"])
    err_text = f"{stats['mean']:.1f} mm"
    if n_tracked > 1:
        err_text += f" +- {stats['std']:.1f} mm over {n_tracked} objects"
    if yaw:
        deg = tracking["tracking_error_deg"]
        err_text += f" in position and {deg['mean']:.2f} deg"
        if len(yaw) > 1:
            err_text += f" +- {deg['std']:.2f} deg over {len(yaw)} objects"
        err_text += (
            " in yaw (a posed object's yaw comes from the line between its two end patches; "
            "its offset is calibrated in its own frame)"
        )
    return Section(
        "Where the objects are (vision, paper Sec. III)",
        paragraphs=[
            "As in the paper, the skill was told the object positions measured by two 320x240 "
            "cameras tracking colored patches (a Gaussian over the CbCr plane per patch, fitted "
            "on a calibration image labelled by MuJoCo's segmentation rendering; largest blob; "
            "stereo triangulation). A per-object offset measured once at the calibration "
            "placement corrects the centroid of the visible patch to the object's reference "
            "point. The simulated world kept the true positions.",
            f"Tracking error in this situation: {err_text} (the paper measured 5.9 +- 2.8 mm "
            "with real webcams). Offsets applied (mm): "
            + "; ".join(
                [
                    f"{k} ({', '.join(f'{v:+.1f}' for v in o)})"
                    for k, o in tracking["offsets_mm"].items()
                ]
                + [
                    f"{k} ({', '.join(f'{v:+.1f}' for v in o['offset_mm'])} in its own frame, "
                    f"yaw {o['yaw_deg']:+.2f} deg)"
                    for k, o in tracking.get("pose_offsets", {}).items()
                ]
            )
            + ".",
        ],
        tables={"True and tracked positions (mm, robot base frame)": (header, rows)},
        anchor="vision",
    )


@dataclass(frozen=True, kw_only=True)
class DemoRun:
    """Everything a robot demo produced, for its report.

    Attributes
    ----------
    out : Path
        The output folder.
    spec : TaskSpec
    ts : TaskSkill
        The demonstrations and the skill learned from them.
    truth, objects : dict str -> array-like, shape (3,)
        The new situation's true positions, and those the skill was told.
    runs : dict str -> ControllerRun
        Per controller, its reproduction and execution.
    metrics : dict
        What ``metrics.json`` holds.
    figures : dict str -> bytes
        PNG files by name.
    video : Path
        The fused controller's video (may not exist).
    online : dict str -> run
        With ``--online``: ``"online"`` (OnlineControllerRun) and ``"offline"`` (ControllerRun
        under the same disturbance); empty otherwise.
    """

    out: Path
    spec: TaskSpec
    ts: Any
    truth: dict[str, Any]
    objects: dict[str, Any]
    runs: dict[str, Any]
    metrics: dict[str, Any]
    figures: dict[str, bytes]
    video: Path
    online: dict[str, Any] = field(default_factory=dict)


def _placement_text(value: Any, *, mm: bool = False) -> str:
    """A placement for the report: "(x, y, z) m" (or the numbers in mm), and a pose's yaw."""
    v = np.asarray(value, dtype=np.float64)
    p = position_of(v)
    text = (
        ", ".join(f"{1e3 * c:.1f}" for c in p) if mm else f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
    )
    if v.shape == (4, 4):
        text += f", yaw {math.degrees(math.atan2(v[1, 0], v[0, 0])):.1f} deg"
    return text


def _write_html(demo: DemoRun) -> None:
    out, spec, ts, truth, objects = demo.out, demo.spec, demo.ts, demo.truth, demo.objects
    runs, metrics, figures, video_path = demo.runs, demo.metrics, demo.figures, demo.video
    fig3, fig45 = figures["fig3_cartesian.png"], figures["fig45_constraints.png"]
    fig6, fig_sel = figures["fig6_controllers.png"], figures["fig_selection.png"]
    fused = runs["fused"]
    verdict = "succeeded" if fused.success else "FAILED"
    metric_names = list(fused.execution.outcome.metrics)
    rows = []
    for name, run in runs.items():
        m = run.execution.outcome.metrics
        rows.append([name, run.success, *(float(m[k]) for k in metric_names)])
    k_rows = [
        [name, int(sel.chosen), int(sel.best), f"{sel.candidates[0]}..{sel.candidates[-1]}"]
        for name, sel in ts.skill.selection_.items()
    ]
    secs = metrics["seconds"]
    place = ", ".join(f"{k} at {_placement_text(v)}" for k, v in truth.items())
    sections = [
        Section(
            "What happened",
            paragraphs=[
                spec.description,
                f"A simulated teacher moved the arm {len(ts.demos)} times by hand (kinesthetic "
                f"demonstrations, objects placed at random). pbdkit learned the skill and "
                f"reproduced it for a new situation never demonstrated ({place}). Executed "
                f"under physics, the fused controller {verdict}.",
            ],
            tables={
                "Every controller on the same new situation (errors in mm, angles in degrees)": (
                    ["controller", "success", *metric_names],
                    rows,
                )
            },
            anchor="summary",
        ),
        _vision_section(truth, objects, metrics),
        Section(
            "What the robot learned (paper Figs. 4-5)",
            paragraphs=[
                "One Gaussian mixture model per space. Grey: the demonstrations rescaled to the "
                "same number of steps; ellipses: "
                "the Gaussian components; coloured band: the GMR mean +- 2 standard deviations. "
                "Where the band is narrow, the demonstrations agreed: that constraint matters "
                "then.",
                _constraints_text(spec, ts),
            ],
            tables={"Components per space": (["space", "K kept", "best K", "K tried"], k_rows)},
            figures=[
                Figure(fig45, "Constraints per space over time.", "constraints"),
                Figure(
                    fig_sel,
                    "How K was chosen: each demonstration in turn is left out, the GMM of the "
                    "others predicts it (GMR mean), and the error is measured relative to the "
                    "demonstrations' own variability. The K kept is the smallest whose error is "
                    f"within {100 * CV_TOLERANCE:g} % of the level the K tried reach (the second "
                    "lowest error, so that one lucky fit does not set it; the cap's while the "
                    "errors still fall there): more components would only "
                    "fit details the demonstrations do not repeat.",
                    "selection",
                ),
            ],
            anchor="learned",
        ),
        Section(
            "Demonstrations and reproduction (paper Fig. 3)",
            figures=[
                Figure(
                    fig3,
                    "Left: hand paths of the demonstrations with the objects' positions. Right: "
                    "the fused reproduction for the new positions.",
                    "cartesian",
                )
            ],
            anchor="cartesian",
        ),
        Section(
            "Which constraint drives the robot, and why fusing matters (paper Fig. 6)",
            paragraphs=[
                "Solid black: all constraints fused. Dash-dot / dotted: the task-space constraint "
                "of one object alone. Dashed: the joint-space constraint alone. Bottom left: the "
                "share of each constraint in the fused controller over time; bottom right: the "
                "distance from the hand to where each object's constraint wants it.",
            ],
            figures=[Figure(fig6, "Controllers compared, and the influence of each constraint.")],
            anchor="controllers",
        ),
        # Oriented constraints (pose tasks): None, and no section, for the paper's tasks.
        *filter(
            None, [orientation_section(ts.skill, {n: r.reproduction for n, r in runs.items()})]
        ),
        *_online_sections(demo),
        _limits_section(demo),
        Section(
            "The run",
            html_paragraphs=[
                f'<video controls width="640" src="{video_path.name}"></video>'
                f'<p>File: <a href="{video_path.name}">{video_path.name}</a> (left camera: '
                f"the fused controller{beside_caption(runs)}).</p>"
                if video_path.exists()
                else "<p>No video was recorded.</p>"
            ],
            anchor="video",
        ),
        Section(
            "Timings",
            tables={
                "Seconds": (
                    ["step", "seconds"],
                    [
                        ["teach (simulated demonstrations)", secs["teach"]],
                        [
                            f"learn ({len(ts.skill.constraint_names)} GMMs, K chosen by "
                            "leaving one demonstration out)",
                            secs["learn"],
                        ],
                        ["reproduce (fused, 1000 steps)", secs["reproduce_fused"]],
                        ["whole demo", secs["total"]],
                    ],
                )
            },
            anchor="timings",
        ),
    ]
    write_report(
        out / "report.html",
        f"pbdkit demo: the {spec.name} task",
        sections,
        intro="Programming by Demonstration with constraints in joint space and task space "
        "(Calinon & Billard, IROS 2008), on a simulated Katana arm.",
    )
