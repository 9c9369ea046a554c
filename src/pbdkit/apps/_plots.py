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
    label: str | None = None,
    centre_label: str | None = None,
) -> None:
    """Draw each component's covariance ellipse (``n_std`` standard deviations) in two dims,
    and its centre (the component's mean) as a black dot.

    Parameters
    ----------
    ax : matplotlib Axes
    gmm : GMM
        A fitted mixture.
    dims : (int, int)
        The dimensions shown on the x and y axes.
    label, centre_label : str, optional
        Legend labels of the ellipses (given to the first one only, so that a legend lists it
        once) and of the centres (one line of dots for all components).
    """
    from matplotlib.patches import Ellipse

    i, j = dims
    for k, (mean, cov) in enumerate(zip(gmm.means_, gmm.covariances_, strict=True)):
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
            label=label if k == 0 else None,
        )
        ax.add_patch(ell)
    centres = np.asarray(gmm.means_, dtype=np.float64)
    ax.plot(centres[:, i], centres[:, j], "k.", ls="none", markersize=4, label=centre_label)


def plot_gmr_tube(
    ax: Axes,
    t: Float,
    mean: Float,
    std: Float,
    *,
    color: str = "tab:blue",
    label: str | None = "GMR",
    n_std: float = 2.0,
    band_label: str | None = None,
) -> None:
    """GMR mean over time with a band of +- ``n_std`` standard deviations.

    Parameters
    ----------
    t : ndarray, shape (T,)
    mean : ndarray, shape (T,)
    std : ndarray, shape (T,)
    label, band_label : str, optional
        Legend labels of the mean and of the band.
    """
    ax.fill_between(
        t,
        mean - n_std * std,
        mean + n_std * std,
        color=color,
        alpha=0.25,
        lw=0,
        label=band_label,
    )
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
    plot_gmm_ellipses(
        ax, gmm, (1, 2), label="GMM component (1 sd)", centre_label="GMM component centre"
    )
    ax.plot(mean[:, 0], mean[:, 1], color="tab:blue", lw=2, label="GMR mean")
    ax.plot(mean[-1, 0], mean[-1, 1], "k*", markersize=10, label="target")
    ax.set_title(f"LASA {name}: K = {gmm.n_components_} components")
    ax.set_xlabel("x1")
    ax.set_ylabel("x2")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    for dim in range(2):
        ax = axes[dim + 1]
        for k, d in enumerate(demos):
            ax.plot(t, d[:, dim], color="0.6", lw=0.8, label="demonstrations" if k == 0 else None)
        plot_gmr_tube(
            ax,
            t,
            mean[:, dim],
            np.sqrt(cov[:, dim, dim]),
            label="GMR mean",
            band_label="GMR +- 2 sd",
        )
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
    import math

    from matplotlib.legend_handler import HandlerTuple

    data = skill.training_data(demos)
    names = [*skill.object_names, "joint"]
    dims = [data[name].shape[2] - 1 for name in names]
    n_rows = max(dims)
    # Each column is split into its own number of panels, so a space with fewer dimensions has
    # taller panels rather than empty cells below them: a grid of lcm(dims) rows, each panel
    # spanning lcm / d of them.
    n_grid = math.lcm(*dims)
    fig = new_figure(figsize=(4.2 * len(names), 1.9 * n_rows + 0.5), layout="constrained")
    grid = fig.add_gridspec(n_grid, len(names))
    t = np.arange(skill.n_steps, dtype=np.float64)
    first: Axes | None = None
    tops: list[Axes] = []  # each column's first panel, whose artists the legend shows
    for col, (name, d_out) in enumerate(zip(names, dims, strict=True)):
        gmm = skill.gmms[name]
        mean, cov = gmm.regress(t[:, None], in_dims=[0], covariance=covariance)  # type: ignore[arg-type]
        # The covariance the reproduction uses: widened by the calibration (not the gripper's).
        n_scaled = skill.n_joints if name == "joint" else cov.shape[1]
        cov[:, :n_scaled, :n_scaled] *= skill.calibration_[name][:, None, None]
        labels = _dim_labels(skill, name)
        color = _space_color(skill, name)
        span = n_grid // d_out
        for row in range(d_out):
            ax = fig.add_subplot(grid[row * span : (row + 1) * span, col], sharex=first)
            first = first or ax
            if row == 0:
                tops.append(ax)
            # Every panel's artists are labelled, so a legend of any one panel is right too.
            for k, demo in enumerate(data[name]):
                ax.plot(
                    demo[:, 0],
                    demo[:, row + 1],
                    color="0.65",
                    lw=0.7,
                    label="demonstrations" if k == 0 else None,
                )
            plot_gmm_ellipses(
                ax,
                gmm,
                (0, row + 1),
                color=color,
                alpha=0.25,
                label="GMM component (1 sd)",
                centre_label="GMM component centre",
            )
            plot_gmr_tube(
                ax,
                t,
                mean[:, row],
                np.sqrt(cov[:, row, row]),
                color=color,
                label="GMR mean",
                band_label="GMR mean +- 2 sd (calibrated)",
            )
            ax.set_ylabel(labels[row], fontsize=7)
            ax.tick_params(labelsize=7, labelbottom=row == d_out - 1)
            if row == 0:
                title = "joint space" if name == "joint" else f"relative to the {name}"
                ax.set_title(f"{title}: K = {gmm.n_components_}", fontsize=9)
            elif row == 3 and name in skill.oriented:
                ax.set_title(
                    f"orientation relative to the {name} (rad, tangent at the mean)", fontsize=9
                )
            if row == d_out - 1:
                ax.set_xlabel("time step", fontsize=8)
    # One legend for the figure. The ellipses, mean and band take each space's colour: their
    # entries show the colours of all the columns side by side; the grey and black ones, once.
    by_label: dict[str, list[Any]] = {}
    for ax in tops:
        for handle, text in zip(*ax.get_legend_handles_labels(), strict=True):
            by_label.setdefault(text, []).append(handle)
    shared = ("demonstrations", "GMM component centre")
    order = ["demonstrations", "GMM component (1 sd)", "GMM component centre", "GMR mean"]
    texts = sorted(by_label, key=lambda k: order.index(k) if k in order else len(order))
    # A tuple of artists is a legend handle too (drawn by HandlerTuple), not in the stubs.
    handles: list[Any] = [by_label[k][0] if k in shared else tuple(by_label[k]) for k in texts]
    fig.legend(
        handles,
        texts,
        loc="outside lower center",
        ncols=len(texts) if len(names) > 1 else 2,  # one column is too narrow for one row
        fontsize=8,
        handlelength=1.2 * len(names),
        handler_map={tuple: HandlerTuple(ndivide=None, pad=0.0)},
    )
    fig.suptitle("Constraints extracted from the demonstrations (a narrow band: they agree)")
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
        ax.scatter(*x[0], color="k", s=12, label="start" if k == 0 else None)
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
    # The start dots are in the legend; the frames' colours are said here (three lines each).
    frames = " (frames: x red, y green, z blue)" if framed else ""
    ax.set_title(f"{len(demos)} demonstrations{frames}")
    _label_3d(ax)
    ax.legend(fontsize=8, loc="upper left")
    if reproduction is not None:
        ax2 = fig.add_subplot(1, 2, 2, projection="3d")
        p = reproduction.positions
        ax2.plot(p[:, 0], p[:, 1], p[:, 2], color="k", lw=2, label="reproduction")
        ax2.scatter(*p[0], color="k", s=12, label="start")
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
    (degrees, dashed) shares the bottom-right panel, on its right axis. The joints' panels (left)
    and the hand's three (right) fill the same height, whatever the number of joints.
    """
    import math

    n = skill.robot.n_joints
    fused = "fused" in results
    # The joint angles (left) and the hand's three coordinates (right) share the height above
    # the bottom row: a grid of lcm(n, 3) rows, each panel spanning lcm / n or lcm / 3 of them,
    # so neither column has empty cells (as plot_constraints). The bottom row (the fused
    # controller only) is as tall as a joint panel.
    n_grid = math.lcm(n, 3)
    span = n_grid // n
    fig = new_figure(figsize=(11, 1.7 * (max(n, 3) + (1 if fused else 0))), layout="constrained")
    grid = fig.add_gridspec(n_grid + (span if fused else 0), 2)
    joint_axes = [fig.add_subplot(grid[j * span : (j + 1) * span, 0]) for j in range(n)]
    h = n_grid // 3
    hand_axes = [fig.add_subplot(grid[i * h : (i + 1) * h, 1]) for i in range(3)]

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
        for j, ax in enumerate(joint_axes):
            ax.plot(
                res.t,
                res.joints[:, j],
                linestyle=style(name),
                color=color,
                lw=lw,
                label=label(name) if j == 0 else None,
            )
            ax.set_ylabel(f"theta{j + 1} [rad]", fontsize=8)
        for i, ax in enumerate(hand_axes):
            ax.plot(res.t, res.positions[:, i], linestyle=style(name), color=color, lw=lw)
            ax.set_ylabel(f"x{i + 1} [m]", fontsize=8)
    joint_axes[0].legend(fontsize=7, loc="best")
    joint_axes[0].set_title("joint angles", fontsize=9)
    hand_axes[0].set_title("hand position (base frame)", fontsize=9)
    if fused:
        plot_influence(fig.add_subplot(grid[n_grid:, 0]), skill, results["fused"])
        ax = fig.add_subplot(grid[n_grid:, 1])
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
        _label_log_y(ax, max_ticks=4)  # a short panel: plain numbers, few of them
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
            _label_log_y(ax_deg, max_ticks=4)
            ax_deg.tick_params(labelsize=7)
            handles, labels = ax.get_legend_handles_labels()
            more = ax_deg.get_legend_handles_labels()
            ax_deg.legend(handles + more[0], labels + more[1], fontsize=7)
            ax.set_title("fused: hand to each object's expected pose", fontsize=9)
        else:
            ax.legend(fontsize=7)
            ax.set_title("fused: hand to each object's expected position", fontsize=9)
    for ax in fig.axes:
        ax.tick_params(labelsize=7)
    figure: Figure = fig
    return figure


# The labelled ticks tried on a log axis, finest first: the mantissas labelled in each decade.
_LOG_MANTISSAS = ((1.0, 1.2, 1.5, 2.0, 3.0, 5.0, 7.0), (1.0, 2.0, 5.0), (1.0, 3.0), (1.0,))


def _log_ticks(lo: float, hi: float, *, max_ticks: int = 6) -> list[float]:
    """Plain numbers to label a log axis from ``lo`` to ``hi``: at most ``max_ticks`` of them.

    The finest series of :data:`_LOG_MANTISSAS` (1, 1.2, 1.5, 2, 3, 5, 7, 10, 12, ...; then
    1, 2, 5, 10, 20, ...; then 1, 3, 10, 30, ...; then the decades) that gives no more than
    ``max_ticks`` ticks in the range, then every n-th decade. A range too narrow to hold two of
    them (less than a factor of about 1.3) gets evenly spaced plain steps instead (1.2, 1.25,
    1.3). Never more than ``max_ticks``; two or more for ``max_ticks`` >= 2.

    Parameters
    ----------
    lo, hi : float
        The axis' limits, 0 < ``lo`` < ``hi``.
    max_ticks : int

    Returns
    -------
    list of float
        Increasing, all in [``lo``, ``hi``].
    """
    from matplotlib.ticker import MaxNLocator

    decades = np.arange(np.floor(np.log10(lo)), np.ceil(np.log10(hi)) + 1)
    ticks: list[float] = []
    for mantissas in _LOG_MANTISSAS:
        # Rounded to 12 digits: 3 * 10 ** -1 is 0.30000000000000004.
        cand = [float(f"{m * 10.0**e:.12g}") for e in decades for m in mantissas]
        ticks = [v for v in cand if lo <= v <= hi]
        if len(ticks) <= max_ticks:
            break
    else:
        step = int(np.ceil(len(decades) / max_ticks))
        ticks = [v for v in (10.0**e for e in decades[::step]) if lo <= v <= hi]
    if len(ticks) < 2:
        plain = MaxNLocator(nbins=max(min(max_ticks, 5) - 1, 1), steps=[1, 2, 5, 10])
        steps = [float(f"{v:.12g}") for v in plain.tick_values(lo, hi) if lo <= v <= hi]
        ticks = steps[:: int(np.ceil(len(steps) / max_ticks))]
    return ticks


def _label_log_y(ax: Axes, *, max_ticks: int = 6) -> None:
    """Label the log y axis of ``ax`` with :func:`_log_ticks` of its current limits, and none
    of its minor ticks.

    matplotlib labels the minor ticks of a log axis that spans few decades, 2 to 9 in each:
    with a plain formatter they stack into an unreadable column (issue 40). Call it once the
    axes is drawn on: the ticks are fixed for the limits it has then.
    """
    from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

    lo, hi = sorted(ax.get_ylim())
    ax.yaxis.set_major_locator(FixedLocator(_log_ticks(lo, hi, max_ticks=max_ticks)))
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def plot_selection(skill: Skill) -> Figure:
    """How K was chosen in every space: the cross-validated error of each K tried.

    One panel per space: the mean error over the left-out demonstrations (1 = the
    demonstrations' own variability about their mean, log scale), the best K, the bound under
    which a K counts as good as the best (:data:`pbdkit.prob._selection.CV_TOLERANCE` above the
    level the grid of K reaches, :func:`pbdkit.prob._selection.reached_level`) and the K kept,
    the smallest under it; a legend below the panels names them.
    """
    from matplotlib.ticker import MaxNLocator

    from ..prob._selection import CV_TOLERANCE, candidate_grid, reached_level

    names = [*skill.object_names, "joint"]
    fig = new_figure(figsize=(3.6 * len(names), 3.2), layout="constrained")
    axes = fig.subplots(1, len(names), squeeze=False)
    legend_from: Axes | None = None  # the first panel with a curve: its artists are listed
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
        ax.plot(ks, sel.scores, "o-", color=color, ms=3, lw=1, label="error of each K tried")
        score = dict(zip(sel.candidates, sel.scores, strict=True))
        ax.plot(sel.best, score[sel.best], "o", mfc="none", mec="k", ms=7, label="best K")
        # The bound the choice used: above the level the grid reaches (the second lowest
        # score), not above the best score, which one lucky EM run can set (reached_level).
        # The K tried are that grid and the K between two of its points: the grid is the
        # candidate_grid of the largest.
        grid = [k for k in candidate_grid(max(sel.candidates)) if k in score]
        bound = (1 + CV_TOLERANCE) * reached_level([score[k] for k in grid])
        ax.axhline(
            bound,
            color="0.5",
            lw=0.8,
            ls="--",
            label=f"bound: {100 * CV_TOLERANCE:.1f} % above the level reached",
        )
        ax.axvline(sel.chosen, color="k", lw=1, label="K kept: the smallest under the bound")
        ax.set_yscale("log")
        _label_log_y(ax)
        # K is a count: integer ticks.
        ax.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 5, 10], integer=True))
        ax.set_title(f"{title}: K = {sel.chosen} (best {sel.best})", fontsize=9)
        ax.set_xlabel("K", fontsize=8)
        ax.tick_params(labelsize=7)
        legend_from = legend_from or ax
    axes[0, 0].set_ylabel("left-out demo error", fontsize=8)
    if legend_from is not None:
        handles, labels = legend_from.get_legend_handles_labels()
        # One row under the panels; two columns of entries under a single narrow panel.
        ncols = len(labels) if len(names) > 1 else 2
        fig.legend(handles, labels, loc="outside lower center", ncols=ncols, fontsize=8)
    fig.suptitle("Choosing K: error predicting a left-out demonstration", fontsize=9)
    figure: Figure = fig
    return figure
