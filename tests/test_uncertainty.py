"""Where a skill is unsure (issue 39, item 2): ``Skill.uncertainty`` from the model alone."""

from __future__ import annotations

import numpy as np
import pytest

from pbdkit import Skill
from pbdkit.data._demonstration import Demonstration
from pbdkit.skill._uncertainty import POSITION_SPREAD_FLOOR, SCORE_PART


def test_the_placement_part_is_the_distance_to_the_nearest_demonstration_in_spreads(
    skill: Skill, demos: list[Demonstration]
) -> None:
    # Brute force: each axis divided by the demonstrated spread (at least the floor), the
    # nearest demonstration's distance.
    places = np.array([d.objects["glass"] for d in demos])
    spread = np.maximum(places.std(axis=0), POSITION_SPREAD_FLOOR)
    rng = np.random.default_rng(4)
    for _ in range(5):
        glass = places.mean(axis=0) + np.r_[rng.uniform(-0.15, 0.15, 2), 0.0]
        expected = np.min(np.linalg.norm((glass - places) / spread, axis=1))
        u = skill.uncertainty({"glass": glass}, parts=("placement",))
        assert u.parts == {"placement": pytest.approx(expected, rel=1e-12)}
        assert u.score == u.parts[SCORE_PART]
    assert skill.uncertainty({"glass": places[2]}, parts=("placement",)).score == 0.0


def test_every_part_grows_away_from_what_was_demonstrated(
    skill: Skill, demos: list[Demonstration]
) -> None:
    # Along a line from the demonstrations' centre outwards, every part is larger far out than
    # at the centre: the skills without one demonstration disagree more, the fused hand leaves
    # the tight glass constraint, the target nears the arm's reach.
    centre = np.mean([d.objects["glass"] for d in demos], axis=0)
    near = skill.uncertainty({"glass": centre})
    far = skill.uncertainty({"glass": centre + np.array([0.12, 0.12, 0.0])})
    assert set(near.parts) == {"placement", "ensemble", "conflict", "reach"}
    for part in near.parts:
        assert np.isfinite(near.parts[part]) and near.parts[part] >= 0.0
        assert far.parts[part] > near.parts[part], part
    assert near.parts["ensemble"] < 0.005  # 5 mm: they agree where they were taught
    # Out of reach: the reproductions are refused; those parts say so.
    out = skill.uncertainty({"glass": np.array([3.0, 0.0, 0.1])})
    assert out.parts["conflict"] == np.inf and out.parts["reach"] == np.inf


def test_uncertainty_refuses_in_one_line(skill: Skill) -> None:
    bare = Skill(
        skill.robot,
        skill.gmms,
        n_steps=skill.n_steps,
        object_names=skill.object_names,
        has_gripper=skill.has_gripper,
        reach=skill.reach,
    )
    with pytest.raises(ValueError, match=r"re-learn it with Skill\.learn to use uncertainty"):
        bare.uncertainty({"glass": np.zeros(3)})
    with pytest.raises(ValueError, match=r"objects lacks \['glass'\]"):
        skill.uncertainty({"cup": np.zeros(3)})
    with pytest.raises(ValueError, match="parts must be among"):
        skill.uncertainty({"glass": np.zeros(3)}, parts=("placement", "luck"))
