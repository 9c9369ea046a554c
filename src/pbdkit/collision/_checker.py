"""Distances between the arm (with what it carries), a scene and the arm itself (private).

:class:`CollisionChecker` puts a robot's collision model (:attr:`pbdkit.Robot.collision_model`),
a :class:`~pbdkit.collision.Scene`'s obstacles and the shapes of the skill's objects (at their
placements) in one world, and measures, per posture, the signed distance of every pair that
may not touch: the arm's links against each other (the robot's ``self_pairs``), against the
obstacles and the objects, and a carried object against all of them. A negative distance is a
penetration (coal's signed distance); a collision is a distance below 0.

**What may touch.** The hand (the bodies on the tip's joint) may touch the objects it grasps.
A grasped object moves with the hand (rigidly, from the posture where the gripper closes) and
may touch what it rested on when grasped (its support: within :data:`SUPPORT_GAP`) and what it
is put on when released (its target). The objects and the obstacles are not checked against
each other (a glass stands on the table).

**Grasps.** Where the gripper signal closes (False -> True), the object whose shape is nearest
the tip, within :data:`GRASP_REACH`, is grasped; where it opens, the object stays where the
hand left it.

**Cost.** Each pair first gets a lower bound (vectorized, :mod:`._bounds`): bounding spheres,
refined (a point against a primitive, two cylinders' capsules) only under an upper bound on the
posture's smallest distance; a sphere against a primitive, and two cylinders whose capsules'
closest points lie inside both axes, get their distance there. coal's GJK runs only on the pairs
whose bound is below the smallest distance found so far (or the margin), its transforms set in
place.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import as_pose, pose_matrix
from .._validation import short
from ..robots._chain import _chain_constants, _chain_frames
from ._bounds import ShapeTable, lower_bounds
from ._shapes import Scene

__all__ = ["GRASP_REACH", "SUPPORT_GAP", "CollisionChecker", "CollisionReport", "Proximity"]

Float = NDArray[np.float64]

#: A closing gripper grasps the object whose shape is nearest its tip, if within this (m).
GRASP_REACH = 0.05

#: A grasped object may touch what lies within this (m) of it when grasped or released.
SUPPORT_GAP = 0.005

_STATIC = -1  # the joint of a body that does not move with the arm

#: The check looks at the postures in stretches of this many, each leaving out the pairs its
#: swept spheres keep apart (:meth:`CollisionChecker._chunk_pairs`).
CHUNK = 64
#: ... when there are more pairs than this (fewer: the stretches cost more than they save).
CHUNK_PAIRS = 50
#: Pairs whose centres' distance bounds each posture's smallest distance from above.
PROBES = 4


@dataclass(frozen=True, eq=False)
class CollisionReport:
    """What :meth:`pbdkit.Skill.check` (and a reproduction with a scene) finds.

    Attributes
    ----------
    clearance : ndarray, shape (T,)
        Per step, the smallest signed distance (m) between the arm (with what it carries) and
        the scene or itself, over the pairs that may not touch; negative: a penetration.
    collisions : list of (int, str, str)
        (step, body, body) for every step and pair closer than 0, the two names sorted (URDF
        link names, shape names, object names), the list sorted; empty when the run is free.
    scene_clearance : ndarray, shape (T,), or None
        The same as ``clearance`` without the arm's pairs with itself: what avoidance keeps
        clear (inf at a step with nothing to check). Exact where under the ``margin`` of
        :meth:`CollisionChecker.check` and where it is the clearance; a lower bound elsewhere.
    """

    clearance: Float
    collisions: list[tuple[int, str, str]]
    scene_clearance: Float | None = None

    @property
    def free(self) -> bool:
        """True when nothing collides."""
        return not self.collisions

    @property
    def min_clearance(self) -> float:
        """The smallest clearance over the run (m)."""
        return float(np.min(self.clearance)) if self.clearance.size else float("inf")


class Proximity(NamedTuple):
    """One pair closer than a margin at one posture.

    ``points`` are the nearest points (or, in a penetration, the deepest ones) in the base
    frame, ``normal`` the unit vector from body 1 towards body 2, and ``joints`` the chain
    joint each body moves with (0: the base; -1: static).
    """

    distance: float
    bodies: tuple[str, str]
    points: tuple[Float, Float]
    normal: Float
    joints: tuple[int, int]


class _State(NamedTuple):
    """What the hand carries (body -> pose in the hand joint's frame) and what it has put
    down (body -> world pose), over a stretch of a run."""

    carried: dict[int, Float]
    released: dict[int, Float]


@dataclass
class _Grasp:
    """One grasp of a run: the object, and the steps where it closes and opens."""

    body: int
    closes: int
    opens: int | None
    allowed: set[int] = field(default_factory=set)


class CollisionChecker:
    """The arm, the scene and the placed objects in one world (see the module docstring).

    Parameters
    ----------
    robot : pbdkit.Robot
        With a collision model (:attr:`pbdkit.Robot.has_collision_model`).
    scene : Scene
        Obstacles and object shapes.
    placements : dict str -> array-like, shape (3,), (4, 4) or (7,), optional
        Where the objects are; an object with a shape in the scene and no placement here is
        left out (with its shape).
    """

    def __init__(
        self,
        robot: Any,
        scene: Scene,
        placements: Mapping[str, npt.ArrayLike] | None = None,
    ) -> None:
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be a pbdkit.Scene, got {type(scene).__name__}")
        model = robot.collision_model
        if model is None:
            raise ValueError(
                f"robot {short(robot.name)} has no collision model (its URDF has no <collision> "
                "elements); add them, or check without a scene"
            )
        self.robot = robot
        pin_model = model.model
        consts = _chain_constants(pin_model, pin_model.createData(), model.tip_frame)
        self._consts, self._revolute, tip_rot, tip_trans = consts
        self._tip_local = pose_matrix(tip_trans, tip_rot)
        self._hand_joint = int(pin_model.frames[model.tip_frame].parentJoint)
        names: list[str] = []
        geoms: list[Any] = []
        joints: list[int] = []
        local: list[Float] = []
        for k, obj in enumerate(model.geometry.geometryObjects):
            names.append(model.links[k])
            geoms.append(obj.geometry)
            joints.append(int(obj.parentJoint))
            local.append(pose_matrix(obj.placement.translation, obj.placement.rotation))
        self._n_arm = len(names)
        self._self_pairs = [tuple(p) for p in model.self_pairs]
        for shape in scene.shapes:
            names.append(str(shape.name))
            geoms.append(shape.geometry())
            joints.append(_STATIC)
            local.append(np.array(shape.pose))
        self.object_bodies: dict[str, int] = {}
        for name, where in (placements or {}).items():
            if name not in scene.objects:
                continue
            shape = scene.objects[name]
            position, rotation = as_pose(where, f"objects[{short(name)}]")
            self.object_bodies[name] = len(names)
            names.append(name)
            geoms.append(shape.geometry())
            joints.append(_STATIC)
            local.append(pose_matrix(position, rotation) @ shape.pose)
        self.names = names
        self._geoms = geoms
        self._joints = np.array(joints)
        self._local = np.array(local).reshape(-1, 4, 4)
        self._table = ShapeTable(geoms)
        import coal

        self._request = coal.DistanceRequest()  # signed distances (coal's default)
        self._result = coal.DistanceResult()
        self._functors: dict[tuple[int, int], Any] = {}
        # One coal transform per body, set in place at each posture (a third of a new one's cost).
        self._transforms = [coal.Transform3s() for _ in names]
        self._grasps: list[_Grasp] = []
        self._pair_cache: dict[int | None, NDArray[np.intp]] = {}

    # ------------------------------------------------------------------ world poses

    def _frames(self, joints: Float) -> tuple[Float, Float]:
        """Joint frames (M, n + 1, 3, 3), (M, n + 1, 3) of postures (M, n)."""
        return _chain_frames(joints, self._consts, self._revolute)

    def _hands(self, rots: Float, origins: Float) -> Float:
        """The hand joint's frames (M, 4, 4) from the joint frames (M, n + 1, 3, 3), (M, n + 1,
        3): what a grasped body moves with."""
        out = np.zeros((rots.shape[0], 4, 4))
        out[:, :3, :3] = rots[:, self._hand_joint]
        out[:, :3, 3] = origins[:, self._hand_joint]
        out[:, 3, 3] = 1.0
        return out

    def hand_frames(self, joints: npt.ArrayLike) -> Float:
        """The hand joint's frames (M, 4, 4) at postures (M, n)."""
        q = np.atleast_2d(np.asarray(joints, dtype=np.float64))
        return self._hands(*self._frames(q))

    def tip_poses(self, joints: npt.ArrayLike) -> Float:
        """The tip's transforms (M, 4, 4) at postures (M, n)."""
        return np.asarray(self.hand_frames(joints) @ self._tip_local)

    def _poses(
        self,
        rots: Float,
        origins: Float,
        carried: Mapping[int, Float],
        released: Mapping[int, Float],
    ) -> tuple[Float, Float]:
        """World rotations (M, B, 3, 3) and positions (M, B, 3) of every body at M postures,
        given their joint frames (M, n + 1, 3, 3), (M, n + 1, 3); ``carried`` maps a body to
        its pose in the hand joint's frame, ``released`` a body to its world pose."""
        joint = self._joints.copy()
        local = self._local.copy()
        for body, offset in carried.items():
            joint[body] = self._hand_joint
            local[body] = offset
        for body, pose in released.items():
            local[body] = pose
        m, n_bodies = rots.shape[0], len(joint)
        rot, pos = np.empty((m, n_bodies, 3, 3)), np.empty((m, n_bodies, 3))
        moving, still = np.flatnonzero(joint >= 0), np.flatnonzero(joint < 0)
        rot[:, still], pos[:, still] = local[still, :3, :3], local[still, :3, 3]
        jr, jp = rots[:, joint[moving]], origins[:, joint[moving]]
        rot[:, moving] = jr
        # A body turned in its joint's frame turns with it; a round sphere needs no turning.
        turned = ~self._table.round[moving] & np.any(
            np.abs(local[moving, :3, :3] - np.eye(3)) > 0.0, axis=(1, 2)
        )
        if turned.any():
            rot[:, moving[turned]] = jr[:, turned] @ local[moving[turned], :3, :3]
        pos[:, moving] = jp + np.einsum("mbij,bj->mbi", jr, local[moving, :3, 3])
        return rot, pos

    # ------------------------------------------------------------------ pairs

    def _pairs(self, carried: int | None, held: set[int], allowed: set[int]) -> NDArray[np.intp]:
        """The pairs checked while ``carried`` is in the hand (None: nothing); ``held``: the
        objects the hand may touch (those it grasps in the run); ``allowed``: what the carried
        object may touch."""
        pairs: list[tuple[int, int]] = list(self._self_pairs)
        hand = {a for a in range(self._n_arm) if self._joints[a] == self._hand_joint}
        others = [b for b in range(self._n_arm, len(self.names)) if b != carried]
        for a in range(self._n_arm):
            if self._joints[a] == 0:  # fixed to the base, as the scene: mounted, not a collision
                continue
            for b in others:
                if a in hand and b in held:
                    continue
                pairs.append((a, b))
        if carried is not None:
            for b in range(len(self.names)):
                if b == carried or b in allowed or b in hand:
                    continue
                pairs.append((min(b, carried), max(b, carried)))
        return np.array(sorted(set(pairs)), dtype=np.intp).reshape(-1, 2)

    def _functor(self, a: int, b: int) -> Any:
        """coal's cached pair solver of bodies a and b (a third of coal.distance's cost)."""
        import coal

        functor = self._functors[(a, b)] = coal.ComputeDistance(self._geoms[a], self._geoms[b])
        return functor

    def _distance(self, a: int, b: int, rot: Float, pos: Float) -> tuple[float, Any]:
        """coal's signed distance of bodies a and b at one posture's rot (B, 3, 3), pos (B, 3),
        and its result (nearest points and normal; valid until the next call)."""
        import coal

        functor = self._functors.get((a, b))
        if functor is None:
            functor = self._functor(a, b)
        result = self._result
        result.clear()
        d = functor(
            coal.Transform3s(rot[a], pos[a]),
            coal.Transform3s(rot[b], pos[b]),
            self._request,
            result,
        )
        return float(d), result

    def _scan(
        self,
        pairs: NDArray[np.intp],
        rots: Float,
        origins: Float,
        state: _State,
        below: float,
        margin: float,
    ) -> tuple[Float, Float, list[list[tuple[int, int]]]]:
        """Per posture of joint frames rots (M, n + 1, 3, 3), origins (M, n + 1, 3), with what
        ``state`` says is carried and released (:meth:`_poses`): the smallest distance over
        ``pairs`` (M,); the smallest over the pairs with the scene (M,; exact where under
        ``margin`` or where it is the smallest, a lower bound elsewhere; inf without such
        pairs); and the pairs closer than ``below``.

        Branch and bound: the pairs in the order of their lower bounds
        (:func:`~pbdkit.collision._bounds.lower_bounds`), measured by coal while a bound is
        under what is known (about one measurement per posture)."""
        import coal

        moves = self._joints >= 0
        moves[list(state.carried)] = True
        own = (pairs[:, 0] < self._n_arm) & (pairs[:, 1] < self._n_arm)
        m = rots.shape[0]
        # Few pairs: all postures at once, every pair; more: stretches (small arrays, warm).
        step = m if len(pairs) <= CHUNK_PAIRS else CHUNK
        best, scene = np.empty(m), np.empty(m)
        close: list[list[tuple[int, int]]] = [[] for _ in range(m)]
        static: dict[int, Any] = {}
        for lo in range(0, m, step):
            hi = min(m, lo + step)
            rot, pos = self._poses(rots[lo:hi], origins[lo:hi], state.carried, state.released)
            if not static:
                static = {
                    int(i): coal.Transform3s(rot[0, i], pos[0, i]) for i in np.flatnonzero(~moves)
                }
            if step == m:
                best[:], scene[:], close[:] = self._scan_pairs(
                    pairs, own, rot, pos, static, below, margin
                )
                break
            centres = self._table.centres(rot, pos)
            kept, apart = self._chunk_pairs(pairs, centres, max(below, margin))
            out = self._scan_pairs(pairs[kept], own[kept], rot, pos, static, below, margin, centres)
            best[lo:hi], scene[lo:hi], close[lo:hi] = out
            left = ~kept & ~own
            if left.any():  # the scene's pairs left out: at least their swept spheres apart
                scene[lo:hi] = np.minimum(scene[lo:hi], float(apart[left].min()))
        return best, scene, close

    def _chunk_pairs(
        self, pairs: NDArray[np.intp], centres: Float, floor: float
    ) -> tuple[NDArray[np.bool_], Float]:
        """The pairs (P,) a stretch of postures (its bounding spheres' ``centres`` (M, B, 3))
        must look at, and their swept spheres'
        distance (P,; a lower bound over the stretch): a
        pair whose bodies' swept spheres (each bounding sphere over the stretch) are farther
        apart than the largest of ``floor`` and an upper bound on every posture's smallest
        distance (the centres' distance of a few primitive pairs: a primitive holds its
        centre) is nearest nowhere, closer than ``floor`` nowhere."""
        table = self._table
        middle = 0.5 * (centres.max(axis=0) + centres.min(axis=0))  # (B, 3)
        swept = np.linalg.norm(centres - middle, axis=2).max(axis=0) + table.radius
        a, b = pairs[:, 0], pairs[:, 1]
        apart = np.linalg.norm(middle[a] - middle[b], axis=1) - swept[a] - swept[b]
        solid = np.flatnonzero((table.kind[a] != 0) & (table.kind[b] != 0))
        if not solid.size:
            return np.ones(len(pairs), dtype=bool), apart
        first = np.linalg.norm(centres[0, a[solid]] - centres[0, b[solid]], axis=1)
        probes = solid[np.argsort(first)[:PROBES]]
        upper = np.linalg.norm(centres[:, a[probes]] - centres[:, b[probes]], axis=2)
        ceiling = max(float(upper.min(axis=1).max()), floor)
        return apart <= ceiling, apart

    def _scan_pairs(
        self,
        pairs: NDArray[np.intp],
        own_pairs: NDArray[np.bool_],
        rot: Float,
        pos: Float,
        static: dict[int, Any],
        below: float,
        margin: float,
        centres: Float | None = None,
    ) -> tuple[Float, Float, list[list[tuple[int, int]]]]:
        """:meth:`_scan` over ``pairs`` (the arm's own where ``own_pairs``) for one stretch,
        with coal's transforms of the static bodies (and the bounding spheres' centres, if
        known)."""
        m = rot.shape[0]
        best = np.full(m, np.inf)
        scene = np.full(m, np.inf)
        close: list[list[tuple[int, int]]] = [[] for _ in range(m)]
        found_bounds = lower_bounds(self._table, pairs, rot, pos, centres, max(below, margin))
        order = np.argsort(found_bounds.lower, axis=1)
        sorted_bounds = np.take_along_axis(found_bounds.lower, order, axis=1)
        # Past the ceiling the search stops at the first pair: the lists end there.
        width = 1 + int(np.max((sorted_bounds <= found_bounds.ceiling[:, None]).sum(axis=1)))
        order = order[:, :width]
        ordered = sorted_bounds[:, :width].tolist()
        exact = np.take_along_axis(found_bounds.exact, order, axis=1).tolist()
        order_l = order.tolist()
        own = own_pairs.tolist()
        firsts, seconds = pairs[:, 0].tolist(), pairs[:, 1].tolist()
        has_scene = not all(own)
        # coal's transforms: a static body's once for the run, a moving one's once a posture.
        request, result, transforms = self._request, self._result, self._transforms
        stamp = [-1] * len(transforms)  # the posture each moving body's transform was set at
        functors = self._functors
        for t in range(m):
            low = scene_low = skipped = math.inf
            rot_t, pos_t, found = rot[t], pos[t], close[t]
            for bound, k, known in zip(ordered[t], order_l[t], exact[t], strict=True):
                scene_pair = not own[k]
                wanted = bound < low or bound < below
                if scene_pair and bound < margin and bound < scene_low:
                    wanted = True
                if not wanted:
                    if bound >= margin or bound >= scene_low:
                        if has_scene:  # the scene's pairs left: bounds at least this
                            skipped = min(skipped, bound)
                        break
                    if scene_pair:
                        skipped = min(skipped, bound)
                    continue
                fa, fb = firsts[k], seconds[k]
                if known and bound > 0.0:  # its bound is its distance
                    low = min(low, bound)
                    if scene_pair:
                        scene_low = min(scene_low, bound)
                    continue
                ta = static.get(fa)
                if ta is None:
                    ta = transforms[fa]
                    if stamp[fa] != t:
                        ta.setRotation(rot_t[fa])
                        ta.setTranslation(pos_t[fa])
                        stamp[fa] = t
                tb = static.get(fb)
                if tb is None:
                    tb = transforms[fb]
                    if stamp[fb] != t:
                        tb.setRotation(rot_t[fb])
                        tb.setTranslation(pos_t[fb])
                        stamp[fb] = t
                functor = functors.get((fa, fb))
                if functor is None:
                    functor = self._functor(fa, fb)
                result.clear()
                d = float(functor(ta, tb, request, result))
                low = min(low, d)
                if scene_pair:
                    scene_low = min(scene_low, d)
                if d < below:
                    found.append((fa, fb))
            best[t], scene[t] = low, min(scene_low, skipped)
        return best, scene, close

    # ------------------------------------------------------------------ grasps

    def plan_grasps(self, joints: Float, gripper: npt.ArrayLike | None) -> None:
        """Find the run's grasps from its gripper signal (closed where True or > 0.5): which
        object each closing takes, and what it may touch (see the module docstring)."""
        self._plan(np.atleast_2d(np.asarray(joints, dtype=np.float64)), gripper)

    def _plan(self, q: Float, gripper: npt.ArrayLike | None) -> tuple[Float, Float, Float]:
        """:meth:`plan_grasps` for postures q (M, n); returns their joint frames and hand
        frames, computed once for the grasps and for the check that follows."""
        rots, origins = self._frames(q)
        hands = self._hands(rots, origins)
        self._grasps = []
        self._pair_cache.clear()
        if gripper is None or not self.object_bodies:
            return rots, origins, hands
        closed = np.asarray(gripper, dtype=np.float64) > 0.5
        if closed.shape != (q.shape[0],):
            raise ValueError(
                f"gripper must have one value per step ({q.shape[0]}), got shape {closed.shape}"
            )
        edges = np.flatnonzero(np.diff(closed.astype(np.int8)))
        closes = [int(e) + 1 for e in edges if closed[e + 1]]
        opens = [int(e) + 1 for e in edges if not closed[e + 1]]
        for k in closes:
            body = self._nearest_object((hands[k] @ self._tip_local)[:3, 3])
            if body is None:
                continue
            release = next((o for o in opens if o > k), None)
            self._grasps.append(_Grasp(body, k, release))
        self._plan_contacts(rots, origins, hands)
        return rots, origins, hands

    def _nearest_object(self, tip: Float) -> int | None:
        """The placed object whose shape is nearest the tip point (3,), within GRASP_REACH."""
        import coal

        probe = coal.Sphere(1e-4)
        where = coal.Transform3s(np.eye(3), tip)
        best, found = GRASP_REACH, None
        for body in self.object_bodies.values():
            self._result.clear()
            d = coal.distance(
                probe,
                where,
                self._geoms[body],
                coal.Transform3s(self._local[body, :3, :3], self._local[body, :3, 3]),
                self._request,
                self._result,
            )
            if d <= best:
                best, found = d, body
        return found

    def _offset(self, grasp: _Grasp, hands: Float) -> Float:
        """The grasped body's pose in the hand joint's frame, fixed where the gripper closes."""
        return np.asarray(np.linalg.inv(hands[grasp.closes]) @ self._local[grasp.body])

    def _plan_contacts(self, rots: Float, origins: Float, hands: Float) -> None:
        """What each grasped object may touch: what lies within SUPPORT_GAP of it where it is
        grasped and where it is released (the run's joint and hand frames)."""
        for g in self._grasps:
            for step in (g.closes, g.opens):
                if step is None:
                    continue
                at = slice(step, step + 1)
                carried = {g.body: self._offset(g, hands)}
                rot, pos = self._poses(rots[at], origins[at], carried, {})
                for b in range(self._n_arm, len(self.names)):
                    if b != g.body and self._distance(g.body, b, rot[0], pos[0])[0] <= SUPPORT_GAP:
                        g.allowed.add(b)

    def _segments(self, n_steps: int, hands: Float) -> list[tuple[int, int, _State]]:
        """The run cut where a grasp closes or opens: (first step, end step, state), the state
        being what is carried (body -> pose in the hand joint's frame) and what was released
        (body -> world pose)."""
        cuts = sorted(
            {0, n_steps, *(g.closes for g in self._grasps)}
            | {g.opens for g in self._grasps if g.opens is not None}
        )
        out = []
        for lo, hi in itertools.pairwise(cuts):
            carried: dict[int, Float] = {}
            released: dict[int, Float] = {}
            for g in self._grasps:
                offset = self._offset(g, hands)
                if g.closes <= lo and (g.opens is None or lo < g.opens):
                    carried[g.body] = offset
                elif g.opens is not None and g.opens <= lo:
                    released[g.body] = hands[g.opens] @ offset
            out.append((lo, hi, _State(carried, released)))
        return out

    # ------------------------------------------------------------------ checks

    def check(
        self,
        joints: npt.ArrayLike,
        gripper: npt.ArrayLike | None = None,
        *,
        contact: float = 0.0,
        margin: float = 0.0,
    ) -> CollisionReport:
        """Clearance and collisions along a joint trajectory (T, n) (see
        :class:`CollisionReport`); ``gripper`` (T,) is the gripper signal, for the grasps;
        ``contact``: a pair closer than this (m) is a collision (0: penetrating only; a
        measured run that stops at a contact touches at about 1 mm); ``margin``: the scene
        clearance is exact where under it (m), a lower bound above."""
        q = np.atleast_2d(self.robot.check_joints(joints, "joints"))
        rots, origins, hands = self._plan(q, gripper)
        clearance = np.empty(q.shape[0])
        outside = np.empty(q.shape[0])
        collisions: set[tuple[int, str, str]] = set()
        for lo, hi, state in self._segments(q.shape[0], hands):
            pairs = self._state_pairs(state)
            low, scene, close = self._scan(
                pairs, rots[lo:hi], origins[lo:hi], state, float(contact), float(margin)
            )
            clearance[lo:hi], outside[lo:hi] = low, scene
            for t, found in enumerate(close):
                for a, b in found:
                    first, second = sorted((self.names[a], self.names[b]))
                    collisions.add((lo + t, first, second))
        return CollisionReport(clearance, sorted(collisions), outside)

    def _state_pairs(self, state: _State) -> NDArray[np.intp]:
        """The pairs checked while ``state``'s object is carried (kept per carried body until
        the grasps are planned again: :meth:`near` asks at every step)."""
        carried = next(iter(state.carried), None)
        pairs = self._pair_cache.get(carried)
        if pairs is None:
            allowed: set[int] = set()
            for g in self._grasps:
                if g.body == carried:
                    allowed = g.allowed
            pairs = self._pairs(carried, {g.body for g in self._grasps}, allowed)
            self._pair_cache[carried] = pairs
        return pairs

    def near(
        self,
        q: Float,
        margin: float,
        carried: Mapping[int, Float] | None = None,
        released: Mapping[int, Float] | None = None,
        *,
        include: Collection[tuple[str, str]] = (),
    ) -> list[Proximity]:
        """The pairs closer than ``margin`` at one posture q (n,), with their nearest points,
        given what the hand carries (body -> pose in the hand joint's frame) and where released
        objects lie (body -> world pose), and the pairs ``include`` names (body names, as in
        :attr:`Proximity.bodies`) at any distance. The grasps are those of the last
        :meth:`check` or :meth:`plan_grasps`."""
        state = _State(dict(carried or {}), dict(released or {}))
        pairs = self._state_pairs(state)
        if not len(pairs):
            return []
        rots, origins = self._frames(q[None])
        rot, pos = self._poses(rots, origins, state.carried, state.released)
        bounds = lower_bounds(self._table, pairs, rot, pos).lower[0]
        joint = self._joints.copy()
        for body in state.carried:
            joint[body] = self._hand_joint
        out: list[Proximity] = []
        wanted = set(include)
        names = self.names
        for k in range(len(pairs)):
            a, b = int(pairs[k, 0]), int(pairs[k, 1])
            always = bool(wanted) and (names[a], names[b]) in wanted
            if bounds[k] >= margin and not always:
                continue
            d, result = self._distance(a, b, rot[0], pos[0])
            if d < margin or always:
                out.append(
                    Proximity(
                        d,
                        (self.names[a], self.names[b]),
                        (
                            np.array(result.getNearestPoint1(), dtype=np.float64),
                            np.array(result.getNearestPoint2(), dtype=np.float64),
                        ),
                        np.array(result.normal, dtype=np.float64),
                        (int(joint[a]), int(joint[b])),
                    )
                )
        return out

    @property
    def grasps(self) -> list[tuple[str, int, int | None]]:
        """(object, closing step, opening step or None) of the last check's grasps."""
        return [(self.names[g.body], g.closes, g.opens) for g in self._grasps]
