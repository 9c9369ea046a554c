"""Hostile inputs, fourth pass (issue 36, items 5, 11, 12, 15 and 17): poses, skill files and
frame models of absurd magnitude.

- 5: a quaternion of 1e200 overflowed its norm into a NaN rotation that passed every check
  (a RuckigError, a traceback, a NaN pose kept by ``ctrl.step``): it is its rotation; a 4x4
  transform of 1e200 is refused.
- 11: a skill file's duration of 1e300 s gave NaN velocities: refused above MAX_DURATION.
- 12: FrameModel went NaN for a frame A = 1e-200 I and a file whose means are 1e308, and
  failed without naming an argument for times of 1e300 and coordinates of 1e200.
- 15: a complex ``rot_base_0`` lost its imaginary part with a warning only.
- 17: a skill of K = 100,000 made ``reproduce`` allocate 3.6 GB: K is capped at load.

Each refusal is a one-line ValueError naming the argument (or the file's key).
"""

from __future__ import annotations

import re
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from pbdkit._rotations import as_pose, check_rotation, matrix_from_quaternion, pose_matrix
from pbdkit.data._demonstration import Demonstration
from pbdkit.data._placement import check_placements
from pbdkit.prob._frames import FrameModel
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill
from pbdkit.skill._skill_file import MAX_DURATION, MAX_FILE_COMPONENTS

Float = NDArray[np.float64]
HUGE_QUATERNION = [1e200, 0.0, 0.0, 0.0]  # the identity, 1e200 times
LIMIT = re.escape(f"MAX_DURATION = {MAX_DURATION:g}")


def _refused(call: Callable[[], object], match: str) -> str:
    """The one-line message of the ValueError ``call`` raises, matching ``match``."""
    with pytest.raises(ValueError, match=match) as info:
        call()
    text = str(info.value)
    assert "\n" not in text and len(text) < 400
    return text


@pytest.fixture(scope="module")
def oriented(robot: Robot, demos: list[Demonstration]) -> Skill:
    """A small skill of the glass given as a pose: its constraint is oriented."""
    posed = [
        Demonstration(d.t, d.joints, {k: pose_matrix(v) for k, v in d.objects.items()}, d.gripper)
        for d in demos
    ]
    return Skill.learn(posed, robot, n_steps=40, n_components=2, align=False, calibrate=False)


@pytest.fixture(scope="module")
def stored(oriented: Skill, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The arrays of ``oriented``'s file, by key."""
    path = tmp_path_factory.mktemp("skill") / "skill.npz"
    oriented.save(path)
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _tampered(stored: dict[str, Any], tmp_path: Path, **change: Any) -> Path:
    path = tmp_path / "bad.npz"
    np.savez(path, **{**stored, **change})
    return path


# ----------------------------------------------------------------------------- item 5: poses
def test_a_huge_quaternion_is_its_rotation() -> None:
    position, rot = as_pose([0.3, 0.0, 0.1, *HUGE_QUATERNION])
    np.testing.assert_array_equal(position, [0.3, 0.0, 0.1])
    np.testing.assert_array_equal(rot, np.eye(3))
    # A quarter turn about x, at any magnitude, up to the largest float.
    quarter = matrix_from_quaternion([1.0, 1.0, 0.0, 0.0])
    for scale in (1e200, 1.7e308, 1e-300):
        np.testing.assert_allclose(
            matrix_from_quaternion([scale, scale, 0, 0]), quarter, atol=1e-15
        )
    _, rot = as_pose([0.0, 0.0, 0.0, 1.7e308, 1.7e308, 0.0, 0.0])
    np.testing.assert_allclose(rot, quarter, atol=1e-15)
    placed = check_placements({"glass": [0.3, 0.0, 0.1, *HUGE_QUATERNION]})
    np.testing.assert_array_equal(placed["glass"], pose_matrix([0.3, 0.0, 0.1]))


def test_a_huge_quaternion_reproduces_as_the_identity(
    oriented: Skill, demos: list[Demonstration]
) -> None:
    glass = demos[0].objects["glass"]
    seven = [*glass, *HUGE_QUATERNION]
    a = oriented.reproduce({"glass": pose_matrix(glass)})
    b = oriented.reproduce({"glass": seven})
    assert np.all(np.isfinite(b.joints))
    np.testing.assert_allclose(b.joints, a.joints, atol=1e-12)
    # ctrl.step keeps the pose it is given: the identity, not NaN.
    q0 = demos[0].joints[0]
    moved = pose_matrix(glass + np.array([0.02, 0.0, 0.0]))
    ctrl = oriented.controller({"glass": moved})
    ref = oriented.controller({"glass": moved})
    for _ in range(3):
        cmd = ctrl.step(q0, objects={"glass": seven})
        want = ref.step(q0, objects={"glass": pose_matrix(glass)})
        assert np.all(np.isfinite(cmd.q))
        np.testing.assert_allclose(cmd.q, want.q, atol=1e-12)


@pytest.mark.parametrize(
    ("block", "match"),
    [
        (1e200 * np.eye(3), r"off by inf with determinant inf"),
        # R^T R and det overflow: a RuntimeWarning (an error under pytest) came first; a NaN
        # deviation (inf - inf) passed the "> tolerance" test.
        ([[1e200, 1e200, 0.0], [1e200, -1e200, 0.0], [0.0, 0.0, 1.0]], r"off by inf"),
        ([[1e300, 1e300, 1e300], [1e300, -1e300, 0.0], [0.0, 0.0, 1.0]], r"off by inf"),
    ],
)
def test_a_huge_transform_is_refused(
    oriented: Skill, demos: list[Demonstration], block: object, match: str
) -> None:
    glass = demos[0].objects["glass"]
    t = pose_matrix(glass)
    t[:3, :3] = block
    expected = r"^objects\['glass'\]: the rotation block of a 4x4 transform .*" + match
    _refused(lambda: check_placements({"glass": t}), expected)
    _refused(lambda: oriented.reproduce({"glass": t}), expected)
    ctrl = oriented.controller({"glass": pose_matrix(glass)})
    _refused(lambda: ctrl.step(demos[0].joints[0], objects={"glass": t}), expected)


def test_a_complex_pose_or_rotation_is_refused() -> None:
    _refused(
        lambda: as_pose(np.array([0.3, 0.0, 0.1, 1.0, 0.0, 0.0, 1e-3j]), "objects['glass']"),
        r"^objects\['glass'\] must be a position .* of real numbers, got complex values",
    )
    _refused(
        lambda: check_rotation(np.eye(3) + 1e-3j, "orientation"),
        r"^orientation must be a rotation matrix \(3, 3\) of real numbers, got complex",
    )


# ----------------------------------------------------------------------------- item 11: duration
def test_a_skill_file_of_1e300_seconds_is_refused(
    stored: dict[str, Any], demos: list[Demonstration], tmp_path: Path
) -> None:
    path = _tampered(stored, tmp_path, duration=np.array(1e300))
    _refused(
        lambda: Skill.load(path),
        r"bad\.npz is not a valid pbdkit-skill file: the duration must be at most "
        + LIMIT
        + r" s, got 1e\+300 s$",
    )
    # Up to the bound it loads, and its velocities are numbers.
    path = _tampered(stored, tmp_path, duration=np.array(MAX_DURATION))
    skill = Skill.load(path)
    assert skill.duration == MAX_DURATION
    res = skill.reproduce({"glass": pose_matrix(demos[0].objects["glass"])})
    assert res.velocities is not None and np.all(np.isfinite(res.velocities))


def test_learn_and_the_constructor_refuse_a_duration_of_1e300(
    robot: Robot, demos: list[Demonstration], oriented: Skill
) -> None:
    slow = [Demonstration(d.t / d.t[-1] * 1e300, d.joints, d.objects, d.gripper) for d in demos]
    _refused(
        lambda: Skill.learn(slow, robot, n_steps=40, n_components=1),
        r"^demos: the duration must be at most " + LIMIT + r" s, got 1e\+300 s",
    )
    for bad in (1e300, np.inf, -1.0, 0.0):
        _refused(
            lambda bad=bad: Skill(
                robot,
                oriented.gmms,
                n_steps=oriented.n_steps,
                object_names=oriented.object_names,
                has_gripper=oriented.has_gripper,
                reach=oriented.reach,
                duration=bad,
                rotation_base=oriented.rotation_base,
            ),
            r"^duration must be NaN \(unknown\) or in \(0, " + LIMIT + r"\] s, got ",
        )


# ----------------------------------------------------------------------------- item 15: complex
@pytest.mark.parametrize(
    "key", ["rot_base_0", "aligned_spreads", "sel_joint_scores", "sel_0_fold_scores"]
)
def test_a_complex_array_in_a_skill_file_is_refused(
    stored: dict[str, Any], tmp_path: Path, key: str
) -> None:
    path = _tampered(stored, tmp_path, **{key: stored[key] + 1e-3j})
    _refused(
        lambda: Skill.load(path),
        rf"bad\.npz is not a valid pbdkit-skill file: {key} must hold real numbers, "
        r"got dtype complex128$",
    )


# ----------------------------------------------------------------------------- item 17: K
@pytest.mark.parametrize("start", ["bogus", "segments" * 40])
def test_a_skill_file_of_an_unknown_start_of_em_is_refused(
    stored: dict[str, Any], tmp_path: Path, start: str
) -> None:
    assert str(stored["sel_joint_start"]) == "equal counts"
    path = _tampered(stored, tmp_path, sel_joint_start=np.array(start))
    _refused(
        lambda: Skill.load(path),
        r"bad\.npz is not a valid pbdkit-skill file: the model selection stored for 'joint' "
        r"is inconsistent$",
    )
    # Files written before the start was recorded load, as started from equal counts.
    older = _tampered({k: v for k, v in stored.items() if k != "sel_joint_start"}, tmp_path)
    assert Skill.load(older).selection_["joint"].start == "equal counts"


def test_a_skill_file_of_too_many_components_is_refused_from_its_headers(
    stored: dict[str, Any], tmp_path: Path
) -> None:
    k = MAX_FILE_COMPONENTS + 1
    means = np.repeat(stored["gmm_0_means"][:1], k, axis=0)
    covariances = np.repeat(stored["gmm_0_covariances"][:1], k, axis=0)
    path = _tampered(
        stored,
        tmp_path,
        gmm_0_weights=np.full(k, 1.0 / k),
        gmm_0_means=means,
        gmm_0_covariances=covariances,
        sel_0_method=np.array("fixed"),
        sel_0_candidates=np.array([k]),
        sel_0_scores=np.zeros(1),
        sel_0_fold_scores=np.zeros((1, 0)),
        sel_0_best_chosen=np.array([k, k]),
    )
    tracemalloc.start()
    start = time.perf_counter()
    try:
        _refused(
            lambda: Skill.load(path),
            rf"bad\.npz is not a valid pbdkit-skill file: gmm_0_weights holds {k} components; "
            rf"a GMM may have at most MAX_FILE_COMPONENTS = {MAX_FILE_COMPONENTS} ",
        )
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - start < 2.0
    assert peak < 20 * 2**20  # the arrays were never loaded


def test_learn_refuses_more_components_than_load_reads(
    robot: Robot, demos: list[Demonstration]
) -> None:
    too_many = MAX_FILE_COMPONENTS + 1
    _refused(
        lambda: Skill.learn(demos, robot, n_steps=40, n_components=too_many),
        rf"^n_components must be <= {MAX_FILE_COMPONENTS}, got {too_many}$",
    )
    _refused(
        lambda: Skill.learn(demos, robot, n_steps=40, max_components=too_many),
        rf"^max_components must be <= {MAX_FILE_COMPONENTS}, got {too_many}$",
    )


# ----------------------------------------------------------------------------- item 12: frames
def _frame_demos(n_demos: int = 3, n: int = 30) -> tuple[list[Float], list[list[Any]]]:
    """Small 2-D demonstrations (seeded), each with a start and a goal frame."""
    rng = np.random.default_rng(0)
    trajectories, frames = [], []
    u = np.linspace(0.0, 1.0, n)
    for i in range(n_demos):
        goal = np.array([1.0, 0.1 * i])
        x = np.outer(u, goal) + 0.01 * rng.standard_normal((n, 2))
        trajectories.append(np.column_stack([u, x]))
        frames.append([(np.eye(2), np.zeros(2)), (np.eye(2), goal)])
    return trajectories, frames


@pytest.fixture(scope="module")
def frame_model() -> FrameModel:
    return FrameModel.learn(*_frame_demos(), n_components=2)


def _with_frame(frames: list[list[Any]], i: int, p: int, a: Any = None, b: Any = None) -> list:
    out = [list(f) for f in frames]
    old_a, old_b = out[i][p]
    out[i][p] = (old_a if a is None else a, old_b if b is None else b)
    return out


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (
            lambda tr, fr: (tr, _with_frame(fr, 1, 1, a=1e-200 * np.eye(2))),
            r"^frames\[1\]\[1\] A must scale by 1e-09 to 1e\+09 \(its singular values, "
            r"FRAME_SCALE_RANGE\), got singular values from 1e-200 to 1e-200$",
        ),
        (
            lambda tr, fr: (tr, _with_frame(fr, 2, 0, a=1e200 * np.eye(2))),
            r"^frames\[2\]\[0\] A must scale by .* from 1e\+200 to 1e\+200$",
        ),
        (
            lambda tr, fr: (tr, _with_frame(fr, 0, 1, b=[1e200, 0.0])),
            r"^frames\[0\]\[1\] b must be at most MAX_MAGNITUDE = 1e\+15 in magnitude, "
            r"got 1e\+200$",
        ),
        (  # within each bound, but not seen from the frame: 1e7 / 1e-9
            lambda tr, fr: (
                [tr[0], np.column_stack([tr[1][:, 0], tr[1][:, 1:] * 1e7]), tr[2]],
                _with_frame(fr, 1, 0, a=1e-9 * np.eye(2)),
            ),
            r"^frames\[1\]\[0\] \(trajectories\[1\] seen from the frame, A\^-1 \(x - b\)\) "
            r"must be at most MAX_MAGNITUDE = 1e\+15 in magnitude, got 1\.\d+e\+16$",
        ),
        (
            lambda tr, fr: ([tr[0], tr[1] * [1e300, 1.0, 1.0], tr[2]], fr),
            r"^trajectories\[1\]\[:, 0\] \(time\) must be at most MAX_MAGNITUDE = 1e\+15 in "
            r"magnitude, got 1e\+300$",
        ),
        (  # was "zero-size array to reduction operation maximum which has no identity"
            lambda tr, fr: ([tr[0] * [1.0, 1e200, 1e200], tr[1], tr[2]], fr),
            r"^trajectories\[0\]\[:, 1:\] \(coordinates\) must be at most MAX_MAGNITUDE",
        ),
    ],
)
def test_frame_model_learn_refuses_absurd_scales(
    change: Callable[[list[Float], list[list[Any]]], tuple[Any, Any]], match: str
) -> None:
    trajectories, frames = change(*_frame_demos())
    _refused(lambda: FrameModel.learn(trajectories, frames, n_components=2), match)


@pytest.mark.parametrize("seed", [-1, 2**32, 1.5, "0", True, np.random.default_rng(0)])
def test_frame_model_learn_validates_random_state(seed: object) -> None:
    _refused(
        lambda: FrameModel.learn(*_frame_demos(), n_components=2, random_state=seed),  # type: ignore[arg-type]
        r"^random_state must be None, an integer in \[0, 2\*\*32 - 1\] or a numpy "
        r"RandomState, got ",
    )


def test_frame_model_learn_takes_sklearn_random_states() -> None:
    for seed in (None, 0, 2**32 - 1, np.int64(3), np.random.RandomState(0)):
        model = FrameModel.learn(*_frame_demos(), n_components=2, random_state=seed)
        assert model.n_components == [2, 2]


def test_frame_model_reproduce_refuses_absurd_frames_and_times(frame_model: FrameModel) -> None:
    t = np.linspace(0.0, 1.0, 5)
    ok = [(np.eye(2), np.zeros(2)), (np.eye(2), np.ones(2))]
    mean, cov = frame_model.reproduce(ok, t)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))
    _refused(
        lambda: frame_model.reproduce([ok[0], (1e-200 * np.eye(2), np.ones(2))], t),
        r"^frames\[1\] A must scale by 1e-09 to 1e\+09 .* from 1e-200 to 1e-200$",
    )
    _refused(
        lambda: frame_model.reproduce(ok, [0.0, 1e300]),
        r"^t must be at most MAX_MAGNITUDE = 1e\+15 in magnitude, got 1e\+300$",
    )


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("gmm_0_means", 1e308, r"gmm_0_means must be at most 1e\+15 in magnitude"),
        ("gmm_1_means", np.nan, r"gmm_1_means must be finite, got \d+ NaN"),
        ("gmm_0_covariances", 1e308, r"gmm_0_covariances must be at most 1e\+30 in magnitude"),
    ],
)
def test_frame_model_load_refuses_absurd_values_naming_the_key(
    frame_model: FrameModel, tmp_path: Path, key: str, value: float, match: str
) -> None:
    path = tmp_path / "model.npz"
    frame_model.save(path)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays[key] = arrays[key].copy()
    arrays[key][(0,) * arrays[key].ndim] = value  # a mean's time, or a variance
    np.savez(path, **arrays)
    _refused(
        lambda: FrameModel.load(path),
        r"model\.npz is not a valid pbdkit-frame-model file: " + match,
    )
