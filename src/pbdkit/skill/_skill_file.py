"""The skill file, a ``pbdkit-skill`` ``.npz`` archive: a skill's arrays (:func:`skill_arrays`)
and the skill they hold (:func:`read_skill`), judged from the archive's headers before an array
is loaded. Version 3 keeps what the skill was learned from (:mod:`pbdkit.skill._provenance`):
the demonstrations (the arrays of a demonstrations file, their keys after ``demos_``), the
options of :meth:`pbdkit.Skill.learn` (``learn_*``) and each space's sample count
(``n_samples``). Its keys: :doc:`/reproduction`, "File formats".
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from .._defaults import MAX_COMPONENTS
from .._io import NpzArchive, check_format
from .._rotations import check_rotation
from .._validation import short
from ..data._demonstration import Demonstration, demonstration_arrays, demonstrations_from_arrays
from ..prob import GMM, ModelSelection
from ..reproduction._constraints import JOINT
from ..robots._protocols import KinematicModel, PoseKinematicModel, RobotDescription, check_robot
from ._calibration import check_calibration
from ._provenance import LEARN_OPTIONS, LearnedFrom, LearnOptions, check_learned_from
from ._spaces import MAX_STEPS, Alignment, duration_problem

__all__ = [
    "DEMOS_PREFIX",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_DURATION",
    "MAX_FILE_BYTES",
    "MAX_FILE_COMPONENTS",
    "READABLE_VERSIONS",
    "SkillState",
    "StoredSkill",
    "read_skill",
    "skill_arrays",
    "skill_duration_problem",
]

Float = NDArray[np.float64]
#: The most bytes the arrays of a skill file may take once loaded (:func:`read_skill`), read
#: from the archive's headers before anything is loaded. A skill holds a few GMMs, a URDF and
#: limits: kilobytes to a few megabytes.
MAX_FILE_BYTES = 64 * 2**20
FORMAT_NAME = "pbdkit-skill"
FORMAT_VERSION = 3
#: The versions :meth:`pbdkit.Skill.load` reads (1: positions only; 2: oriented constraints too;
#: 3: what the skill was learned from too).
READABLE_VERSIONS = (1, 2, 3)
#: The prefix of the demonstrations' keys in a version-3 file (``demos_n_demos``,
#: ``demos_demo_0_t``, ...: :func:`pbdkit.data._demonstration.demonstration_arrays`).
DEMOS_PREFIX = "demos_"
#: The longest duration (s) of a skill (:meth:`pbdkit.Skill.learn`, :meth:`pbdkit.Skill.load`,
#: :class:`pbdkit.Skill`): 317 years, where demonstrations last seconds to minutes, and still
#: beyond a bag's int32 seconds (2**31 s, which ``pbdkit reproduce --bag`` checks). A file's
#: duration of 1e300 s made reproductions' velocities NaN (from about 1e200 s on).
MAX_DURATION = 1e10
#: The largest K of a GMM that :meth:`pbdkit.Skill.load` (and :meth:`pbdkit.Skill.learn`) accept,
#: far above the K learning chooses (1 .. :data:`pbdkit._defaults.MAX_COMPONENTS` = 30 by
#: default): a reproduction's memory grows as K times n_steps (a 46 MB file of K = 100,000 made
#: ``reproduce`` allocate 3.6 GB).
MAX_FILE_COMPONENTS = 1000


def skill_duration_problem(duration: float, n_steps: int) -> str:
    """Why a skill cannot last ``duration`` seconds over ``n_steps`` (>= 2) steps ("" if it
    can): :func:`~pbdkit.skill._spaces.duration_problem` (finite, > 0, a step of at least
    ``MIN_STEP_SECONDS``), and at most :data:`MAX_DURATION`."""
    if math.isfinite(duration) and duration > MAX_DURATION:
        return (
            f"the duration must be at most MAX_DURATION = {MAX_DURATION:g} s, "
            f"got {short(duration)} s"
        )
    return duration_problem(duration, n_steps)


class SkillState(Protocol):
    """What :func:`skill_arrays` reads of a skill (a :class:`pbdkit.Skill`)."""

    robot: KinematicModel
    gmms: dict[str, GMM]
    n_steps: int
    object_names: list[str]
    has_gripper: bool
    reach: float
    duration: float
    rotation_base: dict[str, Float]
    aligned_: Alignment
    calibration_: dict[str, Float]
    demonstrations_: list[Demonstration] | None
    learn_options_: LearnOptions | None
    n_samples_: dict[str, int] | None


def skill_arrays(skill: SkillState) -> dict[str, Any]:
    """The arrays of a skill's file, by key (:meth:`pbdkit.Skill.save`).

    The robot is stored as its URDF text and tip frame when it is a
    :class:`~pbdkit.robots.RobotDescription` (a :class:`pbdkit.Robot`); otherwise
    :meth:`~pbdkit.Skill.load` needs the robot again. Its velocity, acceleration and jerk limits
    are stored too (a value that is not > 0, such as a URDF's 0, as inf: no limit). A skill that
    keeps what it was learned from is written as version 3; one that does not as version 2
    (oriented constraints) or 1, which older versions of pbdkit read.
    """
    robot, object_names, rotation_base = skill.robot, skill.object_names, skill.rotation_base
    aligned, calibration = skill.aligned_, skill.calibration_
    n_joints = int(robot.n_joints)
    # The one place a robot is asked what it is: one built from a URDF is rebuilt from it.
    urdf = tip = ""
    srdf: str | None = None
    if isinstance(robot, RobotDescription):
        urdf, tip = robot.urdf, robot.tip
        srdf = getattr(robot, "srdf", None)  # a pbdkit.Robot's disabled collision pairs
    limits: dict[str, NDArray[np.float64]] = {}
    for kind, value in (
        ("velocity", robot.velocity_limit),
        ("acceleration", robot.acceleration_limit),
        ("jerk", robot.jerk_limit),
    ):
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape == (n_joints,):
            limits[f"robot_{kind}_limit"] = np.where(arr > 0, arr, np.inf)
    arrays: dict[str, Any] = {
        "format": np.array(FORMAT_NAME),
        # Without what it was learned from: version 2, or 1 for positions only, as before
        # (older readers load it).
        "version": np.array(
            FORMAT_VERSION if skill.demonstrations_ is not None else 2 if rotation_base else 1,
            dtype=np.int64,
        ),
        "n_steps": np.array(skill.n_steps, dtype=np.int64),
        "n_joints": np.array(n_joints, dtype=np.int64),
        "object_names": np.array(object_names, dtype=np.str_)
        if object_names
        else np.zeros(0, dtype="<U1"),
        "has_gripper": np.array(skill.has_gripper),
        "reach": np.array(skill.reach),
        "duration": np.array(skill.duration),
        "robot_urdf": np.array(urdf if isinstance(urdf, str) else ""),
        "robot_tip": np.array(tip if isinstance(tip, str) else ""),
        **({"robot_srdf": np.array(srdf)} if isinstance(srdf, str) and srdf else {}),
        **limits,
        # What learning did about timing (optional: files of before it have none).
        "aligned_requested": np.array(aligned.requested),
        "aligned_applied": np.array(aligned.applied),
        "aligned_band": np.array(aligned.band),
        "aligned_reference": np.array(aligned.reference),
        "aligned_spreads": np.array([aligned.spread_linear, aligned.spread_aligned]),
    }
    for i, k in enumerate([JOINT, *object_names]):
        key = "joint" if k == JOINT else str(i - 1)
        g = skill.gmms[k]
        arrays[f"gmm_{key}_weights"] = g.weights_
        arrays[f"gmm_{key}_means"] = g.means_
        arrays[f"gmm_{key}_covariances"] = g.covariances_
        sel = g.selection_
        arrays[f"sel_{key}_method"] = np.array(sel.method)
        arrays[f"sel_{key}_candidates"] = np.asarray(sel.candidates, dtype=np.int64)
        arrays[f"sel_{key}_scores"] = np.asarray(sel.scores, dtype=np.float64)
        arrays[f"sel_{key}_fold_scores"] = np.asarray(sel.fold_scores, dtype=np.float64)
        arrays[f"sel_{key}_best_chosen"] = np.array([sel.best, sel.chosen], dtype=np.int64)
        arrays[f"sel_{key}_start"] = np.array(sel.start)
        if k in rotation_base:
            arrays[f"rot_base_{key}"] = rotation_base[k]
        if k in calibration and np.any(calibration[k] != 1.0):  # optional: ones without it
            arrays[f"calib_{key}"] = calibration[k]
    if skill.demonstrations_ is not None:
        assert skill.learn_options_ is not None and skill.n_samples_ is not None  # all or none
        arrays.update(demonstration_arrays(skill.demonstrations_, DEMOS_PREFIX))
        arrays.update(_options_arrays(skill.learn_options_))
        spaces = [JOINT, *object_names]
        arrays["n_samples"] = np.array([skill.n_samples_[k] for k in spaces], dtype=np.int64)
    return arrays


def _options_arrays(options: LearnOptions) -> dict[str, Any]:
    """``learn_*``: the options of :meth:`pbdkit.Skill.learn` as plain arrays (n_steps and
    task_objects are the skill's ``n_steps`` and ``object_names``); None is no key."""
    arrays: dict[str, Any] = {
        "learn_n_components": np.array(options["n_components"])
        if isinstance(options["n_components"], str)
        else np.array(options["n_components"], dtype=np.int64),
        "learn_max_components": np.array(options["max_components"], dtype=np.int64),
        "learn_bic_samples_per_sequence": np.array(
            options["bic_samples_per_sequence"], dtype=np.float64
        ),
        "learn_orientation": np.array(options["orientation"]),
        "learn_align": np.array(options["align"]),
        "learn_calibrate": np.array(options["calibrate"]),
    }
    reg = options["reg_covar"]
    if isinstance(reg, dict):
        arrays["learn_reg_covar_names"] = np.array(list(reg), dtype=np.str_).reshape(-1)
        arrays["learn_reg_covar"] = np.array(list(reg.values()), dtype=np.float64).reshape(-1)
    elif reg is not None:
        arrays["learn_reg_covar"] = np.array(reg, dtype=np.float64)
    if options["random_state"] is not None:
        arrays["learn_random_state"] = np.array(options["random_state"], dtype=np.int64)
    if options["fit_samples"] is not None:
        arrays["learn_fit_samples"] = np.array(options["fit_samples"], dtype=np.int64)
    return arrays


@dataclass(frozen=True, kw_only=True)
class StoredSkill:
    """What a skill file holds: the arguments of :class:`pbdkit.Skill` (:func:`read_skill`)."""

    robot: KinematicModel
    gmms: dict[str, GMM]
    n_steps: int
    object_names: list[str]
    has_gripper: bool
    reach: float
    duration: float
    rotation_base: dict[str, Float]
    aligned: Alignment
    calibration: dict[str, Float]
    demonstrations: list[Demonstration] | None
    learn_options: LearnOptions | None
    n_samples: dict[str, int] | None


def read_skill(data: NpzArchive, p: Path, robot: KinematicModel | None) -> StoredSkill:
    """The skill in an open archive (:meth:`pbdkit.Skill.load`), checked: ``robot`` as given
    (a :class:`~pbdkit.robots.KinematicModel`, a :class:`~pbdkit.robots.PoseKinematicModel` for
    oriented constraints), else rebuilt from the stored URDF, tip frame and limits."""
    from ..robots._joint_limits import check_limit_array, joint_limits_mapping

    version = check_format(data, p, FORMAT_NAME, READABLE_VERSIONS)
    try:
        names = [str(s) for s in np.asarray(data["object_names"]).reshape(-1)]
    except KeyError as exc:
        raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: missing key {exc}") from exc
    data.check_keys(functools.partial(_is_skill_key, n_objects=len(names), version=version))
    _check_headers(data, p)
    try:
        n_steps = _stored_int(data["n_steps"])
        if n_steps is None or not 2 <= n_steps <= MAX_STEPS:
            raise ValueError(
                f"n_steps must be an integer in [2, {MAX_STEPS}], got {_shown(data['n_steps'])}"
            )
        n_joints = _stored_int(data["n_joints"])
        if n_joints is None or n_joints < 1:
            raise ValueError(f"n_joints must be an integer >= 1, got {_shown(data['n_joints'])}")
        has_gripper = bool(data["has_gripper"])
        reach = float(data["reach"])
        duration = float(data["duration"]) if "duration" in data else float("nan")
        urdf = str(data["robot_urdf"])
        tip = str(data["robot_tip"])
        srdf = str(data["robot_srdf"]) if "robot_srdf" in data else None
        gmms: dict[str, GMM] = {}
        rotation_base: dict[str, Float] = {}
        calibration: dict[str, Float] = {}
        for i, k in enumerate([JOINT, *names]):
            key = "joint" if k == JOINT else str(i - 1)
            gmms[k] = GMM.from_params(
                data[f"gmm_{key}_weights"],
                data[f"gmm_{key}_means"],
                data[f"gmm_{key}_covariances"],
            )
            if f"sel_{key}_method" in data:  # files before the selection was recorded lack it
                gmms[k].selection_ = _selection_from_arrays(data, key, k)
            if version >= 2 and f"rot_base_{key}" in data:
                rotation_base[k] = check_rotation(data[f"rot_base_{key}"], f"rot_base_{key}")
            if f"calib_{key}" in data:
                calibration[k] = np.asarray(data[f"calib_{key}"], dtype=np.float64)
        calibration = check_calibration(calibration, [JOINT, *names], n_steps)
    except KeyError as exc:
        raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: missing key {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {exc}") from exc
    if len(set(names)) != len(names) or JOINT in names or "" in names:
        raise ValueError(
            f"{p} is not a valid {FORMAT_NAME} file: object names {names} must be unique, "
            f"non-empty and not {short(JOINT)}"
        )
    d_joint = 1 + n_joints + int(has_gripper)
    dims = {k: int(g.means_.shape[1]) for k, g in gmms.items()}
    expected = {k: (d_joint if k == JOINT else 7 if k in rotation_base else 4) for k in gmms}
    if dims != expected:
        raise ValueError(
            f"{p} is not a valid {FORMAT_NAME} file: GMM dimensions {dims}, expected "
            f"{expected} for n_joints={n_joints}, gripper={has_gripper} (time, then "
            "the joints and the gripper; time and x - o for an object; time, R^T (x - p) "
            "and the relative orientation for an oriented object)"
        )
    # NaN: unknown (a skill learned before durations were stored); else as learn checks it.
    problem = "" if math.isnan(duration) else skill_duration_problem(duration, n_steps)
    if problem:
        raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {problem}")
    if not (np.isfinite(reach) and reach > 0):
        raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: reach must be > 0, got {reach}")
    stored_limits: dict[str, NDArray[np.float64]] = {}
    for kind in ("velocity", "acceleration", "jerk"):
        name = f"robot_{kind}_limit"
        if name in data:  # files written before the limits were stored lack them
            try:
                stored_limits[kind] = check_limit_array(data[name], name, n_joints)
            except ValueError as exc:
                raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {exc}") from exc
    if robot is None:
        if not urdf:
            raise ValueError(
                f"{p} holds no URDF (the skill was learned with a robot not built from a "
                "URDF): pass robot= to Skill.load"
            )
        from ..robots._robot import Robot

        try:
            robot = Robot.from_urdf(urdf, tip=tip or None, srdf=srdf)
            if stored_limits and robot.n_joints == n_joints:  # else refused below
                limits = joint_limits_mapping(robot.joint_names, **stored_limits)
                robot = Robot.from_urdf(urdf, tip=tip or None, joint_limits=limits, srdf=srdf)
        except ValueError as exc:
            raise ValueError(
                f"{p} is not a valid {FORMAT_NAME} file: its robot URDF does not load: {exc}"
            ) from exc
    else:
        check_robot(robot, PoseKinematicModel if rotation_base else KinematicModel)
    if int(robot.n_joints) != n_joints:
        raise ValueError(f"robot has {robot.n_joints} joints, the skill in {p} has {n_joints}")
    learned = None
    if version >= 3:
        try:
            learned = _read_learned(
                data,
                n_joints=n_joints,
                has_gripper=has_gripper,
                object_names=names,
                oriented=rotation_base,
                n_steps=n_steps,
            )
        except KeyError as exc:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: missing key {exc}") from exc
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {exc}") from exc
    return StoredSkill(
        robot=robot,
        gmms=gmms,
        n_steps=n_steps,
        object_names=names,
        has_gripper=has_gripper,
        reach=reach,
        duration=duration,
        rotation_base=rotation_base,
        aligned=_read_alignment(data, p),
        calibration=calibration,
        demonstrations=None if learned is None else learned.demonstrations,
        learn_options=None if learned is None else learned.options,
        n_samples=None if learned is None else learned.n_samples,
    )


def _read_learned(
    data: NpzArchive,
    *,
    n_joints: int,
    has_gripper: bool,
    object_names: list[str],
    oriented: Mapping[str, Float],
    n_steps: int,
) -> LearnedFrom:
    """What a version-3 file's skill was learned from, checked against the skill: the
    demonstrations as :func:`pbdkit.load_demonstrations` checks them, then as
    :meth:`pbdkit.Skill.learn` would (:func:`~pbdkit.skill._provenance.check_learned_from`)."""
    demos = demonstrations_from_arrays(
        data, posed=f"{DEMOS_PREFIX}demo_0_rotations" in data, prefix=DEMOS_PREFIX
    )
    options: dict[str, object] = {"n_steps": n_steps, "task_objects": list(object_names)}
    for name in LEARN_OPTIONS:
        key = f"learn_{name}"
        if name in options:
            continue
        if name in _OPTIONAL and key not in data:
            options[name] = None
        elif name == "reg_covar" and "learn_reg_covar_names" in data:
            options[name] = _reg_covar_mapping(data)
        else:
            options[name] = _stored_scalar(data, key, _OPTION_KINDS.get(name, "iu"))
    counts = np.asarray(data["n_samples"])
    spaces = [JOINT, *object_names]
    if counts.shape != (len(spaces),) or counts.dtype.kind not in "iu":
        raise ValueError(
            f"n_samples must hold {len(spaces)} integers (one per space, {spaces}), "
            f"got {_shown(counts)}"
        )
    learned = check_learned_from(
        demos,
        options,
        {k: int(c) for k, c in zip(spaces, counts, strict=True)},
        n_joints=n_joints,
        has_gripper=has_gripper,
        object_names=object_names,
        oriented=oriented,
        n_steps=n_steps,
        k_max=MAX_FILE_COMPONENTS,
        key=_learned_key,
    )
    assert learned is not None  # all three given
    return learned


#: The options a file may leave out: None.
_OPTIONAL = frozenset({"reg_covar", "random_state", "fit_samples"})
#: The dtype kinds of each option's 0-d array (the others: integers).
_OPTION_KINDS = {
    "n_components": "iuU",
    "reg_covar": "f",
    "bic_samples_per_sequence": "f",
    "orientation": "b",
    "align": "bU",
    "calibrate": "b",
}
#: The keys that hold what :func:`~pbdkit.skill._provenance.check_learned_from` names.
_LEARNED_KEYS = {
    "demonstrations": f"{DEMOS_PREFIX}n_demos",
    "demonstrations.joints": f"{DEMOS_PREFIX}demo_0_joints",
    "demonstrations.gripper": f"{DEMOS_PREFIX}has_gripper",
    "demonstrations.object_names": f"{DEMOS_PREFIX}object_names",
    "demonstrations.poses": f"{DEMOS_PREFIX}demo_0_rotations",
    "n_samples": "n_samples",
    "n_steps": "n_steps",
    "task_objects": "object_names",
}


def _learned_key(name: str) -> str:
    """The key of a version-3 file that holds ``name`` (an option: ``learn_{name}``)."""
    return _LEARNED_KEYS.get(name, f"learn_{name}")


def _stored_scalar(data: NpzArchive, key: str, kinds: str) -> object:
    """The value of a 0-d array of one of the dtype ``kinds`` (``"iu"``, ``"f"``, ``"b"``,
    ``"U"``), as a Python int, float, bool or str."""
    arr = np.asarray(data[key])
    if arr.shape != () or arr.dtype.kind not in kinds:
        names = {"i": "an integer", "u": "", "f": "a float", "b": "a boolean", "U": "a string"}
        wanted = " or ".join(names[k] for k in kinds if names[k])
        raise ValueError(f"{key} must hold {wanted}, got {_shown(arr)} of dtype {arr.dtype}")
    value: object = arr.item()
    return value


def _reg_covar_mapping(data: NpzArchive) -> dict[str, float]:
    """``reg_covar`` as a dict: ``learn_reg_covar_names`` (k,) and ``learn_reg_covar`` (k,)."""
    names = np.asarray(data["learn_reg_covar_names"])
    values = np.asarray(data["learn_reg_covar"])
    if names.ndim != 1 or (names.size and names.dtype.kind != "U"):
        raise ValueError(f"learn_reg_covar_names must be strings (k,), got {_shown(names)}")
    if values.shape != names.shape or values.dtype.kind != "f":
        raise ValueError(
            f"learn_reg_covar must be floats of the shape of learn_reg_covar_names "
            f"{names.shape}, got {_shown(values)} of dtype {values.dtype}"
        )
    if len(set(names.tolist())) != names.size:
        raise ValueError(f"learn_reg_covar_names must be distinct, got {names.tolist()}")
    return {str(k): float(v) for k, v in zip(names, values, strict=True)}


def _check_headers(data: NpzArchive, p: Path) -> None:
    """Refuse from the archive's headers, before an array is loaded, complex arrays (their
    conversion to real numbers would drop the imaginary part with a warning only) and GMMs of
    more than :data:`MAX_FILE_COMPONENTS` components."""
    bad = f"{p} is not a valid {FORMAT_NAME} file"
    for key, header in data.headers.items():
        if header.dtype.kind == "c":
            raise ValueError(f"{bad}: {key} must hold real numbers, got dtype {header.dtype}")
        if key.startswith("gmm_") and header.shape and header.shape[0] > MAX_FILE_COMPONENTS:
            raise ValueError(
                f"{bad}: {key} holds {header.shape[0]} components; a GMM may have at most "
                f"MAX_FILE_COMPONENTS = {MAX_FILE_COMPONENTS} (learning chooses K up to "
                f"max_components, {MAX_COMPONENTS} by default)"
            )


def _read_alignment(data: NpzArchive, p: Path) -> Alignment:
    """The file's :class:`Alignment` (a file of before alignment: not aligned)."""
    if "aligned_applied" not in data:
        return Alignment("no", False)
    try:
        requested = str(data["aligned_requested"])
        reference = str(data["aligned_reference"])
        applied = bool(data["aligned_applied"])
        band = float(data["aligned_band"])
        spreads = np.asarray(data["aligned_spreads"], dtype=np.float64).reshape(2)
    except (KeyError, ValueError, TypeError) as exc:
        raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: its alignment: {exc}") from exc
    if requested not in ("auto", "yes", "no") or reference not in ("medoid", "mean"):
        raise ValueError(
            f"{p} is not a valid {FORMAT_NAME} file: its alignment is {short(requested)} onto "
            f"{short(reference)}"
        )
    if not 0.0 < band <= 1.0:
        raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: alignment band {short(band)}")
    return Alignment(requested, applied, band, reference, float(spreads[0]), float(spreads[1]))


_BASE_KEYS = frozenset(
    {
        "format",
        "version",
        "n_steps",
        "n_joints",
        "object_names",
        "has_gripper",
        "reach",
        "duration",
        "robot_urdf",
        "robot_tip",
        "robot_srdf",
        "robot_velocity_limit",
        "robot_acceleration_limit",
        "robot_jerk_limit",
        "aligned_requested",
        "aligned_applied",
        "aligned_band",
        "aligned_reference",
        "aligned_spreads",
    }
)
# Version 3: what the skill was learned from.
_LEARNED_BASE_KEYS = frozenset(
    {"n_samples", "learn_reg_covar_names"}
    | {f"learn_{k}" for k in LEARN_OPTIONS if k not in ("n_steps", "task_objects")}
    | {f"{DEMOS_PREFIX}{k}" for k in ("n_demos", "object_names", "has_gripper")}
)
_DEMOS_KEY = re.compile(
    re.escape(DEMOS_PREFIX) + r"demo_(0|[1-9][0-9]{0,8})_(?:t|joints|objects|rotations|gripper)"
)
# gmm_{space}_{array} and sel_{space}_{array}: space "joint", or an object's index.
_SPACE_KEY = re.compile(
    r"(?:gmm_(?:joint|(0|[1-9][0-9]{0,8}))_(?:weights|means|covariances)"
    r"|sel_(?:joint|(0|[1-9][0-9]{0,8}))_(?:method|candidates|scores|fold_scores|best_chosen|start)"
    r"|rot_base_(0|[1-9][0-9]{0,8})"
    r"|calib_(?:joint|(0|[1-9][0-9]{0,8})))"
)


def _is_skill_key(key: str, n_objects: int, version: int) -> bool:
    """Whether :meth:`pbdkit.Skill.save` writes ``key`` for a skill of ``n_objects`` objects in
    a file of ``version`` (the demonstrations' indices are judged by their own reader)."""
    if key in _BASE_KEYS:
        return True
    if version >= 3 and (key in _LEARNED_BASE_KEYS or _DEMOS_KEY.fullmatch(key)):
        return True
    match = _SPACE_KEY.fullmatch(key)
    if match is None:
        return False
    index = match.group(1) or match.group(2) or match.group(3) or match.group(4)
    return index is None or int(index) < n_objects


def _stored_int(value: NDArray[Any]) -> int | None:
    """The integer stored in a 0-d integer array of a file, or None if it holds anything else."""
    arr = np.asarray(value)
    return int(arr) if arr.shape == () and arr.dtype.kind in "iu" else None


def _shown(value: NDArray[Any]) -> str:
    arr = np.asarray(value)
    return repr(arr.tolist()) if arr.size <= 6 else f"an array of shape {arr.shape}"


def _selection_from_arrays(data: Mapping[str, Any], key: str, name: str) -> ModelSelection:
    """The ModelSelection stored under ``sel_{key}_*`` by :meth:`pbdkit.Skill.save`."""
    method = str(data[f"sel_{key}_method"])
    cand = np.asarray(data[f"sel_{key}_candidates"]).reshape(-1)
    scores = np.asarray(data[f"sel_{key}_scores"], dtype=np.float64).reshape(-1)
    folds = np.asarray(data[f"sel_{key}_fold_scores"], dtype=np.float64)
    best, chosen = (int(v) for v in np.asarray(data[f"sel_{key}_best_chosen"]).reshape(-1)[:2])
    # Files before the second start was recorded lack it: their sweeps all began at equal counts.
    start = str(data[f"sel_{key}_start"]) if f"sel_{key}_start" in data else "equal counts"
    if (
        method not in ("cv", "bic", "fixed")
        or cand.dtype.kind not in "iu"
        or scores.shape != cand.shape
        or folds.ndim != 2
        or (folds.size and folds.shape[0] != cand.shape[0])
        or best not in cand
        or chosen not in cand
        or start not in ("equal counts", "segments")
    ):
        raise ValueError(f"the model selection stored for {short(name)} is inconsistent")
    n_folds = folds.shape[1] if method == "cv" else 0
    cands = tuple(int(k) for k in cand)
    return ModelSelection(method, cands, scores, folds, best, chosen, n_folds, start)
