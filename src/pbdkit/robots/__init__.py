"""Robots: a URDF's kinematics, limits and inverse kinematics (:class:`Robot`,
:meth:`Robot.ik`), the arms shipped with pbdkit (:func:`katana`, :func:`panda`, by name:
:func:`load`) and the pseudo-inverse the reproduction uses (:func:`damped_pinv`,
:func:`nullspace_projector`).

=========  ======  ==============================================================================
name       joints  source
=========  ======  ==============================================================================
katana     5       Neuronics Katana 6M180 (the paper's arm): ``katana_6m180.urdf`` in this package,
                   written from published dimensions, primitive geometry and inertias for MuJoCo.
                   Joints pan, lift1, lift2, lift3, wrist_roll; tip frame ``tool``.
panda      7       Franka Emika Panda, from its published modified-DH parameters (generated at call
                   time, kinematics only). Joints panda_joint1..7; tip frame ``flange``.
=========  ======  ==============================================================================
"""

from __future__ import annotations

from ._kinematics import damped_pinv, nullspace_projector
from ._protocols import KinematicModel, PoseKinematicModel, RobotDescription
from ._robot import Robot
from ._shipped import (
    available,
    katana,
    katana_joint_limits_path,
    katana_urdf_path,
    load,
    panda,
    panda_joint_limits_path,
)
from ._urdf import urdf_from_dh

__all__ = [
    "KinematicModel",
    "PoseKinematicModel",
    "Robot",
    "RobotDescription",
    "available",
    "damped_pinv",
    "katana",
    "katana_joint_limits_path",
    "katana_urdf_path",
    "load",
    "nullspace_projector",
    "panda",
    "panda_joint_limits_path",
    "urdf_from_dh",
]
