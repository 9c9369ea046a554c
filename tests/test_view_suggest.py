"""Where to demonstrate next, in the browser (issue 39): the ghosts stand where the suggestions
say, turn when an object is brought within the tolerances, and ``pbdkit view --suggest``
suggests off the server's threads, refuses bad options in one line, and shows nothing, with a
line, for a skill that keeps no demonstrations. No browser: the scene's handles are read on
the server."""

from __future__ import annotations

import contextlib
import io
import math
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser import free_port, quiet_viser_server
from synthetic_teacher import bare_skill

from pbdkit._rotations import matrix_from_quaternion, pose_matrix, yaw_of
from pbdkit.skill._skill import Skill
from pbdkit.skill._suggest import Suggestion

viser = pytest.importorskip("viser")

from pbdkit.apps._view_serve import HOST  # noqa: E402
from pbdkit.apps._view_suggest import (  # noqa: E402
    FAINT_OPACITY,
    GHOST_OPACITY,
    MATCH_DISTANCE,
    MATCH_YAW,
    MATCHED_RGB,
    SuggestionGhosts,
    in_place,
    placement_error,
    suggest_settings,
)


def _yaw_pose(position: Any, degrees: float) -> np.ndarray:
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return pose_matrix(position, [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.fixture
def server() -> Iterator[Any]:
    with quiet_viser_server() as srv:
        yield srv


# ----------------------------------------------------------------------------- matching
def test_in_place_within_a_centimetre_and_five_degrees_the_yaw_wrapped() -> None:
    rng = np.random.default_rng(3)
    target = rng.uniform(-0.5, 0.5, 3)
    for _ in range(20):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        assert in_place(target + 0.98 * MATCH_DISTANCE * direction, target)
        assert not in_place(target + 1.02 * MATCH_DISTANCE * direction, target)
    # Yaw: 178 and -179 degrees are 3 apart across the wrap, 178 and 171 are 7.
    at = _yaw_pose(target, 178.0)
    assert placement_error(_yaw_pose(target, -179.0), at) == (0.0, pytest.approx(3.0))
    assert in_place(_yaw_pose(target, -179.0), at)
    assert in_place(_yaw_pose(target, 178.0 - 0.98 * MATCH_YAW), at)
    assert not in_place(_yaw_pose(target, 178.0 - 1.02 * MATCH_YAW), at)
    # A position (a source without orientation) is matched on its position alone; a pose as
    # x, y, z, qw, qx, qy, qz (w first) like the 4x4.
    assert in_place(target, at) and placement_error(target, at)[1] is None
    half = math.radians(-179.0) / 2
    seven = np.r_[target, math.cos(half), 0.0, 0.0, math.sin(half)]
    assert placement_error(seven, at)[1] == pytest.approx(3.0)


# ----------------------------------------------------------------------------- the layer
def test_ghosts_stand_at_the_suggestions_and_turn_when_the_objects_are_in_place(
    server: Any,
) -> None:
    rng = np.random.default_rng(7)
    shown = [
        Suggestion(
            {
                "glass": rng.uniform(0.2, 0.5, 3),
                "tray": _yaw_pose(rng.uniform(0.2, 0.5, 3), float(rng.uniform(-180, 180))),
            },
            score,
        )
        for score in (2.5, 1.25)
    ]
    again: list[int] = []
    put: list[Suggestion] = []
    ghosts = SuggestionGhosts(
        server, ["glass", "tray"], on_again=lambda: again.append(1), on_put=put.append
    )
    ghosts.busy()
    assert ghosts.status == "suggesting ..."
    ghosts.show(shown)
    for i, s in enumerate(shown):
        frame, sphere, _ = ghosts.nodes[(i, "glass")]
        np.testing.assert_allclose(frame.position, s.objects["glass"], atol=1e-12)
        np.testing.assert_allclose(frame.wxyz, [1.0, 0.0, 0.0, 0.0])
        tray = ghosts.nodes[(i, "tray")][0]
        np.testing.assert_allclose(tray.position, s.objects["tray"][:3, 3], atol=1e-12)
        rotation = matrix_from_quaternion(tray.wxyz)
        np.testing.assert_allclose(rotation, s.objects["tray"][:3, :3], atol=1e-9)
        assert sphere.opacity == (GHOST_OPACITY if i == 0 else FAINT_OPACITY)
    assert ghosts.nodes[(0, "glass")][2].text == "next 1 glass (2.50)"
    assert ghosts.nodes[(1, "glass")][2].text == "next 2"
    listed = ghosts.ui_list.content.splitlines()
    assert len(listed) == 2 and "uncertainty 1.25" in listed[1]
    x, y, z = shown[1].objects["glass"]
    assert f"glass at ({x:.3f}, {y:.3f}, {z:.3f}) m" in listed[1]
    yaw = math.degrees(yaw_of(shown[1].objects["tray"]))
    assert f"yaw {yaw:.0f} deg" in listed[1]

    # The glass 8 mm off its ghost is in place, the tray turned 7 degrees is not.
    first = shown[0].objects
    tray = first["tray"]
    turned = _yaw_pose(tray[:3, 3], 7.0)
    turned[:3, :3] = tray[:3, :3] @ turned[:3, :3]
    near = {"glass": first["glass"] + np.array([0.008, 0.0, 0.0]), "tray": turned}
    assert ghosts.match(near) == {"glass": True, "tray": False}
    glass_sphere, glass_label = ghosts.nodes[(0, "glass")][1:]
    assert tuple(glass_sphere.color) == MATCHED_RGB and glass_label.text.endswith(": in place")
    assert tuple(ghosts.nodes[(0, "tray")][1].color) != MATCHED_RGB
    assert "In place: glass." in ghosts.status
    near["tray"] = tray.copy()
    assert ghosts.match(near) == {"glass": True, "tray": True}
    assert "every object in place" in ghosts.status
    # The second suggestion active: matched against it; its ghosts opaque.
    ghosts.select(1)
    assert ghosts.ui_active.value == "next 2" and ghosts.matched == {"glass": False, "tray": False}
    assert ghosts.nodes[(1, "glass")][1].opacity == GHOST_OPACITY
    assert ghosts.nodes[(0, "glass")][1].opacity == FAINT_OPACITY
    ghosts.put()
    assert put == [shown[1]]
    with pytest.raises(ValueError, match=r"suggestion 3 is not shown \(1\.\.2\)"):
        ghosts.select(2)
    # New suggestions replace the ghosts; none at all says why.
    ghosts.show(shown[:1])
    assert sorted(ghosts.nodes) == [(0, "glass"), (0, "tray")] and ghosts.active == 0
    assert ghosts.matched == {"glass": True, "tray": True}  # the last placements, kept
    ghosts.show([])
    assert ghosts.nodes == {} and "within the arm's reach" in ghosts.status
    assert "/suggest/0/glass" not in server.scene._handle_from_node_name
    ghosts.failed(ValueError("ranges names 'cup',\n not an object"))
    assert ghosts.status == "could not suggest: ranges names 'cup', not an object"


# ----------------------------------------------------------------------------- the view
def test_view_suggests_off_its_threads_and_a_dragged_glass_matches(skill: Skill) -> None:
    from pbdkit.apps._cli_suggest import default_ranges
    from pbdkit.apps._view import ViewApp
    from pbdkit.apps._view_serve import served
    from pbdkit.apps._view_suggest import SuggestSettings

    ranges = default_ranges(skill)
    settings = SuggestSettings(ranges, n=2)
    objects = {"glass": np.asarray(skill.demonstrations_[0].objects["glass"])}  # type: ignore[index]
    with served(
        lambda srv: ViewApp(skill, objects, srv, suggest=settings, preview_steps=None),
        port=free_port(),
    ) as view:
        sug = view.suggestions
        assert sug is not None and sug.wait_idle(30.0)
        expected = skill.suggest(ranges, n=2)
        for i, s in enumerate(expected):
            frame = sug.ghosts.nodes[(i, "glass")][0]
            np.testing.assert_allclose(frame.position, s.objects["glass"], atol=1e-12)
        assert sug.ghosts.matched == {"glass": False}
        # Dragged to 6 mm from the first ghost: in place, and said so.
        target = expected[0].objects["glass"]
        view.move_object("glass", target + np.array([0.0, 0.006, 0.0]))
        assert sug.ghosts.matched == {"glass": True}
        assert "every object in place" in sug.ghosts.status
        # "suggest again": other candidates (seed 1), suggested on the worker thread while
        # the page says so (held here until the check).
        with sug.ghosts._lock:
            sug.again()
            assert sug.ghosts.status == "suggesting ..."
        assert sug.wait_idle(30.0)
        again = skill.suggest(ranges, n=2, seed=1)
        frame = sug.ghosts.nodes[(0, "glass")][0]
        np.testing.assert_allclose(frame.position, again[0].objects["glass"], atol=1e-12)
        assert not np.allclose(again[0].objects["glass"], target)
        # "put the objects there": the glass moves to the active ghost, and the plan follows.
        sug.ghosts.put()
        np.testing.assert_array_equal(view.objects["glass"], again[0].objects["glass"])
        assert view.wait_idle(30.0) and view.plan is not None
        np.testing.assert_array_equal(view.plan.objects["glass"], again[0].objects["glass"])
        assert sug.ghosts.matched == {"glass": True}


def test_view_command_suggest_options(skill: Skill, tmp_path: Path, monkeypatch: Any) -> None:
    """Bad options are refused in one line before anything is served; ``--range`` reaches
    the suggestions; a skill file without demonstrations is served without them, with a
    line."""
    from typer.testing import CliRunner

    from pbdkit.apps import _view_serve
    from pbdkit.apps._cli import app

    path = tmp_path / "skill.npz"
    skill.save(path)
    bare = bare_skill(skill)
    old = tmp_path / "v1.npz"
    bare.save(old)
    served: list[Any] = []

    def serve(factory: Any, **_: Any) -> None:  # build the page on a server, then stop
        with contextlib.redirect_stdout(io.StringIO()):
            srv = viser.ViserServer(host=HOST, port=free_port(), verbose=False)
        try:
            page = factory(srv)
            if page.suggestions is not None:
                assert page.suggestions.wait_idle(30.0)
            served.append(page)
            page.close()
        finally:
            with contextlib.redirect_stdout(io.StringIO()):
                srv.stop()

    monkeypatch.setattr(_view_serve, "serve", serve)
    view = ["view", "--no-browser", "--port", str(free_port())]
    cases = [
        (["--skill", str(path), "--suggest", "2", "--range", "glass=1:0,0:1"], "lo <= hi"),
        (["--skill", str(path), "--suggest", "2", "--range", "cup=0:1,0:1"], "not an object"),
        (["--skill", str(path), "--range", "glass=0:1,0:1"], "--range goes with --suggest N"),
        (["--skill", str(path), "--suggest", "101"], "--suggest"),
        (["--task", "coaster", "--suggest", "1"], "apply to --skill"),
    ]
    runner = CliRunner()
    for args, words in cases:
        out = runner.invoke(app, [*view, *args])
        lines = out.output.strip().splitlines()
        assert out.exit_code == 2 and len(lines) == 1 and words in lines[0], (args, out.output)
    assert served == []
    # --range: the ghosts stand at the suggestions inside it (at the demonstrated height).
    out = runner.invoke(app, [*view, "--skill", str(path), "--suggest", "1", "--range",
                              "glass=0.40:0.45,0.20:0.25"])  # fmt: skip
    assert out.exit_code == 0, out.output
    ghosts = served[-1].suggestions.ghosts
    glass = ghosts.suggestions[0].objects["glass"]
    assert 0.40 <= glass[0] <= 0.45 and 0.20 <= glass[1] <= 0.25
    np.testing.assert_allclose(ghosts.nodes[(0, "glass")][0].position, glass, atol=1e-12)
    # Version 1: one line, and the view without suggestions.
    out = runner.invoke(app, [*view, "--skill", str(old), "--suggest", "2"])
    assert out.exit_code == 0, out.output
    lines = out.output.strip().splitlines()
    assert len(lines) == 1 and "keeps no demonstrations" in lines[0], out.output
    assert served[-1].suggestions is None
    said: list[str] = []
    assert suggest_settings(bare, 0, [], say=said.append) is None and said == []


# ----------------------------------------------------------------------------- ros record
def test_the_record_page_draws_the_latest_sample_on_its_thread(
    skill: Skill, tmp_path: Path
) -> None:
    """``pbdkit ros record --suggest --view`` without a graph: the recording loop hands the
    page a sample; the page's thread draws the arm at its joint angles and the glass where
    its source says, and the ghost turns once the glass is in place."""
    from typer.testing import CliRunner

    from pbdkit.apps._cli import app
    from pbdkit.apps._cli_suggest import default_ranges
    from pbdkit.apps._view_record import RecordView
    from pbdkit.apps._view_serve import check_port

    port = free_port()
    ranges = default_ranges(skill)
    page = RecordView(skill, port, ranges=ranges)
    try:
        assert "/suggest_ranges/glass" in page.server.scene._handle_from_node_name
        found = skill.suggest(ranges)
        page.show(found)
        target = found[0].objects["glass"]
        q = skill.demonstrations_[0].joints[-1]  # type: ignore[index]
        off = target + np.array([0.02, 0.0, 0.0])
        page.sample(q, {"glass": off})
        page.draw()
        np.testing.assert_array_equal(page.arm._cfg[page.arm._index], q)
        marker = page.markers["glass"]
        np.testing.assert_allclose(marker.position, off, atol=1e-12)
        assert marker.visible and page.ghosts.matched == {"glass": False}
        page.sample(q, {"glass": target + np.array([0.005, 0.0, 0.0])})
        for _ in range(50):  # the page's thread, at 10 Hz
            if page.ghosts.matched == {"glass": True}:
                break
            threading.Event().wait(0.05)
        assert page.ghosts.matched == {"glass": True}
        assert tuple(page.ghosts.nodes[(0, "glass")][1].color) == MATCHED_RGB
    finally:
        page.close()
    check_port(port)  # let go
    out = CliRunner().invoke(app, ["ros", "record", "--out", str(tmp_path / "d.npz"), "--view"])
    assert out.exit_code == 2 and "--view goes with --suggest SKILL" in out.output
