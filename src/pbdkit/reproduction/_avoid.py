"""Clearance as one more constraint of the fused step (private; :doc:`/collisions`).

At step j, linearized at theta = theta_{j-1} as every constraint of Table II, each pair of
bodies closer than the margin m (:meth:`pbdkit.collision.CollisionChecker.near`: distance d,
nearest points p_1, p_2, unit normal n from body 1 to body 2) gets a one-dimensional Gaussian
on its distance's change::

    r = n^T (J_p2 - J_p1)                    (1, n): d(d) / d(theta) at theta
    r dtheta ~ N(m - d, sigma(d)^2),          sigma(d) = SIGMA_0 + SIGMA_SLOPE max(d, 0)

with J_p the position Jacobian of the point p on its body (zero for what does not move). In
information form it adds Lambda_c = r^T r / sigma^2 to the fused precision and
Lambda_c theta + r^T (m - d) / sigma^2 to its right-hand side: a push out to the margin whose
precision grows as the clearance shrinks (4e6 m^-2 at contact, 1e4 at 1 cm with the defaults,
against a loose skill phase's 1e3-1e4), and which vanishes at the margin. Pairs at the margin
or beyond add nothing, so a run that never comes near anything is the plain run to the bit.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..robots._chain import _chain_frames

__all__ = ["DEFAULT_MARGIN", "SIGMA_0", "SIGMA_SLOPE", "Avoidance"]

Float = NDArray[np.float64]

#: Pairs closer than this (m) are pushed apart (``margin=`` of :meth:`pbdkit.Skill.reproduce`).
DEFAULT_MARGIN = 0.02

#: The clearance constraint's standard deviation at contact (m), and its growth per m of
#: clearance: sigma(d) = SIGMA_0 + SIGMA_SLOPE d.
SIGMA_0 = 5e-4
SIGMA_SLOPE = 0.5


class Avoidance:
    """The clearance constraint of one run: the checker with its grasps planned (the objects
    the hand may touch, what each carried object may touch), and the margin.

    :meth:`terms` is called once per step, in order; it tracks what the hand carries (the
    grasp closes at its step, at the posture the run has reached there) and where a released
    object lies. :attr:`precisions` keeps each step's Lambda_c for the covariance and the
    influence.
    """

    def __init__(self, checker: Any, margin: float = DEFAULT_MARGIN) -> None:
        self.checker = checker
        self.margin = float(margin)
        self.n = int(checker._consts.shape[0])
        self.precisions: dict[int, Float] = {}
        self._carried: dict[int, Float] = {}
        self._released: dict[int, Float] = {}

    def reset(self) -> None:
        """Start a run again (from its first step)."""
        self.precisions.clear()
        self._carried.clear()
        self._released.clear()

    def _update_grasps(self, j: int, theta: Float) -> None:
        checker = self.checker
        for g in checker._grasps:
            if g.closes == j and g.body not in self._carried and g.body not in self._released:
                hand = checker.tip_poses(theta)[0] @ np.linalg.inv(checker._tip_local)
                self._carried[g.body] = np.linalg.inv(hand) @ checker._local[g.body]
            if g.opens == j and g.body in self._carried:
                hand = checker.tip_poses(theta)[0] @ np.linalg.inv(checker._tip_local)
                self._released[g.body] = hand @ self._carried.pop(g.body)

    def terms(self, j: int, theta: Float) -> tuple[Float, Float] | None:
        """(Lambda_c (n, n), its right-hand side (n,)) for step j at theta = theta_{j-1}; None
        where nothing is within the margin."""
        self._update_grasps(j - 1, theta)
        near = self.checker.near(theta, self.margin, self._carried, self._released)
        if not near:
            return None
        rots, origins = _chain_frames(theta[None], self.checker._consts, self.checker._revolute)
        axes = np.einsum("kij,kj->ki", rots[0, :-1], self.checker._consts[:, :, 10])
        lam = np.zeros((self.n, self.n))
        rhs = np.zeros(self.n)
        for prox in near:
            row = np.zeros(self.n)
            for point, joint, sign in (
                (prox.points[0], prox.joints[0], -1.0),
                (prox.points[1], prox.joints[1], 1.0),
            ):
                if joint > 0:
                    row += sign * self._normal_row(prox.normal, point, joint, axes, origins[0])
            if not np.any(row):
                continue
            sigma = SIGMA_0 + SIGMA_SLOPE * max(prox.distance, 0.0)
            w = 1.0 / (sigma * sigma)
            lam += w * np.outer(row, row)
            rhs += w * row * (self.margin - prox.distance)
        if not np.any(lam):
            return None
        self.precisions[j] = lam
        return lam, lam.dot(theta) + rhs

    def _normal_row(
        self, normal: Float, point: Float, joint: int, axes: Float, origins: Float
    ) -> Float:
        """n^T J_p: the rate of the point's motion along ``normal`` per joint, for a point on
        a body that moves with chain joint ``joint`` (1-based; joints after it do not move
        it)."""
        revolute = self.checker._revolute
        row = np.zeros(self.n)
        for i in range(joint):
            if revolute[i]:
                # n . (a_i x (p - o_i)) = (p - o_i) . (n x a_i)
                row[i] = np.dot(point - origins[i + 1], np.cross(normal, axes[i]))
            else:
                row[i] = np.dot(normal, axes[i])
        return row
