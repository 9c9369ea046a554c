"""Stereo tracking of colored patches in the CbCr plane (paper Section III).

The paper's system: two 320x240 webcams at 15 Hz; each object carries a colored patch whose
color is a Gaussian over (Cb, Cr) fitted on a labelled calibration image (only chroma, for
robustness to brightness); pixels within a Mahalanobis threshold form blobs; the largest blob's
centroid in each image is triangulated. Measured error there: 5.9 +- 2.8 mm.

Pipeline and names
------------------
- :class:`ColorModel`: Gaussian over (Cb, Cr): ``fit(image, mask)``, ``mahalanobis2``, ``classify``.
- :func:`find_blob`: largest connected component of a mask, or a refusal (:class:`Blob`).
- :class:`PinholeCamera`: K, R, t (OpenCV axes); ``from_fovy`` for MuJoCo/OpenGL cameras.
- :func:`calibrate_camera`: pose (and intrinsics) from one view of a calibration object;
  :func:`calibrate_intrinsics`: intrinsics from several views of a planar target.
- :func:`triangulate`: two views -> world points (OpenCV DLT + Gauss-Newton refinement).
- :class:`StereoTracker`: two frames -> ``{name: Track}``, a status and a position or None.
- :class:`PoseModel`, :class:`PoseTrack`: an object that turns, located by two patches (its
  ends): its pose, position and yaw about the vertical (:mod:`pbdkit.vision._pose`;
  :meth:`StereoTracker.track_objects`).
- :class:`TrackFilter`: a stream of tracks while a skill runs -> the positions to trust (holds
  the last good one when the arm hides a patch or carries the object; refuses jumps).
- :mod:`pbdkit.vision._synthetic`: images of colored discs at known 3-D positions (for tests).

Beyond the paper, both measured to be needed: pixels near the neutral point of the CbCr plane
(gray, black, white) never match a color (``min_chroma``, see :class:`ColorModel`), and a blob is
refused rather than guessed when two patches share a color, a patch touches the image border, or
the two views disagree (the statuses of :class:`Track`).

With a simulator: ``PinholeCamera.from_fovy(fovy, 320, 240, cam_xpos, R_world_from_cam=cam_xmat)``
(MuJoCo's camera arrays as they are), and a labelled calibration image from a segmentation render.

Symbols: (u, v) pixel column and row (centre of the top-left pixel at (0, 0)); X world point (3,);
K intrinsics (3, 3); R, t world -> camera rotation (3, 3) and translation (3,): ``x_c = R X + t``;
P = K [R | t] projection matrix (3, 4); d^2 squared Mahalanobis distance in CbCr.

This package needs OpenCV (``opencv-python-headless``, the ``sim`` extra); the rest of pbdkit does
not import it.
"""

from __future__ import annotations

from ._blobs import find_blob
from ._camera import PinholeCamera, calibrate_camera
from ._color import ColorModel, cbcr_from_rgb
from ._filter import TrackFilter
from ._pose import PoseModel, PoseTrack
from ._stereo import StereoTracker, Track, triangulate

__all__ = [
    "ColorModel",
    "PinholeCamera",
    "PoseModel",
    "PoseTrack",
    "StereoTracker",
    "Track",
    "TrackFilter",
    "calibrate_camera",
    "cbcr_from_rgb",
    "find_blob",
    "triangulate",
]
