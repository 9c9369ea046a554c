"""The paper's figures: they are drawn, and what their captions claim holds in the data they show
(the glass-relative constraint is tight while grasping, the coaster-relative one while placing;
in the basin task the pouring gesture is a joint-space constraint)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from pbdkit.plots import (
    figure_png,
    plot_constraints,
    plot_demonstrations_3d,
    plot_reproductions,
    space_data,
)
from pbdkit.robots import katana
from pbdkit.sim.teacher import teach
from pbdkit.skill import Skill

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


def test_basin_glass_matters_while_grasping_not_while_pouring(basin: tuple[Skill, list]) -> None:
    skill, _ = basin
    c = skill.constraints()
    grasp, _ = _grasp_release(skill)
    glass = np.sqrt(np.trace(c.task_cov["glass"], axis1=1, axis2=2))
    assert glass[grasp] < 0.5 * glass[-1]


def test_basin_pouring_gesture_is_tight_in_joint_space_with_enough_components() -> None:
    # The pouring roll is the same in every demonstration. With the default BIC the joint space
    # gets K = 3, too few to follow the gesture (its roll std at the end is ~0.3 rad); with
    # bic_samples_per_sequence=50 (K = 7) the model captures it: the paper's Fig. 5 finding.
    demos = teach("basin", 5, seed=0)
    skill = Skill.learn(demos, katana(), n_steps=N_STEPS, bic_samples_per_sequence=50)
    c = skill.constraints()
    assert skill.n_components["joint"] >= 5
    assert np.sqrt(c.joint_cov[-1, 4, 4]) < 0.05  # rad
    assert abs(c.joint_mean[-1, 4] - np.mean([d.joints[-1, 4] for d in demos])) < 0.1


def test_figures_are_drawn_with_one_panel_per_dimension(coaster: tuple[Skill, list]) -> None:
    skill, demos = coaster
    data = space_data(skill, demos)
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
    labels = fig6.axes[0].get_legend_handles_labels()[1]
    assert labels == [
        "fused (all constraints)",
        "joint space only",
        "task space only (glass)",
        "task space only (coaster)",
    ]
    figure_png(fig6)


def test_figures_leave_the_users_matplotlib_backend_alone() -> None:
    # A Jupyter session keeps its inline backend: plotting must not call matplotlib.use.
    import subprocess
    import sys

    code = (
        "import matplotlib; matplotlib.use('svg'); import numpy as np\n"
        "from pbdkit.plots import figure_png, plot_gmr_tube\n"
        "from matplotlib.figure import Figure\n"
        "fig = Figure(); ax = fig.subplots()\n"
        "t = np.linspace(0, 1, 5); plot_gmr_tube(ax, t, t, 0.1 + 0 * t)\n"
        "png = figure_png(fig)\n"
        "assert png[:4] == b'\\x89PNG', png[:4]\n"
        "from pbdkit import GMM\n"
        "from pbdkit.plots import plot_lasa_summary\n"
        "x = np.column_stack([t, t, t])\n"
        "gmm = GMM.from_params([1.0], [[0.5, 0.5, 0.5]], [np.eye(3)])\n"
        "m, c = gmm.regress(t[:, None])\n"
        "figure_png(plot_lasa_summary('demo', t, [x[:, 1:]], gmm, m, c))\n"
        "print(matplotlib.get_backend())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "svg"
