"""The robot's collision model: its URDF's ``<collision>`` geometry on the robot's kinematic
model (:class:`CollisionModel`), and the link pairs self-collision checking skips
(:func:`pbdkit.robots.disabled_pairs`, MoveIt setup assistant style, in ``_pairs.py``).

The geometry is pinocchio's (``pin.GeometryModel``, coal shapes: box, sphere, cylinder,
capsule, and meshes as triangle soups, ``coal.BVHModelOBBRSS``), built from the same URDF text
as the robot and reduced to the same joints (the joints off the root-to-tip path locked at the
neutral posture), so that its ``model`` is joint for joint the robot's.

Disabled pairs (MoveIt's reasons):

- Adjacent: links joined by a joint, also through links without geometry (a link fixed to a
  flange is adjacent to the link before the flange), and links that move as one body (joined by
  fixed joints, or joints locked off the chain);
- Default: in collision at the default posture (0 clipped into the joint limits);
- Always: in collision in every sampled posture;
- Never: in collision in none of ``n`` postures drawn uniformly within the joint limits;
- and, in :attr:`CollisionModel.disabled`, the pairs of the robot's SRDF.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from numpy.typing import NDArray

from .._validation import check_array, shape_str, short
from ._srdf import LinkPair, _pair
from ._urdf import _parse_urdf, _pinocchio_xml

__all__ = ["CollisionModel", "build_collision_model", "has_collision_elements"]


@dataclass(frozen=True, eq=False)
class CollisionModel:
    """A robot's collision geometry on its kinematic model (``robot.collision_model``).

    Holds models only, no work data: create ``model.createData()`` and
    ``pin.GeometryData(geometry)`` (after adding collision pairs) per thread.

    Attributes
    ----------
    model : pinocchio.Model
        Joint for joint the robot's model (same nq, joint order and placements): a
        configuration ``q`` of shape (n,) of the robot is one of this model.
    geometry : pinocchio.GeometryModel
        The ``<collision>`` elements of every link, collision type, with no collision pair
        (add your own: :attr:`self_pairs`, obstacles, ...). A mesh is its triangles (coal's
        BVHModel, as in MoveIt), not a solid: a shape wholly inside it does not touch it.
    links : tuple of str, length ngeoms
        The URDF link of each geometry object (index-aligned with
        ``geometry.geometryObjects``, which pinocchio names ``<link>_<k>``, k counting the
        link's ``<collision>`` elements in order).
    self_pairs : tuple of (int, int)
        Geometry index pairs (i < j), sorted, that self-collision checking uses: on different
        links, neither adjacent nor disabled.
    disabled : frozenset of (str, str)
        Link pairs never checked, each sorted alphabetically: :attr:`adjacent` and the SRDF's.
    adjacent : frozenset of (str, str)
        Link pairs with geometry that are joined by a joint (also through links without
        geometry) or move as one body (fixed or locked joints); sorted alphabetically.
    tip_frame : int
        The id in :attr:`model` of the robot's tip frame (to attach a grasped object).
    """

    model: Any
    geometry: Any
    links: tuple[str, ...]
    self_pairs: tuple[tuple[int, int], ...]
    disabled: frozenset[LinkPair]
    adjacent: frozenset[LinkPair]
    tip_frame: int
    _self_geometry: Any = field(init=False, repr=False)  # with the self_pairs: distances()

    def __post_init__(self) -> None:
        geometry = self.geometry.clone()
        for i, j in self.self_pairs:
            geometry.addCollisionPair(pin.CollisionPair(i, j))
        object.__setattr__(self, "_self_geometry", geometry)

    def __repr__(self) -> str:
        return (
            f"CollisionModel(nq={self.model.nq}, ngeoms={self.geometry.ngeoms}, "
            f"links={len(set(self.links))}, self_pairs={len(self.self_pairs)}, "
            f"disabled={len(self.disabled)})"
        )

    def distances(self, q: npt.ArrayLike) -> NDArray[np.float64]:
        """Signed distances of the :attr:`self_pairs` at one posture (coal; a convenience that
        allocates its work data: in a loop, keep your own ``GeometryData``).

        Parameters
        ----------
        q : array-like, shape (n,)

        Returns
        -------
        d : ndarray, shape (len(self_pairs),)
            Metres; negative when two primitives overlap (the penetration depth).
        """
        arr = check_array(q, "q", ndim=1)
        if arr.shape != (self.model.nq,):
            raise ValueError(
                f"q must have shape ({self.model.nq},) (one value per joint), got "
                f"{shape_str(arr.shape)}"
            )
        data = self.model.createData()
        gdata = pin.GeometryData(self._self_geometry)
        pin.computeDistances(self.model, data, self._self_geometry, gdata, arr)
        return np.array([r.min_distance for r in gdata.distanceResults], dtype=np.float64)


# --------------------------------------------------------------------------------------------
# building
# --------------------------------------------------------------------------------------------


def _frame_id(model: Any, name: str) -> int:
    """A frame's id; a link and a joint may share a name: prefer the link (BODY) frame."""
    if model.existFrame(name, pin.FrameType.BODY):
        return int(model.getFrameId(name, pin.FrameType.BODY))
    return int(model.getFrameId(name))


def _joints_to_lock(full: Any, tip: str) -> list[int]:
    """The joints of ``full`` off the path from the root to the frame ``tip``."""
    supports = set(full.supports[full.frames[_frame_id(full, tip)].parentJoint])
    return [j for j in range(1, full.njoints) if j not in supports]


def has_collision_elements(root: ET.Element) -> bool:
    """Whether a URDF (parsed) has a ``<collision>`` with a ``<geometry>`` on a link."""
    return any(
        col.find("geometry") is not None
        for link in root.findall("link")
        for col in link.findall("collision")
    )


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 300 else f"{text[:200]}...{text[-80:]}"


def _mesh_candidates(filename: str, mesh_dir: Path | None) -> list[Path]:
    """Where a mesh ``filename`` of a URDF may be: ``package://pkg/rest`` in the
    ``ROS_PACKAGE_PATH`` folders (``dir/pkg/rest``, or ``dir/rest`` for a folder named pkg)
    and ROS 2's ``AMENT_PREFIX_PATH`` (``prefix/share/pkg/rest``); ``file://`` and absolute
    paths as they are; relative paths in ``mesh_dir``."""
    if filename.startswith("package://"):
        pkg, _, rest = filename[len("package://") :].partition("/")
        out: list[Path] = []
        for d in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
            out.append(Path(d) / pkg / rest)
            if Path(d).name == pkg:
                out.append(Path(d) / rest)
        for d in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
            out.append(Path(d) / "share" / pkg / rest)
        return out
    if filename.startswith("file://"):
        return [Path(unquote(filename[len("file://") :]))]
    path = Path(filename)
    if path.is_absolute():
        return [path]
    return [] if mesh_dir is None else [mesh_dir / path]


def _resolve_meshes(root: ET.Element, mesh_dir: Path | None) -> None:
    """Replace the file name of every collision ``<mesh>`` by the absolute path of the file
    (see :func:`_mesh_candidates`); a one-line ValueError naming it if there is none."""
    for link in root.findall("link"):
        for mesh in (m for col in link.findall("collision") for m in col.iter("mesh")):
            name = mesh.get("filename", "")
            where = f"collision mesh {short(name)} of link {short(link.get('name', ''))}"
            if not name:
                raise ValueError(f"{where} has no filename; give <mesh filename=...>")
            candidates = _mesh_candidates(name, mesh_dir)
            found = next((p for p in candidates if p.is_file()), None)
            if found is not None:
                mesh.set("filename", str(found.resolve()))
                continue
            if candidates:
                looked = ", ".join(short(str(p)) for p in candidates[:3])
                hint = f"looked for {looked}"
            elif name.startswith("package://"):
                hint = "set ROS_PACKAGE_PATH (or AMENT_PREFIX_PATH) to the folders of its package"
            else:
                hint = (
                    "the path is relative and the URDF was given as text: load the URDF from its "
                    "file (Robot.from_urdf(path)) or give the mesh an absolute path"
                )
            raise ValueError(f"{where} not found ({hint})")


def build_collision_model(
    urdf: str,
    tip: str,
    srdf_disabled: frozenset[LinkPair],
    mesh_dir: Path | None,
    reference: Any,
) -> CollisionModel:
    """The collision model of a robot's URDF text (see :class:`CollisionModel`).

    Parameters
    ----------
    urdf : str
        ``robot.urdf`` (normalized already).
    tip : str
        ``robot.tip``.
    srdf_disabled : frozenset of (str, str)
        The SRDF's disabled pairs.
    mesh_dir : pathlib.Path, optional
        The folder relative mesh paths are in (the URDF file's).
    reference : pinocchio.Model
        The robot's reduced model, which the result's ``model`` must equal joint for joint.
    """
    root = _parse_urdf(urdf)
    _resolve_meshes(root, mesh_dir)
    pin_xml, _ = _pinocchio_xml(root, ET.tostring(root, encoding="unicode"))
    full = pin.buildModelFromXML(pin_xml)
    try:
        full_geometry = pin.buildGeomFromUrdfString(full, pin_xml, pin.GeometryType.COLLISION)
    except (RuntimeError, ValueError) as exc:
        raise ValueError(
            f"the collision geometry of URDF {short(root.get('name', ''))} could not be "
            f"built: {_one_line(exc)}"
        ) from exc
    links = tuple(str(full.frames[o.parentFrame].name) for o in full_geometry.geometryObjects)
    to_lock = _joints_to_lock(full, tip)
    if to_lock:
        model, geometry = pin.buildReducedModel(full, full_geometry, to_lock, pin.neutral(full))
    else:
        model, geometry = full, full_geometry
    same = (
        model.nq == reference.nq
        and list(model.names) == list(reference.names)
        and all(
            model.jointPlacements[i].isApprox(reference.jointPlacements[i], 0.0)
            for i in range(model.njoints)
        )
    )
    if not same:  # pragma: no cover (the robot's model is built from the same text)
        raise AssertionError("the collision model's joints differ from the robot's")
    body_of = {
        link: int(o.parentJoint) for link, o in zip(links, geometry.geometryObjects, strict=True)
    }
    adjacent = frozenset(_adjacent_pairs(root, body_of))
    disabled = adjacent | srdf_disabled
    self_pairs = tuple(
        (i, j)
        for i in range(len(links))
        for j in range(i + 1, len(links))
        if links[i] != links[j] and _pair(links[i], links[j]) not in disabled
    )
    return CollisionModel(
        model=model,
        geometry=geometry,
        links=links,
        self_pairs=self_pairs,
        disabled=disabled,
        adjacent=adjacent,
        tip_frame=_frame_id(model, tip),
    )


def _adjacent_pairs(root: ET.Element, body_of: dict[str, int]) -> set[LinkPair]:
    """Pairs of links with geometry (``body_of``: link -> the joint of the reduced model that
    carries it) joined by a joint, also through links without geometry (MoveIt's connection
    graph), or carried by the same joint (they move as one body)."""
    neighbours: dict[str, set[str]] = defaultdict(set)
    for joint in root.findall("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        if parent is not None and child is not None:
            p, c = parent.get("link", ""), child.get("link", "")
            neighbours[p].add(c)
            neighbours[c].add(p)
    pairs: set[LinkPair] = set()
    for link in body_of:
        seen, stack = {link}, list(neighbours[link])
        while stack:
            other = stack.pop()
            if other in seen:
                continue
            seen.add(other)
            if other in body_of:
                pairs.add(_pair(link, other))
            else:  # no geometry: look through it
                stack.extend(neighbours[other])
    names = sorted(body_of)
    for i, a in enumerate(names):
        pairs.update(_pair(a, b) for b in names[i + 1 :] if body_of[a] == body_of[b])
    return pairs
