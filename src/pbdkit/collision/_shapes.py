"""Obstacles and the shapes of the skill's objects: :class:`Box`, :class:`Sphere`,
:class:`Cylinder` and the :class:`Scene` that holds them (private; public as ``pbdkit.Scene``
etc.).

A shape's pose is in the robot's base frame: a position (3,), a 4x4 transform, or
(x, y, z, qw, qx, qy, qz) with the quaternion w first (as every placement in pbdkit). A box's
``size`` holds its full side lengths along its own x, y, z; a cylinder's axis is its own z, and
``length`` its full length, centred on its pose (the URDF's and coal's convention).

A scene file is YAML, read with the safe loader only and at most :data:`MAX_SCENE_BYTES`::

    shapes:
      - {type: box, name: table, size: [1.2, 0.8, 0.04], pose: [0.3, 0, -0.02, 1, 0, 0, 0]}
      - {type: cylinder, name: post, radius: 0.03, length: 0.4, pose: [0.5, 0.3, 0.2]}
    objects:            # optional: the skill's objects get a shape, in the object's own frame
      glass: {type: cylinder, radius: 0.035, length: 0.1, pose: [0, 0, 0.05]}
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._io import atomic_write_bytes
from .._rotations import as_pose, pose_matrix, quaternion_from_matrix
from .._validation import short
from .._yaml import parse_yaml, read_capped_text

__all__ = ["MAX_SCENE_BYTES", "MAX_SHAPES", "Box", "Cylinder", "Scene", "Shape", "Sphere"]

Float = NDArray[np.float64]

#: The largest scene file read (bytes): a scene of a few hundred shapes is a few tens of KB.
MAX_SCENE_BYTES = 1024 * 1024

#: The most shapes a scene holds (each is checked against every link at every step).
MAX_SHAPES = 1000

#: The largest side, radius or length accepted (m): larger is a typo, not a room.
MAX_EXTENT = 1000.0


def _extent(value: object, name: str) -> float:
    """A side, radius or length: a finite number in (0, MAX_EXTENT] m."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number (m), got {short(value)}")
    out = float(value)
    if not (0.0 < out <= MAX_EXTENT):
        raise ValueError(f"{name} must be > 0 and at most {MAX_EXTENT:g} m, got {short(value)}")
    return out


class Shape:
    """A primitive shape with a pose (the base class of :class:`Box`, :class:`Sphere` and
    :class:`Cylinder`).

    Attributes
    ----------
    pose : ndarray, shape (4, 4)
        Its frame in the robot's base frame (read-only).
    name : str or None
        Its name in collision reports (a :class:`Scene` names unnamed shapes ``box_0`` ...).
    """

    kind: ClassVar[str] = ""

    def __init__(self, pose: npt.ArrayLike, name: str | None) -> None:
        if name is not None and (not isinstance(name, str) or not name.strip()):
            raise ValueError(
                f"{self.kind} name must be a non-empty string or None, got {short(name)}"
            )
        position, rotation = as_pose(pose, f"{self.kind} pose")
        self.pose: Float = pose_matrix(position, rotation)
        self.pose.flags.writeable = False
        self.name = name

    def _extents(self) -> dict[str, Any]:
        raise NotImplementedError

    def geometry(self) -> Any:
        """The coal collision geometry of the shape, in its own frame."""
        raise NotImplementedError

    def with_pose(self, pose: npt.ArrayLike) -> Shape:
        """The same shape at another pose (same name)."""
        return type(self)(**self._extents(), pose=pose, name=self.name)

    def with_name(self, name: str) -> Shape:
        """The same shape under another name."""
        return type(self)(**self._extents(), pose=self.pose, name=name)

    def to_dict(self) -> dict[str, Any]:
        """The shape as a scene file's entry (pose as x, y, z, qw, qx, qy, qz)."""
        quat = quaternion_from_matrix(self.pose[:3, :3])
        entry: dict[str, Any] = {"type": self.kind}
        if self.name is not None:
            entry["name"] = self.name
        for key, value in self._extents().items():
            entry[key] = [float(v) for v in value] if key == "size" else float(value)
        entry["pose"] = [float(v) for v in (*self.pose[:3, 3], *quat)]
        return entry

    def __repr__(self) -> str:
        extents = ", ".join(
            f"{k}={np.round(v, 4).tolist() if k == 'size' else round(float(v), 4)}"
            for k, v in self._extents().items()
        )
        position = np.round(self.pose[:3, 3], 4).tolist()
        return f"{type(self).__name__}({extents}, position={position}, name={short(self.name)})"

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        assert isinstance(other, Shape)
        mine, theirs = self._extents(), other._extents()
        return (
            self.name == other.name
            and np.array_equal(self.pose, other.pose)
            and all(np.array_equal(mine[k], theirs[k]) for k in mine)
        )

    __hash__ = None  # type: ignore[assignment]


class Box(Shape):
    """A box of full side lengths ``size`` = (sx, sy, sz) (m) along its own axes, centred on
    its pose."""

    kind = "box"

    def __init__(
        self, size: npt.ArrayLike, pose: npt.ArrayLike = (0.0, 0.0, 0.0), name: str | None = None
    ) -> None:
        try:
            arr = np.asarray(size, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"box size must be 3 side lengths (m), got {short(size)}") from None
        if arr.shape != (3,):
            raise ValueError(f"box size must be 3 side lengths (m), got {short(size)}")
        self.size: Float = np.array([_extent(v, "box size") for v in arr])
        self.size.flags.writeable = False
        super().__init__(pose, name)

    def _extents(self) -> dict[str, Any]:
        return {"size": self.size}

    def geometry(self) -> Any:
        import coal

        return coal.Box(*self.size)


class Sphere(Shape):
    """A sphere of ``radius`` (m) centred on its pose."""

    kind = "sphere"

    def __init__(
        self, radius: float, pose: npt.ArrayLike = (0.0, 0.0, 0.0), name: str | None = None
    ) -> None:
        self.radius = _extent(radius, "sphere radius")
        super().__init__(pose, name)

    def _extents(self) -> dict[str, Any]:
        return {"radius": self.radius}

    def geometry(self) -> Any:
        import coal

        return coal.Sphere(self.radius)


class Cylinder(Shape):
    """A cylinder of ``radius`` and full ``length`` (m) along its own z axis, centred on its
    pose."""

    kind = "cylinder"

    def __init__(
        self,
        radius: float,
        length: float,
        pose: npt.ArrayLike = (0.0, 0.0, 0.0),
        name: str | None = None,
    ) -> None:
        self.radius = _extent(radius, "cylinder radius")
        self.length = _extent(length, "cylinder length")
        super().__init__(pose, name)

    def _extents(self) -> dict[str, Any]:
        return {"radius": self.radius, "length": self.length}

    def geometry(self) -> Any:
        import coal

        return coal.Cylinder(self.radius, self.length)


#: A scene file's shape types -> (class, the keys of its extents).
SHAPE_TYPES: dict[str, tuple[type[Shape], tuple[str, ...]]] = {
    "box": (Box, ("size",)),
    "sphere": (Sphere, ("radius",)),
    "cylinder": (Cylinder, ("radius", "length")),
}


class Scene:
    """What the arm must not hit, and the shapes of the skill's objects.

    Parameters
    ----------
    shapes : iterable of Box, Sphere or Cylinder
        Obstacles, posed in the robot's base frame. Unnamed shapes are named ``box_0``,
        ``sphere_1``, ... by their index; names must be unique.
    objects : dict str -> shape, optional
        A shape for some of the skill's objects, posed in the **object's own frame** (the frame
        its placement gives): wherever the object is placed, its shape is there; while the hand
        holds it, it moves with the hand and is checked as part of the arm. An object's name
        may not be a shape's.

    Examples
    --------
    >>> scene = Scene([Box(size=(1.2, 0.8, 0.04), pose=(0.3, 0.0, -0.02), name="table")],
    ...               objects={"glass": Cylinder(0.035, 0.1, pose=(0, 0, 0.05))})
    >>> scene.names
    ['table']
    """

    def __init__(
        self, shapes: Iterable[Shape] = (), *, objects: Mapping[str, Shape] | None = None
    ) -> None:
        if isinstance(shapes, (Shape, str, bytes, Mapping)):
            raise ValueError(
                f"shapes must be a list of Box, Sphere or Cylinder, got {type(shapes).__name__}"
            )
        named: list[Shape] = []
        for i, shape in enumerate(shapes):
            if i >= MAX_SHAPES:
                raise ValueError(f"shapes: a scene holds at most {MAX_SHAPES} shapes (MAX_SHAPES)")
            if not isinstance(shape, Shape):
                raise ValueError(
                    f"shapes[{i}] must be a Box, Sphere or Cylinder, got {type(shape).__name__}"
                )
            named.append(shape if shape.name is not None else shape.with_name(f"{shape.kind}_{i}"))
        names = [str(s.name) for s in named]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"shapes: names must be unique, {short(twice)} appear more than once")
        objs: dict[str, Shape] = {}
        for key, shape in (objects or {}).items():
            if not isinstance(key, str) or not key:
                raise ValueError(f"objects: names must be non-empty strings, got {short(key)}")
            if not isinstance(shape, Shape):
                raise ValueError(
                    f"objects[{short(key)}] must be a Box, Sphere or Cylinder, got "
                    f"{type(shape).__name__}"
                )
            if key in names:
                raise ValueError(f"objects: {short(key)} is also the name of a shape; rename one")
            objs[key] = shape.with_name(key)
        self.shapes: tuple[Shape, ...] = tuple(named)
        self.objects: dict[str, Shape] = objs

    @property
    def names(self) -> list[str]:
        """The obstacles' names, in order."""
        return [str(s.name) for s in self.shapes]

    def __len__(self) -> int:
        return len(self.shapes)

    def __iter__(self) -> Iterator[Shape]:
        return iter(self.shapes)

    def __repr__(self) -> str:
        objs = f", objects={sorted(self.objects)}" if self.objects else ""
        return f"Scene({len(self.shapes)} shapes: {short(self.names)}{objs})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Scene):
            return NotImplemented
        return self.shapes == other.shapes and self.objects == other.objects

    __hash__ = None  # type: ignore[assignment]

    def with_shapes(self, *shapes: Shape) -> Scene:
        """This scene with more obstacles."""
        return Scene([*self.shapes, *shapes], objects=self.objects)

    def without_objects(self) -> Scene:
        """The obstacles alone (the objects' shapes dropped)."""
        return Scene(self.shapes)

    def to_dict(self) -> dict[str, Any]:
        """The scene as a scene file's mapping."""
        out: dict[str, Any] = {"shapes": [s.to_dict() for s in self.shapes]}
        if self.objects:
            out["objects"] = {
                k: {key: v for key, v in s.to_dict().items() if key != "name"}
                for k, s in self.objects.items()
            }
        return out

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scene as a YAML scene file (atomically, with the user's umask)."""
        import yaml

        text = yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None)
        atomic_write_bytes(path, text.encode("utf-8"))

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Scene:
        """Read a YAML scene file (see the module's docstring for the format).

        Raises
        ------
        ValueError
            A missing file, one over :data:`MAX_SCENE_BYTES`, not YAML, an unknown shape type
            or key, a missing or non-positive size, a pose that is not finite or not a pose;
            the one-line message names the file and the entry.
        """
        label = f"scene file '{Path(path)}'"
        text = read_capped_text(
            Path(path), label, MAX_SCENE_BYTES, "MAX_SCENE_BYTES", "scene YAML file"
        )
        return cls.from_dict(parse_yaml(text, label), label)

    @classmethod
    def from_dict(cls, data: object, label: str = "scene") -> Scene:
        """A scene from the mapping of a scene file (``{"shapes": [...], "objects": {...}}``)."""
        if data is None:
            data = {}
        if not isinstance(data, Mapping):
            raise ValueError(
                f"{label}: expected a mapping with 'shapes', got {type(data).__name__}"
            )
        unknown = sorted(str(k) for k in data if k not in ("shapes", "objects"))
        if unknown:
            raise ValueError(f"{label}: unknown keys {short(unknown)}; expected shapes, objects")
        entries = data.get("shapes") or []
        if not isinstance(entries, list):
            raise ValueError(f"{label}: 'shapes' must be a list, got {type(entries).__name__}")
        if len(entries) > MAX_SHAPES:
            raise ValueError(f"{label}: {len(entries)} shapes, over the cap of {MAX_SHAPES}")
        objects = data.get("objects") or {}
        if not isinstance(objects, Mapping):
            raise ValueError(f"{label}: 'objects' must be a mapping, got {type(objects).__name__}")
        shapes = [_shape_from_entry(e, f"{label}: shapes[{i}]") for i, e in enumerate(entries)]
        objs = {
            str(k): _shape_from_entry(e, f"{label}: objects[{short(k)}]", named=False)
            for k, e in objects.items()
        }
        try:
            return cls(shapes, objects=objs)
        except ValueError as exc:
            raise ValueError(f"{label}: {exc}") from None


def _shape_from_entry(entry: object, where: str, *, named: bool = True) -> Shape:
    """One shape of a scene file."""
    if not isinstance(entry, Mapping):
        raise ValueError(f"{where} must be a mapping with a type, got {type(entry).__name__}")
    kind = entry.get("type")
    if kind not in SHAPE_TYPES:
        raise ValueError(f"{where}: type must be one of {sorted(SHAPE_TYPES)}, got {short(kind)}")
    cls, keys = SHAPE_TYPES[str(kind)]
    allowed = {"type", "pose", *keys, *(("name",) if named else ())}
    unknown = sorted(str(k) for k in entry if k not in allowed)
    if unknown:
        raise ValueError(
            f"{where} ({kind}): unknown keys {short(unknown)}; expected {sorted(allowed)}"
        )
    missing = [k for k in keys if k not in entry]
    if missing:
        raise ValueError(f"{where} ({kind}): missing {', '.join(missing)}")
    pose = entry.get("pose", [0.0, 0.0, 0.0])
    if not isinstance(pose, list) or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in pose
    ):
        raise ValueError(
            f"{where} ({kind}): pose must be a list [x, y, z] or [x, y, z, qw, qx, qy, qz], "
            f"got {short(pose)}"
        )
    if any(isinstance(v, float) and not math.isfinite(v) for v in pose):
        raise ValueError(f"{where} ({kind}): pose must be finite, got {short(pose)}")
    name = entry.get("name")
    if named and name is not None and not isinstance(name, str):
        raise ValueError(f"{where} ({kind}): name must be a string, got {short(name)}")
    kwargs = {k: entry[k] for k in keys}
    try:
        return cls(**kwargs, pose=pose, name=name)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
