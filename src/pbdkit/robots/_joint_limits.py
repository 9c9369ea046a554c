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
are passed back). The YAML is read with ``yaml.safe_load`` only: loading it cannot run code.

Rules (those of MoveIt and ros2_control unless said otherwise):

- ``has_X_limits: true`` needs ``max_X``, a number > 0 (``.inf``: no limit);
- ``has_X_limits: false`` means no limit (inf), even if ``max_X`` is present;
- ``has_X_limits`` absent: the joint keeps what it has without the file (the URDF's velocity and
  position limits; no acceleration or jerk limit). A ``max_X`` (or ``min_position``) without
  its ``has_X_limits`` is refused: MoveIt and ros2_control would silently ignore it;
- ``has_position_limits: true`` with finite ``min_position <= max_position`` replaces the URDF's
  position limits; ``false`` keeps them (a :class:`pbdkit.Robot` needs finite position limits);
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
import yaml
from numpy.typing import NDArray

from .._validation import short

__all__ = [
    "JointLimits",
    "JointLimitsSource",
    "check_limit_array",
    "joint_limits_mapping",
    "read_joint_limits",
]

#: What ``joint_limits=`` accepts: a path to a YAML file, the YAML text, or a parsed mapping.
JointLimitsSource = str | os.PathLike[str] | Mapping[str, Any]

#: Derivative limits a joint may declare, with their units (revolute joints; m for prismatic).
KINDS = {"velocity": "rad/s", "acceleration": "rad/s^2", "jerk": "rad/s^3"}

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
        A missing or unreadable file, text that is not YAML, no ``joint_limits`` mapping, a
        ``has_*`` flag that is not a boolean, a flag set without its value, or a value that is
        not a number > 0. The message names the source, the joint and the key.
    """
    data, label = _load(source)
    table = data.get("joint_limits") if isinstance(data, Mapping) else None
    if not isinstance(table, Mapping):
        if not isinstance(data, Mapping):
            where = f"the document is a {type(data).__name__}"
        elif "joint_limits" not in data:
            where = f"the 'joint_limits' key is missing (keys: {list(data)})"
        else:
            where = f"'joint_limits' holds a {type(table).__name__}"
        raise ValueError(
            f"{label} must hold a mapping 'joint_limits: {{joint name: {{key: value}}}}' "
            f"(MoveIt / ros2_control joint_limits.yaml); {where}"
        )
    out: dict[str, JointLimits] = {}
    for name, entry in table.items():
        where = f"{label}: joint '{name}'"
        if not isinstance(entry, Mapping):
            raise ValueError(
                f"{where} must map keys such as max_velocity to values, got "
                f"{type(entry).__name__} {short(entry)}"
            )
        derivatives = {kind: _derivative(entry, kind, where) for kind in KINDS}
        out[str(name)] = JointLimits(**derivatives, position=_position(entry, where))
    return out


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
        arr = np.asarray(values, dtype=np.float64).reshape(-1)
        if arr.shape != (len(table),):
            raise ValueError(
                f"{kind} must have shape ({len(table)},) (one value per joint), got {arr.shape}"
            )
        for entry, value in zip(table.values(), arr.tolist(), strict=True):
            entry[f"has_{kind}_limits"] = bool(math.isfinite(value))
            if math.isfinite(value):
                entry[f"max_{kind}"] = value
    return {"joint_limits": table}


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


def _load(source: JointLimitsSource) -> tuple[Any, str]:
    """The parsed YAML (or the mapping as given) and how error messages name the source."""
    if isinstance(source, Mapping):
        return source, "joint_limits (mapping)"
    if isinstance(source, str) and _LOOKS_LIKE_YAML.search(source):
        text, label = source, "joint_limits (YAML text)"
    elif isinstance(source, str | os.PathLike):
        path = Path(source)
        label = f"joint_limits file '{path}'"
        if not path.is_file():
            what = "is a directory" if path.is_dir() else "does not exist"
            raise ValueError(
                f"{label} {what}; pass an existing joint_limits.yaml path, the YAML text or a "
                "mapping"
            )
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise ValueError(
                f"{label} is not UTF-8 text (byte {exc.start}: {exc.reason}); expected YAML"
            ) from exc
    else:
        raise ValueError(
            "joint_limits must be a path to a joint_limits.yaml file, its YAML text or a mapping, "
            f"got {type(source).__name__}"
        )
    try:
        return yaml.safe_load(text), label
    except yaml.YAMLError as exc:
        detail = " ".join(str(exc).split())
        raise ValueError(f"{label} is not valid YAML ({detail})") from exc


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
    return float(value)


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
