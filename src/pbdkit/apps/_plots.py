"""The paper's figures: GMM ellipses, GMR mean with its covariance tube, demonstrations,
constraints, controllers (motion limits and online runs: :mod:`pbdkit.apps._plots_motion`).

matplotlib is imported inside each function (the core never needs it). Figures are built with
matplotlib's object-oriented API (``matplotlib.figure.Figure``), never through pyplot: they render
on a machine without a screen and leave the user's backend alone (a Jupyter session stays
inline, and shows a returned figure). Functions draw on the axes they are given or return a new
figure; saving is the caller's business (:func:`save_figure` writes a PNG atomically).
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._io import atomic_write_bytes

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from ..data._demonstration import Demonstration
    from ..prob._gmm import GMM
    from ..reproduction._result import ReproductionResult
    from ..skill._skill import Skill

__all__ = [
    "figure_png",
    "new_figure",
    "plot_constraints",
    "plot_demonstrations_3d",
    "plot_gmm_ellipses",
    "plot_gmr_tube",
    "plot_influence",
    "plot_lasa_summary",
    "plot_reproductions",
    "plot_selection",
    "save_figure",
]

# Line styles of the paper's Fig. 6: fused solid, object 1 dash-dot, object 2 dotted, joint dashed.
CONTROLLER_STYLES = {"fused": "-", "joint": "--"}
OBJECT_STYLES = ["-.", ":", (0, (5, 1, 1, 1, 1, 1)), (0, (1, 3))]
SPACE_COLORS = ["tab:red", "tab:blue", "tab:purple", "tab:brown"]
JOINT_COLOR = "tab:green"
UNCONSTRAINED_COLOR = "0.3"  # an object the skill has no constraint on (the fixed basin)
# A frame's x, y and z axes in the 3-D figure (red, green, blue, as in RViz).
FRAME_COLORS = ("#d62728", "#2ca02c", "#1f77b4")
# The gid of the lines drawing frames in the 3-D figure: objects' poses, and the hand's.
OBJECT_FRAME_GID = "object frame"
HAND_FRAME_GID = "hand frame"

Float = NDArray[np.float64]


def new_figure(**kwargs: Any) -> Figure:
    """A figure outside pyplot's registry: no backend is chosen or switched, nothing to close.

    Parameters
    ----------
    **kwargs
        Passed to :class:`matplotlib.figure.Figure` (``figsize``, ``dpi``, ...).

    Returns
    -------
    fig : matplotlib.figure.Figure
        Render it with :func:`figure_png` or :func:`save_figure`.
    """
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def figure_png(fig: Figure, *, dpi: int = 110) -> bytes:
    """Render ``fig`` to PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def save_figure(fig: Figure, path: str | os.PathLike[str], *, dpi: int = 110) -> bytes:
    """Render ``fig`` to PNG and write it atomically to ``path``; returns the PNG bytes."""
    png = figure_png(fig, dpi=dpi)
    atomic_write_bytes(path, png)
    return png


def plot_gmm_ellipses(
    ax: Axes,
    gmm: GMM,
    dims: tuple[int, int],
    *,
    n_std: float = 1.0,
    color: str = "tab:orange",
    alpha: float = 0.35,
) -> None:
    """Draw each component's covariance ellipse (``n_std`` standard deviations) in two dims.

    Parameters
    ----------
    ax : matplotlib Axes
    gmm : GMM
        A fitted mixture.
    dims : (int, int)
        The dimensions shown on the x and y axes.
    """
    from matplotlib.patches import Ellipse

    i, j = dims
    for mean, cov in zip(gmm.means_, gmm.covariances_, strict=True):
        c = cov[np.ix_([i, j], [i, j])]
        w, v = np.linalg.eigh(c)
        w = np.maximum(w, 0.0)
        angle = float(np.degrees(np.arctan2(v[1, 1], v[0, 1])))
        ell = Ellipse(
            (float(mean[i]), float(mean[j])),
            width=float(2 * n_std * np.sqrt(w[1])),
            height=float(2 * n_std * np.sqrt(w[0])),
            angle=angle,
            facecolor=color,
            edgecolor="k",
            linewidth=0.6,
            alpha=alpha,
        )
        ax.add_patch(ell)
        ax.plot(mean[i], mean[j], "k.", markersize=4)


def plot_gmr_tube(
    ax: Axes,
    t: Float,
    mean: Float,
    std: Float,
    *,
    color: str = "tab:blue",
    label: str | None = "GMR",
    n_std: float = 2.0,
) -> None:
    """GMR mean over time with a band of +- ``n_std`` standard deviations.

    Parameters
    ----------
    t : ndarray, shape (T,)
    mean : ndarray, shape (T,)
    std : ndarray, shape (T,)
    """
    ax.fill_between(t, mean - n_std * std, mean + n_std * std, color=color, alpha=0.25, lw=0)
    ax.plot(t, mean, color=color, lw=2, label=label)


def plot_lasa_summary(
    name: str,
    t: Float,
    demos: Sequence[Float],
    gmm: GMM,
    mean: Float,
    cov: Float,
) -> Figure:
    """A LASA shape: demonstrations, GMM ellipses and GMR in the plane, and each coordinate
    over time with the GMR covariance tube.

    Parameters
    ----------
    name : str
    t : ndarray, shape (T,)
        Time (the GMR input).
    demos : sequence of ndarray, shape (T, 2)
    gmm : GMM
        Fitted over {t, x1, x2}.
    mean : ndarray, shape (T, 2)
    cov : ndarray, shape (T, 2, 2)
    """
    fig = new_figure(figsize=(13, 4.2))
    axes = fig.subplots(1, 3)
    ax = axes[0]
    for k, d in enumerate(demos):
        ax.plot(d[:, 0], d[:, 1], color="0.55", lw=1, label="demonstrations" if k == 0 else None)
    plot_gmm_ellipses(ax, gmm, (1, 2))
    ax.plot(mean[:, 0], mean[:, 1], color="tab:blue", lw=2, label="GMR mean")
    ax.plot(mean[-1, 0], mean[-1, 1], "k*", markersize=10, label="target")
    ax.set_title(f"LASA {name}: K = {gmm.n_components_} components")
    ax.set_xlabel("x1")
    ax.set_ylabel("x2")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    for dim in range(2):
        ax = axes[dim + 1]
        for d in demos:
            ax.plot(t, d[:, dim], color="0.6", lw=0.8)
        plot_gmr_tube(ax, t, mean[:, dim], np.sqrt(cov[:, dim, dim]), label="GMR +- 2 sd")
        ax.set_xlabel("t")
        ax.set_ylabel(f"x{dim + 1}")
        ax.set_title(f"x{dim + 1} over time")
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    figure: Figure = fig
    return figure


def _space_color(skill: Skill, name: str) -> str:
    if name == "joint":
        return JOINT_COLOR
    return SPACE_COLORS[skill.object_names.index(name) % len(SPACE_COLORS)]


def _dim_labels(skill: Skill, name: str) -> list[str]:
    if name == "joint":
        labels = [f"theta{i + 1} ({j}) [rad]" for i, j in enumerate(skill.robot.joint_names)]
        if skill.has_gripper:
            labels.append("gripper")
        return labels
    if name in skill.oriented:
        # {R^T (x - p), r}: the hand's position in the object's frame, then its orientation
        # relative to the object (rotation vector in the tangent space at the mean, object axes).
        return [f"R^T(x - p){i + 1} ({name} frame) [m]" for i in range(3)] + [
            f"r{i + 1} ({name}) [rad]" for i in range(3)
        ]
    return [f"x{i + 1} - o{i + 1} ({name}) [m]" for i in range(3)]


def plot_constraints(
    skill: Skill,
    demos: Sequence[Demonstration],
    *,
    covariance: str = "exact",
) -> Figure:
    """The paper's Figs. 4-5: per space, demonstrations over time, GMM ellipses, GMR tube.

    One column per space (each object's frame, then joint space), one row per dimension. A
    narrow tube means the demonstrations agreed: that constraint matters at that time.

    An oriented object (:attr:`pbdkit.Skill.oriented`) has six rows: the hand's position in the
    object's frame, R^T (x - p), then the three components of its orientation relative to the
    object, the rotation vector r in the tangent space at the demonstrations' mean relative
    orientation (R^T R_hand = exp([r]x) M, object axes; rad), titled "orientation relative to
    the <object> (rad, tangent at the mean)". Position-only objects have three rows, x - o.
    """
    data = skill.training_data(demos)
    names = [*skill.object_names, "joint"]
    n_rows = max(d.shape[2] - 1 for d in data.values())
    fig = new_figure(figsize=(4.2 * len(names), 1.9 * n_rows))
    axes = fig.subplots(n_rows, len(names), sharex=True, squeeze=False)
    t = np.arange(skill.n_steps, dtype=np.float64)
    for col, name in enumerate(names):
        gmm = skill.gmms[name]
        mean, cov = gmm.regress(t[:, None], in_dims=[0], covariance=covariance)  # type: ignore[arg-type]
        # The covariance the reproduction uses: widened by the calibration (not the gripper's).
        n_scaled = skill.n_joints if name == "joint" else cov.shape[1]
        cov[:, :n_scaled, :n_scaled] *= skill.calibration_[name][:, None, None]
        labels = _dim_labels(skill, name)
        color = _space_color(skill, name)
        d_out = mean.shape[1]
        for row in range(n_rows):
            ax = axes[row, col]
            if row >= d_out:
                ax.set_visible(False)
                continue
            for demo in data[name]:
                ax.plot(demo[:, 0], demo[:, row + 1], color="0.65", lw=0.7)
            plot_gmm_ellipses(ax, gmm, (0, row + 1), color=color, alpha=0.25)
            plot_gmr_tube(ax, t, mean[:, row], np.sqrt(cov[:, row, row]), color=color, label=None)
            ax.set_ylabel(labels[row], fontsize=7)
            ax.tick_params(labelsize=7)
            if row == 0:
                title = "joint space" if name == "joint" else f"relative to the {name}"
                ax.set_title(f"{title}: K = {gmm.n_components_}", fontsize=9)
            elif row == 3 and name in skill.oriented:
                ax.set_title(
                    f"orientation relative to the {name} (rad, tangent at the mean)", fontsize=9
                )
            if row == d_out - 1:
                ax.set_xlabel("time step", fontsize=8)
    fig.suptitle(
        "Constraints extracted from the demonstrations (GMM, and GMR mean +- 2 sd, calibrated)"
    )
    fig.tight_layout()
    figure: Figure = fig
    return figure


def plot_demonstrations_3d(
    skill: Skill,
    demos: Sequence[Demonstration],
    *,
    objects: Mapping[str, npt.ArrayLike] | None = None,
    reproduction: ReproductionResult | None = None,
    frame_length: float = 0.05,
    hand_frames: int = 6,
) -> Figure:
    """The paper's Fig. 3: demonstrated hand paths in 3-D with the objects' positions (left) and
    the reproduction for a new situation (right).

    Every recorded object is drawn: those of the skill in their constraint's colour, the others
    (a fixed basin the skill has no constraint on) in grey, labelled "(no constraint)".

    An object given as a pose (in the demonstrations, or in ``objects``: a 4x4 transform or
    x, y, z, qw, qx, qy, qz) is also drawn with its frame: a line of ``frame_length`` m along
    each of its axes, x, y and z in red, green and blue (:data:`FRAME_COLORS`; the lines' gid
    is :data:`OBJECT_FRAME_GID`). When the reproduction has the hand's orientations (a skill
    with oriented constraints), the hand's frame is drawn so at ``hand_frames`` samples evenly
    spaced along the path (gid :data:`HAND_FRAME_GID`).
    """
    from ..data._placement import check_placements, is_pose, position_of

    markers = ["+", "x", "^", "s"]
    placed = None if objects is None else check_placements(objects, "objects")
    recorded = list(dict.fromkeys(k for demo in demos for k in demo.objects))
    extra = [k for k in recorded if k not in skill.object_names]
    if placed is not None:
        extra += [k for k in placed if k not in skill.object_names and k not in extra]
    shown = [*skill.object_names, *extra]

    def color(name: str) -> str:
        return _space_color(skill, name) if name in skill.object_names else UNCONSTRAINED_COLOR

    def label(name: str) -> str:
        return name if name in skill.object_names else f"{name} (no constraint)"

    framed = False  # whether any frame is drawn (said in the title)
    ncols = 2 if reproduction is not None else 1
    fig = new_figure(figsize=(6.0 * ncols, 5.2))
    ax = fig.add_subplot(1, ncols, 1, projection="3d")
    for k, demo in enumerate(demos):
        x = np.asarray(skill.robot.fk(demo.joints), dtype=np.float64)
        ax.plot(
            x[:, 0],
            x[:, 1],
            x[:, 2],
            color="0.45",
            lw=1,
            label="demonstrations" if k == 0 else None,
        )
        ax.scatter(*x[0], color="k", s=12)
        for i, name in enumerate(shown):
            if name not in demo.objects:
                continue
            where = demo.objects[name]
            ax.scatter(
                *position_of(where),
                marker=markers[i % 4],
                color=color(name),
                s=50,
                label=label(name) if k == 0 else None,
            )
            if is_pose(where):
                _draw_frame(ax, where, frame_length, OBJECT_FRAME_GID)
                framed = True
    frames = "; frames: x red, y green, z blue" if framed else ""
    ax.set_title(f"{len(demos)} demonstrations (dots: start{frames})")
    _label_3d(ax)
    ax.legend(fontsize=8, loc="upper left")
    if reproduction is not None:
        ax2 = fig.add_subplot(1, 2, 2, projection="3d")
        p = reproduction.positions
        ax2.plot(p[:, 0], p[:, 1], p[:, 2], color="k", lw=2, label="reproduction")
        ax2.scatter(*p[0], color="k", s=12)
        for i, name in enumerate(shown):
            if placed is not None and name in placed:
                where = placed[name]
                ax2.scatter(
                    *position_of(where),
                    marker=markers[i % 4],
                    color=color(name),
                    s=90,
                    linewidths=2.5,
                    label=f"{label(name)} (new)" if name in skill.object_names else label(name),
                )
                if is_pose(where):
                    _draw_frame(ax2, where, frame_length, OBJECT_FRAME_GID)
        title = "reproduction for a new situation"
        rot = reproduction.orientations
        if rot is not None and hand_frames > 0:
            samples = np.unique(np.linspace(0, len(p) - 1, hand_frames).round().astype(np.intp))
            for j in samples:
                pose = np.eye(4)
                pose[:3, :3], pose[:3, 3] = rot[j], p[j]
                _draw_frame(ax2, pose, frame_length, HAND_FRAME_GID, lw=1.0)
            title += f" (the hand's frame at {len(samples)} samples)"
        ax2.set_title(title)
        _label_3d(ax2)
        ax2.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    figure: Figure = fig
    return figure


def _draw_frame(ax: Any, pose: Float, length: float, gid: str, *, lw: float = 1.8) -> None:
    """A frame as three lines of ``length`` from its origin along its x, y and z axes (the
    columns of its rotation), coloured :data:`FRAME_COLORS`."""
    origin = pose[:3, 3]
    for axis, axis_color in enumerate(FRAME_COLORS):
        tip = origin + length * pose[:3, axis]
        ax.plot(*np.stack([origin, tip]).T, color=axis_color, lw=lw, gid=gid)


def _label_3d(ax: Any) -> None:
    ax.set_xlabel("x1 [m]", fontsize=8)
    ax.set_ylabel("x2 [m]", fontsize=8)
    ax.set_zlabel("x3 [m]", fontsize=8)
    ax.tick_params(labelsize=7)


def plot_influence(ax: Axes, skill: Skill, result: ReproductionResult) -> None:
    """Stacked shares of each constraint in the fused controller over time.

    ``result.influence``: each constraint's share of the information on the hand's position
    (hand space, summing to 1; see :mod:`pbdkit.reproduction._probabilistic_ik`, "Influence").
    """
    names = [n for n in ("joint", *skill.object_names) if n in result.influence]
    shares = np.stack([result.influence[n] for n in names])
    colors = [_space_color(skill, n) for n in names]
    labels = ["joint space" if n == "joint" else f"relative to the {n}" for n in names]
    ax.stackplot(result.t, shares, labels=labels, colors=colors, alpha=0.6)
    ax.set_ylim(0.0, 1.0)
    ax.set_ylabel("share (hand space)", fontsize=8)
    ax.set_xlabel("time step", fontsize=8)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("which constraint drives the fused controller", fontsize=9)


def plot_reproductions(
    skill: Skill,
    results: dict[str, ReproductionResult],
) -> Figure:
    """The paper's Fig. 6: joint angles and hand position of each controller, and the
    influence of each constraint over time in the fused one.

    ``results`` maps a controller name ("fused", "joint", or an object name for its task-only
    controller) to its reproduction. Line styles follow the paper: fused solid, task-only
    dash-dot (first object) and dotted (second), joint-only dashed. For a skill with oriented
    constraints, the fused controller's angle to each oriented object's expected orientation
    (degrees, dashed) shares the bottom-right panel, on its right axis.
    """
    n = skill.robot.n_joints
    rows = max(n, 3) + 1
    fig = new_figure(figsize=(11, 1.7 * rows))
    axes = fig.subplots(rows, 2, squeeze=False)

    def style(name: str) -> Any:
        if name in CONTROLLER_STYLES:
            return CONTROLLER_STYLES[name]
        return OBJECT_STYLES[skill.object_names.index(name) % len(OBJECT_STYLES)]

    def label(name: str) -> str:
        if name == "fused":
            return "fused (all constraints)"
        if name == "joint":
            return "joint space only"
        return f"task space only ({name})"

    for name, res in results.items():
        color = "k" if name == "fused" else _space_color(skill, name)
        lw = 2.0 if name == "fused" else 1.2
        for j in range(n):
            axes[j, 0].plot(
                res.t,
                res.joints[:, j],
                linestyle=style(name),
                color=color,
                lw=lw,
                label=label(name) if j == 0 else None,
            )
            axes[j, 0].set_ylabel(f"theta{j + 1} [rad]", fontsize=8)
        for i in range(3):
            axes[i, 1].plot(res.t, res.positions[:, i], linestyle=style(name), color=color, lw=lw)
            axes[i, 1].set_ylabel(f"x{i + 1} [m]", fontsize=8)
    for j in range(n, rows - 1):
        axes[j, 0].set_visible(False)
    for i in range(3, rows - 1):
        axes[i, 1].set_visible(False)
    axes[0, 0].legend(fontsize=7, loc="best")
    axes[0, 0].set_title("joint angles", fontsize=9)
    axes[0, 1].set_title("hand position (base frame)", fontsize=9)
    if "fused" in results:
        plot_influence(axes[rows - 1, 0], skill, results["fused"])
        ax = axes[rows - 1, 1]
        for name, err in results["fused"].task_errors.items():
            ax.plot(
                results["fused"].t,
                1000 * err,
                color=_space_color(skill, name),
                label=f"distance to the {name} target",
            )
        ax.set_ylabel("[mm]", fontsize=8)
        ax.set_xlabel("time step", fontsize=8)
        ax.set_yscale("log")
        angles = results["fused"].orientation_errors
        if angles:
            # Oriented objects: the angle to the orientation each expects, on a second axis.
            ax_deg = ax.twinx()
            for name, err in angles.items():
                ax_deg.plot(
                    results["fused"].t,
                    np.degrees(err),
                    color=_space_color(skill, name),
                    ls="--",
                    label=f"angle to the {name} target orientation",
                )
            ax_deg.set_ylabel("[deg] (dashed)", fontsize=8)
            ax_deg.set_yscale("log")
            ax_deg.tick_params(labelsize=7)
            handles, labels = ax.get_legend_handles_labels()
            more = ax_deg.get_legend_handles_labels()
            ax_deg.legend(handles + more[0], labels + more[1], fontsize=7)
            ax.set_title("fused: hand to each object's expected pose", fontsize=9)
        else:
            ax.legend(fontsize=7)
            ax.set_title("fused: hand to each object's expected position", fontsize=9)
    else:
        axes[rows - 1, 0].set_visible(False)
        axes[rows - 1, 1].set_visible(False)
    for ax in axes.ravel():
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    figure: Figure = fig
    return figure


def plot_selection(skill: Skill) -> Figure:
    """How K was chosen in every space: the cross-validated error of each K tried.

    One panel per space: the mean error over the left-out demonstrations (1 = the
    demonstrations' own variability about their mean), the bound within which a K counts as
    good as the best (:data:`pbdkit.prob._gmm.CV_TOLERANCE`), the best K and the K kept.
    """
    from matplotlib.ticker import FormatStrFormatter

    from ..prob._selection import CV_TOLERANCE

    names = [*skill.object_names, "joint"]
    fig = new_figure(figsize=(3.6 * len(names), 2.8))
    axes = fig.subplots(1, len(names), squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        sel = skill.selection_[name]
        color = _space_color(skill, name)
        title = "joint space" if name == "joint" else f"relative to the {name}"
        if sel.method != "cv":
            label = f"K = {sel.chosen} ({sel.method})"
            ax.text(0.5, 0.5, label, ha="center", transform=ax.transAxes)
            ax.set_title(title, fontsize=9)
            continue
        ks = np.asarray(sel.candidates)
        ax.plot(ks, sel.scores, "o-", color=color, ms=3, lw=1)
        best = float(sel.scores[list(sel.candidates).index(sel.best)])
        ax.axhline((1 + CV_TOLERANCE) * best, color="0.5", lw=0.8, ls="--")
        ax.axvline(sel.chosen, color="k", lw=1)
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
        ax.set_title(f"{title}: K = {sel.chosen} (best {sel.best})", fontsize=9)
        ax.set_xlabel("K", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0, 0].set_ylabel("left-out demo error", fontsize=8)
    fig.suptitle(
        "Choosing K: error predicting a left-out demonstration (dashed: within "
        f"{100 * CV_TOLERANCE:.1f} % of the best; line: K kept)",
        fontsize=9,
    )
    fig.tight_layout()
    figure: Figure = fig
    return figure
