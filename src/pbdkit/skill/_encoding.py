"""Encoding (paper Table I): a skill's GMMs from checked demonstrations and resolved options
(:meth:`pbdkit.Skill.learn` checks them; :mod:`pbdkit.skill._provenance`).

The demonstrations are aligned in time (or not), every one rescaled to ``n_steps`` steps of
which ``fit_samples`` evenly spaced ones are kept, the data of every space computed
(:func:`~pbdkit.skill._spaces.space_data`), and one GMM fitted per space, K chosen per space;
the joint space's GMR covariance is calibrated from its left-out demonstrations.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from .._validation import short
from ..data._demonstration import Demonstration
from ..data._placement import is_pose
from ..prob import GMM, SelectionWarning
from ..reproduction._constraints import JOINT
from ..reproduction._setup import reach_from_samples
from ..robots._protocols import KinematicModel, PoseKinematicModel, check_robot
from ._calibration import step_factors
from ._provenance import LearnOptions, resolve_task_objects
from ._spaces import (
    Alignment,
    aligned_demonstrations,
    mean_relative_rotation,
    space_data,
    space_floors,
    variability_floor,
)

__all__ = ["Encoding", "encode"]

Float = NDArray[np.float64]


@dataclass(frozen=True)
class Encoding:
    """What :func:`encode` learned: the arguments of :class:`pbdkit.Skill` beyond the
    demonstrations' own (``n_samples``: the rows each space's GMM was fitted on)."""

    gmms: dict[str, GMM]
    aligned: Alignment
    rotation_base: dict[str, Float]
    calibration: dict[str, Float]
    reach: float
    n_samples: dict[str, int]


def encode(
    items: Sequence[Demonstration], robot: KinematicModel, options: LearnOptions
) -> Encoding:
    """Table I for demonstrations checked against ``robot`` and options as resolved.

    Warns as :meth:`pbdkit.Skill.learn` (a space's :class:`~pbdkit.prob.SelectionWarning` says
    which space), at its caller.
    """
    n = int(robot.n_joints)
    n_steps = options["n_steps"]
    items, alignment = aligned_demonstrations(items, robot, options["align"])
    floors = variability_floor(options["reg_covar"])
    names = resolve_task_objects(options["task_objects"], items[0].object_names)
    has_gripper = items[0].gripper is not None
    n_fit = n_steps if options["fit_samples"] is None else options["fit_samples"]
    steps = np.unique(np.round(np.linspace(0, n_steps - 1, min(n_fit, n_steps))).astype(int))

    oriented = [k for k in names if options["orientation"] and is_pose(items[0].objects[k])]
    bases: dict[str, Float] = {}
    if oriented:
        try:
            pose_robot = cast(PoseKinematicModel, check_robot(robot, PoseKinematicModel))
        except ValueError as exc:
            raise ValueError(
                f"the objects {oriented} are poses: learning the hand's orientation needs a "
                f"PoseKinematicModel; pass orientation=False to learn positions only ({exc})"
            ) from exc
        bases = {k: mean_relative_rotation(items, pose_robot, k, n_steps, steps) for k in oriented}
    spaces = space_data(items, robot, names, n_steps, steps, rotation_base=bases)
    data = {k: v.reshape(-1, v.shape[2]) for k, v in spaces.items()}
    groups = np.repeat(np.arange(len(items)), steps.shape[0])  # the demonstration of a row
    space_floor = space_floors(floors, n, has_gripper, names, bases)
    gmms: dict[str, GMM] = {}
    for k, X in data.items():
        gmm = GMM(
            n_components=options["n_components"],
            max_components=options["max_components"],
            reg_covar=space_floor[k],
            random_state=options["random_state"],
            # The gripper is a binary command thresholded at 0.5: K is chosen on the joints.
            score_dims=list(range(1, n + 1)) if k == JOINT else None,
            bic_samples_per_sequence=options["bic_samples_per_sequence"],
            # Calibration widens the joint space only (docs/math.md, "Calibration").
            loo_residuals=options["calibrate"] and k == JOINT,
        )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SelectionWarning)
            gmms[k] = gmm.fit(X, groups=groups)
        for w in caught:  # said again with the space it is about, at learn's caller
            text = f"space {short(k)}: {w.message}" if w.category is SelectionWarning else w.message
            warnings.warn(text, w.category, stacklevel=3)
    calibration = {
        k: step_factors(g.loo_residuals_, steps, len(items), n_steps)
        for k, g in gmms.items()
        if g.loo_residuals_.size
    }
    return Encoding(
        gmms=gmms,
        aligned=alignment,
        rotation_base=bases,
        calibration=calibration,
        reach=reach_from_samples(robot, data[JOINT][:, 1 : n + 1]),
        n_samples={k: int(X.shape[0]) for k, X in data.items()},
    )
