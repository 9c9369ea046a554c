"""Tests of pbdkit.prob._frames: the frame mappings against explicit inverses, FrameModel's
prediction against its definition (GMR per frame, product of the world Gaussians), its
equivariance under similarity transforms, leave-one-demonstration-out accuracy on reaching data
with rotated targets against the same model given translation-only frames, files and bad input.

The reaching data are made here (seeded): a start frame and a target frame per demonstration,
the hand reaching the target from a direction fixed in the target's frame.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from pbdkit.prob import GMM, SelectionWarning
from pbdkit.prob._frames import (
    FrameModel,
    covariance_to_world,
    precision_to_world,
    product_in_world,
    to_local,
    to_world,
)

Float = NDArray[np.float64]
Frames = list[tuple[Float, Float]]
APPROACH = 0.25  # length of the final approach, along the target's local x axis
APPROACH_START = 0.6  # phase at which the approach starts


def rotation(rng: np.random.Generator, dim: int, max_angle: float = np.pi) -> Float:
    """A random rotation (dim, dim): in 2-D by an angle in [-max_angle, max_angle]."""
    if dim == 2:
        a = rng.uniform(-max_angle, max_angle)
        return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return np.asarray(Rotation.random(random_state=rng).as_matrix(), dtype=np.float64)


def min_jerk(u: Float) -> Float:
    return np.asarray(10 * u**3 - 15 * u**4 + 6 * u**5, dtype=np.float64)


def reaching(
    rng: np.random.Generator,
    n_demos: int,
    dim: int = 2,
    target_angle: float = 2.1,
    general: bool = False,
) -> tuple[list[Float], list[Frames]]:
    """Demonstrations of reaching a target from a direction fixed in the target's frame.

    Each demonstration has a start frame (at its start point, rotated at random) and a target
    frame (at a random point, rotated by up to ``target_angle`` rad in 2-D, at random in 3-D;
    with ``general``, also scaled and reflected). The hand moves from the start to the point
    A_target (-APPROACH, 0, ...) + b_target (min-jerk over phase 0 .. APPROACH_START) and then
    along the target's first axis onto the target. Time is the phase in [0, 1], sampled at 80
    to 140 points (the demonstrations differ in duration), and 3 mm of noise is added.
    """
    trajectories, frames = [], []
    for _ in range(n_demos):
        start = rng.uniform(-0.2, 0.2, dim)
        a_start = rotation(rng, dim)
        goal = np.r_[1.0, np.zeros(dim - 1)] + rng.uniform(-0.3, 0.3, dim)
        a_goal = rotation(rng, dim, target_angle)
        if general:
            a_goal = a_goal @ np.diag(rng.uniform(0.5, 2.0, dim) * rng.choice([-1.0, 1.0], dim))
        n = int(rng.integers(80, 141))
        u = np.linspace(0.0, 1.0, n)
        local_pre = np.r_[-APPROACH, np.zeros(dim - 1)]
        pre = a_goal @ local_pre + goal
        x = np.empty((n, dim))
        first = u < APPROACH_START
        x[first] = start + np.outer(min_jerk(u[first] / APPROACH_START), pre - start)
        s = min_jerk((u[~first] - APPROACH_START) / (1 - APPROACH_START))
        x[~first] = goal + np.outer(1 - s, a_goal @ local_pre)
        x += 0.003 * rng.standard_normal(x.shape)
        trajectories.append(np.column_stack([u, x]))
        frames.append([(a_start, start), (a_goal, goal)])
    return trajectories, frames


def translation_only(frames: Frames) -> Frames:
    return [(np.eye(b.shape[0]), b) for _, b in frames]


def random_spd(rng: np.random.Generator, d: int) -> Float:
    a = rng.normal(size=(d, d))
    return np.asarray(a @ a.T + 0.1 * np.eye(d), dtype=np.float64)


@pytest.fixture(scope="module")
def data() -> tuple[list[Float], list[Frames]]:
    return reaching(np.random.default_rng(0), 6)


@pytest.fixture(scope="module")
def model(data: tuple[list[Float], list[Frames]]) -> FrameModel:
    return FrameModel.learn(*data, max_components=8)


# ----------------------------------------------------------------------------- frame mappings
FRAME_MATRICES = {
    "scaled": np.diag([2.0, 0.5, 3.0]),
    "rotation": Rotation.from_rotvec([0.3, -1.0, 0.4]).as_matrix(),
    "reflected": np.diag([1.0, -1.0, 1.0]) @ Rotation.from_rotvec([0.3, -1.0, 0.4]).as_matrix(),
    "scaled reflection": np.diag([-0.2, 4.0, 1.5]) @ Rotation.from_rotvec([1, 2, 3]).as_matrix(),
    "general": np.array([[1.0, 0.7, -0.2], [0.1, 0.3, 0.0], [-0.5, 0.2, 2.0]]),
}


@pytest.mark.parametrize("a", FRAME_MATRICES.values(), ids=FRAME_MATRICES.keys())
def test_world_precision_is_the_inverse_of_the_world_covariance(a: Float) -> None:
    rng = np.random.default_rng(1)
    s, m, b = random_spd(rng, 3), rng.normal(size=3), rng.normal(size=3)
    explicit_cov = a @ s @ a.T
    np.testing.assert_allclose(covariance_to_world(a, s), explicit_cov, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(
        precision_to_world(a, np.linalg.inv(s)), np.linalg.inv(explicit_cov), rtol=1e-10
    )
    mean, cov = to_world(a, b, m, s)
    np.testing.assert_allclose(mean, a @ m + b, rtol=1e-14)
    np.testing.assert_allclose(cov, explicit_cov, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(to_local(a, b, mean), m, rtol=1e-12, atol=1e-14)
    # A L A^T (pbdlib's GMM.lintrans) is the world precision for an orthogonal A only.
    a_l_at = a @ np.linalg.inv(s) @ a.T
    orthogonal = np.allclose(a.T @ a, np.eye(3), atol=1e-12)
    assert np.allclose(a_l_at, np.linalg.inv(explicit_cov), rtol=1e-10) == orthogonal


def test_a_l_a_transpose_holds_for_orthogonal_frames_only() -> None:
    rng = np.random.default_rng(2)
    q = rotation(rng, 3)
    lam = np.linalg.inv(random_spd(rng, 3))
    np.testing.assert_allclose(precision_to_world(q, lam), q @ lam @ q.T, rtol=1e-12)
    mirror = q @ np.diag([1.0, -1.0, 1.0])  # a reflection: orthogonal too
    np.testing.assert_allclose(precision_to_world(mirror, lam), mirror @ lam @ mirror.T, rtol=1e-12)
    # Scaled by 2: A^-T L A^-1 = L / 4 in the world, where A L A^T would give 4 L.
    np.testing.assert_allclose(precision_to_world(2.0 * q, lam), q @ lam @ q.T / 4, rtol=1e-12)


def test_mappings_broadcast_over_frames() -> None:
    rng = np.random.default_rng(3)
    a = np.stack(list(FRAME_MATRICES.values()))  # (P, 3, 3)
    n = a.shape[0]
    b = rng.normal(size=(n, 3))
    x = rng.normal(size=(5, n, 3))  # 5 points seen from each of the P frames
    local = to_local(a, b, x)
    for p in range(n):
        np.testing.assert_allclose(local[:, p], (np.linalg.inv(a[p]) @ (x[:, p] - b[p]).T).T)


def test_product_in_world_against_explicit_inverses() -> None:
    rng = np.random.default_rng(4)
    a = np.stack(list(FRAME_MATRICES.values()))
    n = a.shape[0]
    b = rng.normal(size=(n, 3))
    means = rng.normal(size=(6, n, 3))
    covs = np.array([[random_spd(rng, 3) for _ in range(n)] for _ in range(6)])
    mean, cov = product_in_world(a, b, means, covs)
    for t in range(6):
        precs = [np.linalg.inv(a[p] @ covs[t, p] @ a[p].T) for p in range(n)]
        ref_cov = np.linalg.inv(sum(precs))
        ref_mean = ref_cov @ sum(precs[p] @ (a[p] @ means[t, p] + b[p]) for p in range(n))
        np.testing.assert_allclose(cov[t], ref_cov, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(mean[t], ref_mean, rtol=1e-10, atol=1e-12)


# ----------------------------------------------------------------------------- FrameModel
def test_model_structure(model: FrameModel, data: tuple[list[Float], list[Frames]]) -> None:
    assert model.n_frames == 2 and model.n_dims == 2
    assert len(model.gmms) == 2 and all(isinstance(g, GMM) for g in model.gmms)
    assert model.n_components == [g.n_components_ for g in model.gmms]
    assert all(1 <= k <= 8 for k in model.n_components)
    # K was chosen by leaving one of the 6 demonstrations out at a time.
    assert all(g.selection_.n_folds == 6 for g in model.gmms)
    assert repr(model) == (f"FrameModel(n_frames=2, n_dims=2, n_components={model.n_components})")


def test_each_frame_is_fitted_on_the_demonstrations_seen_from_it(
    data: tuple[list[Float], list[Frames]],
) -> None:
    trajectories, frames = data
    model = FrameModel.learn(trajectories, frames, n_components=3, fit_samples=None)
    for p in range(2):
        x = np.vstack(
            [
                np.column_stack([tr[:, 0], (np.linalg.inv(f[p][0]) @ (tr[:, 1:] - f[p][1]).T).T])
                for tr, f in zip(trajectories, frames, strict=True)
            ]
        )
        groups = np.repeat(np.arange(6), [tr.shape[0] for tr in trajectories])
        ref = GMM(n_components=3, random_state=0).fit(x, groups=groups)
        np.testing.assert_allclose(model.gmms[p].means_, ref.means_, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(model.gmms[p].covariances_, ref.covariances_, rtol=1e-9)


def test_reproduce_is_the_product_of_the_frames_gmr_in_the_world(
    model: FrameModel, data: tuple[list[Float], list[Frames]]
) -> None:
    rng = np.random.default_rng(5)
    # New frames, the target scaled and reflected: the model must map with A^-T L A^-1.
    frames = [
        (rotation(rng, 2), rng.normal(size=2)),
        (rotation(rng, 2) @ np.diag([1.5, -0.5]), rng.normal(size=2)),
    ]
    t = np.linspace(0.0, 1.0, 25)
    mean, cov = model.reproduce(frames, t)
    assert mean.shape == (25, 2) and cov.shape == (25, 2, 2)
    world = []
    for (a, b), g in zip(frames, model.gmms, strict=True):
        m, s = g.regress(t, in_dims=[0])
        world.append(((a @ m.T).T + b, a @ s @ a.T))
    for i in range(25):
        precs = [np.linalg.inv(c[i]) for _, c in world]
        ref_cov = np.linalg.inv(sum(precs))
        ref_mean = ref_cov @ sum(lam @ m[i] for lam, (m, _) in zip(precs, world, strict=True))
        np.testing.assert_allclose(cov[i], ref_cov, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(mean[i], ref_mean, rtol=1e-9, atol=1e-12)
    # One frame's model: its GMR, mapped to the world, nothing else.
    single = FrameModel([model.gmms[1]])
    m1, c1 = single.reproduce(frames[1:], t)
    np.testing.assert_allclose(m1, world[1][0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(c1, world[1][1], rtol=1e-9, atol=1e-15)


def test_prediction_is_equivariant_under_a_similarity_transform() -> None:
    """x -> s Q x + c for the demonstrations and A -> s Q A, b -> s Q b + c for every frame
    leave the data seen from each frame as they were, so the model is the same and its
    prediction moves alike: mean s Q m + c, covariance s^2 Q S Q^T. In 3-D, with targets
    rotated, scaled and reflected."""
    rng = np.random.default_rng(6)
    trajectories, frames = reaching(rng, 5, dim=3, general=True)
    _, (new_frames,) = reaching(rng, 1, dim=3, general=True)
    q, s, c = rotation(rng, 3), 3.7, np.array([10.0, -4.0, 2.5])

    def move(frames: Frames) -> Frames:
        return [(s * q @ a, s * q @ b + c) for a, b in frames]

    moved = [np.column_stack([x[:, 0], s * x[:, 1:] @ q.T + c]) for x in trajectories]
    t = np.linspace(0.0, 1.0, 40)
    mean, cov = FrameModel.learn(trajectories, frames, max_components=8).reproduce(new_frames, t)
    model = FrameModel.learn(moved, [move(f) for f in frames], max_components=8)
    mean2, cov2 = model.reproduce(move(new_frames), t)
    expected_mean = s * mean @ q.T + c
    expected_cov = s**2 * q @ cov @ q.T
    assert np.max(np.abs(mean2 - expected_mean)) <= 1e-9 * np.max(np.abs(expected_mean))
    assert np.max(np.abs(cov2 - expected_cov)) <= 1e-9 * np.max(np.abs(expected_cov))
    # Not trivially: the prediction did move, and mapping precisions as A L A^T would not
    # scale the covariance by s^2.
    assert np.max(np.abs(mean2 - mean)) > 1.0


def leave_one_out_errors(
    trajectories: list[Float], frames: list[Frames], max_components: int
) -> Float:
    """Per left-out demonstration: the mean distance, over the last third of the motion, from
    the prediction of the model learned on the others (for the left-out frames, at its times)
    to the left-out demonstration."""
    errors = []
    for j in range(len(trajectories)):
        keep = [i for i in range(len(trajectories)) if i != j]
        with warnings.catch_warnings():
            # K is capped low to keep the test fast: its cap warning is expected here.
            warnings.simplefilter("ignore", SelectionWarning)
            model = FrameModel.learn(
                [trajectories[i] for i in keep],
                [frames[i] for i in keep],
                max_components=max_components,
            )
        t = trajectories[j][:, 0]
        mean, _ = model.reproduce(frames[j], t)
        last = t >= 2.0 / 3.0
        errors.append(np.linalg.norm(mean[last] - trajectories[j][last, 1:], axis=1).mean())
    return np.asarray(errors)


def test_frames_with_orientation_beat_translation_only_leaving_one_demonstration_out() -> None:
    """Leave one of 6 demonstrations out, predict it from the other 5 for its own frames, and
    measure the mean distance over the last third of the motion (phase >= 2/3: the approach
    and its end). The frame-aware model against the same model given translation-only frames
    (I, b). Targets turned by up to +-120 degrees (2.1 rad): seen from a translation-only
    target frame the approach comes from every direction, seen from the rotated one it comes
    from one.

    Measured: frame-aware 9.9 mm (6 to 17 mm per left-out demonstration, 3 mm of noise),
    translation-only 93 mm (49 to 131 mm): ratio 0.11; the issue's bar is 0.6. (With K up to
    30 instead of 8: 8.0 mm and 86 mm, ratio 0.09.)
    """
    trajectories, frames = reaching(np.random.default_rng(7), 6)
    start = time.perf_counter()
    aware = leave_one_out_errors(trajectories, frames, max_components=8)
    plain = leave_one_out_errors(
        trajectories, [translation_only(f) for f in frames], max_components=8
    )
    seconds = time.perf_counter() - start
    ratio = aware.mean() / plain.mean()
    print(
        f"leave-one-out error over the last third: frame-aware {aware.mean():.4f} m, "
        f"translation-only {plain.mean():.4f} m, ratio {ratio:.3f} ({seconds:.2f} s)"
    )
    assert ratio <= 0.6
    # The frame-aware model reaches each left-out target within the noise's order.
    assert aware.max() < 0.025


# ----------------------------------------------------------------------------- files
def test_save_load_round_trip(model: FrameModel, tmp_path: Path) -> None:
    path = tmp_path / "model.npz"
    model.save(path)
    loaded = FrameModel.load(path)
    assert repr(loaded) == repr(model)
    rng = np.random.default_rng(8)
    frames = [(rotation(rng, 2), rng.normal(size=2)) for _ in range(2)]
    t = np.linspace(0.0, 1.0, 30)
    for a, b in zip(model.reproduce(frames, t), loaded.reproduce(frames, t), strict=True):
        np.testing.assert_array_equal(a, b)


def test_load_refuses_foreign_and_inconsistent_files(model: FrameModel, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="not found"):
        FrameModel.load(tmp_path / "none.npz")
    text = tmp_path / "text.npz"
    text.write_text("not an archive")
    with pytest.raises(ValueError, match=r"text\.npz is not a NumPy \.npz archive"):
        FrameModel.load(text)
    path = tmp_path / "model.npz"
    model.save(path)
    with np.load(path) as stored:
        arrays = {k: stored[k] for k in stored.files}
    cases = {
        "skill": ({**arrays, "format": np.array("pbdkit-skill")}, "is not a pbdkit-frame-model"),
        "v2": ({**arrays, "version": np.array(2)}, "of version 2; this pbdkit reads version 1"),
        "unknown": ({**arrays, "extra": np.zeros(3)}, r"unknown key\(s\) 'extra'"),
        "missing": (
            {k: v for k, v in arrays.items() if k != "gmm_1_means"},
            "missing key 'gmm_1_means'",
        ),
        "beyond": (
            {**arrays, "n_frames": np.array(1)},
            "key 'gmm_1_weights' for a frame beyond n_frames = 1",
        ),
        "dims": ({**arrays, "n_dims": np.array(3)}, r"GMM dimensions \[3, 3\], expected 4"),
        "weights": (
            {**arrays, "gmm_0_weights": 2 * arrays["gmm_0_weights"]},
            "weights must sum to 1",
        ),
        "n_frames": ({**arrays, "n_frames": np.array(1.5)}, "n_frames must be an integer >= 1"),
    }
    for name, (content, match) in cases.items():
        np.savez(tmp_path / f"{name}.npz", **content)
        with pytest.raises(ValueError, match=match):
            FrameModel.load(tmp_path / f"{name}.npz")


# ----------------------------------------------------------------------------- bad input
def _with(frames: list[Frames], i: int, p: int, a: object = None, b: object = None) -> list:
    out: list = [list(f) for f in frames]
    old_a, old_b = out[i][p]
    out[i][p] = (old_a if a is None else a, old_b if b is None else b)
    return out


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda tr, fr: (tr[:1], fr[:1]), r"at least 2 demonstrations .*got 1"),
        (lambda tr, fr: (tr[0], fr), r"a single array of shape \(\d+, 3\)"),
        (lambda tr, fr: (5, fr), "must be a list of .* got int"),
        (lambda tr, fr: ([tr[0], tr[1][:, :2]], fr[:2]), r"trajectories\[1\] must have 3 columns"),
        (lambda tr, fr: ([tr[0][:, :1], tr[1]], fr[:2]), r"trajectories\[0\] must have shape"),
        (lambda tr, fr: ([tr[0], tr[1][:1]], fr[:2]), r"trajectories\[1\] must have at least 2"),
        (
            lambda tr, fr: ([tr[0], np.where(tr[1] > 0.9, np.nan, tr[1])], fr[:2]),
            r"trajectories\[1\] must be finite, got \d+ NaN",
        ),
        (lambda tr, fr: (tr, fr[:3]), r"one list of frames \(A, b\) per demonstration, 6, got 3"),
        (lambda tr, fr: (tr, "frames"), "frames must be a list, per demonstration"),
        (lambda tr, fr: (tr, [[], *fr[1:]]), r"frames\[0\] must hold at least one frame"),
        (
            lambda tr, fr: (tr, [fr[0], fr[1][:1], *fr[2:]]),
            r"frames\[1\] must hold 2 frames \(A, b\) as frames\[0\] does.*got 1",
        ),
        (
            lambda tr, fr: (tr, [fr[0], [*fr[1], fr[1][0]], *fr[2:]]),
            r"frames\[1\] must hold 2 frames .* got 3",
        ),
        (
            lambda tr, fr: (tr, _with(fr, 2, 1, a=np.eye(3))),
            r"frames\[2\]\[1\] A must have shape \(2, 2\), got \(3, 3\)",
        ),
        (
            lambda tr, fr: (tr, _with(fr, 2, 0, b=np.zeros(3))),
            r"frames\[2\]\[0\] b must have shape \(2,\), got \(3,\)",
        ),
        (
            lambda tr, fr: (tr, _with(fr, 3, 1, a=[[1.0, 2.0], [2.0, 4.0]])),
            # Singular: its condition number is rounding noise (2.5e+16 .. inf by the LAPACK).
            r"frames\[3\]\[1\] A must be invertible .*\(condition number "
            r"(\d(\.\d+)?e\+(1[5-9]|[2-9]\d)|inf)",
        ),
        (
            lambda tr, fr: (tr, _with(fr, 3, 1, a=[[1.0, 0.0], [0.0, 1e-14]])),
            r"frames\[3\]\[1\] A must be invertible .* \(condition number 1e\+14",
        ),
        (
            lambda tr, fr: (tr, _with(fr, 4, 0, b=[np.nan, 0.0])),
            r"frames\[4\]\[0\] b must be finite",
        ),
        (
            lambda tr, fr: (tr, _with(fr, 4, 0, a=[[np.inf, 0.0], [0.0, 1.0]])),
            r"frames\[4\]\[0\] A must be finite",
        ),
        (
            lambda tr, fr: (tr, [fr[0], [(*fr[1][0], 1.0), fr[1][1]], *fr[2:]]),
            r"frames\[1\]\[0\] must be a pair \(A, b\), .* got tuple of length 3",
        ),
    ],
)
def test_learn_refuses_bad_input(change: object, match: str) -> None:
    trajectories, frames = reaching(np.random.default_rng(9), 6)
    args = change(trajectories, frames)  # type: ignore[operator]
    with pytest.raises(ValueError, match=match):
        FrameModel.learn(*args, n_components=2)


def test_learn_names_the_frame_whose_gmm_fails(data: tuple[list[Float], list[Frames]]) -> None:
    trajectories, frames = data
    with pytest.raises(ValueError, match=r"frame 0: .*reg_covar must have shape \(3,\)"):
        FrameModel.learn(trajectories, frames, reg_covar=[1e-6, 1e-6])
    with pytest.raises(ValueError, match="fit_samples must be >= 2, got 1"):
        FrameModel.learn(trajectories, frames, fit_samples=1)


def test_reproduce_refuses_bad_input(model: FrameModel) -> None:
    frames = [(np.eye(2), np.zeros(2)), (np.eye(2), np.ones(2))]
    t = np.linspace(0.0, 1.0, 5)
    with pytest.raises(ValueError, match=r"frames must hold 2 frames \(A, b\), one per frame"):
        model.reproduce(frames[:1], t)
    with pytest.raises(ValueError, match=r"frames\[1\] A must be invertible"):
        model.reproduce([frames[0], (np.zeros((2, 2)), np.ones(2))], t)
    with pytest.raises(ValueError, match=r"frames\[0\] A must have shape \(2, 2\)"):
        model.reproduce([(np.eye(3), np.zeros(3)), frames[1]], t)
    with pytest.raises(ValueError, match="t must be finite"):
        model.reproduce(frames, [0.0, np.nan])
    with pytest.raises(ValueError, match="t must be 1-D"):
        model.reproduce(frames, t[:, None])
    with pytest.raises(ValueError, match="gmms must all have the same"):
        FrameModel(
            [model.gmms[0], GMM(n_components=1).fit(np.random.default_rng(0).random((9, 4)))]
        )
    with pytest.raises(ValueError, match=r"gmms\[0\] must be a fitted GMM"):
        FrameModel([GMM()])
