"""pbdkit: probabilistic Programming by Demonstration with constraints in joint and task space.

Implements Calinon & Billard, "A Probabilistic Programming by Demonstration Framework Handling
Constraints in Joint Space and Task Space" (IROS 2008): demonstrations are encoded by Gaussian
mixture models (GMM), generalized by Gaussian mixture regression (GMR), and reproduced for new
object positions by probabilistic inverse kinematics that fuses every constraint as a product of
Gaussians.

Notation (used in names and docstrings throughout)
--------------------------------------------------
=============  ==============================================================================
symbol         meaning
=============  ==============================================================================
t              time (rescaled so that every demonstration has ``n_steps`` steps)
theta          joint angles, shape (n,); ``joints`` in the API
x              hand (tool point) position in the robot's base frame, shape (3,)
o, o(n)        position of object n in the base frame, shape (3,)
x - o(n)       hand position relative to object n: the task space of object n
xi             a data point {t, xi^S} of a GMM (time first, then the spatial part)
pi_k           prior (weight) of GMM component k
mu_k, Sigma_k  mean and covariance of GMM component k
beta_k         responsibility of component k for a query (GMR)
J, J+          position Jacobian dx/dtheta (3, n) and its (damped) right pseudo-inverse
Lambda, eta    precision Sigma^-1 and information vector Sigma^-1 mu of a Gaussian
T, D, K, M     number of time steps, of dimensions, of components, batch size
=============  ==============================================================================

Arrays have rows = samples and are float64: a trajectory is (T, D), a batch leads: (M, ...).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from . import _moved

if TYPE_CHECKING:
    from . import robots
    from .learning.bags import read_bag, write_trajectory_bag
    from .learning.controller import Command, Controller
    from .learning.demonstration import (
        Demonstration,
        LimitWarning,
        demonstration_from_csv,
        load_demonstrations,
        save_demonstrations,
    )
    from .learning.probabilistic_ik import ReachWarning, ReproductionResult
    from .learning.skill import Skill
    from .prob import gaussian
    from .prob.frames import FrameModel
    from .prob.gmm import GMM
    from .robots.kinematics import damped_pinv, nullspace_projector
    from .robots.model import Robot

# The public names and the modules they live in. They are imported on first use (PEP 562), so
# that `import pbdkit` and the command line start in a fraction of a second: scikit-learn,
# SciPy and pinocchio are loaded when a name that needs them is first used.
_WHERE = {
    "GMM": "prob.gmm",
    "FrameModel": "prob.frames",
    "Command": "learning.controller",
    "Controller": "learning.controller",
    "Demonstration": "learning.demonstration",
    "LimitWarning": "learning.demonstration",
    "ReachWarning": "learning.probabilistic_ik",
    "ReproductionResult": "learning.probabilistic_ik",
    "Robot": "robots.model",
    "Skill": "learning.skill",
    "damped_pinv": "robots.kinematics",
    "demonstration_from_csv": "learning.demonstration",
    "load_demonstrations": "learning.demonstration",
    "nullspace_projector": "robots.kinematics",
    "read_bag": "learning.bags",
    "save_demonstrations": "learning.demonstration",
    "write_trajectory_bag": "learning.bags",
}
_SUBMODULES = {"gaussian": "prob.gaussian", "robots": "robots"}

__all__ = [
    "GMM",
    "Command",
    "Controller",
    "Demonstration",
    "FrameModel",
    "LimitWarning",
    "ReachWarning",
    "ReproductionResult",
    "Robot",
    "Skill",
    "damped_pinv",
    "demonstration_from_csv",
    "gaussian",
    "load_demonstrations",
    "nullspace_projector",
    "read_bag",
    "robots",
    "save_demonstrations",
    "write_trajectory_bag",
]
__version__ = "0.1.0"

_moved.install()


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f".{_SUBMODULES[name]}", __name__)
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'pbdkit' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{where}", __name__), name)
    globals()[name] = value  # the next look-up is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
