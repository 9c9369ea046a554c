"""The paper's figures: they are drawn, and what their captions claim holds in the data they show
(the glass-relative constraint is tight while grasping, the coaster-relative one while placing;
in the basin task the pouring gesture is a joint-space constraint)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")

from pbdkit.apps._plots import (
    figure_png,
    new_figure,
    plot_constraints,
    plot_demonstrations_3d,
    plot_reproductions,
)
from pbdkit.apps._plots_motion import plot_motion_limits
from pbdkit.motion._limits import MotionLimits, divided_differences
from pbdkit.robots import katana
from pbdkit.sim._task_skill import teach
from pbdkit.skill._skill import Skill

N_STEPS = 300


@pytest.fixture(scope="module")
def coaster() -> tuple[Skill, list]:
    demos = teach("coaster", 5, seed=0)
    return Skill.learn(demos, katana(), n_steps=N_STEPS), demos


@pytest.fixture(scope="module")
def basin() -> tuple[Skill, list]:
    demos = teach("basin", 5, seed=0)
    return Skill.learn(demos, katana(), n_steps=N_STEPS), demos


def _grasp_release(skill: Skill) -> tuple[int, int]:
    g = skill.constraints().gripper
    assert g is not None
    closed = np.nonzero(g > 0.5)[0]
    return int(closed[0]), int(closed[-1])


@pytest.mark.slow
def test_coaster_captions_hold(coaster: tuple[Skill, list]) -> None:
    skill, _ = coaster
    c = skill.constraints()
    grasp, release = _grasp_release(skill)
    spread = {k: np.sqrt(np.trace(c.task_cov[k], axis1=1, axis2=2)) for k in skill.object_names}
    # Tight relative to the glass when grasping, loose relative to it when placing ...
    # (measured: 19-23 mm vs 52-55 mm of spread, sqrt of the covariance trace)
    assert spread["glass"][grasp] < 0.5 * spread["glass"][release]
    # ... and the other way round for the coaster (18-21 mm vs about 50 mm).
    assert spread["coaster"][release] < 0.5 * spread["coaster"][grasp]
    # At each moment the tight constraint is the tighter of the two.
    assert spread["glass"][grasp] < spread["coaster"][grasp]
    assert spread["coaster"][release] < spread["glass"][release]


@pytest.mark.slow
def test_basin_glass_matters_while_grasping_not_while_pouring(basin: tuple[Skill, list]) -> None:
    skill, _ = basin
    c = skill.constraints()
    grasp, _ = _grasp_release(skill)
    glass = np.sqrt(np.trace(c.task_cov["glass"], axis1=1, axis2=2))
    assert glass[grasp] < 0.5 * glass[-1]


@pytest.mark.slow
def test_basin_pouring_gesture_is_tight_in_joint_space_with_enough_components(
    basin: tuple[Skill, list],
) -> None:
    # The pouring roll is the same in every demonstration. The default choice of K (leaving
    # one demonstration out, Skill.learn's n_components="auto") keeps enough joint-space
    # components to follow the gesture, where the effective-sample-size BIC of earlier
    # versions gave K = 3 and a roll std of ~0.3 rad at the end: the paper's Fig. 5 finding.
    skill, demos = basin  # teach("basin", 5, seed=0), learned with the defaults
    c = skill.constraints()
    assert skill.selection_["joint"].method == "cv"
    assert skill.n_components["joint"] >= 5
    # Measured: 0.048 rad; 0.053 since the gripper is scored and the arrival aligned to the
    # millimetre (issue 34), where the demonstrations' own end roll spreads by 0.012 rad.
    assert np.sqrt(c.joint_cov[-1, 4, 4]) < 0.06  # rad
    assert abs(c.joint_mean[-1, 4] - np.mean([d.joints[-1, 4] for d in demos])) < 0.1


@pytest.mark.slow
def test_figures_are_drawn_with_one_panel_per_dimension(coaster: tuple[Skill, list]) -> None:
    skill, demos = coaster
    data = skill.training_data(demos)
    assert data["joint"].shape == (5, N_STEPS, 1 + 5 + 1)
    assert data["glass"].shape == (5, N_STEPS, 4)
    fig = plot_constraints(skill, demos)
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 3 + 3 + 6  # glass x3, coaster x3, joints x5 + gripper
    assert figure_png(fig)[:4] == b"\x89PNG"
    objects = {k: v + np.array([0.01, -0.01, 0.0]) for k, v in demos[0].objects.items()}
    fused = skill.reproduce(objects)
    fig3 = plot_demonstrations_3d(skill, demos, objects=objects, reproduction=fused)
    assert len(fig3.axes) == 2
    figure_png(fig3)
    runs = {"fused": fused, "joint": skill.reproduce(objects, use=["joint"])}
    for k in skill.object_names:
        runs[k] = skill.reproduce(objects, use=[k])
    fig6 = plot_reproductions(skill, runs)
    # 5 joints, the hand's x1-x3, the bottom row: positions only, no axis of angles (issue 23)
    assert len(fig6.axes) == 5 + 3 + 2
    labels = fig6.axes[0].get_legend_handles_labels()[1]
    assert labels == [
        "fused (all constraints)",
        "joint space only",
        "task space only (glass)",
        "task space only (coaster)",
    ]
    figure_png(fig6)


def _dashed_levels(ax: Any) -> list[float]:
    """The y of every horizontal dashed line of ``ax``, sorted."""
    levels = []
    for line in ax.get_lines():
        y = np.asarray(line.get_ydata(), dtype=float)
        if line.get_linestyle() == "--" and y.size == 2 and y[0] == y[1]:
            levels.append(float(y[0]))
    return sorted(levels)


@pytest.mark.slow
def test_motion_limits_figure_shows_the_joint_closest_to_its_acceleration_limit(
    coaster: tuple[Skill, list],
) -> None:
    skill, demos = coaster
    robot = skill.robot
    limits = MotionLimits.from_robot(robot, robot.n_joints)
    objects = {k: v + np.array([0.01, -0.01, 0.0]) for k, v in demos[0].objects.items()}
    res = skill.reproduce(objects)
    t = skill.times(res)
    _, a, _ = divided_differences(t, res.joints)
    ratio = np.abs(a).max(axis=0) / limits.acceleration
    joint = int(np.argmax(ratio))
    assert ratio[joint] > 1.01 * np.sort(ratio)[-2]  # a clear winner, so the test can fail
    fig = plot_motion_limits(t, res.joints, limits, joint_names=robot.joint_names)
    axes = fig.axes
    assert len(axes) == 4  # position, velocity, acceleration, jerk
    name = robot.joint_names[joint]
    assert all(name in ax.get_ylabel() for ax in axes)
    assert _dashed_levels(axes[0]) == []
    for ax, lim in zip(axes[1:], (limits.velocity, limits.acceleration, limits.jerk), strict=True):
        assert _dashed_levels(ax) == pytest.approx([-lim[joint], lim[joint]])
        # The plotted derivative stays between its limit lines: the reproduction is timed.
        (curve,) = [line for line in ax.get_lines() if line.get_linestyle() == "-"]
        assert np.abs(curve.get_ydata()).max() <= lim[joint]
    assert figure_png(fig)[:4] == b"\x89PNG"
    # Another joint on request, with its range dashed on the position panel.
    other = (joint + 1) % robot.n_joints
    fig2 = plot_motion_limits(
        t, res.joints, limits, joint=other, position_limits=(robot.lower, robot.upper)
    )
    assert f"theta{other + 1}" in fig2.axes[0].get_ylabel()
    assert _dashed_levels(fig2.axes[0]) == pytest.approx(
        sorted([robot.lower[other], robot.upper[other]])
    )
    with pytest.raises(ValueError, match=r"joint must be in 0\.\.4"):
        plot_motion_limits(t, res.joints, limits, joint=7)


@pytest.mark.slow
def test_figures_leave_the_users_matplotlib_backend_alone() -> None:
    # A Jupyter session keeps its inline backend: plotting must not call matplotlib.use.
    import subprocess
    import sys

    code = (
        "import matplotlib; matplotlib.use('svg'); import numpy as np\n"
        "from pbdkit.apps._plots import figure_png, plot_gmr_tube\n"
        "from matplotlib.figure import Figure\n"
        "fig = Figure(); ax = fig.subplots()\n"
        "t = np.linspace(0, 1, 5); plot_gmr_tube(ax, t, t, 0.1 + 0 * t)\n"
        "png = figure_png(fig)\n"
        "assert png[:4] == b'\\x89PNG', png[:4]\n"
        "from pbdkit import GMM\n"
        "from pbdkit.apps._plots import plot_lasa_summary\n"
        "x = np.column_stack([t, t, t])\n"
        "gmm = GMM.from_params([1.0], [[0.5, 0.5, 0.5]], [np.eye(3)])\n"
        "m, c = gmm.regress(t[:, None])\n"
        "figure_png(plot_lasa_summary('demo', t, [x[:, 1:]], gmm, m, c))\n"
        "print(matplotlib.get_backend())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "svg"


def test_new_figure_is_outside_pyplot() -> None:
    # The study draws its figures with it: public, sized as asked, not in pyplot's registry.
    fig = new_figure(figsize=(2.0, 1.0))
    assert tuple(fig.get_size_inches()) == (2.0, 1.0)
    assert fig.canvas.manager is None  # pyplot's figures have a manager
    fig.subplots().plot([0, 1], [0, 1])
    assert figure_png(fig, dpi=50).startswith(b"\x89PNG")


# ----------------------------------------------------------------------------- poses (issue 23)
@pytest.fixture(scope="module")
def mug() -> dict[str, Any]:
    """A Panda grasping a mug by its handle, the mug at yaws -80 .. 80 degrees: the skill with
    orientation, the position-only one of the same demonstrations, and a reproduction of each
    for a new pose of the mug (given as x, y, z, qw, qx, qy, qz)."""
    import pose_teacher

    from pbdkit._rotations import quaternion_from_matrix
    from pbdkit.robots import panda

    robot = panda()
    demos = pose_teacher.demonstrations(robot)
    posed = Skill.learn(demos, robot, n_steps=40, n_components=3)
    flat = Skill.learn(demos, robot, n_steps=40, n_components=3, orientation=False)
    pose = pose_teacher.mug_pose(0.6, 0.5, 0.05)
    seven = np.r_[pose[:3, 3], quaternion_from_matrix(pose[:3, :3])]
    return {
        "demos": demos,
        "posed": posed,
        "flat": flat,
        "pose": pose,
        "seven": seven,
        "posed_res": posed.reproduce({"mug": seven}),
        "flat_res": flat.reproduce({"mug": seven}),
    }


def test_constraint_figure_shows_the_orientation_of_an_oriented_object(
    mug: dict[str, Any],
) -> None:
    skill, demos = mug["posed"], mug["demos"]
    assert skill.oriented == ["mug"]
    fig = plot_constraints(skill, demos)
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 6 + 8  # mug: position x3, orientation x3; joints x7 + gripper
    by_label = {ax.get_ylabel(): ax for ax in visible}
    assert [f"R^T(x - p){i} (mug frame) [m]" in by_label for i in (1, 2, 3)] == [True] * 3
    titled = [ax for ax in visible if "orientation" in ax.get_title()]
    assert [ax.get_title() for ax in titled] == [
        "orientation relative to the mug (rad, tangent at the mean)"
    ]
    assert titled[0] is by_label["r1 (mug) [rad]"]
    # Each orientation panel: the demonstrations' rotation vectors, the GMR mean, +- 2 sd.
    data = skill.training_data(demos)["mug"]  # (M, T, 7): t, R^T (x - p), r
    c = skill.constraints()
    for i in range(3):
        ax = by_label[f"r{i + 1} (mug) [rad]"]
        thin = [ln for ln in ax.get_lines() if ln.get_linewidth() < 1]
        assert len(thin) == len(demos)
        for line, demo in zip(thin, data, strict=True):
            np.testing.assert_allclose(line.get_ydata(), demo[:, 4 + i])
        (gmr,) = [ln for ln in ax.get_lines() if ln.get_linewidth() == 2]
        mean = c.task_mean["mug"][:, 3 + i]
        sd = np.sqrt(c.task_cov["mug"][:, 3 + i, 3 + i])
        np.testing.assert_allclose(gmr.get_ydata(), mean, atol=1e-12)
        (band,) = ax.collections[-1:]
        y = band.get_paths()[0].vertices[:, 1]
        assert y.max() == pytest.approx((mean + 2 * sd).max())
        assert y.min() == pytest.approx((mean - 2 * sd).min())


def test_constraint_figure_of_the_position_only_skill_has_no_orientation(
    mug: dict[str, Any],
) -> None:
    # The position-only skill of the same demonstrations: x - o, no orientation panel.
    fig = plot_constraints(mug["flat"], mug["demos"])
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 3 + 8
    labels = [ax.get_ylabel() for ax in visible]
    assert [s for s in labels if "mug" in s] == [f"x{i} - o{i} (mug) [m]" for i in (1, 2, 3)]
    assert not any("orientation" in ax.get_title() or "r1" in ax.get_ylabel() for ax in visible)


def _frame_lines(ax: Any, gid: str) -> list[tuple[Any, np.ndarray, np.ndarray]]:
    """The frame lines of ``ax`` with that gid: (colour, start, end)."""
    out = []
    for line in ax.get_lines():
        if line.get_gid() == gid:
            xyz = np.array(line.get_data_3d(), dtype=float)
            out.append((line.get_color(), xyz[:, 0], xyz[:, 1]))
    return out


def test_3d_figure_draws_the_frames_of_posed_objects_and_of_the_hand(
    mug: dict[str, Any],
) -> None:
    from matplotlib.colors import to_rgb

    from pbdkit.apps._plots import FRAME_COLORS, HAND_FRAME_GID, OBJECT_FRAME_GID

    skill, demos, res = mug["posed"], mug["demos"], mug["posed_res"]
    fig = plot_demonstrations_3d(
        skill, demos, objects={"mug": mug["seven"]}, reproduction=res, hand_frames=4
    )
    left, right = fig.axes
    rgb = [to_rgb(c) for c in FRAME_COLORS]
    assert [int(np.argmax(c)) for c in rgb] == [0, 1, 2]  # x red, y green, z blue
    # One frame per demonstration: x, y, z in red, green, blue along the mug's axes.
    lines = _frame_lines(left, OBJECT_FRAME_GID)
    assert len(lines) == 3 * len(demos)
    for k, demo in enumerate(demos):
        pose = demo.objects["mug"]
        for axis in range(3):
            color, start, end = lines[3 * k + axis]
            assert to_rgb(color) == rgb[axis]
            np.testing.assert_allclose(start, pose[:3, 3])
            np.testing.assert_allclose(end - start, 0.05 * pose[:3, axis], atol=1e-12)
    assert "frames: x red, y green, z blue" in left.get_title()
    # The new pose's frame: its x axis turned by the yaw (0.6 rad) about z.
    lines = _frame_lines(right, OBJECT_FRAME_GID)
    assert len(lines) == 3
    _, start, end = lines[0]
    np.testing.assert_allclose(start, mug["seven"][:3])
    np.testing.assert_allclose((end - start) / 0.05, [np.cos(0.6), np.sin(0.6), 0.0], atol=1e-12)
    # The hand's frame at 4 samples along the path, from the reproduced orientations.
    hand = _frame_lines(right, HAND_FRAME_GID)
    assert len(hand) == 3 * 4
    samples = np.linspace(0, len(res.t) - 1, 4).round().astype(int)
    for s, j in enumerate(samples):
        for axis in range(3):
            color, start, end = hand[3 * s + axis]
            assert to_rgb(color) == rgb[axis]
            np.testing.assert_allclose(start, res.positions[j])
            np.testing.assert_allclose(end - start, 0.05 * res.orientations[j][:, axis])
    # A position-only skill: the objects' frames, and no hand frame (no orientation reproduced).
    fig = plot_demonstrations_3d(
        mug["flat"], demos, objects={"mug": mug["pose"]}, reproduction=mug["flat_res"]
    )
    assert len(_frame_lines(fig.axes[1], OBJECT_FRAME_GID)) == 3
    assert _frame_lines(fig.axes[1], HAND_FRAME_GID) == []


def test_controllers_figure_shows_the_angle_to_an_oriented_target(mug: dict[str, Any]) -> None:
    skill, res = mug["posed"], mug["posed_res"]
    fig = plot_reproductions(skill, {"fused": res})
    # The joints, the hand's x1-x3, the bottom row, and the right axis of the error panel.
    assert len(fig.axes) == skill.robot.n_joints + 3 + 2 + 1
    twin = fig.axes[-1]
    assert twin.get_ylabel() == "[deg] (dashed)"
    (line,) = twin.get_lines()
    np.testing.assert_allclose(line.get_ydata(), np.degrees(res.orientation_errors["mug"]))
    assert "expected pose" in fig.axes[-2].get_title()
    # (A position-only skill's figure has no such axis: test_figures_are_drawn_with_one_...)
