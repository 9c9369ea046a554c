"""Joint limits in the ``joint_limits.yaml`` format of MoveIt and ros2_control (private).

A URDF gives position, velocity and effort limits only; MoveIt and ros2_control read velocity,
acceleration and jerk limits (and optionally position limits) from a YAML file::

    joint_limits:
      panda_joint1:
        has_velocity_limits: true
        max_velocity: 2.175
        has_acceleration_limits: true
        max_acceleration: 15.0
        has_jerk_limits: true
        max_jerk: 7500.0

:func:`read_joint_limits` parses such a file, its text or an already-parsed mapping of the same
structure into one :class:`JointLimits` per named joint; :func:`joint_limits_mapping` writes
arrays back into that structure (how a :class:`pbdkit.Robot` is pickled and a skill file's limits
are passed back); :func:`limits_on_chain` matches the names to a robot's joints. The YAML is read
with PyYAML's safe loader only (libyaml's where present): loading it cannot run code. A file or
text over :data:`MAX_YAML_BYTES` is refused unread.

Rules (those of MoveIt and ros2_control unless said otherwise):

- ``has_X_limits: true`` needs ``max_X``, a number > 0 (``.inf``: no limit);
- ``has_X_limits: false`` means no limit (inf), even if ``max_X`` is present;
- ``has_X_limits`` absent: the joint keeps what it has without the file (the URDF's velocity and
  position limits; no acceleration or jerk limit). A ``max_X`` (or ``min_position``) without
  its ``has_X_limits`` is refused: MoveIt and ros2_control would silently ignore it;
- ``has_position_limits: true`` with finite ``min_position <= max_position`` replaces the URDF's
  position limits; ``false`` keeps them (a :class:`pbdkit.Robot` needs finite position limits);
- a joint name the URDF does not have is refused (a typo, or a file for another arm, would
  otherwise leave the arm unlimited); a joint of the URDF off the arm's chain (a finger) is
  ignored;
- other keys (``has_effort_limits``/``max_effort``, ``has_deceleration_limits``/
  ``max_deceleration``, soft limits, a top-level ``default_velocity_scaling_factor``, ...) are
  accepted and not used.
"""

from __future__ import annotations

import math
import numbers
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._limit_values import LIMIT_RANGES
from .._validation import short
from .._yaml import parse_yaml, read_capped_text

__all__ = [
    "JointLimits",
    "JointLimitsSource",
    "check_limit_array",
    "joint_limits_mapping",
    "limits_on_chain",
    "read_joint_limits",
]

#: What ``joint_limits=`` accepts: a path to a YAML file, the YAML text, or a parsed mapping.
JointLimitsSource = str | os.PathLike[str] | Mapping[str, Any]

#: Derivative limits a joint may declare, with their units (revolute joints; m for prismatic).
KINDS = {"velocity": "rad/s", "acceleration": "rad/s^2", "jerk": "rad/s^3"}

#: The largest joint_limits file (bytes) or YAML text (characters) read: such a file is a few KB,
#: and loading one MB costs about 0.7 s and 50 MB with libyaml (its constructor is Python), 3-6 s
#: and 70 MB with the pure-Python loader.
MAX_YAML_BYTES = 1024 * 1024

# A string holding "joint_limits:" (or a newline) is YAML text, anything else a file path.
_LOOKS_LIKE_YAML = re.compile(r"\n|joint_limits['\"]?\s*:")


@dataclass(frozen=True)
class JointLimits:
    """The limits one joint declares in a joint_limits mapping.

    Each field is None when the mapping does not say (``has_X_limits`` absent), inf for
    ``has_X_limits: false`` (or ``max_X: .inf``), else the limit.

    Attributes
    ----------
    velocity, acceleration, jerk : float or None
        rad/s, rad/s^2, rad/s^3 (m/s, m/s^2, m/s^3 for a prismatic joint), > 0.
    position : tuple of float (lower, upper), or None
        Finite, lower <= upper; None also for ``has_position_limits: false``.
    """

    velocity: float | None = None
    acceleration: float | None = None
    jerk: float | None = None
    position: tuple[float, float] | None = None


def read_joint_limits(source: JointLimitsSource) -> dict[str, JointLimits]:
    """Parse a joint_limits YAML file, YAML text or mapping.

    Parameters
    ----------
    source : str, path-like or mapping
        A path to a ``joint_limits.yaml`` file, the YAML text itself (a string with a newline or
        ``joint_limits:``), or a mapping ``{"joint_limits": {joint name: {key: value}}}``.

    Returns
    -------
    limits : dict of str to JointLimits
        One entry per joint named in the source, in its order.

    Raises
    ------
    ValueError
        A missing or unreadable file, a file or text over :data:`MAX_YAML_BYTES`, text that is
        not YAML (or that the loader chokes on: nested too deeply, a 13th month), no
        ``joint_limits`` mapping, a ``has_*`` flag that is not a boolean, a flag set without its
        value, or a value that is not a number > 0 within the float range. The message names
        the source, the joint and the key.
    """
    data, label = _load(source)
    table = data.get("joint_limits") if isinstance(data, Mapping) else None
    if not isinstance(table, Mapping):
        if not isinstance(data, Mapping):
            where = f"the document is a {type(data).__name__}"
        elif "joint_limits" not in data:
            where = f"the 'joint_limits' key is missing (keys: {short(list(data))})"
        else:
            where = f"'joint_limits' holds a {type(table).__name__}"
        raise ValueError(
            f"{label} must hold a mapping 'joint_limits: {{joint name: {{key: value}}}}' "
            f"(MoveIt / ros2_control joint_limits.yaml); {where}"
        )
    out: dict[str, JointLimits] = {}
    for name, entry in table.items():
        where = f"{label}: joint {short(str(name))}"
        if not isinstance(entry, Mapping):
            raise ValueError(
                f"{where} must map keys such as max_velocity to values, got "
                f"{type(entry).__name__} {short(entry)}"
            )
        derivatives = {kind: _derivative(entry, kind, where) for kind in KINDS}
        out[str(name)] = JointLimits(**derivatives, position=_position(entry, where))
    return out


def limits_on_chain(
    declared: Mapping[str, JointLimits],
    chain: Sequence[str],
    urdf_joints: Sequence[str],
    source: JointLimitsSource,
) -> dict[str, JointLimits]:
    """The declared limits of the chain's joints; a name the URDF does not have is refused.

    Parameters
    ----------
    declared : mapping of str to JointLimits
        What :func:`read_joint_limits` returned for ``source``.
    chain : sequence of str
        The robot's joint names (the joints that move its tip).
    urdf_joints : sequence of str
        Every joint name of the URDF: a declared joint among them but off the chain (a finger)
        is ignored, as MoveIt's files name the joints of every group.
    source : str, path-like or mapping
        The joint_limits source, to name it in the message.

    Returns
    -------
    on_chain : dict of str to JointLimits
        The entries of ``declared`` named in ``chain``.

    Raises
    ------
    ValueError
        A declared name that is no joint of the URDF (a typo, or a file for another arm would
        leave the joint without its limits): the message names it and the robot's joints.
    """
    known = set(urdf_joints)
    unknown = [name for name in declared if name not in known]
    if unknown:
        joints = "joint" if len(unknown) == 1 else "joints"
        raise ValueError(
            f"{_label(source)} names {len(unknown)} {joints} the URDF does not have: "
            f"{short(unknown)}; the robot's {len(chain)} joints are {short(list(chain))} (a "
            "typo, or a file for another arm?)"
        )
    return {name: declared[name] for name in chain if name in declared}


def joint_limits_mapping(
    joint_names: Sequence[str],
    velocity: npt.ArrayLike | None = None,
    acceleration: npt.ArrayLike | None = None,
    jerk: npt.ArrayLike | None = None,
) -> dict[str, Any]:
    """Per-joint limit arrays as a joint_limits mapping (inf: ``has_X_limits: false``).

    Parameters
    ----------
    joint_names : sequence of str, length n
    velocity, acceleration, jerk : array-like, shape (n,), optional
        Limits > 0 or inf; None leaves that kind out of the mapping (the joint keeps what it has).

    Returns
    -------
    mapping : dict
        ``{"joint_limits": {name: {"has_velocity_limits": bool, "max_velocity": float, ...}}}``,
        readable by :func:`read_joint_limits`.
    """
    table: dict[str, dict[str, Any]] = {str(name): {} for name in joint_names}
    for kind, values in (("velocity", velocity), ("acceleration", acceleration), ("jerk", jerk)):
        if values is None:
            continue
        arr = _float_array(values, kind)
        if arr.shape != (len(table),):
            raise ValueError(
                f"{kind} must have shape ({len(table)},) (one value per joint), got {arr.shape}"
            )
        for entry, value in zip(table.values(), arr.tolist(), strict=True):
            entry[f"has_{kind}_limits"] = bool(math.isfinite(value))
            if math.isfinite(value):
                entry[f"max_{kind}"] = value
    return {"joint_limits": table}


def _float_array(values: npt.ArrayLike, kind: str) -> NDArray[np.float64]:
    """``values`` as a flat float64 array; ValueError naming ``kind`` if they are not numbers."""
    try:
        return np.asarray(values, dtype=np.float64).reshape(-1)
    except (OverflowError, TypeError, ValueError) as exc:  # 10**400, a string, ragged lists
        raise ValueError(
            f"{kind} must be numbers within the float range, one per joint, got {short(values)}"
        ) from exc


def check_limit_array(value: npt.ArrayLike, name: str, n_joints: int) -> NDArray[np.float64]:
    """A stored per-joint limit array: float64 (n_joints,), each value > 0 or inf.

    Parameters
    ----------
    value : array-like, shape (n_joints,)
    name : str
        The array's name in error messages.
    n_joints : int

    Returns
    -------
    limits : ndarray of float64, shape (n_joints,)

    Raises
    ------
    ValueError
        Another shape, values that are not numbers, or a value that is not > 0 (0, negative or
        NaN).
    """
    arr = np.asarray(value)
    if arr.shape != (n_joints,) or arr.dtype.kind not in "fiu":
        raise ValueError(
            f"{name} must be an array of numbers of shape ({n_joints},) (one per joint), got "
            f"{arr.dtype} of shape {arr.shape}"
        )
    out = arr.astype(np.float64)
    bad = np.flatnonzero(~(out > 0))
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{name}[{i}] must be > 0 (inf for no limit), got {short(float(out[i]))}")
    return out


def _label(source: JointLimitsSource) -> str:
    """How error messages name the source."""
    if isinstance(source, Mapping):
        return "joint_limits (mapping)"
    if isinstance(source, str) and _LOOKS_LIKE_YAML.search(source):
        return "joint_limits (YAML text)"
    if isinstance(source, str | os.PathLike):
        return f"joint_limits file '{Path(source)}'"
    raise ValueError(
        "joint_limits must be a path to a joint_limits.yaml file, its YAML text or a mapping, "
        f"got {type(source).__name__}"
    )


def _load(source: JointLimitsSource) -> tuple[Any, str]:
    """The parsed YAML (or the mapping as given) and how error messages name the source."""
    label = _label(source)
    if isinstance(source, Mapping):
        return source, label
    if isinstance(source, str) and _LOOKS_LIKE_YAML.search(source):
        text = source
        if len(text) > MAX_YAML_BYTES:
            raise ValueError(
                f"{label} has {len(text)} characters, over the cap of {MAX_YAML_BYTES} "
                "(MAX_YAML_BYTES; a joint_limits.yaml is a few KB)"
            )
    else:
        text = read_capped_text(
            Path(source),
            label,
            MAX_YAML_BYTES,
            "MAX_YAML_BYTES; a joint_limits.yaml is a few KB",
            "joint_limits.yaml path, the YAML text or a mapping",
        )
    return parse_yaml(text, label), label


def _flag(entry: Mapping[str, Any], key: str, where: str) -> bool | None:
    """A ``has_*`` flag: True, False, or None when absent."""
    if key not in entry:
        return None
    value = entry[key]
    if not isinstance(value, bool):
        raise ValueError(f"{where}: {key} must be true or false, got {short(value)}")
    return value


def _number(entry: Mapping[str, Any], key: str, where: str, flag: str) -> float:
    if key not in entry:
        raise ValueError(f"{where}: {flag} is true but {key} is missing; give {key}")
    value = entry[key]
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where}: {key} must be a number, got {short(value)}")
    try:
        return float(value)
    except OverflowError as exc:  # an int (or Fraction) such as 10**400
        raise ValueError(
            f"{where}: {key} must be a number within the float range (.inf for no limit), got "
            f"{short(value)}"
        ) from exc


def _derivative(entry: Mapping[str, Any], kind: str, where: str) -> float | None:
    flag, key = f"has_{kind}_limits", f"max_{kind}"
    has = _flag(entry, flag, where)
    if has is None:
        if key in entry:
            raise ValueError(
                f"{where}: {key} is given without {flag}; add '{flag}: true' to use it "
                f"('false' for no limit: MoveIt and ros2_control ignore {key} without it)"
            )
        return None
    if not has:
        return math.inf
    value = _number(entry, key, where, flag)
    if not value > 0:  # also NaN
        raise ValueError(
            f"{where}: {key} must be a number > 0 ({KINDS[kind]}; .inf for no limit), got "
            f"{short(value)}"
        )
    low, high = LIMIT_RANGES[kind]
    if math.isfinite(value) and not low <= value <= high:  # refused here, naming the file
        raise ValueError(
            f"{where}: {key} must be in [{low:g}, {high:g}] {KINDS[kind]} (LIMIT_RANGES, around "
            f"every real arm's; .inf for no limit), got {short(value)}"
        )
    return value


def _position(entry: Mapping[str, Any], where: str) -> tuple[float, float] | None:
    flag = "has_position_limits"
    has = _flag(entry, flag, where)
    if has is None:
        given = [key for key in ("min_position", "max_position") if key in entry]
        if given:
            raise ValueError(
                f"{where}: {' and '.join(given)} given without {flag}; add '{flag}: true' to "
                "use them (MoveIt and ros2_control ignore them without it)"
            )
    if not has:
        return None
    lower = _number(entry, "min_position", where, flag)
    upper = _number(entry, "max_position", where, flag)
    if not (math.isfinite(lower) and math.isfinite(upper) and lower <= upper):
        raise ValueError(
            f"{where}: min_position and max_position must be finite with min_position <= "
            f"max_position, got {short(lower)} and {short(upper)}"
        )
    return lower, upper
