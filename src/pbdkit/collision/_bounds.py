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

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["ShapeTable", "lower_bounds"]

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


def lower_bounds(table: ShapeTable, pairs: NDArray[np.intp], rot: Float, pos: Float) -> Float:
    """Lower bounds (M, P) on the distances of ``pairs`` (P, 2) at M postures whose bodies are
    at rotations ``rot`` (M, B, 3, 3) and positions ``pos`` (M, B, 3)."""
    m = rot.shape[0]
    centres = pos + np.einsum("mbij,bj->mbi", rot, table.centre)  # (M, B, 3)
    a, b = pairs[:, 0], pairs[:, 1]
    gap = np.linalg.norm(centres[:, a] - centres[:, b], axis=2)
    bound = gap - table.radius[a] - table.radius[b]
    for near, far in ((a, b), (b, a)):
        for kind in (_BOX, _CYLINDER, _SPHERE):
            sel = np.flatnonzero(table.kind[far] == kind)
            if not sel.size:
                continue
            fb, nb = far[sel], near[sel]
            d = centres[:, nb] - pos[:, fb]  # (M, S, 3)
            local = np.einsum("msji,msj->msi", rot[:, fb], d).reshape(-1, 3)
            extent = np.broadcast_to(table.extent[fb], (m, sel.size, 3)).reshape(-1, 3)
            dist = _point_to_shape(local, kind, extent).reshape(m, sel.size)
            bound[:, sel] = np.maximum(bound[:, sel], dist - table.radius[nb])
    both = np.flatnonzero((table.kind[a] == _CYLINDER) & (table.kind[b] == _CYLINDER))
    if both.size:  # two cylinders: their capsules' distance (a link's sphere is loose)
        caps = _capsules(table, a[both], b[both], rot, pos)
        bound[:, both] = np.maximum(bound[:, both], caps)
    return np.asarray(bound)


def _capsules(
    table: ShapeTable, a: NDArray[np.intp], b: NDArray[np.intp], rot: Float, pos: Float
) -> Float:
    """Distances (M, S) between the capsules around cylinders a and b (S,) (each capsule holds
    its cylinder: a lower bound on theirs): the closest points of the axes' segments
    (Ericson, Real-Time Collision Detection, 5.1.9), less both radii."""
    half_a, half_b = table.extent[a, 1], table.extent[b, 1]
    axis_a, axis_b = rot[:, a][..., 2], rot[:, b][..., 2]  # (M, S, 3)
    start_a = pos[:, a] - axis_a * half_a[:, None]
    start_b = pos[:, b] - axis_b * half_b[:, None]
    d1 = 2.0 * axis_a * half_a[:, None]
    d2 = 2.0 * axis_b * half_b[:, None]
    r = start_a - start_b
    aa = np.einsum("msi,msi->ms", d1, d1)
    ee = np.einsum("msi,msi->ms", d2, d2)
    ff = np.einsum("msi,msi->ms", d2, r)
    cc = np.einsum("msi,msi->ms", d1, r)
    bb = np.einsum("msi,msi->ms", d1, d2)
    denom = aa * ee - bb * bb
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-12 * aa * ee, np.clip((bb * ff - cc * ee) / denom, 0.0, 1.0), 0.0)
        t = (bb * s + ff) / ee
        low, high = t < 0.0, t > 1.0
        s = np.where(
            low, np.clip(-cc / aa, 0.0, 1.0), np.where(high, np.clip((bb - cc) / aa, 0.0, 1.0), s)
        )
    t = np.clip(t, 0.0, 1.0)
    gap = start_a + d1 * s[..., None] - (start_b + d2 * t[..., None])
    return np.asarray(np.linalg.norm(gap, axis=2) - table.extent[a, 0] - table.extent[b, 0])
