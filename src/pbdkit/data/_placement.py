"""Where an object is: a position, or a pose with orientation.

Everywhere pbdkit takes objects (``Demonstration.objects``, :meth:`pbdkit.Skill.reproduce`,
``ctrl.step(..., objects=)``, the command line's ``--object``), an object is

- a position (3,) in the robot's base frame (m): the paper's objects, which translate the
  task-space constraint only; or
- a pose: a 4x4 homogeneous transform [[R, p], [0, 0, 0, 1]], or (x, y, z, qw, qx, qy, qz) with
  the quaternion **w first** (pytransform3d's convention; ROS messages hold x, y, z, w).

A pose is kept as its 4x4 transform (:func:`check_placements`); a position as (3,).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from .._rotations import as_pose, pose_matrix
from .._validation import check_object_names, short

__all__ = ["check_placements", "is_pose", "position_of", "rotation_of"]

Float = NDArray[np.float64]


def check_placements(
    objects: object,
    name: str = "objects",
    *,
    expected: Sequence[str] | None = None,
    what: str = "this skill",
) -> dict[str, Float]:
    """Validate a mapping object name -> position or pose.

    Parameters
    ----------
    objects : dict str -> array-like
        Each value a position (3,), a 4x4 transform or (x, y, z, qw, qx, qy, qz).
    name : str
        The argument's name, for errors.
    expected : sequence of str, optional
        The names there must be, exactly (the result follows their order).
    what : str
        Who expects the names, for errors.

    Returns
    -------
    placements : dict str -> ndarray, shape (3,) or (4, 4)
        New float64 arrays: positions as (3,), poses as 4x4 transforms with an orthonormal
        rotation.
    """
    if not isinstance(objects, Mapping):
        wanted = f"the object names {list(expected)}" if expected is not None else "object names"
        raise ValueError(
            f"{name} must be a dict mapping {wanted} to positions (3,) or poses (4x4, or "
            f"x, y, z, qw, qx, qy, qz), got {type(objects).__name__}"
        )
    keys = check_object_names(objects, name, expected=expected, what=what)
    out: dict[str, Float] = {}
    for k in keys:
        p, rot = as_pose(objects[k], f"{name}[{short(k)}]")
        out[k] = p if rot is None else pose_matrix(p, rot)
    return out


def is_pose(value: Float) -> bool:
    """Whether a checked placement is a pose (4x4) rather than a position (3,)."""
    return value.shape == (4, 4)


def position_of(value: Float) -> Float:
    """The position (3,) of a checked placement."""
    return value[:3, 3] if value.shape == (4, 4) else value


def rotation_of(value: Float) -> Float | None:
    """The rotation (3, 3) of a checked pose; None for a position."""
    return value[:3, :3] if value.shape == (4, 4) else None
