"""Tests of pbdkit.vision: color model, blobs, cameras, calibration, triangulation, tracker.

Scenes are synthetic: a stereo pair of 320x240 pinhole cameras 0.4 m apart looking at a
table-top region 0.7-1.0 m away, and colored discs (patches) at known 3-D positions drawn into
both images over a textured, noisy background with random brightness changes.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from pbdkit.vision import (
    ColorModel,
    PinholeCamera,
    StereoTracker,
    calibrate_camera,
    cbcr_from_rgb,
    find_blob,
    triangulate,
)
from pbdkit.vision._camera import calibrate_intrinsics
from pbdkit.vision._color import DEFAULT_THRESHOLD, threshold_from_probability
from pbdkit.vision._stereo import reprojection_error
from pbdkit.vision._synthetic import Disc, random_discs, render_discs

Float = NDArray[np.float64]

COLORS = {"red": (190, 50, 50), "green": (50, 160, 60), "blue": (50, 70, 190)}
TARGET = np.array([0.0, 0.7, 0.03])
RADIUS = 0.02


def stereo_pair() -> tuple[PinholeCamera, PinholeCamera]:
    cam_a = PinholeCamera.from_fovy(45.0, 320, 240, (-0.2, 0.0, 0.5), look_at=TARGET)
    cam_b = PinholeCamera.from_fovy(45.0, 320, 240, (0.2, 0.0, 0.5), look_at=TARGET)
    return cam_a, cam_b


def random_scene(
    rng: np.random.Generator,
    cams: tuple[PinholeCamera, ...],
    colors: dict[str, tuple[int, int, int]],
) -> list[Disc]:
    """Discs with random positions and tilts, fully visible and apart in every camera."""
    return random_discs(rng, cams, colors, center=TARGET, radius=RADIUS)


def calibrated_models(
    rng: np.random.Generator, cam: PinholeCamera, n_frames: int = 4
) -> dict[str, ColorModel]:
    """Color models fitted on labelled frames under different brightness and illumination."""
    images, masks = [], []
    for _ in range(n_frames):
        discs = random_scene(rng, (cam,), COLORS)
        img, m = render_discs(cam, discs, rng, brightness=rng.uniform(-40.0, 40.0))
        images.append(img)
        masks.append(m)
    return {name: ColorModel.fit(images, [m[i] for m in masks]) for i, name in enumerate(COLORS)}


def dlt_triangulate(pa: Float, pb: Float, uv_a: Float, uv_b: Float) -> Float:
    """Independent linear triangulation: null vector of the 4x4 system (H&Z 12.2)."""
    out = []
    for (ua, va), (ub, vb) in zip(uv_a, uv_b, strict=True):
        a = np.stack(
            [ua * pa[2] - pa[0], va * pa[2] - pa[1], ub * pb[2] - pb[0], vb * pb[2] - pb[1]]
        )
        x = np.linalg.svd(a)[2][-1]
        out.append(x[:3] / x[3])
    return np.array(out)


def rotation_angle_deg(r1: Float, r2: Float) -> float:
    c = (np.trace(r1 @ r2.T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


# -- color model ------------------------------------------------------------------------------


def test_cbcr_is_bt601_full_range() -> None:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    r, g, b = (img[..., i].astype(np.float64) for i in range(3))
    cb = 128.0 - 0.168736 * r - 0.331264 * g + 0.5 * b
    cr = 128.0 + 0.5 * r - 0.418688 * g - 0.081312 * b
    got = cbcr_from_rgb(img)
    np.testing.assert_allclose(got[..., 0], cb, rtol=0, atol=1e-10)
    np.testing.assert_allclose(got[..., 1], cr, rtol=0, atol=1e-10)
    # OpenCV's 8-bit YCrCb (Y, Cr, Cb order) is the same transform, rounded
    ycc = cv2.cvtColor(img, cv2.COLOR_RGB2YCrCb).astype(np.float64)
    np.testing.assert_allclose(ycc[..., 2], cb, rtol=0, atol=1.0)
    np.testing.assert_allclose(ycc[..., 1], cr, rtol=0, atol=1.0)


def test_fit_equals_numpy_mean_and_covariance() -> None:
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (40, 50, 3), dtype=np.uint8)
    mask = rng.random((40, 50)) < 0.3
    model = ColorModel.fit(img, mask, min_std=2.0, min_chroma=0.0)
    px = img[mask].astype(np.float64)
    cbcr = np.column_stack(
        [
            128.0 - 0.168736 * px[:, 0] - 0.331264 * px[:, 1] + 0.5 * px[:, 2],
            128.0 + 0.5 * px[:, 0] - 0.418688 * px[:, 1] - 0.081312 * px[:, 2],
        ]
    )
    np.testing.assert_allclose(model.mean, cbcr.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(model.covariance, np.cov(cbcr.T, bias=True), rtol=1e-10)
    assert model.n_samples == int(mask.sum())
    np.testing.assert_allclose(model.precision @ model.covariance, np.eye(2), atol=1e-12)
    # the distance is the quadratic form with the inverse covariance
    d = cbcr_from_rgb(img) - model.mean
    want = np.einsum("hwi,ij,hwj->hw", d, np.linalg.inv(model.covariance), d)
    np.testing.assert_allclose(model.mahalanobis2(img), want, rtol=1e-10, atol=1e-10)


def test_achromatic_pixels_are_left_out_and_never_match() -> None:
    rng = np.random.default_rng(26)
    img = rng.integers(0, 256, (40, 50, 3), dtype=np.uint8)
    gray = rng.integers(0, 256, (40, 50), dtype=np.uint8)
    img[:20] = gray[:20, :, None]  # top half: gray levels, chroma exactly neutral
    mask = np.ones((40, 50), dtype=bool)
    model = ColorModel.fit(img, mask, min_chroma=10.0)
    c = cbcr_from_rgb(img)[mask]
    kept = c[np.hypot(c[:, 0] - 128, c[:, 1] - 128) >= 10.0]
    assert model.n_samples == kept.shape[0] < 40 * 50 // 2
    np.testing.assert_allclose(model.mean, kept.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(model.covariance, np.cov(kept.T, bias=True), rtol=1e-10)
    # a model whose Gaussian covers the neutral point still rejects gray pixels
    wide = ColorModel([125.0, 135.0], 400.0 * np.eye(2), min_chroma=10.0)
    assert wide.mahalanobis2(img)[:20].max() < DEFAULT_THRESHOLD
    assert not wide.classify(img)[:20].any()
    assert ColorModel([125.0, 135.0], 400.0 * np.eye(2), min_chroma=0.0).classify(img)[:20].all()
    cams = stereo_pair()
    tracker = StereoTracker(*cams, {"wide": wide})
    frame = cv2.resize(img, (320, 240), interpolation=cv2.INTER_NEAREST)
    np.testing.assert_array_equal(tracker.masks(frame)["wide"], wide.classify(frame))
    with pytest.raises(ValueError, match=r"all 1000 labelled pixels are achromatic"):
        ColorModel.fit(img, np.arange(40)[:, None].repeat(50, 1) < 20)


def test_covariance_floor_on_flat_patch() -> None:
    rng = np.random.default_rng(2)
    img = rng.integers(0, 256, (30, 30, 3), dtype=np.uint8)
    img[10:20, 5:15] = (200, 40, 60)
    mask = np.zeros((30, 30), dtype=bool)
    mask[10:20, 5:15] = True
    model = ColorModel.fit(img, mask, min_std=2.0)
    np.testing.assert_allclose(model.covariance, 4.0 * np.eye(2), atol=1e-12)
    d2 = model.mahalanobis2(img)
    assert np.all(np.isfinite(d2))
    np.testing.assert_allclose(d2[mask], 0.0, atol=1e-12)
    assert model.classify(img)[mask].all()


def test_covariance_floor_keeps_large_spread() -> None:
    rng = np.random.default_rng(3)
    # long along (1, 1), flat across: std 10 and 0.1
    t = rng.normal(0.0, 10.0, 500)
    s = rng.normal(0.0, 0.1, 500)
    samples = np.column_stack([100 + (t + s) / np.sqrt(2), 150 + (t - s) / np.sqrt(2)])
    model = ColorModel.from_samples(samples, min_std=3.0)
    w, v = np.linalg.eigh(model.covariance)
    raw_w, raw_v = np.linalg.eigh(np.cov(samples.T, bias=True))
    np.testing.assert_allclose(w[0], 9.0, rtol=1e-12)
    np.testing.assert_allclose(w[1], raw_w[1], rtol=1e-12)
    np.testing.assert_allclose(abs(v[:, 1] @ raw_v[:, 1]), 1.0, rtol=1e-12)


def test_default_threshold_is_chi2_99() -> None:
    from scipy.stats import chi2

    np.testing.assert_allclose(DEFAULT_THRESHOLD, chi2.ppf(0.99, 2), rtol=1e-12)
    np.testing.assert_allclose(threshold_from_probability(0.9), chi2.ppf(0.9, 2), rtol=1e-12)
    with pytest.raises(ValueError, match=r"probability must be in \(0, 1\)"):
        threshold_from_probability(1.0)


def test_color_model_dict_roundtrip_through_json() -> None:
    rng = np.random.default_rng(4)
    model = ColorModel.from_samples(rng.normal([100, 160], [5, 3], (50, 2)))
    back = ColorModel.from_dict(json.loads(json.dumps(model.as_dict())))
    np.testing.assert_array_equal(back.mean, model.mean)
    np.testing.assert_array_equal(back.covariance, model.covariance)
    assert back.n_samples == 50
    with pytest.raises(ValueError, match=r"missing \['covariance'\]"):
        ColorModel.from_dict({"mean": [1.0, 2.0]})


def test_color_model_errors() -> None:
    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
    mask = np.zeros((24, 32), dtype=bool)
    with pytest.raises(ValueError, match=r"mask must label at least one pixel.*empty mask"):
        ColorModel.fit(img, mask)
    with pytest.raises(
        ValueError, match=r"mask must have the image's shape .*\(24, 32\).*\(32, 24\)"
    ):
        ColorModel.fit(img, np.ones((32, 24), dtype=bool))
    with pytest.raises(ValueError, match="mask must have dtype bool, got uint8"):
        ColorModel.fit(img, np.ones((24, 32), dtype=np.uint8))
    with pytest.raises(ValueError, match=r"image must have dtype uint8.*got float64"):
        ColorModel.fit(img.astype(np.float64), mask | True)
    with pytest.raises(
        ValueError, match=r"image must have shape \(height, width, 3\), got \(24, 32\)"
    ):
        ColorModel.fit(img[..., 0], mask | True)
    with pytest.raises(ValueError, match=r"mask\[1\] must label at least one pixel"):
        ColorModel.fit([img, img], [mask | True, mask])
    with pytest.raises(ValueError, match=r"one mask per image \(2\), got 1"):
        ColorModel.fit([img, img], [mask | True])
    with pytest.raises(ValueError, match="covariance must be positive definite"):
        ColorModel([100.0, 100.0], [[1.0, 0.0], [0.0, 0.0]])
    with pytest.raises(ValueError, match="min_std must be finite and > 0"):
        ColorModel.fit(img, mask | True, min_std=0.0)


# -- blobs ------------------------------------------------------------------------------------


def test_blob_centroid_is_mean_of_pixel_coordinates() -> None:
    rng = np.random.default_rng(6)
    mask = np.zeros((240, 320), dtype=bool)
    mask[50:70, 100:131] = rng.random((20, 31)) < 0.9
    mask[50:70, 100] = True  # keep it one component
    mask[50, 100:131] = True
    mask[200:203, 10:13] = True  # a small second blob (9 px)
    blob = find_blob(mask, min_area=20)
    assert blob.status == "ok"
    lab = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)[1]
    v, u = np.nonzero(lab == lab[50, 100])
    assert blob.centroid is not None
    np.testing.assert_allclose(blob.centroid, np.array([u.mean(), v.mean()]), rtol=0, atol=1e-9)
    assert blob.area == u.size
    assert blob.second_area == 9


def test_blob_rules() -> None:
    mask = np.zeros((100, 100), dtype=bool)
    assert find_blob(mask).status == "not_visible"
    mask[10:14, 10:14] = True  # 16 px < min_area
    b = find_blob(mask, min_area=20)
    assert (b.status, b.area, b.centroid) == ("not_visible", 16, None)
    mask[40:50, 40:50] = True  # 100 px
    mask[70:78, 70:78] = True  # 64 px > 0.5 x 100: two patches of the same color
    b = find_blob(mask, min_area=20)
    assert (b.status, b.area, b.second_area, b.centroid) == ("ambiguous", 100, 64, None)
    assert find_blob(mask, min_area=20, ambiguity_ratio=0.7).status == "ok"
    mask[70:78, 70:78] = False
    mask[70:75, 70:75] = True  # 25 px < 0.5 x 100: ignored
    b = find_blob(mask, min_area=20)
    assert (b.status, b.second_area) == ("ok", 25)
    assert b.centroid is not None
    np.testing.assert_allclose(b.centroid, np.array([44.5, 44.5]), atol=1e-12)
    mask[:, :] = False
    mask[30:40, 0:10] = True  # touches the left border
    assert find_blob(mask).status == "clipped"
    with pytest.raises(ValueError, match=r"mask must be a 2-D numpy array"):
        find_blob(np.zeros((4, 4, 3), dtype=bool))


def test_synthetic_scene_errors() -> None:
    rng = np.random.default_rng(25)
    cams = stereo_pair()
    with pytest.raises(ValueError, match="no placement of 3 discs fits"):
        random_discs(rng, cams, COLORS, center=TARGET, radius=0.5, max_tries=5)
    with pytest.raises(ValueError, match="normal must be nonzero"):
        Disc(TARGET, (0.0, 0.0, 0.0), RADIUS, COLORS["red"]).boundary()


# -- cameras ----------------------------------------------------------------------------------


def test_project_matches_opencv() -> None:
    rng = np.random.default_rng(7)
    cam_a, _ = stereo_pair()
    pts = TARGET + rng.uniform(-0.2, 0.2, (50, 3))
    rvec = cv2.Rodrigues(cam_a.R)[0]
    want = cv2.projectPoints(pts, rvec, cam_a.t, cam_a.K, None)[0].reshape(-1, 2)
    np.testing.assert_allclose(cam_a.project(pts), want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(cam_a.center, [-0.2, 0.0, 0.5], atol=1e-12)
    behind = cam_a.center - (TARGET - cam_a.center)
    assert np.all(np.isnan(cam_a.project(behind[None])))


def test_from_fovy_axis_conventions() -> None:
    rng = np.random.default_rng(8)
    cam, _ = stereo_pair()
    cx, cy = (cam.width - 1) / 2, (cam.height - 1) / 2
    np.testing.assert_allclose(cam.project(TARGET[None])[0], [cx, cy], atol=1e-9)
    up = cam.project((TARGET + np.array([0.0, 0.0, 0.05]))[None])[0]
    right = cam.project((TARGET + np.array([0.05, 0.0, 0.0]))[None])[0]
    assert up[1] < cy  # world up is image up (v decreases)
    assert right[0] > cx  # world +x is to the right for a camera looking along +y
    # A MuJoCo camera with identity cam_xmat looks along world -z, y up: fovy maps to the rows
    pos = rng.normal(size=3)
    mj = PinholeCamera.from_fovy(60.0, 320, 240, pos, R_world_from_cam=np.eye(3))
    np.testing.assert_allclose(
        mj.project((pos + np.array([0.0, 0.0, -1.0]))[None])[0], [cx, cy], atol=1e-9
    )
    edge = pos + np.array(
        [0.0, np.tan(np.radians(30.0)), -1.0]
    )  # top of the vertical field of view
    np.testing.assert_allclose(mj.project(edge[None])[0], [cx, -0.5], atol=1e-9)
    right = pos + np.array([0.1, 0.0, -1.0])
    assert mj.project(right[None])[0, 0] > cx
    # the same pose given as a frame or as a look-at point
    r_gl = cam.R.T @ np.diag([1.0, -1.0, -1.0])
    same = PinholeCamera.from_fovy(45.0, 320, 240, cam.center, R_world_from_cam=r_gl)
    np.testing.assert_allclose(same.projection_matrix, cam.projection_matrix, atol=1e-12)
    with pytest.raises(ValueError, match="exactly one of R_world_from_cam and look_at"):
        PinholeCamera.from_fovy(45.0, 320, 240, pos)
    with pytest.raises(ValueError, match=r"fovy_deg must be in \(0, 180\)"):
        PinholeCamera.from_fovy(180.0, 320, 240, pos, look_at=TARGET)


def test_camera_validation_and_roundtrip() -> None:
    cam, _ = stereo_pair()
    back = PinholeCamera.from_dict(json.loads(json.dumps(cam.as_dict())))
    np.testing.assert_array_equal(back.projection_matrix, cam.projection_matrix)
    assert back.image_size == (320, 240)
    with pytest.raises(ValueError, match="R must be a rotation matrix"):
        PinholeCamera(cam.K, 2 * cam.R, cam.t, 320, 240)
    with pytest.raises(ValueError, match=r"K must be upper triangular"):
        PinholeCamera(cam.K.T, cam.R, cam.t, 320, 240)
    with pytest.raises(ValueError, match=r"t must have shape \(3,\), got \(2,\)"):
        PinholeCamera(cam.K, cam.R, cam.t[:2], 320, 240)
    with pytest.raises(ValueError, match="read-only"):
        cam.K[0, 0] = 1.0  # the projection matrix would go stale


def test_perturbed_pose_and_triangulation_sensitivity() -> None:
    rng = np.random.default_rng(9)
    cam_a, cam_b = stereo_pair()
    bad_b = cam_b.perturbed(translation=0.001, rotation_deg=0.1, rng=rng)
    np.testing.assert_allclose(np.linalg.norm(bad_b.center - cam_b.center), 0.001, rtol=1e-9)
    np.testing.assert_allclose(rotation_angle_deg(bad_b.R, cam_b.R), 0.1, rtol=1e-6)
    np.testing.assert_array_equal(bad_b.K, cam_b.K)
    pts = TARGET + rng.uniform([-0.15, -0.15, -0.03], [0.15, 0.15, 0.08], (200, 3))
    # images from the true cameras, triangulated with the perturbed calibration
    est = triangulate(cam_a, bad_b, cam_a.project(pts), cam_b.project(pts))
    err = np.linalg.norm(est - pts, axis=1)
    assert 1e-3 < err.mean() < 6e-3  # 1 mm / 0.1 degree of pose error: ~3 mm in 3-D
    # explicit vectors are applied as given
    moved = cam_b.perturbed(translation=[0.0, 0.0, 0.01], rotation_deg=[0.0, 0.0, 0.0])
    np.testing.assert_allclose(moved.center - cam_b.center, [0, 0, 0.01], atol=1e-12)


# -- calibration ------------------------------------------------------------------------------


def calibration_object() -> Float:
    """A two-plane calibration target: a 6x5 grid on the table and a 6x5 grid on a back wall."""
    gx, gy = np.meshgrid(np.linspace(-0.12, 0.12, 6), np.linspace(0.62, 0.82, 5))
    table = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    gx, gz = np.meshgrid(np.linspace(-0.12, 0.12, 6), np.linspace(0.03, 0.2, 5))
    wall = np.column_stack([gx.ravel(), np.full(gx.size, 0.85), gz.ravel()])
    return np.vstack([table, wall])


def test_calibrate_camera_without_K_recovers_K_R_t() -> None:
    rng = np.random.default_rng(10)
    for cam in stereo_pair():
        obj = calibration_object()
        uv = cam.project(obj) + rng.normal(0.0, 0.1, (obj.shape[0], 2))
        est = calibrate_camera(obj, uv, (320, 240))
        np.testing.assert_allclose(est.K[[0, 1], [0, 1]], cam.K[[0, 1], [0, 1]], rtol=0.01)
        np.testing.assert_allclose(est.K[:2, 2], cam.K[:2, 2], atol=3.0)
        # the rotation trades off against the principal point (1 px ~ 0.2 degree here)
        assert rotation_angle_deg(est.R, cam.R) < 0.5
        np.testing.assert_allclose(est.center, cam.center, atol=5e-3)
        assert reprojection_error(est, obj, uv).mean() < 0.2


def test_calibrate_camera_with_K_planar_target() -> None:
    rng = np.random.default_rng(11)
    cam, _ = stereo_pair()
    board = calibration_object()[:30]  # the table grid only: coplanar
    uv = cam.project(board) + rng.normal(0.0, 0.1, (30, 2))
    est = calibrate_camera(board, uv, (320, 240), K=cam.K)
    assert rotation_angle_deg(est.R, cam.R) < 0.1
    np.testing.assert_allclose(est.center, cam.center, atol=3e-3)


def test_calibrate_intrinsics_from_planar_views() -> None:
    rng = np.random.default_rng(12)
    cam, _ = stereo_pair()
    gx, gy = np.meshgrid(np.arange(9) * 0.04, np.arange(6) * 0.04)  # a 9x6 board, 4 cm
    board = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]) - [0.16, 0.1, 0.0]
    objs, imgs = [], []
    for _ in range(10):  # the board held in front of the camera at random poses
        r = cv2.Rodrigues(rng.normal(0.0, 0.35, 3))[0]
        t = np.array([0.0, 0.0, 0.6]) + rng.normal(0.0, 0.05, 3)
        view = PinholeCamera(cam.K, r, t, 320, 240)
        objs.append(board)
        imgs.append(view.project(board) + rng.normal(0.0, 0.1, (board.shape[0], 2)))
    k = calibrate_intrinsics(objs, imgs, (320, 240))
    np.testing.assert_allclose(k[[0, 1], [0, 1]], cam.K[[0, 1], [0, 1]], rtol=0.01)
    np.testing.assert_allclose(k[:2, 2], cam.K[:2, 2], atol=3.0)


def test_calibration_errors() -> None:
    cam, _ = stereo_pair()
    board = calibration_object()[:30]
    with pytest.raises(ValueError, match=r"coplanar.*calibrate_intrinsics"):
        calibrate_camera(board, cam.project(board), (320, 240))
    obj = calibration_object()[:5]
    with pytest.raises(ValueError, match=r"at least 6 points.*got 5"):
        calibrate_camera(obj, cam.project(obj), (320, 240))
    with pytest.raises(ValueError, match=r"image_points must have shape \(60, 2\), got \(59, 2\)"):
        calibrate_camera(calibration_object(), cam.project(calibration_object())[:59], (320, 240))
    with pytest.raises(ValueError, match=r"image_size must be \(width, height\)"):
        calibrate_camera(board, cam.project(board), 320)  # type: ignore[arg-type]


# -- triangulation ----------------------------------------------------------------------------


def test_triangulate_exact_and_against_independent_dlt() -> None:
    rng = np.random.default_rng(13)
    cam_a, cam_b = stereo_pair()
    pts = TARGET + rng.uniform(-0.15, 0.15, (40, 3))
    uv_a, uv_b = cam_a.project(pts), cam_b.project(pts)
    np.testing.assert_allclose(triangulate(cam_a, cam_b, uv_a, uv_b), pts, rtol=0, atol=1e-9)
    # with pixel noise: OpenCV's linear solution is the DLT, and refinement lowers the error
    na = uv_a + rng.normal(0.0, 0.5, uv_a.shape)
    nb = uv_b + rng.normal(0.0, 0.5, uv_b.shape)
    lin = triangulate(cam_a, cam_b, na, nb, refine=False)
    dlt = dlt_triangulate(cam_a.projection_matrix, cam_b.projection_matrix, na, nb)
    np.testing.assert_allclose(lin, dlt, rtol=0, atol=1e-9)
    ref = triangulate(cam_a, cam_b, na, nb)

    def cost(x: Float) -> Float:
        return reprojection_error(cam_a, x, na) ** 2 + reprojection_error(cam_b, x, nb) ** 2

    assert np.all(cost(ref) <= cost(lin) + 1e-9)
    np.testing.assert_allclose(ref, dlt, rtol=0, atol=1e-3)  # they differ by < 1 mm here
    # the refined point is the optimal two-view triangulation (Hartley-Sturm, H&Z Alg. 12.1):
    # OpenCV's correctMatches moves the observations onto the epipolar geometry, then DLT
    pa, pb = cam_a.projection_matrix, cam_b.projection_matrix
    e = pb @ np.append(cam_a.center, 1.0)  # epipole in image b
    ex = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
    fund = ex @ pb @ np.linalg.pinv(pa)
    ca, cb = cv2.correctMatches(fund, na[None], nb[None])
    optimal = dlt_triangulate(pa, pb, np.asarray(ca[0]), np.asarray(cb[0]))
    np.testing.assert_allclose(ref, optimal, rtol=0, atol=1e-8)
    with pytest.raises(ValueError, match=r"uv_b must have shape \(40, 2\), got \(39, 2\)"):
        triangulate(cam_a, cam_b, na, nb[:39])


# -- tracker ----------------------------------------------------------------------------------


def test_tracker_mask_equals_reference_classify() -> None:
    rng = np.random.default_rng(14)
    cam_a, cam_b = stereo_pair()
    models = calibrated_models(rng, cam_a)
    tracker = StereoTracker(cam_a, cam_b, models)
    img, _ = render_discs(cam_a, random_scene(rng, (cam_a,), COLORS), rng, brightness=20.0)
    fast = tracker.masks(img, "a")
    for name, model in models.items():
        d2 = model.mahalanobis2(img)
        differ = fast[name] != (d2 <= DEFAULT_THRESHOLD)
        # float32 vs float64: only pixels at the threshold may differ
        assert np.all(np.abs(d2[differ] - DEFAULT_THRESHOLD) < 1e-3)
        assert fast[name].sum() > 50


def test_tracker_recovers_3d_positions_within_mm() -> None:
    rng = np.random.default_rng(15)
    cams = stereo_pair()
    models = calibrated_models(rng, cams[0])
    tracker = StereoTracker(*cams, models)
    errors = []
    for _ in range(12):
        discs = random_scene(rng, cams, COLORS)
        img_a, _ = render_discs(cams[0], discs, rng, brightness=rng.uniform(-40.0, 40.0))
        img_b, _ = render_discs(cams[1], discs, rng, brightness=rng.uniform(-40.0, 40.0))
        tracks = tracker.track(img_a, img_b)
        assert list(tracks) == list(COLORS)
        for disc, (name, tr) in zip(discs, tracks.items(), strict=True):
            assert tr.status == "ok", (name, tr)
            assert tr.position is not None and tr.uv_a is not None and tr.uv_b is not None
            errors.append(np.linalg.norm(tr.position - np.asarray(disc.center)))
            assert tr.reprojection_error is not None and tr.reprojection_error < 0.5
            pa, pb = cams[0].projection_matrix, cams[1].projection_matrix
            dlt = dlt_triangulate(pa, pb, tr.uv_a[None], tr.uv_b[None])[0]
            np.testing.assert_allclose(tr.position, dlt, rtol=0, atol=2e-4)
    err = np.array(errors)
    assert err.max() < 3e-3
    assert err.mean() < 1.5e-3


def test_tracking_ignores_brightness_offsets() -> None:
    rng = np.random.default_rng(16)
    cams = stereo_pair()
    tracker = StereoTracker(*cams, calibrated_models(rng, cams[0]))
    discs = random_scene(rng, cams, COLORS)
    results = []
    for brightness in (-40.0, 0.0, 40.0):  # same noise, different luminosity
        imgs = [
            render_discs(c, discs, np.random.default_rng(99), brightness=brightness)[0]
            for c in cams
        ]
        results.append(tracker.track(*imgs))
    for name in COLORS:
        pos = [r[name].position for r in results]
        assert pos[0] is not None and pos[1] is not None and pos[2] is not None
        np.testing.assert_allclose(pos[0], pos[1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(pos[2], pos[1], rtol=0, atol=1e-12)


def test_object_not_visible_in_one_camera() -> None:
    rng = np.random.default_rng(17)
    cams = stereo_pair()
    tracker = StereoTracker(*cams, calibrated_models(rng, cams[0]))
    discs = random_scene(rng, cams, COLORS)
    img_a, _ = render_discs(cams[0], discs, rng)
    img_b, _ = render_discs(cams[1], discs[1:], rng)  # red hidden from camera b
    tracks = tracker.track(img_a, img_b)
    red = tracks["red"]
    assert red.status == "not_visible_b"
    assert red.position is None and red.reprojection_error is None
    assert red.blob_a.ok and red.area_b == 0
    assert tracks["green"].ok and tracks["blue"].ok
    img_a2, _ = render_discs(cams[0], discs[1:], rng)
    assert tracker.track(img_a2, img_b)["red"].status == "not_visible_ab"


def test_two_patches_of_the_same_color_are_ambiguous() -> None:
    rng = np.random.default_rng(18)
    cams = stereo_pair()
    tracker = StereoTracker(*cams, calibrated_models(rng, cams[0]))
    two_reds = {**COLORS, "red2": COLORS["red"]}
    discs = random_scene(rng, cams, two_reds)
    imgs = [render_discs(c, discs, rng)[0] for c in cams]
    red = tracker.track(*imgs)["red"]
    assert red.status == "ambiguous_ab"
    assert red.position is None
    assert red.blob_a.second_area > 0.5 * red.blob_a.area
    # a much smaller second red patch is ignored (its area is reported)
    small = [*discs[:3], Disc(discs[3].center, discs[3].normal, 0.4 * RADIUS, COLORS["red"])]
    imgs = [render_discs(c, small, rng)[0] for c in cams]
    red = tracker.track(*imgs)["red"]
    assert red.status == "ok"
    assert 20 <= red.blob_a.second_area < 0.5 * red.area_a
    assert red.position is not None
    np.testing.assert_allclose(red.position, np.asarray(discs[0].center), atol=3e-3)


def test_patch_at_image_border_is_clipped() -> None:
    rng = np.random.default_rng(19)
    cams = stereo_pair()
    tracker = StereoTracker(*cams, calibrated_models(rng, cams[0]))
    discs = random_scene(rng, cams, COLORS)
    # move red to where camera a sees it at the left edge (back-projection of pixel (2, 120))
    ray = np.linalg.solve(cams[0].K @ cams[0].R, [2.0, 120.0, 1.0])
    center = cams[0].center + ray / np.linalg.norm(ray) * 0.8
    discs[0] = Disc(center, cams[0].center - center, RADIUS, COLORS["red"])
    imgs = [render_discs(c, discs, rng)[0] for c in cams]
    red = tracker.track(*imgs)["red"]
    assert red.status == "clipped_a"
    assert red.blob_b.ok  # fully inside camera b's image
    assert red.position is None and red.uv_a is None
    assert red.blob_a.bbox[0] == 0


def test_views_of_different_objects_are_inconsistent() -> None:
    rng = np.random.default_rng(20)
    cams = stereo_pair()
    tracker = StereoTracker(*cams, calibrated_models(rng, cams[0]))
    discs = random_scene(rng, cams, COLORS)
    img_a, _ = render_discs(cams[0], discs, rng)
    moved = Disc(
        np.asarray(discs[0].center) + np.array([0.0, 0.0, 0.04]),
        discs[0].normal,
        RADIUS,
        COLORS["red"],
    )
    img_b, _ = render_discs(cams[1], [moved, *discs[1:]], rng)  # off the epipolar line
    red = tracker.track(img_a, img_b)["red"]
    assert red.status == "inconsistent"
    assert red.position is None
    assert red.reprojection_error is not None and red.reprojection_error > 3.0


def test_tracker_input_errors() -> None:
    rng = np.random.default_rng(21)
    cams = stereo_pair()
    tracker = StereoTracker(*cams, calibrated_models(rng, cams[0], n_frames=1))
    img = np.zeros((240, 320, 3), dtype=np.uint8)
    big = np.zeros((480, 640, 3), dtype=np.uint8)
    with pytest.raises(
        ValueError, match=r"image_b must have shape .*\(240, 320, 3\).*got \(480, 640, 3\)"
    ):
        tracker.track(img, big)
    with pytest.raises(
        ValueError, match=r"image_a must have shape .*\(240, 320, 3\).*got \(240, 320\)"
    ):
        tracker.track(img[..., 0], img)
    with pytest.raises(ValueError, match=r"image_a must have dtype uint8.*got float32"):
        tracker.track(img.astype(np.float32), img)
    with pytest.raises(ValueError, match="models must be a non-empty dict"):
        StereoTracker(*cams, {})
    with pytest.raises(ValueError, match=r"models\['red'\] must be a ColorModel"):
        StereoTracker(*cams, {"red": "not a model"})  # type: ignore[dict-item]
    with pytest.raises(ValueError, match="threshold must be finite and > 0"):
        StereoTracker(*cams, {"red": ColorModel([0, 0], np.eye(2))}, threshold=-1.0)
    tracks = tracker.track(img, img)  # nothing of any color: no position is made up
    assert all(t.status == "not_visible_ab" and t.position is None for t in tracks.values())


def test_end_to_end_with_calibrated_cameras() -> None:
    """Cameras calibrated from the calibration object (noisy corners), then tracking."""
    rng = np.random.default_rng(22)
    true = stereo_pair()
    obj = calibration_object()
    est_a, est_b = (
        calibrate_camera(obj, c.project(obj) + rng.normal(0.0, 0.1, (obj.shape[0], 2)), (320, 240))
        for c in true
    )
    tracker = StereoTracker(est_a, est_b, calibrated_models(rng, true[0]))
    errors = []
    for _ in range(6):
        discs = random_scene(rng, true, COLORS)
        imgs = [render_discs(c, discs, rng, brightness=rng.uniform(-40, 40))[0] for c in true]
        for disc, tr in zip(discs, tracker.track(*imgs).values(), strict=True):
            assert tr.position is not None, tr
            errors.append(np.linalg.norm(tr.position - np.asarray(disc.center)))
    assert np.max(errors) < 5e-3


def test_triangulation_behind_the_cameras_is_flagged_not_refined() -> None:
    rng = np.random.default_rng(23)
    cam_a, cam_b = stereo_pair()
    # rays that meet behind both cameras: a point behind projected without the sign check
    behind = 2 * cam_a.center - TARGET + rng.normal(0.0, 0.01, 3)
    uv = []
    for cam in (cam_a, cam_b):
        q = cam.projection_matrix @ np.append(behind, 1.0)
        assert q[2] < 0
        uv.append((q[:2] / q[2])[None])
    x = triangulate(cam_a, cam_b, uv[0], uv[1])  # no warning, no exception
    np.testing.assert_allclose(x[0], behind, atol=1e-6)
    assert np.isnan(reprojection_error(cam_a, x, uv[0])[0])


def test_from_fovy_matches_mujoco_renderer() -> None:
    """End to end with MuJoCo's own cameras: pose from cam_xpos/cam_xmat, fovy, rendered pixels."""
    import os

    os.environ.setdefault("MUJOCO_GL", "egl")
    mujoco = pytest.importorskip("mujoco")
    discs = {"red": (0.05, 0.65, 0.05, 60), "green": (-0.08, 0.78, 0.02, 30)}
    bodies = "".join(
        f'<body name="{n}" pos="{x} {y} {z}"><geom type="cylinder" size="0.02 0.0003" '
        f'rgba="{0.8 if n == "red" else 0.1} {0.7 if n == "green" else 0.1} 0.1 1" '
        f'euler="{tilt} 0 0"/></body>'
        for n, (x, y, z, tilt) in discs.items()
    )
    xml = f"""<mujoco><visual><quality shadowsize="0" offsamples="0"/>
      <global offwidth="320" offheight="240"/></visual><worldbody>
      <light pos="0 0.5 2" dir="0 0 -1" castshadow="false"/>
      <geom type="plane" size="1 1 0.1" rgba="0.6 0.6 0.6 1"/>{bodies}
      <body name="target" pos="0 0.7 0.03"/>
      <camera name="a" pos="-0.2 0 0.5" mode="targetbody" target="target" fovy="45"/>
      <camera name="b" pos="0.2 0 0.5" mode="targetbody" target="target" fovy="45"/>
      </worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    try:
        renderer = mujoco.Renderer(model, 240, 320)
    except Exception as exc:  # no OpenGL context on this machine
        pytest.skip(f"MuJoCo cannot render here: {exc}")
    cams, images, segs = [], [], []
    for name in ("a", "b"):
        i = model.camera(name).id
        cams.append(
            PinholeCamera.from_fovy(
                float(model.cam_fovy[i]),
                320,
                240,
                data.cam_xpos[i],
                R_world_from_cam=data.cam_xmat[i].reshape(3, 3),
            )
        )
        renderer.update_scene(data, camera=name)
        images.append(renderer.render().copy())
        renderer.enable_segmentation_rendering()
        renderer.update_scene(data, camera=name)
        segs.append(renderer.render()[..., 0].copy())
        renderer.disable_segmentation_rendering()
    renderer.close()
    models = {n: ColorModel.fit(images[0], segs[0] == model.body(n).geomadr[0]) for n in discs}
    tracks = StereoTracker(cams[0], cams[1], models).track(images[0], images[1])
    for name, tr in tracks.items():
        truth = data.xpos[model.body(name).id]
        assert tr.status == "ok" and tr.position is not None and tr.uv_a is not None
        assert tr.reprojection_error is not None and tr.reprojection_error < 0.3
        np.testing.assert_allclose(tr.uv_a, cams[0].project(truth[None])[0], atol=0.5)
        np.testing.assert_allclose(tr.position, truth, atol=3e-3)


def test_tracker_dict_roundtrip_through_json() -> None:
    rng = np.random.default_rng(24)
    cams = stereo_pair()
    tracker = StereoTracker(*cams, calibrated_models(rng, cams[0], n_frames=1), min_area=15)
    back = StereoTracker.from_dict(json.loads(json.dumps(tracker.as_dict())))
    assert back.min_area == 15 and list(back.models) == list(COLORS)
    discs = random_scene(rng, cams, COLORS)
    imgs = [render_discs(c, discs, rng)[0] for c in cams]
    for a, b in zip(tracker.track(*imgs).values(), back.track(*imgs).values(), strict=True):
        assert a.status == b.status == "ok"
        assert a.position is not None and b.position is not None
        np.testing.assert_array_equal(a.position, b.position)
    with pytest.raises(ValueError, match=r"missing keys \['models'\]"):
        StereoTracker.from_dict({"cam_a": {}, "cam_b": {}})


def test_constructors_do_not_freeze_the_callers_arrays() -> None:
    cam, _ = stereo_pair()
    k, r, t = cam.K.copy(), cam.R.copy(), cam.t.copy()
    PinholeCamera(k, r, t, 320, 240)
    mean, cov = np.array([100.0, 150.0]), 4.0 * np.eye(2)
    ColorModel(mean, cov)
    for arr in (k, r, t, mean, cov):
        assert arr.flags.writeable


def test_offsets_move_reported_positions() -> None:
    rng = np.random.default_rng(27)
    cams = stereo_pair()
    models = calibrated_models(rng, cams[0], n_frames=1)
    discs = random_scene(rng, cams, COLORS)
    imgs = [render_discs(c, discs, rng)[0] for c in cams]
    plain = StereoTracker(*cams, models).track(*imgs)
    shifted = StereoTracker(*cams, models, offsets={"green": [0.0, 0.0, -0.012]}).track(*imgs)
    for name in COLORS:
        p, q = plain[name].position, shifted[name].position
        assert p is not None and q is not None
        want = [0.0, 0.0, -0.012] if name == "green" else [0.0, 0.0, 0.0]
        np.testing.assert_allclose(q - p, want, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match=r"offsets has names \['cyan'\] that are not in models"):
        StereoTracker(*cams, models, offsets={"cyan": [0.0, 0.0, 0.0]})
    with pytest.raises(ValueError, match=r"offsets\['red'\] must have shape \(3,\), got \(2,\)"):
        StereoTracker(*cams, models, offsets={"red": [0.0, 0.0]})


def test_vision_does_not_import_the_simulator_or_plotting() -> None:
    import subprocess
    import sys

    code = (
        "import sys, pbdkit.vision; "
        "print([m for m in ('mujoco', 'matplotlib') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
