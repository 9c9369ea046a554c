"""Input validation shared by every public entry point.

Each ``check_*`` function returns the cleaned array (float64, C-contiguous) or raises a
``ValueError`` that names the argument, the expected value and the actual one.
"""

from __future__ import annotations

import reprlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

__all__ = [
    "RESERVED_NAMES",
    "check_array",
    "check_int",
    "check_object_names",
    "check_positions",
    "check_positive_float",
    "check_trajectories",
    "shape_str",
    "short",
]

#: How messages show a value: bounded in length and depth, whatever it is (a YAML alias bomb
#: of 0.5 KB expands into a nested list whose full repr is 312 MB).
_SHORT = reprlib.Repr()  # (keyword arguments only from Python 3.12)
_SHORT.maxlevel = 3
_SHORT.maxtuple = _SHORT.maxlist = _SHORT.maxarray = _SHORT.maxdeque = 8
_SHORT.maxdict = _SHORT.maxset = _SHORT.maxfrozenset = 8
_SHORT.maxstring = _SHORT.maxother = 200
_SHORT.maxlong = 40


def short(value: object) -> str:
    """``repr(value)`` for a message, bounded: at most 8 items a level, 3 levels, strings and
    other values (a path) at most 200 characters, and 300 in all (longer ones elided in the
    middle)."""
    try:
        text = _SHORT.repr(value)
    except Exception:  # a repr that raises: its type instead
        return f"<{type(value).__name__}>"
    return text if len(text) <= 300 else f"{text[:200]}...{text[-80:]}"


def shape_str(shape: Sequence[int | str | None]) -> str:
    """Format a shape for an error message: ``(T, 3)``; ``None`` entries print as ``*``."""
    parts = ["*" if s is None else str(s) for s in shape]
    if len(parts) == 1:
        return f"({parts[0]},)"
    return "(" + ", ".join(parts) + ")"


# dtype kinds of real numbers (float, signed and unsigned integers), and how the others read.
_REAL_KINDS = frozenset("fiu")
_KIND_NAMES = {
    "b": "booleans",
    "c": "complex (not real) values",
    "U": "strings",
    "S": "bytes",
    "M": "dates",
    "m": "time deltas",
    "V": "raw or structured records",
}


def check_array(
    x: npt.ArrayLike,
    name: str,
    *,
    ndim: int | tuple[int, ...] | None = None,
    shape: Sequence[int | None] | None = None,
    finite: bool = True,
    min_rows: int | None = None,
    allow_bool: bool = True,
) -> NDArray[np.float64]:
    """Convert ``x`` to a float64 array and check its shape and values.

    Real numbers only: complex values (whose imaginary part a conversion would drop), strings
    (which NumPy would parse) and dates are refused, and booleans unless ``allow_bool``.

    Parameters
    ----------
    x : array-like
        The value given by the user.
    name : str
        The argument's name, used in error messages.
    ndim : int or tuple of int, optional
        Allowed numbers of dimensions.
    shape : sequence of int or None, optional
        Expected shape; ``None`` entries match any size. Implies ``ndim``.
    finite : bool
        Reject NaN and infinite values.
    min_rows : int, optional
        Minimum size of the first axis.
    allow_bool : bool
        Accept booleans (as 0 and 1): a gripper signal may be given so; a joint angle may not.

    Returns
    -------
    arr : ndarray of float64
    """
    not_numbers = f"{name} must be an array of numbers, got {type(x).__name__}"
    try:
        given = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise ValueError(not_numbers) from exc
    kind = given.dtype.kind
    if kind not in _REAL_KINDS and kind != "O" and not (kind == "b" and allow_bool):
        raise ValueError(
            f"{name} must be an array of numbers, got {_KIND_NAMES.get(kind, 'other values')} "
            f"(dtype {given.dtype})"
        )
    try:
        # An object array (Python integers beyond int64, Fractions, ...): converted from x,
        # one value at a time, as before.
        arr = np.ascontiguousarray(x if kind == "O" else given, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(not_numbers) from exc
    if shape is not None:
        expected = tuple(shape)
        ok = arr.ndim == len(expected) and all(
            e is None or e == a for e, a in zip(expected, arr.shape, strict=False)
        )
        if not ok:
            raise ValueError(
                f"{name} must have shape {shape_str(expected)}, got {shape_str(arr.shape)}"
            )
    elif ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else tuple(ndim)
        if arr.ndim not in allowed:
            want = " or ".join(f"{d}-D" for d in allowed)
            raise ValueError(f"{name} must be {want}, got {arr.ndim}-D with shape {arr.shape}")
    if min_rows is not None and (arr.ndim == 0 or arr.shape[0] < min_rows):
        got = 0 if arr.ndim == 0 else arr.shape[0]
        raise ValueError(f"{name} must have at least {min_rows} rows, got {got}")
    if finite and arr.size and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(f"{name} must be finite, got {bad} NaN or infinite value(s)")
    return arr


def check_int(
    value: object, name: str, *, minimum: int | None = None, maximum: int | None = None
) -> int:
    """Check that ``value`` is an integer (not a bool) in [``minimum``, ``maximum``]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {short(value)}")
    v = int(value)
    if minimum is not None and v < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {v}")
    if maximum is not None and v > maximum:
        raise ValueError(f"{name} must be <= {maximum}, got {v}")
    return v


def check_positive_float(value: object, name: str, *, allow_zero: bool = False) -> float:
    """Check that ``value`` is a finite real number > 0 (or >= 0 with ``allow_zero``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number, got {short(value)}")
    v = float(value)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {short(value)}")
    return v


#: Object names that cannot be used: "joint" names the joint-space constraint.
RESERVED_NAMES = frozenset({"joint"})


def check_positions(
    objects: object,
    name: str = "objects",
    *,
    expected: Sequence[str] | None = None,
    what: str = "this skill",
) -> dict[str, NDArray[np.float64]]:
    """Validate a mapping object name -> position (3,): the one validator of object positions.

    Parameters
    ----------
    objects : dict str -> array-like, shape (3,)
    name : str
        The argument's name, used in error messages.
    expected : sequence of str, optional
        The names there must be, exactly (unknown and missing names are errors); the result
        follows their order. Default: any non-empty names except the reserved ``"joint"``, in
        the order given.
    what : str
        Who expects the names, for the error messages ("this skill", "the basin task", ...).

    Returns
    -------
    positions : dict str -> ndarray, shape (3,)
        New float64 arrays, finite.
    """
    if not isinstance(objects, Mapping):
        wanted = f"the object names {list(expected)}" if expected is not None else "object names"
        raise ValueError(
            f"{name} must be a dict mapping {wanted} to positions (3,), "
            f"got {type(objects).__name__}"
        )
    keys = check_object_names(objects, name, expected=expected, what=what)
    return {k: check_array(objects[k], f"{name}[{short(k)}]", shape=(3,)).copy() for k in keys}


def check_object_names(
    objects: Mapping[Any, Any],
    name: str = "objects",
    *,
    expected: Sequence[str] | None = None,
    what: str = "this skill",
) -> list[str]:
    """The names of a mapping of objects, checked as :func:`check_positions` checks them
    (exactly ``expected`` if given, in its order; else the names given, none reserved)."""
    for key in objects:
        if not isinstance(key, str) or not key:
            raise ValueError(f"{name} keys must be non-empty strings, got {short(key)}")
        if key in RESERVED_NAMES:
            raise ValueError(
                f"{name}: {short(key)} is reserved for the joint-space constraint; rename the "
                "object"
            )
    keys: list[str] = list(objects)
    if expected is not None:
        unknown = [k for k in keys if k not in expected]
        if unknown:
            raise ValueError(
                f"{name}: unknown object name(s) {unknown}; {what} knows {list(expected)}"
            )
        missing = [k for k in expected if k not in objects]
        if missing:
            raise ValueError(
                f"{name}: missing position(s) for {missing}; {what} needs {list(expected)}"
            )
        keys = list(expected)
    return keys


def check_trajectories(
    value: object, name: str, *, what: str, why: str = "", increasing_time: bool = False
) -> list[NDArray[np.float64]]:
    """Trajectories as (T_i, 1 + D) float64 arrays, time in column 0: at least 2, each of at
    least 2 rows, finite, all with the same D >= 1; with ``increasing_time`` the time strictly
    increasing. ``what`` names one of them in messages ("demonstration", "trajectory"), ``why``
    (" (...)") says why two are needed."""
    expected = f"a list of (T_i, 1 + D) arrays, one per {what}, time in column 0"
    if isinstance(value, np.ndarray) and value.ndim == 2:
        raise ValueError(f"{name} must be {expected}, got a single array of shape {value.shape}")
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name} must be {expected}, got a string")
    try:
        items = list(value)  # type: ignore[call-overload]
    except TypeError:
        raise ValueError(f"{name} must be {expected}, got {type(value).__name__}") from None
    if len(items) < 2:
        plural = what[:-1] + "ies" if what.endswith("y") else what + "s"
        raise ValueError(f"{name} must hold at least 2 {plural}{why}, got {len(items)}")
    out: list[NDArray[np.float64]] = []
    for i, item in enumerate(items):
        x = check_array(item, f"{name}[{i}]", ndim=2, min_rows=2, allow_bool=False)
        if x.shape[1] < 2:
            raise ValueError(
                f"{name}[{i}] must have shape (T, 1 + D) with D >= 1 (time in column 0, then "
                f"the D coordinates), got {x.shape}"
            )
        if out and x.shape[1] != out[0].shape[1]:
            raise ValueError(
                f"{name}[{i}] must have {out[0].shape[1]} columns (time and D = "
                f"{out[0].shape[1] - 1} coordinates, as {name}[0]), got {x.shape[1]}"
            )
        dt = np.diff(x[:, 0])
        if increasing_time and np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            raise ValueError(
                f"{name}[{i}][:, 0] (time) must be strictly increasing, got "
                f"t[{k}]={short(float(x[k, 0]))} >= t[{k + 1}]={short(float(x[k + 1, 0]))}"
            )
        out.append(x)
    return out
