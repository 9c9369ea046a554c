"""Clearance as one more constraint of the fused step (private; :doc:`/collisions`).

A reproduction that comes within the margin m of something in the scene is made again, in
passes. Each meeting of the path with a static body (an **encounter**: the steps where any of
the arm's bodies, or what the hand carries, comes within the margin of it) bends the path
around it along one direction, as one smooth bump:

- **the point**: where the moving body came nearest, fixed in the frame of the joint it moves
  with; **the direction** e: the contact normal there without its component along the path
  (an obstacle met head-on is passed, not backed away from), or up where that leaves little
  (:meth:`Avoidance._escape`);
- **the bump**: at step k the point is asked to lie a * w_k further along e than on the path
  where the encounter was first met (ref_k), w_k being 1 over the encounter's steps and falling
  as a raised cosine over :data:`TAPER` of the path's steps on either side; a, the amplitude,
  grows by the pass's shortfall, and the bump widens to the steps it still meets the body at,
  until the margin holds (:meth:`Avoidance.update`).

At every step k of a bump, one Gaussian on the posture theta_k, linearized at the last pass's
posture theta'_k::

    r = e^T J_p(theta'_k)                   (1, n): the point's motion along e per joint
    r theta_k ~ N(r theta'_k + ref_k + a w_k - e^T p(theta'_k), SIGMA^2 / rho_k)

with rho_k = 10^(-TAPER_DECADES (1 - w_k)): full precision where the bump is whole, four
decades less at its ends. In information form it adds Lambda_c = rho_k r^T r / SIGMA^2 to the
fused precision of step k, like the skill's own constraints. One direction and one amplitude per
encounter make the bend continuous along the steps: per-step directions (each posture's own
shortest way out) switched sides mid-obstacle, and the path jumped past the box between two
samples that were clear of it. Where the clearance acts, the fused step's trust region is
``CLEARANCE_STEP`` times ``max_step`` (:mod:`._steps`) and the timing gives its steps
:data:`SLOWER` times their nominal duration (:meth:`Avoidance.slower`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
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
MAX_PASSES = 8

#: A path that keeps the margin within this (m) ends the passes.
TOLERANCE = 2e-3

#: A bump rises and falls over this share of the path's steps (at least TAPER_MIN) on either
#: side of its encounter, its precision falling by TAPER_DECADES decades to its ends (from
#: 4e6 m^-2 to 400, a loose phase of a skill).
TAPER = 0.04
TAPER_MIN = 5
TAPER_DECADES = 4.0

#: A normal with less than this left across the path is replaced by up (:meth:`_escape`).
ESCAPE_MIN = 0.3

#: Where the clearance acts, the steps take this many times their nominal duration.
SLOWER = 3.0


@dataclass
class _Encounter:
    """The path meeting one static body: the steps it is within the margin (lo .. hi), the
    moving point (fixed in the frame of chain joint ``joint``), the direction e it is moved
    along, the bump's amplitude, and e . p on the path where it was first met (per step)."""

    body: str
    lo: int
    hi: int
    joint: int
    local: Float
    escape: Float
    amplitude: float
    ref: Float
    taper: int

    def weight(self, k: int) -> float:
        """w_k: 1 over lo .. hi, a raised cosine to 0 over ``taper`` steps on either side."""
        gap = self.lo - k if k < self.lo else k - self.hi
        if gap <= 0:
            return 1.0
        return 0.5 * (1.0 + math.cos(math.pi * min(gap, self.taper) / self.taper))


class Avoidance:
    """The clearance constraints of one reproduction: the checker with its grasps planned
    (:meth:`pbdkit.collision.CollisionChecker.plan_grasps`), the margin, and its encounters
    (:meth:`update`).

    :meth:`terms` is what the fused step adds at step j; :attr:`precisions` gives each step's
    Lambda_c for the covariance and the influence.
    """

    def __init__(self, checker: Any, margin: float = DEFAULT_MARGIN) -> None:
        self.checker = checker
        self.margin = float(margin)
        self.n = int(checker._consts.shape[0])
        self.encounters: list[_Encounter] = []
        self.first = 0  # the skill's step of the path's first sample
        self._terms: dict[int, tuple[Float, Float]] = {}

    @property
    def precisions(self) -> dict[int, Float]:
        """Lambda_c (n, n) of every step where the clearance acts."""
        return {j: lam for j, (lam, _) in self._terms.items()}

    def terms(self, j: int) -> tuple[Float, Float] | None:
        """(Lambda_c (n, n), its information (n,)) of step j, None where nothing acts."""
        return self._terms.get(j)

    def update(self, joints: Float, gripper: Float | None, *, first: int = 0) -> int:
        """Meet the path ``joints`` (the steps ``first`` .. T - 1 of a pass: from the start,
        or from a state along the way): grow the amplitude of every encounter it still comes
        within the margin at, start an encounter where it meets a body none covers, and
        linearize every bump at this path; returns the number of (step, pair)s within the
        margin. The encounters' steps are the skill's (``first`` + the path's sample)."""
        del gripper  # the checker's grasps are planned (plan_grasps) for this path
        if first != self.first and self.encounters:
            raise ValueError("an avoidance's passes start at one step")
        self.first = first
        checker = self.checker
        frames = _chain_frames(joints, checker._consts, checker._revolute)
        near: dict[str, list[tuple[int, Any]]] = {}
        for lo, hi, state in checker._segments(joints.shape[0], checker._hands(*frames)):
            for j in range(lo, hi):
                for prox in checker.near(joints[j], self.margin, state.carried, state.released):
                    moves = [prox.joints[0] > 0, prox.joints[1] > 0]
                    if moves[0] == moves[1]:
                        continue  # both move (the arm with itself): checked, not avoided
                    static = prox.bodies[1] if moves[0] else prox.bodies[0]
                    near.setdefault(static, []).append((first + j, prox))
        caught = 0
        for body, hits in near.items():
            caught += len(hits)
            steps = [j for j, _ in hits]
            enc = self._covering(body, min(steps), max(steps))
            if enc is None:
                self.encounters.append(self._start(body, hits, joints, frames))
                continue
            enc.lo, enc.hi = min(enc.lo, *steps), max(enc.hi, *steps)
            enc.amplitude += max(self._shortfall(prox) for _, prox in hits)
        self._linearize(joints, frames)
        return caught

    def _covering(self, body: str, lo: int, hi: int) -> _Encounter | None:
        """The encounter with ``body`` whose bump reaches steps lo .. hi, if any."""
        for enc in self.encounters:
            if enc.body == body and lo <= enc.hi + enc.taper and hi >= enc.lo - enc.taper:
                return enc
        return None

    def _shortfall(self, prox: Any) -> float:
        """How much further along its direction a pair ``prox`` needs its encounter's point:
        its distance to the margin (a first estimate, exact where the direction is the contact
        normal; the next pass measures again)."""
        return max(self.margin - float(prox.distance), 0.0)

    def _start(
        self, body: str, hits: list[tuple[int, Any]], joints: Float, frames: tuple[Float, Float]
    ) -> _Encounter:
        """A new encounter with ``body`` from its pairs within the margin (step, Proximity):
        the point and direction where it came nearest, the amplitude its shortfall."""
        step, prox = min(hits, key=lambda hit: hit[1].distance)
        j = step - self.first  # the path's sample
        moving = 0 if prox.joints[0] > 0 else 1
        joint = int(prox.joints[moving])
        rots, origins = frames
        local = rots[j, joint].T.dot(prox.points[moving] - origins[j, joint])
        escape = self._escape(joints, j, prox, frames)
        points = np.einsum("kab,b->ka", rots[:, joint], local) + origins[:, joint]
        enc = _Encounter(
            body=body,
            lo=min(k for k, _ in hits),
            hi=max(k for k, _ in hits),
            joint=joint,
            local=local,
            escape=escape,
            amplitude=max(self._shortfall(p) for _, p in hits),
            ref=points.dot(escape),
            taper=max(TAPER_MIN, round(TAPER * joints.shape[0])),
        )
        return enc

    def _escape(self, joints: Float, j: int, prox: Any, frames: tuple[Float, Float]) -> Float:
        """The direction the moving body of ``prox`` (caught nearest at step j) is moved
        along: away from the other body (the contact normal's sense) without the component
        along the path (the moving point's motion through step j), so that an obstacle met
        head-on is passed, not backed away from: up (the base frame's z) without it, unless
        the other body is above; where that leaves less than :data:`ESCAPE_MIN`, the contact
        normal without it."""
        moving = 0 if prox.joints[0] > 0 else 1
        away = -np.asarray(prox.normal) if moving == 0 else np.asarray(prox.normal)
        lo, hi = max(j - 1, 0), min(j + 1, joints.shape[0] - 1)
        rows = self._point_rows(j, prox.points[moving], int(prox.joints[moving]), frames)
        motion = rows.dot(joints[hi] - joints[lo])
        speed = float(np.linalg.norm(motion))
        if speed < 1e-12:
            return np.asarray(away / np.linalg.norm(away))
        along = motion / speed
        up = np.array([0.0, 0.0, 1.0])
        # Up, unless the other body is above (up would go into it).
        for candidate in (up, away) if float(up.dot(away)) > -0.5 else (away,):
            side = candidate - candidate.dot(along) * along
            size = float(np.linalg.norm(side))
            if size >= ESCAPE_MIN:
                return np.asarray(side / size)
        return np.asarray(away / np.linalg.norm(away))

    def _point_rows(self, k: int, point: Float, joint: int, frames: tuple[Float, Float]) -> Float:
        """J_p (3, n): the motion of ``point`` (base frame), fixed to chain joint ``joint``
        (1-based; the joints after it do not move it), per joint at step k of ``frames``."""
        rots, origins = frames
        consts, revolute = self.checker._consts, self.checker._revolute
        jac = np.zeros((3, self.n))
        for i in range(joint):
            axis = rots[k, i].dot(consts[i, :, 10])
            if revolute[i]:
                jac[:, i] = np.cross(axis, point - origins[k, i + 1])
            else:
                jac[:, i] = axis
        return jac

    def _linearize(self, joints: Float, frames: tuple[Float, Float]) -> None:
        """Every encounter's Gaussians over its bump, at the path ``joints``, summed per step
        (the skill's steps; the path's sample k is step ``first`` + k)."""
        self._terms.clear()
        rots, origins = frames
        first, last = self.first, self.first + joints.shape[0] - 1
        for enc in self.encounters:
            for step in range(max(first, enc.lo - enc.taper), min(last, enc.hi + enc.taper) + 1):
                k = step - first
                w = enc.weight(step)
                point = rots[k, enc.joint].dot(enc.local) + origins[k, enc.joint]
                row = enc.escape.dot(self._point_rows(k, point, enc.joint, frames))
                push = enc.ref[k] + enc.amplitude * w - float(enc.escape.dot(point))
                rho = 10.0 ** (-TAPER_DECADES * (1.0 - w)) / (SIGMA * SIGMA)
                lam = rho * np.outer(row, row)
                info = rho * row * (row.dot(joints[k]) + push)
                if step in self._terms:
                    old = self._terms[step]
                    lam, info = old[0] + lam, old[1] + info
                self._terms[step] = (lam, info)

    def slower(self, n_samples: int, n_lead: int) -> Float | None:
        """The factor on each step's nominal duration (n_samples - 1,) of a pass's timing, its
        first ``n_lead`` samples a lead-in (step :attr:`first` is sample ``n_lead``):
        :data:`SLOWER` where the clearance acts, 1 elsewhere; None where it acts nowhere. A
        pass bends the path around an obstacle, sharper than the skill's own path: at the
        demonstrations' pace a drive following its samples would leave it by tenths of a
        radian."""
        if not self._terms:
            return None
        steps = sorted(self._terms)
        factors = np.ones(n_samples - 1)
        lo = max(0, n_lead + steps[0] - self.first)
        hi = min(n_samples - 1, n_lead + steps[-1] - self.first)
        factors[lo:hi] = SLOWER
        return factors
