"""Robots: a URDF's kinematics, limits and inverse kinematics (:class:`Robot`,
:meth:`Robot.ik`), its collision model (:class:`CollisionModel`; the link pairs to skip:
:func:`disabled_pairs`, saved by :func:`write_srdf`), the arms shipped with pbdkit
(:func:`katana`, :func:`panda`, by name: :func:`load`) and the pseudo-inverse the reproduction
uses (:func:`damped_pinv`, :func:`nullspace_projector`).

=========  ======  ==============================================================================
name       joints  source
=========  ======  ==============================================================================
katana     5       Neuronics Katana 6M180 (the paper's arm): ``katana_6m180.urdf`` in this package,
                   written from published dimensions, primitive geometry and inertias for MuJoCo.
                   Joints pan, lift1, lift2, lift3, wrist_roll; tip frame ``tool``.
                   Collision model: the URDF's primitives, disabled pairs ``katana_6m180.srdf``.
panda      7       Franka Emika Panda, from its published modified-DH parameters (generated at call
                   time). Joints panda_joint1..7; tip frame ``flange``. Collision model:
                   franka_description's spheres and cylinders (Apache-2.0) on the links, the hand
                   and the fingers (fixed, 0.04 m open), and its SRDF's disabled pairs.
=========  ======  ==============================================================================
"""

from __future__ import annotations

from ._collision import CollisionModel
from ._kinematics import damped_pinv, nullspace_projector
from ._pairs import disabled_pairs
from ._protocols import KinematicModel, PoseKinematicModel, RobotDescription
from ._robot import Robot
from ._shipped import (
    available,
    katana,
    katana_joint_limits_path,
    katana_srdf_path,
    katana_urdf_path,
    load,
    panda,
    panda_joint_limits_path,
)
from ._srdf import write_srdf
from ._urdf import urdf_from_dh

__all__ = [
    "CollisionModel",
    "KinematicModel",
    "PoseKinematicModel",
    "Robot",
    "RobotDescription",
    "available",
    "damped_pinv",
    "disabled_pairs",
    "katana",
    "katana_joint_limits_path",
    "katana_srdf_path",
    "katana_urdf_path",
    "load",
    "nullspace_projector",
    "panda",
    "panda_joint_limits_path",
    "urdf_from_dh",
    "write_srdf",
]
