"""One object's result for one stereo frame (:class:`Track`) and why it may give no position
(:data:`TrackStatus`): what :class:`pbdkit.vision.StereoTracker` returns per patch, and
what a pose from two patches (:mod:`pbdkit.vision._pose`) is built from."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ._blobs import Blob

__all__ = ["Track", "TrackStatus"]

Float = NDArray[np.float64]

#: What the stereo pair found for an object: a position (``"ok"``), or why it gives none
#: (``_a`` / ``_b``: in the first / second view, ``_ab``: in both).
TrackStatus = Literal[
    "ok",
    "inconsistent",
    "not_visible_a",
    "not_visible_b",
    "not_visible_ab",
    "ambiguous_a",
    "ambiguous_b",
    "ambiguous_ab",
    "clipped_a",
    "clipped_b",
    "clipped_ab",
]


@dataclass(frozen=True)
class Track:
    """One object's result for one stereo frame.

    Attributes
    ----------
    name : str
        The object's name (key of the tracker's ``models``).
    status : str
        "ok"; "not_visible_X", "ambiguous_X" or "clipped_X" with X = a, b or ab the camera(s)
        where the blob was refused (see :mod:`pbdkit.vision._blobs`; when the cameras fail for
        different reasons, not_visible wins over ambiguous over clipped, and ``blob_a.status`` /
        ``blob_b.status`` tell each); "inconsistent" when both blobs were found but the
        triangulated point reprojects further than ``max_reprojection_error`` pixels from them
        (the two cameras did not see the same thing).

        A partially occluded patch is not refused: its blob's centroid is biased (measured on
        synthetic scenes: up to 25 mm when another patch hides half of it in one camera); the
        reprojection check catches it only when the bias crosses the epipolar lines.
    position : ndarray, shape (3,), or None
        World position of the patch centroid plus the tracker's offset for this object (zero by
        default); None unless status is "ok".
    reprojection_error : float or None
        Largest of the two cameras' reprojection errors (pixels), when both blobs were found.
    blob_a, blob_b : Blob
        Per-camera blob results (status, centroid (2,) or None, area, second_area, bbox).
    """

    name: str
    status: TrackStatus
    position: Float | None
    reprojection_error: float | None
    blob_a: Blob
    blob_b: Blob

    @property
    def ok(self) -> bool:
        """True when a position is available."""
        return self.status == "ok"

    @property
    def uv_a(self) -> Float | None:
        """Pixel centroid in camera a, shape (2,), or None."""
        return self.blob_a.centroid

    @property
    def uv_b(self) -> Float | None:
        """Pixel centroid in camera b, shape (2,), or None."""
        return self.blob_b.centroid

    @property
    def area_a(self) -> int:
        """Pixels of the largest blob in camera a."""
        return self.blob_a.area

    @property
    def area_b(self) -> int:
        """Pixels of the largest blob in camera b."""
        return self.blob_b.area
