"""Encoding (paper Table I): a skill's GMMs from checked demonstrations and resolved options
(:meth:`pbdkit.Skill.learn` checks them; :mod:`pbdkit.skill._provenance`).

The demonstrations are aligned in time (or not), every one rescaled to ``n_steps`` steps of
which ``fit_samples`` evenly spaced ones are kept, the data of every space computed
(:func:`~pbdkit.skill._spaces.space_data`), and one GMM fitted per space, K chosen per space;
the spaces' GMR covariances are calibrated from the left-out demonstrations of every space.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
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
from ._calibration import space_factors, step_factors
from ._provenance import LearnOptions, resolve_task_objects
from ._spaces import (
    Alignment,
    aligned_demonstrations,
    fit_steps,
    mean_relative_rotation,
    space_data,
    space_floors,
    variability_floor,
)

__all__ = ["RESELECT_GROWTH", "RESELECT_SURPRISE", "Encoding", "encode"]

Float = NDArray[np.float64]

#: An update (:func:`encode` with ``warm``) chooses a space's K again once the demonstrations
#: have grown to this many times the number it was chosen with ...
RESELECT_GROWTH = 2.0
#: ... or when a new demonstration's left-out error at that K is more than this many times the
#: largest of the others' (the K does not hold for it).
RESELECT_SURPRISE = 2.0


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
    reselected: tuple[str, ...] = ()


def encode(
    items: Sequence[Demonstration],
    robot: KinematicModel,
    options: LearnOptions,
    *,
    warm: Mapping[str, GMM] | None = None,
    n_old: int = 0,
    old_bases: Mapping[str, Float] | None = None,
) -> Encoding:
    """Table I for demonstrations checked against ``robot`` and options as resolved.

    Warns as :meth:`pbdkit.Skill.learn` (a space's :class:`~pbdkit.prob.SelectionWarning` says
    which space), at its caller.

    An update (:meth:`pbdkit.Skill.update`) gives the skill's GMMs as ``warm``, learned from
    the first ``n_old`` of ``items``, and its orientation bases (``old_bases``, kept): each
    space's EM starts from the old GMM's responsibilities, its K kept, unless K is to be chosen
    (``"auto"``) and the data warrant choosing it again (:data:`RESELECT_GROWTH`,
    :data:`RESELECT_SURPRISE`): then that space is fitted as :meth:`~pbdkit.Skill.learn` fits
    it (``reselected`` names it).
    """
    n = int(robot.n_joints)
    n_steps = options["n_steps"]
    items, alignment = aligned_demonstrations(items, robot, options["align"])
    floors = variability_floor(options["reg_covar"])
    names = resolve_task_objects(options["task_objects"], items[0].object_names)
    has_gripper = items[0].gripper is not None
    steps = fit_steps(n_steps, options["fit_samples"])

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
        if old_bases is None:
            bases = {
                k: mean_relative_rotation(items, pose_robot, k, n_steps, steps) for k in oriented
            }
        else:
            bases = {k: np.asarray(old_bases[k], dtype=np.float64) for k in oriented}
    spaces = space_data(items, robot, names, n_steps, steps, rotation_base=bases)
    data = {k: v.reshape(-1, v.shape[2]) for k, v in spaces.items()}
    groups = np.repeat(np.arange(len(items)), steps.shape[0])  # the demonstration of a row
    space_floor = space_floors(floors, n, has_gripper, names, bases)
    gmms: dict[str, GMM] = {}
    reselected: list[str] = []
    for k, X in data.items():
        old = None if warm is None else warm.get(k)
        if old is not None:
            kept = _warm_fit(old, X, groups, n_old, options, space_floor[k])
            if kept is not None:
                gmms[k] = kept
                continue
            reselected.append(k)
        gmm = GMM(
            n_components=options["n_components"],
            max_components=options["max_components"],
            reg_covar=space_floor[k],
            random_state=options["random_state"],
            # K is scored on the joints and the gripper: its closing is a phase where the
            # demonstrations agree, and a K that blurs it closes the hand early (docs/math.md,
            # "Choosing K").
            score_dims=None,
            bic_samples_per_sequence=options["bic_samples_per_sequence"],
            # Every space's left-out residuals: the joints are calibrated against the objects'
            # (docs/math.md, "Calibration").
            loo_residuals=options["calibrate"],
        )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", SelectionWarning)
            gmms[k] = gmm.fit(X, groups=groups)
        for w in caught:  # said again with the space it is about, at learn's caller
            text = f"space {short(k)}: {w.message}" if w.category is SelectionWarning else w.message
            warnings.warn(text, w.category, stacklevel=3)
    factors = {
        k: step_factors(g.loo_residuals_, steps, len(items), n_steps)
        for k, g in gmms.items()
        if g.loo_residuals_.size
    }
    # The joints against the best-described object; the objects widened together, never one
    # on its own (docs/math.md, "Calibration"): that moves the balance between the objects.
    calibration = (
        space_factors(factors[JOINT], {k: c for k, c in factors.items() if k != JOINT})
        if JOINT in factors
        else {}
    )
    return Encoding(
        gmms=gmms,
        aligned=alignment,
        rotation_base=bases,
        calibration=calibration,
        reach=reach_from_samples(robot, data[JOINT][:, 1 : n + 1]),
        n_samples={k: int(X.shape[0]) for k, X in data.items()},
        reselected=tuple(reselected),
    )


def _warm_fit(
    old: GMM,
    X: Float,
    groups: NDArray[np.intp],
    n_old: int,
    options: LearnOptions,
    floor: Float,
) -> GMM | None:
    """One space's GMM refitted from ``old``'s responsibilities, its K kept; None where K is
    chosen (``"auto"``) and the data warrant choosing it again."""
    chosen = isinstance(options["n_components"], str)
    selection = old.selection_
    if chosen and selection.method != "cv":
        return None  # "bic": chosen again every time
    if chosen and len(set(groups.tolist())) >= RESELECT_GROWTH * max(selection.n_folds, 1):
        return None
    gmm = GMM(
        n_components=old.n_components_,
        max_components=options["max_components"],
        reg_covar=floor,
        random_state=options["random_state"],
        score_dims=None,
        loo_residuals=options["calibrate"],
    )
    gmm._warm = old  # EM starts where the old fit ended (GMM._initial_resp)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SelectionWarning)
        gmm.fit(X, groups=groups)
    if chosen:
        errors = gmm.selection_.fold_scores
        if errors.size and n_old < errors.shape[1]:
            worst_old = float(errors[0, :n_old].max())
            if float(errors[0, n_old:].max()) > RESELECT_SURPRISE * worst_old:
                return None
        gmm.selection_ = selection  # K as it was chosen
    return gmm
