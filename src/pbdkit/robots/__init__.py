"""Robot models shipped with pbdkit.

=========  ======  ==============================================================================
name       joints  source
=========  ======  ==============================================================================
katana     5       Neuronics Katana 6M180 (the paper's arm): ``katana_6m180.urdf`` in this package,
                   written from published dimensions, primitive geometry and inertias for MuJoCo.
                   Joints pan, lift1, lift2, lift3, wrist_roll; tip frame ``tool``.
panda      7       Franka Emika Panda, from its published modified-DH parameters (generated at call
                   time, kinematics only). Joints panda_joint1..7; tip frame ``flange``.
=========  ======  ==============================================================================

Use :func:`load` to get a robot by name (e.g. from a command-line option) and
:func:`katana_urdf_path` for the file a simulator loads.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from importlib.resources import files
from pathlib import Path

from ..robot import Robot

__all__ = ["PANDA_DH", "available", "katana", "katana_urdf_path", "load", "panda"]

_KATANA_FILE = "katana_6m180.urdf"

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
_PANDA_VELOCITY = (2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61)
_PANDA_EFFORT = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)


def katana_urdf_path() -> Path:
    """Path of the Katana 6M180 URDF shipped with pbdkit (primitive geometry only).

    Returns
    -------
    path : pathlib.Path
    """
    return Path(str(files(__name__).joinpath(_KATANA_FILE)))


def katana() -> Robot:
    """The 5-DOF Katana 6M180 of the paper, tip = the ``tool`` frame (0.1505 m on the roll axis).

    Returns
    -------
    robot : Robot
        Joints pan, lift1, lift2, lift3, wrist_roll; base = ``base_link``.
    """
    return Robot.from_urdf(katana_urdf_path().read_text(encoding="utf-8"), tip="tool")


def panda() -> Robot:
    """The 7-DOF Franka Emika Panda from its modified-DH table, tip = the ``flange`` frame.

    Returns
    -------
    robot : Robot
        Joints panda_joint1 ... panda_joint7; links panda_link0 (base) ... panda_link7.
    """
    return Robot.from_dh(
        PANDA_DH,
        lower=_PANDA_LOWER,
        upper=_PANDA_UPPER,
        tip_offset=(0.0, 0.0, 0.107),
        convention="modified",
        name="panda",
        joint_names=[f"panda_joint{i}" for i in range(1, 8)],
        link_prefix="panda_link",
        tip="flange",
        velocity=_PANDA_VELOCITY,
        effort=_PANDA_EFFORT,
    )


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
        raise ValueError(f"name must be one of {available()}, got {name!r}") from None
    return factory()
