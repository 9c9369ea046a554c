"""Hostile inputs, fourth pass (issue 36), ``pbdkit view``: items 1, 7, 10 and 18's view part.

- 1: ``--object NAME=x,y,z,qw,qx,qy,qz`` failed for every pose with numpy's "operands could not
  be broadcast"; a pose is now checked as a reproduction checks it (a one-line error naming
  --object and the object) and the page plans and draws with it.
- 7: a Ctrl+C while the view started could be lost (trimesh, imported by yourdfpy, catches
  ``BaseException`` around its optional imports) and the command went on to serve; a SIGINT
  at each point of start-up now ends it.
- 10: ``--robot FILE`` with a file that is not a URDF printed yourdfpy's TypeError traceback,
  and ``--robot NAME`` of an arm with another number of joints was silently ignored.
- 18: a NaN the run or the plan has no value for never reaches the page as "nan".

The skill is a small Panda pose skill (``tests/pose_teacher.py``: a mug grasped by its handle,
its constraint oriented), learned once for the module.
"""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser import free_port
from typer.testing import CliRunner

from pbdkit._rotations import exp_map, pose_matrix
from pbdkit.apps._cli import app
from pbdkit.robots import panda
from pbdkit.skill._skill import Skill

pytest.importorskip("viser")
pytest.importorskip("yourdfpy")

# x, y, z, qw, qx, qy, qz: the mug turned 0.2 rad about the vertical.
MUG_POSE = (0.5, 0.05, 0.0, math.cos(0.1), 0.0, 0.0, math.sin(0.1))


@pytest.fixture(scope="module")
def mug_skill(tmp_path_factory: pytest.TempPathFactory) -> tuple[Skill, Path]:
    """Three demonstrations of 24 samples, a grid of 30 steps: (skill, its file)."""
    import pose_teacher

    robot = panda()
    rng = np.random.default_rng(0)
    demos = [pose_teacher.demonstration(robot, rng, math.radians(y), n=24)[0] for y in (-40, 0, 40)]
    skill = Skill.learn(demos, robot, n_steps=30, random_state=0)
    path = tmp_path_factory.mktemp("view") / "mug.npz"
    skill.save(path)
    return skill, path


def _view(args: list[str], serve: Callable[..., None]) -> Any:
    """``pbdkit view --no-browser ARGS`` in this process, with ``serve`` in place of the real
    one (which serves until a signal)."""
    from pbdkit.apps import _view_serve

    mp = pytest.MonkeyPatch()
    mp.setattr(_view_serve, "serve", serve)
    try:
        return CliRunner().invoke(app, ["view", "--no-browser", *args])
    finally:
        mp.undo()


def _never_served(factory: Any, **kwargs: Any) -> None:
    raise AssertionError("bad input reached the server")


def _refused(result: Any, *words: str) -> None:
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and all(w in lines[0] for w in words), result.output


def _served_app(args: list[str], check: Callable[[Any], None]) -> None:
    """Run the command; once the page is served, ``check(app)`` runs on it and the server
    stops."""
    from pbdkit.apps import _view_serve

    real = _view_serve.serve
    errors: list[BaseException] = []
    checked: list[bool] = []

    def serve(factory: Any, **kwargs: Any) -> None:
        stop = threading.Event()

        def ready(view: Any) -> None:
            try:
                assert view.wait_idle(30.0)
                check(view)
                checked.append(True)
            except BaseException as exc:  # raised in the test, after the server stopped
                errors.append(exc)
            finally:
                stop.set()

        real(factory, port=free_port(), open_browser=False, say=str, ready=ready, stop=stop)

    result = _view(args, serve)
    if errors:
        raise errors[0]
    assert result.exit_code == 0 and checked, result.output


# ----------------------------------------------------------------------------- item 1
def test_a_bad_object_pose_is_refused_in_one_line_naming_the_object(
    mug_skill: tuple[Skill, Path],
) -> None:
    path = str(mug_skill[1])
    cases = [
        ("mug=0.5,0.05,0,0,0,0,0", "zero norm"),  # no rotation
        ("mug=0.5,0.05,0", "must be a pose"),  # a position for an oriented constraint
        ("mug=nan,0.05,0,1,0,0,0", "finite"),
        ("mug=0.5,0.05,0,1,0,0,inf", "finite"),
    ]
    for text, words in cases:
        result = _view(["--skill", path, "--object", text], _never_served)
        _refused(result, "--object", "mug", words)
    _refused(_view(["--skill", path, "--object", "cup=0,0,0"], _never_served), "--object", "cup")


def test_the_view_plans_and_draws_with_an_object_pose(mug_skill: tuple[Skill, Path]) -> None:
    """The pose given is the placement planned for: the page's plan is the reproduction for
    it, and the mug's handle, yaw field and Gaussian (in its frame) turn with it."""
    from pbdkit.apps._view_plan import step_gaussians

    skill, path = mug_skill
    pose = pose_matrix(np.array(MUG_POSE[:3]), exp_map([0.0, 0.0, 0.2]))
    expected = skill.reproduce({"mug": pose}).positions

    def check(view: Any) -> None:
        np.testing.assert_allclose(view.objects["mug"], pose, atol=1e-12)
        assert view.plan is not None, view.ui_status.content
        np.testing.assert_allclose(view.plan.result.positions, expected, atol=1e-9)
        np.testing.assert_allclose(view.handles["mug"].wxyz, MUG_POSE[3:], atol=1e-9)
        yaw = view.ui_fields["mug"][1]
        assert yaw is not None and yaw.value == pytest.approx(math.degrees(0.2), abs=0.01)
        mean, _ = step_gaussians(view.plan, view.step)["mug"]
        np.testing.assert_allclose(view.gauss["mug"].position, mean, atol=1e-6)

    _served_app(["--skill", str(path), "--object", "mug=" + ",".join(map(str, MUG_POSE))], check)


# ----------------------------------------------------------------------------- item 10
def test_a_robot_that_is_not_a_urdf_or_not_the_skills_arm_is_refused_in_one_line(
    mug_skill: tuple[Skill, Path], tmp_path: Path
) -> None:
    path = str(mug_skill[1])
    files = {
        "text.urdf": b"hello",
        "empty.urdf": b"",
        "binary.urdf": bytes(range(256)),
        "svg.urdf": b"<svg></svg>",
        "nolinks.urdf": b'<robot name="r"></robot>',
        "one_link.urdf": b'<robot name="r"><link name="a"/></robot>',  # no joints to move
    }
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
        result = _view(["--skill", path, "--robot", str(tmp_path / name)], _never_served)
        _refused(result, "--robot", name)
    _refused(_view(["--skill", path, "--robot", "katana"], _never_served), "--robot", "5 joints")
    _refused(_view(["--skill", path, "--robot", str(tmp_path)], _never_served), "--robot")


def test_a_shipped_robot_of_the_skills_arm_is_drawn(mug_skill: tuple[Skill, Path]) -> None:
    """``--robot panda`` for the Panda's skill: its URDF draws the arm, every joint moving."""

    def check(view: Any) -> None:
        arm = view._urdf_arm
        assert arm is not None and arm._index == list(range(7))
        q = view.plan.result.joints[view.step]
        np.testing.assert_allclose(arm._cfg, q)

    _served_app(["--skill", str(mug_skill[1]), "--robot", "panda"], check)


# ----------------------------------------------------------------------------- item 7
# Runs the command and sends the process SIGINT when trimesh (imported by yourdfpy) first looks
# for networkx, inside its ``try: ... except BaseException``. SIGINT raises KeyboardInterrupt
# here as in a terminal, even when pytest runs with it ignored.
_SIGINT_IN_IMPORT = """
import importlib.abc, os, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)
class Trigger(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "networkx":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Trigger())
sys.argv = ["pbdkit", *sys.argv[1:]]
from pbdkit.apps._cli import main
main()
"""


def test_a_sigint_in_the_imports_ends_the_command(mug_skill: tuple[Skill, Path]) -> None:
    """Before, trimesh swallowed the KeyboardInterrupt and the view went on to serve."""
    args = ["view", "--skill", str(mug_skill[1]), "--no-browser", "--port", str(free_port())]
    proc = subprocess.Popen(
        [sys.executable, "-c", _SIGINT_IN_IMPORT, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "COLUMNS": "200"},
    )
    try:
        out = proc.communicate(timeout=15)[0]
    except subprocess.TimeoutExpired:
        proc.kill()
        out = proc.communicate()[0]
        pytest.fail(f"still running 15 s after a SIGINT in its imports: {out}")
    assert "serving" not in out and "Traceback" not in out, out
    assert proc.returncode in (130, -signal.SIGINT), (proc.returncode, out)


@pytest.mark.parametrize("at", ["server", "page"])
def test_a_sigint_while_the_server_starts_or_the_page_is_built_stops_it(
    at: str, mug_skill: tuple[Skill, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGINT right after the server's thread starts (inside viser's constructor: before, a
    KeyboardInterrupt out of serve that left the server running) or while the page is
    built: serve returns, without serving, and lets the port go."""
    import viser.infra

    from pbdkit.apps._view import ViewApp
    from pbdkit.apps._view_plan import typical_placements
    from pbdkit.apps._view_serve import check_port, serve

    def sigint() -> None:
        os.kill(os.getpid(), signal.SIGINT)

    if at == "server":
        start = viser.infra.WebsockServer.start

        def started(self: Any) -> None:
            start(self)
            sigint()

        monkeypatch.setattr(viser.infra.WebsockServer, "start", started)
    skill = mug_skill[0]

    def factory(server: Any) -> ViewApp:
        if at == "page":
            sigint()
        return ViewApp(skill, typical_placements(skill), server)

    port, said = free_port(), []
    t0 = time.monotonic()
    try:
        serve(factory, port=port, open_browser=False, say=said.append)
    except KeyboardInterrupt:
        pytest.fail(f"SIGINT at the {at}: a KeyboardInterrupt out of serve, the server left")
    assert time.monotonic() - t0 < 10.0 and said == []
    check_port(port)  # released


# ----------------------------------------------------------------------------- item 18
def _nan_reproduce(skill: Skill) -> Callable[..., Any]:
    """``skill.reproduce`` with a NaN in the hand's last position (as a diverging run)."""
    real = skill.reproduce

    def reproduce(*args: Any, **kwargs: Any) -> Any:
        res = real(*args, **kwargs)
        positions = np.array(res.positions)
        positions[-1, 0] = np.nan
        return dataclasses.replace(res, positions=positions)

    return reproduce


def test_a_plan_with_a_nan_is_refused_not_shown_as_nan(
    mug_skill: tuple[Skill, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The page says it could not plan; no field reads "nan"."""
    from pbdkit.apps._view import ViewApp
    from pbdkit.apps._view_plan import make_plan, typical_placements
    from pbdkit.apps._view_serve import served

    skill = Skill.load(mug_skill[1])
    monkeypatch.setattr(skill, "reproduce", _nan_reproduce(skill))
    placement = typical_placements(skill)
    with pytest.raises(ValueError, match=r"non-finite .* hand positions"):
        make_plan(skill, placement, "fused", None)
    with served(lambda srv: ViewApp(skill, placement, srv), port=free_port()) as view:
        assert view.wait_idle(30.0)
        assert view.plan is None
        assert "could not plan" in view.ui_status.content
        assert "non-finite" in view.ui_status.content
        for field in (view.ui_end, view.ui_reproduce, view.ui_driving):
            assert "nan" not in str(field.value).lower()


def test_a_run_metric_the_run_has_no_value_for_is_not_shown_as_a_number() -> None:
    """The basin's pour error when nothing was poured is NaN: "n/a", never "nan"."""
    from pbdkit.apps._cli_output import NOT_A_NUMBER, metrics_text

    metrics = {"liquid_fraction": 0.0, "held": 1.0, "pour_error_mm": math.nan, "tilt": math.inf}
    text = metrics_text(metrics)
    # The names and formats of evaluate's tables (issue 40): the unit in the name, yes/no.
    expected = f"liquid in basin 0%, held yes, pour from centre (mm) {NOT_A_NUMBER}, tilt n/a"
    assert text == expected
    assert "nan" not in text and "inf" not in text
