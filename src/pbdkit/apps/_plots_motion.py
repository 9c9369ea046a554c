"""Figures of motion: a joint against its velocity, acceleration and jerk limits
(:func:`plot_motion_limits`), and an online run at a glance (:func:`plot_online_run`).

As every figure of :mod:`pbdkit.apps._plots`: matplotlib's object-oriented API, imported when a
figure is drawn, never pyplot.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ._plots import SPACE_COLORS, new_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..motion._limits import MotionLimits
    from ..sim._execute import ExecutionResult
    from ..sim._online import OnlineRun

__all__ = ["plot_motion_limits", "plot_online_run"]

Float = NDArray[np.float64]


def plot_motion_limits(
    t: npt.ArrayLike,
    joints: npt.ArrayLike,
    limits: MotionLimits,
    *,
    joint: int | None = None,
    joint_names: Sequence[str] | None = None,
    position_limits: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
    title: str = "",
) -> Figure:
    """One joint's position, velocity, acceleration and jerk against its limits.

    Four panels over time. The derivatives are the divided differences that check a motion
    against its limits (:func:`pbdkit.motion._limits.divided_differences`, with the rest before the
    first sample and after the last), each drawn at the mean time of the samples it spans;
    dashed lines at +- the joint's limits (and at its range with ``position_limits``).

    Parameters
    ----------
    t : array-like, shape (K,)
        Strictly increasing times (s): a servo stream (e.g.
        :attr:`pbdkit.sim.ExecutionResult.servo_targets` every ``servo_period``) or a
        reproduction's samples at :meth:`pbdkit.Skill.times`.
    joints : array-like, shape (K, n)
    limits : MotionLimits
        n joints.
    joint : int, optional
        The joint to show; default: the one closest to its acceleration limit (largest peak
        ``|acceleration|`` / limit).
    joint_names : sequence of str, optional
        n names for the labels (default theta1 ... thetan).
    position_limits : (array-like (n,), array-like (n,)), optional
        Lower and upper joint limits.
    title : str

    Returns
    -------
    Figure
    """
    from ..motion._limits import PAD_REST, divided_differences

    t_ = np.asarray(t, dtype=np.float64)
    q = np.asarray(joints, dtype=np.float64)
    v, a, jerk = divided_differences(t_, q, pad_rest=PAD_REST)
    n = q.shape[1]
    if limits.n_joints != n:
        raise ValueError(f"limits are for {limits.n_joints} joints, joints has {n}")
    if joint is None:
        peak_a = np.abs(a).max(axis=0)
        score = np.where(np.isfinite(limits.acceleration), peak_a / limits.acceleration, 0.0)
        joint = int(np.argmax(score if score.max() > 0 else peak_a))
    if not 0 <= joint < n:
        raise ValueError(f"joint must be in 0..{n - 1}, got {joint}")
    name = joint_names[joint] if joint_names is not None else f"theta{joint + 1}"
    # Times of the padded samples (spaced like the end steps), and of each difference.
    h0, h1 = t_[1] - t_[0], t_[-1] - t_[-2]
    pad = np.arange(1, PAD_REST + 1)
    tp = np.concatenate([t_[0] - h0 * pad[::-1], t_, t_[-1] + h1 * pad])
    windows = np.lib.stride_tricks.sliding_window_view

    fig = new_figure(figsize=(9.0, 7.2))
    axes = fig.subplots(4, 1, sharex=True)
    series = [
        ("position", "rad", t_, q[:, joint], None),
        ("velocity", "rad/s", windows(tp, 2).mean(axis=1), v[:, joint], limits.velocity[joint]),
        (
            "acceleration",
            "rad/s^2",
            windows(tp, 3).mean(axis=1),
            a[:, joint],
            limits.acceleration[joint],
        ),
        ("jerk", "rad/s^3", windows(tp, 4).mean(axis=1), jerk[:, joint], limits.jerk[joint]),
    ]
    for ax, (kind, unit, times, values, lim) in zip(axes, series, strict=True):
        ax.plot(times, values, color="k", lw=0.8, label=kind)
        peak = float(np.abs(values).max()) if values.size else 0.0
        if lim is not None and np.isfinite(lim):
            for sign in (1.0, -1.0):
                ax.axhline(sign * lim, color="tab:red", lw=0.9, ls="--")
            ax.set_title(
                f"{kind}: peak {peak:.3g} {unit}, {peak / lim:.2f} of the limit "
                f"(dashed: +-{lim:.3g})",
                fontsize=9,
            )
        elif kind == "position" and position_limits is not None:
            lo = float(np.asarray(position_limits[0], dtype=np.float64)[joint])
            hi = float(np.asarray(position_limits[1], dtype=np.float64)[joint])
            for bound in (lo, hi):
                ax.axhline(bound, color="tab:red", lw=0.9, ls="--")
            ax.set_title(f"{kind} (dashed: the joint's range)", fontsize=9)
        else:
            ax.set_title(kind if kind == "position" else f"{kind}: no limit", fontsize=9)
        ax.set_ylabel(f"{name} [{unit}]", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[-1].set_xlabel("time (s)", fontsize=8)
    fig.suptitle(title or f"{name} against its limits", fontsize=10)
    fig.tight_layout()
    figure: Figure = fig
    return figure


# Colors of a TrackFilter's statuses in the online figure (others: refusals by the tracker).
_STATUS_COLORS = {
    "ok": "tab:green",
    "held": "tab:blue",
    "occluded": "tab:orange",
    "jump": "tab:red",
    "unseen": "0.85",
}


def plot_online_run(
    run: OnlineRun,
    velocity_limit: Float,
    offline: ExecutionResult | None = None,
    *,
    title: str = "",
) -> Figure:
    """An online run (:func:`pbdkit.sim.execute_online`) at a glance, beside an offline one.

    Four panels: the phase (the step each command targets against time: it holds while the
    arm is held back); the fastest joint's speed over its velocity limit (online and offline);
    how far each object the controller knows has moved from where it started, as the
    controller was told and in truth; the tracker's status per object over time (with vision).
    The disturbance's window is shaded.
    """
    fig = new_figure(figsize=(10.0, 6.4))
    (a_phase, a_speed), (a_obj, a_track) = fig.subplots(2, 2)
    dist = run.disturbance
    window = None
    if "start_s" in dist:
        window = (float(dist["start_s"]), float(dist["start_s"]) + float(dist["duration_s"]))
    ex = run.execution
    dt = run.dt
    for ax in (a_phase, a_speed, a_obj, a_track):
        if window is not None:
            ax.axvspan(*window, color="0.85", lw=0, label=f"{dist['name']}")
        ax.tick_params(labelsize=7)
        ax.set_xlabel("time (s)", fontsize=8)
    a_phase.plot(run.tick_times, run.index, color="k", lw=1, label="step targeted")
    a_phase.plot(
        run.tick_times,
        np.round(run.tick_times / dt) + 1,
        color="0.5",
        lw=0.8,
        ls="--",
        label="one step per dt",
    )
    a_phase.set_ylabel("skill step", fontsize=8)
    a_phase.set_title(f"phase ({run.held_steps} commands held it)", fontsize=9)
    a_phase.legend(fontsize=7, loc="upper left")

    def speed(e: ExecutionResult) -> tuple[Float, Float]:
        dq = np.abs(np.diff(e.joints, axis=0)) / np.diff(e.t)[:, None]
        return e.t[1:], (dq / velocity_limit).max(axis=1)

    if offline is not None:
        a_speed.plot(*speed(offline), color="tab:gray", lw=0.8, label="offline")
    a_speed.plot(*speed(ex), color="k", lw=1, label="online")
    a_speed.axhline(1.0, color="tab:red", lw=0.8, ls="--", label="velocity limit")
    a_speed.set_ylabel("fastest joint / its limit", fontsize=8)
    a_speed.set_title("joint speed (measured)", fontsize=9)
    a_speed.legend(fontsize=7, loc="upper right")

    for i, (name, used) in enumerate(run.objects.items()):
        color = SPACE_COLORS[i % len(SPACE_COLORS)]
        if len(used):
            a_obj.plot(
                run.tick_times,
                1e3 * np.linalg.norm(used - used[0], axis=1),
                color=color,
                lw=1.2,
                label=f"{name}: told",
            )
        if name in ex.objects and len(ex.objects[name]):
            true = ex.objects[name]
            a_obj.plot(
                ex.t,
                1e3 * np.linalg.norm(true - true[0], axis=1),
                color=color,
                lw=0.8,
                ls=":",
                label=f"{name}: true",
            )
    a_obj.set_ylabel("moved from its start (mm)", fontsize=8)
    a_obj.set_title("objects: what the controller was told", fontsize=9)
    a_obj.legend(fontsize=7, loc="upper left")

    tracking = run.tracking
    if tracking is None:
        a_track.text(
            0.5,
            0.5,
            "no cameras: the controller was told the true positions",
            ha="center",
            va="center",
            fontsize=8,
            transform=a_track.transAxes,
        )
        a_track.set_yticks([])
    else:
        names = list(tracking["frames"])
        end = float(ex.t[-1]) if len(ex.t) else 1.0
        for row, name in enumerate(names):
            events = [e for e in tracking["events"] if e["name"] == name]
            for j, e in enumerate(events):
                stop = events[j + 1]["time"] if j + 1 < len(events) else end
                color = _STATUS_COLORS.get(e["status"], "tab:purple")
                a_track.barh(row, stop - e["time"], left=e["time"], color=color, height=0.6)
        a_track.set_yticks(range(len(names)), names, fontsize=8)
        seen = sorted({e["status"] for e in tracking["events"]})
        from matplotlib.patches import Patch

        a_track.legend(
            handles=[Patch(color=_STATUS_COLORS.get(s, "tab:purple"), label=s) for s in seen],
            fontsize=7,
            loc="upper left",
            ncols=len(seen),
        )
        a_track.set_ylim(-0.6, len(names) + 0.4)
    a_track.set_title("cameras (15 Hz): estimate accepted or held", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    figure: Figure = fig
    return figure
