"""Where to demonstrate next: :meth:`pbdkit.Skill.suggest` (private; :doc:`/active`).

Candidates are spread over the ranges a user allows (a scrambled Halton sequence, seeded) and
taken in the order of how much a demonstration at each would lower the skill's uncertainty
score (:data:`pbdkit.skill._uncertainty.SCORE_PART`, the placement part) on average over all the
candidates (:func:`coverage_gain`: the expected reduction of active learning, not the largest
uncertainty, which sends every demonstration to a corner of the ranges), skipping those the
skill could not reproduce at all or whose targets lie beyond the arm's reach (nothing a
demonstration there could teach: the teacher could not show it either). For more than one
suggestion the choice is greedy: each suggestion counts as demonstrated for the next.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._rotations import as_pose, pose_matrix
from .._validation import check_int, short
from ._uncertainty import SCORE_PART, _model, object_distances, uncertainty

__all__ = ["CANDIDATES", "PRESELECT", "Suggestion", "parse_ranges", "suggest"]

Float = NDArray[np.float64]

#: Candidate placements scored per suggestion.
CANDIDATES = 256
#: Where the score is not the placement's, the candidates farthest from what was demonstrated
#: measured by it, per suggestion.
PRESELECT = 24


@dataclass(frozen=True)
class Suggestion:
    """A placement where a new demonstration would help the skill most
    (:meth:`pbdkit.Skill.suggest`).

    Attributes
    ----------
    objects : dict str -> ndarray
        A placement of every object of the skill, in the robot's base frame: (3,) or, for an
        object given as a pose (or with a yaw range), (4, 4).
    score : float
        The skill's uncertainty score there (:meth:`pbdkit.Skill.uncertainty`), before the
        suggestions listed before it were demonstrated.
    """

    objects: dict[str, Float]
    score: float


@dataclass(frozen=True)
class _Range:
    low: Float
    high: Float
    yaw: tuple[float, float] | None


def parse_ranges(skill: Any, ranges: object) -> dict[str, _Range]:
    """The checked ranges (see :meth:`pbdkit.Skill.suggest`); one-line ValueErrors."""
    if not isinstance(ranges, Mapping) or not ranges:
        raise ValueError(
            "ranges must be a non-empty dict {name: {'low': (3,), 'high': (3,), 'yaw': (lo, hi) "
            f"or None}}, got {short(ranges)}"
        )
    out: dict[str, _Range] = {}
    for name, spec in ranges.items():
        if name not in skill.object_names:
            raise ValueError(
                f"ranges names {short(name)}, not an object of the skill {skill.object_names}"
            )
        if not isinstance(spec, Mapping) or not {"low", "high"} <= set(spec):
            raise ValueError(f"ranges[{short(name)}] must have 'low' and 'high', got {short(spec)}")
        unknown = set(spec) - {"low", "high", "yaw"}
        if unknown:
            raise ValueError(f"ranges[{short(name)}] has unknown keys {sorted(map(str, unknown))}")
        low = np.asarray(spec["low"], dtype=np.float64)
        high = np.asarray(spec["high"], dtype=np.float64)
        if low.shape != (3,) or high.shape != (3,):
            raise ValueError(f"ranges[{short(name)}] 'low' and 'high' must be 3 numbers (m)")
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(low <= high)):
            raise ValueError(
                f"ranges[{short(name)}] must be finite with low <= high, got low "
                f"{low.tolist()}, high {high.tolist()}"
            )
        yaw = spec.get("yaw")
        if yaw is not None:
            lo_hi = np.asarray(yaw, dtype=np.float64)
            if lo_hi.shape != (2,) or not np.all(np.isfinite(lo_hi)) or lo_hi[0] > lo_hi[1]:
                raise ValueError(
                    f"ranges[{short(name)}] 'yaw' must be (lo, hi) in rad with lo <= hi, or None"
                )
            yaw = (float(lo_hi[0]), float(lo_hi[1]))
        out[str(name)] = _Range(low, high, yaw)
    return out


def _candidates(skill: Any, ranges: dict[str, _Range], n: int, seed: int) -> list[dict[str, Float]]:
    """``n`` placements spread over the ranges; objects without one at their first
    demonstration's place."""
    from scipy.stats import qmc

    model = _model(skill)
    fixed = {k: np.asarray(model.demos[0].objects[k]) for k in skill.object_names}
    dims = list(ranges.items())
    width = sum(3 + (r.yaw is not None) for _, r in dims)
    u = qmc.Halton(d=width, scramble=True, seed=seed).random(n)
    out = []
    for row in u:
        at = 0
        objects = dict(fixed)
        for k, r in dims:
            position = r.low + row[at : at + 3] * (r.high - r.low)
            at += 3
            _, rotation = as_pose(fixed[k], f"objects[{short(k)}]")
            if r.yaw is not None:
                yaw = r.yaw[0] + row[at] * (r.yaw[1] - r.yaw[0])
                at += 1
                c, s = math.cos(yaw), math.sin(yaw)
                rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            objects[k] = position if rotation is None else pose_matrix(position, rotation)
        out.append(objects)
    return out


def suggest(skill: Any, ranges: object, n: int = 1, *, seed: int = 0) -> list[Suggestion]:
    """:meth:`pbdkit.Skill.suggest` (see there and the module docstring)."""
    skill._learned_from("suggest")  # one line, naming suggest, for a skill without them
    n = check_int(n, "n", minimum=1, maximum=100)
    checked = parse_ranges(skill, ranges)
    cands = _candidates(skill, checked, CANDIDATES, check_int(seed, "seed", minimum=0))
    chosen: list[Suggestion] = []
    taken: set[int] = set()  # chosen, or out of reach
    known: dict[int, float] = {}  # the score of the candidates measured so far
    # Each object's distance from each candidate to the nearest placement shown (N,).
    nearest = {k: d.min(axis=1) for k, d in object_distances(skill, cands).items()}
    pair = object_distances(skill, cands, cands)
    while len(chosen) < n:
        # Where a demonstration lowers the placement part over the candidates most first;
        # where the score is another part than the placement's, the PRESELECT first are
        # measured by it.
        far = np.max(list(nearest.values()), axis=0)
        order = [int(i) for i in np.argsort(-coverage_gain(nearest, pair), kind="stable")]
        order = [i for i in order if i not in taken]
        if SCORE_PART != "placement":
            pool = order[:PRESELECT]
            for i in pool:
                if i not in known:
                    known[i] = _score(skill, cands[i])
            order = sorted(pool, key=lambda i: -known[i])
        for i in order:
            taken.add(i)
            reach = uncertainty(skill, cands[i], ("placement", "reach")).parts["reach"]
            if not math.isfinite(reach) or reach > 1.0:
                continue  # out of reach: nothing to teach there
            score = float(far[i]) if SCORE_PART == "placement" else known[i]
            chosen.append(Suggestion({k: v.copy() for k, v in cands[i].items()}, score))
            nearest = {k: np.minimum(d, pair[k][:, i]) for k, d in nearest.items()}  # shown
            break
        else:
            break  # every candidate is out of reach
    return chosen


def coverage_gain(nearest: dict[str, Float], pair: dict[str, Float]) -> Float:
    """(N,): how much a demonstration at each candidate would lower the placement part, on
    average over the candidates.

    ``nearest[k]`` (N,): object k's distance from each candidate to the nearest placement shown;
    ``pair[k]`` (N, N): between the candidates. The placement part of candidate x is
    max over k of nearest[k][x]; with a demonstration at candidate c, max over k of
    min(nearest[k][x], pair[k][x, c]).
    """
    now = np.max(list(nearest.values()), axis=0)
    after = np.max([np.minimum(d[:, None], pair[k]) for k, d in nearest.items()], axis=0)
    return np.asarray(now.mean() - after.mean(axis=0), dtype=np.float64)


def _score(skill: Any, objects: dict[str, Float]) -> float:
    """The uncertainty score at a candidate (-inf where it cannot be reproduced: inf would put
    the unreachable first)."""
    value = uncertainty(skill, objects, (SCORE_PART, "placement")).score
    return value if math.isfinite(value) else -math.inf
