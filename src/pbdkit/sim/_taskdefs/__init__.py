"""The built-in tasks, one module each, registered on import (by :mod:`pbdkit.sim`).

- :mod:`.coaster`: task 1 of the paper, set the table (glass from a shelf onto a coaster);
- :mod:`.basin`: task 2, clear the table (pour the glass's content into a fixed basin);
- :mod:`.slot`: a turned block into a turned slot, where orientation decides success.

A new built-in task is one module here and its import below; a task of one's own is one module
anywhere that calls :func:`pbdkit.sim.register_task` (see :mod:`pbdkit.sim._tasks`).
"""

from __future__ import annotations

from . import basin, coaster, slot

# Registration order is the order of task_names(): the paper's task 1 first.
coaster.register()
basin.register()
slot.register()

__all__ = ["basin", "coaster", "slot"]
