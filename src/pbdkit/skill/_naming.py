"""The controllers of the experiment by name, as in ``pbdkit evaluate``'s JSON.

Controllers (paper Sec. II-B and Fig. 6):

- ``"fused"``: every constraint, fused as a product of Gaussians (eq. (1));
- ``"joint"``: the joint-space constraint only;
- ``"task:OBJECT"``: the task-space constraint of one object only (null-space term alpha = 0.5).

So the coaster task's controllers are ``"fused"``, ``"joint"``, ``"task:glass"``,
``"task:coaster"`` and the basin task's ``"fused"``, ``"joint"``, ``"task:glass"``: a skill has a
task-space constraint per object of :func:`pbdkit.sim._task_skill.constrained_objects`.

A task whose objects are poses (oriented constraints, :attr:`pbdkit.Skill.oriented`) adds
``"fused-position"`` (:data:`FUSED_POSITION`): every constraint fused, in the position-only skill
of the same demonstrations (``Skill.learn(..., orientation=False)``: the paper's frames, which
translate only). Its ``"task:OBJECT"`` controllers are pose-aware.
"""

from __future__ import annotations

from collections.abc import Sequence

from .._validation import short

__all__ = ["FUSED_POSITION", "controller_names", "controller_use"]

#: The fused controller of the position-only skill (a task with oriented constraints).
FUSED_POSITION = "fused-position"


def controller_names(object_names: Sequence[str], *, has_oriented: bool = False) -> list[str]:
    """``["fused", "joint", "task:OBJ", ...]`` for a skill's objects, with
    ``"fused-position"`` after ``"fused"`` for a skill with oriented constraints."""
    extra = [FUSED_POSITION] if has_oriented else []
    return ["fused", *extra, "joint", *(f"task:{k}" for k in object_names)]


def controller_use(
    controller: str, object_names: Sequence[str], *, has_oriented: bool = False
) -> list[str] | None:
    """The ``use`` argument of :meth:`pbdkit.Skill.reproduce` for a controller name
    (``"fused-position"``: None, of the position-only skill)."""
    if controller == "fused" or (has_oriented and controller == FUSED_POSITION):
        return None
    if controller == "joint":
        return ["joint"]
    if controller.startswith("task:") and controller[5:] in object_names:
        return [controller[5:]]
    raise ValueError(
        f"controller must be one of {controller_names(object_names, has_oriented=has_oriented)}, "
        f"got {short(controller)}"
    )
