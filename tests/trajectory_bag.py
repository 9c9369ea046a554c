"""A trajectory bag read back as a ros2_control controller receives it (``pbdkit reproduce
--bag``, ``pbdkit.write_trajectory_bag``): shared by tests/test_examples.py and
tests/test_readme.py, read with rosbags' own reader, not pbdkit's."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_HUMBLE)


class Trajectory(NamedTuple):
    """A trajectory bag as a controller receives it."""

    names: list[str]
    q: np.ndarray  # (T, n) positions
    t: np.ndarray  # (T,) time_from_start, s
    v: np.ndarray  # (T, n) velocities of the points
    a: np.ndarray  # (T, n) accelerations of the points
    gripper: list[bool]  # the /gripper messages


def read_trajectory(path: Path) -> Trajectory:
    """The bag's one ``/joint_trajectory`` message and its ``/gripper`` messages."""
    with AnyReader([path], default_typestore=TS) as reader:
        msgs = {
            c.topic: [reader.deserialize(raw, c.msgtype) for _, _, raw in reader.messages([c])]
            for c in reader.connections
        }
    (traj,) = msgs["/joint_trajectory"]
    return Trajectory(
        list(traj.joint_names),
        np.stack([p.positions for p in traj.points]),
        np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in traj.points]),
        np.stack([p.velocities for p in traj.points]),
        np.stack([p.accelerations for p in traj.points]),
        [m.data for m in msgs["/gripper"]],
    )
