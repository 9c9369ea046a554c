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

Refused frames keep the last good estimate; every change of an object's status is logged as a
:class:`TrackEvent`, and frames are counted per reason (:meth:`TrackFilter.summary`).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_positive_float
from .stereo import Track

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

    Attributes
    ----------
    estimates : dict str -> ndarray, shape (3,)
        The last good position of each object seen at least once.
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
    ) -> None:
        self.names = tuple(str(k) for k in names)
        if not self.names or len(set(self.names)) != len(self.names):
            raise ValueError(f"names must be distinct object names, at least one, got {names!r}")
        self.max_speed = check_positive_float(max_speed, "max_speed")
        self.tolerance = check_positive_float(tolerance, "tolerance")
        self.min_area_ratio = check_positive_float(min_area_ratio, "min_area_ratio")
        if self.min_area_ratio >= 1.0:
            raise ValueError(f"min_area_ratio must be < 1, got {min_area_ratio}")
        if cameras is None:
            self.cameras: tuple[Float, Float] | None = None
        else:
            if len(cameras) != 2:
                raise ValueError(f"cameras must be two centres (a, b), got {cameras!r}")
            centres = [check_array(c, "cameras[i]", shape=(3,)) for c in cameras]
            self.cameras = (centres[0], centres[1])
        self.estimates: dict[str, Float] = {}
        self.status: dict[str, str] = dict.fromkeys(self.names, "unseen")
        self.events: list[TrackEvent] = []
        self._time: dict[str, float] = {}
        self._area: dict[str, tuple[float, float]] = {}
        self._counts: dict[str, dict[str, int]] = {k: {} for k in self.names}

    def update(
        self, t: float, tracks: Mapping[str, Track], *, held: Collection[str] = ()
    ) -> dict[str, Float]:
        """Take one frame's tracks; return the positions accepted from it.

        Parameters
        ----------
        t : float
            The frame's time (s), not decreasing.
        tracks : dict str -> Track
            From :meth:`pbdkit.vision.StereoTracker.track`; objects left out count as unseen
            ("missing").
        held : collection of str
            Objects now in the gripper: their frames are refused ("held").

        Returns
        -------
        accepted : dict str -> ndarray, shape (3,)
            New estimates of the objects whose position this frame gave and the checks passed
            (a subset of :attr:`estimates`; empty when nothing changed).
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
        self, t: float, name: str, track: Track | None, held: Collection[str]
    ) -> tuple[str, str, Float | None]:
        if name in held:
            return "held", "in the gripper", None
        if track is None:
            return "missing", "no track for this object", None
        if not track.ok or track.position is None:
            return str(track.status), f"blob areas {track.area_a}, {track.area_b} px", None
        pos = np.asarray(track.position, dtype=np.float64)
        ref = self._area.get(name)
        areas = (float(track.area_a), float(track.area_b))
        if self.cameras is not None:
            areas = (
                areas[0] * float(np.sum((pos - self.cameras[0]) ** 2)),
                areas[1] * float(np.sum((pos - self.cameras[1]) ** 2)),
            )
        if ref is None:
            self._area[name] = areas
        else:
            ratio = min(a / max(r, 1e-12) for a, r in zip(areas, ref, strict=True))
            if ratio < self.min_area_ratio:
                return "occluded", f"blob area {100 * ratio:.0f} % of its first", None
        last = self.estimates.get(name)
        if last is not None:
            dist = float(np.linalg.norm(pos - last))
            allowed = self.max_speed * max(0.0, t - self._time[name]) + self.tolerance
            if dist > allowed:
                return "jump", f"{1e3 * dist:.1f} mm in {t - self._time[name]:.3f} s", None
        return "ok", "", pos

    def summary(self) -> dict[str, Any]:
        """JSON-ready: per object, frames per status, and the status changes (events)."""
        return {
            "frames": {k: dict(v) for k, v in self._counts.items()},
            "events": [e.as_dict() for e in self.events],
        }
