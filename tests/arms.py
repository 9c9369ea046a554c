"""Arms that are not a pbdkit.Robot, for tests of the robot contract (pbdkit.robots'
KinematicModel): a wrapper that hands on exactly the members the Protocol declares."""

from __future__ import annotations

from typing import Any

import numpy as np

from pbdkit.robots import KinematicModel, Robot
from pbdkit.robots._protocols import _members


class KinematicOnly:
    """The KinematicModel members of ``robot`` and nothing else (no URDF, no tip, no poses);
    ``overrides`` replace some of them (a velocity limit, say)."""

    def __init__(self, robot: Robot, **overrides: Any) -> None:
        for name in _members(KinematicModel):
            value = overrides.pop(name, getattr(robot, name))
            object.__setattr__(self, name, value)
        assert not overrides, f"not KinematicModel members: {sorted(overrides)}"


def no_limits(n: int) -> dict[str, np.ndarray]:
    """Velocity, acceleration and jerk limits of ``inf`` for ``n`` joints."""
    inf = np.full(n, np.inf)
    return {"velocity_limit": inf, "acceleration_limit": inf, "jerk_limit": inf}
