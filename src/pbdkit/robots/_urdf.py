"""URDF text: reading and checking a URDF, normalising its joints, the copy pinocchio loads, the
tip frame; and writing a URDF from a Denavit-Hartenberg table (:func:`urdf_from_dh`).

Only revolute and prismatic joints are supported. A ``continuous`` joint is turned into a revolute
joint limited to [-pi, pi] (pinocchio would otherwise give it two configuration variables, cos and
sin). ``floating`` and ``planar`` joints are rejected. In a URDF tree with branches only the joints
on the path from the root to the tip are actuated; the other joints cannot move the tip and are
locked. A ``<mimic>`` joint (one that follows another joint) on that path is refused: it would
become an independent actuated joint; off the path it is locked like any other. Meshes are never
loaded: only kinematics is built.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from copy import deepcopy
from pathlib import Path
from typing import Literal
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, shape_str, short
from ._joint_limits import JointLimits

__all__ = ["urdf_from_dh"]


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
                    f"joint '{joint.get('name', '?')}' has {tag} link {short(link)}, which is not "
                    "a "
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
        raise ValueError(f"convention must be 'modified' or 'standard', got {short(convention)}")
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
                f"got {short(joint_types)}"
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
            raise ValueError(f"joint_names must hold {n} distinct names, got {short(joint_names)}")
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
        raise ValueError(f"tip must differ from the link and joint names, got {short(tip)}")
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
            f'    <limit lower="{short(float(lo[i]))}" upper="{short(float(hi[i]))}" '
            f'effort="{short(float(eff[i]))}" velocity="{short(float(vel[i]))}"/>\n'
        )
        out.append("  </joint>\n")
    out.append(f'  <joint name={q(tip + "_joint")} type="fixed">\n')
    out.append(f"    <parent link={q(links[n])}/>\n    <child link={q(tip)}/>\n")
    out.append(_origin_xml(tip_origin, "    "))
    out.append("  </joint>\n</robot>\n")
    return "".join(out)
