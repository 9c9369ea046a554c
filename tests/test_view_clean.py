"""Clean output of ``pbdkit view`` (issue 40, the view's part).

- The outcome of a run in physics is the plan's it ran: a drag (or another controller) clears
  it at once, and an outcome that comes after such a change is not shown. The runs are
  stand-ins (:func:`_fake_runs`): what is tested is the page, not the physics.
- A URDF whose mesh files are not found gives one line, not yourdfpy's two per file, and the
  arm is still drawn (the stick figure).

No browser: the scene's nodes and the panel's line are read on the server.
"""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from browser import free_port, quiet_viser_server

from pbdkit.robots._robot import Robot

viser = pytest.importorskip("viser")
pytest.importorskip("yourdfpy")

from pbdkit.apps._view_serve import HOST  # noqa: E402
from pbdkit.apps._view_urdf import UrdfArm, missing_meshes  # noqa: E402
from pbdkit.apps._view_verdict import STALE, Verdict  # noqa: E402

# A run's metrics, as the coaster task's outcome has them.
METRICS = {"placement_error_mm": 0.4, "released": 1.0}
SUCCESS = "fused in physics: **success** (placement (mm) 0.4, released yes)"


# ----------------------------------------------------------------------------- the verdict
def test_verdict_clears_on_a_change_and_drops_an_outcome_that_comes_after_one() -> None:
    shown: list[str] = []
    verdict = Verdict(shown.append)
    token = verdict.start("running ...")
    assert verdict.finish(token, "**success**") and verdict.text == "**success**"
    verdict.changed()  # the plan changes: the outcome was another plan's
    assert verdict.text == "" and shown[-1] == ""
    # A change while a run goes on: its line stays, its outcome is not shown.
    token = verdict.start("running ...")
    verdict.changed()
    assert verdict.text == "running ..."
    assert not verdict.finish(token, "**failure**") and verdict.text == STALE
    # ... but an error is the run's, shown whatever the plan.
    token = verdict.start("running ...")
    verdict.changed()
    assert verdict.finish(token, "run failed: boom", always=True)
    assert shown == [
        "running ...", "**success**", "",
        "running ...", STALE,
        "running ...", "run failed: boom",
    ]  # fmt: skip


@pytest.fixture
def coaster_page(small_task_skill: Callable[..., Any]) -> Iterator[Any]:
    """``pbdkit view --task coaster`` on a small skill (previews of 50 steps), served from a
    thread, its first plan made."""
    from pbdkit.apps._view import ViewApp
    from pbdkit.apps._view_serve import served

    ts = small_task_skill("coaster", 3, 1)
    placement = ts.task.nominal_objects()
    with served(
        lambda srv: ViewApp(ts.skill, placement, srv, task_skill=ts, preview_steps=50),
        port=free_port(),
    ) as app:
        assert app.wait_idle(60.0)
        yield app


def _fake_runs(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """Runs in physics that succeed at once, or, with ``box["hold"]`` set, once
    ``box["go"]`` is set (``box["entered"]`` says the run began); an online one takes the
    moves dragged until then, as the physics loop does, unless ``box["take"]`` is False."""
    from pbdkit.sim import _runs

    box: dict[str, Any] = {"hold": False, "take": True}

    def run(ts: Any, objects: Any, controller: str, disturbance: Any) -> Any:
        if box["hold"]:
            box["entered"].set()
            assert box["go"].wait(30.0)
        if box["take"]:
            with disturbance.lock:
                disturbance.moves.clear()
        outcome = SimpleNamespace(metrics=dict(METRICS))
        return SimpleNamespace(success=True, execution=SimpleNamespace(outcome=outcome))

    monkeypatch.setattr(_runs, "run_controller", run)
    monkeypatch.setattr(_runs, "run_online", run)
    return box


def _hold(box: dict[str, Any]) -> None:
    box.update(hold=True, entered=threading.Event(), go=threading.Event())


def _drag(app: Any, name: str, phase: str, to: np.ndarray | None = None) -> None:
    """The handle of ``name`` moved to ``to`` (None: where it is), as viser reports a drag."""
    handle = app.handles[name]
    if to is not None:
        handle.position = to
    app._dragged(name)(SimpleNamespace(phase=phase))


def test_a_drag_clears_the_verdict_and_an_outcome_for_the_plan_before_is_not_shown(
    coaster_page: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    app = coaster_page
    box = _fake_runs(monkeypatch)
    start = np.array(app.objects["coaster"])
    app.start_run(online=False).join(30.0)
    assert app.result_text == SUCCESS and app.ui_result.content == SUCCESS
    # The handle grabbed and let go where it was: the plan is the same, the outcome stays.
    _drag(app, "coaster", "start")
    _drag(app, "coaster", "end")
    assert app.wait_idle(60.0) and app.result_text == SUCCESS
    # Dragged: cleared at once, before the new plan is made.
    _drag(app, "coaster", "start")
    _drag(app, "coaster", "update", start + np.array([0.02, 0.0, 0.0]))
    assert app.result_text == "" and app.ui_result.content == ""
    _drag(app, "coaster", "end")
    assert app.wait_idle(60.0) and app.result_text == ""
    np.testing.assert_allclose(app.plan.objects["coaster"], start + np.array([0.02, 0.0, 0.0]))
    # A drag while a run goes on: the run keeps its line, and its outcome (for the placement
    # before the drag) is not shown.
    _hold(box)
    thread = app.start_run(online=False)
    assert box["entered"].wait(30.0)
    app.move_object("coaster", start + np.array([0.04, 0.0, 0.0]))
    assert app.result_text == "running in physics (fused) ..."
    box["go"].set()
    thread.join(30.0)
    assert app.result_text == STALE and "success" not in app.ui_result.content
    assert app.last_run is not None and app.last_run.success  # the run itself is kept
    # The next run, on the new plan, shows its outcome; another controller clears it.
    box["hold"] = False
    app.start_run(online=False).join(30.0)
    assert app.result_text == SUCCESS
    app.ui_controller.value = "joint"
    app._controller_changed(None)
    assert app.result_text == ""
    assert app.wait_idle(60.0)


def test_an_online_run_keeps_the_moves_it_took_and_drops_its_outcome_after_one_it_did_not(
    coaster_page: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    app = coaster_page
    box = _fake_runs(monkeypatch)
    start = np.array(app.objects["coaster"])
    online = SUCCESS.replace("in physics", "online")
    # Dragged while the online run goes on, and moved in its physics: its outcome holds.
    _hold(box)
    thread = app.start_run(online=True)
    assert box["entered"].wait(30.0)
    app.move_object("coaster", start + np.array([0.0, 0.02, 0.0]))
    box["go"].set()
    thread.join(30.0)
    assert app.result_text == online
    # Dragged after the run's last step (the move waits, never taken): not its outcome.
    _hold(box)
    box["take"] = False
    thread = app.start_run(online=True)
    assert box["entered"].wait(30.0)
    app.move_object("coaster", start + np.array([0.0, 0.04, 0.0]))
    box["go"].set()
    thread.join(30.0)
    assert app.result_text == STALE
    assert app.wait_idle(60.0)


# ----------------------------------------------------------------------------- the meshes
# Three links in a row, each with a mesh that is nowhere (as an arm's URDF copied without its
# meshes names them), and a tool frame.
ARM = """<?xml version="1.0"?>
<robot name="bare">
  <link name="base">{base}</link>
  <link name="upper">{upper}</link>
  <link name="fore">{fore}</link>
  <link name="tool"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/>
  </joint>
  <joint name="wrist" type="revolute">
    <parent link="fore"/><child link="tool"/><origin xyz="0.25 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/>
  </joint>
</robot>
"""
LINKS = ("base", "upper", "fore")
# A triangle, for a mesh file that is there.
TRIANGLE = "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n"


def _visual(filename: str) -> str:
    return f'<visual><geometry><mesh filename="{filename}"/></geometry></visual>'


def _arm(tmp_path: Path, found: tuple[str, ...] = ()) -> tuple[Path, Robot]:
    """The arm's URDF in ``tmp_path``, its links' meshes under package://, those of ``found``
    beside it (as ``meshes/LINK.obj``)."""
    meshes = {}
    for link in LINKS:
        if link in found:
            (tmp_path / "meshes").mkdir(exist_ok=True)
            (tmp_path / "meshes" / f"{link}.obj").write_text(TRIANGLE)
            meshes[link] = _visual(f"meshes/{link}.obj")
        else:
            meshes[link] = _visual(f"package://bare_description/meshes/{link}.dae")
    path = tmp_path / "bare.urdf"
    path.write_text(ARM.format(**meshes))
    return path, Robot.from_urdf(path, tip="tool")


@pytest.fixture
def server() -> Iterator[Any]:
    with quiet_viser_server() as srv:
        yield srv


def _sticks(arm: UrdfArm) -> np.ndarray:
    return np.asarray(arm.sticks.points)


def test_a_urdf_whose_meshes_are_not_found_says_so_in_one_line_and_draws_the_arm(
    tmp_path: Path, server: Any, caplog: pytest.LogCaptureFixture
) -> None:
    path, robot = _arm(tmp_path)
    with caplog.at_level(logging.DEBUG):
        arm = UrdfArm(server, robot, path)
    said = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(said) == 1, caplog.text
    assert said[0].name == "pbdkit.apps._view_urdf"
    assert said[0].getMessage() == (
        f"{str(path)!r}: meshes not found (3 files, e.g. "
        "'package://bare_description/meshes/base.dae'): the arm is drawn as a stick figure"
    )
    assert "Unable to resolve filename" not in caplog.text
    assert "Can't find" not in caplog.text
    # The stick figure: a line per joint between links apart, the arm at the posture.
    q = np.array([0.3, -0.5, 0.2])
    arm.show(q)
    assert "/arm_sticks" in server.scene._handle_from_node_name
    np.testing.assert_array_equal(arm._cfg[arm._index], q)
    tool = robot.fk(q)
    np.testing.assert_allclose(_sticks(arm)[-1, 1], tool, atol=1e-6)  # float32 points
    assert _sticks(arm).shape == (3, 2, 3)


def test_some_meshes_found_and_what_else_yourdfpy_says_goes_out(
    tmp_path: Path, server: Any, caplog: pytest.LogCaptureFixture
) -> None:
    path, robot = _arm(tmp_path, found=("upper",))
    with caplog.at_level(logging.WARNING):
        arm = UrdfArm(server, robot, path)
    assert [r.getMessage() for r in caplog.records] == [
        f"{str(path)!r}: 2 of its 3 mesh files not found (e.g. "
        "'package://bare_description/meshes/base.dae'): the arm is drawn without them, and "
        "as a stick figure"
    ]
    assert arm.viser_urdf is not None
    nodes = list(server.scene._handle_from_node_name)
    assert any(n.startswith("/arm/") and "upper" in n for n in nodes), nodes  # the one found
    # A link yourdfpy warns of for another reason: that warning is not held back.
    text = path.read_text().replace('<link name="tool"/>', '<link name="tool"/><link name="x"/>')
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        UrdfArm(server, robot, text)
    messages = [r.getMessage() for r in caplog.records]
    assert [r.name for r in caplog.records] == ["yourdfpy.urdf", "pbdkit.apps._view_urdf"]
    assert messages[0].startswith("x "), messages
    # (Text: its meshes are looked up from the working directory, where none is.)
    assert messages[1].startswith("the URDF: meshes not found (3 files, e.g. "), messages


def test_the_line_reads_for_one_file_and_the_command_prints_only_it(tmp_path: Path) -> None:
    one = missing_meshes(["a.stl"], 1, "the skill's URDF")
    assert one == (
        "the skill's URDF: meshes not found (1 file: 'a.stl'): the arm is drawn as a stick figure"
    )
    # What a user sees: Python's last-resort handler prints the warning alone on stderr.
    path, _ = _arm(tmp_path)
    script = f"""
import contextlib, io
import viser
from pbdkit.robots._robot import Robot
from pbdkit.apps._view_urdf import UrdfArm
with contextlib.redirect_stdout(io.StringIO()):
    server = viser.ViserServer(host="{HOST}", port={free_port()}, verbose=False)
try:
    UrdfArm(server, Robot.from_urdf({str(path)!r}, tip="tool"), None)
finally:
    with contextlib.redirect_stdout(io.StringIO()):
        server.stop()
"""
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 0, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("the skill's URDF: meshes not found (3 files"), (
        out.stderr
    )
