"""Where a skill is unsure: :meth:`pbdkit.Skill.uncertainty` (private; :doc:`/active`).

From the model alone, no physics: how far outside what was demonstrated a placement of the
objects lies, for this skill. Four candidate measures (the ``parts``); the score is the one that
predicts the simulated study's failures best (:data:`SCORE_PART`, chosen on the ROC AUC
against success on the wide grids of the three tasks: ``benchmarks/uncertainty_auc.py``):

- ``"placement"``: how far each object lies from its demonstrated placements, in the object's
  own space: the distance to the nearest demonstrated placement, each axis divided by the
  demonstrated spread along it (at least :data:`POSITION_SPREAD_FLOOR`; the yaw of an object
  given as a pose is one more axis, at least :data:`YAW_SPREAD_FLOOR`); the largest over the
  objects. 0 on a demonstrated placement, about 1 a spread away.
- ``"ensemble"``: how much skills learned leaving one demonstration out disagree about the
  hand where each object's constraint is tightest (the grasp, the placement): the RMS distance
  of their hands from their mean there (m), the largest over the objects.
- ``"conflict"``: how far the fused reproduction's hand is from each object's constraint
  where it is tightest, in its standard deviations there: a constraint the others pull away
  from.
- ``"reach"``: the tightest steps' targets (object plus the constraint's mean) against the
  arm's reach (their largest distance from the base over :attr:`pbdkit.Skill.reach`), or the
  share of the fused run's steps with a joint at a limit, whichever is larger.

A placement the skill cannot reproduce at all (an object out of reach) gets inf in the parts
that need a reproduction.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import as_pose, wrap_angle, yaw_of
from .._validation import short
from ._update import warm_skill

__all__ = [
    "PARTS",
    "POSITION_SPREAD_FLOOR",
    "SCORE_PART",
    "YAW_SPREAD_FLOOR",
    "Uncertainty",
    "object_distances",
    "placement_distance",
    "uncertainty",
]

Float = NDArray[np.float64]

#: The candidate measures, in the order of :attr:`Uncertainty.parts`.
PARTS = ("placement", "ensemble", "conflict", "reach")
#: The part that is the score (the best ROC AUC against the study's failures).
SCORE_PART = "placement"
#: The demonstrated spread of an object's position along an axis is at least this (m).
POSITION_SPREAD_FLOOR = 0.01
#: ... and of its yaw (rad).
YAW_SPREAD_FLOOR = math.radians(5.0)

_NO_LIMITS: dict[str, Any] = {
    "velocity_limit": None,
    "acceleration_limit": None,
    "jerk_limit": None,
    "on_unreachable": "raise",
}


@dataclass(frozen=True)
class Uncertainty:
    """How unsure a skill is at one placement of its objects (:meth:`pbdkit.Skill.uncertainty`).

    Attributes
    ----------
    score : float
        The part :data:`SCORE_PART` (larger: less sure).
    parts : dict str -> float
        Every candidate measure computed (:data:`PARTS`; see :doc:`/active`).
    """

    score: float
    parts: dict[str, float] = field(default_factory=dict)


class _Model:
    """What a skill's uncertainty needs, computed once per skill: the demonstrated placements
    and their spreads, the tightest step of each object's constraint and its standard
    deviation, and the leave-one-out skills (made when first asked)."""

    def __init__(self, skill: Any) -> None:
        demos, options = skill._learned_from("uncertainty")
        self.skill, self.demos, self.options = skill, demos, options
        self.places: dict[str, Float] = {}
        self.spreads: dict[str, Float] = {}
        for k in skill.object_names:
            places = np.array([_place_row(d.objects[k], k, posed=True) for d in demos])
            floor = np.r_[
                np.full(3, POSITION_SPREAD_FLOOR), [YAW_SPREAD_FLOOR] * (places.shape[1] - 3)
            ]
            spread = places.std(axis=0)
            if places.shape[1] > 3:
                spread[3] = float(np.std(wrap_angle(places[:, 3] - places[0, 3])))
            self.places[k] = places
            self.spreads[k] = np.maximum(spread, floor)
        cons = skill.constraints()
        self.tight: dict[str, int] = {}
        self.sd: dict[str, float] = {}
        self.mean: dict[str, Float] = {}
        for k in skill.object_names:
            loosest = np.sqrt(np.linalg.eigvalsh(cons.task_cov[k][:, :3, :3])[:, -1])
            step = int(np.argmin(loosest))
            self.tight[k], self.sd[k] = step, float(loosest[step])
            self.mean[k] = np.asarray(cons.task_mean[k][step, :3], dtype=np.float64)
        self._loo: list[Any] | None = None

    def loo(self) -> list[Any]:
        """The skills learned leaving one demonstration out (K kept, EM from the skill's)."""
        if self._loo is None:
            skill, out = self.skill, []
            for i in range(len(self.demos)):
                items = [d for j, d in enumerate(self.demos) if j != i]
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    # No new demonstration: every space keeps its K.
                    out.append(
                        warm_skill(skill, items, self.options, len(items), reach=skill.reach)
                    )
            self._loo = out
        return self._loo


def _model(skill: Any) -> _Model:
    model: _Model | None = getattr(skill, "_uncertainty_model", None)
    if model is None:
        model = _Model(skill)
        skill._uncertainty_model = model
    return model


def _place_row(value: object, name: str, *, posed: bool) -> Float:
    """An object's placement as the placement part compares it: its position, and its yaw
    where it is a pose and ``posed`` (the demonstrations give it as one)."""
    position, rotation = as_pose(value, f"objects[{short(name)}]")
    return position if rotation is None or not posed else np.r_[position, yaw_of(rotation)]


def object_distances(
    skill: Any,
    placements: Sequence[Mapping[str, Any]],
    others: Sequence[Mapping[str, Any]] | None = None,
) -> dict[str, Float]:
    """Per object of the skill, (N, M): the distance of each of ``placements`` to each of
    ``others`` (the demonstrated placements when None), each axis divided by the demonstrated
    spread along it."""
    model = _model(skill)
    out: dict[str, Float] = {}
    for k in skill.object_names:
        places, spread = model.places[k], model.spreads[k]
        posed = places.shape[1] > 3
        rows = np.array([_place_row(p[k], k, posed=posed) for p in placements])
        width = rows.shape[1]
        if others is None:
            known = places[:, :width]
        else:
            known = np.array([_place_row(p[k], k, posed=posed) for p in others])
        diff = rows[:, None, :] - known[None, :, :]
        if width > 3:
            diff[..., 3] = wrap_angle(diff[..., 3])
        out[k] = np.linalg.norm(diff / spread[:width], axis=2)
    return out


def placement_distance(
    skill: Any,
    placements: Sequence[Mapping[str, Any]],
    extra: Sequence[Mapping[str, Any]] = (),
) -> Float:
    """The placement part (N,) of each of ``placements``: over the skill's objects, the
    largest distance to the nearest demonstrated placement (and of ``extra``, counted as
    demonstrated), each axis divided by the demonstrated spread."""
    near = object_distances(skill, placements)
    if extra:
        more = object_distances(skill, placements, extra)
        near = {k: np.c_[near[k], more[k]] for k in near}
    if not near:
        return np.zeros(len(placements))
    out: Float = np.max([d.min(axis=1) for d in near.values()], axis=0)
    return out


def _hands_at(res: Any, steps: list[int]) -> Float:
    """The hand (len(steps), 3) of a reproduction at skill steps (its own samples, not the
    lead-in)."""
    own = ~res.lead_in if res.lead_in is not None else np.ones(len(res.t), dtype=bool)
    t, p = res.t[own], res.positions[own]
    return np.stack([np.interp(steps, t, p[:, i]) for i in range(3)], axis=1)


def uncertainty(
    skill: Any, objects: Mapping[str, npt.ArrayLike], parts: tuple[str, ...] = PARTS
) -> Uncertainty:
    """:meth:`pbdkit.Skill.uncertainty` (see there and the module docstring)."""
    unknown = [p for p in parts if p not in PARTS]
    if unknown or SCORE_PART not in parts:
        raise ValueError(
            f"parts must be among {list(PARTS)} and hold '{SCORE_PART}', got {short(parts)}"
        )
    model = _model(skill)
    missing = [k for k in skill.object_names if k not in objects]
    if missing:
        raise ValueError(f"objects lacks {missing}: the skill's objects are {skill.object_names}")
    placed: dict[str, tuple[Float, Float | None]] = {
        k: as_pose(objects[k], f"objects[{short(k)}]") for k in skill.object_names
    }
    out: dict[str, float] = {"placement": float(placement_distance(skill, [objects])[0])}
    told = {k: np.asarray(objects[k], dtype=np.float64) for k in objects}
    steps = [model.tight[k] for k in skill.object_names]
    fused = None
    if {"conflict", "reach", "ensemble"} & set(parts):
        try:
            fused = skill.reproduce(told, **_NO_LIMITS)
        except ValueError:
            fused = None
    if "conflict" in parts:
        if fused is None:
            out["conflict"] = math.inf
        else:
            out["conflict"] = max(
                float(fused.task_errors[k][_own_index(fused, model.tight[k])]) / model.sd[k]
                for k in skill.object_names
            )
    if "reach" in parts:
        far = 0.0
        for k, (position, rotation) in placed.items():
            mean = model.mean[k]  # the hand in the object's frame where it is oriented
            target = position + (
                mean if k not in skill.oriented or rotation is None else rotation @ mean
            )
            far = max(far, float(np.linalg.norm(target)) / skill.reach)
        if fused is None:
            far = math.inf
        else:
            q = fused.joints
            at = (q <= skill.robot.lower + 1e-6) | (q >= skill.robot.upper - 1e-6)
            far = max(far, float(np.mean(at.any(axis=1))))
        out["reach"] = far
    if "ensemble" in parts:
        hands = []
        for member in model.loo():
            try:
                hands.append(_hands_at(member.reproduce(told, **_NO_LIMITS), steps))
            except ValueError:
                hands = []
                break
        if len(hands) < 2:
            out["ensemble"] = math.inf
        else:
            stack = np.array(hands)  # (members, objects, 3)
            rms = np.sqrt(np.mean(np.sum((stack - stack.mean(axis=0)) ** 2, axis=2), axis=0))
            out["ensemble"] = float(rms.max())
    return Uncertainty(out[SCORE_PART], out)


def _own_index(res: Any, step: int) -> int:
    """The sample of a reproduction nearest skill step ``step`` (not in its lead-in)."""
    own = np.flatnonzero(~res.lead_in) if res.lead_in is not None else np.arange(len(res.t))
    return int(own[np.argmin(np.abs(res.t[own] - step))])
