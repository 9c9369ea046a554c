"""``pbdkit view``: the planner's pieces against independent computations, the command's bad
input and signals, and the page in a real browser (Debian's chromium through playwright,
software WebGL), where moving the glass from the page's own fields changes the plan to what
``skill.reproduce`` gives for that placement."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser import CHROMIUM, free_port, launch

from pbdkit._rotations import matrix_from_quaternion
from pbdkit.apps._view_plan import (
    LatestWins,
    carry_transform,
    coarse_skill,
    ellipsoid_pose,
    make_plan,
    step_gaussians,
    typical_placements,
)
from pbdkit.apps._view_serve import HOST, check_port
from pbdkit.skill._skill import Skill


def _port(port: int) -> list[str]:
    return ["--port", str(port), "--no-browser"]


# ----------------------------------------------------------------------------- pieces
def test_latest_wins_runs_only_the_newest_waiting_request() -> None:
    """While one request runs, three more arrive: the first two are replaced (never run), the
    last runs; latencies are counted from each run request's arrival."""
    started, release = threading.Event(), threading.Event()
    ran: list[int] = []

    def work(r: int) -> None:
        ran.append(r)
        if r == 0:
            started.set()
            release.wait(5.0)

    lw: LatestWins[int] = LatestWins(work)
    try:
        lw.submit(0)
        assert started.wait(5.0)
        for r in (1, 2, 3):
            lw.submit(r)
        release.set()
        assert lw.wait_idle(5.0)
        assert ran == [0, 3]
        assert lw.superseded == 2
        assert len(lw.latencies) == 2 and all(x >= 0 for x in lw.latencies)
    finally:
        lw.close()


def test_latest_wins_reports_an_error_and_goes_on() -> None:
    errors: list[BaseException] = []

    def work(r: int) -> None:
        if r == 1:
            raise ValueError("bad placement")

    lw: LatestWins[int] = LatestWins(work, on_error=errors.append)
    try:
        lw.submit(1)
        assert lw.wait_idle(5.0)
        lw.submit(2)
        assert lw.wait_idle(5.0)
        assert [str(e) for e in errors] == ["bad placement"]
        assert len(lw.latencies) == 1
    finally:
        lw.close()


def test_a_port_in_use_is_refused_in_one_line() -> None:
    with socket.socket() as s:
        s.bind((HOST, 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(ValueError, match=f"port {port} on 127.0.0.1 is in use"):
            check_port(port)
    check_port(port)  # free again
    with pytest.raises(ValueError, match=r"1\.\.65535"):
        check_port(70000)


def test_ellipsoid_axes_and_turn_rebuild_the_covariance() -> None:
    """Semi-axes a and rotation R of the n-sd ellipsoid: R diag(a / n)^2 R^T is the covariance
    (seeded random covariances, including a near-degenerate one)."""
    rng = np.random.default_rng(0)
    for scale in (1e-2, 1e-4):
        a = rng.normal(size=(3, 3))
        cov = scale * (a @ a.T) + 1e-9 * np.eye(3)
        axes, wxyz = ellipsoid_pose(cov, n_sd=2.0)
        rot = matrix_from_quaternion(wxyz)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        rebuilt = rot @ np.diag((axes / 2.0) ** 2) @ rot.T
        np.testing.assert_allclose(rebuilt, cov, atol=1e-12 + 1e-9 * scale)


def test_plan_matches_reproduce_and_its_driving_constraint(skill: Skill) -> None:
    objects = {"glass": np.array([0.42, 0.05, 0.03])}
    plan = make_plan(skill, objects, "fused", None)
    res = skill.reproduce(objects)
    np.testing.assert_array_equal(plan.end, res.positions[-1])
    np.testing.assert_array_equal(plan.result.joints, res.joints)
    shares = np.stack([res.influence[k] for k in res.influence], axis=1)
    names = list(res.influence)
    assert plan.driving == [names[i] for i in shares.argmax(axis=1)]
    assert len(set(plan.driving)) == 2  # the joint space and the glass take turns
    np.testing.assert_array_equal(plan.times, skill.times(res))


def test_gaussians_at_a_step_are_the_constraints_in_the_world(skill: Skill) -> None:
    """The object's Gaussian at step k is Constraints.world_task's target (the hand where the
    constraint expects it); the joint-space one is the forward kinematics of its mean posture
    with J S J^T, against a finite-difference Jacobian."""
    objects = {"glass": np.array([0.40, -0.02, 0.03])}
    plan = make_plan(skill, objects, "fused", None)
    c = plan.constraints
    lead = int(np.count_nonzero(plan.result.lead_in))
    k = c.n_steps // 2
    g = step_gaussians(plan, k + lead)
    world = c.world_task("glass", objects["glass"])
    np.testing.assert_allclose(g["glass"][0], world.position[k], atol=1e-12)
    np.testing.assert_allclose(g["glass"][1], np.linalg.inv(world.precision[k]), rtol=1e-8)
    q = c.joint_mean[k]
    eps = 1e-6
    jac = np.stack(
        [
            (skill.robot.fk(q + eps * e) - skill.robot.fk(q - eps * e)) / (2 * eps)
            for e in np.eye(len(q))
        ],
        axis=1,
    )
    np.testing.assert_allclose(g["joint"][0], skill.robot.fk(q), atol=1e-12)
    np.testing.assert_allclose(g["joint"][1], jac @ c.joint_cov[k] @ jac.T, atol=1e-10)


def test_typical_placement_is_near_the_demonstrations(skill: Skill, demos: Any) -> None:
    """A skill file keeps no placements; the view starts where its constraints put the object
    on average: within 2 cm of the demonstrations' mean glass, whose spread is larger."""
    placed = typical_placements(skill)["glass"]
    glasses = np.array([d.objects["glass"] for d in demos])
    mean = glasses.mean(axis=0)
    spread = np.linalg.norm(glasses - mean, axis=1).mean()
    assert np.linalg.norm(placed - mean) < 0.02 < spread


def test_typical_pose_of_an_oriented_skill_is_the_demonstrations_mean(
    small_task_skill: Callable[..., Any],
) -> None:
    """For the slot's pose skill (3 demonstrations, yaws 60 degrees apart): each object's
    typical pose is within 1 cm and 6 degrees of the demonstrations' mean position and yaw,
    well inside their spread."""
    from pbdkit.sim._tasks import yaw_of

    ts = small_task_skill("slot", 3, 1)
    placed = typical_placements(ts.skill)
    assert {k: v.shape for k, v in placed.items()} == {"block": (4, 4), "tray": (4, 4)}
    for name, pose in placed.items():
        poses = [d.objects[name] for d in ts.demos]
        mean = np.mean([p[:3, 3] for p in poses], axis=0)
        yaws = np.array([yaw_of(p) for p in poses])
        mean_yaw = math.atan2(np.sin(yaws).mean(), np.cos(yaws).mean())
        assert np.linalg.norm(pose[:3, 3] - mean) < 0.01
        off = abs(math.degrees(math.remainder(yaw_of(pose) - mean_yaw, 2 * math.pi)))
        assert off < 6.0 < math.degrees(np.ptp(yaws)) / 4
        np.testing.assert_allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-9)


def test_coarse_skill_has_the_full_skills_constraints_at_the_same_moments(
    robot: Any, demos: Any
) -> None:
    """201 steps and 51: every 4th step of the full skill is a step of the coarse one, and
    GMR gives the same constraints there (the time axis is only rescaled)."""
    full = Skill.learn(demos, robot, n_steps=201, random_state=0)
    coarse = coarse_skill(full, 51)
    a, b = full.constraints(), coarse.constraints()
    np.testing.assert_allclose(b.joint_mean, a.joint_mean[::4], atol=1e-9)
    np.testing.assert_allclose(b.joint_cov, a.joint_cov[::4], rtol=1e-7, atol=1e-14)
    np.testing.assert_allclose(b.task_mean["glass"], a.task_mean["glass"][::4], atol=1e-9)
    np.testing.assert_allclose(b.task_cov["glass"], a.task_cov["glass"][::4], rtol=1e-7)
    assert coarse.duration == full.duration and coarse.n_steps == 51
    # The same duration in fewer steps; the hand ends where the full plan's does (within 2 mm).
    objects = {"glass": np.array([0.42, 0.05, 0.03])}
    end_full = full.reproduce(objects).positions[-1]
    end_coarse = coarse.reproduce(objects).positions[-1]
    assert np.linalg.norm(end_full - end_coarse) < 0.002
    with pytest.raises(ValueError, match="n_steps"):
        coarse_skill(full, 202)


def test_the_plan_carries_the_glass_onto_the_coaster(small_task_skill: Callable[..., Any]) -> None:
    """The page draws the grasped glass moving with the hand from the grasp to the release:
    untouched before, rigid with the hand while held, let go on the coaster (within 15 mm of
    it across the table), and left there after."""
    ts = small_task_skill("coaster", 3, 1)
    objects = ts.task.nominal_objects()
    plan = make_plan(ts.skill, objects, "fused", None)
    closed = np.flatnonzero(plan.result.gripper)
    grasp, last = int(closed[0]), int(closed[-1])
    robot = ts.skill.robot
    assert carry_transform(robot, plan, grasp - 1) is None
    np.testing.assert_allclose(carry_transform(robot, plan, grasp), np.eye(4), atol=1e-12)
    glass = np.append(objects["glass"], 1.0)
    reach = np.linalg.norm(robot.fk(plan.result.joints[grasp]) - objects["glass"])
    for k in (grasp + 5, (grasp + last) // 2, last):
        carried = carry_transform(robot, plan, k) @ glass
        hand = robot.fk(plan.result.joints[k])
        assert np.linalg.norm(hand - carried[:3]) == pytest.approx(reach, abs=1e-9)
    let_go = (carry_transform(robot, plan, last) @ glass)[:3]
    assert np.linalg.norm(let_go[:2] - objects["coaster"][:2]) < 0.015
    after = carry_transform(robot, plan, len(plan.times) - 1)
    np.testing.assert_allclose(after @ glass, carry_transform(robot, plan, last) @ glass)


# ----------------------------------------------------------------------------- the command
def _pbdkit(*args: str, **kwargs: Any) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pbdkit", *args],
        capture_output=True,
        text=True,
        timeout=120,
        **kwargs,
    )


def test_view_command_refuses_bad_input_in_one_line(skill: Skill, tmp_path: Path) -> None:
    path = tmp_path / "skill.npz"
    skill.save(path)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a skill")
    scene = tmp_path / "scene.yaml"
    scene.write_text("shapes:\n  - {type: cone, radius: 0.1, pose: [0, 0, 0]}\n")
    with socket.socket() as s:
        s.bind((HOST, 0))
        s.listen()
        taken = str(s.getsockname()[1])
        cases = [
            (["view", "--skill", str(path), "--port", taken, "--no-browser"], "is in use"),
            (["view", "--no-browser"], "give --task or --skill"),
            (["view", "--task", "coaster", "--skill", str(path)], "give --task or --skill"),
            (["view", "--skill", str(bad), "--port", str(free_port())], "bad.npz"),
            (["view", "--skill", str(tmp_path / "none.npz")], "none.npz"),
            (["view", "--skill", str(path), "--object", "mug=0,0,0"], "not objects of"),
            (["view", "--skill", str(path), "--scene", str(scene)], "scene.yaml"),
            (["view", "--task", "coaster", "--scene", str(scene)], "apply to --skill"),
        ]
        for args, words in cases:
            out = _pbdkit(*args)
            assert out.returncode == 2, (args, out.stderr)
            lines = out.stderr.strip().splitlines()
            assert len(lines) == 1 and words in lines[0], (args, out.stderr)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_view_command_serves_and_stops_cleanly_on_a_signal(
    skill: Skill, tmp_path: Path, sig: signal.Signals
) -> None:
    path = tmp_path / "skill.npz"
    skill.save(path)
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "pbdkit", "view", "--skill", str(path), *_port(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "COLUMNS": "200"},
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert f"serving http://127.0.0.1:{port}" in line, line
        with urllib.request.urlopen(f"http://{HOST}:{port}", timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        proc.send_signal(sig)
        rest = proc.communicate(timeout=30)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, rest
    assert "Traceback" not in rest
    check_port(port)  # released


# ----------------------------------------------------------------------------- the page
@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed (make system-deps)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as p:
        b = launch(p)
        yield b
        b.close()


@pytest.fixture(scope="module")
def coaster_view(small_task_skill: Callable[..., Any]) -> Iterator[Any]:
    """``pbdkit view --task coaster`` on a small skill (previews of 50 steps), served from a
    thread: (task skill, {"app": the app}, port)."""
    pytest.importorskip("viser")
    from pbdkit.apps._view import ViewApp
    from pbdkit.apps._view_serve import served

    ts = small_task_skill("coaster", 3, 1)
    placement = ts.task.nominal_objects()
    port = free_port()
    with served(
        lambda srv: ViewApp(ts.skill, placement, srv, task_skill=ts, preview_steps=50), port=port
    ) as app:
        yield ts, {"app": app}, port
    check_port(port)  # the server let it go


def _field(page: Any, label: str) -> Any:
    """The (first) input of the panel row labelled ``label`` (viser's text fields do not tie
    their label to the input by id)."""
    row = f"//label[normalize-space()='{label}']/ancestor::div[contains(@class, 'Flex-root')][1]"
    return page.locator(f"xpath={row}//input").first


def _wait_value(page: Any, label: str, done: Callable[[str], bool], timeout: float = 60) -> str:
    """Poll the field ``label`` until ``done(value)`` (the page re-renders its inputs)."""
    deadline = time.monotonic() + timeout
    while True:
        field = _field(page, label)
        value = str(field.input_value()) if field.count() else ""
        if done(value):
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"{label!r} still reads {value!r} after {timeout} s")
        time.sleep(0.1)


def _pixels(page: Any) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), dtype=np.int16)


def test_page_shows_the_arm_and_objects_and_follows_a_moved_glass(
    browser: Any, coaster_view: Any, tmp_path: Path
) -> None:
    ts, box, port = coaster_view
    app = box["app"]
    assert app.wait_idle(30)
    page = browser.new_page(viewport={"width": 1200, "height": 800})
    outside: list[str] = []
    local = (f"http://{HOST}", f"ws://{HOST}", "data:", "blob:")
    page.on("request", lambda r: None if r.url.startswith(local) else outside.append(r.url))
    page.goto(f"http://{HOST}:{port}")
    page.wait_for_selector("canvas", timeout=60_000)
    before = _wait_value(page, "hand at the end (mm)", lambda v: len(v) > 0)
    time.sleep(2.0)  # the first frames
    shown = _pixels(page)
    # The scene is drawn: the arm and the objects (MuJoCo's bodies), taken away and put back.
    nodes = list(app._draw_world._nodes.values())
    for node in nodes:
        node.visible = False
    app.server.flush()
    time.sleep(1.5)
    hidden = _pixels(page)
    for node in nodes:
        node.visible = True
    app.server.flush()
    canvas = (slice(100, 700), slice(0, 850))  # left of the panel
    changed = np.abs(shown[canvas] - hidden[canvas]).sum(axis=2) > 60
    assert changed.mean() > 0.02, changed.mean()  # the bodies cover a part of the view
    assert shown[canvas].std() > 10  # not a blank canvas

    # Move the glass from the page: its x field, as a user types it.
    x_field = _field(page, "glass (m)")
    new = np.array(app.objects["glass"])
    new[0] = round(new[0] - 0.03, 3)
    x_field.fill(f"{new[0]:.3f}")
    x_field.press("Enter")
    deadline = time.monotonic() + 30
    while abs(app.objects["glass"][0] - new[0]) > 1e-12 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert app.wait_idle(30)
    after = _wait_value(page, "hand at the end (mm)", lambda v: v != before, timeout=30)
    moved = {**ts.task.nominal_objects(), "glass": new}
    expected = 1e3 * ts.skill.reproduce({k: moved[k] for k in ts.skill.object_names}).positions[-1]
    shown_end = np.array([float(v) for v in after.split(",")])
    np.testing.assert_allclose(shown_end, expected, atol=0.051)  # shown to 0.1 mm
    assert np.abs(shown_end - np.array([float(v) for v in before.split(",")])).max() > 0.5
    page.screenshot(path=str(tmp_path / "view.png"))
    assert outside == []  # nothing fetched from the network
    page.close()


def test_drag_previews_while_held_and_plans_in_full_at_the_release(coaster_view: Any) -> None:
    """While a handle is held the plans are previews (50 steps here); its release plans in
    full; a preview finished after the release is followed by a full plan: the page never
    rests on a preview."""
    ts, box, _ = coaster_view
    app = box["app"]
    assert app.wait_idle(30)
    start = np.array(app.objects["coaster"])
    try:
        app.hold("coaster", True)
        app.move_object("coaster", start + np.array([0.01, 0.0, 0.0]), preview=True)
        assert app.wait_idle(30)
        assert app.plan.preview and len(app.plan.skill.constraints().t) == 50
        assert "preview" in app.ui_status.content
        app.hold("coaster", False)
        app.move_object("coaster", start + np.array([0.02, 0.0, 0.0]))
        assert app.wait_idle(30)
        assert not app.plan.preview and app.plan.skill is ts.skill
        # A late preview (thread-pool order): nothing is held, so a full plan follows it (it
        # is queued before the preview's work ends: wait_idle covers both).
        app.move_object("coaster", start + np.array([0.03, 0.0, 0.0]), preview=True)
        assert app.wait_idle(30)
        assert list(app.planner.kinds)[-2:] == ["preview", "full"]
        assert not app.plan.preview
        np.testing.assert_allclose(app.plan.objects["coaster"], start + np.array([0.03, 0, 0]))
    finally:
        app.move_object("coaster", start)
        app.wait_idle(30)


@pytest.mark.slow
def test_online_run_follows_an_object_dragged_while_the_arm_moves(coaster_view: Any) -> None:
    """The "online" button: the controller runs in MuJoCo at the wall clock's pace; the coaster
    dragged 3 cm while the arm moves is moved in the physics and the controller is told (its
    commands' object positions end at the new place); the page shows the outcome."""
    _, box, _ = coaster_view
    app = box["app"]
    assert app.wait_idle(30)
    start = np.array(app.objects["coaster"])
    moved = start + np.array([0.0, 0.03, 0.0])
    try:
        thread = app.start_run(online=True)
        time.sleep(1.0)  # the arm is on its way to the glass
        assert thread.is_alive()
        with pytest.raises(ValueError, match="a run is going on"):
            app.start_run(online=False)
        app.move_object("coaster", moved)
        thread.join(timeout=120)
        assert not thread.is_alive()
        run = app.last_run
        told = run.online.objects["coaster"]
        np.testing.assert_allclose(told[0], start, atol=1e-9)
        np.testing.assert_allclose(told[-1], moved, atol=1e-6)  # the truth, at 15 Hz
        world = run.execution.objects["coaster"]
        np.testing.assert_allclose(world[-1], moved, atol=1e-6)  # moved in the physics
        verdict = "success" if run.success else "failure"
        assert f"fused online: **{verdict}**" in app.result_text
    finally:
        app.move_object("coaster", start)
        app.wait_idle(30)


def test_the_view_draws_a_scene_avoids_it_and_marks_where_the_arm_comes_near(
    skill: Skill,
) -> None:
    # Issue 38: a box at the mid-carry of the fused plan. The view's fused plan keeps clear of
    # it (as skill.reproduce with the scene does), the box is drawn, and the mark shows at
    # the step nearest the box (within the margin), not at the start.
    pytest.importorskip("viser")
    from pbdkit.apps._view import ViewApp
    from pbdkit.apps._view_scene import CONTACT_RGB, NEAR_RGB
    from pbdkit.apps._view_serve import served
    from pbdkit.collision import Box, Scene
    from pbdkit.reproduction._avoid import TOLERANCE

    objects = typical_placements(skill)
    res = skill.reproduce(objects)
    closed = np.flatnonzero(res.gripper[:-1])
    speed = np.linalg.norm(np.diff(res.positions, axis=0), axis=1)
    box = Scene([Box((0.06, 0.06, 0.06), res.positions[closed[np.argmax(speed[closed])]], "box")])
    with served(lambda srv: ViewApp(skill, objects, srv, scene=box), port=free_port()) as view:
        assert view.wait_idle(60.0)
        plan = view.plan
        expected = skill.reproduce(objects, scene=box)
        np.testing.assert_allclose(plan.result.joints, expected.joints, atol=1e-12)
        assert plan.result.collisions == [] and "Clearance at least" in view.ui_status.content
        # The clearance drives some steps of the path: drawn in its own colour (it had none,
        # and the plan was not drawn: KeyError 'clearance').
        assert "clearance" in plan.driving and view.colors["clearance"] == (127, 127, 127)
        assert view.scene.avoids and "/scene/box" in view.server.scene._handle_from_node_name
        # Kept clear of it: the margin within the passes' tolerance, so at the nearest step the
        # mark is orange (within the margin) or hidden, never red.
        kept = float(np.min(plan.result.clearance))
        assert kept > 0.02 - TOLERANCE
        view._show_step(int(np.argmin(plan.result.clearance)))
        assert view.scene.mark.visible == (kept < 0.02)
        if kept < 0.02:
            assert tuple(view.scene.mark.color) == NEAR_RGB and "box" in view.scene.label.text
        # The joint-space controller does not avoid (checked only): it goes through the box,
        # and the mark shows red where it does, on the arm near the hand.
        view.ui_controller.value = "joint"
        view._controller_changed(None)
        assert view.wait_idle(60.0) and view.plan is not None and view.plan.controller == "joint"
        plan = view.plan
        assert plan.result.collisions and "In contact: " in view.ui_status.content
        near = int(np.argmin(plan.result.clearance))
        view._show_step(near)
        assert view.scene.mark.visible and "box" in view.scene.label.text
        assert tuple(view.scene.mark.color) == CONTACT_RGB
        hand = skill.robot.fk(plan.result.joints[near])
        assert np.linalg.norm(np.asarray(view.scene.mark.position) - hand) < 0.25
        view._show_step(0)
        assert not view.scene.mark.visible
