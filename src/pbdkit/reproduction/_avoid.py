"""Clearance as one more constraint of the fused step (private; :doc:`/collisions`).

A reproduction that comes within the margin m of something is made again, in passes. Each pass
runs Table II with, at every step j where a pair of bodies came within the margin in some
earlier pass, one Gaussian per such pair on the posture theta_j, linearized at the last pass's
posture theta'_j (:meth:`pbdkit.collision.CollisionChecker.near` there: distance d, nearest
points p_1, p_2, unit normal n from body 1 to body 2)::

    r = n^T (J_p2 - J_p1)                    (1, n): d(d) / d(theta) at theta'_j
    r theta_j ~ N(r theta'_j + m - d, SIGMA^2)

with J_p the position Jacobian of the point p on its body (zero for what does not move). In
information form it adds Lambda_c = r^T r / SIGMA^2 to the fused precision of step j and
r^T (r theta'_j + m - d) / SIGMA^2 to its right-hand side: a constraint of the step like the
skill's own, which asks the pair to be at the margin. A pair once caught keeps its Gaussian in
later passes (re-linearized at the newer path), so that a pass does not fall back where the
one before it was pushed out of, and acts :data:`TAPER` steps before and after where it was
caught with a precision falling geometrically, asking only not to come nearer: the path bends
gradually. The passes stop when the path keeps the margin (within :data:`TOLERANCE`) or after
:data:`MAX_PASSES`. Where the clearance acts, the fused step's trust region is
``CLEARANCE_STEP`` times ``max_step`` (:mod:`._steps`; each pass linearizes again) and the
timing gives its steps :data:`SLOWER` times their nominal duration (:meth:`Avoidance.slower`).

Each Gaussian is fixed for its pass, as the skill's constraints are: the loop sees no
constraint switch on and off from one step to the next (which made a clearance computed on the
fly from the current posture chatter, 40-80 mrad a step), and an obstacle met head-on is left by
the shortest way out of it for each step's posture (coal's penetration normal), not pushed
back along the path.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..robots._chain import _chain_frames

__all__ = ["DEFAULT_MARGIN", "MAX_PASSES", "SIGMA", "TAPER", "TOLERANCE", "Avoidance"]

Float = NDArray[np.float64]

#: Pairs closer than this (m) are pushed apart (``margin=`` of :meth:`pbdkit.Skill.reproduce`).
DEFAULT_MARGIN = 0.02

#: The clearance constraint's standard deviation (m).
SIGMA = 5e-4

#: Passes at most (each a run of Table II and a check of its path).
MAX_PASSES = 6

#: A path that keeps the margin within this (m) ends the passes.
TOLERANCE = 2e-3

#: A caught pair's Gaussian also acts this many steps before and after the steps it was
#: caught at, its precision falling geometrically by TAPER_DECADES decades (from 4e6 m^-2 to
#: 400, a loose phase of a skill): the path bends gradually.
TAPER = 25
TAPER_DECADES = 4.0

#: Where the clearance acts, the steps take this many times their nominal duration.
SLOWER = 3.0


class Avoidance:
    """The clearance constraints of one reproduction: the checker with its grasps planned
    (:meth:`pbdkit.collision.CollisionChecker.plan_grasps`), the margin, and per step the
    Gaussians of the pairs caught so far (:meth:`update`).

    :meth:`terms` is what the fused step adds at step j; :attr:`precisions` gives each step's
    Lambda_c for the covariance and the influence.
    """

    def __init__(self, checker: Any, margin: float = DEFAULT_MARGIN) -> None:
        self.checker = checker
        self.margin = float(margin)
        self.n = int(checker._consts.shape[0])
        self.caught: dict[int, set[tuple[str, str]]] = {}
        self._terms: dict[int, tuple[Float, Float]] = {}

    @property
    def precisions(self) -> dict[int, Float]:
        """Lambda_c (n, n) of every step where the clearance acts."""
        return {j: lam for j, (lam, _) in self._terms.items()}

    def terms(self, j: int) -> tuple[Float, Float] | None:
        """(Lambda_c (n, n), its information (n,)) of step j, None where nothing was caught."""
        return self._terms.get(j)

    def update(self, joints: Float, gripper: Float | None) -> int:
        """Catch the pairs the path ``joints`` (the steps 0 .. T - 1 of a pass) brings within
        the margin, and linearize every caught pair at this path, over its steps and
        :data:`TAPER` steps on either side; returns the number of (step, pair)s newly caught."""
        checker, margin = self.checker, self.margin
        new = 0
        self._terms.clear()
        hands = checker.hand_frames(joints)
        links = set(checker.names[: checker._n_arm])
        arm = {(a, b) for a in links for b in links}
        for lo, hi, state in checker._segments(joints.shape[0], hands):
            for j in range(lo, hi):
                near = checker.near(joints[j], margin, state.carried, state.released)
                for prox in near:
                    if prox.joints[0] >= 0 and prox.joints[1] >= 0 and prox.bodies in arm:
                        continue  # the arm with itself: checked, not avoided (docs)
                    if prox.bodies not in self.caught.setdefault(j, set()):
                        self.caught[j].add(prox.bodies)
                        new += 1
            weights = self._tapered(lo, hi)
            for j, pairs in weights.items():
                near = checker.near(
                    joints[j], 0.0, state.carried, state.released, include=set(pairs)
                )
                active = [(p, pairs[p.bodies]) for p in near if p.bodies in pairs]
                terms = self._gaussians(joints[j], active)
                if terms is not None:
                    self._terms[j] = terms
        return new

    def _tapered(self, lo: int, hi: int) -> dict[int, dict[tuple[str, str], float]]:
        """Per step of [lo, hi), the caught pairs acting there and their weights: 1 where a
        pair was caught, falling by :data:`TAPER_DECADES` decades over :data:`TAPER` steps
        around."""
        out: dict[int, dict[tuple[str, str], float]] = {}
        for j in range(lo, hi):
            for pair in self.caught.get(j, ()):
                for k in range(max(lo, j - TAPER), min(hi, j + TAPER + 1)):
                    w = 10.0 ** (-TAPER_DECADES * abs(k - j) / TAPER)
                    slot = out.setdefault(k, {})
                    slot[pair] = max(slot.get(pair, 0.0), float(w))
        return out

    def slower(self, n_samples: int, n_lead: int) -> Float | None:
        """The factor on each step's nominal duration (n_samples - 1,) of a pass's timing, its
        first ``n_lead`` samples a lead-in (step 0 of the path is sample ``n_lead``):
        :data:`SLOWER` where the clearance acts (and :data:`TAPER` steps around), 1 elsewhere;
        None where it acts nowhere. A pass bends the path where it catches a pair, sharper than
        the skill's own path: at the demonstrations' pace a drive following its samples would
        leave it by tenths of a radian."""
        if not self._terms:
            return None
        steps = sorted(self._terms)
        factors = np.ones(n_samples - 1)
        lo = max(0, n_lead + steps[0] - TAPER)
        hi = min(n_samples - 1, n_lead + steps[-1] + TAPER)
        factors[lo:hi] = SLOWER
        return factors

    def _gaussians(self, at: Float, active: list[Any]) -> tuple[Float, Float] | None:
        """The Gaussians of the pairs ``active`` ((Proximity, weight)) at the posture ``at``,
        summed: where the weight is 1 the pair is asked to the margin; on the taper, not to
        come nearer than the margin or than it is (precision times the weight)."""
        checker = self.checker
        rots, origins = _chain_frames(at[None], checker._consts, checker._revolute)
        axes = np.einsum("kij,kj->ki", rots[0, :-1], checker._consts[:, :, 10])
        lam = np.zeros((self.n, self.n))
        info = np.zeros(self.n)
        for prox, weight in active:
            w = weight / (SIGMA * SIGMA)
            row = np.zeros(self.n)
            for point, joint, sign in (
                (prox.points[0], prox.joints[0], -1.0),
                (prox.points[1], prox.joints[1], 1.0),
            ):
                if joint > 0:
                    row += sign * self._normal_row(prox.normal, point, joint, axes, origins[0])
            if not np.any(row):
                continue
            push = self.margin - prox.distance
            if weight < 1.0:
                push = max(push, 0.0)
            lam += w * np.outer(row, row)
            info += w * row * (row.dot(at) + push)
        return (lam, info) if np.any(lam) else None

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
