"""The built-in tasks, one module each: their specs, in the order of ``task_names()``.

- :mod:`.coaster`: task 1 of the paper, set the table (glass from a shelf onto a coaster);
- :mod:`.basin`: task 2, clear the table (pour the glass's content into a fixed basin);
- :mod:`.slot`: a turned block into a turned slot, where orientation decides success.

The modules only define their :data:`SPEC`: the registry
(:mod:`pbdkit.sim._task_registry`) imports this package and registers :data:`BUILT_IN` when a task
is first looked up. A new built-in task is one module here and its spec below; a task of one's
own is one module anywhere that calls :func:`pbdkit.sim.register_task` (see ``docs/tasks.md``).
"""

from __future__ import annotations

from .._tasks import TaskSpec
from . import basin, coaster, slot

#: The built-in tasks, the paper's task 1 first.
BUILT_IN: tuple[TaskSpec, ...] = (coaster.SPEC, basin.SPEC, slot.SPEC)

__all__ = ["BUILT_IN", "basin", "coaster", "slot"]
