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

Glossary (one word, one meaning, in names and docstrings)
---------------------------------------------------------
====================  ==========================================================================
word                  meaning
====================  ==========================================================================
step                  an index into a skill's time grid, 0 .. n_steps - 1 (``cmd.index``;
                      ``res.t`` is a step index too: its name is the public API's)
t, time, seconds      time in seconds (``Demonstration.t``, ``skill.times(res)``, ``ctrl.dt``)
space                 where a GMM lives: joint space ``"joint"``, or an object's task space
task space            the hand relative to one object: x - o(n), or in its frame with a pose
constraint            one space's GMR Gaussians along the steps, named like the space
controller            which constraints are fused (``use=``): ``"fused"``, ``"fused-position"``
                      (poses given, orientation ignored), ``"joint"``, ``"task:OBJECT"``
task                  a scenario of the experiment (:class:`pbdkit.sim.TaskSpec`: coaster,
                      basin, slot); a "task constraint" and a "task-only controller" are the
                      paper's words for task-space ones
placement             where an object is: a position (3,) or a pose (4x4, or position and
                      quaternion w first); ``objects`` maps names to placements
oriented              of an object placed by a pose, whose constraint includes orientation
grasped object        the object the gripper holds in a task (a glass, or the slot's block)
``_unchecked``        a method that skips input validation, for control loops
``as_dict()``         a JSON-ready dict of a record (the one verb for serialising to JSON)
====================  ==========================================================================
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from ._validation import short

if TYPE_CHECKING:
    from . import datasets, robots
    from .collision import Box, Cylinder, Scene, Sphere
    from .data import (
        Demonstration,
        LimitWarning,
        align,
        align_trajectories,
        demonstration_from_csv,
        load_demonstrations,
        read_bag,
        save_demonstrations,
        write_trajectory_bag,
    )
    from .prob import GMM, FrameModel, gaussian
    from .reproduction import Command, Controller, ReachWarning, ReproductionResult
    from .robots import Robot, damped_pinv, nullspace_projector
    from .skill import Skill

# The public names and the sub-packages they live in. They are imported on first use (PEP 562),
# so that `import pbdkit` and the command line start in a fraction of a second: scikit-learn,
# SciPy and pinocchio are loaded when a name that needs them is first used.
_WHERE = {
    "Box": "collision",
    "Cylinder": "collision",
    "Scene": "collision",
    "Sphere": "collision",
    "GMM": "prob",
    "FrameModel": "prob",
    "Command": "reproduction",
    "Controller": "reproduction",
    "Demonstration": "data",
    "LimitWarning": "data",
    "ReachWarning": "reproduction",
    "ReproductionResult": "reproduction",
    "Robot": "robots",
    "Skill": "skill",
    "align": "data",
    "align_trajectories": "data",
    "damped_pinv": "robots",
    "demonstration_from_csv": "data",
    "load_demonstrations": "data",
    "nullspace_projector": "robots",
    "read_bag": "data",
    "save_demonstrations": "data",
    "write_trajectory_bag": "data",
}
_SUBMODULES = {"datasets": "datasets", "gaussian": "prob.gaussian", "robots": "robots"}

__all__ = [
    "GMM",
    "Box",
    "Command",
    "Controller",
    "Cylinder",
    "Demonstration",
    "FrameModel",
    "LimitWarning",
    "ReachWarning",
    "ReproductionResult",
    "Robot",
    "Scene",
    "Skill",
    "Sphere",
    "align",
    "align_trajectories",
    "damped_pinv",
    "datasets",
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


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f".{_SUBMODULES[name]}", __name__)
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module 'pbdkit' has no attribute {short(name)}")
    value = getattr(importlib.import_module(f".{where}", __name__), name)
    globals()[name] = value  # the next look-up is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
