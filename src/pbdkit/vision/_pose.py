"""An object's pose from two patches: its position and its yaw about the vertical.

An object that turns on the table carries two colored patches, one at each end (end a and end
b, two colors). The stereo tracker locates each end as it locates any patch (a color model per
patch, the largest blob in each image, triangulation: :class:`pbdkit.vision.StereoTracker`);
the object's pose follows from the two points ``a`` and ``b`` (:class:`PoseModel`):

- yaw: the heading of ``b - a`` in the horizontal plane, ``atan2(dy, dx)``, plus the model's
  ``yaw_offset`` (what the object calls its yaw against the line through its patches);
- position: the midpoint ``(a + b) / 2`` plus the model's ``offset`` turned with the object,
  ``R(yaw) offset`` (``frame="object"``), or added as it is (``frame="world"``).

Why the offset turns with the object
------------------------------------
The cameras measure the centroid of what they see of a patch, which is not exactly where one
calls the object's point (the glass's band is seen by its front half, :mod:`pbdkit.sim._tracking`),
and the object's point need not be the patches' midpoint. For an object that only slides, that
bias is a constant vector in the world, measured once (:class:`StereoTracker`'s ``offsets``).
For an object that turns, the part of the bias that belongs to the object (a point off the line
of its patches, patches of unequal size or distance from the point, a patch seen partly hidden
by the object's own rim) turns with it: a world offset measured at one yaw is wrong by
``2 |offset| sin(delta / 2)`` at a yaw ``delta`` away (8.7 mm for a 10 mm offset turned 60
degrees). The offset is therefore kept in the object's frame. What depends on the cameras
rather than on the object (the visible side of a raised patch) does not turn; it is small for
flat patches seen from above (the slot task's marks: ``benchmarks/bench_pose_tracking.py``
measures both kinds of offset).

A pose is given only when both ends are: an end that the tracker refuses (hidden, clipped,
ambiguous, inconsistent) makes the object's status that end's (:class:`PoseTrack`); and when the
two ends are further apart or closer than the object allows (``span``, measured at the
calibration, within ``max_span_error``) the pose is ``"inconsistent"``: one of the blobs is not
that end.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, short
from ._track import Track, TrackStatus

__all__ = ["PoseModel", "PoseTrack", "ends_heading", "yaw_matrix"]

Float = NDArray[np.float64]

OffsetFrame = Literal["object", "world"]


def yaw_matrix(yaw: float) -> Float:
    """Rotation (3, 3) by ``yaw`` (rad) about the vertical (z)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ends_heading(a: npt.ArrayLike, b: npt.ArrayLike) -> tuple[Float, float]:
    """Midpoint (3,) of two end points and the heading (rad, in (-pi, pi]) of ``b - a`` in the
    horizontal plane."""
    pa = np.asarray(a, dtype=np.float64)
    pb = np.asarray(b, dtype=np.float64)
    d = pb - pa
    return 0.5 * (pa + pb), math.atan2(float(d[1]), float(d[0]))


def _wrap(angle: float) -> float:
    return math.remainder(angle, 2.0 * math.pi)


@dataclass(frozen=True, eq=False)
class PoseModel:
    """How a posed object's pose follows from the points of its two end patches.

    Attributes
    ----------
    ends : (str, str)
        The patches at end a and end b (names of the tracker's color models); the yaw points
        from a to b.
    offset : ndarray, shape (3,)
        From the ends' midpoint to the object's point (m): in the object's frame (x along its
        yaw, z up) with ``frame="object"``, in the world frame with ``frame="world"``.
    yaw_offset : float
        Added to the heading of ``b - a`` (rad).
    frame : {"object", "world"}
        The frame of ``offset`` (module docstring: "object" turns it with the object).
    span : float, optional
        Distance between the two ends' points (m) as calibrated; None: not checked.
    max_span_error : float
        Largest accepted difference between the measured distance and ``span`` (m); default
        4 mm: over 100 slot placements the ends' distance read within 2.4 mm of the calibrated
        one (sd 0.6-0.7 mm), and a mark the hand began to cover shortened it by 7.6 mm.
    """

    ends: tuple[str, str]
    offset: Float = field(default_factory=lambda: np.zeros(3))
    yaw_offset: float = 0.0
    frame: OffsetFrame = "object"
    span: float | None = None
    max_span_error: float = 0.004

    def __post_init__(self) -> None:
        ends = tuple(self.ends)
        if len(ends) != 2 or not all(isinstance(e, str) and e for e in ends) or ends[0] == ends[1]:
            raise ValueError(
                f"ends must be two different patch names (a, b), got {short(self.ends)}"
            )
        object.__setattr__(self, "ends", (str(ends[0]), str(ends[1])))
        object.__setattr__(self, "offset", check_array(self.offset, "offset", shape=(3,)))
        yaw = float(self.yaw_offset)
        if not math.isfinite(yaw):
            raise ValueError(f"yaw_offset must be finite (rad), got {short(self.yaw_offset)}")
        object.__setattr__(self, "yaw_offset", _wrap(yaw))
        if self.frame not in ("object", "world"):
            raise ValueError(f"frame must be 'object' or 'world', got {short(self.frame)}")
        if self.span is not None:
            span = float(self.span)
            if not (span > 0.0 and math.isfinite(span)):
                raise ValueError(f"span must be a distance > 0 (m) or None, got {short(self.span)}")
            object.__setattr__(self, "span", span)
        err = float(self.max_span_error)
        if not (err > 0.0 and math.isfinite(err)):
            raise ValueError(f"max_span_error must be > 0 (m), got {short(self.max_span_error)}")
        object.__setattr__(self, "max_span_error", err)

    @classmethod
    def calibrate(
        cls,
        ends: tuple[str, str],
        a: npt.ArrayLike,
        b: npt.ArrayLike,
        truth: npt.ArrayLike,
        *,
        frame: OffsetFrame = "object",
        max_span_error: float = 0.004,
    ) -> PoseModel:
        """The model that maps the measured end points ``a``, ``b`` onto the true pose(s).

        Parameters
        ----------
        ends : (str, str)
            The end patches' names.
        a, b : array-like, shape (3,) or (k, 3)
            Measured points of end a and end b (the triangulated centroids), in one view or in
            ``k`` views of the object (e.g. turned to several yaws).
        truth : array-like, shape (4, 4) or (k, 4, 4)
            The object's true pose in each view (a rotation about the vertical).
        frame : {"object", "world"}
            The frame in which the position offset is kept.
        max_span_error : float
            As the attribute.

        Returns
        -------
        PoseModel
            With ``yaw_offset`` the (circular) mean of ``yaw - heading(b - a)``, ``offset`` the
            mean offset from the midpoint to the true position (each turned back by its view's
            true yaw in the object's frame) and ``span`` the mean of ``|b - a|``: the views'
            noise averages out.
        """
        pa = np.atleast_2d(check_array(a, "a", ndim=(1, 2)))
        k = pa.shape[0]
        pa = check_array(pa, "a", shape=(k, 3))
        pb = check_array(np.atleast_2d(check_array(b, "b", ndim=(1, 2))), "b", shape=(k, 3))
        poses = check_array(truth, "truth", ndim=(2, 3))
        poses = check_array(poses.reshape((-1, *poses.shape[-2:])), "truth", shape=(None, 4, 4))
        if poses.shape[0] != k or k == 0:
            raise ValueError(
                f"a, b and truth must hold the same number of views (>= 1), got {k}, "
                f"{pb.shape[0]} and {poses.shape[0]}"
            )
        offsets, turns = [], []
        for pose, ea, eb in zip(poses, pa, pb, strict=True):
            mid, heading = ends_heading(ea, eb)
            yaw = math.atan2(float(pose[1, 0]), float(pose[0, 0]))
            offset = pose[:3, 3] - mid
            offsets.append(yaw_matrix(yaw).T @ offset if frame == "object" else offset)
            turns.append(_wrap(yaw - heading))
        yaw_offset = math.atan2(float(np.mean(np.sin(turns))), float(np.mean(np.cos(turns))))
        return cls(
            ends,
            np.mean(offsets, axis=0),
            yaw_offset,
            frame,
            float(np.mean(np.linalg.norm(pb - pa, axis=1))),
            max_span_error,
        )

    def pose(self, a: npt.ArrayLike, b: npt.ArrayLike) -> Float:
        """The object's pose (4, 4) from the points of end a and end b (module docstring)."""
        mid, heading = ends_heading(a, b)
        yaw = _wrap(heading + self.yaw_offset)
        rot = yaw_matrix(yaw)
        out = np.eye(4)
        out[:3, :3] = rot
        out[:3, 3] = mid + (rot @ self.offset if self.frame == "object" else self.offset)
        return out

    def track(self, name: str, end_a: Track, end_b: Track) -> PoseTrack:
        """The :class:`PoseTrack` of object ``name`` from its two ends' tracks."""
        for end in (end_a, end_b):
            if not end.ok or end.position is None:
                return PoseTrack(name, end.status, None, end_a, end_b, None)
        pa = np.asarray(end_a.position, dtype=np.float64)
        pb = np.asarray(end_b.position, dtype=np.float64)
        span = float(np.linalg.norm(pb - pa))
        if self.span is not None and not abs(span - self.span) <= self.max_span_error:
            return PoseTrack(name, "inconsistent", None, end_a, end_b, span)
        return PoseTrack(name, "ok", self.pose(pa, pb), end_a, end_b, span)

    def as_dict(self) -> dict[str, Any]:
        """Plain-data form (:meth:`from_dict` inverts it)."""
        return {
            "ends": list(self.ends),
            "offset": self.offset.tolist(),
            "yaw_offset": self.yaw_offset,
            "frame": self.frame,
            "span": self.span,
            "max_span_error": self.max_span_error,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PoseModel:
        """Inverse of :meth:`as_dict`; validates every field."""
        if not isinstance(data, dict) or "ends" not in data:
            raise ValueError(f"data must be a dict from PoseModel.as_dict, got {short(data)}")
        ends = data["ends"]
        if not isinstance(ends, (list, tuple)) or len(ends) != 2:
            raise ValueError(f"data['ends'] must be two patch names, got {short(ends)}")
        return cls(
            (str(ends[0]), str(ends[1])),
            np.asarray(data.get("offset", [0.0, 0.0, 0.0]), dtype=np.float64),
            float(data.get("yaw_offset", 0.0)),
            data.get("frame", "object"),
            data.get("span"),
            float(data.get("max_span_error", 0.004)),
        )


@dataclass(frozen=True)
class PoseTrack:
    """One posed object's result for one stereo frame: its pose, from its two ends' tracks.

    Attributes
    ----------
    name : str
        The object.
    status : str
        "ok"; the status of the first end that has no position (end a's, else end b's:
        ``not_visible_X``, ``clipped_X``, ...; :attr:`failed_end` says which); or
        "inconsistent" when both ends were located but their distance is not the object's
        (:attr:`PoseModel.span`), or one end's two views disagreed.
    pose : ndarray, shape (4, 4), or None
        The object's pose (a rotation about the vertical and its point); None unless "ok".
    end_a, end_b : Track
        The two end patches' tracks (their positions are the triangulated centroids).
    span : float or None
        Measured distance between the ends (m), when both were located.
    """

    name: str
    status: TrackStatus
    pose: Float | None
    end_a: Track
    end_b: Track
    span: float | None

    @property
    def ok(self) -> bool:
        """True when a pose is available."""
        return self.status == "ok"

    @property
    def position(self) -> Float | None:
        """The object's point (3,), or None."""
        return None if self.pose is None else self.pose[:3, 3].copy()

    @property
    def yaw(self) -> float | None:
        """The object's yaw (rad, in (-pi, pi]), or None."""
        if self.pose is None:
            return None
        return math.atan2(float(self.pose[1, 0]), float(self.pose[0, 0]))

    @property
    def ends(self) -> tuple[Track, Track]:
        """(end_a, end_b)."""
        return self.end_a, self.end_b

    @property
    def failed_end(self) -> str | None:
        """ "a" or "b": the end without a position (a first), or None."""
        if not self.end_a.ok:
            return "a"
        if not self.end_b.ok:
            return "b"
        return None

    @property
    def reprojection_error(self) -> float | None:
        """Largest reprojection error (pixels) of the two ends, when both were triangulated."""
        errs = [e.reprojection_error for e in (self.end_a, self.end_b)]
        return None if any(e is None for e in errs) else max(e for e in errs if e is not None)

    @property
    def area_a(self) -> int:
        """Pixels of the smaller end's blob in camera a."""
        return min(self.end_a.area_a, self.end_b.area_a)

    @property
    def area_b(self) -> int:
        """Pixels of the smaller end's blob in camera b."""
        return min(self.end_a.area_b, self.end_b.area_b)

    def describe(self) -> str:
        """One line for a refusal message: the status, which end, the blob areas."""
        end = self.failed_end
        patch = self.end_b.name if end == "b" else self.end_a.name
        which = "" if end is None else f" at end {end} ({patch})"
        span = "" if self.span is None else f", ends {1e3 * self.span:.1f} mm apart"
        areas = (
            f"blob areas a {self.end_a.area_a}, {self.end_a.area_b} px, "
            f"b {self.end_b.area_a}, {self.end_b.area_b} px"
        )
        return f"{self.status}{which} ({areas}{span})"
