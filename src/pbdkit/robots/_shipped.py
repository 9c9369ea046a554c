"""Robot models shipped with pbdkit.

=========  ======  ==============================================================================
name       joints  source
=========  ======  ==============================================================================
katana     5       Neuronics Katana 6M180 (the paper's arm): ``katana_6m180.urdf`` in this package,
                   written from published dimensions, primitive geometry and inertias for MuJoCo.
                   Joints pan, lift1, lift2, lift3, wrist_roll; tip frame ``tool``.
                   Limits: velocity 1.19 rad/s (the URDF's, the top motor speed); acceleration
                   6 rad/s^2 and jerk 60 rad/s^3 on every joint from
                   ``katana_6m180_joint_limits.yaml`` (the maker publishes none: conservative
                   values, about twice the peaks of the simulated teacher's demonstrations).
                   Collision model: the URDF's 6 cylinders and box, with the disabled pairs of
                   ``katana_6m180.srdf`` (found by :func:`pbdkit.robots.disabled_pairs`).
panda      7       Franka Emika Panda, from its published modified-DH parameters (generated at call
                   time). Joints panda_joint1..7; tip frame ``flange``.
                   Limits: Franka's published velocity, acceleration and jerk limits from
                   ``panda_joint_limits.yaml``; position limits in the generated URDF.
                   Collision model: the spheres and cylinders of franka_description (via
                   example-robot-data, Apache-2.0: ``panda_collision.urdf``,
                   ``LICENSE-panda_description.txt``) on links panda_link0..7 and on panda_hand
                   and its fingers (fixed after the flange, 0.04 m open), with the disabled pairs
                   of its SRDF (``panda.srdf``).
=========  ======  ==============================================================================

The ``*_joint_limits.yaml`` files are in the ``joint_limits.yaml`` format of MoveIt and
ros2_control (see :meth:`pbdkit.Robot.from_urdf`). Everything is read from the package's files.

Use :func:`load` to get a robot by name (e.g. from a command-line option),
:func:`katana_urdf_path` for the file a simulator loads, :func:`katana_srdf_path` for its
disabled collision pairs, and :func:`katana_joint_limits_path` /
:func:`panda_joint_limits_path` for the limit files (to load a variant with
``Robot.from_urdf(..., joint_limits=path)``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from importlib.resources import files
from pathlib import Path

from .._validation import short
from ._robot import Robot
from ._urdf import urdf_from_dh

__all__ = [
    "PANDA_DH",
    "available",
    "katana",
    "katana_joint_limits_path",
    "katana_srdf_path",
    "katana_urdf_path",
    "load",
    "panda",
    "panda_joint_limits_path",
]

_KATANA_FILE = "katana_6m180.urdf"
_KATANA_LIMITS_FILE = "katana_6m180_joint_limits.yaml"
_KATANA_SRDF_FILE = "katana_6m180.srdf"
_PANDA_LIMITS_FILE = "panda_joint_limits.yaml"
_PANDA_COLLISION_FILE = "panda_collision.urdf"
_PANDA_SRDF_FILE = "panda.srdf"
#: How far each Panda finger is open (m, 0 to 0.04) in the shipped model's collision geometry.
_PANDA_FINGER_OPENING = 0.04

#: Franka Panda modified-DH table (Craig), rows (a_{i-1}, alpha_{i-1}, d_i, theta_offset_i), from
#: Franka's published "Robot and interface specifications"; the flange is d = 0.107 m after joint 7.
PANDA_DH: tuple[tuple[float, float, float, float], ...] = (
    (0.0, 0.0, 0.333, 0.0),
    (0.0, -math.pi / 2, 0.0, 0.0),
    (0.0, math.pi / 2, 0.316, 0.0),
    (0.0825, math.pi / 2, 0.0, 0.0),
    (-0.0825, -math.pi / 2, 0.384, 0.0),
    (0.0, math.pi / 2, 0.0, 0.0),
    (0.088, math.pi / 2, 0.0, 0.0),
)
_PANDA_LOWER = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
_PANDA_UPPER = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)
_PANDA_EFFORT = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)


def katana_urdf_path() -> Path:
    """Path of the Katana 6M180 URDF shipped with pbdkit (primitive geometry only).

    Returns
    -------
    path : pathlib.Path
    """
    return _package_file(_KATANA_FILE)


def katana_srdf_path() -> Path:
    """Path of the Katana's SRDF shipped with pbdkit: the link pairs self-collision checking
    skips, found by :func:`pbdkit.robots.disabled_pairs` (10^6 postures, seed 0; each pair
    disabled as "Never" checked by minimising its distance; the file's comment has the
    numbers).

    Returns
    -------
    path : pathlib.Path
    """
    return _package_file(_KATANA_SRDF_FILE)


def katana_joint_limits_path() -> Path:
    """Path of the Katana's ``joint_limits.yaml`` shipped with pbdkit (acceleration and jerk).

    Returns
    -------
    path : pathlib.Path
    """
    return _package_file(_KATANA_LIMITS_FILE)


def panda_joint_limits_path() -> Path:
    """Path of the Panda's ``joint_limits.yaml`` shipped with pbdkit (Franka's published
    velocity, acceleration and jerk limits).

    Returns
    -------
    path : pathlib.Path
    """
    return _package_file(_PANDA_LIMITS_FILE)


def _package_file(name: str) -> Path:
    return Path(str(files("pbdkit.robots").joinpath(name)))


def katana() -> Robot:
    """The 5-DOF Katana 6M180 of the paper, tip = the ``tool`` frame (0.1505 m on the roll axis).

    Returns
    -------
    robot : Robot
        Joints pan, lift1, lift2, lift3, wrist_roll; base = ``base_link``. Velocity limits
        1.19 rad/s (the URDF's), acceleration 6 rad/s^2 and jerk 60 rad/s^3 on every joint
        (:func:`katana_joint_limits_path`: conservative values, the maker publishes none).
        Its collision model: the URDF's primitives, with the disabled pairs of
        :func:`katana_srdf_path`.
    """
    return Robot.from_urdf(
        katana_urdf_path().read_text(encoding="utf-8"),
        tip="tool",
        joint_limits=katana_joint_limits_path(),
        srdf=katana_srdf_path(),
    )


def panda() -> Robot:
    """The 7-DOF Franka Emika Panda from its modified-DH table, tip = the ``flange`` frame.

    Returns
    -------
    robot : Robot
        Joints panda_joint1 ... panda_joint7; links panda_link0 (base) ... panda_link7.
        Franka's published limits ("Robot and interface specifications"): position in the
        generated URDF; velocity 2.175 rad/s (joints 1-4) and 2.61 rad/s (5-7), acceleration
        15, 7.5, 10, 12.5, 15, 20, 20 rad/s^2 and jerk 7500, 3750, 5000, 6250, 7500, 10000,
        10000 rad/s^3 from :func:`panda_joint_limits_path`.

        Its collision model: franka_description's spheres and cylinders (via
        example-robot-data 6.0.0, Apache-2.0; ``panda_collision.urdf`` in this package) on
        panda_link0 ... panda_link7, and on the links panda_hand (fixed after the flange,
        turned -45 deg about its z axis as on the real arm) and panda_leftfinger /
        panda_rightfinger (fixed to the hand, each open 0.04 m: the widest opening); the
        disabled pairs of its SRDF (``panda.srdf``: upstream's, plus link5 / right finger,
        which these spheres overlap at the default posture as the hand's do). The kinematics
        are the DH table's: the hand adds no joint.
    """
    urdf = urdf_from_dh(
        PANDA_DH,
        lower=_PANDA_LOWER,
        upper=_PANDA_UPPER,
        tip_offset=(0.0, 0.0, 0.107),
        convention="modified",
        name="panda",
        joint_names=[f"panda_joint{i}" for i in range(1, 8)],
        link_prefix="panda_link",
        tip="flange",
        effort=_PANDA_EFFORT,
    )
    return Robot.from_urdf(
        _with_panda_collision(urdf),
        tip="flange",
        joint_limits=panda_joint_limits_path(),
        srdf=_package_file(_PANDA_SRDF_FILE),
    )


def _with_panda_collision(urdf: str) -> str:
    """The DH-generated Panda URDF with the vendored collision elements put on its links by
    name, and the hand and fingers added as fixed links after the flange."""
    root = ET.fromstring(urdf)
    vendored = ET.fromstring(_package_file(_PANDA_COLLISION_FILE).read_text(encoding="utf-8"))
    source = {str(link.get("name")): link for link in vendored.findall("link")}
    ours = {str(link.get("name")): link for link in root.findall("link")}
    for i in range(8):
        ours[f"panda_link{i}"].extend(source[f"panda_link{i}"].findall("collision"))
    root.insert(
        0,
        ET.Comment(
            " Kinematics: pbdkit.robots.urdf_from_dh from pbdkit.robots.PANDA_DH (modified DH). "
            "Collision geometry: franka_description (franka_ros) via example-robot-data 6.0.0, "
            "Apache-2.0 (pbdkit/robots/panda_collision.urdf, LICENSE-panda_description.txt). "
        ),
    )
    joints = {str(joint.get("name")): joint for joint in vendored.findall("joint")}
    for name, parent, joint_name in (
        ("panda_hand", "flange", "panda_hand_joint"),
        ("panda_leftfinger", "panda_hand", "panda_finger_joint1"),
        ("panda_rightfinger", "panda_hand", "panda_finger_joint2"),
    ):
        root.append(source[name])
        upstream = joints[joint_name]
        origin = upstream.find("origin")
        assert origin is not None
        xyz = [float(v) for v in origin.get("xyz", "0 0 0").split()]
        axis = upstream.find("axis")
        if axis is not None:  # a finger: its prismatic joint fixed at the opening
            direction = [float(v) for v in axis.get("xyz", "1 0 0").split()]
            xyz = [p + _PANDA_FINGER_OPENING * a for p, a in zip(xyz, direction, strict=True)]
        joint = ET.SubElement(root, "joint", {"name": joint_name, "type": "fixed"})
        ET.SubElement(joint, "parent", {"link": parent})
        ET.SubElement(joint, "child", {"link": name})
        ET.SubElement(
            joint,
            "origin",
            {"xyz": " ".join(repr(v) for v in xyz), "rpy": origin.get("rpy", "0 0 0")},
        )
    ET.indent(root, "  ")
    return ET.tostring(root, encoding="unicode") + "\n"


_FACTORIES: dict[str, Callable[[], Robot]] = {"katana": katana, "panda": panda}


def available() -> list[str]:
    """Names of the shipped robots, for :func:`load`.

    Returns
    -------
    names : list of str
    """
    return sorted(_FACTORIES)


def load(name: str) -> Robot:
    """A shipped robot by name.

    Parameters
    ----------
    name : str
        One of :func:`available`.

    Returns
    -------
    robot : Robot
    """
    try:
        factory = _FACTORIES[name]
    except KeyError:
        raise ValueError(f"name must be one of {available()}, got {short(name)}") from None
    return factory()
