"""Reproduction by probabilistic inverse kinematics (paper Table II): each constraint's GMR
Gaussians mapped to joint space and fused step by step (:class:`ReproductionResult`), offline
or online (:class:`Controller`, :class:`Command`).

Above :mod:`pbdkit.data`; never imports the simulator, OpenCV or matplotlib."""

from __future__ import annotations

from ._controller import Command, Controller
from ._result import ReproductionResult
from ._setup import ReachWarning
from ._stream import CommandStream, LimitViolation

__all__ = [
    "Command",
    "CommandStream",
    "Controller",
    "LimitViolation",
    "ReachWarning",
    "ReproductionResult",
]
