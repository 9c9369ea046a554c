"""Tests of the slot task's world (issue 24): the block and the tray (:mod:`pbdkit.sim._parts`), and
the simulation holding a block instead of a glass (:class:`pbdkit.sim.Simulation`).

The scenes are built from throwaway task specs (never registered) whose ``add_objects`` puts a
block and a tray at given poses; the block is the grasped object.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")

import mujoco
from numpy.typing import NDArray

from pbdkit.robots import katana
from pbdkit.sim import Outcome, PlacementRange, Simulation, TaskSpec, get_task
from pbdkit.sim import _parts as P
from pbdkit.sim._tasks import yaw_of, yaw_pose
from pbdkit.sim._teacher import LIMIT_MARGIN, solve_ik
from pbdkit.vision._color import CBCR_FROM_RGB, cbcr_from_rgb

Float = NDArray[np.float64]

# Elbow-up guess for a top-down grasp (the teacher's branch, the wrist pitched down).
_ELBOW_UP = np.array([0.0, 1.2, -1.8, 0.0, 0.0])
# A posture with the hand raised above the base, out of the cameras' way and off the objects.
_REST = np.array([0.0, 1.6, -1.0, 0.0, 0.0])
DOWN = -math.pi / 2  # tool pitch of a hand pointing down


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _spec(block: Float, tray: Float, *, mocap: bool = False) -> TaskSpec:
    """A task with a block (grasped) and a tray at the given 4x4 poses: posed ranges of one
    placement each, whose poses add_objects hands on to the builders."""

    def add_objects(world: Any, objects: Mapping[str, Float], rng: np.random.Generator) -> None:
        P.add_block(world, objects["block"])
        P.add_tray(world, objects["tray"], mocap=mocap)

    def posed(pose: Float) -> PlacementRange:
        p, yaw = tuple(pose[:3, 3]), yaw_of(pose)
        return PlacementRange.box(p, p, yaw=(yaw, yaw))

    return TaskSpec(
        name="slot_world_test",
        description="A block and a tray.",
        ranges={"block": posed(block), "tray": posed(tray)},
        add_objects=add_objects,
        via_points=lambda objects, rng, speed: [],
        judge=lambda sim, run: Outcome(True, {}),
        grasped="block",
        patches={"block": "block_mark", "tray": "tray_mark"},
    )


def _block(x: float, y: float, yaw: float) -> Float:
    return yaw_pose((x, y, P.BLOCK_HEIGHT), yaw)


def _tray(x: float, y: float, yaw: float) -> Float:
    return yaw_pose((x, y, P.TRAY_RIM_HEIGHT), yaw)


@pytest.fixture
def scene() -> Iterator[Simulation]:
    spec = _spec(_block(0.22, 0.10, math.radians(30)), _tray(0.20, -0.12, math.radians(-40)))
    with Simulation.from_task(spec) as sim:
        sim.set_joints(_REST)
        yield sim


def _bottom_above_floor(block: Float) -> float:
    """Height of the block's bottom above the pocket's floor (m)."""
    return float(block[2, 3] - P.BLOCK_HEIGHT - P.TRAY_FLOOR)


# ---------------------------------------------------------------------------------- geometry
def test_footprint_margin_and_pose_checks() -> None:
    tray = _tray(0.2, -0.1, -0.4)
    for turn in (0.0, math.pi):
        aligned = _block(0.2, -0.1, -0.4 + turn)
        assert P.footprint_margin(aligned, tray) == pytest.approx(P.POCKET_CLEARANCE, abs=1e-12)
    # 1 mm along the tray's x: 1 mm less margin at that end
    shifted = _block(0.2 + 0.001 * math.cos(-0.4), -0.1 + 0.001 * math.sin(-0.4), -0.4)
    assert P.footprint_margin(shifted, tray) == pytest.approx(0.002, abs=1e-12)
    # the footprint leaves the pocket between 5.5 and 6 degrees of relative yaw
    assert P.footprint_margin(_block(0.2, -0.1, -0.4 + math.radians(5.5)), tray) > 0
    assert P.footprint_margin(_block(0.2, -0.1, -0.4 + math.radians(6.0)), tray) < 0
    assert P.footprint_margin(_block(0.2, -0.1, -0.4 - math.radians(10.0)), tray) < -0.002
    tilted = np.eye(4)
    tilted[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    with pytest.raises(ValueError, match="yaw about the vertical"):
        P.add_block(mujoco.MjSpec().worldbody, tilted)
    with pytest.raises(ValueError, match="4x4"):
        P.add_tray(mujoco.MjSpec().worldbody, np.eye(3))
    with pytest.raises(ValueError, match="'a' or 'b'"):
        P.mark_prefix("block", "c")


def test_pocket_is_the_block_footprint_plus_the_clearance(scene: Simulation) -> None:
    m = scene.model
    np.testing.assert_allclose([P.POCKET_LENGTH, P.POCKET_WIDTH], [0.066, 0.026], atol=1e-12)
    # inner faces of the walls, in the tray's frame (geom positions are relative to the body)
    ends = [m.geom(f"tray_wall{i}") for i in (0, 1)]
    sides = [m.geom(f"tray_wall{i}") for i in (2, 3)]
    inner_x = sorted(abs(g.pos[0]) - g.size[0] for g in ends)
    inner_y = sorted(abs(g.pos[1]) - g.size[1] for g in sides)
    np.testing.assert_allclose(inner_x, [P.POCKET_LENGTH / 2] * 2, atol=1e-12)
    np.testing.assert_allclose(inner_y, [P.POCKET_WIDTH / 2] * 2, atol=1e-12)
    box = m.geom(P.block_geom("block"))
    np.testing.assert_allclose(
        2 * box.size, [P.BLOCK_LENGTH, P.BLOCK_WIDTH, P.BLOCK_HEIGHT], atol=1e-12
    )
    # walls reach the rim plane (the tray's point), the floor's top is TRAY_DEPTH below it
    for g in ends + sides:
        assert g.pos[2] + g.size[2] == pytest.approx(0.0, abs=1e-12)
    floor = m.geom("tray_floor")
    assert floor.pos[2] + floor.size[2] == pytest.approx(-P.TRAY_DEPTH, abs=1e-12)
    assert m.body("block").mass[0] == pytest.approx(P.BLOCK_MASS)
    assert m.body_mocapid[m.body("tray").id] == -1  # static unless asked


def test_marks_exist_with_their_colors_and_are_visual_only(scene: Simulation) -> None:
    m = scene.model
    colors = {
        "block_mark_a": P.BLOCK_MARK_A_RGBA,
        "block_mark_b": P.BLOCK_MARK_B_RGBA,
        "tray_mark_a": P.TRAY_MARK_A_RGBA,
        "tray_mark_b": P.TRAY_MARK_B_RGBA,
    }
    poses = scene.object_poses()
    for name, rgba in colors.items():
        g = m.geom(name)
        np.testing.assert_allclose(g.rgba, rgba, atol=1e-6)
        assert g.contype[0] == 0 and g.conaffinity[0] == 0
    # The midpoint of each object's marks is its point; a -> b is its x axis (its yaw).
    mujoco.mj_kinematics(m, scene.data)
    for obj in ("block", "tray"):
        a = scene.data.geom_xpos[m.geom(f"{obj}_mark_a").id]
        b = scene.data.geom_xpos[m.geom(f"{obj}_mark_b").id]
        mid = 0.5 * (a + b) - np.array([0.0, 0.0, P.MARK_THICKNESS / 2])
        np.testing.assert_allclose(mid, poses[obj][:3, 3], atol=1e-9)
        d = b - a
        assert math.atan2(d[1], d[0]) == pytest.approx(yaw_of(poses[obj]), abs=1e-9)
    # Four hues apart from each other and from the red band and the coaster's blue
    # (hue = direction of (Cb, Cr) - 128, degrees).
    hues = {
        k: _rgba_hue(rgba)
        for k, rgba in {
            **colors,
            "red band": (0.9, 0.05, 0.05),
            "coaster": (0.1, 0.25, 0.9),
            "table": (0.78, 0.68, 0.52),
        }.items()
    }
    keys = list(hues)
    for i, a in enumerate(keys):
        for b in keys[i + 1 :]:
            assert abs(_wrap(math.radians(hues[a] - hues[b]))) > math.radians(14), (a, b, hues)


def _rgba_hue(rgba: tuple[float, ...]) -> float:
    """Direction (deg) of a color's (Cb, Cr) - 128: its hue in the chroma plane."""
    cb, cr = CBCR_FROM_RGB @ (255.0 * np.asarray(rgba[:3]))
    return math.degrees(math.atan2(cr, cb))


def test_a_camera_sees_both_marks_of_each_object(scene: Simulation) -> None:
    # Pixels whose chroma points the way of a mark's color (within 12 deg) and is strong: the
    # render's shading scales the chroma, the hue stays.
    for cam in scene.info.cameras:
        cbcr = cbcr_from_rgb(scene.render(cam)) - 128.0
        hue = np.degrees(np.arctan2(cbcr[..., 1], cbcr[..., 0]))
        strong = np.hypot(cbcr[..., 0], cbcr[..., 1]) > 40.0
        for rgba in (
            P.BLOCK_MARK_A_RGBA,
            P.BLOCK_MARK_B_RGBA,
            P.TRAY_MARK_A_RGBA,
            P.TRAY_MARK_B_RGBA,
        ):
            target = _rgba_hue(rgba)
            near = strong & (np.abs((hue - target + 180.0) % 360.0 - 180.0) < 12.0)
            assert near.sum() >= 6, f"{cam}: {near.sum()} pixels of {rgba}"


# ----------------------------------------------------------------------------------- physics
def test_block_rests_on_the_table_at_its_pose() -> None:
    rng = np.random.default_rng(0)
    for _ in range(3):
        r, a = rng.uniform(0.14, 0.26), rng.uniform(-1.0, 1.0)
        pose = _block(r * math.cos(a), r * math.sin(a), rng.uniform(-math.pi / 3, math.pi / 3))
        with Simulation.from_task(_spec(pose, _tray(0.30, -0.30, 0.0))) as sim:
            assert sim.grasped_kind == "block"
            sim.set_joints(_REST)
            np.testing.assert_allclose(sim.object_positions()["block"], pose[:3, 3], atol=1e-12)
            placements = sim.object_placements()  # posed ranges: poses, as the task gives them
            np.testing.assert_allclose(placements["block"], pose, atol=1e-12)
            np.testing.assert_allclose(placements["tray"], _tray(0.30, -0.30, 0.0), atol=1e-12)
            sim.step(1000)  # 2 s
            now = sim.object_poses()["block"]
            np.testing.assert_allclose(now[:3, 3], pose[:3, 3], atol=1e-3)
            assert abs(_wrap(yaw_of(now) - yaw_of(pose))) < math.radians(0.5)
            assert sim.grasped_tilt() < math.radians(0.1)
            np.testing.assert_allclose(sim.grasped_pose(), now, atol=1e-12)
            assert sim.grasped_released() and not sim.grasped_held()


def _drop(sim: Simulation, dx: float, dy: float, yaw_off: float, height: float = 0.005) -> Float:
    """Drop the block, its bottom ``height`` above the rim, over the pocket's centre moved by
    (dx, dy) in the tray's frame, turned by ``yaw_off`` from the tray; its pose 2 s later."""
    tray = sim.object_poses()["tray"]
    p = tray[:3, 3] + tray[:3, :3] @ np.array([dx, dy, height + P.BLOCK_HEIGHT])
    sim.place_object("block", p, yaw=yaw_of(tray) + yaw_off)
    sim.step(1000)
    return sim.object_poses()["block"]


@pytest.mark.parametrize("turn", [0.0, math.pi])
def test_block_dropped_at_the_pockets_yaw_goes_in(scene: Simulation, turn: float) -> None:
    rng = np.random.default_rng(1)
    tray = scene.object_poses()["tray"]
    for height in (0.001, 0.005, 0.005):
        dx, dy = rng.uniform(-0.0015, 0.0015), rng.uniform(-0.0015, 0.0015)
        yaw = turn + rng.uniform(-math.radians(2), math.radians(2))
        block = _drop(scene, dx, dy, yaw, height)
        assert abs(_bottom_above_floor(block)) < 5e-4  # on the pocket's floor
        assert P.footprint_margin(block, tray) > 0  # inside the walls
        assert scene.grasped_tilt() < math.radians(1.0)


@pytest.mark.parametrize("yaw_deg", [10.0, -10.0, 15.0, 190.0])
def test_block_turned_10_degrees_off_cannot_go_in(scene: Simulation, yaw_deg: float) -> None:
    tray = scene.object_poses()["tray"]
    for dx, dy, height in [(0.0, 0.0, 0.005), (0.0015, -0.001, 0.005), (0.0, 0.0, 0.001)]:
        block = _drop(scene, dx, dy, math.radians(yaw_deg), height)
        # It rests on the walls' rim (TRAY_DEPTH above the floor), not inside.
        assert _bottom_above_floor(block) > P.TRAY_DEPTH - 0.001
        assert P.footprint_margin(block, tray) < 0


def test_place_object_keeps_or_sets_a_blocks_yaw_and_turns_a_mocap_tray() -> None:
    spec = _spec(_block(0.22, 0.10, 0.5), _tray(0.20, -0.12, -0.3), mocap=True)
    with Simulation.from_task(spec) as sim:
        sim.set_joints(_REST)
        target = np.array([0.18, 0.12, P.BLOCK_HEIGHT])
        sim.place_object("block", target)
        poses = sim.object_poses()
        np.testing.assert_allclose(poses["block"][:3, 3], target, atol=1e-12)
        assert yaw_of(poses["block"]) == pytest.approx(0.5, abs=1e-9)
        sim.place_object("block", target, yaw=-0.2)
        assert yaw_of(sim.object_poses()["block"]) == pytest.approx(-0.2, abs=1e-9)
        # The mocap tray turns about its point, and slides keeping its yaw.
        centre = sim.object_positions()["tray"]
        sim.place_object("tray", centre, yaw=0.1)
        tray = sim.object_poses()["tray"]
        np.testing.assert_allclose(tray[:3, 3], centre, atol=1e-12)
        assert yaw_of(tray) == pytest.approx(0.1, abs=1e-12)
        moved = centre + np.array([0.01, 0.0, 0.0])
        sim.place_object("tray", moved)
        tray = sim.object_poses()["tray"]
        np.testing.assert_allclose(tray[:3, 3], moved, atol=1e-12)
        assert yaw_of(tray) == pytest.approx(0.1, abs=1e-12)
        with pytest.raises(ValueError, match="yaw"):
            sim.place_object("tray", centre, yaw=math.nan)
    static = _spec(_block(0.22, 0.1, 0.0), _tray(0.2, -0.12, 0.0))
    with Simulation.from_task(static) as sim, pytest.raises(ValueError, match="cannot move"):
        sim.place_object("tray", [0.2, -0.1, P.TRAY_RIM_HEIGHT])


# ------------------------------------------------------------------------------ grasp checks
def test_top_down_reach_of_the_katana() -> None:
    # Hand pointing down (pitch -90 deg), tool point at the block's grasp height: reachable
    # 0.14-0.26 m from the base axis, not at 0.32 m; the hand cannot rise above ~0.12 m.
    robot = katana()
    z = P.BLOCK_HEIGHT + P.BLOCK_GRASP_HEIGHT
    for r in (0.14, 0.20, 0.26):
        q = solve_ik(robot, np.array([r, 0.0, z]), DOWN, 0.0, _ELBOW_UP)
        assert np.all(q > robot.lower + LIMIT_MARGIN) and np.all(q < robot.upper - LIMIT_MARGIN)
    for x in ([0.32, 0.0, z], [0.15, 0.0, 0.14]):
        with pytest.raises(ValueError, match="IK did not reach"):
            solve_ik(robot, np.array(x), DOWN, 0.0, _ELBOW_UP, max_iter=300)


def test_grasp_checks_for_a_block_closed_between_the_fingers() -> None:
    robot = katana()
    x, y, yaw = 0.20, 0.06, math.radians(25)
    spec = _spec(_block(x, y, yaw), _tray(0.18, -0.14, -0.8))
    with Simulation.from_task(spec) as sim:
        start = sim.object_positions()["block"]
        pan = math.atan2(y, x)
        # The fingers close along heading pan + roll + 90 deg: across the block at this roll.
        roll = _wrap(yaw - pan)
        q = _ELBOW_UP.copy()
        q[0] = pan

        def ik(z: float) -> Float:
            nonlocal q
            q = solve_ik(robot, np.array([x, y, z]), DOWN, roll, q)
            return q

        def move(z0: float, z1: float) -> None:
            for z in np.linspace(z0, z1, 50):
                sim.set_targets(ik(float(z)), np.zeros(5))
                sim.step(5)
            sim.step(200)

        grasp = start[2] + P.BLOCK_GRASP_HEIGHT
        sim.set_joints(ik(grasp + 0.04))
        sim.step(300)  # the fingers open
        np.testing.assert_allclose(sim.finger_opening(), [0.04, 0.04], atol=1e-3)
        move(grasp + 0.04, grasp)
        assert sim.grasped_released() and not sim.grasped_held()  # open around the block
        sim.set_gripper(True)
        sim.step(300)
        assert sim.grasped_held() and not sim.grasped_released()
        np.testing.assert_allclose(sim.finger_opening(), [P.BLOCK_WIDTH / 2] * 2, atol=2e-4)
        move(grasp, grasp + 0.04)  # lift 4 cm
        assert sim.grasped_held()
        now = sim.object_positions()["block"]
        np.testing.assert_allclose(now, start + np.array([0.0, 0.0, 0.04]), atol=1e-3)
        sim.refresh()
        np.testing.assert_allclose(
            sim.tool_position() - now, [0.0, 0.0, P.BLOCK_GRASP_HEIGHT], atol=1e-3
        )
        assert abs(_wrap(yaw_of(sim.grasped_pose()) - yaw)) < math.radians(0.5)
        assert sim.grasped_tilt() < math.radians(1.0)
        sim.set_gripper(False)
        sim.step(500)
        assert sim.grasped_released() and not sim.grasped_held()
        np.testing.assert_allclose(sim.object_positions()["block"], start, atol=1e-3)


def test_a_glass_is_still_the_grasped_object_of_the_papers_tasks() -> None:
    with Simulation.from_task(get_task("coaster")) as sim:
        assert sim.grasped_kind == "glass"
        bottom, rot = sim.grasped_frame()
        pose = sim.grasped_pose()
        np.testing.assert_array_equal(pose[:3, 3], bottom)
        np.testing.assert_array_equal(pose[:3, :3], rot)
        positions, poses = sim.object_positions(), sim.object_poses()
        assert list(poses) == list(positions)
        placements = sim.object_placements()  # positions only: the paper's task is not posed
        assert list(placements) == list(positions)
        for name, p in positions.items():
            np.testing.assert_array_equal(placements[name], p)
        for name, p in positions.items():
            np.testing.assert_array_equal(poses[name][:3, 3], p)
            np.testing.assert_array_equal(poses[name][:3, :3], np.eye(3))
