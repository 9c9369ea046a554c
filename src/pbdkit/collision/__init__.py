"""Collisions: the obstacles around the arm (:class:`Scene` of :class:`Box`, :class:`Sphere` and
:class:`Cylinder`, the skill's objects with their shapes), the arm's distance to them and to
itself along a trajectory (:class:`CollisionChecker`, :class:`CollisionReport`), and the
clearance a reproduction keeps (:doc:`/collisions`).

The arm's own geometry is its URDF's ``<collision>`` elements with an SRDF's disabled pairs
(:attr:`pbdkit.Robot.collision_model`, :func:`pbdkit.robots.disabled_pairs`).
"""

from __future__ import annotations

from ._checker import CollisionChecker, CollisionReport
from ._shapes import Box, Cylinder, Scene, Shape, Sphere

__all__ = [
    "Box",
    "CollisionChecker",
    "CollisionReport",
    "Cylinder",
    "Scene",
    "Shape",
    "Sphere",
]
