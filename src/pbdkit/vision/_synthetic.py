"""Synthetic camera images of colored discs, to test and benchmark tracking without a simulator.

A disc (a flat circular patch of radius r, centre c, unit normal n) is drawn by projecting 128
points of its boundary and filling the polygon (``cv2.fillPoly`` with sub-pixel vertices), far
discs first, over a smooth low-saturation textured background. Brightness offsets, an
illumination gain field and per-pixel noise are applied to the whole image.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_positive_float
from ._camera import PinholeCamera

__all__ = ["Disc", "random_discs", "render_discs"]

Float = NDArray[np.float64]


@dataclass(frozen=True)
class Disc:
    """A flat colored disc.

    Attributes
    ----------
    center : array-like, shape (3,)
        Centre in world coordinates (metres): the position a tracker should report.
    normal : array-like, shape (3,)
        Normal of the disc's plane (any length but zero).
    radius : float
        Metres.
    rgb : tuple of 3 int
        Color, 0..255.
    """

    center: npt.ArrayLike
    normal: npt.ArrayLike
    radius: float
    rgb: tuple[int, int, int]

    def boundary(self, n_points: int = 128) -> Float:
        """Points on the rim, shape (n_points, 3)."""
        c = check_array(self.center, "center", shape=(3,))
        n = check_array(self.normal, "normal", shape=(3,))
        norm = np.linalg.norm(n)
        if norm == 0:
            raise ValueError("normal must be nonzero")
        n = n / norm
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(n, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        a = np.linspace(0.0, 2.0 * np.pi, n_points, endpoint=False)
        r = check_positive_float(self.radius, "radius")
        return np.asarray(c + r * (np.outer(np.cos(a), e1) + np.outer(np.sin(a), e2)))


def render_discs(
    camera: PinholeCamera,
    discs: list[Disc],
    rng: np.random.Generator,
    *,
    brightness: float = 0.0,
    gain_amplitude: float = 0.05,
    noise_std: float = 2.0,
    background_seed: int = 0,
) -> tuple[NDArray[np.uint8], list[NDArray[np.bool_]]]:
    """Image of discs seen by a camera, and the mask of each disc's visible pixels.

    Parameters
    ----------
    camera : PinholeCamera
        Image size and projection.
    discs : list of Disc
        Drawn far to near (painter's algorithm); discs behind the camera are skipped.
    rng : numpy Generator
        Pixel noise and the illumination field.
    brightness : float
        Offset added to R, G and B (a change of luminosity; CbCr does not see it).
    gain_amplitude : float
        Smooth multiplicative illumination field in [1 - a, 1 + a] (CbCr does see it, a little).
    noise_std : float
        Per-pixel, per-channel Gaussian noise (8-bit units).
    background_seed : int
        Seed of the background texture, fixed per scene so frames differ only by lighting/noise.

    Returns
    -------
    image : ndarray of uint8, shape (height, width, 3)
        RGB.
    masks : list of ndarray of bool, shape (height, width)
        Visible pixels of each disc, in the order of ``discs``.
    """
    w, h = camera.width, camera.height
    bg_rng = np.random.default_rng(background_seed)
    luma = cv2.resize(bg_rng.uniform(70.0, 170.0, (6, 8)), (w, h), interpolation=cv2.INTER_CUBIC)
    tint = cv2.resize(bg_rng.normal(0.0, 5.0, (6, 8, 3)), (w, h), interpolation=cv2.INTER_CUBIC)
    fine = bg_rng.normal(0.0, 8.0, (h, w, 1))  # gray texture
    img = luma[..., None] + tint + fine
    depth = [float(camera.depth(np.asarray(d.center, dtype=np.float64)[None])[0]) for d in discs]
    label = np.full((h, w), -1, dtype=np.int32)
    for i in sorted(range(len(discs)), key=lambda k: -depth[k]):
        if depth[i] <= 0:
            continue
        uv = camera.project(discs[i].boundary())
        if not np.all(np.isfinite(uv)):
            continue
        poly = np.round(uv * 16.0).astype(np.int32)
        cv2.fillPoly(label, [poly], i, lineType=cv2.LINE_8, shift=4)
    for i, d in enumerate(discs):
        img[label == i] = np.asarray(d.rgb, dtype=np.float64)
    field = cv2.resize(rng.uniform(-1.0, 1.0, (3, 4)), (w, h), interpolation=cv2.INTER_CUBIC)
    img = img * (1.0 + gain_amplitude * np.clip(field, -1.0, 1.0))[..., None]
    img += brightness + rng.normal(0.0, noise_std, img.shape)
    image = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return image, [label == i for i in range(len(discs))]


def random_discs(
    rng: np.random.Generator,
    cameras: Sequence[PinholeCamera],
    colors: Mapping[str, tuple[int, int, int]],
    *,
    center: npt.ArrayLike = (0.0, 0.7, 0.03),
    low: npt.ArrayLike = (-0.15, -0.15, -0.03),
    high: npt.ArrayLike = (0.15, 0.15, 0.08),
    radius: float = 0.02,
    tilt_std: float = 0.3,
    margin_px: float = 3.0,
    max_tries: int = 1000,
) -> list[Disc]:
    """One disc per color at random positions, fully visible and apart in every camera's image.

    Parameters
    ----------
    rng : numpy Generator
        Positions and tilts.
    cameras : sequence of PinholeCamera
        Every disc must be inside each image and not overlap another disc there (occlusion
        biases a blob's centroid, which a tracker cannot detect; tested scenes avoid it).
    colors : mapping of str to (R, G, B)
        One disc per entry, in order.
    center : array-like, shape (3,)
        Centre of the region where disc centres are drawn uniformly, between
        ``center + low`` and ``center + high``.
    low, high : array-like, shape (3,)
        Bounds of the region relative to ``center`` (metres).
    radius : float
        Disc radius (metres).
    tilt_std : float
        Normals point at the cameras' mean centre plus Gaussian noise of this std.
    margin_px : float
        Minimum gap in pixels to the image border and between discs.
    max_tries : int
        Draws before giving up.

    Returns
    -------
    discs : list of Disc
        In the order of ``colors``.
    """
    c0 = check_array(center, "center", shape=(3,))
    lo = check_array(low, "low", shape=(3,))
    hi = check_array(high, "high", shape=(3,))
    eye = np.mean([cam.center for cam in cameras], axis=0)
    for _ in range(max_tries):
        discs = []
        for rgb in colors.values():
            c = c0 + rng.uniform(lo, hi)
            n = (eye - c) / np.linalg.norm(eye - c) + rng.normal(0.0, tilt_std, 3)
            discs.append(Disc(c, n, radius, rgb))
        if all(_apart_and_inside(cam, discs, margin_px) for cam in cameras):
            return discs
    raise ValueError(
        f"no placement of {len(colors)} discs fits in every image after {max_tries} tries; "
        "widen the region, shrink the radius or use fewer colors"
    )


def _apart_and_inside(cam: PinholeCamera, discs: list[Disc], margin: float) -> bool:
    fp = []
    for d in discs:
        uv = cam.project(d.boundary(32))
        if not np.all(np.isfinite(uv)):
            return False
        c = uv.mean(axis=0)
        fp.append((c, float(np.linalg.norm(uv - c, axis=1).max()) + margin))
    for i, (c, r) in enumerate(fp):
        if not (r < c[0] < cam.width - 1 - r and r < c[1] < cam.height - 1 - r):
            return False
        if any(np.linalg.norm(c - c2) <= r + r2 for c2, r2 in fp[i + 1 :]):
            return False
    return True
