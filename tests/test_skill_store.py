"""A skill that keeps what it learned from (issue 39, item 1): ``Skill.learn`` keeps the
demonstrations as given, its options as resolved and each space's sample count; learning again
from them gives the same skill, bit for bit; skill files of version 3 store them (no pickle), and
a skill without them (built by hand, or of a file of version 1 or 2) says in one line that it
must be learned again. A version-3 file whose demonstrations, options or counts are wrong is
refused in one line that names the key.

The skills are small (three synthetic coaster demonstrations of ``synthetic_teacher.py`` on a
grid of 60 steps; one test learns conftest's skill again): the module runs in about 3 s.
"""

from __future__ import annotations

import copy
import pickle
import re
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from synthetic_teacher import bare_skill, synthetic_demos

from pbdkit._io import open_npz
from pbdkit.data._demonstration import Demonstration, save_demonstrations
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill
from pbdkit.skill._skill_file import MAX_FILE_BYTES

Float = NDArray[np.float64]
Arrays = dict[str, NDArray[Any]]
N_STEPS = 60


def _yaw(angle: float, position: Float) -> Float:
    """A pose: ``position``, turned by ``angle`` about z."""
    c, s = np.cos(angle), np.sin(angle)
    pose = np.eye(4)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:3, 3] = position
    return pose


@pytest.fixture(scope="module")
def coaster_demos(robot: Robot) -> list[Demonstration]:
    """Three demonstrations of carrying the glass to the coaster (seed 3)."""
    return synthetic_demos(robot, np.random.default_rng(3), n_demos=3, coaster=True)


@pytest.fixture(scope="module")
def posed_demos(coaster_demos: list[Demonstration]) -> list[Demonstration]:
    """The same, with the coaster given as a pose (turned differently in each)."""
    return [
        Demonstration(
            d.t,
            d.joints,
            {"glass": d.objects["glass"], "coaster": _yaw(0.2 * i, d.objects["coaster"])},
            d.gripper,
        )
        for i, d in enumerate(coaster_demos)
    ]


@pytest.fixture(scope="module")
def positions(robot: Robot, coaster_demos: list[Demonstration]) -> Skill:
    """Positions only; K chosen, options away from their defaults."""
    return Skill.learn(
        coaster_demos,
        robot,
        n_steps=N_STEPS,
        max_components=4,
        reg_covar={"task": 1e-6},
        random_state=None,
        fit_samples=25,
        align="auto",
    )


@pytest.fixture(scope="module")
def oriented(robot: Robot, posed_demos: list[Demonstration]) -> Skill:
    """The coaster's constraint oriented; K fixed, one reg_covar, not aligned."""
    return Skill.learn(
        posed_demos,
        robot,
        n_steps=N_STEPS,
        n_components=2,
        reg_covar=1e-5,
        random_state=7,
        fit_samples=None,
        task_objects=("coaster", "glass"),
        align=False,
        calibrate=False,
    )


def _arrays(path: Path) -> Arrays:
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def _objects(skill: Skill, demo: Demonstration) -> dict[str, Float]:
    """A new placement for every object of the skill: near ``demo``'s, turned for a pose."""
    out = {}
    for k in skill.object_names:
        p = np.asarray(demo.objects[k], dtype=np.float64)
        position = (p[:3, 3] if p.shape == (4, 4) else p) + [0.02, -0.01, 0.0]
        out[k] = _yaw(0.1, position) if k in skill.oriented else position
    return out


def _same_gmms(a: Skill, b: Skill) -> None:
    assert list(a.gmms) == list(b.gmms)
    for k in a.gmms:
        for name in ("weights_", "means_", "covariances_"):
            np.testing.assert_array_equal(getattr(a.gmms[k], name), getattr(b.gmms[k], name))
        assert a.gmms[k].selection_.candidates == b.gmms[k].selection_.candidates
        np.testing.assert_array_equal(a.gmms[k].selection_.scores, b.gmms[k].selection_.scores)


# ----------------------------------------------------------------------------- learning
def test_learn_keeps_the_demonstrations_as_given_and_the_options_as_resolved(
    positions: Skill, oriented: Skill, coaster_demos: list[Demonstration]
) -> None:
    # The very objects given (before alignment and resampling), in a list of its own.
    assert positions.demonstrations_ is not None
    assert all(a is b for a, b in zip(positions.demonstrations_, coaster_demos, strict=True))
    assert positions.learn_options_ == {
        "n_steps": N_STEPS,
        "n_components": "auto",
        "max_components": 4,
        "reg_covar": {"task": 1e-6},
        "random_state": None,
        "fit_samples": 25,
        "bic_samples_per_sequence": 20.0,
        "task_objects": ["glass", "coaster"],  # None: every recorded object, resolved
        "orientation": True,
        "align": "auto",
        "calibrate": True,
    }
    assert oriented.learn_options_ is not None
    assert oriented.learn_options_["task_objects"] == ["coaster", "glass"]  # a tuple given
    assert oriented.learn_options_["fit_samples"] is None
    assert oriented.learn_options_["reg_covar"] == 1e-5
    assert oriented.oriented == ["coaster"]


def test_n_samples_counts_the_rows_each_gmm_was_fitted_on(
    robot: Robot, positions: Skill, oriented: Skill, coaster_demos: list[Demonstration]
) -> None:
    # 25 evenly spaced steps of 60 per demonstration; all 60 when fit_samples is None.
    assert positions.n_samples_ == dict.fromkeys(["joint", "glass", "coaster"], 3 * 25)
    assert oriented.n_samples_ == dict.fromkeys(["joint", "coaster", "glass"], 3 * N_STEPS)
    # Rounding can merge steps: 40 of 60 are 40 distinct ones, 59 of 60 are not all distinct.
    skill = Skill.learn(coaster_demos, robot, n_steps=N_STEPS, n_components=2, fit_samples=59)
    steps = np.unique(np.round(np.linspace(0, N_STEPS - 1, 59)).astype(int))
    assert skill.n_samples_ is not None and skill.n_samples_["joint"] == 3 * steps.size
    assert skill.learn_options_ is not None and skill.learn_options_["fit_samples"] == 59
    over = Skill.learn(coaster_demos, robot, n_steps=N_STEPS, n_components=2, fit_samples=500)
    assert over.learn_options_ is not None and over.learn_options_["fit_samples"] == N_STEPS
    assert over.n_samples_ == dict.fromkeys(over.constraint_names, 3 * N_STEPS)


@pytest.mark.parametrize("name", ["positions", "oriented", "skill"])
def test_learning_again_from_what_it_keeps_gives_the_same_skill_bit_for_bit(
    name: str, request: pytest.FixtureRequest
) -> None:
    skill: Skill = request.getfixturevalue(name)  # "skill": conftest's, every default
    assert skill.demonstrations_ is not None and skill.learn_options_ is not None
    again = Skill.learn(skill.demonstrations_, skill.robot, **skill.learn_options_)
    _same_gmms(skill, again)
    assert again.object_names == skill.object_names and again.reach == skill.reach
    a, b = again.aligned_, skill.aligned_
    assert (a.requested, a.applied, a.band, a.reference) == (
        b.requested,
        b.applied,
        b.band,
        b.reference,
    )
    np.testing.assert_array_equal(
        [a.spread_linear, a.spread_aligned], [b.spread_linear, b.spread_aligned]
    )
    for k in skill.calibration_:
        np.testing.assert_array_equal(again.calibration_[k], skill.calibration_[k])
    for k in skill.rotation_base:
        np.testing.assert_array_equal(again.rotation_base[k], skill.rotation_base[k])
    assert again.n_samples_ == skill.n_samples_ and again.learn_options_ == skill.learn_options_


def test_learn_checks_the_options_it_keeps(
    robot: Robot, coaster_demos: list[Demonstration]
) -> None:
    def learn(**kwargs: Any) -> object:
        return Skill.learn(coaster_demos, robot, n_steps=N_STEPS, **{"n_components": 2, **kwargs})

    for kwargs, match in [
        ({"random_state": -1}, r"random_state must be >= 0, got -1"),
        ({"random_state": 2**32}, r"random_state must be <= 4294967295"),
        ({"random_state": np.random.default_rng(0)}, r"random_state must be an integer"),
        ({"bic_samples_per_sequence": 0.0}, r"bic_samples_per_sequence must be finite and > 0"),
        ({"orientation": 1}, r"orientation must be True or False, got 1"),
        ({"calibrate": "yes"}, r"calibrate must be True or False, got 'yes'"),
        ({"align": "always"}, r"align must be True, False or 'auto', got 'always'"),
        ({"n_components": "best"}, r"n_components must be a positive integer, 'auto' or 'bic'"),
    ]:
        with pytest.raises(ValueError, match=match):
            learn(**kwargs)


# ----------------------------------------------------------------------------- version 3
@pytest.mark.parametrize("name", ["positions", "oriented"])
def test_a_version_3_file_keeps_what_the_skill_learned_from(
    name: str, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    skill: Skill = request.getfixturevalue(name)
    path = tmp_path / "skill.npz"
    skill.save(path)
    arrays = _arrays(path)
    assert int(arrays["version"]) == 3 and all(a.dtype != object for a in arrays.values())
    # The demonstrations' arrays are those of a demonstrations file, under "demos_".
    assert skill.demonstrations_ is not None
    save_demonstrations(skill.demonstrations_, tmp_path / "demos.npz")
    demo_file = _arrays(tmp_path / "demos.npz")
    del demo_file["format"], demo_file["version"]
    stored = {k[len("demos_") :]: v for k, v in arrays.items() if k.startswith("demos_")}
    assert sorted(stored) == sorted(demo_file)
    for k, v in demo_file.items():
        np.testing.assert_array_equal(stored[k], v)
        assert stored[k].dtype == v.dtype
    assert ("demos_demo_0_rotations" in arrays) == bool(skill.oriented)

    back = Skill.load(path)
    assert back.learn_options_ == skill.learn_options_ and back.n_samples_ == skill.n_samples_
    assert back.demonstrations_ is not None
    assert len(back.demonstrations_) == len(skill.demonstrations_)
    for a, b in zip(back.demonstrations_, skill.demonstrations_, strict=True):
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.joints, b.joints)
        assert a.gripper is not None and b.gripper is not None
        np.testing.assert_array_equal(a.gripper, b.gripper)
        assert a.object_names == b.object_names
        for k in a.objects:
            np.testing.assert_array_equal(a.objects[k], b.objects[k])
    objects = _objects(skill, skill.demonstrations_[0])
    for use in (None, ["joint"], [skill.object_names[0]]):
        a_res, b_res = skill.reproduce(objects, use=use), back.reproduce(objects, use=use)
        for field in ("joints", "positions", "covariances", "gripper", "times"):
            np.testing.assert_array_equal(getattr(a_res, field), getattr(b_res, field))
    # And a loaded skill learns again as the original did.
    assert back.learn_options_ is not None
    _same_gmms(skill, Skill.learn(back.demonstrations_, back.robot, **back.learn_options_))
    # Far below the cap: what the file's arrays take once loaded.
    with open_npz(path) as data:
        loaded = sum(h.nbytes for h in data.headers.values())
    assert loaded < MAX_FILE_BYTES / 200


def test_a_learned_skill_pickles_with_its_demonstrations(positions: Skill) -> None:
    # evaluate sends skills to Dask workers and threads deep-copy them.
    for back in (pickle.loads(pickle.dumps(positions)), copy.deepcopy(positions)):
        assert back.demonstrations_ is not None and positions.demonstrations_ is not None
        for a, b in zip(back.demonstrations_, positions.demonstrations_, strict=True):
            np.testing.assert_array_equal(a.joints, b.joints)
            assert not a.joints.flags.writeable and dict(a.objects).keys() == b.objects.keys()
        assert back.learn_options_ == positions.learn_options_


# ----------------------------------------------------------------------------- without them
ONE_LINE = (
    r"^this skill does not keep its demonstrations \(a skill file of version 1 or 2, or a skill "
    r"built by hand\): re-learn it with Skill.learn to use {}$"
)


@pytest.mark.parametrize(("name", "version"), [("positions", 1), ("oriented", 2)])
def test_a_skill_without_demonstrations_writes_version_1_or_2_and_says_to_learn_again(
    name: str, version: int, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    learned: Skill = request.getfixturevalue(name)
    bare = bare_skill(learned)
    assert bare.demonstrations_ is None and bare.learn_options_ is None and bare.n_samples_ is None
    for what in ("update", "suggest"):
        with pytest.raises(ValueError, match=ONE_LINE.format(what)):
            bare._learned_from(what)
    bare.save(tmp_path / "bare.npz")
    learned.save(tmp_path / "learned.npz")
    old, new = _arrays(tmp_path / "bare.npz"), _arrays(tmp_path / "learned.npz")
    # As older versions of pbdkit wrote it: the version-3 file without its own keys.
    own = {"n_samples", "version"} | {k for k in new if k.startswith(("demos_", "learn_"))}
    assert int(old["version"]) == version and sorted(old) == sorted(set(new) - own | {"version"})
    for path in (tmp_path / "bare.npz", _written(tmp_path / "v.npz", new, drop=own, version=2)):
        loaded = Skill.load(path)
        assert loaded.demonstrations_ is None and loaded.learn_options_ is None
        assert loaded.n_samples_ is None
        with pytest.raises(ValueError, match=ONE_LINE.format("update")):
            loaded._learned_from("update")
        _same_gmms(loaded, learned)
    # A learned skill gives copies: changing them changes nothing of the skill.
    demos, options = learned._learned_from("update")
    demos.clear()
    options["task_objects"] = []
    assert learned.demonstrations_ and learned.learn_options_ is not None
    assert learned.learn_options_["task_objects"] == learned.object_names


def _written(path: Path, arrays: Arrays, *, drop: Collection[str] = (), **change: Any) -> Path:
    """``arrays`` without ``drop``, with ``change``, written to ``path``."""
    out = {k: v for k, v in arrays.items() if k not in drop}
    out.update({k: np.asarray(v) for k, v in change.items()})
    np.savez(path, **out)
    return path


def test_the_constructor_checks_what_it_is_given(positions: Skill) -> None:
    parts = {
        "demonstrations": positions.demonstrations_,
        "learn_options": positions.learn_options_,
        "n_samples": positions.n_samples_,
    }

    def build(**change: Any) -> Skill:
        bare = bare_skill(positions)
        return Skill(
            bare.robot,
            bare.gmms,
            n_steps=bare.n_steps,
            object_names=bare.object_names,
            has_gripper=bare.has_gripper,
            reach=bare.reach,
            **{**parts, **change},
        )

    assert build().learn_options_ == positions.learn_options_
    assert positions.demonstrations_ is not None and positions.learn_options_ is not None
    for change, match in [
        ({"n_samples": None}, r"go together .*: give all three or none"),
        ({"demonstrations": positions.demonstrations_[:1]}, r"at least 2 demonstrations"),
        (
            {"learn_options": {**positions.learn_options_, "align": "often"}},
            r"learn_options\['align'\] must be True, False or 'auto', got 'often'",
        ),
        (
            {"learn_options": {**positions.learn_options_, "n_steps": 61}},
            r"learn_options\['n_steps'\] is 61, the skill has 60 steps",
        ),
        ({"n_samples": {"joint": 75}}, r"n_samples must give a count for \['joint', 'glass'"),
        ({"n_samples": {"joint": 0, "glass": 1, "coaster": 1}}, r"n_samples\['joint'\] must"),
    ]:
        with pytest.raises(ValueError, match=match) as info:
            build(**change)
        assert "\n" not in str(info.value)


# ----------------------------------------------------------------------------- hostile files
def _drop_demo_1(arrays: Arrays) -> None:
    for k in [k for k in arrays if k.startswith("demos_demo_") and k.split("_")[2] != "0"]:
        del arrays[k]
    arrays["demos_n_demos"] = np.array(1)


def _no_gripper(arrays: Arrays) -> None:
    for k in [k for k in arrays if k.startswith("demos_demo_") and k.endswith("_gripper")]:
        del arrays[k]
    arrays["demos_has_gripper"] = np.array(False)


def _set(key: str, value: Any) -> Callable[[Arrays], None]:
    def change(arrays: Arrays) -> None:
        arrays[key] = np.asarray(value)

    return change


def _edit(key: str, edit: Callable[[NDArray[Any]], NDArray[Any]]) -> Callable[[Arrays], None]:
    def change(arrays: Arrays) -> None:
        arrays[key] = edit(arrays[key].copy())

    return change


def _nan_at(index: tuple[int, ...]) -> Callable[[NDArray[Any]], NDArray[Any]]:
    def edit(a: NDArray[Any]) -> NDArray[Any]:
        a[index] = np.nan
        return a

    return edit


def _delete(key: str) -> Callable[[Arrays], None]:
    def change(arrays: Arrays) -> None:
        del arrays[key]

    return change


HOSTILE: list[tuple[str, Callable[[Arrays], None], str]] = [
    # The demonstrations, as load_demonstrations judges them.
    (
        "times not increasing",
        _edit("demos_demo_1_t", lambda t: t[::-1].copy()),
        r"demos_demo_1: t must be strictly increasing",
    ),
    (
        "NaN joint angle",
        _edit("demos_demo_0_joints", _nan_at((3, 2))),
        r"demos_demo_0: joints must be finite",
    ),
    (
        "joints of another shape",
        _edit("demos_demo_2_joints", lambda q: q[:, :4]),
        r"demos_demo_2_joints has 4 joints, expected 5 like demos_demo_0_joints",
    ),
    (
        "objects of another shape",
        _edit("demos_demo_0_objects", lambda o: o[:1]),
        r"demos_demo_0_objects must have shape \(2, 3\), got \(1, 3\)",
    ),
    (
        "gripper of another length",
        _edit("demos_demo_1_gripper", lambda g: g[:-1]),
        r"demos_demo_1: gripper must have shape",
    ),
    ("unknown key", _set("demos_extra", 1.0), r"unknown key\(s\) 'demos_extra'"),
    (
        "a demonstration beyond n_demos",
        _set("demos_demo_7_t", np.arange(3.0)),
        r"demos_n_demos is 3 but the file holds 'demos_demo_7_t', which it does not describe",
    ),
    ("n_demos of 1", _drop_demo_1, r"demos_n_demos: demos must hold at least 2 demonstrations"),
    ("n_demos a float", _set("demos_n_demos", 3.0), r"demos_n_demos must be an integer >= 1"),
    ("missing demonstration", _delete("demos_demo_2_joints"), r"missing key 'demos_demo_2_joints'"),
    ("complex times", _edit("demos_demo_0_t", lambda t: t + 0j), r"demos_demo_0_t must hold real"),
    # The demonstrations against the skill.
    (
        "object names of another skill",
        _set("demos_object_names", ["glass", "cup"]),
        r"demos_object_names: the demonstrations record the objects \['glass', 'cup'\], not the "
        r"skill's \['coaster'\]",
    ),
    (
        "no gripper signal",
        _no_gripper,
        r"demos_has_gripper: the demonstrations have no gripper signal, the skill has",
    ),
    (
        "no joint like the skill's",
        lambda a: a.update(
            {k: v[:, :4] for k, v in a.items() if k.startswith("demos_") and k.endswith("joints")}
        ),
        r"demos_demo_0_joints: the demonstrations have 4 joints, the skill 5",
    ),
    # The options, as Skill.learn judges them.
    ("max_components 0", _set("learn_max_components", 0), r"learn_max_components must be >= 1"),
    (
        "max_components over the cap",
        _set("learn_max_components", 5000),
        r"learn_max_components must be <= 1000, got 5000",
    ),
    (
        "n_components a word",
        _set("learn_n_components", "best"),
        r"learn_n_components must be a positive integer, 'auto' or 'bic', got 'best'",
    ),
    (
        "n_components a float",
        _set("learn_n_components", 2.0),
        r"learn_n_components must hold an integer or a string, got 2.0 of dtype float64",
    ),
    ("random_state -1", _set("learn_random_state", -1), r"learn_random_state must be >= 0"),
    ("fit_samples 1", _set("learn_fit_samples", 1), r"learn_fit_samples must be >= 2, got 1"),
    (
        "bic_samples_per_sequence NaN",
        _set("learn_bic_samples_per_sequence", np.nan),
        r"learn_bic_samples_per_sequence must be finite and > 0, got nan",
    ),
    (
        "reg_covar negative",
        _set("learn_reg_covar", [-1.0]),
        r"learn_reg_covar: reg_covar\['task'\] must be finite and >= 0",
    ),
    (
        "reg_covar of an unknown kind",
        _set("learn_reg_covar_names", ["hand"]),
        r"learn_reg_covar: reg_covar: unknown key\(s\) \['hand'\]",
    ),
    (
        "reg_covar names without values",
        _set("learn_reg_covar", [1e-6, 1e-6]),
        r"learn_reg_covar must be floats of the shape of learn_reg_covar_names \(1,\)",
    ),
    (
        "orientation an integer",
        _set("learn_orientation", 1),
        r"learn_orientation must hold a boolean, got 1 of dtype int64",
    ),
    (
        "align a word",
        _set("learn_align", "sometimes"),
        r"learn_align must be True, False or 'auto', got 'sometimes'",
    ),
    (
        "calibrate two booleans",
        _set("learn_calibrate", [True, True]),
        r"learn_calibrate must hold a boolean, got \[True, True\]",
    ),
    ("missing option", _delete("learn_align"), r"missing key 'learn_align'"),
    # The sample counts.
    (
        "n_samples of another shape",
        _set("n_samples", [75, 75]),
        r"n_samples must hold 3 integers \(one per space, \['joint', 'glass', 'coaster'\]\)",
    ),
    ("n_samples 0", _edit("n_samples", lambda n: n * 0), r"n_samples\['joint'\] must be >= 1"),
    (
        "n_samples beyond every step",
        _edit("n_samples", lambda n: n * 10),
        r"n_samples\['joint'\] must be <= 180, got 750",
    ),
    ("missing n_samples", _delete("n_samples"), r"missing key 'n_samples'"),
    # Version 3's keys in a file of version 2.
    ("version 2", _set("version", 2), r"unknown key\(s\) 'demos_n_demos'"),
]


@pytest.mark.parametrize(
    ("change", "match"), [case[1:] for case in HOSTILE], ids=[case[0] for case in HOSTILE]
)
def test_a_hostile_version_3_file_is_refused_in_one_line_naming_the_key(
    positions: Skill, tmp_path: Path, change: Callable[[Arrays], None], match: str
) -> None:
    positions.save(tmp_path / "skill.npz")
    arrays = _arrays(tmp_path / "skill.npz")
    change(arrays)
    np.savez(tmp_path / "bad.npz", **arrays)
    bad = r"bad\.npz is not a valid pbdkit-skill file: "
    with pytest.raises(ValueError, match=bad + match) as info:
        Skill.load(tmp_path / "bad.npz")
    assert "\n" not in str(info.value) and len(str(info.value)) < 400


def test_a_version_3_file_whose_orientation_disagrees_is_refused(
    oriented: Skill, tmp_path: Path
) -> None:
    oriented.save(tmp_path / "skill.npz")
    arrays = _arrays(tmp_path / "skill.npz")
    _written(tmp_path / "bad.npz", arrays, learn_orientation=False)
    with pytest.raises(
        ValueError,
        match=re.escape(
            "demos_demo_0_rotations and learn_orientation: learning with orientation=False "
            "orients the constraints of [], the skill those of ['coaster']"
        ),
    ):
        Skill.load(tmp_path / "bad.npz")
    # A demonstration whose coaster is a position where the others have a pose.
    rotations = arrays["demos_demo_1_rotations"].copy()
    rotations[1] = np.nan  # object_names: glass (a position), coaster
    _written(tmp_path / "mixed.npz", arrays, demos_demo_1_rotations=rotations)
    with pytest.raises(ValueError, match=r"demos_n_demos: demos\[1\]\.objects\['coaster'\] is a"):
        Skill.load(tmp_path / "mixed.npz")
