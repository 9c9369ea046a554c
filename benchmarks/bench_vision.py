"""Vision tracker: time of one stereo tracking cycle, and accuracy on synthetic scenes.

One cycle = two 320x240 RGB frames -> CbCr -> Mahalanobis mask per object -> largest blob ->
triangulation of every object seen in both images. Three objects. Renders are NOT included
(the simulator's cameras are timed separately).

Peer, measured in the same run: a straightforward implementation with the same steps
(cv2.cvtColor to YCrCb, per-pixel Mahalanobis in numpy with the covariance inverted at each call,
scipy.ndimage.label for the blobs, cv2.triangulatePoints), and the paper's 15 Hz frame budget.

Run: .venv/bin/python benchmarks/bench_vision.py [--repeats N] [--frames N]
"""

from __future__ import annotations

import argparse
import platform
from collections.abc import Sequence

import cv2
import numpy as np
import scipy.ndimage as ndi
from _common import fmt_time, median_time, print_table
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from pbdkit.vision import ColorModel, PinholeCamera, StereoTracker, calibrate_camera, triangulate
from pbdkit.vision._synthetic import random_discs, render_discs

COLORS = {"red": (190, 50, 50), "green": (50, 160, 60), "blue": (50, 70, 190)}
TARGET = np.array([0.0, 0.7, 0.03])


def naive_track(
    cams: tuple[PinholeCamera, PinholeCamera],
    models: dict[str, ColorModel],
    images: Sequence[NDArray[np.uint8]],
    min_area: int = 20,
) -> dict[str, NDArray[np.float64] | None]:
    """The peer: same pipeline, written the obvious way."""
    centroids: list[dict[str, NDArray[np.float64] | None]] = []
    for img in images:
        ycc = cv2.cvtColor(img, cv2.COLOR_RGB2YCrCb).astype(np.float64)
        cbcr = ycc[..., [2, 1]]
        found: dict[str, NDArray[np.float64] | None] = {}
        for name, m in models.items():
            d = cbcr - m.mean
            d2 = np.einsum("hwi,ij,hwj->hw", d, np.linalg.inv(m.covariance), d)
            labels, n = ndi.label(d2 <= 9.21, structure=np.ones((3, 3)))
            if n == 0:
                found[name] = None
                continue
            areas = np.bincount(labels.ravel())[1:]
            best = int(np.argmax(areas)) + 1
            if areas[best - 1] < min_area:
                found[name] = None
                continue
            v, u = np.nonzero(labels == best)
            found[name] = np.array([u.mean(), v.mean()])
        centroids.append(found)
    out: dict[str, NDArray[np.float64] | None] = {}
    for name in models:
        a, b = centroids[0][name], centroids[1][name]
        if a is None or b is None:
            out[name] = None
            continue
        xh = cv2.triangulatePoints(
            cams[0].projection_matrix, cams[1].projection_matrix, a[:, None], b[:, None]
        )
        out[name] = (xh[:3, 0] / xh[3, 0]).astype(np.float64)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=200, help="timed runs per row")
    parser.add_argument("--frames", type=int, default=100, help="synthetic frames for accuracy")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    cam_a = PinholeCamera.from_fovy(45.0, 320, 240, (-0.2, 0.0, 0.5), look_at=TARGET)
    cam_b = PinholeCamera.from_fovy(45.0, 320, 240, (0.2, 0.0, 0.5), look_at=TARGET)
    cams = (cam_a, cam_b)

    # color calibration: four labelled frames of camera a under different brightness
    cal = [
        render_discs(
            cam_a,
            random_discs(rng, (cam_a,), COLORS, center=TARGET),
            rng,
            brightness=rng.uniform(-40, 40),
        )
        for _ in range(4)
    ]
    models = {
        name: ColorModel.fit([c[0] for c in cal], [c[1][i] for c in cal])
        for i, name in enumerate(COLORS)
    }
    tracker = StereoTracker(cam_a, cam_b, models)

    # accuracy over random scenes (no mutual occlusion), and with a 1 mm / 0.1 deg pose error
    bad_b = cam_b.perturbed(translation=0.001, rotation_deg=0.1, rng=rng)
    tracker_bad = StereoTracker(cam_a, bad_b, models)
    # both cameras calibrated (K, R, t by DLT + refinement) from a two-plane calibration object
    # whose 60 corners are located with 0.1 px noise
    gx, gy = np.meshgrid(np.linspace(-0.12, 0.12, 6), np.linspace(0.62, 0.82, 5))
    gx2, gz = np.meshgrid(np.linspace(-0.12, 0.12, 6), np.linspace(0.03, 0.2, 5))
    target = np.vstack(
        [
            np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]),
            np.column_stack([gx2.ravel(), np.full(gx2.size, 0.85), gz.ravel()]),
        ]
    )
    est_a, est_b = (
        calibrate_camera(target, c.project(target) + rng.normal(0.0, 0.1, (60, 2)), (320, 240))
        for c in cams
    )
    tracker_cal = StereoTracker(est_a, est_b, models)
    err_cal: list[float] = []
    err: list[float] = []
    err_naive: list[float] = []
    err_bad: list[float] = []
    failures = 0
    frames = []
    for _ in range(args.frames):
        discs = random_discs(rng, cams, COLORS, center=TARGET)
        imgs = tuple(render_discs(c, discs, rng, brightness=rng.uniform(-40, 40))[0] for c in cams)
        frames.append(imgs)
        tracks = tracker.track(*imgs)
        naive = naive_track(cams, models, imgs)
        bad = tracker_bad.track(*imgs)
        by_cal = tracker_cal.track(*imgs)
        for d, name in zip(discs, COLORS, strict=True):
            truth = np.asarray(d.center)
            p, q, r, c = (
                tracks[name].position,
                naive[name],
                bad[name].position,
                by_cal[name].position,
            )
            if p is None or q is None or r is None or c is None:
                failures += 1
                continue
            err.append(float(np.linalg.norm(p - truth)))
            err_naive.append(float(np.linalg.norm(q - truth)))
            err_bad.append(float(np.linalg.norm(r - truth)))
            err_cal.append(float(np.linalg.norm(c - truth)))

    img_a, img_b = frames[0]
    uv_a = np.array([tracker.track(img_a, img_b)[n].uv_a for n in COLORS], dtype=np.float64)
    uv_b = np.array([tracker.track(img_a, img_b)[n].uv_b for n in COLORS], dtype=np.float64)

    n = args.repeats
    cases = [
        ("pbdkit StereoTracker.track", lambda: tracker.track(img_a, img_b)),
        ("  of which masks + blobs, 1 image", lambda: tracker.blobs(img_a, "a")),
        ("  of which triangulate 3 points", lambda: triangulate(cam_a, cam_b, uv_a, uv_b)),
    ]
    n_cv = cv2.getNumThreads()
    with threadpool_limits(limits=1):
        timed = [(name, median_time(fn, repeat=n)) for name, fn in cases]
        cv2.setNumThreads(1)
        timed.append(("pbdkit, OpenCV 1 thread", median_time(cases[0][1], repeat=n)))
        cv2.setNumThreads(n_cv)
        peer = median_time(lambda: naive_track(cams, models, frames[0]), repeat=max(20, n // 5))
    ours = timed[0][1]
    budget = 1.0 / 15.0

    print(
        f"Vision tracker: two 320x240 frames, 3 objects, median of {n} runs; BLAS 1 thread, "
        f"OpenCV {cv2.__version__} with {n_cv} threads unless stated; {platform.machine()}"
    )
    rows = [[name, fmt_time(t), "" if name[0] == " " else f"{t / ours:.2f}x"] for name, t in timed]
    rows.append(["peer: naive pipeline", fmt_time(peer), f"{peer / ours:.1f}x"])
    rows.append(["budget: 1 frame at 15 Hz (paper)", fmt_time(budget), f"{budget / ours:.0f}x"])
    print_table(["operation", "time", "time / pbdkit"], rows)
    print(
        f"pbdkit uses {ours / budget * 100:.1f}% of the 15 Hz frame; renders not included "
        "(cycle target: 2 renders + tracking + triangulation <= 15 ms)."
    )
    print()
    print(
        f"Accuracy: {len(err)} object positions in {args.frames} random synthetic frames "
        f"(brightness +-40, 5% illumination field, pixel noise 2); {failures} not ok"
    )

    def stats(name: str, x: list[float]) -> list[str]:
        mm = 1e3 * np.array(x)
        return [name, f"{mm.mean():.2f} +- {mm.std():.2f} mm", f"{mm.max():.2f} mm"]

    print_table(
        ["tracker", "3-D error mean +- std", "max"],
        [
            stats("pbdkit, true calibration", err),
            stats("peer, true calibration", err_naive),
            stats("pbdkit, camera b off 1 mm + 0.1 deg", err_bad),
            stats("pbdkit, both calibrated (DLT, 0.1 px)", err_cal),
            ["paper (real webcams)", "5.9 +- 2.8 mm", ""],
        ],
    )


if __name__ == "__main__":
    main()
