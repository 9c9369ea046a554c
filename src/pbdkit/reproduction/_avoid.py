"""Clearance as one more constraint of the fused step (private; :doc:`/collisions`).

A reproduction that comes within the margin m of something in the scene is made again, in
passes. Each meeting of the path with a static body (an **encounter**: the steps where any of
the arm's bodies, or what the hand carries, comes within the margin of it; a body met again
more than two tapers later is met anew, as on the way there and back) bends the path around it
along one direction, as one smooth bump:

- **the points**: where each moving body that came within the margin came nearest, fixed in
  the frame of the joint it moves with (the nearest one's first, the others as they are met:
  with one point, a redundant arm swings another link in); **the direction** e: up without its
  component along the path (an obstacle met head-on is passed, not backed away from), or the
  contact normal without it where that leaves little (:meth:`Avoidance._escape`); with
  ``beside``, the contact normal made level first (the passes run again where going over
  fails: ``BESIDE`` in :mod:`._probabilistic_ik`);
- **the bump**: at step k each point is asked to lie a_k * w_k further along e than on the
  path where the encounter was first met (ref_k; a point added later, where it lay less the
  bump the path already had), w_k being 1 over the point's own steps within the margin and
  falling as a raised cosine over :data:`TAPER` of the path's steps on either side, or fewer:
  by the nearest step where the skill is tight (``tight``), before the encounter and after it,
  the bump has fallen to nothing (:meth:`Avoidance._flanks`; a flank that reached back into a
  coaster skill's lift-off lifted the glass 5 cm as it left the shelf); the lift
  a_k is the largest need_j c(k - j) over the steps met (:meth:`_Encounter.lift`), a step's
  need growing by its shortfall each pass that still meets it, and the bump widens to the
  steps it still meets the body at, until the margin holds (:meth:`Avoidance.update`).

At every step k of a bump, one Gaussian per point on the posture theta_k, linearized at the
posture the fused step starts from, theta'_k = theta_{k-1} of the run being made, as Table II
linearizes the skill's constraints (:meth:`Avoidance.terms`; linearized once a pass at the last
pass's path, the next pass asked for the lift at postures it no longer went through, and the
passes swung instead of rising to the margin)::

    r = e^T J_p(theta'_k)                   (1, n): the point's motion along e per joint
    r theta_k ~ N(r theta'_k + ref_k + a_k w_k - e^T p(theta'_k), SIGMA^2 / rho_k)

with rho_k = 10^(-TAPER_DECADES (1 - w_k)): full precision where the bump is whole, four
decades less at its ends. In information form it adds Lambda_c = rho_k r^T r / SIGMA^2 to the
fused precision of step k, like the skill's own constraints. With ``hold`` (passes run again
where these fail: ``HOLD`` in :mod:`._probabilistic_ik`), across e (P = I - e e^T) the
encounter's point is also held where it was on the path the encounter started on (q_k), with
:data:`ACROSS_SIGMA`::

    P J_p theta_k ~ N(P (J_p theta'_k + q_k - p(theta'_k)), ACROSS_SIGMA^2 / rho_k)

adding rho_k J_p^T P J_p / ACROSS_SIGMA^2: the lift then moves it along e alone (one
coordinate asked left the other two to the skill's loose phases, and the passes wandered).

One direction per encounter and a lift that is a smooth envelope make the bend continuous along
the steps: per-step directions (each posture's own shortest way out) switched sides mid-
obstacle, and the path jumped past the box between two samples that were clear of it. Where the
clearance acts, the fused step's trust region is ``CLEARANCE_STEP`` times ``max_step``
(:mod:`._steps`) and the timing gives its steps :data:`SLOWER` times their nominal duration
(:meth:`Avoidance.slower`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ..robots._chain import _chain_frames

__all__ = [
    "ACROSS_SIGMA",
    "DEFAULT_MARGIN",
    "MAX_PASSES",
    "SIGMA",
    "STEEP",
    "TAPER",
    "TOLERANCE",
    "Avoidance",
]

Float = NDArray[np.float64]

#: Pairs closer than this (m) are pushed apart (``margin=`` of :meth:`pbdkit.Skill.reproduce`).
DEFAULT_MARGIN = 0.02

#: The clearance constraint's standard deviation (m).
SIGMA = 5e-4

#: Passes at most (each a run of Table II and a check of its path). A lift that grows by each
#: pass's shortfall took 12-14 passes where 8 did not clear a 5 cm cube that a carried glass
#: went through (7 of 50 coaster plans of one skill still touched it with 8, 1 with 14).
MAX_PASSES = 14

#: A path that keeps the margin within this (m) ends the passes.
TOLERANCE = 2e-3

#: A bump rises and falls over this share of the path's steps (at least TAPER_MIN) on either
#: side of its encounter, its precision falling by TAPER_DECADES decades to its ends (from
#: 4e6 m^-2 to 400, a loose phase of a skill).
TAPER = 0.04
TAPER_MIN = 5
TAPER_DECADES = 4.0

#: With ``hold``, across its direction the encounter's point is held where it was on the path
#: it joined at, with this standard deviation (m) where the bump is whole (tapered as the
#: lift's precision). A lift of one coordinate alone leaves the other two to a carry's loose
#: constraints: the hand swung back and forth along its way while it rose (a coaster plan went
#: 10 cm back and ahead over eight passes, each meeting the box somewhere new), and the passes
#: did not converge. ``HOLD`` in :mod:`._probabilistic_ik` says when it is used.
ACROSS_SIGMA = 0.005

#: A normal with less than this left across the path is replaced by up (:meth:`_escape`).
ESCAPE_MIN = 0.3

#: The path's direction at an encounter is the moving point's motion over the steps around
#: its nearest one, widened until the point moves this far (m), or to the path's ends. Over
#: one step either side, a carry that nearly stopped beside a box (3 mm in two steps) gave a
#: direction of noise: the glass was bumped up and 63 % outward, the passes met the box anew
#: each time, and the plan went 24 cm off the coaster it then had to reach.
ALONG_MIN = 0.02
#: A path whose direction at an encounter is less steep than this (the sine of its slope) is
#: passed straight up. Up without the path's component tilts forward where the path goes down
#: a little, and the bump then carried the glass toward the box before reaching it: on the
#: coaster benchmark's skill of teach seed 0, right after the lift-off, 3.1 mm from the box at
#: the samples and 3.8 mm into it between them (10.9 and 9.3 mm straight up).
STEEP = 0.5

#: Where the clearance acts, the steps take this many times their nominal duration.
SLOWER = 3.0


class _Ask(NamedTuple):
    """What one step of a bump asks of one point (fixed in the frame of chain joint ``joint``
    at ``local``): e . p = ``along`` with precision ``rho`` (m^-2), and with ``hold``, P p =
    P ``held`` with precision ``held_rho``."""

    joint: int
    local: Float
    escape: Float
    along: float
    rho: float
    held: Float | None
    held_rho: float


@dataclass
class _Encounter:
    """The path meeting one static body: the steps it is within the margin (lo .. hi), the
    nearest moving body's point (fixed in the frame of chain joint ``joint``; the body
    ``moving``), the direction e the points are moved along, the lift each step where it was
    met needs (``needs``), e . p on the path where it was first met (per step), and the other
    moving bodies' points."""

    body: str
    lo: int
    hi: int
    joint: int
    local: Float
    escape: Float
    #: step -> how far along e the points must go there (m): the bump's lift at step k is
    #: the largest need_j c(k - j), c a raised cosine over ``taper`` steps (:meth:`lift`).
    needs: dict[int, float]
    ref: Float
    taper: int
    #: The other moving bodies met within the margin (body -> (joint, point, ref)): each
    #: point is moved along e by the same bump (a 7-joint arm would swing another link in).
    others: dict[str, tuple[int, Float, Float]] = field(default_factory=dict)
    moving: str = ""
    #: Each moving body's own steps within the margin ([lo, hi]): its point is moved there
    #: (and over the tapers around), not over the whole encounter. A hand that passed near the
    #: obstacle on its way is not held up at the grasp, where a link is still near it.
    spans: dict[str, list[int]] = field(default_factory=dict)
    #: With ``hold``, the encounter's point's positions (T, 3) on the path where the encounter
    #: started: across e, the bump holds it there (:data:`ACROSS_SIGMA`); None without.
    held: Float | None = None
    #: The bump's flanks (steps) before lo and after hi: ``taper`` (given as 0), or fewer where
    #: the skill is tight nearer (:meth:`Avoidance._flanks`).
    before: int = 0
    after: int = 0

    def __post_init__(self) -> None:
        self.before = self.before or self.taper
        self.after = self.after or self.taper

    @property
    def amplitude(self) -> float:
        """The bump's largest lift (m)."""
        return max(self.needs.values())

    def lift(self, steps: npt.ArrayLike) -> Float:
        """a_k at ``steps``: the largest need_j c(k - j) (c = 1 at 0, a raised cosine to 0
        ``taper`` steps away). Each step is lifted by what it and its neighbours need: a path
        that goes down through an obstacle is lifted more on its far side, not everywhere by
        the deepest need (one amplitude for the whole bump grew 7 -> 39 cm, past the reach)."""
        k = np.atleast_1d(np.asarray(steps, dtype=np.float64))
        at = np.fromiter(self.needs.keys(), dtype=np.float64, count=len(self.needs))
        need = np.fromiter(self.needs.values(), dtype=np.float64, count=len(self.needs))
        off = k[:, None] - at[None, :]
        d = np.minimum(np.where(off < 0, -off / self.before, off / self.after), 1.0)
        out: Float = (need * 0.5 * (1.0 + np.cos(np.pi * d))).max(axis=1)
        return out

    def weight(self, k: int, body: str | None = None) -> float:
        """w_k: 1 over lo .. hi (``body``'s own span, if given), a raised cosine to 0 over
        ``taper`` steps on either side."""
        return _taper_weight(*self._gap(k, body))

    def _gap(self, k: int, body: str | None) -> tuple[int, int]:
        """How many steps k lies outside lo .. hi (``body``'s span, if given; <= 0 inside),
        and the flank on that side (steps)."""
        lo, hi = self.spans.get(body, (self.lo, self.hi)) if body else (self.lo, self.hi)
        if k < lo:
            return lo - k, self.before
        return k - hi, self.after


def _taper_weight(gap: int, taper: int) -> float:
    """1 at a gap <= 0 steps outside a span, a raised cosine to 0 at ``taper`` steps."""
    if gap <= 0:
        return 1.0
    return 0.5 * (1.0 + math.cos(math.pi * min(gap, taper) / taper))


def _motion(points: Float, j: int) -> tuple[Float, float]:
    """The motion of a point along a path (``points``, (T, 3)) from step j - w to j + w, w
    widened from 1 until it moves :data:`ALONG_MIN` or spans the path, and its length."""
    last = points.shape[0] - 1
    w = 1
    while True:
        lo, hi = max(j - w, 0), min(j + w, last)
        motion = points[hi] - points[lo]
        speed = float(np.linalg.norm(motion))
        if speed >= ALONG_MIN or (lo == 0 and hi == last):
            return motion, speed
        w += 1


def _moving(prox: Any) -> int:
    """Which of a pair's two bodies moves with the arm (0 or 1)."""
    return 0 if prox.joints[0] > 0 else 1


def _meetings(
    meets: dict[str, list[tuple[int, Any]]], gap: int
) -> list[tuple[str, list[tuple[int, Any]]]]:
    """Each body's (step, Proximity)s cut where more than ``gap`` steps pass without one:
    a path that meets a body twice (on the way there and back) bends twice."""
    out: list[tuple[str, list[tuple[int, Any]]]] = []
    for body, hits in meets.items():
        hits = sorted(hits, key=lambda hit: hit[0])
        group = [hits[0]]
        for hit in hits[1:]:
            if hit[0] - group[-1][0] > gap:
                out.append((body, group))
                group = []
            group.append(hit)
        out.append((body, group))
    return out


class Avoidance:
    """The clearance constraints of one reproduction: the checker with its grasps planned
    (:meth:`pbdkit.collision.CollisionChecker.plan_grasps`), the margin, and its encounters
    (:meth:`update`).

    :meth:`terms` is what the fused step adds at step j; :attr:`precisions` gives each step's
    Lambda_c for the covariance and the influence. ``beside``: each encounter's direction is
    level first (:meth:`_escape`); ``hold``: its point is held across it (:data:`ACROSS_SIGMA`).
    """

    def __init__(
        self,
        checker: Any,
        margin: float = DEFAULT_MARGIN,
        *,
        beside: bool = False,
        hold: bool = False,
        tight: NDArray[np.bool_] | None = None,
    ) -> None:
        self.checker = checker
        self.margin = float(margin)
        self.beside = bool(beside)
        self.hold = bool(hold)
        self.tight = None if tight is None else np.asarray(tight, dtype=bool)
        self.n = int(checker._consts.shape[0])
        self.encounters: list[_Encounter] = []
        self.first = 0  # the skill's step of the path's first sample
        self._asks: dict[int, list[_Ask]] = {}
        self._terms: dict[int, tuple[Float, Float]] = {}

    @property
    def precisions(self) -> dict[int, Float]:
        """Lambda_c (n, n) of every step where the clearance acts (at the last pass's path)."""
        return {j: lam for j, (lam, _) in self._terms.items()}

    def terms(self, j: int, theta: Float | None = None) -> tuple[Float, Float] | None:
        """(Lambda_c (n, n), its information (n,)) of step j, None where nothing acts:
        linearized at the posture ``theta`` (the fused step's theta_{j-1}, as it linearizes
        the skill's own constraints), or at the last pass's path without it."""
        asks = self._asks.get(j)
        if theta is None or asks is None:
            return self._terms.get(j)
        theta = np.asarray(theta, dtype=np.float64)
        frames = _chain_frames(theta[None, :], self.checker._consts, self.checker._revolute)
        return self._gaussian(asks, theta, frames, 0)

    def update(
        self,
        joints: Float,
        gripper: Float | None,
        *,
        first: int = 0,
        near: NDArray[np.intp] | None = None,
    ) -> int:
        """Meet the path ``joints`` (the steps ``first`` .. T - 1 of a pass: from the start,
        or from a state along the way): grow the lift of every encounter where it still comes
        within the margin, start an encounter where it meets a body none covers, and
        linearize every bump at this path; returns the number of (step, pair)s within the
        margin. The encounters' steps are the skill's (``first`` + the path's sample).
        ``near``: the path's samples that may be within the margin (a check's, where its
        scene clearance is under it); None: every sample is looked at."""
        del gripper  # the checker's grasps are planned (plan_grasps) for this path
        if first != self.first and self.encounters:
            raise ValueError("an avoidance's passes start at one step")
        self.first = first
        checker = self.checker
        frames = _chain_frames(joints, checker._consts, checker._revolute)
        meets: dict[str, list[tuple[int, Any]]] = {}
        look = None if near is None else set(near.tolist())
        for lo, hi, state in checker._segments(joints.shape[0], checker._hands(*frames)):
            for j in range(lo, hi):
                if look is not None and j not in look:
                    continue
                for prox in checker.near(joints[j], self.margin, state.carried, state.released):
                    moves = [prox.joints[0] > 0, prox.joints[1] > 0]
                    if moves[0] == moves[1]:
                        continue  # both move (the arm with itself): checked, not avoided
                    static = prox.bodies[1] if moves[0] else prox.bodies[0]
                    meets.setdefault(static, []).append((first + j, prox))
        caught = sum(len(hits) for hits in meets.values())
        taper = max(TAPER_MIN, round(TAPER * (first + joints.shape[0])))
        for body, hits in _meetings(meets, 2 * taper):
            steps = [j for j, _ in hits]
            enc = self._covering(body, min(steps), max(steps))
            if enc is None:
                enc = self._start(body, hits, joints, frames)
                self._flanks(enc)
                self.encounters.append(enc)
                self._join(enc, hits, frames, bumped=False)
                continue
            # Each step met needs what its body was lifted there (a_k w_k: a body met in a
            # taper was lifted less than a_k) and its shortfall; a body not moved yet, a_k more.
            lifted = enc.lift(steps)
            needs = [
                a * self._moved(enc, j, prox) + self._shortfall(prox)
                for a, (j, prox) in zip(lifted, hits, strict=True)
            ]
            enc.lo, enc.hi = min(enc.lo, *steps), max(enc.hi, *steps)
            self._flanks(enc)
            self._join(enc, hits, frames, bumped=True)
            for j, need in zip(steps, needs, strict=True):
                enc.needs[j] = max(enc.needs.get(j, 0.0), need)
        self._linearize(joints, frames)
        return caught

    def _join(
        self,
        enc: _Encounter,
        hits: list[tuple[int, Any]],
        frames: tuple[Float, Float],
        *,
        bumped: bool,
    ) -> None:
        """Add to ``enc`` every moving body of ``hits`` it does not move yet: its point where
        it came nearest, and e . p along the path without the bump it already has
        (``bumped``)."""
        rots, origins = frames
        nearest: dict[str, tuple[int, Any]] = {}
        for step, prox in hits:
            moving = _moving(prox)
            name = prox.bodies[moving]
            span = enc.spans.setdefault(name, [step, step])
            span[0], span[1] = min(span[0], step), max(span[1], step)
            if name == enc.moving or name in enc.others:
                continue
            if name not in nearest or prox.distance < nearest[name][1].distance:
                nearest[name] = (step, prox)
        for name, (step, prox) in nearest.items():
            moving = _moving(prox)
            joint, j = int(prox.joints[moving]), step - self.first
            local = rots[j, joint].T.dot(prox.points[moving] - origins[j, joint])
            points = np.einsum("kab,b->ka", rots[:, joint], local) + origins[:, joint]
            ref = points.dot(enc.escape)
            if bumped:
                steps = self.first + np.arange(len(ref))
                ref = ref - enc.lift(steps) * np.array([enc.weight(int(k), name) for k in steps])
            enc.others[name] = (joint, local, ref)

    def _flanks(self, enc: _Encounter) -> None:
        """Shorten ``enc``'s flanks so that its bump has fallen to nothing by the nearest
        step before lo and after hi where the skill is tight (:attr:`tight`)."""
        if self.tight is None:
            return
        below = np.flatnonzero(self.tight[: max(enc.lo, 0)])
        above = np.flatnonzero(self.tight[enc.hi + 1 :])
        enc.before = min(max(enc.lo - int(below[-1]), 1), enc.taper) if below.size else enc.taper
        enc.after = min(max(int(above[0]) + 1, 1), enc.taper) if above.size else enc.taper

    @staticmethod
    def _moved(enc: _Encounter, step: int, prox: Any) -> float:
        """How much of the lift ``prox``'s moving body was given at ``step``: its weight
        there, or 1 for a body the encounter does not move yet (its point stays where it is)."""
        name = prox.bodies[_moving(prox)]
        return enc.weight(step, name) if name in enc.spans else 1.0

    def _covering(self, body: str, lo: int, hi: int) -> _Encounter | None:
        """The encounter with ``body`` whose bump reaches steps lo .. hi, if any."""
        for enc in self.encounters:
            if enc.body == body and lo <= enc.hi + enc.taper and hi >= enc.lo - enc.taper:
                return enc
        return None

    def _shortfall(self, prox: Any) -> float:
        """How much further along its direction a pair ``prox`` needs its encounter's point:
        its distance to the margin (a first estimate, exact where the direction is the contact
        normal; the next pass measures again). Divided by the cosine of the two (at least
        0.3 or 0.7), the lifts went past the arm's reach on 2 of 50 coaster plans, or an online
        re-plan kept 4 mm where this keeps 25."""
        return max(self.margin - float(prox.distance), 0.0)

    def _start(
        self, body: str, hits: list[tuple[int, Any]], joints: Float, frames: tuple[Float, Float]
    ) -> _Encounter:
        """A new encounter with ``body`` from its pairs within the margin (step, Proximity):
        the point and direction where it came nearest, each step's need its shortfall."""
        step, prox = min(hits, key=lambda hit: hit[1].distance)
        j = step - self.first  # the path's sample
        moving = _moving(prox)
        joint = int(prox.joints[moving])
        rots, origins = frames
        local = rots[j, joint].T.dot(prox.points[moving] - origins[j, joint])
        points = np.einsum("kab,b->ka", rots[:, joint], local) + origins[:, joint]
        escape = self._escape(points, j, prox)
        enc = _Encounter(
            body=body,
            lo=min(k for k, _ in hits),
            hi=max(k for k, _ in hits),
            joint=joint,
            local=local,
            escape=escape,
            needs={},
            ref=points.dot(escape),
            taper=max(TAPER_MIN, round(TAPER * joints.shape[0])),
            moving=prox.bodies[moving],
        )
        if self.hold:
            enc.held = points
        own = [k for k, p in hits if p.bodies[_moving(p)] == enc.moving]
        enc.spans[enc.moving] = [min(own), max(own)]
        for k, p in hits:
            enc.needs[k] = max(enc.needs.get(k, 0.0), self._shortfall(p))
        return enc

    def _escape(self, points: Float, j: int, prox: Any) -> Float:
        """The direction the moving body of ``prox`` (caught nearest at step j; ``points``
        (T, 3): its point, fixed to its joint, at every step of the path) is moved
        along: away from the other body (the contact normal's sense) without the component
        along the path (the moving point's motion around step j: :func:`_motion`), so that an
        obstacle met head-on is passed, not backed away from: up (the base frame's z) without
        it (straight up where the path is less steep than :data:`STEEP`), unless the other body
        is above; where that leaves less than :data:`ESCAPE_MIN`, the
        contact normal without it. With :attr:`beside`, the contact normal made level (without its
        vertical component) is tried first."""
        moving = _moving(prox)
        away = -np.asarray(prox.normal) if moving == 0 else np.asarray(prox.normal)
        motion, speed = _motion(points, j)
        if speed < 1e-12:
            return np.asarray(away / np.linalg.norm(away))
        along = motion / speed
        up = np.array([0.0, 0.0, 1.0])
        # Up, unless the other body is above (up would go into it); beside: level, away.
        order = (up, away) if float(up.dot(away)) > -0.5 else (away,)
        if self.beside:
            order = (away - away.dot(up) * up, *order)
        for candidate in order:
            if candidate is up and abs(float(along[2])) < STEEP:
                return up
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
        # Joint i's world axis and the point's offset from its origin; a x r written out
        # (np.cross cost 47 us a call: most of an avoided run's time).
        a = np.matmul(rots[k, :joint], consts[:joint, :, 10, None])[:, :, 0]
        r = point - origins[k, 1 : joint + 1]
        jac = np.zeros((3, self.n))
        jac[0, :joint] = a[:, 1] * r[:, 2] - a[:, 2] * r[:, 1]
        jac[1, :joint] = a[:, 2] * r[:, 0] - a[:, 0] * r[:, 2]
        jac[2, :joint] = a[:, 0] * r[:, 1] - a[:, 1] * r[:, 0]
        slide = np.flatnonzero(~revolute[:joint])
        jac[:, slide] = a[slide].T
        return jac

    def _linearize(self, joints: Float, frames: tuple[Float, Float]) -> None:
        """Every encounter's asks over its bump (:class:`_Ask`, per step: the skill's steps;
        the path's sample k is step ``first`` + k), and their Gaussians at the path
        ``joints``, summed per step."""
        self._asks.clear()
        first, last = self.first, self.first + joints.shape[0] - 1
        for enc in self.encounters:
            points = {enc.moving: (enc.joint, enc.local, enc.ref), **enc.others}
            lo, hi = max(first, enc.lo - enc.before), min(last, enc.hi + enc.after)
            lifts = enc.lift(np.arange(lo, hi + 1)) if hi >= lo else np.zeros(0)
            for step in range(lo, hi + 1):
                k = step - first
                for name, (joint, local, ref) in points.items():
                    gap, taper = enc._gap(step, name)
                    if gap > taper:
                        continue  # this body is moved only around its own span
                    w = _taper_weight(gap, taper)
                    rho = 10.0 ** (-TAPER_DECADES * (1.0 - w)) / (SIGMA * SIGMA)
                    # Across e, held where it was (``hold``; the encounter's own point).
                    ask = _Ask(
                        joint=joint,
                        local=local,
                        escape=enc.escape,
                        along=float(ref[k] + lifts[step - lo] * w),
                        rho=rho,
                        held=enc.held[k] if enc.held is not None and name == enc.moving else None,
                        held_rho=rho * (SIGMA / ACROSS_SIGMA) ** 2,
                    )
                    self._asks.setdefault(step, []).append(ask)
        self._terms = {
            step: self._gaussian(asks, joints[step - first], frames, step - first)
            for step, asks in self._asks.items()
        }

    def _gaussian(
        self, asks: list[_Ask], theta: Float, frames: tuple[Float, Float], k: int
    ) -> tuple[Float, Float]:
        """(Lambda_c, information) of one step's asks, linearized at the posture ``theta``
        (entry k of ``frames``, its joints' frames)."""
        rots, origins = frames
        lam = np.zeros((self.n, self.n))
        info = np.zeros(self.n)
        for ask in asks:
            point = rots[k, ask.joint].dot(ask.local) + origins[k, ask.joint]
            rows = self._point_rows(k, point, ask.joint, frames)
            row = ask.escape.dot(rows)
            push = ask.along - float(ask.escape.dot(point))
            lam += ask.rho * np.outer(row, row)
            info += ask.rho * row * (row.dot(theta) + push)
            if ask.held is not None:
                # Across e: P = I - e e^T, a projector.
                across = np.eye(3) - np.outer(ask.escape, ask.escape)
                pr = across.dot(rows)
                lam += ask.held_rho * rows.T.dot(pr)
                info += ask.held_rho * pr.T.dot(rows.dot(theta) + ask.held - point)
        return lam, info

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
