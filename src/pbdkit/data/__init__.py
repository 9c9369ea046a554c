"""Demonstrations: what a teacher recorded (:class:`Demonstration`), its files, ROS bags in
(:func:`read_bag`) and out (:func:`write_trajectory_bag`, :func:`check_trajectory_bag`,
:func:`write_demonstration_bag`), and alignment in time (:func:`align`,
:func:`align_trajectories`).

Above :mod:`pbdkit.robots`; never imports the simulator, OpenCV or matplotlib."""

from __future__ import annotations

from ._align import align, align_trajectories
from ._bag_read import read_bag
from ._bag_write import check_trajectory_bag, write_demonstration_bag, write_trajectory_bag
from ._demonstration import (
    Demonstration,
    LimitWarning,
    demonstration_from_csv,
    load_demonstrations,
    save_demonstrations,
)

__all__ = [
    "Demonstration",
    "LimitWarning",
    "align",
    "align_trajectories",
    "check_trajectory_bag",
    "demonstration_from_csv",
    "load_demonstrations",
    "read_bag",
    "save_demonstrations",
    "write_demonstration_bag",
    "write_trajectory_bag",
]
