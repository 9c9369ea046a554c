"""``pbdkit ros record --suggest SKILL --view``: where the next take's objects go, in a browser,
while recording (issue 39, item 6).

:class:`RecordView` serves a page on 127.0.0.1 from threads of its own: the arm as its joint
states put it (drawn from its URDF, :class:`pbdkit.apps._view_urdf.UrdfArm`), each object
where its source says, and the next take's suggestion as ghosts of the objects
(:class:`pbdkit.apps._view_suggest.SuggestionGhosts`) that turn when an object is put in place.
The recording loop only hands it values (:meth:`RecordView.sample`, a copy under a lock); a
thread of the view draws the latest at :data:`DRAW_RATE` Hz, so the page never slows the
recording. Imported only with ``--view`` (the ``view`` extra).
"""

from __future__ import annotations

import contextlib
import io
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..data._placement import position_of
from ..skill._suggest import Suggestion
from ._view_plan import camera_pose, constraint_colors
from ._view_serve import HOST, check_port
from ._view_suggest import GHOST_RADIUS, SuggestionGhosts

__all__ = ["DRAW_RATE", "RecordView"]

Float = NDArray[np.float64]

#: The page is redrawn at most this often (Hz), from the latest sample.
DRAW_RATE = 10.0


class RecordView:
    """The page of ``pbdkit ros record --view`` (module docstring); :meth:`close` stops it.

    Parameters
    ----------
    skill : Skill
        The skill that suggests: its arm and objects are drawn.
    port : int
        On 127.0.0.1; a port in use is refused (ValueError).
    urdf : path or str, optional
        The URDF to draw the arm from (:func:`pbdkit.apps._view_urdf.arm_urdf`); default: the
        skill's robot's.
    ranges : mapping, optional
        Where the suggestions are drawn from (as :meth:`pbdkit.Skill.suggest` takes them):
        outlined on the table.
    """

    def __init__(
        self,
        skill: Any,
        port: int,
        *,
        urdf: Path | str | None = None,
        ranges: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> None:
        import viser

        from ._view_urdf import UrdfArm

        check_port(port)
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner
            self.server = viser.ViserServer(host=HOST, port=port, verbose=False)
        self.url = f"http://{HOST}:{port}"
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        try:
            self.server.gui.configure_theme(show_share_button=False)
            if self.server.get_port() != port:
                raise ValueError(f"port {port} on {HOST} is in use: choose another with --port")
            scene = self.server.scene
            scene.set_up_direction("+z")
            scene.add_grid("/grid", width=2.0, height=2.0, cell_size=0.1)
            camera = self.server.initial_camera
            placed = skill.demonstrations_[0].objects.values() if skill.demonstrations_ else ()
            camera.position, camera.look_at = camera_pose(skill.reach, placed)
            names = list(skill.object_names)
            colors = {k: v for k, v in constraint_colors(names).items() if k in names}
            self.server.gui.add_markdown(
                "**pbdkit ros record**: put the objects on the active suggestion's ghosts, "
                "then record the take."
            )
            self.arm = UrdfArm(self.server, skill.robot, urdf)
            self.markers = {
                k: scene.add_icosphere(
                    f"/objects/{k}", radius=GHOST_RADIUS, color=colors[k], visible=False
                )
                for k in names
            }
            for k in names:
                scene.add_label(f"/objects/{k}/label", k, position=(0.0, 0.0, 0.05))
            self.ghosts = SuggestionGhosts(self.server, names, colors)
            if ranges is not None:
                self.ghosts.draw_ranges(ranges)
        except BaseException:
            self._stop_server()
            raise
        self._lock = threading.Lock()
        self._q: Float | None = None
        self._objects: dict[str, Float] = {}
        self._fresh = False
        self._thread = threading.Thread(
            target=self._draw_loop, name="pbdkit-record-view", daemon=True
        )
        self._thread.start()

    def show(self, suggestions: Sequence[Suggestion]) -> None:
        """The next take's suggestions, as ghosts (the first active)."""
        self.ghosts.show(suggestions)

    def sample(self, q: Any, objects: Mapping[str, Any]) -> None:
        """The arm's joint angles (the skill's order) and where the objects are now; drawn by
        the view's thread."""
        copy = {k: np.array(v, dtype=np.float64) for k, v in objects.items()}
        with self._lock:
            self._q = np.array(q, dtype=np.float64)
            self._objects.update(copy)
            self._fresh = True

    def draw(self) -> None:
        """Draw the latest sample (the view's thread does, at :data:`DRAW_RATE`)."""
        with self._lock:
            if not self._fresh:
                return
            q, objects, self._fresh = self._q, dict(self._objects), False
        with self.server.atomic():
            if q is not None:
                self.arm.show(q)
            for name, value in objects.items():
                marker = self.markers.get(name)
                if marker is not None:
                    marker.position = np.asarray(position_of(value), dtype=np.float64)
                    marker.visible = True
        self.ghosts.match(objects)

    def _draw_loop(self) -> None:
        while not self._stop.wait(1.0 / DRAW_RATE):
            try:
                self.draw()
            except Exception as exc:  # a bad sample: said on the page, the loop goes on
                self.ghosts.say(f"could not draw the arm or the objects: {exc}")

    def close(self) -> None:
        """Stop drawing and serving."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._stop_server()

    def _stop_server(self) -> None:
        with contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()
