"""Where to demonstrate next, in the browser (issue 39): the skill's suggestions
(:meth:`pbdkit.Skill.suggest`) drawn as ghosts of the objects, for the user to drag the real
objects to (:doc:`/active`).

- :class:`SuggestionGhosts`, the layer: on a viser server, a translucent copy of each object
  (its marker, in its color; a frame for a pose) at each suggested placement, labelled with
  its rank and score, and a panel folder that lists the placements in numbers and picks the
  active suggestion. Given where the objects are (:meth:`SuggestionGhosts.match`), each ghost
  of the active suggestion that an object is within :data:`MATCH_DISTANCE` and
  :data:`MATCH_YAW` of turns :data:`MATCHED_RGB` and reads "in place". It knows no skill:
  ``pbdkit view --suggest`` (:class:`ViewSuggestions`) and ``pbdkit ros record --suggest
  --view`` (:class:`pbdkit.apps._view_record.RecordView`) drive it.
- :class:`ViewSuggestions`: ``pbdkit view --skill S --suggest N``. Suggesting runs on a thread
  of its own (:class:`pbdkit.apps._view_plan.LatestWins`), never on the server's; the panel
  reads "suggesting ..." meanwhile. "suggest again" draws other candidates (the next seed);
  "put the objects there" moves the objects to the active suggestion, and the plan follows.

viser is imported by the server's owner; this module only calls it.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from .._rotations import as_pose, pose_matrix, wrap_angle, yaw_of
from .._validation import check_int
from ..data._placement import position_of
from ..skill._suggest import Suggestion
from ._cli_suggest import default_ranges, placement_text, ranges_from_options
from ._view_plan import LatestWins, constraint_colors, wxyz_of

__all__ = [
    "FAINT_OPACITY",
    "GHOST_OPACITY",
    "GHOST_RADIUS",
    "MATCHED_RGB",
    "MATCH_DISTANCE",
    "MATCH_YAW",
    "SuggestSettings",
    "SuggestionGhosts",
    "ViewSuggestions",
    "in_place",
    "placement_error",
    "suggest_settings",
]

Float = NDArray[np.float64]
RGB = tuple[int, int, int]


class ViewLike(Protocol):
    """What :class:`ViewSuggestions` uses of :class:`pbdkit.apps._view.ViewApp` (a protocol,
    so that this module does not import the view that imports it)."""

    server: Any
    skill: Any
    colors: Any
    objects: dict[str, Float]
    handles: dict[str, Any]
    _lock: Any

    def move_object(self, name: str, placement: Any) -> None: ...


#: An object this close to its ghost (m, between the positions) ...
MATCH_DISTANCE = 0.01
#: ... and, where both are poses, turned this little from it about the vertical (degrees) is
#: in place.
MATCH_YAW = 5.0
#: The opacity of the active suggestion's ghosts ...
GHOST_OPACITY = 0.4
#: ... and of the others'.
FAINT_OPACITY = 0.12
#: A ghost whose object is in place.
MATCHED_RGB = (0, 200, 90)
#: A ghost's sphere (the view's object marker's radius, m).
GHOST_RADIUS = 0.02


def placement_error(actual: Any, target: Any) -> tuple[float, float | None]:
    """How far an object is from a placement: the distance between the positions (m) and,
    where both are poses (4x4, or x, y, z, qw, qx, qy, qz), the yaw difference about the
    vertical (degrees, wrapped into [-180, 180)); None where either is a position."""
    p, r = as_pose(actual, "actual")
    q, s = as_pose(target, "target")
    distance = float(np.linalg.norm(p - q))
    if r is None or s is None:
        return distance, None
    return distance, math.degrees(float(wrap_angle(yaw_of(r) - yaw_of(s))))


def in_place(
    actual: Any, target: Any, *, distance: float = MATCH_DISTANCE, yaw: float = MATCH_YAW
) -> bool:
    """Whether an object at ``actual`` is at ``target`` within ``distance`` (m) and ``yaw``
    (degrees; checked where both are poses)."""
    d, turn = placement_error(actual, target)
    return d <= distance and (turn is None or abs(turn) <= yaw)


@dataclass(frozen=True)
class SuggestSettings:
    """What ``pbdkit view --suggest`` suggests: ``n`` placements inside ``ranges`` (as
    :meth:`pbdkit.Skill.suggest` takes them), candidates drawn with ``seed``."""

    ranges: Mapping[str, Mapping[str, Any]]
    n: int = 1
    seed: int = 0


def suggest_settings(
    skill: Any, n: int, parsed: Sequence[Any], *, say: Callable[[str], None] = print
) -> SuggestSettings | None:
    """``pbdkit view``'s ``--suggest N`` and ``--range`` (parsed by
    :func:`pbdkit.apps._cli_suggest.parse_range`) for ``skill``: None for ``n = 0``, and for a
    skill that keeps no demonstrations (a file of version 1 or 2), which ``say`` tells in one
    line (the view goes on without suggestions). Without a range, each object's demonstrated
    box widened (:func:`pbdkit.apps._cli_suggest.default_ranges`)."""
    n = check_int(n, "--suggest", minimum=0, maximum=100)
    if n == 0:
        return None
    if skill.demonstrations_ is None:
        say(
            "note: the skill keeps no demonstrations (a skill file of version 1 or 2), so the "
            "view shows no suggestions; learn it again with pbdkit learn"
        )
        return None
    ranges = ranges_from_options(skill, list(parsed)) if parsed else default_ranges(skill)
    return SuggestSettings(ranges, n)


class SuggestionGhosts:
    """Ghosts of the objects at suggested placements, and a panel folder that lists them
    (module docstring). Thread-safe: :meth:`show`, :meth:`match` and :meth:`select` may come
    from any thread.

    Parameters
    ----------
    server : viser.ViserServer
    names : sequence of str
        The objects, in the order the panel lists them.
    colors : mapping str -> (r, g, b), optional
        Each object's color (0-255); default: Fig. 6's, as the view colors them.
    on_again : callable, optional
        Adds a "suggest again" button that calls it.
    on_put : callable, optional
        Adds a "put the objects there" button that calls it with the active suggestion.
    root : str
        The scene node the ghosts go under.
    """

    def __init__(
        self,
        server: Any,
        names: Sequence[str],
        colors: Mapping[str, RGB] | None = None,
        *,
        on_again: Callable[[], None] | None = None,
        on_put: Callable[[Suggestion], None] | None = None,
        root: str = "/suggest",
    ) -> None:
        self.server, self.names, self.root = server, list(names), root
        self.colors = dict(constraint_colors(self.names) if colors is None else colors)
        self.suggestions: list[Suggestion] = []
        self.active = 0
        #: The active suggestion's objects in place at the last :meth:`match`.
        self.matched: dict[str, bool] = {}
        self.nodes: dict[tuple[int, str], tuple[Any, Any, Any]] = {}
        self._objects: dict[str, Any] = {}
        self._lock = threading.RLock()
        self._on_put = on_put
        self._note = ""
        self._busy = False  # between busy() and show(): the status says only that
        gui = server.gui
        with gui.add_folder("where to demonstrate next"):
            self.ui_status: Any = gui.add_markdown("")
            self.ui_list: Any = gui.add_markdown("")
            self.ui_active: Any = gui.add_dropdown("active", ("next 1",), disabled=True)
            self.ui_active.on_update(self._active_changed)
            self.ui_again: Any = None
            self.ui_put: Any = None
            if on_again is not None:
                self.ui_again = gui.add_button("suggest again")
                self.ui_again.on_click(lambda _: on_again())
            if on_put is not None:
                self.ui_put = gui.add_button("put the objects there", disabled=True)
                self.ui_put.on_click(lambda _: self.put())

    # ------------------------------------------------------------------ state
    @property
    def status(self) -> str:
        """The panel's status line."""
        return str(self.ui_status.content)

    def busy(self, text: str = "suggesting ...") -> None:
        """Say that suggestions are on their way (the ghosts shown stay until they come)."""
        with self._lock:
            self._note, self._busy = text, True
            self._write()

    def failed(self, exc: BaseException | str) -> None:
        """Say, in one line, why there is nothing to suggest."""
        self.say(f"could not suggest: {exc}")

    def say(self, text: str) -> None:
        """Put ``text`` in the status line (on one line)."""
        with self._lock:
            self._note, self._busy = " ".join(text.split()), False
            self._write()

    def show(self, suggestions: Sequence[Suggestion]) -> None:
        """Draw ``suggestions`` (the ghosts before go), the first active; matched against the
        placements of the last :meth:`match`."""
        scene = self.server.scene
        with self._lock, self.server.atomic():
            for frame, _, _ in self.nodes.values():
                frame.remove()  # and its sphere and label with it
            self.nodes = {}
            self.suggestions, self._busy = list(suggestions), False
            for i, s in enumerate(self.suggestions):
                for name in self.names:
                    value = np.asarray(s.objects[name], dtype=np.float64)
                    path = f"{self.root}/{i}/{name}"
                    frame = scene.add_frame(
                        path,
                        show_axes=value.shape == (4, 4),
                        axes_length=0.05,
                        axes_radius=0.002,
                        position=np.asarray(position_of(value), dtype=np.float64),
                        wxyz=wxyz_of(value),
                    )
                    sphere = scene.add_icosphere(
                        f"{path}/ghost",
                        radius=GHOST_RADIUS,
                        color=self.colors.get(name, (90, 90, 90)),
                        opacity=GHOST_OPACITY,
                        cast_shadow=False,
                        receive_shadow=False,
                    )
                    label = scene.add_label(f"{path}/label", "", position=(0.0, 0.0, -0.04))
                    self.nodes[(i, name)] = (frame, sphere, label)
            n = len(self.suggestions)
            if n:
                self._note = (
                    f"{n} placement{'s' if n > 1 else ''} where a demonstration would teach "
                    "the skill most, the best first: drag the objects onto the active one's "
                    "ghosts."
                )
            else:
                self._note = "no placement inside the ranges is within the arm's reach."
            self.active = 0
            labels = tuple(f"next {i + 1}" for i in range(max(n, 1)))
            self.ui_active.options = labels
            self.ui_active.value = labels[0]
            self.ui_active.disabled = n < 2
            if self.ui_put is not None:
                self.ui_put.disabled = n == 0
            self._paint()
        self.server.flush()

    def draw_ranges(self, ranges: Mapping[str, Mapping[str, Any]]) -> None:
        """Outline, in each object's color, the rectangle its suggestions are drawn from
        (``ranges`` as :meth:`pbdkit.Skill.suggest` takes them; at the range's low height)."""
        for name, spec in ranges.items():
            (x0, y0, z), (x1, y1, _) = np.asarray(spec["low"]), np.asarray(spec["high"])
            corners = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])
            edges = np.stack([corners, np.roll(corners, -1, axis=0)], axis=1)
            self.server.scene.add_line_segments(
                f"{self.root}_ranges/{name}",
                points=edges.astype(np.float32),
                colors=self.colors.get(name, (90, 90, 90)),
                thickness=0.002,
            )

    def select(self, index: int) -> None:
        """Make suggestion ``index`` (from 0) the active one."""
        with self._lock:
            if not 0 <= index < len(self.suggestions):
                raise ValueError(
                    f"suggestion {index + 1} is not shown (1..{len(self.suggestions)})"
                )
            self.active = index
            label = f"next {index + 1}"
            if self.ui_active.value != label:
                self.ui_active.value = label
            self._paint()

    def match(self, objects: Mapping[str, Any]) -> dict[str, bool]:
        """Mark the active suggestion's ghosts whose object is in place (:func:`in_place`);
        ``objects``: where the objects are (any of them; kept for the next suggestions).
        Returns the objects in place, by name (those of ``names`` given)."""
        with self._lock:
            self._objects.update({k: np.array(v, dtype=np.float64) for k, v in objects.items()})
            self._paint()
            return dict(self.matched)

    # ------------------------------------------------------------------ drawing
    def _paint(self) -> None:
        """The ghosts' colors, opacities and labels, and the panel, for the active suggestion
        and the objects' last placements."""
        self.matched = {}
        if self.suggestions:
            target = self.suggestions[self.active].objects
            self.matched = {
                k: in_place(self._objects[k], target[k]) for k in self.names if k in self._objects
            }
        for (i, name), (_, sphere, label) in self.nodes.items():
            active = i == self.active
            here = active and self.matched.get(name, False)
            sphere.color = MATCHED_RGB if here else self.colors.get(name, (90, 90, 90))
            sphere.opacity = GHOST_OPACITY if active else FAINT_OPACITY
            score = self.suggestions[i].score
            label.text = (
                f"next {i + 1} {name}: in place"
                if here
                else (f"next {i + 1} {name} ({score:.2f})" if active else f"next {i + 1}")
            )
        self._write()

    def _write(self) -> None:
        rows = []
        for i, s in enumerate(self.suggestions):
            mark = " (active)" if i == self.active else ""
            where = placement_text(s.objects, self.names)
            rows.append(f"- **next {i + 1}**{mark}, uncertainty {s.score:.2f}: {where}")
        self.ui_list.content = "\n".join(rows)
        text = self._note
        if self.suggestions and self.matched and not self._busy:
            placed = [k for k, v in self.matched.items() if v]
            if len(placed) == len(self.names):
                text += f" **next {self.active + 1}: every object in place.**"
            elif placed:
                text += f" In place: {', '.join(placed)}."
        self.ui_status.content = text

    # ------------------------------------------------------------------ events
    def _active_changed(self, event: Any) -> None:
        label = str(self.ui_active.value)
        index = int(label.split()[-1]) - 1
        with self._lock:
            if index != self.active and 0 <= index < len(self.suggestions):
                self.active = index
                self._paint()

    def put(self) -> None:
        """Hand the active suggestion to ``on_put`` (the "put the objects there" button)."""
        with self._lock:
            if not self.suggestions or self._on_put is None:
                return
            chosen = self.suggestions[self.active]
        self._on_put(chosen)


class ViewSuggestions:
    """``pbdkit view --skill S --suggest N``: the ghosts of a :class:`pbdkit.apps._view.ViewApp`
    (module docstring); the app makes it, tells it of each move (:meth:`moved`) and closes
    it.

    Parameters
    ----------
    app : ViewLike
    settings : SuggestSettings
    """

    def __init__(self, app: ViewLike, settings: SuggestSettings) -> None:
        self.app, self.settings, self.seed = app, settings, settings.seed
        self.ghosts = SuggestionGhosts(
            app.server,
            app.skill.object_names,
            app.colors,
            on_again=self.again,
            on_put=self.put,
        )
        self.ghosts.draw_ranges(settings.ranges)
        self.worker: LatestWins[int] = LatestWins(
            self._suggest, on_error=self.ghosts.failed, name="pbdkit-view-suggest"
        )
        self.request()

    def request(self) -> None:
        """Suggest (with the present seed) on the worker thread; "suggesting ..." meanwhile."""
        self.ghosts.busy()
        self.worker.submit(self.seed)

    def again(self) -> None:
        """Other suggestions: candidates drawn with the next seed."""
        self.seed += 1
        self.request()

    def _suggest(self, seed: int) -> None:
        found = self.app.skill.suggest(self.settings.ranges, n=self.settings.n, seed=seed)
        self.ghosts.show(found)
        self.moved()

    def moved(self) -> None:
        """Match the ghosts against where the app's objects are now."""
        with self.app._lock:
            objects = {k: v.copy() for k, v in self.app.objects.items()}
        self.ghosts.match(objects)

    def put(self, suggestion: Suggestion) -> None:
        """Move the app's objects to ``suggestion`` (a position stays a position; a pose keeps
        its rotation where the suggestion gives a position)."""
        for name in self.app.handles:
            if name not in suggestion.objects:
                continue
            position, rotation = as_pose(suggestion.objects[name], name)
            old = self.app.objects[name]
            if old.shape != (4, 4):
                value = position
            else:
                value = pose_matrix(position, old[:3, :3] if rotation is None else rotation)
            self.app.move_object(name, value)

    def wait_idle(self, timeout: float | None = 30.0) -> bool:
        """Block until the suggestions asked for are shown."""
        return self.worker.wait_idle(timeout)

    def close(self) -> None:
        """Stop suggesting (the one under way finishes)."""
        self.worker.close()
