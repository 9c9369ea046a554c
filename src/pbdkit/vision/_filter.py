"""A stream of stereo tracks -> the object positions a running controller may trust.

While a skill runs, the cameras keep tracking (15 Hz), and the arm gets in their way: it hides
part of a patch (the centroid of what is left is biased, by up to 25-32 mm), all of it (no
blob), or carries the glass itself. :class:`TrackFilter` holds, per object, the last good
estimate and refuses a frame's position when:

- the tracker gave none (its status: ``not_visible_a``, ``clipped_b``, ``inconsistent``, ...);
- ``"occluded"``: the patch's blob in either camera has shrunk below ``min_area_ratio`` of its
  area when the object was first seen (a partly hidden patch). Given the cameras' centres,
  areas are first scaled by the squared distance from the camera, so that an object that
  slides away is not mistaken for a hidden one (measured on the coaster sliding 5 cm: raw
  area +14 %, scaled +4 %; the glass lowered onto it: scaled 0.98, 0.74, 0.43 of the first
  area with position errors 1.4, 10 and 12 mm, hence the default 0.9);
- ``"jump"``: the position moved farther from the last good estimate than an object can move
  in the time since (``max_speed`` times the elapsed time, plus ``tolerance`` for the tracker's
  noise);
- ``"held"``: the caller says the object is in the gripper (its position is then the arm's,
  not the world's: a controller fed the carried glass's position would chase its own hand).

An object that turns is tracked by its two end patches (:class:`pbdkit.vision.PoseTrack`): its
estimate is its pose (4, 4), refused as a whole when either end is (not located, or its blob
shrunk: ``"occluded"``, each end's area compared with its own first one), when its point jumps
as above, or when its yaw turned faster than ``max_turn_rate`` allows (``"jump"`` too). A turn
changes a flat mark's blob a little: the slot task's marks turned -60..60 degrees in place read
0.91-1.08 of their area at 0 degrees, and a tray turned by 28 degrees (``--perturb rotate``)
stayed above 0.95 of its first areas, inside the default 0.9. A mark the hand begins to cover
reads 0.82 of its first area with its centroid already 5 mm off (measured): a lower ratio
would let that pose through.

Refused frames keep the last good estimate; every change of an object's status is logged as a
:class:`TrackEvent`, and frames are counted per reason (:meth:`TrackFilter.as_dict`).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_positive_float, short
from ._pose import PoseTrack
from ._stereo import ObjectTrack

__all__ = ["TrackEvent", "TrackFilter"]

Float = NDArray[np.float64]


@dataclass(frozen=True)
class TrackEvent:
    """A change of an object's status in a :class:`TrackFilter`.

    Attributes
    ----------
    time : float
        Seconds (the caller's clock).
    name : str
        The object.
    status : str
        The new status: "ok", "held", "occluded", "jump" or a tracker status.
    detail : str
        Human-readable: the distance of a jump, the areas of an occluded patch, ...
    """

    time: float
    name: str
    status: str
    detail: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {"time": self.time, "name": self.name, "status": self.status, "detail": self.detail}


class TrackFilter:
    """Hold the last good position of each tracked object (module docstring).

    Parameters
    ----------
    names : sequence of str
        The objects to follow.
    max_speed : float
        Fastest plausible object motion (m/s); default 0.25.
    tolerance : float
        Metres added to the plausible displacement (tracker noise); default 5 mm.
    min_area_ratio : float
        A blob smaller than this fraction of the object's first-seen area (in either camera) is
        a partly hidden patch; default 0.9.
    cameras : (array-like (3,), array-like (3,)), optional
        World positions of the centres of cameras a and b (:attr:`PinholeCamera.center`):
        areas are then compared after scaling by the squared distance to the camera.
    max_turn_rate : float
        Fastest plausible turn of a posed object about the vertical (rad/s); default 3.
    yaw_tolerance : float
        Radians added to the plausible turn (tracker noise); default 0.05 (2.9 degrees).

    Attributes
    ----------
    estimates : dict str -> ndarray, shape (3,) or (4, 4)
        The last good position of each object seen at least once (its pose for an object
        tracked by a :class:`pbdkit.vision.PoseTrack`).
    status : dict str -> str
        Each object's status at the last update ("unseen" before its first good frame).
    events : list of TrackEvent
        Status changes, in order.
    """

    def __init__(
        self,
        names: Sequence[str],
        *,
        max_speed: float = 0.25,
        tolerance: float = 0.005,
        min_area_ratio: float = 0.9,
        cameras: Sequence[npt.ArrayLike] | None = None,
        max_turn_rate: float = 3.0,
        yaw_tolerance: float = 0.05,
    ) -> None:
        self.names = tuple(str(k) for k in names)
        if not self.names or len(set(self.names)) != len(self.names):
            raise ValueError(
                f"names must be distinct object names, at least one, got {short(names)}"
            )
        self.max_speed = check_positive_float(max_speed, "max_speed")
        self.tolerance = check_positive_float(tolerance, "tolerance")
        self.min_area_ratio = check_positive_float(min_area_ratio, "min_area_ratio")
        self.max_turn_rate = check_positive_float(max_turn_rate, "max_turn_rate")
        self.yaw_tolerance = check_positive_float(yaw_tolerance, "yaw_tolerance")
        if self.min_area_ratio >= 1.0:
            raise ValueError(f"min_area_ratio must be < 1, got {min_area_ratio}")
        if cameras is None:
            self.cameras: tuple[Float, Float] | None = None
        else:
            if len(cameras) != 2:
                raise ValueError(f"cameras must be two centres (a, b), got {short(cameras)}")
            centres = [check_array(c, "cameras[i]", shape=(3,)) for c in cameras]
            self.cameras = (centres[0], centres[1])
        self.estimates: dict[str, Float] = {}
        self.status: dict[str, str] = dict.fromkeys(self.names, "unseen")
        self.events: list[TrackEvent] = []
        self._time: dict[str, float] = {}
        self._area: dict[str, tuple[float, ...]] = {}
        self._counts: dict[str, dict[str, int]] = {k: {} for k in self.names}

    def update(
        self, t: float, tracks: Mapping[str, ObjectTrack], *, held: Collection[str] = ()
    ) -> dict[str, Float]:
        """Take one frame's tracks; return the positions accepted from it.

        Parameters
        ----------
        t : float
            The frame's time (s), not decreasing.
        tracks : dict str -> Track or PoseTrack
            From :meth:`pbdkit.vision.StereoTracker.track` or
            :meth:`~pbdkit.vision.StereoTracker.track_objects`; objects left out count as
            unseen ("missing").
        held : collection of str
            Objects now in the gripper: their frames are refused ("held").

        Returns
        -------
        accepted : dict str -> ndarray, shape (3,) or (4, 4)
            New estimates of the objects whose position (pose) this frame gave and the checks
            passed (a subset of :attr:`estimates`; empty when nothing changed).
        """
        accepted: dict[str, Float] = {}
        for name in self.names:
            status, detail, pos = self._judge(float(t), name, tracks.get(name), held)
            counts = self._counts[name]
            counts[status] = counts.get(status, 0) + 1
            if status != self.status[name]:
                self.events.append(TrackEvent(float(t), name, status, detail))
                self.status[name] = status
            if pos is not None:
                self.estimates[name] = pos
                self._time[name] = float(t)
                accepted[name] = pos.copy()
        return accepted

    def _judge(
        self, t: float, name: str, track: ObjectTrack | None, held: Collection[str]
    ) -> tuple[str, str, Float | None]:
        if name in held:
            return "held", "in the gripper", None
        if track is None:
            return "missing", "no track for this object", None
        posed = isinstance(track, PoseTrack)
        if not track.ok or track.position is None:
            detail = (
                track.describe()
                if isinstance(track, PoseTrack)
                else f"blob areas {track.area_a}, {track.area_b} px"
            )
            return str(track.status), detail, None
        pos = np.asarray(track.position, dtype=np.float64)
        ref = self._area.get(name)
        areas = self._areas(track, pos)
        if ref is None:
            self._area[name] = areas
        else:
            ratio = min(a / max(r, 1e-12) for a, r in zip(areas, ref, strict=True))
            if ratio < self.min_area_ratio:
                return "occluded", f"blob area {100 * ratio:.0f} % of its first", None
        last = self.estimates.get(name)
        if last is not None:
            dt = max(0.0, t - self._time[name])
            dist = float(np.linalg.norm(pos - last[:3, 3] if posed else pos - last))
            allowed = self.max_speed * dt + self.tolerance
            if dist > allowed:
                return "jump", f"{1e3 * dist:.1f} mm in {dt:.3f} s", None
            if isinstance(track, PoseTrack) and track.pose is not None:
                turn = _yaw_between(track.pose, last)
                if turn > self.max_turn_rate * dt + self.yaw_tolerance:
                    return "jump", f"turned {math.degrees(turn):.1f} deg in {dt:.3f} s", None
        if isinstance(track, PoseTrack) and track.pose is not None:
            return "ok", "", np.array(track.pose, dtype=np.float64)
        return "ok", "", pos

    def _areas(self, track: ObjectTrack, pos: Float) -> tuple[float, ...]:
        """The blob areas to compare with the first ones: per camera, and per end of a posed
        object; scaled by the squared distance to the camera when the centres are known."""
        if isinstance(track, PoseTrack):
            parts = [(e, e.position if e.position is not None else pos) for e in track.ends]
        else:
            parts = [(track, pos)]
        out: list[float] = []
        for tr, p in parts:
            areas = (float(tr.area_a), float(tr.area_b))
            if self.cameras is not None:
                areas = (
                    areas[0] * float(np.sum((p - self.cameras[0]) ** 2)),
                    areas[1] * float(np.sum((p - self.cameras[1]) ** 2)),
                )
            out.extend(areas)
        return tuple(out)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: per object, frames per status, and the status changes (events)."""
        return {
            "frames": {k: dict(v) for k, v in self._counts.items()},
            "events": [e.as_dict() for e in self.events],
        }


def _yaw_between(a: Float, b: Float) -> float:
    """Absolute yaw difference (rad, in [0, pi]) between two poses (4, 4)."""
    ya = math.atan2(float(a[1, 0]), float(a[0, 0]))
    yb = math.atan2(float(b[1, 0]), float(b[0, 0]))
    return abs(math.remainder(ya - yb, 2.0 * math.pi))
