"""The tf tree of a bag's first second: each parent -> child link estimated from its
transforms, and a frame's pose in the robot's base frame (tf2's lookup).

A link is the median translation and the sign-aligned mean of its finite, non-zero quaternions,
normalized; T_base_frame = T_root_base^-1 T_root_frame (:doc:`/reproduction`, "ROS bags").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._rotations import pose_matrix
from .._validation import short
from ._bag_stream import _Bag
from ._ros import (
    OBJECT_WINDOW_NS,
    TF_TOPICS,
    TF_TYPE,
    _frame,
    _is_rotation,
    _ros_rotation,
    _stamp_ns,
)

__all__: list[str] = []

Float = NDArray[np.float64]


class _Link(NamedTuple):
    """One tf link: the child frame's pose in its parent's."""

    parent: str
    rotation: Float  # (3, 3)
    translation: Float  # (3,)


class _TfTree:
    """The tf links of a demonstration's first second: child frame -> :class:`_Link`."""

    def __init__(self, links: Mapping[str, _Link], source: str) -> None:
        self.links = dict(links)
        self.source = source

    @classmethod
    def from_bag(cls, bag: _Bag, t0: int) -> _TfTree:
        present = [t for t in TF_TOPICS if t in bag.topics]
        if not present:
            raise ValueError(
                f"tf: the bag {bag.path} has neither /tf nor /tf_static, needed to place a "
                f"frame in the robot's base frame; {bag.listing()}"
            )
        samples: dict[tuple[str, str], list[tuple[Float, Float]]] = {}
        for topic in present:
            bag.check_topic(topic, (TF_TYPE,), "tf")
            static = topic == "/tf_static"
            for _, msg in bag.messages(topic):
                for tr in msg.transforms:
                    ns = _stamp_ns(tr.header.stamp)
                    if not static and not t0 <= ns <= t0 + OBJECT_WINDOW_NS:
                        continue
                    v, r = tr.transform.translation, tr.transform.rotation
                    key = (_frame(str(tr.header.frame_id)), _frame(str(tr.child_frame_id)))
                    samples.setdefault(key, []).append(
                        (np.array([v.x, v.y, v.z]), np.array([r.x, r.y, r.z, r.w]))
                    )
        links: dict[str, _Link] = {}
        for (parent, child), items in samples.items():
            if child in links:
                raise ValueError(
                    f"tf: frame {short(child)} has two parents, {short(links[child].parent)} and "
                    f"{short(parent)}"
                )
            links[child] = _Link(parent, *_mean_transform(items, parent, child))
        return cls(links, " and ".join(present))

    def _to_root(self, frame: str) -> tuple[list[str], Float, Float]:
        """The chain frame <- parent <- ... <- root and the pose of ``frame`` in the root."""
        chain = [frame]
        rot, trans = np.eye(3), np.zeros(3)
        while chain[-1] in self.links:
            parent, r, p = self.links[chain[-1]]
            if parent in chain:
                raise ValueError(f"tf: the frames {[*chain, parent]} form a cycle")
            # T_parent_frame = T_parent_child @ T_child_frame
            rot, trans = r @ rot, r @ trans + p
            chain.append(parent)
        return chain, rot, trans

    def transform(self, frame: str, base: str, what: str) -> tuple[Float, Float]:
        """Rotation (3, 3) and translation (3,) of ``frame`` in ``base``."""
        chain_f, rot_f, trans_f = self._to_root(frame)
        chain_b, rot_b, trans_b = self._to_root(base)
        if chain_f[-1] != chain_b[-1]:
            raise ValueError(
                f"{what}: tf does not join {short(frame)} to the robot's base {short(base)}: "
                f"{' <- '.join(chain_f)} and {' <- '.join(chain_b)} end in different roots "
                f"(transforms of {self.source} during the first second)"
            )
        # T_base_frame = T_root_base^-1 @ T_root_frame
        return rot_b.T @ rot_f, rot_b.T @ (trans_f - trans_b)

    def pose(self, frame: str, base: str, what: str) -> Float:
        """The pose (4, 4) of ``frame`` in ``base``: its origin (m) and axes."""
        rot, trans = self.transform(frame, base, f"{what} (tf:{frame})")
        return pose_matrix(trans, rot)


def _mean_transform(
    items: Sequence[tuple[Float, Float]], parent: str, child: str
) -> tuple[Float, Float]:
    """Rotation and translation of one link from its samples (quaternions (x, y, z, w), ROS's
    order): median translation, mean of the sign-aligned quaternions, normalized (the chordal
    mean: exact for equal samples). A zero quaternion (no rotation) counts for the translation
    only: as the reference of the signs it would leave them unaligned."""
    items = [(p, q) for p, q in items if np.all(np.isfinite(p)) and np.all(np.isfinite(q))]
    if not items:  # non-finite samples are dropped as outliers, as an object topic's are
        raise ValueError(
            f"tf: the transforms {short(parent)} -> {short(child)} of the first second are all NaN "
            "or "
            "infinite"
        )
    trans = np.median(np.stack([p for p, _ in items]), axis=0)
    quats = np.stack([q for _, q in items if _is_rotation(q)] or [np.zeros(4)])
    quats = quats * np.where(quats @ quats[0] < 0, -1.0, 1.0)[:, None]
    q = quats.mean(axis=0)
    norm = float(np.linalg.norm(q))
    if not (np.isfinite(norm) and norm > 1e-9 and np.all(np.isfinite(trans))):
        raise ValueError(
            f"tf: the transform {short(parent)} -> {short(child)} is not a valid rotation"
        )
    return _ros_rotation(q / norm), np.asarray(trans, dtype=np.float64)
