"""What a motion limit may be: a number > 0 per joint (or inf: not limited) within
:data:`LIMIT_RANGES`, checked where limits are given (:func:`positive_bounds`,
:func:`check_limit_range`) and by :class:`pbdkit.motion._limits.MotionLimits`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ._validation import check_array, short

__all__ = ["LIMIT_RANGES", "UNITS", "check_limit_range", "names_of", "positive_bounds"]

Float = NDArray[np.float64]
#: The range of a finite limit, per kind: (lowest, highest) in rad/s, rad/s^2, rad/s^3 (inf: not
#: limited). Every real arm is well inside (the Katana: 1.19, 6, 60; a Franka Panda: 2.6, 15,
#: 7500), and a limit of 1e9 never binds (the way to say so is inf). Beyond it no timing works
#: (issue 36: a limit of 1e-300 was accepted as > 0 and a reproduction died inside Ruckig; the
#: generator fails on a velocity limit of 1e-4 rad/s and on a jerk limit of 1e300), and at the
#: lowest limits an arm already takes hours to move a radian.
LIMIT_RANGES: Mapping[str, tuple[float, float]] = MappingProxyType(
    {"velocity": (1e-3, 1e9), "acceleration": (1e-3, 1e9), "jerk": (1e-2, 1e9)}
)
#: The unit of each kind of limit, for the messages.
UNITS = MappingProxyType({"velocity": "rad/s", "acceleration": "rad/s^2", "jerk": "rad/s^3"})


def check_limit_range(
    arr: Float, kind: str, name: str, joint_names: Sequence[str] | None = None
) -> None:
    """Every finite value of ``arr`` (limits of kind ``kind``: "velocity", "acceleration" or
    "jerk") within :data:`LIMIT_RANGES`; else a ValueError naming ``name``, the joint (by name
    when ``joint_names`` are given), the range and the value."""
    low, high = LIMIT_RANGES[kind]
    bad = np.flatnonzero(np.isfinite(arr) & ((arr < low) | (arr > high)))
    if not bad.size:
        return
    i = int(bad[0])
    joint = ""
    if joint_names is not None and i < len(joint_names):
        joint = f" (joint {short(joint_names[i])})"
    raise ValueError(
        f"{name}[{i}]{joint} must be in [{low:g}, {high:g}] {UNITS[kind]} (LIMIT_RANGES, "
        f"around every real arm's; inf: not limited), got {short(float(arr[i]))}"
    )


def names_of(robot: object) -> list[str] | None:
    """The robot's joint names for a message, if it has them."""
    names = getattr(robot, "joint_names", None)
    try:
        return [str(k) for k in names] if names is not None else None
    except TypeError:
        return None


def positive_bounds(value: npt.ArrayLike, n: int, name: str, unit: str) -> Float:
    """A number or (n,) values, each > 0 or inf (unbounded) -> ndarray (n,)."""
    scalar = np.ndim(value) == 0
    arr = check_array(value, name, ndim=(0, 1), finite=False)
    if scalar:
        arr = np.full(n, arr.item())
    elif arr.shape[0] != n:
        raise ValueError(
            f"{name} must be a number or have shape ({n},) (one value per joint), "
            f"got shape ({arr.shape[0]},)"
        )
    bad = np.flatnonzero(~(arr > 0))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{name}[{i}] must be > 0 ({unit}; inf leaves that joint unbounded), got {arr[i]:.6g}"
        )
    return arr
