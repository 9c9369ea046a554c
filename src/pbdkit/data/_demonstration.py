"""Demonstrations: validated containers, time rescaling and file I/O.

A :class:`Demonstration` is one kinesthetic demonstration of a skill (paper Sec. II-A): the joint
angles theta recorded at times t, the positions o(n) of the objects in the scene (fixed during the
demonstration, as in the paper) and, optionally, the gripper signal. The hand position x is not
stored: it follows from the joint angles by forward kinematics when a skill is learned.

Time rescaling (paper Table I). :meth:`Demonstration.rescaled` linearly interpolates the joint
angles and the gripper signal onto ``n_steps`` samples uniformly spread over the demonstration's
own duration ``[t[0], t[-1]]``; the time of the result is expressed in *steps*:
``t = 0, 1, ..., n_steps - 1`` (the paper's t_j, as in its figures "time steps 200-500").

Files: ``.npz`` (:func:`save_demonstrations` / :func:`load_demonstrations`, a
``pbdkit-demonstrations`` archive without pickle, written atomically, judged from its headers
before an array is loaded) and CSV logs of a real robot (:func:`demonstration_from_csv`). Their
keys and columns: :doc:`/reproduction`, "File formats".
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._io import check_format, open_npz, save_npz_atomic
from .._validation import check_array, check_int, short
from ._placement import check_placements, is_pose, position_of

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LIMIT_TOLERANCE",
    "Demonstration",
    "LimitWarning",
    "check_demonstrations",
    "demonstration_arrays",
    "demonstration_from_csv",
    "demonstrations_from_arrays",
    "load_demonstrations",
    "save_demonstrations",
]

FORMAT_NAME = "pbdkit-demonstrations"
FORMAT_VERSION = 2
#: The versions :func:`load_demonstrations` reads (1: positions only; 2: poses too).
READABLE_VERSIONS = (1, 2)
#: How far (rad, or m for a prismatic joint) a demonstrated joint angle may lie outside the
#: robot's limits before :meth:`pbdkit.Skill.learn` warns (:class:`LimitWarning`): recorded
#: encoders can graze a limit.
LIMIT_TOLERANCE = 1e-6

Float = NDArray[np.float64]


class LimitWarning(UserWarning):
    """A demonstrated joint angle lies outside the robot's joint limits.

    Issued by :meth:`pbdkit.Skill.learn` (the demonstrations need the robot to be judged);
    learning goes on, and reproductions are clipped to the limits anyway.
    """


def _check_objects(objects: object, name: str = "objects") -> dict[str, Float]:
    """Validated placements (:func:`pbdkit.data._placement.check_placements`: a position
    (3,) or a pose, kept as 4x4), made read-only."""
    out = check_placements(objects, name)
    for pos in out.values():
        pos.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False, init=False)
class Demonstration:
    """One demonstration of a skill, validated on construction.

    Parameters
    ----------
    t : array-like, shape (T,)
        Time stamps (seconds, or any unit), finite and strictly increasing, T >= 2.
    joints : array-like, shape (T, n)
        Joint angles theta in radians, one row per time stamp.
    objects : dict str -> array-like, shape (3,), (4, 4) or (7,)
        Where each object is in the robot's base frame (metres), constant during the
        demonstration: a position (3,), or a pose, as a 4x4 transform or
        (x, y, z, qw, qx, qy, qz) (quaternion w first), kept as its 4x4 transform
        (:mod:`pbdkit.data._placement`). The name ``"joint"`` is reserved. May be empty
        (joint-space skill only).
    gripper : array-like, shape (T,), optional
        Gripper signal (0 open, 1 closed; booleans accepted), one value per time stamp, within
        [0, 1] (a value in between is a partly closed gripper, or a resampled transition).

    Notes
    -----
    Joint limits are not checked here (a demonstration does not know its robot):
    :meth:`pbdkit.Skill.learn` warns (:class:`LimitWarning`) about angles outside the robot's
    limits by more than :data:`LIMIT_TOLERANCE`.

    Attributes
    ----------
    t, joints, objects, gripper
        The validated float64 arrays (read-only; ``objects`` is a read-only mapping).
    n_steps : int
        T.
    n_joints : int
        n.
    object_names : tuple of str
        Names of the objects, in the order given.

    Raises
    ------
    ValueError
        If a shape is wrong, a value is NaN or infinite, t is not strictly increasing, there are
        fewer than 2 samples, an object position is not (3,), or a gripper value is outside
        [0, 1] (the first such sample is named). The message names the argument, the expected
        and the actual value.
    """

    t: Float
    joints: Float
    objects: Mapping[str, Float]
    gripper: Float | None

    def __init__(
        self,
        t: npt.ArrayLike,
        joints: npt.ArrayLike,
        objects: Mapping[str, npt.ArrayLike] | None = None,
        gripper: npt.ArrayLike | None = None,
    ) -> None:
        # Copies: the arrays are made read-only and must not freeze the caller's own arrays.
        t_ = check_array(t, "t", ndim=1, allow_bool=False).copy()
        if t_.shape[0] < 2:
            raise ValueError(f"t must have at least 2 samples, got {t_.shape[0]}")
        dt = np.diff(t_)
        if np.any(dt <= 0):
            i = int(np.argmax(dt <= 0))
            raise ValueError(
                f"t must be strictly increasing, got t[{i}]={short(float(t_[i]))} "
                f">= t[{i + 1}]={short(float(t_[i + 1]))}"
            )
        joints_ = check_array(joints, "joints", ndim=2, allow_bool=False).copy()
        if joints_.shape[0] != t_.shape[0] or joints_.shape[1] < 1:
            raise ValueError(f"joints must have shape ({t_.shape[0]}, n), got {joints_.shape}")
        objects_ = _check_objects({} if objects is None else objects)
        gripper_: Float | None = None
        if gripper is not None:
            gripper_ = check_array(gripper, "gripper", shape=(t_.shape[0],)).copy()
            outside = (gripper_ < 0.0) | (gripper_ > 1.0)
            if outside.any():
                i = int(np.argmax(outside))
                raise ValueError(
                    f"gripper[{i}] must be within [0, 1] (0 open, 1 closed), "
                    f"got {short(float(gripper_[i]))}"
                )
            gripper_.setflags(write=False)
        t_.setflags(write=False)
        joints_.setflags(write=False)
        object.__setattr__(self, "t", t_)
        object.__setattr__(self, "joints", joints_)
        object.__setattr__(self, "objects", MappingProxyType(objects_))
        object.__setattr__(self, "gripper", gripper_)

    def __reduce__(self) -> tuple[type[Demonstration], tuple[Any, ...]]:
        # Pickled (a skill sent to a worker) as its arrays: a read-only mapping does not pickle.
        return (type(self), (self.t, self.joints, dict(self.objects), self.gripper))

    @property
    def n_steps(self) -> int:
        """Number of samples T."""
        return int(self.t.shape[0])

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return int(self.joints.shape[1])

    @property
    def object_names(self) -> tuple[str, ...]:
        """Names of the objects, in the order given."""
        return tuple(self.objects)

    @property
    def duration(self) -> float:
        """t[-1] - t[0]."""
        return float(self.t[-1] - self.t[0])

    def rescaled(self, n_steps: int) -> Demonstration:
        """The demonstration resampled on ``n_steps`` uniform steps (paper Table I).

        Joint angles and gripper are linearly interpolated at ``n_steps`` times uniformly spread
        over ``[t[0], t[-1]]``; the returned time is in steps: ``t = 0, 1, ..., n_steps - 1``.

        Parameters
        ----------
        n_steps : int
            Number of samples of the result (>= 2).

        Returns
        -------
        demo : Demonstration
            t (n_steps,), joints (n_steps, n), same objects, gripper (n_steps,) or None.
        """
        n_steps = check_int(n_steps, "n_steps", minimum=2)
        joints, gripper = _resample(self.t, self.joints, self.gripper, n_steps)
        return Demonstration(
            t=np.arange(n_steps, dtype=np.float64),
            joints=joints,
            objects=dict(self.objects),
            gripper=gripper,
        )

    def __repr__(self) -> str:
        grip = "yes" if self.gripper is not None else "no"
        return (
            f"Demonstration(T={self.n_steps}, n_joints={self.n_joints}, "
            f"duration={self.duration:.3g}, objects={list(self.objects)}, gripper={grip})"
        )


def _resample(
    t: Float, joints: Float, gripper: Float | None, n_steps: int
) -> tuple[Float, Float | None]:
    """Linear interpolation of joints (T, n) and gripper (T,) onto n_steps uniform times."""
    grid = np.linspace(t[0], t[-1], n_steps)
    # searchsorted + one vectorised lerp for all joints (np.interp is per column).
    idx = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, t.shape[0] - 2)
    w = ((grid - t[idx]) / (t[idx + 1] - t[idx]))[:, None]
    out = joints[idx] * (1.0 - w) + joints[idx + 1] * w
    g = None
    if gripper is not None:
        g = gripper[idx] * (1.0 - w[:, 0]) + gripper[idx + 1] * w[:, 0]
    return out, g


def check_demonstrations(demos: object, *, min_demos: int = 2) -> list[Demonstration]:
    """Validate a set of demonstrations that must share one structure.

    Parameters
    ----------
    demos : sequence of Demonstration
    min_demos : int
        Minimum number of demonstrations (2 to learn a skill: variability needs at least two).

    Returns
    -------
    demos : list of Demonstration

    Raises
    ------
    ValueError
        Fewer than ``min_demos`` demonstrations, an element that is not a Demonstration,
        different joint counts, different object names, or a gripper signal in some
        demonstrations only.
    """
    if isinstance(demos, Demonstration) or not isinstance(demos, Sequence):
        raise ValueError(f"demos must be a list of Demonstration, got {type(demos).__name__}")
    out = list(demos)
    if len(out) < min_demos:
        raise ValueError(f"demos must hold at least {min_demos} demonstrations, got {len(out)}")
    for i, d in enumerate(out):
        if not isinstance(d, Demonstration):
            raise ValueError(f"demos[{i}] must be a Demonstration, got {type(d).__name__}")
    ref = out[0]
    for i, d in enumerate(out[1:], start=1):
        if d.n_joints != ref.n_joints:
            raise ValueError(
                f"demos[{i}] has {d.n_joints} joints, expected {ref.n_joints} like demos[0]"
            )
        if set(d.object_names) != set(ref.object_names):
            raise ValueError(
                f"demos[{i}] has objects {sorted(d.object_names)}, expected "
                f"{sorted(ref.object_names)} like demos[0]"
            )
        for k in ref.object_names:
            if is_pose(d.objects[k]) != is_pose(ref.objects[k]):
                kind = "a pose" if is_pose(d.objects[k]) else "a position"
                raise ValueError(
                    f"demos[{i}].objects[{short(k)}] is {kind}, unlike in demos[0]: give each "
                    "object as a pose in every demonstration or as a position in every one"
                )
        if (d.gripper is None) != (ref.gripper is None):
            raise ValueError(
                f"demos[{i}] {'has no' if d.gripper is None else 'has a'} gripper signal, "
                f"unlike demos[0]: give it in every demonstration or in none"
            )
    return out


def save_demonstrations(demos: Sequence[Demonstration], path: str | os.PathLike[str]) -> None:
    """Save demonstrations to a versioned ``.npz`` file (no pickle, written atomically).

    Parameters
    ----------
    demos : sequence of Demonstration
        At least one; all with the same joint count, object names and gripper presence.
    path : str or path-like
        Destination; replaced atomically (readers see the old file or the new one).

    Its keys: :doc:`/reproduction`, "Demonstration files".

    Raises
    ------
    ValueError
        Invalid demonstrations, or more than :func:`load_demonstrations` reads
        (:data:`pbdkit._io.MAX_NPZ_BYTES` of arrays, 1 GiB: e.g. 200 demonstrations of 10**5
        samples of a 7-joint arm with a gripper): nothing is written.
    """
    arrays = demonstration_arrays(demos)
    posed = "demo_0_rotations" in arrays
    header = {
        "format": np.array(FORMAT_NAME),
        # Positions only: version 1, as before poses (older readers still load the file).
        "version": np.array(FORMAT_VERSION if posed else 1, dtype=np.int64),
    }
    # Refused before anything is written if load_demonstrations could not read it back.
    save_npz_atomic(path, {**header, **arrays}, what="demos")


def demonstration_arrays(demos: Sequence[Demonstration], prefix: str = "") -> dict[str, Any]:
    """The arrays of demonstrations in a file, by key (:func:`save_demonstrations`; a
    version-3 skill file holds them under the prefix ``"demos_"``): ``n_demos``,
    ``object_names``, ``has_gripper`` and ``demo_{i}_*``, each key after ``prefix``; the
    ``demo_{i}_rotations`` when some object is a pose (version 2 of a demonstrations file).

    Raises
    ------
    ValueError
        Invalid demonstrations (:func:`check_demonstrations`, at least one).
    """
    items = check_demonstrations(demos, min_demos=1)
    names = list(items[0].object_names)
    has_gripper = items[0].gripper is not None
    posed = bool(names) and any(is_pose(items[0].objects[n]) for n in names)
    arrays: dict[str, Any] = {
        "n_demos": np.array(len(items), dtype=np.int64),
        "object_names": np.array(names, dtype=np.str_) if names else np.zeros(0, dtype="<U1"),
        "has_gripper": np.array(has_gripper),
    }
    for i, d in enumerate(items):
        arrays[f"demo_{i}_t"] = d.t
        arrays[f"demo_{i}_joints"] = d.joints
        arrays[f"demo_{i}_objects"] = (
            np.stack([position_of(d.objects[n]) for n in names]) if names else np.zeros((0, 3))
        )
        if posed:
            arrays[f"demo_{i}_rotations"] = np.stack(
                [
                    d.objects[n][:3, :3] if is_pose(d.objects[n]) else np.full((3, 3), np.nan)
                    for n in names
                ]
            )
        if d.gripper is not None:
            arrays[f"demo_{i}_gripper"] = d.gripper
    return {prefix + k: v for k, v in arrays.items()}


def load_demonstrations(path: str | os.PathLike[str]) -> list[Demonstration]:
    """Load demonstrations saved by :func:`save_demonstrations`.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    demos : list of Demonstration

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is corrupt, not a pbdkit demonstrations file, of another version, or holds
        invalid or inconsistent data: ``n_demos`` not an integer >= 1, demonstrations missing
        or beyond ``n_demos``, different joint counts, duplicate object names, or any
        :class:`Demonstration` check. The message names the file and the key.
    """
    p = Path(path)
    # The archive's headers are checked first (sizes, object arrays); then its header keys are
    # read, and every other key is judged by name against them before any array is loaded.
    with open_npz(p, what=FORMAT_NAME + " file") as data:
        version = check_format(data, p, FORMAT_NAME, READABLE_VERSIONS)
        try:
            demos = demonstrations_from_arrays(data, posed=version >= 2)
        except KeyError as exc:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: missing key {exc}") from exc
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {exc}") from exc
    return demos


_HEADER_KEYS = ("n_demos", "object_names", "has_gripper")


def demonstrations_from_arrays(
    data: Mapping[str, NDArray[Any]], *, posed: bool = False, prefix: str = ""
) -> list[Demonstration]:
    """The demonstrations of a file, checked against its header keys (n_demos, ...).

    ``data`` may load each array when it is asked for (:class:`pbdkit._io.NpzArchive`): the
    keys are checked against the header before any demonstration's array is read. With a
    ``prefix`` (:func:`demonstration_arrays`), the keys that start with it are the
    demonstrations' (every message names the key as stored); without, every key but
    ``format`` and ``version`` is.
    """
    n_arr = np.asarray(data[prefix + "n_demos"])
    n_demos = int(n_arr) if n_arr.shape == () and n_arr.dtype.kind in "iu" else -1
    if n_demos < 1:
        value = n_arr.tolist() if n_arr.size < 10 else f"an array of shape {n_arr.shape}"
        raise ValueError(f"{prefix}n_demos must be an integer >= 1, got {value}")
    names_arr = np.asarray(data[prefix + "object_names"])
    if names_arr.ndim != 1 or (names_arr.size and names_arr.dtype.kind != "U"):
        raise ValueError(
            f"{prefix}object_names must be a 1-D array of strings, got {short(names_arr)}"
        )
    names = [str(s) for s in names_arr]
    if len(set(names)) != len(names):
        raise ValueError(f"{prefix}object_names must be distinct, got {names}")
    grip_arr = np.asarray(data[prefix + "has_gripper"])
    if grip_arr.shape != () or grip_arr.dtype.kind != "b":
        raise ValueError(f"{prefix}has_gripper must be a boolean, got {short(grip_arr)}")
    has_gripper = bool(grip_arr)
    fields: tuple[str, ...] = ("t", "joints", "objects")
    if posed:
        fields += ("rotations",)
    if has_gripper:
        fields += ("gripper",)
    # Key by key up to the first missing one: the file's own keys bound the work, whatever
    # n_demos it declares.
    for i in range(n_demos):
        for f in fields:
            if f"{prefix}demo_{i}_{f}" not in data:
                raise ValueError(f"missing key '{prefix}demo_{i}_{f}' (n_demos is {n_demos})")
    header = {"format", "version"} if not prefix else set()
    header.update(prefix + k for k in _HEADER_KEYS)
    extra = sorted(
        (
            k
            for k in data
            if k.startswith(prefix)
            and k not in header
            and not _described(k[len(prefix) :], n_demos, fields)
        ),
        key=lambda k: _demo_key_order(k[len(prefix) :]),
    )
    if extra:
        shown = ", ".join(repr(k) for k in extra[:4]) + (", ..." if len(extra) > 4 else "")
        raise ValueError(
            f"{prefix}n_demos is {n_demos} but the file holds {shown}, which it does not describe"
        )
    demos: list[Demonstration] = []
    for i in range(n_demos):
        pos = np.asarray(data[f"{prefix}demo_{i}_objects"], dtype=np.float64)
        if pos.shape != (len(names), 3):
            raise ValueError(
                f"{prefix}demo_{i}_objects must have shape ({len(names)}, 3), got {pos.shape}"
            )
        placements: dict[str, Any] = {n: pos[k] for k, n in enumerate(names)}
        if posed:
            rot = np.asarray(data[f"{prefix}demo_{i}_rotations"], dtype=np.float64)
            if rot.shape != (len(names), 3, 3):
                raise ValueError(
                    f"{prefix}demo_{i}_rotations must have shape ({len(names)}, 3, 3), "
                    f"got {rot.shape}"
                )
            for k, n in enumerate(names):
                if not np.all(np.isnan(rot[k])):  # all NaN: a position-only object
                    pose = np.eye(4)
                    pose[:3, :3], pose[:3, 3] = rot[k], pos[k]
                    placements[n] = pose
        try:
            demo = Demonstration(
                t=data[f"{prefix}demo_{i}_t"],
                joints=data[f"{prefix}demo_{i}_joints"],
                objects=placements,
                gripper=data[f"{prefix}demo_{i}_gripper"] if has_gripper else None,
            )
        except ValueError as exc:
            raise ValueError(f"{prefix}demo_{i}: {exc}") from exc
        if demos and demo.n_joints != demos[0].n_joints:
            raise ValueError(
                f"{prefix}demo_{i}_joints has {demo.n_joints} joints, expected {demos[0].n_joints} "
                f"like {prefix}demo_0_joints"
            )
        demos.append(demo)
    return demos


def _described(key: str, n_demos: int, fields: Sequence[str]) -> bool:
    """Whether ``key`` is ``demo_{i}_{field}`` with i < n_demos (i written as str(i) does)."""
    i, field = _demo_key_order(key)
    return 0 <= i < n_demos and field in fields and key == f"demo_{i}_{field}"


def _demo_key_order(key: str) -> tuple[int, str]:
    """Sort ``demo_{i}_*`` keys by demonstration number (demo_2 before demo_10)."""
    parts = key.split("_", 2)
    # ASCII digits, at most 18 (int() refuses other digits, and strings of over 4300).
    digits = parts[1] if len(parts) == 3 else ""
    if parts[0] == "demo" and digits.isascii() and digits.isdigit() and len(digits) <= 18:
        return int(parts[1]), parts[2]
    return -1, key


def demonstration_from_csv(
    path: str | os.PathLike[str],
    objects: Mapping[str, npt.ArrayLike] | None,
    *,
    joint_columns: Sequence[str] | None = None,
    delimiter: str = ",",
) -> Demonstration:
    """Read one demonstration from a CSV log (format: :doc:`/reproduction`, "Demonstration
    files").

    Parameters
    ----------
    path : str or path-like
        CSV file with a header line; columns ``t``, joint angles, optional ``gripper``. UTF-8,
        with or without a byte order mark (as spreadsheet programs write it).
    objects : dict str -> array-like, shape (3,), or None
        Object positions in the robot's base frame during this demonstration (None or ``{}``:
        none, a joint-space skill only).
    joint_columns : sequence of str, optional
        Joint columns to use, in this order, each once (not ``t`` nor ``gripper``). Default:
        every column other than ``t`` and ``gripper``, in file order.
    delimiter : str
        Field separator: one character that cannot occur in a number (``","``, ``";"``,
        ``"\\t"``, ...).

    Returns
    -------
    demo : Demonstration

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        A bad ``delimiter`` or ``joint_columns``, no header, no ``t`` column, a missing joint
        column, a non-numeric value, or any :class:`Demonstration` check. Every message about
        the file names it.
    """
    _check_delimiter(delimiter)
    cols_given = None if joint_columns is None else _check_joint_columns(joint_columns)
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"CSV file not found: {p}")
    try:
        # utf-8-sig: a byte order mark (Excel's "CSV UTF-8") is not part of the first column name.
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{p} is not a UTF-8 text CSV file: {exc}") from exc
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{p}: empty CSV file, expected a header line 't,<joints...>'")
    header = [h.strip() for h in next(csv.reader([lines[0]], delimiter=delimiter))]
    if "t" not in header:
        raise ValueError(f"{p}: the header must contain a column 't', got {header}")
    if len(set(header)) != len(header):
        raise ValueError(f"{p}: duplicate column names in the header {header}")
    if cols_given is None:
        cols = [h for h in header if h not in ("t", "gripper")]
    else:
        cols = cols_given
        missing = [c for c in cols if c not in header]
        if missing:
            raise ValueError(f"{p}: joint columns {missing} not in the header {header}")
    if not cols:
        raise ValueError(f"{p}: no joint column in the header {header}")
    try:
        table = np.loadtxt(
            io.StringIO("\n".join(lines[1:])), delimiter=delimiter, dtype=np.float64, ndmin=2
        )
    except ValueError as exc:
        raise ValueError(f"{p}: non-numeric or ragged CSV data: {exc}") from exc
    if table.shape[0] == 0 or table.shape[1] != len(header):
        raise ValueError(
            f"{p}: expected rows of {len(header)} values (header {header}), "
            f"got a table of shape {table.shape}"
        )
    col = {h: i for i, h in enumerate(header)}
    try:
        return Demonstration(
            t=table[:, col["t"]],
            joints=table[:, [col[c] for c in cols]],
            objects=objects,
            gripper=table[:, col["gripper"]] if "gripper" in col else None,
        )
    except ValueError as exc:
        raise ValueError(f"{p}: {exc}") from exc


# Characters of numbers (and of nan, inf), quotes, comments and line ends: not separators.
_NOT_DELIMITERS = frozenset('.+-"#\r\n')


def _check_delimiter(delimiter: object) -> None:
    if (
        not isinstance(delimiter, str)
        or len(delimiter) != 1
        or delimiter.isalnum()
        or delimiter in _NOT_DELIMITERS
    ):
        raise ValueError(
            "delimiter must be one character that cannot occur in a number, such as ',', ';' "
            f"or a tab, got {short(delimiter)}"
        )


def _check_joint_columns(joint_columns: object) -> list[str]:
    if isinstance(joint_columns, str) or not isinstance(joint_columns, Sequence):
        raise ValueError(
            f"joint_columns must be a list of column names, got {type(joint_columns).__name__}"
        )
    cols = list(joint_columns)
    bad = [c for c in cols if not isinstance(c, str)]
    if bad:
        raise ValueError(f"joint_columns must be column names (strings), got {short(bad[0])}")
    roles = {"t": "the time", "gripper": "the gripper signal"}
    taken = [c for c in cols if c in roles]
    if taken:
        raise ValueError(f"joint_columns: {short(taken[0])} is {roles[taken[0]]}, not a joint")
    twice = sorted({c for c in cols if cols.count(c) > 1})
    if twice:
        raise ValueError(f"joint_columns must name each column once, got {twice} more than once")
    return cols
