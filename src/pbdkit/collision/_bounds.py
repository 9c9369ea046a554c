"""Lower bounds on the distance between two posed shapes, for many pairs and postures at once
(private): the cheap test that decides which pairs coal's GJK must measure.

Each body has a bounding sphere (its local AABB's centre c and radius r, coal's). For a pair
(a, b), the distance between the shapes is at least

- |c_a - c_b| - r_a - r_b (the spheres), and
- dist(c_a, shape_b) - r_a where b is a box, a cylinder or a sphere (the point's exact distance
  to the primitive, in b's frame), and the same with a and b swapped;
- for two cylinders, the distance between the capsules around them (their axes' segments'
  closest points, less both radii);

the bound is the largest of those that apply. A table's bounding sphere is a metre wide, its
box is 2 cm from the arm: the second form is what makes the test worth having.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["Bounds", "ShapeTable", "lower_bounds"]

Float = NDArray[np.float64]

_OTHER, _BOX, _CYLINDER, _SPHERE = 0, 1, 2, 3


class ShapeTable:
    """The bounding spheres and primitive extents of every body, index-aligned.

    ``kind`` (B,) is 1 box, 2 cylinder, 3 sphere, 0 anything else (a mesh, a capsule: the
    sphere bound alone); ``extent`` (B, 3) holds a box's half sides, a cylinder's (radius,
    half length, 0), a sphere's (radius, 0, 0); ``round`` (B,): a sphere (its own bound).
    """

    def __init__(self, geometries: list[Any]) -> None:
        import coal

        n = len(geometries)
        self.centre = np.zeros((n, 3))
        self.radius = np.zeros(n)
        self.kind = np.zeros(n, dtype=np.intp)
        self.extent = np.zeros((n, 3))
        for i, g in enumerate(geometries):
            g.computeLocalAABB()
            self.centre[i] = np.asarray(g.aabb_center, dtype=np.float64)
            self.radius[i] = float(g.aabb_radius)
            if isinstance(g, coal.Box):
                self.kind[i], self.extent[i] = _BOX, np.asarray(g.halfSide, dtype=np.float64)
            elif isinstance(g, coal.Cylinder):
                self.kind[i], self.extent[i] = _CYLINDER, (g.radius, g.halfLength, 0.0)
            elif isinstance(g, coal.Sphere):
                self.kind[i], self.extent[i] = _SPHERE, (g.radius, 0.0, 0.0)
        # A sphere's bounding sphere is itself: its bound against a primitive is the distance.
        self.round = (self.kind == _SPHERE) & np.all(np.abs(self.centre) < 1e-12, axis=1)

    def centres(self, rot: Float, pos: Float) -> Float:
        """The bounding spheres' centres (M, B, 3) of bodies at rotations ``rot`` (M, B, 3, 3)
        and positions ``pos`` (M, B, 3)."""
        off = np.flatnonzero(np.any(self.centre != 0.0, axis=1))
        out = pos.copy()
        out[:, off] += np.einsum("mbij,bj->mbi", rot[:, off], self.centre[off])
        return out

    def exact(self, pairs: NDArray[np.intp]) -> NDArray[np.bool_]:
        """The pairs (P,) whose positive lower bound is their distance: a sphere and a box, a
        cylinder or a sphere."""
        a, b = pairs[:, 0], pairs[:, 1]
        prim_a, prim_b = self.kind[a] != _OTHER, self.kind[b] != _OTHER
        return np.asarray((self.round[a] & prim_b) | (self.round[b] & prim_a))


def _point_to_shape(local: Float, kind: int, extent: Float) -> Float:
    """Distances (N,) from points (N, 3), in the shapes' frames, to primitives of one kind
    with extents (N, 3); 0 inside."""
    if kind == _BOX:
        return np.asarray(np.linalg.norm(np.maximum(np.abs(local) - extent, 0.0), axis=1))
    if kind == _CYLINDER:
        radial = np.maximum(np.hypot(local[:, 0], local[:, 1]) - extent[:, 0], 0.0)
        axial = np.maximum(np.abs(local[:, 2]) - extent[:, 1], 0.0)
        return np.asarray(np.hypot(radial, axial))
    return np.asarray(np.maximum(np.linalg.norm(local, axis=1) - extent[:, 0], 0.0))


class Bounds(NamedTuple):
    """What :func:`lower_bounds` finds: the bounds (M, P), where (M, P) a bound is the
    distance itself (a round sphere and a primitive apart, or two cylinders whose capsules'
    closest points lie inside both axes), and per posture (M,) the ceiling under which the
    bounds were refined (inf: all were)."""

    lower: Float
    exact: NDArray[np.bool_]
    ceiling: Float


def lower_bounds(
    table: ShapeTable,
    pairs: NDArray[np.intp],
    rot: Float,
    pos: Float,
    centres: Float | None = None,
    floor: float | None = None,
) -> Bounds:
    """Lower bounds (M, P) on the distances of ``pairs`` (P, 2) at M postures whose bodies are
    at rotations ``rot`` (M, B, 3, 3) and positions ``pos`` (M, B, 3) (``centres``: their
    :meth:`ShapeTable.centres`, if known).

    With a ``floor`` (m), a posture's spheres' bound is refined (the point and capsule forms)
    only where it is under the larger of the floor and an upper bound on that posture's
    smallest distance (two primitives are no farther apart than their centres, less a round
    sphere's radius): a pair left at its spheres' bound there is at least that far, and a
    search for the smallest distance, or for the pairs under the floor, never needs it."""
    m = rot.shape[0]
    if centres is None:
        centres = table.centres(rot, pos)
    a, b = pairs[:, 0], pairs[:, 1]
    gap = np.linalg.norm(centres[:, a] - centres[:, b], axis=2)
    bound = gap - table.radius[a] - table.radius[b]
    exact = np.broadcast_to(table.exact(pairs), bound.shape).copy()
    live: NDArray[np.bool_] | None = None
    ceiling = np.full(m, np.inf)
    both = np.flatnonzero((table.kind[a] == _CYLINDER) & (table.kind[b] == _CYLINDER))
    if both.size:  # two cylinders: their capsules' distance (a link's sphere is loose)
        steps, cols = np.repeat(np.arange(m), both.size), np.tile(both, m)
        ia, ib = a[cols], b[cols]
        caps, inside, apart = _capsules(
            table,
            ia,
            ib,
            rot[steps, ia],
            rot[steps, ib],
            pos[steps, ia],
            pos[steps, ib],
            upper=floor is not None,
        )
        bound[:, both] = np.maximum(bound[:, both], caps.reshape(m, both.size))
        exact[:, both] |= inside.reshape(m, both.size)
        if apart is not None:
            ceiling = apart.reshape(m, both.size).min(axis=1)
    solid = np.flatnonzero((table.kind[a] != _OTHER) & (table.kind[b] != _OTHER))
    if floor is not None and solid.size:  # (two cylinders are solid: no ceiling without)
        shrink = table.radius * table.round  # a round sphere's surface, not its centre
        upper = (gap[:, solid] - shrink[a[solid]] - shrink[b[solid]]).min(axis=1)
        ceiling = np.maximum(np.minimum(upper, ceiling), floor)
        live = bound < ceiling[:, None]
    for near, far in ((a, b), (b, a)):
        for kind in (_BOX, _CYLINDER, _SPHERE):
            # A round sphere's point bound is the spheres' bound: left out.
            sel = np.flatnonzero((table.kind[far] == kind) & ~table.round[far])
            if not sel.size:
                continue
            if live is None:
                steps, cols = np.repeat(np.arange(m), sel.size), np.tile(sel, m)
            else:
                steps, at = np.nonzero(live[:, sel])
                cols = sel[at]
            if not steps.size:
                continue
            fb, nb = far[cols], near[cols]
            d = centres[steps, nb] - pos[steps, fb]  # (N, 3)
            local = np.einsum("nji,nj->ni", rot[steps, fb], d)
            dist = _point_to_shape(local, kind, table.extent[fb]) - table.radius[nb]
            bound[steps, cols] = np.maximum(bound[steps, cols], dist)
    return Bounds(np.asarray(bound), exact, ceiling)


def _capsules(
    table: ShapeTable,
    a: NDArray[np.intp],
    b: NDArray[np.intp],
    rot_a: Float,
    rot_b: Float,
    pos_a: Float,
    pos_b: Float,
    *,
    upper: bool = True,
) -> tuple[Float, NDArray[np.bool_], Float | None]:
    """Distances (N,) between the capsules around cylinders a and b (N,), posed at ``rot_a``,
    ``rot_b`` (N, 3, 3) and ``pos_a``, ``pos_b`` (N, 3) (each capsule holds its cylinder: a
    lower bound on theirs): the closest points of the axes' segments (Ericson, Real-Time
    Collision Detection, 5.1.9), less both radii; where that is the cylinders' distance
    (N,; the closest points inside both segments, apart); and an upper bound on it (N,): the
    distance of two points of the cylinders' sides, each the closest point of its axis moved
    by its radius towards the other's, square to its axis (None unless ``upper``)."""
    half_a, half_b = table.extent[a, 1], table.extent[b, 1]
    axis_a, axis_b = rot_a[..., 2], rot_b[..., 2]  # (N, 3)
    start_a = pos_a - axis_a * half_a[:, None]
    start_b = pos_b - axis_b * half_b[:, None]
    d1 = 2.0 * axis_a * half_a[:, None]
    d2 = 2.0 * axis_b * half_b[:, None]
    r = start_a - start_b
    aa = np.einsum("ni,ni->n", d1, d1)
    ee = np.einsum("ni,ni->n", d2, d2)
    ff = np.einsum("ni,ni->n", d2, r)
    cc = np.einsum("ni,ni->n", d1, r)
    bb = np.einsum("ni,ni->n", d1, d2)
    denom = aa * ee - bb * bb
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-12 * aa * ee, np.clip((bb * ff - cc * ee) / denom, 0.0, 1.0), 0.0)
        t = (bb * s + ff) / ee
        low, high = t < 0.0, t > 1.0
        s = np.where(
            low, np.clip(-cc / aa, 0.0, 1.0), np.where(high, np.clip((bb - cc) / aa, 0.0, 1.0), s)
        )
    # Closest points inside both segments (not parallel): the capsules' nearest points lie on
    # the cylinders' sides, and a positive distance is the cylinders' own.
    inside = (
        (denom > 1e-9 * aa * ee) & (s > 1e-9) & (s < 1.0 - 1e-9) & (t > 1e-9) & (t < 1.0 - 1e-9)
    )
    t = np.clip(t, 0.0, 1.0)
    gap = start_a + d1 * s[..., None] - (start_b + d2 * t[..., None])
    dist = np.linalg.norm(gap, axis=1) - table.extent[a, 0] - table.extent[b, 0]
    exact = np.asarray(inside & (dist > 0.0))
    if not upper:
        return np.asarray(dist), exact, None
    side_a = _square(-gap, axis_a) * table.extent[a, 0][:, None]
    side_b = _square(gap, axis_b) * table.extent[b, 0][:, None]
    return np.asarray(dist), exact, np.asarray(np.linalg.norm(gap + side_a - side_b, axis=1))


def _square(v: Float, axis: Float) -> Float:
    """Unit vectors (N, 3) along v (N, 3) without its part along the unit ``axis`` (N, 3)
    (zero where that leaves nothing)."""
    w = v - np.einsum("ni,ni->n", v, axis)[:, None] * axis
    norm = np.linalg.norm(w, axis=1)
    return np.asarray(np.where(norm[:, None] > 1e-12, w / np.maximum(norm, 1e-12)[:, None], 0.0))
