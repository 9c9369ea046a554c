"""What a skill was learned from: the demonstrations as :meth:`pbdkit.Skill.learn` was given
them, its options as resolved (:class:`LearnOptions`: learning again from both gives the same
skill, bit for bit) and the number of samples each space's GMM was fitted on. ``Skill.update``
and ``Skill.suggest`` start from them (``Skill._learned_from``); a skill built by hand or read
from a skill file of version 1 or 2 has none. Checked here wherever they enter (learning, the
constructor, a version-3 skill file: :func:`pbdkit.skill._skill_file.read_skill`).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, TypedDict

import numpy as np

from .._validation import check_int, check_positive_float, short
from ..data._demonstration import Demonstration, check_demonstrations
from ..data._placement import is_pose
from ..reproduction._constraints import JOINT
from ._spaces import MAX_STEPS, variability_floor

__all__ = [
    "LEARN_OPTIONS",
    "LearnOptions",
    "LearnedFrom",
    "check_learn_options",
    "check_learned_from",
    "learned_from",
    "resolve_task_objects",
]

#: The keyword arguments of :meth:`pbdkit.Skill.learn` that decide what it learns.
LEARN_OPTIONS = (
    "n_steps",
    "n_components",
    "max_components",
    "reg_covar",
    "random_state",
    "fit_samples",
    "bic_samples_per_sequence",
    "task_objects",
    "orientation",
    "align",
    "calibrate",
)
#: The largest seed: scikit-learn's (a 32-bit unsigned integer).
MAX_SEED = 2**32 - 1


class LearnOptions(TypedDict):
    """:meth:`pbdkit.Skill.learn`'s options as resolved (:func:`check_learn_options`):
    ``Skill.learn(demos, robot, **options)`` learns the same skill again."""

    n_steps: int
    n_components: int | Literal["auto", "bic"]
    max_components: int
    reg_covar: float | dict[str, float] | None
    random_state: int | None
    fit_samples: int | None
    bic_samples_per_sequence: float
    task_objects: list[str] | None
    orientation: bool
    align: bool | Literal["auto"]
    calibrate: bool


@dataclass(frozen=True)
class LearnedFrom:
    """What a skill was learned from (:func:`check_learned_from`)."""

    demonstrations: list[Demonstration]
    options: LearnOptions
    n_samples: dict[str, int]


def resolve_task_objects(task_objects: object, recorded: Sequence[str]) -> list[str]:
    """The objects that get a task-space constraint: ``task_objects`` (a name, or distinct
    names among ``recorded``), all of ``recorded`` when None."""
    if task_objects is None:
        return list(recorded)
    if isinstance(task_objects, str):
        task_objects = [task_objects]
    names = list(task_objects) if isinstance(task_objects, Sequence) else [task_objects]
    unknown = [k for k in names if k not in recorded]
    if unknown or len(set(names)) != len(names):
        raise ValueError(
            f"task_objects must be distinct names among the recorded objects {list(recorded)}, "
            f"got {names}"
        )
    return [str(k) for k in names]


def check_learn_options(
    options: Mapping[str, object], *, k_max: int, key: Callable[[str], str] = str
) -> LearnOptions:
    """:meth:`pbdkit.Skill.learn`'s options, checked and resolved: integers as ``int``, numbers
    as ``float``, a ``reg_covar`` mapping as a dict, ``fit_samples`` at most ``n_steps`` (more
    keeps every step, as ``n_steps`` does). ``k_max`` bounds K (``MAX_FILE_COMPONENTS``);
    ``key`` names an option in a message (a file's key)."""
    if set(options) != set(LEARN_OPTIONS):
        missing = [k for k in LEARN_OPTIONS if k not in options]
        unknown = sorted(str(k) for k in options if k not in LEARN_OPTIONS)
        raise ValueError(f"learn options: missing {missing}, unknown {unknown}")
    n_steps = check_int(options["n_steps"], key("n_steps"), minimum=2, maximum=MAX_STEPS)
    n_components = options["n_components"]
    if isinstance(n_components, str):
        if n_components not in ("auto", "bic"):
            raise ValueError(
                f"{key('n_components')} must be a positive integer, 'auto' or 'bic', "
                f"got {short(n_components)}"
            )
        k: int | Literal["auto", "bic"] = "auto" if n_components == "auto" else "bic"
    else:
        k = check_int(n_components, key("n_components"), minimum=1, maximum=k_max)
    reg = options["reg_covar"]
    try:
        variability_floor(reg)  # type: ignore[arg-type]  # what it checks
    except ValueError as exc:
        if key("reg_covar") == "reg_covar":  # its message names it
            raise
        raise ValueError(f"{key('reg_covar')}: {exc}") from exc
    random_state = options["random_state"]
    fit_samples = options["fit_samples"]
    align = options["align"]
    if not (isinstance(align, (bool, np.bool_)) or (isinstance(align, str) and align == "auto")):
        raise ValueError(f"{key('align')} must be True, False or 'auto', got {short(align)}")
    return LearnOptions(
        n_steps=n_steps,
        n_components=k,
        max_components=check_int(
            options["max_components"], key("max_components"), minimum=1, maximum=k_max
        ),
        reg_covar=_resolved_reg_covar(reg, key("reg_covar")),
        random_state=None
        if random_state is None
        else check_int(random_state, key("random_state"), minimum=0, maximum=MAX_SEED),
        fit_samples=None
        if fit_samples is None
        else min(check_int(fit_samples, key("fit_samples"), minimum=2), n_steps),
        bic_samples_per_sequence=check_positive_float(
            options["bic_samples_per_sequence"], key("bic_samples_per_sequence")
        ),
        task_objects=_check_names(options["task_objects"], key("task_objects")),
        orientation=_check_bool(options["orientation"], key("orientation")),
        align="auto" if isinstance(align, str) else bool(align),
        calibrate=_check_bool(options["calibrate"], key("calibrate")),
    )


def _resolved_reg_covar(reg: object, name: str) -> float | dict[str, float] | None:
    """``reg_covar`` (checked by :func:`~pbdkit.skill._spaces.variability_floor`) as a float,
    a dict of floats or None."""
    if reg is None:
        return None
    if isinstance(reg, Mapping):
        return {
            str(k): check_positive_float(v, f"{name}[{short(k)}]", allow_zero=True)
            for k, v in reg.items()
        }
    return check_positive_float(reg, name, allow_zero=True)


def _check_names(value: object, name: str) -> list[str] | None:
    """``task_objects`` as resolved: None, or a list of distinct object names."""
    if value is None:
        return None
    names = list(value) if isinstance(value, (list, tuple)) else [None]
    if all(isinstance(n, str) and n and n != JOINT for n in names) and len(set(names)) == len(
        names
    ):
        return [str(n) for n in names]
    raise ValueError(f"{name} must be None or a list of distinct object names, got {short(value)}")


def _check_bool(value: object, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {short(value)}")
    return bool(value)


def check_learned_from(
    demonstrations: object,
    options: Mapping[str, object] | None,
    n_samples: Mapping[str, object] | None,
    *,
    n_joints: int,
    has_gripper: bool,
    object_names: Sequence[str],
    oriented: Collection[str],
    n_steps: int,
    k_max: int,
    key: Callable[[str], str] | None = None,
) -> LearnedFrom | None:
    """What a skill of this structure was learned from, checked against it; None when all three
    are None (a skill built by hand, or of a skill file of version 1 or 2).

    ``key`` names what a message is about: an option's name, ``"n_samples"``,
    ``"demonstrations"`` and its parts ``"demonstrations.joints"``, ``".gripper"``,
    ``".object_names"``, ``".poses"`` (a file's keys, when it reads one); by default the
    constructor's arguments (``learn_options['align']``).
    """
    key = key or _argument_name
    if demonstrations is None and options is None and n_samples is None:
        return None
    if demonstrations is None or options is None or n_samples is None:
        raise ValueError(
            "demonstrations, learn_options and n_samples go together (what the skill was "
            "learned from): give all three or none"
        )
    try:
        demos = check_demonstrations(demonstrations, min_demos=2)
    except ValueError as exc:
        raise ValueError(f"{key('demonstrations')}: {exc}") from exc
    first = demos[0]
    if first.n_joints != n_joints:
        raise ValueError(
            f"{key('demonstrations.joints')}: the demonstrations have {first.n_joints} joints, "
            f"the skill {n_joints}"
        )
    if (first.gripper is not None) != has_gripper:
        raise ValueError(
            f"{key('demonstrations.gripper')}: the demonstrations "
            f"{'have a' if first.gripper is not None else 'have no'} gripper signal, the skill "
            f"{'has' if has_gripper else 'has none'}"
        )
    recorded = list(first.object_names)
    missing = [k for k in object_names if k not in recorded]
    if missing:
        raise ValueError(
            f"{key('demonstrations.object_names')}: the demonstrations record the objects "
            f"{recorded}, not the skill's {missing}"
        )
    opts = check_learn_options(options, k_max=k_max, key=key)
    if opts["n_steps"] != n_steps:
        raise ValueError(f"{key('n_steps')} is {opts['n_steps']}, the skill has {n_steps} steps")
    if resolve_task_objects(opts["task_objects"], recorded) != list(object_names):
        raise ValueError(
            f"{key('task_objects')} is {opts['task_objects']}, the skill's objects are "
            f"{list(object_names)}"
        )
    posed = [k for k in object_names if opts["orientation"] and is_pose(first.objects[k])]
    if set(posed) != set(oriented):
        raise ValueError(
            f"{key('demonstrations.poses')} and {key('orientation')}: learning with "
            f"orientation={opts['orientation']} orients the constraints of {posed}, the skill "
            f"those of {sorted(oriented)}"
        )
    opts["task_objects"] = list(object_names)  # None: all of them, resolved
    counts = _check_n_samples(n_samples, [JOINT, *object_names], len(demos) * n_steps, key)
    return LearnedFrom(demos, opts, counts)


def _argument_name(name: str) -> str:
    """How :class:`pbdkit.Skill`'s messages name what a skill was learned from: its
    constructor's arguments."""
    if name.startswith("demonstrations") or name == "n_samples":
        return name.split(".")[0]
    return f"learn_options['{name}']"


def _check_n_samples(
    n_samples: Mapping[str, object], spaces: list[str], most: int, key: Callable[[str], str]
) -> dict[str, int]:
    """``n_samples``: an integer in [1, ``most``] (every demonstration at every step) for each
    space."""
    if not isinstance(n_samples, Mapping) or sorted(n_samples) != sorted(spaces):
        shown = sorted(n_samples) if isinstance(n_samples, Mapping) else short(n_samples)
        raise ValueError(f"{key('n_samples')} must give a count for {spaces}, got {shown}")
    name = key("n_samples")
    return {
        k: check_int(n_samples[k], f"{name}[{short(k)}]", minimum=1, maximum=most) for k in spaces
    }


def learned_from(
    demonstrations: Sequence[Demonstration] | None, options: LearnOptions | None, what: str
) -> tuple[list[Demonstration], LearnOptions]:
    """Copies of the demonstrations and options a skill was learned from, for ``what`` (a
    method's name); ValueError, one line, for a skill that does not keep them."""
    if demonstrations is None or options is None:
        raise ValueError(
            "this skill does not keep its demonstrations (a skill file of version 1 or 2, or a "
            f"skill built by hand): re-learn it with Skill.learn to use {what}"
        )
    return list(demonstrations), copy.deepcopy(options)
