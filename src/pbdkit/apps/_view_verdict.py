"""The outcome of a run in physics in ``pbdkit view``, kept to the plan it ran
(:class:`Verdict`): the panel never shows a success or a failure for a placement that is no
longer the page's.

No browser or server here: :class:`pbdkit.apps._view.ViewApp` hands it the function that puts
a line in the panel.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["STALE", "Verdict"]

#: Shown, instead of its outcome, when a run ends after the plan changed.
STALE = "the plan changed during the run: run it again for its outcome"


class Verdict:
    """The panel's line about runs in physics, cleared when the plan changes.

    A run starts for the plan of the moment (:meth:`start`: it shows that it runs and gets a
    token). A change of the plan (:meth:`changed`: an object moved where no run sees it,
    another controller) clears an outcome shown at once, since it was another plan's; while a
    run goes on, its line stays, and its outcome, when it comes (:meth:`finish`), is shown
    only if the plan has not changed since it started (else :data:`STALE`).

    Parameters
    ----------
    show : callable
        Puts a line (markdown) in the panel; ``""`` empties it.
    """

    def __init__(self, show: Callable[[str], None]) -> None:
        self._show = show
        # One lock for the count and the line: an outcome checked against the count cannot be
        # shown after a change that came between the check and the line.
        self._lock = threading.Lock()
        self._plan = 0  # changes of the plan so far
        self._runs = 0  # runs going on
        #: The line shown.
        self.text = ""

    def _set(self, text: str) -> None:
        self.text = text
        self._show(text)

    def changed(self) -> None:
        """The plan changed: an outcome shown is cleared; a run going on will not show its."""
        with self._lock:
            self._plan += 1
            if self._runs == 0:
                self._set("")

    def start(self, text: str) -> int:
        """A run starts for the present plan: show ``text``; the token to :meth:`finish` it."""
        with self._lock:
            self._runs += 1
            self._set(text)
            return self._plan

    def finish(self, token: int, text: str, *, always: bool = False) -> bool:
        """The run of ``token`` (:meth:`start`) ended with ``text``: shown if the plan is still
        the one it ran (or ``always``: an error, which is the run's, not the plan's), else
        :data:`STALE`. Returns whether ``text`` is shown."""
        with self._lock:
            self._runs = max(self._runs - 1, 0)
            shown = always or token == self._plan
            self._set(text if shown else STALE)
            return shown
