"""pbdkit on a live ROS 2 graph (issue 37): joint states matched by name, and the nodes built
on them. The message-free parts import without ROS; the nodes need the ``ros`` extra (PyPI's
ROS 2 Jazzy wheels: ``pip install -e '.[ros]'`` in the checkout)."""

from ._joints import JointOrder, parse_joint_map

__all__ = ["JointOrder", "parse_joint_map"]
