"""The skill file, a ``pbdkit-skill`` ``.npz`` archive: a skill's arrays (:func:`skill_arrays`)
and the skill they hold (:func:`read_skill`), judged from the archive's headers before an array
is loaded. Its keys: :doc:`/reproduction`, "File formats".
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._defaults import MAX_COMPONENTS
from .._io import NpzArchive, check_format
from .._rotations import check_rotation
from .._validation import short
from ..prob import GMM, ModelSelection
from ..reproduction._constraints import JOINT
from ..robots._protocols import KinematicModel, PoseKinematicModel, RobotDescription, check_robot
from ._calibration import check_calibration
from ._spaces import MAX_STEPS, Alignment, duration_problem

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_DURATION",
    "MAX_FILE_BYTES",
    "MAX_FILE_COMPONENTS",
    "READABLE_VERSIONS",
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
FORMAT_VERSION = 2
#: The versions :meth:`pbdkit.Skill.load` reads (1: positions only; 2: oriented constraints too).
READABLE_VERSIONS = (1, 2)
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


def skill_arrays(
    robot: KinematicModel,
    gmms: Mapping[str, GMM],
    *,
    n_steps: int,
    object_names: Sequence[str],
    has_gripper: bool,
    reach: float,
    duration: float,
    rotation_base: Mapping[str, Float],
    aligned: Alignment,
    calibration: Mapping[str, Float],
) -> dict[str, Any]:
    """The arrays of a skill's file, by key (:meth:`pbdkit.Skill.save`).

    The robot is stored as its URDF text and tip frame when it is a
    :class:`~pbdkit.robots.RobotDescription` (a :class:`pbdkit.Robot`); otherwise
    :meth:`~pbdkit.Skill.load` needs the robot again. Its velocity, acceleration and jerk limits
    are stored too (a value that is not > 0, such as a URDF's 0, as inf: no limit).
    """
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
        # Positions only: version 1, as before orientations (older readers load it).
        "version": np.array(FORMAT_VERSION if rotation_base else 1, dtype=np.int64),
        "n_steps": np.array(n_steps, dtype=np.int64),
        "n_joints": np.array(n_joints, dtype=np.int64),
        "object_names": np.array(object_names, dtype=np.str_)
        if object_names
        else np.zeros(0, dtype="<U1"),
        "has_gripper": np.array(has_gripper),
        "reach": np.array(reach),
        "duration": np.array(duration),
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
        g = gmms[k]
        arrays[f"gmm_{key}_weights"] = g.weights_
        arrays[f"gmm_{key}_means"] = g.means_
        arrays[f"gmm_{key}_covariances"] = g.covariances_
        sel = g.selection_
        arrays[f"sel_{key}_method"] = np.array(sel.method)
        arrays[f"sel_{key}_candidates"] = np.asarray(sel.candidates, dtype=np.int64)
        arrays[f"sel_{key}_scores"] = np.asarray(sel.scores, dtype=np.float64)
        arrays[f"sel_{key}_fold_scores"] = np.asarray(sel.fold_scores, dtype=np.float64)
        arrays[f"sel_{key}_best_chosen"] = np.array([sel.best, sel.chosen], dtype=np.int64)
        if k in rotation_base:
            arrays[f"rot_base_{key}"] = rotation_base[k]
        if k in calibration and np.any(calibration[k] != 1.0):  # optional: ones without it
            arrays[f"calib_{key}"] = calibration[k]
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
    data.check_keys(functools.partial(_is_skill_key, n_objects=len(names)))
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
    )


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
# gmm_{space}_{array} and sel_{space}_{array}: space "joint", or an object's index.
_SPACE_KEY = re.compile(
    r"(?:gmm_(?:joint|(0|[1-9][0-9]{0,8}))_(?:weights|means|covariances)"
    r"|sel_(?:joint|(0|[1-9][0-9]{0,8}))_(?:method|candidates|scores|fold_scores|best_chosen)"
    r"|rot_base_(0|[1-9][0-9]{0,8})"
    r"|calib_(?:joint|(0|[1-9][0-9]{0,8})))"
)


def _is_skill_key(key: str, n_objects: int) -> bool:
    """Whether :meth:`pbdkit.Skill.save` writes ``key`` for a skill of ``n_objects`` objects."""
    if key in _BASE_KEYS:
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
    if (
        method not in ("cv", "bic", "fixed")
        or cand.dtype.kind not in "iu"
        or scores.shape != cand.shape
        or folds.ndim != 2
        or (folds.size and folds.shape[0] != cand.shape[0])
        or best not in cand
        or chosen not in cand
    ):
        raise ValueError(f"the model selection stored for {short(name)} is inconsistent")
    n_folds = folds.shape[1] if method == "cv" else 0
    return ModelSelection(method, tuple(int(k) for k in cand), scores, folds, best, chosen, n_folds)
