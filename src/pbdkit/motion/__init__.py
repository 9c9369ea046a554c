"""Motion limits: velocity, acceleration and jerk limits and retiming (:class:`MotionLimits`),
and online trajectory generation under them (Ruckig).

The bottom layer, beside :mod:`pbdkit.prob`."""

from __future__ import annotations

from ._limits import MotionLimits, MotionPeaks, motion_peaks

__all__ = ["MotionLimits", "MotionPeaks", "motion_peaks"]
