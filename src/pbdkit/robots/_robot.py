"""The Robot class: the kinematics and limits of a serial arm from a URDF, to one tip frame.

A :class:`Robot` is built from a URDF (file or XML text) with pinocchio and exposes the forward
kinematics of one *tip* frame, x = f(theta), and its position Jacobian J = dx/dtheta, both in the
frame of the URDF's root link (the base); the tip's pose and 6-D Jacobian; and inverse
kinematics (:meth:`Robot.ik`, :mod:`pbdkit.robots._ik`).

Two evaluation paths give the same numbers (tested to 1e-12):

- one configuration ``q`` of shape (n,): pinocchio (``computeFrameJacobian``, about 1 us);
- a batch ``Q`` of shape (M, n): a vectorized numpy chain built once from the pinocchio model
  (joint placements, joint axes, tip placement), one pass over the joints for the whole batch
  (:mod:`pbdkit.robots._chain`).

The URDF's joints are read and checked by :mod:`pbdkit.robots._urdf` (revolute and prismatic
joints; continuous ones become revolute on [-pi, pi]; the joints off the root-to-tip path are
locked).

Limits. Position and velocity limits come from the URDF's ``<limit>`` tags; a velocity of 0
(URDF's "not limited", also what a continuous joint without ``<limit>`` gets) reads inf. URDF has
no acceleration or jerk limits: they come from a ``joint_limits.yaml`` file in the format of
MoveIt and ros2_control (``Robot.from_urdf(..., joint_limits=...)``, see
:mod:`pbdkit.robots._joint_limits` for the rules), which also overrides the URDF's velocity limits
(as in MoveIt) and, with ``has_position_limits: true``, its position limits. A joint without a
declared limit has inf.

:meth:`Robot.from_dh` loads the URDF that :func:`pbdkit.robots.urdf_from_dh` writes from a
Denavit-Hartenberg table.

Collision. The URDF's ``<collision>`` elements and an SRDF's disabled pairs make
:attr:`Robot.collision_model` (:mod:`pbdkit.robots._collision`), built on first use: loading a
robot reads no mesh.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from numpy.typing import NDArray

from .._validation import check_array, shape_str, short
from ._chain import _chain_constants, _chain_fk_jacobian
from ._collision import (
    CollisionModel,
    _frame_id,
    _joints_to_lock,
    build_collision_model,
    has_collision_elements,
)
from ._ik import ik
from ._joint_limits import (
    JointLimits,
    JointLimitsSource,
    joint_limits_mapping,
    limits_on_chain,
    read_joint_limits,
)
from ._srdf import read_srdf
from ._urdf import (
    _choose_tip,
    _normalize_joints,
    _parse_urdf,
    _pinocchio_xml,
    _read_urdf_text,
    _refuse_mimic_joints,
    _write_position_limits,
    urdf_from_dh,
)

__all__ = ["Robot"]


def _positive_per_joint(
    value: npt.ArrayLike | None, name: str, n: int, unit: str
) -> NDArray[np.float64] | None:
    """None, or a number or (n,) values, each > 0 or inf (no limit) -> ndarray (n,)."""
    if value is None:
        return None
    arr = check_array(value, name, ndim=(0, 1), finite=False)
    if np.ndim(value) == 0:
        arr = np.full(n, arr.item())
    elif arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) (one value per joint), got {arr.shape}")
    bad = np.flatnonzero(~(arr > 0))  # zero, negative or NaN
    if bad.size:
        i = int(bad[0])
        got = float(arr[i])
        raise ValueError(f"{name}[{i}] must be > 0 ({unit}; inf for no limit), got {short(got)}")
    return arr


class Robot:
    """Kinematics of the serial chain from a URDF's root link to one tip frame.

    Build it with :meth:`from_urdf` or :meth:`from_dh` (or :func:`pbdkit.robots.katana`).
    A Robot holds pinocchio work data: do not share one Robot between threads.

    Attributes
    ----------
    n_joints : int
        Number of actuated joints n (the joints on the path from the root to the tip).
    joint_names : list of str, length n
        Joint names in chain order (from the base to the tip).
    lower, upper : ndarray, shape (n,)
        Joint position limits (rad for revolute joints, m for prismatic ones): the URDF's, or the
        joint_limits YAML's where it declares ``has_position_limits: true``.
    velocity_limit : ndarray, shape (n,)
        Joint speed limits, rad/s (m/s for prismatic joints), > 0: the joint_limits YAML's where
        it declares one (it wins over the URDF, as in MoveIt), else the URDF's; inf where neither
        limits the joint (a URDF velocity of 0 means "not limited").
    acceleration_limit : ndarray, shape (n,)
        rad/s^2 (m/s^2), > 0, from the joint_limits YAML; inf where it declares none.
    jerk_limit : ndarray, shape (n,)
        rad/s^3 (m/s^3), > 0, from the joint_limits YAML; inf where it declares none.
    effort_limit : ndarray, shape (n,)
        From the URDF ``<limit>`` tags (N m or N; 0 when the URDF gives none).
    revolute : ndarray of bool, shape (n,)
        True for revolute joints, False for prismatic ones.
    tip : str
        Name of the frame whose position is computed.
    base : str
        Name of the URDF root link; positions and Jacobians are expressed in its frame.
    name : str
        The URDF robot name.
    urdf : str
        The URDF XML text that was loaded (continuous joints already turned into revolute ones,
        position limits from the joint_limits YAML written into the ``<limit>`` tags), so that a
        simulator can load the same model.
    srdf : str or None
        The SRDF XML text that was loaded (its ``<disable_collisions>`` pairs are in
        :attr:`collision_model`), or None.
    has_collision_model : bool
        Whether the URDF has ``<collision>`` geometry (decided from the XML, no mesh read).
    collision_model : CollisionModel or None
        The collision geometry on the robot's joints, built on first access (meshes are read
        then), None without ``<collision>`` elements.

    All limit arrays are float64 and read-only.
    """

    def __init__(
        self,
        urdf: str,
        tip: str | None = None,
        joint_limits: JointLimitsSource | None = None,
        srdf: str | os.PathLike[str] | None = None,
        mesh_dir: str | os.PathLike[str] | None = None,
    ) -> None:
        """Build from URDF XML text; prefer :meth:`from_urdf`, which also accepts a file path.

        Parameters
        ----------
        urdf : str
            The URDF XML text.
        tip : str, optional
            The frame to control (see :meth:`from_urdf`).
        joint_limits : str, path-like or mapping, optional
            Velocity, acceleration and jerk limits (see :meth:`from_urdf`).
        srdf : str or path-like, optional
            Disabled collision pairs (see :meth:`from_urdf`).
        mesh_dir : str or path-like, optional
            The folder relative collision mesh paths are in (:meth:`from_urdf` gives the URDF
            file's); without it, a relative mesh path is an error when the collision model is
            built.
        """
        declared = {} if joint_limits is None else read_joint_limits(joint_limits)
        root = _parse_urdf(urdf)
        if _normalize_joints(root):
            urdf = ET.tostring(root, encoding="unicode")
        base_name, tip_name = _choose_tip(root, tip)
        pin_xml, urdf_names = _pinocchio_xml(root, urdf)
        try:
            full = pin.buildModelFromXML(pin_xml)
        except (RuntimeError, ValueError) as exc:
            raise ValueError(f"path_or_xml: pinocchio could not build the URDF: {exc}") from exc
        frame_names = list(dict.fromkeys(f.name for f in full.frames if f.name != "universe"))
        if not full.existFrame(tip_name):
            raise ValueError(
                f"tip frame '{tip_name}' does not exist in the URDF; available frames: "
                f"{frame_names}"
            )
        to_lock = _joints_to_lock(full, tip_name)
        model = pin.buildReducedModel(full, to_lock, pin.neutral(full)) if to_lock else full
        if model.nq == 0:
            raise ValueError(
                f"tip frame '{tip_name}' is not moved by any joint (it is fixed to the base); "
                f"choose a frame further down the chain, one of {frame_names}"
            )
        lower = np.array(model.lowerPositionLimit, dtype=np.float64)
        upper = np.array(model.upperPositionLimit, dtype=np.float64)
        names = [
            urdf_names.get(str(model.names[i]), str(model.names[i]))
            for i in range(1, model.njoints)
        ]
        _refuse_mimic_joints(root, names)
        velocity = np.array(model.velocityLimit, dtype=np.float64)
        velocity[~(velocity > 0)] = np.inf  # URDF writes velocity="0" for "not limited"
        acceleration, jerk = np.full(len(names), np.inf), np.full(len(names), np.inf)
        on_chain: dict[str, JointLimits] = {}
        if joint_limits is not None:
            urdf_joints = [str(joint.get("name")) for joint in root.iter("joint")]
            on_chain = limits_on_chain(declared, names, urdf_joints, joint_limits)
        for i, name in enumerate(names):
            lim = on_chain.get(name, JointLimits())
            for arr, value in (
                (velocity, lim.velocity),
                (acceleration, lim.acceleration),
                (jerk, lim.jerk),
            ):
                if value is not None:
                    arr[i] = value
            if lim.position is not None:
                lower[i], upper[i] = lim.position
        if _write_position_limits(root, on_chain):
            urdf = ET.tostring(root, encoding="unicode")
            model.lowerPositionLimit = lower.copy()
            model.upperPositionLimit = upper.copy()
        if not (
            np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(lower <= upper)
        ):
            raise ValueError(
                f"joint limits must be finite with lower <= upper, got lower={lower.tolist()}, "
                f"upper={upper.tolist()} for joints {names}; fix the <limit> tags"
            )
        self._model = model
        self._data = model.createData()
        self._tip_id = _frame_id(model, tip_name)
        self._consts, self._revolute, self._tip_rot, self._tip_trans = _chain_constants(
            model, self._data, self._tip_id
        )
        self.n_joints: int = int(model.nq)
        self.joint_names: list[str] = names
        self.lower = lower
        self.upper = upper
        self.velocity_limit = velocity
        self.acceleration_limit = acceleration
        self.jerk_limit = jerk
        self.effort_limit = np.array(model.effortLimit, dtype=np.float64)
        self.revolute = self._revolute.copy()
        for arr in (
            self.lower,
            self.upper,
            self.velocity_limit,
            self.acceleration_limit,
            self.jerk_limit,
            self.effort_limit,
            self.revolute,
        ):
            arr.flags.writeable = False
        self.tip: str = tip_name
        self.base: str = base_name
        self.name: str = root.get("name", "")
        self.urdf: str = urdf
        self.srdf: str | None = None
        self._srdf_disabled: frozenset[tuple[str, str]] = frozenset()
        if srdf is not None:
            links = [str(link.get("name", "")) for link in root.findall("link")]
            self.srdf, self._srdf_disabled = read_srdf(srdf, links, self.name)
        self._mesh_dir = None if mesh_dir is None else Path(mesh_dir).resolve()
        self._has_collision = has_collision_elements(root)
        self._collision: CollisionModel | None = None
        self._lf = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        self._oMf = self._data.oMf
        self._single_shape = (self.n_joints,)

    @property
    def has_collision_model(self) -> bool:
        """Whether the URDF has ``<collision>`` geometry (so :attr:`collision_model` is not
        None); decided from the XML alone."""
        return self._has_collision

    @property
    def collision_model(self) -> CollisionModel | None:
        """The URDF's collision geometry on this robot's joints, with the SRDF's disabled
        pairs (:class:`~pbdkit.robots.CollisionModel`); None without ``<collision>`` elements.

        Built on first access and kept: collision meshes are read then, relative paths from the
        URDF file's folder, ``package://`` ones from ``ROS_PACKAGE_PATH``.

        Raises
        ------
        ValueError
            A collision mesh that cannot be found or read (the message names it).
        """
        if self._collision is None and self._has_collision:
            self._collision = build_collision_model(
                self.urdf, self.tip, self._srdf_disabled, self._mesh_dir, self._model
            )
        return self._collision

    # ---------------------------------------------------------------- constructors

    @classmethod
    def from_urdf(
        cls,
        path_or_xml: str | os.PathLike[str],
        tip: str | None = None,
        joint_limits: JointLimitsSource | None = None,
        srdf: str | os.PathLike[str] | None = None,
    ) -> Robot:
        """Load a robot from a URDF file or URDF XML text, and optionally a joint_limits YAML
        and an SRDF.

        Parameters
        ----------
        path_or_xml : str or path-like
            A path to a ``.urdf`` file, or the XML text itself (a string starting with ``<``).
            Mesh files are not opened here, so they need not exist: the ``<collision>``
            geometry is read when :attr:`collision_model` is first used (meshes then, relative
            paths from the URDF file's folder, ``package://pkg/...`` from the
            ``ROS_PACKAGE_PATH`` folders).
        tip : str, optional
            Name of the frame (link or joint) to control. If None, the URDF must be a chain
            (no branches) and its last link is used.
        joint_limits : str, path-like or mapping, optional
            Limits in the ``joint_limits.yaml`` format of MoveIt and ros2_control: a path to
            such a file, its YAML text (a string with a newline or ``joint_limits:``), or the
            parsed mapping ``{"joint_limits": {joint: {"has_acceleration_limits": True,
            "max_acceleration": 15.0, ...}}}``. Read with PyYAML's safe loader only, at most
            1 MiB (``pbdkit.robots._joint_limits.MAX_YAML_BYTES``).
            ``has_X_limits: true`` with ``max_X`` (> 0, ``.inf`` for none) sets the velocity,
            acceleration or jerk limit; ``has_X_limits: false`` removes it (inf) even if
            ``max_X`` is given. A velocity limit here wins over the URDF's (as in MoveIt);
            ``has_position_limits: true`` with ``min_position``/``max_position`` replaces the
            URDF's position limits (and is written into :attr:`urdf`). Joints of the chain the
            YAML does not name keep the URDF's limits and get no acceleration or jerk limit
            (inf); joints of the URDF it names that are not on the chain (fingers, ...) are
            ignored, and so are other keys (effort, deceleration, scaling factors); a name the
            URDF does not have is an error. Default: no YAML.

        Returns
        -------
        robot : Robot

        Raises
        ------
        ValueError
            If the file does not exist, the text is not a URDF, the tip frame does not exist,
            the tree branches and no tip is given, or a joint type is not supported; if the
            joint_limits file is missing, over 1 MiB or not YAML, has no ``joint_limits``
            mapping, names a joint the URDF does not have, a ``has_*`` flag is not a boolean, a
            flag is true without its value, or a value is not a number > 0 (the message names
            the source, the joint and the key); if the SRDF is missing, over the cap, not XML,
            has a ``<!DOCTYPE>`` or names a link the URDF does not have (the message names the
            link and the file).
        """
        text = _read_urdf_text(path_or_xml)
        folder = None if text is path_or_xml else Path(path_or_xml).resolve().parent
        return cls(text, tip, joint_limits, srdf, folder)

    @classmethod
    def from_dh(
        cls,
        table: npt.ArrayLike,
        joint_types: str | Sequence[str] | None = None,
        *,
        lower: npt.ArrayLike | None = None,
        upper: npt.ArrayLike | None = None,
        tip_offset: npt.ArrayLike | None = None,
        convention: Literal["modified", "standard"] = "modified",
        name: str = "dh_robot",
        joint_names: Sequence[str] | None = None,
        link_prefix: str = "link",
        tip: str = "tip",
        velocity: npt.ArrayLike | None = None,
        effort: npt.ArrayLike | None = None,
        acceleration: npt.ArrayLike | None = None,
        jerk: npt.ArrayLike | None = None,
    ) -> Robot:
        """Build a robot from a Denavit-Hartenberg table (see :func:`urdf_from_dh`).

        Parameters
        ----------
        table, joint_types, lower, upper, tip_offset, convention, name, joint_names, \
link_prefix, tip, velocity, effort
            As for :func:`urdf_from_dh` (``velocity`` goes into the URDF; 0, the default,
            reads inf: no limit).
        acceleration, jerk : array-like, shape (n,) or scalar, optional
            Limits in rad/s^2 and rad/s^3 (m/s^2, m/s^3 for prismatic joints), each > 0 or inf
            (no limit). Default: none (inf). They are not part of a URDF: they become the
            robot's :attr:`acceleration_limit` and :attr:`jerk_limit`, as a joint_limits YAML
            would make them in :meth:`from_urdf`.

        Returns
        -------
        robot : Robot
            Its tip is the frame ``tip``; ``robot.urdf`` holds the generated URDF.

        Raises
        ------
        ValueError
            Bad input to :func:`urdf_from_dh`, or an acceleration or jerk limit that is not
            > 0 (or has the wrong shape).
        """
        urdf = urdf_from_dh(
            table,
            joint_types,
            lower=lower,
            upper=upper,
            tip_offset=tip_offset,
            convention=convention,
            name=name,
            joint_names=joint_names,
            link_prefix=link_prefix,
            tip=tip,
            velocity=velocity,
            effort=effort,
        )
        if acceleration is None and jerk is None:
            return cls(urdf, tip)
        names = [
            str(j.get("name"))
            for j in ET.fromstring(urdf).iter("joint")
            if j.get("type") != "fixed"
        ]
        limits = joint_limits_mapping(
            names,
            acceleration=_positive_per_joint(acceleration, "acceleration", len(names), "rad/s^2"),
            jerk=_positive_per_joint(jerk, "jerk", len(names), "rad/s^3"),
        )
        return cls(urdf, tip, limits)

    def __reduce__(
        self,
    ) -> tuple[type[Robot], tuple[str, str, dict[str, Any], str | None, str | None]]:
        """Pickle as the URDF text, tip, limits, SRDF text and mesh folder (for worker
        processes; never for files):
        rebuilt from them, the copy computes exactly what this robot computes and has the same
        limits (position limits from a joint_limits YAML are in :attr:`urdf`). Pickling
        pinocchio's model and data as they are loses the work data of the fast paths."""
        limits = joint_limits_mapping(
            self.joint_names, self.velocity_limit, self.acceleration_limit, self.jerk_limit
        )
        mesh_dir = None if self._mesh_dir is None else str(self._mesh_dir)
        return (type(self), (self.urdf, self.tip, limits, self.srdf, mesh_dir))

    def __repr__(self) -> str:
        return (
            f"Robot(name={short(self.name)}, n_joints={self.n_joints}, base={short(self.base)}, "
            f"tip={short(self.tip)}, joint_names={self.joint_names})"
        )

    # ---------------------------------------------------------------- validation and limits

    def check_joints(
        self, q: npt.ArrayLike, name: str = "q", *, enforce_limits: bool = False
    ) -> NDArray[np.float64]:
        """Validate joint positions and return them as a float64 array.

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)
            One configuration or a batch.
        name : str
            The argument's name, used in error messages.
        enforce_limits : bool
            Also require ``lower <= q <= upper``.

        Returns
        -------
        q : ndarray, shape (n,) or (M, n)

        Raises
        ------
        ValueError
            Wrong shape, NaN or infinite values, or (with ``enforce_limits``) a value outside
            the joint limits; the message names the argument, the expected and the actual value.
        """
        if (
            not enforce_limits
            and type(q) is np.ndarray
            and q.dtype == np.float64
            and q.shape == self._single_shape
            and math.isfinite(q @ q)  # fast path of the reproduction loop: one BLAS dot
        ):
            return q
        arr = check_array(q, name, ndim=(1, 2))
        if arr.shape[-1] != self.n_joints:
            want = (self.n_joints,) if arr.ndim == 1 else ("M", self.n_joints)
            raise ValueError(
                f"{name} must have shape {shape_str(want)} (one value per joint "
                f"{self.joint_names}), got {shape_str(arr.shape)}"
            )
        if enforce_limits:
            bad = (arr < self.lower) | (arr > self.upper)
            if bad.any():
                idx = np.argwhere(bad)[0]
                j = int(idx[-1])
                where = f"{name}[{', '.join(str(int(k)) for k in idx)}]"
                raise ValueError(
                    f"{where} (joint '{self.joint_names[j]}') must be within "
                    f"[{self.lower[j]:.6g}, {self.upper[j]:.6g}], got {arr[tuple(idx)]:.6g}; "
                    f"use robot.clip({name}) to bring it inside the limits"
                )
        return arr

    def within_limits(self, q: npt.ArrayLike, tol: float = 0.0) -> bool | NDArray[np.bool_]:
        """Whether joint positions are inside the limits (widened by ``tol``).

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)
        tol : float
            Allowed excess beyond each limit.

        Returns
        -------
        inside : bool, or ndarray of bool with shape (M,) for a batch
        """
        arr = self.check_joints(q)
        ok = np.all((arr >= self.lower - tol) & (arr <= self.upper + tol), axis=-1)
        return bool(ok) if arr.ndim == 1 else ok

    def clip(self, q: npt.ArrayLike) -> NDArray[np.float64]:
        """Clip joint positions to the limits.

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)

        Returns
        -------
        q_clipped : ndarray, shape (n,) or (M, n)
        """
        return np.clip(self.check_joints(q), self.lower, self.upper)

    # ---------------------------------------------------------------- kinematics

    def fk(self, q: npt.ArrayLike) -> NDArray[np.float64]:
        """Tip position in the base frame.

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)
            Joint positions.

        Returns
        -------
        x : ndarray, shape (3,) or (M, 3)
        """
        arr = self.check_joints(q)
        if arr.ndim == 1:
            pin.forwardKinematics(self._model, self._data, arr)
            return np.array(
                pin.updateFramePlacement(self._model, self._data, self._tip_id).translation
            )
        x, _ = _chain_fk_jacobian(
            arr, self._consts, self._revolute, self._tip_rot, self._tip_trans, jacobian=False
        )
        return x

    def jacobian(self, q: npt.ArrayLike) -> NDArray[np.float64]:
        """Position Jacobian dx/dq of the tip, in the base frame.

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)

        Returns
        -------
        J : ndarray, shape (3, n) or (M, 3, n)
        """
        return self.fk_jacobian(q)[1]

    def fk_jacobian(self, q: npt.ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Tip position and position Jacobian in one pass.

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)

        Returns
        -------
        x : ndarray, shape (3,) or (M, 3)
            Tip position in the base frame.
        J : ndarray, shape (3, n) or (M, 3, n)
            Position Jacobian dx/dq in the base frame (rows 0:3 of pinocchio's
            LOCAL_WORLD_ALIGNED frame Jacobian).
        """
        arr = self.check_joints(q)
        if arr.ndim == 1:
            return self.fk_jacobian_unchecked(arr)
        x, jb = _chain_fk_jacobian(
            arr, self._consts, self._revolute, self._tip_rot, self._tip_trans, jacobian=True
        )
        assert jb is not None
        return x, jb

    def fk_pose(self, q: npt.ArrayLike) -> NDArray[np.float64]:
        """Tip pose in the base frame: its position and orientation.

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)

        Returns
        -------
        pose : ndarray, shape (4, 4) or (M, 4, 4)
            Homogeneous transforms [[R, x], [0, 0, 0, 1]]: R the tip frame's axes in the base
            frame, x = :meth:`fk`.
        """
        arr = self.check_joints(q)
        if arr.ndim == 1:
            pin.forwardKinematics(self._model, self._data, arr)
            return np.array(pin.updateFramePlacement(self._model, self._data, self._tip_id))
        tf, _ = _chain_fk_jacobian(
            arr,
            self._consts,
            self._revolute,
            self._tip_rot,
            self._tip_trans,
            jacobian=False,
            pose=True,
        )
        return tf

    def jacobian6(self, q: npt.ArrayLike) -> NDArray[np.float64]:
        """The tip's 6-D Jacobian: [dx/dq ; omega/dq], linear rows then angular rows, both in
        the base frame (pinocchio's LOCAL_WORLD_ALIGNED frame Jacobian).

        The angular rows give the tip's angular velocity omega = J_w dq in base axes (for a
        revolute joint, its axis in the base frame; 0 for a prismatic one). An orientation
        error e = log(R R_ref^T) moves with de = J_l(e)^-1 J_w dq
        (:mod:`pbdkit._rotations`).

        Parameters
        ----------
        q : array-like, shape (n,) or (M, n)

        Returns
        -------
        J : ndarray, shape (6, n) or (M, 6, n)
        """
        arr = self.check_joints(q)
        if arr.ndim == 1:
            return self.fk_pose_jacobian_unchecked(arr)[2]
        _, j6 = _chain_fk_jacobian(
            arr,
            self._consts,
            self._revolute,
            self._tip_rot,
            self._tip_trans,
            jacobian=True,
            pose=True,
        )
        assert j6 is not None
        return j6

    def ik(
        self,
        target: npt.ArrayLike,
        q0: npt.ArrayLike | None = None,
        *,
        orientation: npt.ArrayLike | None = None,
        tol: float = 1e-4,
        max_iter: int = 200,
    ) -> NDArray[np.float64]:
        """Joint angles that put the tip at ``target`` (and ``orientation``), within the limits.

        Damped least squares from ``q0`` (:mod:`pbdkit.robots._ik`): position only, or with
        ``orientation`` the 6-D Jacobian (:meth:`jacobian6`).

        Parameters
        ----------
        target : array-like, shape (3,)
            Tip position in the base frame.
        q0 : array-like, shape (n,), optional
            Initial posture, within the joint limits; it picks the solution (elbow up or down,
            a redundant arm's null space). Default: the middle of the limits,
            (lower + upper) / 2.
        orientation : array-like, shape (3, 3), optional
            The tip frame's axes in the base frame (as in :meth:`fk_pose`); None: position only.
        tol : float
            Largest residual accepted: the norm of the position error (m) stacked with the
            orientation error (rotation vector, rad).
        max_iter : int
            Iterations at most.

        Returns
        -------
        q : ndarray, shape (n,)
            Within [lower, upper], with a residual below ``tol``.

        Raises
        ------
        ValueError
            Bad input (the message names the argument), or no convergence (the message gives
            the residual, ``tol`` and ``max_iter``): the target is out of reach, beyond a joint
            limit, or needs another ``q0``.
        """
        return ik(self, target, q0, orientation=orientation, tol=tol, max_iter=max_iter)

    def fk_pose_jacobian_unchecked(
        self, q: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Tip position (3,), rotation (3, 3) and 6-D Jacobian (6, n) for one configuration,
        without input validation (control loops; ``q`` as for :meth:`fk_jacobian_unchecked`)."""
        jac = pin.computeFrameJacobian(self._model, self._data, q, self._tip_id, self._lf)
        placement = self._oMf[self._tip_id]
        full = np.array(jac, dtype=np.float64).reshape(6, self.n_joints)
        return placement.translation.copy(), placement.rotation.copy(), full

    def fk_jacobian_unchecked(
        self, q: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`fk_jacobian` for one configuration without input validation (control loops).

        Parameters
        ----------
        q : ndarray of float64, shape (n,)
            Must already be a finite, contiguous float64 array of the right length (as returned
            by :meth:`check_joints`); anything else gives undefined results.

        Returns
        -------
        x : ndarray, shape (3,)
        J : ndarray, shape (3, n)
        """
        jac = pin.computeFrameJacobian(self._model, self._data, q, self._tip_id, self._lf)
        # computeFrameJacobian also updates data.oMf[tip] for this q
        x = np.array(self._oMf[self._tip_id].translation)
        if self.n_joints == 1:  # pinocchio returns a 1-D array when nv == 1
            return x, np.array(jac[:3]).reshape(3, 1)
        return x, np.ascontiguousarray(jac[:3])

    def fk_jacobian_axes_unchecked(
        self, q: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`fk_jacobian_unchecked` and the joints' axes, for second derivatives of f.

        For a serial chain, d^2 x / (d theta_a d theta_b) = omega_min(a,b) x J_max(a,b), with
        omega_i the world axis of revolute joint i (0 for a prismatic one) and J_i the column
        of the position Jacobian: the axes are the angular rows of the frame Jacobian
        (pinocchio, LOCAL_WORLD_ALIGNED), returned at no extra cost.

        Returns
        -------
        x : ndarray, shape (3,)
        J : ndarray, shape (3, n)
        axes : ndarray, shape (n, 3)
        """
        jac = pin.computeFrameJacobian(self._model, self._data, q, self._tip_id, self._lf)
        x = self._oMf[self._tip_id].translation.copy()
        # Views of the fresh (6, n) array pinocchio returns (C order: its first 3 rows are
        # contiguous); copies would cost a third of the call.
        full = np.asarray(jac).reshape(6, self.n_joints)
        return x, full[:3], full[3:].T
