"""Learning a new demonstration at once: :meth:`pbdkit.Skill.update` (private).

The skill keeps what it learned from (:attr:`pbdkit.Skill.demonstrations_`, its options); an
update encodes the old demonstrations and the new ones again (alignment in time included), each
space's EM starting from the old GMM's responsibilities with its K kept, and chooses K again
where the data warrant it (:func:`pbdkit.skill._encoding.encode`, ``warm``). Orientation bases
stay the old skill's. What it costs against a refit, and how far their reproductions are apart:
``benchmarks/bench_update.py``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..data._demonstration import Demonstration, check_demonstrations
from ._encoding import encode
from ._provenance import LearnOptions
from ._skill_file import skill_duration_problem
from ._spaces import warn_outside_limits

__all__ = ["update_skill", "warm_skill"]


def update_skill(skill: Any, new: Demonstration | Sequence[Demonstration]) -> Any:
    """:meth:`pbdkit.Skill.update` (see there)."""
    demos, options = skill._learned_from("update")
    given: object = new
    if isinstance(given, Demonstration):
        added = [given]
    elif isinstance(given, Sequence) and not isinstance(given, (str, bytes)):
        added = list(given)
    else:
        raise ValueError(
            f"new must be a Demonstration or a sequence of them, got {type(new).__name__}"
        )
    if not added:
        raise ValueError("new holds no demonstration: give at least one")
    check_demonstrations(added, min_demos=1)
    try:
        items = check_demonstrations([*demos, *added], min_demos=2)
    except ValueError as exc:
        raise ValueError(f"new does not match the skill's demonstrations: {exc}") from None
    with np.errstate(over="ignore"):
        duration = float(np.mean([d.duration for d in items]))
    problem = skill_duration_problem(duration, options["n_steps"])
    if problem:
        raise ValueError(f"new: {problem} (are the time stamps t in seconds?)")
    warn_outside_limits(added, skill.robot)
    return warm_skill(skill, items, options, len(demos), duration=duration, keep=True)


def warm_skill(
    skill: Any,
    items: list[Demonstration],
    options: LearnOptions,
    n_old: int,
    *,
    duration: float = float("nan"),
    keep: bool = False,
    reach: float | None = None,
) -> Any:
    """The skill of ``items`` encoded from ``skill``'s GMMs (:func:`encode` with ``warm``:
    its first ``n_old`` are what ``skill`` learned), its orientation bases kept. ``keep``: the
    new skill keeps ``items`` and ``options`` (an update); ``reach``: instead of the one the
    demonstrations give."""
    code = encode(
        items, skill.robot, options, warm=skill.gmms, n_old=n_old, old_bases=skill.rotation_base
    )
    kept: dict[str, Any] = {}
    if keep:
        kept = {"demonstrations": items, "learn_options": options, "n_samples": code.n_samples}
    return type(skill)(
        skill.robot,
        code.gmms,
        n_steps=skill.n_steps,
        object_names=skill.object_names,
        has_gripper=skill.has_gripper,
        reach=code.reach if reach is None else reach,
        duration=duration,
        rotation_base=code.rotation_base,
        aligned=code.aligned,
        calibration=code.calibration,
        **kept,
    )
