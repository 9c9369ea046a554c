"""The robot contract: what each use of an arm needs from it, as Protocols, checked where a robot
enters (:func:`check_robot`).

:class:`pbdkit.Robot` satisfies all three. An arm of one's own (a wrapper around another
kinematics library, a test arm) implements the members of the Protocol its use needs:

- :class:`KinematicModel`: learning and reproducing positions (``Skill.learn``,
  ``Skill.reproduce``, ``Skill.controller``): size, names, limits, forward kinematics and the
  position Jacobian, and their unchecked fast paths for the reproduction loop;
- :class:`PoseKinematicModel`: constraints on orientation too (objects given as poses): the tip's
  pose and 6-D Jacobian;
- :class:`RobotDescription`: saving a skill (``Skill.save``): the URDF text and tip frame it
  is rebuilt from;
- :class:`BagRobot`: reading a ROS bag (``read_bag``): joint names and the base frame.

Unchecked fast paths (the ``_unchecked`` suffix) take a finite, contiguous float64 array of
shape (n,) and skip validation; anything else gives undefined results.
"""

from __future__ import annotations

from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

__all__ = [
    "BagRobot",
    "KinematicModel",
    "PoseKinematicModel",
    "RobotDescription",
    "check_robot",
    "missing",
]

Float = NDArray[np.float64]


@runtime_checkable
class KinematicModel(Protocol):
    """What learning and reproducing positions need from an arm (:class:`pbdkit.Robot` has it).

    Attributes
    ----------
    n_joints : int
    joint_names : list of str, length n
    lower, upper : ndarray, shape (n,)
        Joint position limits.
    revolute : ndarray of bool, shape (n,)
        True for a revolute joint (angles wrap), False for a prismatic one.
    velocity_limit, acceleration_limit, jerk_limit : ndarray, shape (n,)
        rad/s, rad/s^2, rad/s^3 (m/s... for a prismatic joint); ``inf`` where there is none.
    """

    @property
    def n_joints(self) -> int: ...

    @property
    def joint_names(self) -> list[str]: ...

    @property
    def lower(self) -> Float: ...

    @property
    def upper(self) -> Float: ...

    @property
    def revolute(self) -> NDArray[np.bool_]: ...

    @property
    def velocity_limit(self) -> Float: ...

    @property
    def acceleration_limit(self) -> Float: ...

    @property
    def jerk_limit(self) -> Float: ...

    def fk(self, q: npt.ArrayLike) -> Float:
        """Tip position: q (n,) -> (3,), Q (M, n) -> (M, 3)."""
        ...

    def fk_jacobian(self, q: npt.ArrayLike) -> tuple[Float, Float]:
        """Tip position (3,) and position Jacobian (3, n) for q (n,); batched for Q (M, n).

        Must return new arrays at each call (reproduction keeps them), not a reused buffer.
        """
        ...

    def fk_jacobian_unchecked(self, q: Float) -> tuple[Float, Float]:
        """:meth:`fk_jacobian` for one configuration, without validation (new arrays)."""
        ...

    def fk_jacobian_axes_unchecked(self, q: Float) -> tuple[Float, Float, Float]:
        """Tip position (3,), position Jacobian (3, n) and the joints' world axes (n, 3): the
        angular rows of the frame Jacobian (zero rows for prismatic joints)."""
        ...


@runtime_checkable
class PoseKinematicModel(KinematicModel, Protocol):
    """What constraints on orientation need too: the tip's pose and 6-D Jacobian."""

    def fk_pose(self, q: npt.ArrayLike) -> Float:
        """Tip pose as a homogeneous transform: q (n,) -> (4, 4), Q (M, n) -> (M, 4, 4)."""
        ...

    def jacobian6(self, q: npt.ArrayLike) -> Float:
        """[dx/dq ; omega/dq] in the base frame: q (n,) -> (6, n), Q (M, n) -> (M, 6, n)."""
        ...

    def fk_pose_jacobian_unchecked(self, q: Float) -> tuple[Float, Float, Float]:
        """Tip position (3,), rotation (3, 3) and 6-D Jacobian (6, n), without validation."""
        ...


@runtime_checkable
class RobotDescription(Protocol):
    """What saving a skill needs: the robot is rebuilt from its URDF text and tip frame."""

    @property
    def urdf(self) -> str: ...

    @property
    def tip(self) -> str: ...


@runtime_checkable
class BagRobot(Protocol):
    """What reading a ROS bag needs (:func:`pbdkit.read_bag`): the names that order the joints,
    and the base frame (the URDF's root link) the objects are placed in."""

    @property
    def joint_names(self) -> list[str]: ...

    @property
    def base(self) -> str: ...


def _members(protocol: type) -> list[str]:
    """The members a Protocol declares, its bases' included, in declaration order."""
    names: list[str] = []
    for cls in reversed(protocol.__mro__):
        if cls in (object, Protocol, Any) or not getattr(cls, "_is_protocol", False):
            continue
        for name in vars(cls):
            if not name.startswith("_") and name not in names:
                names.append(name)
    return names


def missing(robot: object, protocol: type) -> list[str]:
    """The members of ``protocol`` that ``robot`` lacks (empty when it satisfies it)."""
    return [name for name in _members(protocol) if not hasattr(robot, name)]


R = TypeVar("R")


def check_robot(robot: R, protocol: type = KinematicModel, *, name: str = "robot") -> R:
    """Return ``robot`` if it has every member of ``protocol``; else a ValueError naming the
    missing ones.

    Parameters
    ----------
    robot : object
    protocol : type
        :class:`KinematicModel` (default), :class:`PoseKinematicModel` or
        :class:`RobotDescription`.
    name : str
        The argument's name, for the message.

    Raises
    ------
    ValueError
        ``robot lacks joint_names, fk_jacobian_unchecked (a KinematicModel: ...)``.
    """
    lacking = missing(robot, protocol)
    if lacking:
        raise ValueError(
            f"{name} must be a {protocol.__name__} ({', '.join(_members(protocol))}; "
            f"e.g. pbdkit.robots.katana() or pbdkit.Robot.from_urdf(...)): "
            f"{type(robot).__name__} lacks {', '.join(lacking)}"
        )
    return robot
