"""ROS conventions shared by the bag reader and writers: message types, the type store,
stamps, frame ids and quaternions (ROS's are (x, y, z, w), w **last**)."""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .._rotations import matrix_from_quaternion

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = [
    "GRIPPER_TYPES",
    "JOINT_STATE_TYPE",
    "OBJECT_TYPES",
    "POSE_TYPES",
    "TF_TOPICS",
    "TRAJECTORY_TYPE",
]

Float = NDArray[np.float64]

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"
#: Message types of an object topic, and where each holds the position.
OBJECT_TYPES: Mapping[str, str] = {
    "geometry_msgs/msg/PoseStamped": "pose.position",
    "geometry_msgs/msg/PointStamped": "point",
    "geometry_msgs/msg/TransformStamped": "transform.translation",
}
#: The object types that give a pose, and where each holds the orientation: a
#: ``geometry_msgs/msg/Quaternion``, (x, y, z, w) with w **last** (ROS's order).
POSE_TYPES: Mapping[str, str] = {
    "geometry_msgs/msg/PoseStamped": "pose.orientation",
    "geometry_msgs/msg/TransformStamped": "transform.rotation",
}
#: A message's quaternion of a smaller norm is no rotation (a tracker's "unknown"): dropped.
MIN_QUATERNION_NORM = 1e-9
GRIPPER_TYPES = ("std_msgs/msg/Bool", "std_msgs/msg/Float64", "std_msgs/msg/Float32")
TF_TYPE = "tf2_msgs/msg/TFMessage"
TF_TOPICS = ("/tf", "/tf_static")
TRAJECTORY_TYPE = "trajectory_msgs/msg/JointTrajectory"
#: Objects are located from the messages of the demonstration's first second.
OBJECT_WINDOW_NS = 1_000_000_000
#: A gripper signal above this is closed.
GRIPPER_THRESHOLD = 0.5
_NS = 1_000_000_000


@functools.cache
def _typestore() -> Typestore:
    """ROS 2 Humble's message types (built once: it takes ~0.1 s)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _stamp_ns(stamp: Any) -> int:
    """A builtin_interfaces Time (sec, nanosec) as integer nanoseconds."""
    return int(stamp.sec) * _NS + int(stamp.nanosec)


def _frame(name: str) -> str:
    """A tf frame id as tf2 keys it: without a leading slash (ROS 1 bags often have one)."""
    return name.lstrip("/")


def _is_rotation(quaternion: Float) -> bool:
    """Whether a message's quaternion is a rotation: finite and not zero (then normalized)."""
    return bool(
        np.all(np.isfinite(quaternion)) and np.linalg.norm(quaternion) > MIN_QUATERNION_NORM
    )


def _ros_rotation(quaternion: Float) -> Float:
    """The rotation matrix of a ROS quaternion (x, y, z, w), w LAST, normalized first (the
    Hamilton convention, as tf2's): pbdkit's quaternions put w first."""
    x, y, z, w = quaternion
    return matrix_from_quaternion(np.array([w, x, y, z], dtype=np.float64))
