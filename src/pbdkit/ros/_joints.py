"""Joint states matched by name (:class:`JointOrder`): a ``sensor_msgs/JointState`` names its
joints in any order, with joints the skill's arm does not have (fingers, a second arm), and
possibly under other names (``--joint-map``: the Panda's model says ``panda_joint1..7``,
franka_ros2's FR3 ``fr3_joint1..7``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import short

__all__ = ["JointOrder", "parse_joint_map"]

Float = NDArray[np.float64]


def parse_joint_map(items: Sequence[str]) -> dict[str, str]:
    """``--joint-map`` items ``FROM=TO`` (FROM a joint of the skill's arm, TO its name on the
    graph) as a mapping; a malformed item, or a name mapped twice either way, is a ValueError
    naming the item."""
    out: dict[str, str] = {}
    for item in items:
        src, sep, dst = item.partition("=")
        src, dst = src.strip(), dst.strip()
        if not sep or not src or not dst or "=" in dst:
            raise ValueError(
                f"--joint-map: {short(item)} is not FROM=TO (the skill's joint=the graph's)"
            )
        if src in out:
            raise ValueError(f"--joint-map: {short(src)} is mapped twice")
        if dst in out.values():
            raise ValueError(f"--joint-map: {short(dst)} is the graph's name of two joints")
        out[src] = dst
    return out


class JointOrder:
    """Where each joint of the arm is in a joint-state message, by name.

    Parameters
    ----------
    joint_names : sequence of str
        The arm's joints, in the order of its postures (the skill's robot).
    joint_map : mapping str -> str, optional
        A joint of the arm -> its name on the graph (the others keep their names).
    """

    def __init__(self, joint_names: Sequence[str], joint_map: Mapping[str, str] | None = None):
        names = [str(n) for n in joint_names]
        given = dict(joint_map or {})
        unknown = [k for k in given if k not in names]
        if unknown:
            raise ValueError(
                f"--joint-map: {short(unknown)} are not joints of the skill's arm {short(names)}"
            )
        #: The arm's joints as the graph names them, in the arm's order.
        self.graph_names = [given.get(n, n) for n in names]
        if len(set(self.graph_names)) != len(names):
            raise ValueError(
                f"--joint-map: two joints share a name on the graph: {self.graph_names}"
            )
        self._cache: dict[tuple[str, ...], NDArray[np.intp]] = {}

    def indices(self, names: Sequence[str], topic: str = "joint states") -> NDArray[np.intp]:
        """The index in ``names`` (a message's) of each of the arm's joints; ValueError where a
        joint is missing (naming it, the message's names and ``--joint-map``) or a name comes
        twice. Cached per tuple of names (a driver sends the same every time)."""
        key = tuple(str(n) for n in names)
        found = self._cache.get(key)
        if found is not None:
            return found
        if len(set(key)) != len(key):
            raise ValueError(f"{topic}: a message names a joint twice: {short(list(key))}")
        where = {n: k for k, n in enumerate(key)}
        missing = [n for n in self.graph_names if n not in where]
        if missing:
            raise ValueError(
                f"{topic}: the arm's joint(s) {short(missing)} are not in the joint states, which "
                f"name {short(list(key))} (a joint named otherwise on the graph: --joint-map "
                "SKILL_JOINT=GRAPH_JOINT)"
            )
        out = np.array([where[n] for n in self.graph_names], dtype=np.intp)
        self._cache[key] = out
        return out

    def positions(
        self, names: Sequence[str], positions: npt.ArrayLike, topic: str = "joint states"
    ) -> Float:
        """The arm's posture (n,) from a message's names and positions (same length; finite)."""
        pos = np.asarray(positions, dtype=np.float64)
        if pos.shape != (len(names),):
            raise ValueError(f"{topic}: a message has {len(names)} names and {pos.size} positions")
        q = pos[self.indices(names, topic)]
        if not np.all(np.isfinite(q)):
            raise ValueError(f"{topic}: a position of the arm is not finite: {short(q.tolist())}")
        return q
