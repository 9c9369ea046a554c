"""The report's figures are readable and explain every marker (issue 40): the log axis of "Choosing
K" has plain, non-overlapping tick labels; the constraints figure has no empty panel and its
legend names every marker, its black dots the GMM components' centres.

On the synthetic glass task of ``tests/conftest.py`` (a skill learned in under a second): its
left-out error spans 1.3 to 4000 in the glass space, four decades whose minor tick labels used
to stack on each other.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pbdkit import GMM
from pbdkit.apps._plots import (
    _log_ticks,
    plot_constraints,
    plot_demonstrations_3d,
    plot_lasa_summary,
    plot_reproductions,
    plot_selection,
)
from pbdkit.data._demonstration import Demonstration
from pbdkit.prob import _selection
from pbdkit.prob._selection import CV_TOLERANCE, candidate_grid, reached_level
from pbdkit.skill._skill import Skill

CENTRE = "GMM component centre"


def _drawn(fig: Figure) -> Any:
    """Draw ``fig`` on an Agg canvas (a figure of :func:`new_figure` has none that draws): the
    layout, limits and ticks are then final. Returns the renderer."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def _tick_labels(axis: Any) -> list[Any]:
    """The tick labels of ``axis`` (major and minor) that are drawn: non-empty, visible, at a
    tick inside the view."""
    lo, hi = sorted(axis.get_view_interval())
    out = []
    for locs, labels in (
        (axis.get_majorticklocs(), axis.get_majorticklabels()),
        (axis.get_minorticklocs(), axis.get_minorticklabels()),
    ):
        for loc, label in zip(locs, labels, strict=False):
            if label.get_visible() and label.get_text() and lo <= loc <= hi:
                out.append(label)
    return out


def _overlapping(labels: list[Any], renderer: Any) -> list[tuple[str, str]]:
    """The pairs of ``labels`` whose boxes on the canvas overlap."""
    boxes = [(label.get_text(), label.get_window_extent(renderer)) for label in labels]
    return [(a, b) for (a, ba), (b, bb) in itertools.combinations(boxes, 2) if ba.overlaps(bb)]


def _legend_texts(fig: Figure) -> set[str]:
    """The texts of every legend of ``fig``: its own and its axes'."""
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    return {t.get_text() for legend in legends for t in legend.get_texts()}


def _has_marker(line: Any) -> bool:
    return line.get_marker() not in (None, "", " ", "None", "none")


def _unexplained(fig: Figure) -> list[str]:
    """The markers of ``fig`` that no legend names: lines drawn with a marker, and scatter
    collections, whose label is missing or not in a legend."""
    texts = _legend_texts(fig)
    missing = []
    for ax in fig.axes:
        marked = [ln for ln in ax.get_lines() if _has_marker(ln)]
        scattered = [c for c in ax.collections if type(c).__name__.endswith("PathCollection")]
        for artist in marked + scattered:
            label = artist.get_label()
            if label.startswith("_") or label not in texts:
                missing.append(f"{ax.get_title()!r}: {label!r}")
    return missing


# ----------------------------------------------------------------------------- log ticks
@pytest.mark.parametrize(
    ("lo", "hi"),
    [(1.3, 4060.0), (0.9, 5000.0), (1.1, 20.0), (1.19, 1.3), (1.2, 1.21), (0.25, 0.9), (1e-3, 1e9)],
)
@pytest.mark.parametrize("max_ticks", [2, 4, 6])
def test_log_ticks_are_few_plain_numbers_in_the_range(lo: float, hi: float, max_ticks: int) -> None:
    ticks = _log_ticks(lo, hi, max_ticks=max_ticks)
    assert 2 <= len(ticks) <= max_ticks, ticks
    assert ticks == sorted(set(ticks))
    assert all(lo <= v <= hi for v in ticks)
    # Plain: at most four significant digits (no 0.30000000000000004).
    assert all(float(f"{v:.4g}") == v for v in ticks), ticks


def test_log_ticks_prefer_the_finest_series_that_fits() -> None:
    assert _log_ticks(1.3, 4060.0) == [10.0, 100.0, 1000.0]
    assert _log_ticks(1.1, 20.0) == [2.0, 5.0, 10.0, 20.0]
    assert _log_ticks(1.1, 4.0) == [1.2, 1.5, 2.0, 3.0]
    assert _log_ticks(0.25, 0.9) == [0.3, 0.5, 0.7]


# ----------------------------------------------------------------------------- choosing K
def test_selection_tick_labels_do_not_overlap(
    robot: Any, demos: list[Demonstration], monkeypatch: pytest.MonkeyPatch
) -> None:
    # K searched from 1 (MIN_COMPONENTS from 12 leaves the scores within a few percent): the
    # scores span four decades.
    from synthetic_teacher import N_STEPS

    monkeypatch.setattr(_selection, "MIN_COMPONENTS", 1)
    skill = Skill.learn(demos, robot, n_steps=N_STEPS, random_state=0)
    assert [skill.selection_[k].method for k in ("glass", "joint")] == ["cv", "cv"]
    scores = skill.selection_["glass"].scores
    assert scores.max() / scores.min() > 1000  # four decades: the case that used to stack
    fig = plot_selection(skill)
    renderer = _drawn(fig)
    panels = [ax for ax in fig.axes if ax.get_yscale() == "log"]
    assert len(panels) == 2
    for ax in panels:
        for axis in (ax.xaxis, ax.yaxis):
            labels = _tick_labels(axis)
            assert len(labels) >= 2
            assert _overlapping(labels, renderer) == []
        # Only the major ticks are labelled, with plain numbers.
        assert [lb for lb in ax.yaxis.get_minorticklabels() if lb.get_text()] == []
        assert all(lb.get_text().replace(".", "").isdigit() for lb in _tick_labels(ax.yaxis))
        # K is a count: integer ticks.
        assert all(float(v).is_integer() for v in ax.get_xticks())


def test_selection_legend_names_every_marker_and_the_bound_is_the_one_used(skill: Skill) -> None:
    fig = plot_selection(skill)
    _drawn(fig)
    assert _unexplained(fig) == []
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == [
        "error of each K tried",
        "best K",
        f"bound: {100 * CV_TOLERANCE:.1f} % above the level reached",
        "K kept: the smallest under the bound",
    ]
    for ax, name in zip(fig.axes, [*skill.object_names, "joint"], strict=True):
        sel = skill.selection_[name]
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        bound = float(lines[legend.get_texts()[2].get_text()].get_ydata()[0])
        score = dict(zip(sel.candidates, sel.scores, strict=True))
        grid = [k for k in candidate_grid(max(sel.candidates)) if k in score]
        assert bound == pytest.approx((1 + CV_TOLERANCE) * reached_level([score[k] for k in grid]))
        # What the legend says: the K kept is the smallest under the dashed line.
        assert score[sel.chosen] <= bound
        assert all(score[k] > bound for k in sel.candidates if k < sel.chosen)
        assert float(lines["K kept: the smallest under the bound"].get_xdata()[0]) == sel.chosen
        best = lines["best K"]
        assert (float(best.get_xdata()[0]), float(best.get_ydata()[0])) == (
            sel.best,
            pytest.approx(score[sel.best]),
        )


# ----------------------------------------------------------------------------- constraints
@pytest.fixture(scope="module")
def constraints(robot: Any) -> tuple[Skill, list[Demonstration], Figure, Any]:
    """The constraints figure of the synthetic task with a coaster, drawn: two objects (3
    dimensions each) and the joints (5 and the gripper), so the columns have different numbers
    of panels. The skill, its demonstrations, the figure and the renderer it was drawn with."""
    from synthetic_teacher import N_STEPS, synthetic_demos

    demos = synthetic_demos(robot, np.random.default_rng(1), n_demos=4, coaster=True)
    skill = Skill.learn(demos, robot, n_steps=N_STEPS, n_components=4, random_state=0)
    fig = plot_constraints(skill, demos)
    return skill, demos, fig, _drawn(fig)


def test_constraint_figure_has_no_empty_panel(
    constraints: tuple[Skill, list[Demonstration], Figure, Any],
) -> None:
    _, demos, fig, _ = constraints
    assert len(fig.axes) == 3 + 3 + 6  # glass, coaster, joints 1-5 and the gripper
    for ax in fig.axes:
        assert ax.get_visible()
        demo_lines = [ln for ln in ax.get_lines() if ln.get_label() == "demonstrations"]
        assert len(demo_lines) == 1  # labelled once; one thin grey line per demonstration
        assert len([ln for ln in ax.get_lines() if ln.get_linewidth() < 1]) == len(demos)
    # The panels fill their columns: every column spans the same height, no cell is empty.
    columns: dict[float, list[Any]] = {}
    for ax in fig.axes:
        columns.setdefault(round(ax.get_position().x0, 3), []).append(ax.get_position())
    assert sorted(len(c) for c in columns.values()) == [3, 3, 6]
    tops = [max(p.y1 for p in c) for c in columns.values()]
    bottoms = [min(p.y0 for p in c) for c in columns.values()]
    assert max(tops) - min(tops) < 0.01
    assert max(bottoms) - min(bottoms) < 0.01
    # Every column's bottom panel shows the time steps.
    for c in columns:
        bottom = min(
            (ax for ax in fig.axes if round(ax.get_position().x0, 3) == c),
            key=lambda ax: ax.get_position().y0,
        )
        assert bottom.get_xlabel() == "time step"
        assert len(_tick_labels(bottom.xaxis)) >= 2


def test_constraint_figure_legend_names_every_marker_the_dots_are_the_gmm_centres(
    constraints: tuple[Skill, list[Demonstration], Figure, Any],
) -> None:
    skill, _, fig, renderer = constraints
    assert _unexplained(fig) == []
    (legend,) = fig.legends
    texts = [t.get_text() for t in legend.get_texts()]
    assert texts == [
        "demonstrations",
        "GMM component (1 sd)",
        CENTRE,
        "GMR mean",
        "GMR mean +- 2 sd (calibrated)",
    ]
    # The legend is inside the figure and clear of every panel.
    box = legend.get_window_extent(renderer)
    assert all(not box.overlaps(ax.get_window_extent(renderer)) for ax in fig.axes)
    # The black dots of each panel are the centres of its space's GMM components in (t, dim).
    names = [*skill.object_names, "joint"]
    n_dims = [3, 3, 6]
    panels = iter(fig.axes)
    for name, n in zip(names, n_dims, strict=True):
        means = np.asarray(skill.gmms[name].means_)
        for dim in range(1, n + 1):
            ax = next(panels)
            (dots,) = [ln for ln in ax.get_lines() if _has_marker(ln)]
            assert dots.get_label() == CENTRE
            assert dots.get_linestyle() == "None"
            np.testing.assert_allclose(dots.get_xdata(), means[:, 0])
            np.testing.assert_allclose(dots.get_ydata(), means[:, dim])
            # The ellipses and the band are named too (the first ellipse carries the label).
            assert ax.patches[0].get_label() == "GMM component (1 sd)"
            assert len(ax.patches) == len(means)
            assert ax.collections[-1].get_label() == "GMR mean +- 2 sd (calibrated)"


# ----------------------------------------------------------------------------- the other figures
def test_3d_figure_names_the_start_dots(skill: Skill, demos: list[Demonstration]) -> None:
    objects = {"glass": demos[0].objects["glass"] + np.array([0.01, -0.01, 0.0])}
    res = skill.reproduce(objects)
    fig = plot_demonstrations_3d(skill, demos, objects=objects, reproduction=res)
    _drawn(fig)
    assert _unexplained(fig) == []
    for ax in fig.axes:
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        assert "start" in texts
    assert "dots" not in fig.axes[0].get_title()  # said by the legend now
    # The error panel of the controllers figure: plain log labels that do not overlap.
    fig6 = plot_reproductions(skill, {"fused": res})
    renderer = _drawn(fig6)
    (errors,) = [ax for ax in fig6.axes if ax.get_visible() and ax.get_yscale() == "log"]
    labels = _tick_labels(errors.yaxis)
    assert len(labels) >= 2
    assert _overlapping(labels, renderer) == []
    assert all("^" not in lb.get_text() for lb in labels)  # 1, 10, 100: not 10^0


def test_lasa_figure_names_the_ellipses_and_their_centres() -> None:
    t = np.linspace(0.0, 1.0, 30)
    demos = [np.column_stack([np.sin(3 * t) + 0.1 * k, np.cos(3 * t)]) for k in range(3)]
    x = np.vstack([np.column_stack([t, d]) for d in demos])
    gmm = GMM(3, random_state=0).fit(x)
    mean, cov = gmm.regress(t[:, None])
    fig = plot_lasa_summary("demo", t, demos, gmm, mean, cov)
    _drawn(fig)
    assert _unexplained(fig) == []
    plane = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert {"GMM component (1 sd)", CENTRE, "target"} <= set(plane)
    for ax in fig.axes[1:]:
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        assert texts == ["demonstrations", "GMR +- 2 sd", "GMR mean"]


# ----------------------------------------------------------------------------- controllers
@pytest.fixture(scope="module")
def panda_mug() -> tuple[Skill, dict[str, Any]]:
    """A Panda (7 joints) grasping a mug by its handle, one oriented object, and the mug's pose
    for a reproduction (x, y, z, qw, qx, qy, qz)."""
    import pose_teacher

    from pbdkit._rotations import quaternion_from_matrix
    from pbdkit.robots import panda

    robot = panda()
    skill = Skill.learn(pose_teacher.demonstrations(robot), robot, n_steps=40, n_components=3)
    pose = pose_teacher.mug_pose(0.6, 0.5, 0.05)
    return skill, {"mug": np.r_[pose[:3, 3], quaternion_from_matrix(pose[:3, :3])]}


@pytest.mark.parametrize("arm", ["katana", "panda"])
@pytest.mark.parametrize("with_fused", [True, False])
def test_controllers_figure_has_no_empty_panel(
    request: pytest.FixtureRequest, arm: str, with_fused: bool
) -> None:
    if arm == "katana":  # 5 joints, two objects
        skill, demos, _, _ = request.getfixturevalue("constraints")
        objects = {k: v + np.array([0.01, -0.01, 0.0]) for k, v in demos[0].objects.items()}
    else:  # 7 joints, one oriented object
        skill, objects = request.getfixturevalue("panda_mug")
    runs = {"joint": skill.reproduce(objects, use=["joint"])}
    for k in skill.object_names:
        runs[k] = skill.reproduce(objects, use=[k])
    if with_fused:
        runs["fused"] = skill.reproduce(objects)
    fig = plot_reproductions(skill, runs)
    _drawn(fig)
    n = skill.robot.n_joints
    twins = 1 if with_fused and skill.oriented else 0  # the error panel's axis of angles
    assert len(fig.axes) == n + 3 + (2 if with_fused else 0) + twins
    for ax in fig.axes:
        assert ax.get_visible()
        assert ax.get_lines() or ax.collections  # data drawn: lines, or the influence's areas
    # The joints' column (left) and the hand's (right) span the same height above the bottom
    # row: no empty cell under the hand's three panels.
    columns: dict[float, list[Any]] = {}
    for ax in fig.axes[: n + 3]:
        columns.setdefault(round(ax.get_position().x0, 3), []).append(ax)
    assert sorted(len(c) for c in columns.values()) == [3, n]
    for column in columns.values():
        assert all(ax.get_lines() for ax in column)
    tops = [max(ax.get_position().y1 for ax in c) for c in columns.values()]
    bottoms = [min(ax.get_position().y0 for ax in c) for c in columns.values()]
    assert max(tops) - min(tops) < 0.01
    assert max(bottoms) - min(bottoms) < 0.01
    for column in columns.values():  # each column's bottom panel shows the time steps
        bottom = min(column, key=lambda ax: ax.get_position().y0)
        assert len(_tick_labels(bottom.xaxis)) >= 2
    if with_fused:  # the bottom row under both columns, its panels level with each other
        row = fig.axes[n + 3 : n + 5]
        assert [ax.get_xlabel() for ax in row] == ["time step"] * 2
        assert max(ax.get_position().y1 for ax in row) < min(bottoms)
        assert abs(row[0].get_position().y0 - row[1].get_position().y0) < 0.01
        assert len(row[0].collections) == len(skill.object_names) + 1  # the influence's areas
