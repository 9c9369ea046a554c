"""Robot kinematics from URDF: tool position, position Jacobian and joint limits of a serial arm.

A :class:`Robot` is built from a URDF (file or XML text) with pinocchio and exposes the forward
kinematics of one *tip* frame, x = f(theta), and its position Jacobian J = dx/dtheta, both in the
frame of the URDF's root link (the base).

Two evaluation paths give the same numbers (tested to 1e-12):

- one configuration ``q`` of shape (n,): pinocchio (``computeFrameJacobian``, about 1 us);
- a batch ``Q`` of shape (M, n): a vectorized numpy chain built once from the pinocchio model
  (joint placements, joint axes, tip placement), one pass over the joints for the whole batch.

Only revolute and prismatic joints are supported. A ``continuous`` joint is turned into a revolute
joint limited to [-pi, pi] (pinocchio would otherwise give it two configuration variables, cos and
sin). ``floating`` and ``planar`` joints are rejected. In a URDF tree with branches only the joints
on the path from the root to the tip are actuated; the other joints cannot move the tip and are
locked. A ``<mimic>`` joint (one that follows another joint) on that path is refused: it would
become an independent actuated joint; off the path it is locked like any other. Meshes are never
loaded: only kinematics is built.

Limits. Position and velocity limits come from the URDF's ``<limit>`` tags; a velocity of 0
(URDF's "not limited", also what a continuous joint without ``<limit>`` gets) reads inf. URDF has
no acceleration or jerk limits: they come from a ``joint_limits.yaml`` file in the format of
MoveIt and ros2_control (``Robot.from_urdf(..., joint_limits=...)``, see
:mod:`pbdkit.robots._joint_limits` for the rules), which also overrides the URDF's velocity limits
(as in MoveIt) and, with ``has_position_limits: true``, its position limits. A joint without a
declared limit has inf.

:func:`urdf_from_dh` writes a URDF from a Denavit-Hartenberg table (modified/Craig or standard),
and :meth:`Robot.from_dh` loads it.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from copy import deepcopy
from pathlib import Path
from typing import Any, Literal
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from numpy.typing import NDArray

from .._validation import check_array, shape_str
from ._joint_limits import JointLimits, JointLimitsSource, joint_limits_mapping, read_joint_limits

__all__ = ["Robot", "urdf_from_dh"]

_SUPPORTED_JOINTS = ("revolute", "prismatic", "continuous", "fixed")


# --------------------------------------------------------------------------------------------
# URDF text: loading, checking, tree analysis
# --------------------------------------------------------------------------------------------


def _read_urdf_text(path_or_xml: str | os.PathLike[str]) -> str:
    """Return the URDF XML text from a path or from the text itself."""
    if isinstance(path_or_xml, os.PathLike):
        path = Path(path_or_xml)
    elif isinstance(path_or_xml, str):
        if path_or_xml.lstrip("\ufeff \t\r\n").startswith("<"):
            return path_or_xml
        path = Path(path_or_xml)
    else:
        raise ValueError(
            "path_or_xml must be a path to a URDF file or the URDF XML text, "
            f"got {type(path_or_xml).__name__}"
        )
    if not path.is_file():
        what = "is a directory" if path.is_dir() else "does not exist"
        raise ValueError(
            f"path_or_xml: URDF file '{path}' {what}; pass an existing file path "
            "or the URDF XML text (starting with '<')"
        )
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"path_or_xml: '{path}' is not a UTF-8 text URDF (byte {exc.start} cannot be "
            f"decoded: {exc.reason}); pass a URDF XML file"
        ) from exc


def _parse_urdf(xml: str) -> ET.Element:
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise ValueError(f"path_or_xml is not valid XML ({exc}); expected a URDF <robot>") from exc
    if root.tag != "robot":
        raise ValueError(
            f"path_or_xml must be a URDF with a <robot> root element, got <{root.tag}>"
        )
    return root


def _normalize_joints(root: ET.Element) -> bool:
    """Check joint types; turn continuous joints into revolute ones limited to [-pi, pi].

    Returns True if the tree was modified.
    """
    changed = False
    for joint in root.iter("joint"):
        if joint.find("parent") is None:  # <joint> elements inside e.g. <transmission>
            continue
        jtype = joint.get("type", "")
        name = joint.get("name", "?")
        if jtype not in _SUPPORTED_JOINTS:
            raise ValueError(
                f"joint '{name}' has type '{jtype}'; supported types are "
                f"{', '.join(_SUPPORTED_JOINTS)} (a fixed base is the URDF root)"
            )
        axis = joint.find("axis")
        if jtype != "fixed" and axis is not None:
            try:
                values = [float(v) for v in axis.get("xyz", "1 0 0").split()]
            except ValueError:
                values = []
            if len(values) != 3 or not all(map(math.isfinite, values)) or not any(values):
                raise ValueError(
                    f"joint '{name}' has axis xyz='{axis.get('xyz')}'; give 3 finite numbers, "
                    "not all zero"
                )
        if jtype in ("revolute", "prismatic") and joint.find("limit") is None:
            raise ValueError(
                f"{jtype} joint '{name}' has no <limit>; add "
                '<limit lower="..." upper="..." effort="..." velocity="..."/>'
            )
        if jtype == "continuous":
            joint.set("type", "revolute")
            limit = joint.find("limit")
            if limit is None:
                limit = ET.SubElement(joint, "limit")
                limit.set("effort", "0")
                limit.set("velocity", "0")
            limit.set("lower", repr(-math.pi))
            limit.set("upper", repr(math.pi))
            changed = True
    return changed


def _pinocchio_xml(root: ET.Element, urdf: str) -> tuple[str, dict[str, str]]:
    """The URDF text given to pinocchio (``urdf``, the text of ``root``, unless a joint is
    renamed), and its joint names -> the URDF's.

    A joint may share its name with a link (SO-100's ``gripper``); pinocchio then finds two
    frames of that name and fails to lock the joint off the tip's chain. Such joints are renamed
    in pinocchio's copy only: the names users see are the URDF's.
    """
    links = {link.get("name", "") for link in root.iter("link")}
    joints = [j for j in root.iter("joint") if j.find("parent") is not None]
    taken = links | {j.get("name", "") for j in joints}
    renamed: dict[str, str] = {}
    for joint in joints:
        name = joint.get("name", "")
        if name in links:
            alias = f"{name}_joint"
            while alias in taken:
                alias += "_"
            taken.add(alias)
            renamed[name] = alias
    if not renamed:
        return urdf, {}
    copy = deepcopy(root)
    for joint in copy.iter("joint"):
        if joint.find("parent") is not None and joint.get("name", "") in renamed:
            joint.set("name", renamed[joint.get("name", "")])
        mimic = joint.find("mimic")
        if mimic is not None and mimic.get("joint", "") in renamed:
            mimic.set("joint", renamed[mimic.get("joint", "")])
    return ET.tostring(copy, encoding="unicode"), {v: k for k, v in renamed.items()}


def _refuse_mimic_joints(root: ET.Element, actuated: Sequence[str]) -> None:
    """Refuse ``<mimic>`` joints among the actuated ones (pbdkit would move them freely)."""
    for joint in root.iter("joint"):
        mimic = joint.find("mimic")
        name = joint.get("name", "?")
        if mimic is not None and joint.find("parent") is not None and name in actuated:
            raise ValueError(
                f"joint '{name}' is a <mimic> joint (it follows '{mimic.get('joint', '?')}'), "
                "which pbdkit would treat as an independent actuated joint; remove the <mimic> "
                'tag to control it independently, or lock it (type="fixed")'
            )


def _choose_tip(root: ET.Element, tip: str | None) -> tuple[str, str]:
    """Check that the kinematic tree has one root; choose the tip link if none is given.

    Returns (root link, tip).
    """
    links = [link.get("name", "") for link in root.findall("link")]
    children: dict[str, list[str]] = {name: [] for name in links}
    child_links = set()
    for joint in root.findall("joint"):
        parent = joint.find("parent")
        child = joint.find("child")
        if parent is None or child is None:
            continue
        p, c = parent.get("link", ""), child.get("link", "")
        children.setdefault(p, []).append(c)
        child_links.add(c)
    if not links:
        raise ValueError("path_or_xml: the URDF has no <link>; expected a kinematic chain")
    known = set(links)
    for joint in root.findall("joint"):
        for tag in ("parent", "child"):
            elem = joint.find(tag)
            link = None if elem is None else elem.get("link")
            if link not in known:
                raise ValueError(
                    f"joint '{joint.get('name', '?')}' has {tag} link {link!r}, which is not a "
                    f"<link> of the URDF; links are {links}"
                )
    roots = [name for name in links if name not in child_links]
    if len(roots) != 1:
        raise ValueError(
            f"path_or_xml: a URDF must have exactly one root link, got {len(roots)}: {roots}"
        )
    if tip is not None:
        return roots[0], tip
    leaves = [name for name in links if not children.get(name)]
    if any(len(c) > 1 for c in children.values()):
        raise ValueError(
            "tip is None but the URDF tree branches; pass tip= one of the leaf links "
            f"{leaves} (or any other frame name)"
        )
    return roots[0], leaves[0]


def _write_position_limits(root: ET.Element, declared: dict[str, JointLimits]) -> bool:
    """Write declared position limits into the ``<limit>`` tags of the chain's joints.

    Returns True if the tree was modified.
    """
    changed = False
    for joint in root.iter("joint"):
        lim = declared.get(joint.get("name", ""))
        limit = joint.find("limit")
        if lim is None or lim.position is None or limit is None or joint.find("parent") is None:
            continue
        limit.set("lower", repr(lim.position[0]))
        limit.set("upper", repr(lim.position[1]))
        changed = True
    return changed


# --------------------------------------------------------------------------------------------
# The numpy chain (batch path)
# --------------------------------------------------------------------------------------------


def _skew(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _chain_constants(
    model: Any, data: Any, frame_id: int
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Constant matrices of the serial chain, one (3, 11) block per joint.

    For joint i with placement (R_p, p_p) in its parent joint frame and unit axis a (its own frame),
    C_i = [R_p, R_p K, R_p K^2, p_p, R_p a] with K = skew(a): then, with B = R_parent C_i,
    R_i = B0 + sin(q) B1 + (1 - cos q) B2 (Rodrigues), the joint origin is p_parent + B[:, 9] and
    the world axis is B[:, 10].

    Returns
    -------
    consts : ndarray, shape (n, 3, 11)
    revolute : ndarray of bool, shape (n,)
    tip_rotation : ndarray, shape (3, 3)
        Rotation of the tip frame in the last joint frame.
    tip_translation : ndarray, shape (3,)
        Position of the tip in the last joint frame.
    """
    n = model.nq
    consts = np.zeros((n, 3, 11))
    revolute = np.zeros(n, dtype=bool)
    q0 = pin.neutral(model)
    for i in range(1, model.njoints):
        if model.parents[i] != i - 1:
            raise ValueError(  # cannot happen after reduction to the root->tip path
                f"joint '{model.names[i]}' is not in a serial chain"
            )
        # The joint's motion subspace in its own frame = its column of the LOCAL joint Jacobian.
        # (pinocchio returns a 1-D array when nv == 1: reshape)
        local = np.asarray(pin.computeJointJacobian(model, data, q0, i)).reshape(6, -1)
        s = local[:, model.joints[i].idx_v]
        lin, ang = s[:3], s[3:]
        placement = model.jointPlacements[i]
        rot, trans = placement.rotation, placement.translation
        if np.linalg.norm(lin) < 1e-12 and abs(np.linalg.norm(ang) - 1.0) < 1e-12:
            k = _skew(ang)
            consts[i - 1, :, 0:3] = rot
            consts[i - 1, :, 3:6] = rot @ k
            consts[i - 1, :, 6:9] = rot @ k @ k
            consts[i - 1, :, 10] = rot @ ang
            revolute[i - 1] = True
        elif np.linalg.norm(ang) < 1e-12 and abs(np.linalg.norm(lin) - 1.0) < 1e-12:
            consts[i - 1, :, 0:3] = rot
            consts[i - 1, :, 10] = rot @ lin
        else:  # pragma: no cover - URDF has no helical joint
            raise ValueError(f"joint '{model.names[i]}' is neither revolute nor prismatic")
        consts[i - 1, :, 9] = trans
    frame = model.frames[frame_id]
    return (
        consts,
        revolute,
        np.array(frame.placement.rotation),
        np.array(frame.placement.translation),
    )


def _chain_fk_jacobian(
    q: NDArray[np.float64],
    consts: NDArray[np.float64],
    revolute: NDArray[np.bool_],
    tip_rotation: NDArray[np.float64],
    tip_translation: NDArray[np.float64],
    *,
    jacobian: bool,
    pose: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """Tip positions (M, 3) and position Jacobians (M, 3, n) for a batch q (M, n).

    With ``pose``: tip transforms (M, 4, 4) instead of positions, and 6-D Jacobians (M, 6, n)
    (linear rows, then angular rows, in the base frame) instead of position Jacobians.
    """
    m, n = q.shape
    s, c1 = np.sin(q), 1.0 - np.cos(q)
    rot = np.broadcast_to(np.eye(3), (m, 3, 3))
    pos = np.zeros((m, 3))
    axes = np.empty((m, n, 3))
    origins = np.empty((m, n, 3))
    for i in range(n):
        # (M*3, 3) @ (3, 11): one BLAS call for the whole batch
        b = (rot.reshape(m * 3, 3) @ consts[i]).reshape(m, 3, 11)
        axes[:, i] = b[:, :, 10]
        if revolute[i]:
            pos = pos + b[:, :, 9]
            rot = (
                b[:, :, 0:3]
                + s[:, i, None, None] * b[:, :, 3:6]
                + c1[:, i, None, None] * b[:, :, 6:9]
            )
        else:
            pos = pos + b[:, :, 9] + q[:, i, None] * b[:, :, 10]
            rot = np.ascontiguousarray(b[:, :, 0:3])
        origins[:, i] = pos
    x = pos + rot @ tip_translation
    if pose:
        tf = np.zeros((m, 4, 4))
        tf[:, :3, :3] = rot @ tip_rotation
        tf[:, :3, 3] = x
        tf[:, 3, 3] = 1.0
    if not jacobian:
        return (tf, None) if pose else (x, None)
    d = x[:, None, :] - origins  # (M, n, 3): from each joint origin to the tip
    # revolute column: w x (x_tip - p_i); prismatic column: w
    cols = np.empty((m, n, 3))
    cols[..., 0] = axes[..., 1] * d[..., 2] - axes[..., 2] * d[..., 1]
    cols[..., 1] = axes[..., 2] * d[..., 0] - axes[..., 0] * d[..., 2]
    cols[..., 2] = axes[..., 0] * d[..., 1] - axes[..., 1] * d[..., 0]
    if not revolute.all():
        cols[:, ~revolute] = axes[:, ~revolute]
    if pose:
        j6 = np.zeros((m, 6, n))
        j6[:, :3] = cols.transpose(0, 2, 1)
        j6[:, 3:] = np.where(revolute[None, :, None], axes, 0.0).transpose(0, 2, 1)
        return tf, j6
    return x, np.ascontiguousarray(cols.transpose(0, 2, 1))


# --------------------------------------------------------------------------------------------
# Robot
# --------------------------------------------------------------------------------------------


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

    All limit arrays are float64 and read-only.
    """

    def __init__(
        self,
        urdf: str,
        tip: str | None = None,
        joint_limits: JointLimitsSource | None = None,
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
        full_tip_id = self._frame_id(full, tip_name)
        tip_joint = full.frames[full_tip_id].parentJoint
        supports = set(full.supports[tip_joint])
        to_lock = [j for j in range(1, full.njoints) if j not in supports]
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
        on_chain = {name: declared[name] for name in names if name in declared}  # not fingers
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
        self._tip_id = self._frame_id(model, tip_name)
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
        self._lf = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        self._oMf = self._data.oMf
        self._single_shape = (self.n_joints,)

    @staticmethod
    def _frame_id(model: Any, name: str) -> int:
        # A link and a joint may share a name: prefer the link (BODY) frame.
        if model.existFrame(name, pin.FrameType.BODY):
            return int(model.getFrameId(name, pin.FrameType.BODY))
        return int(model.getFrameId(name))

    # ---------------------------------------------------------------- constructors

    @classmethod
    def from_urdf(
        cls,
        path_or_xml: str | os.PathLike[str],
        tip: str | None = None,
        joint_limits: JointLimitsSource | None = None,
    ) -> Robot:
        """Load a robot from a URDF file or URDF XML text, and optionally a joint_limits YAML.

        Parameters
        ----------
        path_or_xml : str or path-like
            A path to a ``.urdf`` file, or the XML text itself (a string starting with ``<``).
            Mesh files are never opened, so they need not exist.
        tip : str, optional
            Name of the frame (link or joint) to control. If None, the URDF must be a chain
            (no branches) and its last link is used.
        joint_limits : str, path-like or mapping, optional
            Limits in the ``joint_limits.yaml`` format of MoveIt and ros2_control: a path to
            such a file, its YAML text (a string with a newline or ``joint_limits:``), or the
            parsed mapping ``{"joint_limits": {joint: {"has_acceleration_limits": True,
            "max_acceleration": 15.0, ...}}}``. Read with ``yaml.safe_load`` only.
            ``has_X_limits: true`` with ``max_X`` (> 0, ``.inf`` for none) sets the velocity,
            acceleration or jerk limit; ``has_X_limits: false`` removes it (inf) even if
            ``max_X`` is given. A velocity limit here wins over the URDF's (as in MoveIt);
            ``has_position_limits: true`` with ``min_position``/``max_position`` replaces the
            URDF's position limits (and is written into :attr:`urdf`). Joints of the chain the
            YAML does not name keep the URDF's limits and get no acceleration or jerk limit
            (inf); joints it names that are not on the chain (fingers, ...) are ignored, and so
            are other keys (effort, deceleration, scaling factors). Default: no YAML.

        Returns
        -------
        robot : Robot

        Raises
        ------
        ValueError
            If the file does not exist, the text is not a URDF, the tip frame does not exist,
            the tree branches and no tip is given, or a joint type is not supported; if the
            joint_limits file is missing or not YAML, has no ``joint_limits`` mapping, a
            ``has_*`` flag is not a boolean, a flag is true without its value, or a value is
            not a number > 0 (the message names the source, the joint and the key).
        """
        return cls(_read_urdf_text(path_or_xml), tip, joint_limits)

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

    def __reduce__(self) -> tuple[type[Robot], tuple[str, str, dict[str, Any]]]:
        """Pickle as the URDF text, tip and limits (for worker processes; never for files):
        rebuilt from them, the copy computes exactly what this robot computes and has the same
        limits (position limits from a joint_limits YAML are in :attr:`urdf`). Pickling
        pinocchio's model and data as they are loses the work data of the fast paths."""
        limits = joint_limits_mapping(
            self.joint_names, self.velocity_limit, self.acceleration_limit, self.jerk_limit
        )
        return (type(self), (self.urdf, self.tip, limits))

    def __repr__(self) -> str:
        return (
            f"Robot(name={self.name!r}, n_joints={self.n_joints}, base={self.base!r}, "
            f"tip={self.tip!r}, joint_names={self.joint_names})"
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


# --------------------------------------------------------------------------------------------
# Denavit-Hartenberg -> URDF
# --------------------------------------------------------------------------------------------


def _rot_x(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(a: float) -> NDArray[np.float64]:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _transform(rot: NDArray[np.float64], trans: Sequence[float]) -> NDArray[np.float64]:
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = trans
    return t


def _rpy_from_matrix(rot: NDArray[np.float64]) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation matrix: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cp = math.hypot(rot[0, 0], rot[1, 0])
    pitch = math.atan2(-rot[2, 0], cp)
    if cp > 1e-9:
        roll = math.atan2(rot[2, 1], rot[2, 2])
        yaw = math.atan2(rot[1, 0], rot[0, 0])
    else:  # gimbal lock (pitch = +-pi/2): only roll -+ yaw is defined; take yaw = 0
        roll = math.atan2(-rot[1, 2], rot[1, 1])
        yaw = 0.0
    return roll, pitch, yaw


def _origin_xml(t: NDArray[np.float64], indent: str) -> str:
    xyz = " ".join(repr(float(v)) for v in t[:3, 3])
    rpy = " ".join(repr(float(v)) for v in _rpy_from_matrix(t[:3, :3]))
    return f'{indent}<origin xyz="{xyz}" rpy="{rpy}"/>\n'


def _per_joint(
    value: npt.ArrayLike | None, name: str, n: int, default: NDArray[np.float64]
) -> NDArray[np.float64]:
    if value is None:
        return default
    arr = check_array(value, name, ndim=(0, 1))
    if np.ndim(value) == 0:  # check_array makes a scalar (1,)
        return np.full(n, arr.item())
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) (one value per joint), got {arr.shape}")
    return arr


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
        raise ValueError(f"{name}[{i}] must be > 0 ({unit}; inf for no limit), got {got!r}")
    return arr


def urdf_from_dh(
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
) -> str:
    """Write a kinematics-only URDF from a Denavit-Hartenberg table.

    Row i of ``table`` is ``(a, alpha, d, theta_offset)`` for joint i:

    - ``convention="modified"`` (Craig): the row holds a_{i-1}, alpha_{i-1}, d_i, theta_i and
      T_{i-1,i} = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(theta_i) TransZ(d_i);
    - ``convention="standard"``: the row holds a_i, alpha_i, d_i, theta_i and
      T_{i-1,i} = RotZ(theta_i) TransZ(d_i) TransX(a_i) RotX(alpha_i).

    A revolute joint adds q_i to theta_i; a prismatic joint adds q_i to d_i. Every joint moves
    about (along) a local z axis. The links are ``{link_prefix}0`` (the base) to
    ``{link_prefix}n``, followed by the fixed frame ``tip`` placed at ``tip_offset`` in the last
    link frame (after the last row's constant part for the standard convention).

    Parameters
    ----------
    table : array-like, shape (n, 4)
        DH parameters, metres and radians.
    joint_types : str or sequence of str, optional
        Per joint "revolute"/"prismatic" (or a string of "R"/"P" such as ``"RRPRRR"``).
        Default: all revolute.
    lower, upper : array-like, shape (n,) or scalar, optional
        Joint limits. Default [-pi, pi] for revolute joints; required for prismatic joints.
    tip_offset : array-like, shape (3,) or (4, 4), optional
        Position (or homogeneous transform) of the tip frame in the last link frame.
        Default: no offset.
    convention : {"modified", "standard"}
    name : str
        Robot name. This and every other name are escaped in the XML (any text is safe).
    joint_names : sequence of str, length n, optional
        Default ``joint1`` ... ``jointn``.
    link_prefix : str
        Prefix of the link names.
    tip : str
        Name of the tip link.
    velocity, effort : array-like, shape (n,) or scalar, optional
        Values for the ``<limit>`` tags. Default 0 (unknown).

    Returns
    -------
    urdf : str
        The URDF XML text (no geometry, no inertia: kinematics only).
    """
    dh = check_array(table, "table", ndim=2)
    if dh.shape[1] != 4 or dh.shape[0] < 1:
        raise ValueError(
            "table must have shape (n, 4) with rows (a, alpha, d, theta_offset), "
            f"got {shape_str(dh.shape)}"
        )
    n = dh.shape[0]
    if convention not in ("modified", "standard"):
        raise ValueError(f"convention must be 'modified' or 'standard', got {convention!r}")
    if joint_types is None:
        types = ["revolute"] * n
    else:
        alias = {
            "r": "revolute",
            "p": "prismatic",
            "revolute": "revolute",
            "prismatic": "prismatic",
        }
        raw = list(joint_types)
        if len(raw) != n or any(str(t).lower() not in alias for t in raw):
            raise ValueError(
                f"joint_types must give {n} entries among 'revolute'/'prismatic' (or 'R'/'P'), "
                f"got {joint_types!r}"
            )
        types = [alias[str(t).lower()] for t in raw]
    prismatic = np.array([t == "prismatic" for t in types])
    if prismatic.any() and (lower is None or upper is None):
        raise ValueError("lower and upper are required when a joint is prismatic (metres)")
    lo = _per_joint(lower, "lower", n, np.full(n, -math.pi))
    hi = _per_joint(upper, "upper", n, np.full(n, math.pi))
    if np.any(lo > hi):
        raise ValueError(f"lower must be <= upper, got lower={lo.tolist()}, upper={hi.tolist()}")
    vel = _per_joint(velocity, "velocity", n, np.zeros(n))
    eff = _per_joint(effort, "effort", n, np.zeros(n))
    if joint_names is None:
        jnames = [f"joint{i + 1}" for i in range(n)]
    else:
        jnames = [str(s) for s in joint_names]
        if len(jnames) != n or len(set(jnames)) != n:
            raise ValueError(f"joint_names must hold {n} distinct names, got {joint_names!r}")
    if tip_offset is None:
        t_tip = np.eye(4)
    else:
        off = check_array(tip_offset, "tip_offset")
        if off.shape == (3,):
            t_tip = _transform(np.eye(3), off.tolist())
        elif off.shape == (4, 4):
            t_tip = off
        else:
            raise ValueError(
                f"tip_offset must have shape (3,) or (4, 4), got {shape_str(off.shape)}"
            )

    def constant(row: NDArray[np.float64]) -> NDArray[np.float64]:
        a, alpha, d, theta = (float(v) for v in row)
        if convention == "modified":
            # RotX(alpha) TransX(a) RotZ(theta) TransZ(d)
            return (
                _transform(_rot_x(alpha), (0.0, 0.0, 0.0))
                @ _transform(np.eye(3), (a, 0.0, 0.0))
                @ _transform(_rot_z(theta), (0.0, 0.0, 0.0))
                @ _transform(np.eye(3), (0.0, 0.0, d))
            )
        # RotZ(theta) TransZ(d) TransX(a) RotX(alpha)
        return (
            _transform(_rot_z(theta), (0.0, 0.0, d))
            @ _transform(np.eye(3), (a, 0.0, 0.0))
            @ _transform(_rot_x(alpha), (0.0, 0.0, 0.0))
        )

    if convention == "modified":
        origins = [constant(dh[i]) for i in range(n)]
        tip_origin = t_tip
    else:
        origins = [np.eye(4)] + [constant(dh[i]) for i in range(n - 1)]
        tip_origin = constant(dh[n - 1]) @ t_tip

    links = [f"{link_prefix}{i}" for i in range(n + 1)]
    if tip in links or tip in jnames:
        raise ValueError(f"tip must differ from the link and joint names, got {tip!r}")
    # Names are user text: quoteattr escapes them (&, <, >, quotes) into attribute values.
    q = quoteattr
    out = [
        '<?xml version="1.0"?>\n',
        f"<!-- Generated by pbdkit.robots.urdf_from_dh ({convention} DH). Kinematics only. -->\n",
        f"<robot name={q(str(name))}>\n",
    ]
    out += [f"  <link name={q(link)}/>\n" for link in [*links, tip]]
    for i in range(n):
        out.append(f'  <joint name={q(jnames[i])} type="{types[i]}">\n')
        out.append(f"    <parent link={q(links[i])}/>\n    <child link={q(links[i + 1])}/>\n")
        out.append(_origin_xml(origins[i], "    "))
        out.append('    <axis xyz="0 0 1"/>\n')
        out.append(
            f'    <limit lower="{float(lo[i])!r}" upper="{float(hi[i])!r}" '
            f'effort="{float(eff[i])!r}" velocity="{float(vel[i])!r}"/>\n'
        )
        out.append("  </joint>\n")
    out.append(f'  <joint name={q(tip + "_joint")} type="fixed">\n')
    out.append(f"    <parent link={q(links[n])}/>\n    <child link={q(tip)}/>\n")
    out.append(_origin_xml(tip_origin, "    "))
    out.append("  </joint>\n</robot>\n")
    return "".join(out)
