"""Where a skill is unsure (issue 39, item 2): ``Skill.uncertainty`` from the model alone."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from synthetic_teacher import bare_skill

from pbdkit import Skill
from pbdkit.data._demonstration import Demonstration
from pbdkit.skill._suggest import CANDIDATES, _candidates, coverage_gain, parse_ranges
from pbdkit.skill._uncertainty import (
    POSITION_SPREAD_FLOOR,
    SCORE_PART,
    object_distances,
    placement_distance,
)


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
    bare = bare_skill(skill)
    with pytest.raises(ValueError, match=r"re-learn it with Skill\.learn to use uncertainty"):
        bare.uncertainty({"glass": np.zeros(3)})
    with pytest.raises(ValueError, match=r"re-learn it with Skill\.learn to use suggest") as info:
        bare.suggest({"glass": {"low": (0, 0, 0), "high": (1, 1, 0)}})
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match=r"objects lacks \['glass'\]"):
        skill.uncertainty({"cup": np.zeros(3)})
    with pytest.raises(ValueError, match="parts must be among"):
        skill.uncertainty({"glass": np.zeros(3)}, parts=("placement", "luck"))


def _ranges(demos: list[Demonstration], half: float = 0.1) -> dict[str, dict[str, object]]:
    centre = np.mean([d.objects["glass"] for d in demos], axis=0)
    step = np.array([half, half, 0.0])
    lo, hi = centre - step, centre + step
    return {"glass": {"low": lo, "high": hi, "yaw": None}}


def test_suggestions_lower_the_uncertainty_over_the_ranges_most_and_spread_out(
    skill: Skill, demos: list[Demonstration]
) -> None:
    ranges = _ranges(demos)
    found = skill.suggest(ranges, n=3)
    assert len(found) == 3
    lo, hi = ranges["glass"]["low"], ranges["glass"]["high"]
    for s in found:
        glass = s.objects["glass"]
        assert np.all(glass >= lo - 1e-12) and np.all(glass <= hi + 1e-12)
    # Brute force, independent of coverage_gain's arrays: the mean placement part over the
    # candidates with each candidate counted as demonstrated, one placement_distance call per
    # pair. The first suggestion lowers it most (all candidates are within reach here).
    full = _candidates(skill, parse_ranges(skill, ranges), CANDIDATES, 0)
    sample = [{"glass": c["glass"]} for c in full[:48]]

    def gain(places: list[dict[str, np.ndarray]]) -> np.ndarray:
        nearest = {k: d.min(axis=1) for k, d in object_distances(skill, places).items()}
        return coverage_gain(nearest, object_distances(skill, places, places))

    def mean_after(shown: list[dict[str, np.ndarray]]) -> float:
        return float(np.mean([placement_distance(skill, [x], shown)[0] for x in sample]))

    first = found[0]
    gains = gain(sample)
    before = mean_after([])
    for i in (0, 7, 23, 47):
        assert gains[i] == pytest.approx(before - mean_after([sample[i]]), rel=1e-9, abs=1e-12)
    everywhere = gain(full)
    best = full[int(np.argmax(everywhere))]["glass"]
    np.testing.assert_array_equal(first.objects["glass"], best)
    # Its score is the uncertainty there; it is not the least sure candidate (a corner would
    # be), and a demonstration there lowers the mean more than one at the least sure does.
    assert first.score == pytest.approx(skill.uncertainty(first.objects).score, rel=1e-12)
    far = placement_distance(skill, full)
    corner = int(np.argmax(far))
    assert first.score < far[corner]
    assert everywhere.max() > everywhere[corner] + 0.05
    # Each next one counts the ones before as demonstrated: they spread out.
    apart = [np.linalg.norm(a.objects["glass"] - b.objects["glass"]) for a, b in
             [(found[0], found[1]), (found[0], found[2]), (found[1], found[2])]]  # fmt: skip
    assert min(apart) > 0.03
    # Seeded: the same suggestions again.
    again = skill.suggest(ranges, n=3)
    for a, b in zip(found, again, strict=True):
        np.testing.assert_array_equal(a.objects["glass"], b.objects["glass"])


def test_nothing_is_suggested_out_of_reach_and_bad_ranges_say_so(skill: Skill) -> None:
    far = {"glass": {"low": (2.5, 2.5, 0.1), "high": (2.8, 2.8, 0.1), "yaw": None}}
    assert skill.suggest(far) == []
    with pytest.raises(ValueError, match=r"not an object of the skill"):
        skill.suggest({"cup": {"low": (0, 0, 0), "high": (1, 1, 0)}})
    with pytest.raises(ValueError, match=r"low <= high"):
        skill.suggest({"glass": {"low": (1, 0, 0), "high": (0, 1, 0)}})
    with pytest.raises(ValueError, match=r"'low' and 'high'"):
        skill.suggest({"glass": {"low": (0, 0, 0)}})
    with pytest.raises(ValueError, match=r"non-empty dict"):
        skill.suggest({})


def test_pbdkit_suggest_prints_and_writes_the_placements(
    skill: Skill, demos: list[Demonstration], tmp_path: Path
) -> None:
    from typer.testing import CliRunner

    from pbdkit.apps._cli import app

    path = tmp_path / "skill.npz"
    skill.save(path)
    centre = np.mean([d.objects["glass"] for d in demos], axis=0)
    x0, x1, y0, y1 = centre[0] - 0.1, centre[0] + 0.1, centre[1] - 0.1, centre[1] + 0.1
    out = tmp_path / "next.json"
    result = CliRunner().invoke(
        app,
        ["suggest", str(path), "--range", f"glass={x0}:{x1},{y0}:{y1}", "--n", "2",
         "--json", str(out)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    written = json.loads(out.read_text())
    assert len(written["suggestions"]) == 2
    glass = np.array(written["suggestions"][0]["objects"]["glass"])
    expected = skill.suggest(
        {"glass": {"low": (x0, y0, glass[2]), "high": (x1, y1, glass[2]), "yaw": None}}, n=2
    )
    np.testing.assert_allclose(glass, expected[0].objects["glass"], atol=1e-12)
    assert glass[2] == pytest.approx(np.mean([d.objects["glass"][2] for d in demos]))
    bad = CliRunner().invoke(app, ["suggest", str(path), "--range", "glass=1:0,0:1"])
    assert bad.exit_code == 2 and "lo <= hi" in bad.output


def test_a_suggesting_teacher_says_where_and_learns_each_take(
    skill: Skill, demos: list[Demonstration], robot: object, tmp_path: Path
) -> None:
    # `pbdkit ros record --suggest SKILL` without the ROS graph: before a take, where to put
    # the glass; after it, the skill has learned the take and is written back.
    from synthetic_teacher import synthetic_demos

    from pbdkit.apps._cli_suggest import SuggestingTeacher, default_ranges

    path = tmp_path / "skill.npz"
    skill.save(path)
    ranges = default_ranges(skill)
    places = np.array([d.objects["glass"] for d in demos])
    low, high = places.min(axis=0), places.max(axis=0)
    np.testing.assert_allclose(ranges["glass"]["high"][:2] - ranges["glass"]["low"][:2],
                               2 * np.maximum(high - low, 0.025)[:2])  # fmt: skip
    teacher = SuggestingTeacher(path)
    first = teacher.next_text()
    assert first.startswith("put glass at (") and "uncertainty" in first
    take = synthetic_demos(robot, np.random.default_rng(11), n_demos=1)[0]  # type: ignore[arg-type]
    assert "learned from 6 demonstrations" in teacher.took(take)
    again = Skill.load(path)
    assert again.demonstrations_ is not None and len(again.demonstrations_) == 6
    np.testing.assert_array_equal(again.demonstrations_[-1].t, take.t)
    assert teacher.next_text() != first  # the take counts as demonstrated


def test_ros_record_refuses_a_range_without_a_skill_to_suggest(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from pbdkit.apps._cli import app

    out = tmp_path / "demos.npz"
    result = CliRunner().invoke(app, ["ros", "record", "--out", str(out), "--range", "g=0:1,0:1"])
    assert result.exit_code == 2 and "--range goes with --suggest SKILL" in result.output
    assert not out.exists()


GLASS, GRIPPER = ["--object", "glass=0.4,0.1,0.1"], ["--gripper-joint", "gripper:0:1"]
SO100 = str(Path(__file__).parent / "data" / "arms" / "so100.urdf")  # 5 joints, not the Katana's


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--robot", "panda", *GLASS, *GRIPPER],
         r"a skill of the joints \['pan', .*\], not of --robot's \['panda_joint1'"),
        (["--robot", SO100, "--tip", "gripper", *GLASS, *GRIPPER],
         r"not of --robot's \['shoulder_pan'"),
        (["--object", "cup=0.4,0.1,0.1", *GRIPPER], r"have objects \['glass'\]; record them"),
        (["--object", "glass=0.4,0.1,0.1,1,0,0,0", *GRIPPER],
         r"--object glass: .* hold it as a position: give x,y,z$"),
        (GLASS, r"learned with a gripper: give --gripper-joint NAME:OPEN:CLOSED$"),
    ],
)  # fmt: skip
def test_ros_record_refuses_a_skill_its_takes_could_not_update(
    skill: Skill, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, args: list[str], match: str
) -> None:
    # `pbdkit ros record --suggest SKILL` refuses, in one line and before it joins the graph,
    # what Skill.update would refuse after the first take: another arm (another joint count,
    # or as many joints of other names), other objects, a pose for an object the skill has as
    # a position, no gripper joint for a skill with a gripper (the glass skill has one).
    import re

    from rosgraph import needs_ros
    from typer.testing import CliRunner

    from pbdkit.apps import _cli_ros
    from pbdkit.apps._cli import app

    needs_ros()
    monkeypatch.setattr(_cli_ros, "run_node", _no_graph)
    path, out = tmp_path / "skill.npz", tmp_path / "demos.npz"
    skill.save(path)
    result = CliRunner().invoke(
        app, ["ros", "record", "--out", str(out), "--suggest", str(path), *args]
    )
    said = result.output.strip()
    assert result.exit_code == 2 and len(said.splitlines()) == 1, said
    assert re.search(match, said), said
    assert not out.exists()


def _no_graph(*args: object, **kwargs: object) -> None:
    raise AssertionError("joined the ROS graph: the options should have been refused")
