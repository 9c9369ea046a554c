"""Tasks as data: a :class:`TaskSpec` per task and the records it is made of.

A task is one :class:`TaskSpec`: where its objects may be placed (:class:`PlacementRange`), how
they are built in the simulated world, how the simulated teacher demonstrates it
(:class:`ViaPoint`) and how a run is judged (:class:`Outcome` from :class:`RunStats`), with its
cameras (:class:`CameraRig`) and disturbances (:class:`ObjectMove`, :class:`ObjectTurn`). Specs
are registered by name in :mod:`pbdkit.sim._task_registry`; a name becomes its spec once, at the
edge (the command line, :func:`pbdkit.sim.evaluate`), and everything below takes the spec.

All positions are in the robot's base frame (metres, z up, the table top at z = 0); ranges are
boxes ``(low, high)`` and a range whose low and high are equal is a fixed object: the ranges are
the one place that says which objects move (:attr:`TaskSpec.tracked_objects`, tracked by the
cameras and constrained in task space) and which do not (:attr:`TaskSpec.fixed_objects`, the
basin). Frames, reference points and how to write a task, with an example: the docs page
"Writing a task" (``docs/tasks.md``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import yaw_of
from .._validation import check_positions, short
from ..data._placement import check_placements, is_pose, position_of
from ._glass import patch_prefix

__all__ = [
    "CameraRig",
    "ObjectMove",
    "ObjectTurn",
    "Outcome",
    "PlacementRange",
    "RunStats",
    "TaskSpec",
    "ViaPoint",
    "check_task",
    "yaw_of",
    "yaw_pose",
]

Float = NDArray[np.float64]


@dataclass(frozen=True)
class PlacementRange:
    """Range of placements of one object: a box of positions, and for an object that turns a
    range of yaws; uniform sampling.

    Attributes
    ----------
    low, high : ndarray, shape (3,)
        Corners of the box (equal for a fixed object).
    yaw : tuple of float, optional
        (low, high) yaw about the vertical (rad) for an object placed as a pose: its placements
        are then 4x4 transforms (:mod:`pbdkit.data._placement`); None (default): positions.
    """

    low: Float
    high: Float
    yaw: tuple[float, float] | None = None

    @classmethod
    def box(
        cls,
        low: tuple[float, float, float],
        high: tuple[float, float, float],
        yaw: tuple[float, float] | None = None,
    ) -> PlacementRange:
        """The box between two corners given as tuples (and a yaw range, rad, for a pose)."""
        return cls(
            np.array(low, dtype=np.float64),
            np.array(high, dtype=np.float64),
            None if yaw is None else (float(yaw[0]), float(yaw[1])),
        )

    @property
    def posed(self) -> bool:
        """True if the object is placed as a pose (it has a yaw range)."""
        return self.yaw is not None

    def sample(self, rng: np.random.Generator, yaw_stratum: tuple[int, int] | None = None) -> Float:
        """A placement drawn uniformly: a position (3,), or a 4x4 pose for a posed range
        (position first, then yaw, from ``rng``). ``yaw_stratum`` (i, n): the yaw is drawn in
        the i-th of n equal parts of the yaw range (so that n draws span it)."""
        p = rng.uniform(self.low, self.high)
        if self.yaw is None:
            return p
        u = float(rng.uniform())
        if yaw_stratum is not None:
            u = (yaw_stratum[0] + u) / yaw_stratum[1]
        return yaw_pose(p, self.yaw[0] + (self.yaw[1] - self.yaw[0]) * u)

    def nominal(self) -> Float:
        """The centre: a position (3,), or the pose at the centre of the yaw range."""
        if self.yaw is None:
            return self.center.copy()
        return yaw_pose(self.center, 0.5 * (self.yaw[0] + self.yaw[1]))

    @property
    def fixed(self) -> bool:
        """True if the object never moves."""
        return bool(np.array_equal(self.low, self.high))

    @property
    def center(self) -> Float:
        """Centre of the box, shape (3,)."""
        return 0.5 * (self.low + self.high)

    def contains(self, position: Float, tol: float = 1e-9) -> bool:
        """True if ``position`` (3,) lies in the box (up to ``tol``); for a pose (4, 4), its
        position in the box and its yaw in the yaw range."""
        p = np.asarray(position, dtype=np.float64)
        if p.shape == (4, 4):
            yaw = math.atan2(float(p[1, 0]), float(p[0, 0]))
            if self.yaw is None or not self.yaw[0] - tol <= yaw <= self.yaw[1] + tol:
                return False
            p = p[:3, 3]
        return bool(np.all(p >= self.low - tol) and np.all(p <= self.high + tol))


def yaw_pose(position: npt.ArrayLike, yaw: float) -> Float:
    """The 4x4 pose at ``position`` turned by ``yaw`` (rad) about the vertical."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:3, 3] = np.asarray(position, dtype=np.float64)
    return out


@dataclass(frozen=True)
class ViaPoint:
    """A waypoint of the teacher's hand (what a task's ``via_points`` returns).

    Attributes
    ----------
    duration : float
        Time (s) to reach it from the previous via point (minimum-jerk profile).
    x : ndarray, shape (3,)
        Tool point.
    pitch, roll : float
        Tool pitch and wrist roll (rad).
    gripper : bool
        Gripper state (closed if True) during the motion to this via point.
    free_pitch : bool
        The pitch is a preference only: if the arm cannot reach ``x`` with it, the nearest
        reachable pitch is used (a person adapts the posture; the glass is not held then).
    joint_space : bool
        Interpolate the segment to this via point in joint space (a free gesture) instead of
        in task space (a controlled hand path).
    """

    duration: float
    x: Float
    pitch: float
    roll: float
    gripper: bool
    free_pitch: bool = False
    joint_space: bool = False


@dataclass(frozen=True)
class Outcome:
    """Success of a run and its measurements (what a task's ``judge`` returns).

    Attributes
    ----------
    success : bool
    metrics : dict str -> float
        The task's measurements, named with their unit (e.g. ``placement_error_mm``,
        ``tilt_deg``); see the task's judge.
    """

    success: bool
    metrics: dict[str, float]


@dataclass(frozen=True)
class RunStats:
    """What a judge may need beyond the final state: measured while the trajectory played.

    Attributes
    ----------
    held_at_end : bool
        Both fingers touched the grasped object at the end of the trajectory (before the
        settling time).
    max_tilt : float
        Largest tilt of the grasped object's axis from the vertical during the run (rad).
    """

    held_at_end: bool
    max_tilt: float


#: ``add_objects(world, objects, rng)``: add the task's bodies to the MjSpec worldbody.
AddObjects = Callable[[Any, Mapping[str, Float], np.random.Generator], None]
#: ``via_points(objects, rng, speed)``: the teacher's via points for a placement.
ViaPoints = Callable[[Mapping[str, Float], np.random.Generator, float], list[ViaPoint]]
#: ``judge(sim, run)``: the outcome of a run, from the final state of the simulation
#: (a :class:`pbdkit.sim.Simulation`, which builds on this module) and the run's
#: measurements.
Judge = Callable[[Any, RunStats], Outcome]

#: ``scene(objects) -> pbdkit.Scene``: what the arm must not hit for a placement (its obstacles,
#: and its objects' shapes in their own frames).
SceneOf = Callable[[Mapping[str, Float]], Any]


@dataclass(frozen=True)
class CameraRig:
    """Where a task's stereo pair stands (:attr:`TaskSpec.cameras`): two 320x240 cameras
    ``cam_left`` and ``cam_right`` looking at one point.

    Attributes
    ----------
    left, right : tuple of float
        Positions (x, y, z) of the cameras ``cam_left`` and ``cam_right``, base frame (m).
    target : tuple of float
        The point both look at (the image centres' rays meet there; the horizon stays level).
    fovy : float
        Vertical field of view (degrees).
    """

    left: tuple[float, float, float]
    right: tuple[float, float, float]
    target: tuple[float, float, float]
    fovy: float

    def __post_init__(self) -> None:
        pts = {}
        for what in ("left", "right", "target"):
            p = tuple(float(v) for v in getattr(self, what))
            if len(p) != 3 or not all(math.isfinite(v) for v in p):
                raise ValueError(f"CameraRig.{what} must be 3 finite numbers, got {short(p)}")
            object.__setattr__(self, what, p)
            pts[what] = np.array(p)
        if not (0.0 < float(self.fovy) < 180.0):
            raise ValueError(f"CameraRig.fovy must be in (0, 180) degrees, got {short(self.fovy)}")
        object.__setattr__(self, "fovy", float(self.fovy))
        if np.array_equal(pts["left"], pts["right"]):
            raise ValueError("CameraRig.left and right must be different positions")
        for what in ("left", "right"):
            d = pts["target"] - pts[what]
            if np.linalg.norm(d[:2]) < 1e-6:
                raise ValueError(
                    f"CameraRig.{what} must not look straight up or down (its horizon is level)"
                )

    def position(self, camera: str) -> tuple[float, float, float]:
        """Position of ``camera`` ("cam_left" or "cam_right")."""
        if camera == "cam_left":
            return self.left
        if camera == "cam_right":
            return self.right
        raise ValueError(f"camera must be 'cam_left' or 'cam_right', got {short(camera)}")


class _GraspedPatch(dict[str, str]):
    """``TaskSpec.patches`` left out: filled in with the grasped glass's red band only."""


def _check_patch(
    task: str, obj: str, prefix: object, posed: bool, moves: bool
) -> str | tuple[str, str]:
    """``TaskSpec.patches[obj]`` checked: a non-empty prefix, or for an object placed as a
    pose a pair of two different ones (required when it moves: the cameras track it; a fixed
    one may name one prefix for all its patches' geoms)."""
    if posed and (moves or not isinstance(prefix, str)):
        if (
            not isinstance(prefix, (tuple, list))
            or len(prefix) != 2
            or not all(isinstance(p, str) and p for p in prefix)
            or prefix[0] == prefix[1]
        ):
            raise ValueError(
                f"patches[{short(obj)}] of task {short(task)}: {short(obj)} is placed as a pose "
                "(its range has "
                "a yaw), so the cameras need two patches, one at each end: a pair (prefix_a, "
                f"prefix_b) of different geom name prefixes, the yaw pointing from a to b; got "
                f"{short(prefix)}"
            )
        return (prefix[0], prefix[1])
    if not isinstance(prefix, str) or not prefix:
        raise ValueError(
            f"patches[{short(obj)}] of task {short(task)} must be the name prefix of its patch's "
            "geoms (a "
            f"non-empty string; a pair is for an object placed as a pose), got {short(prefix)}"
        )
    return prefix


@dataclass(frozen=True)
class ObjectMove:
    """A task's ``move`` disturbance (``pbdkit evaluate --perturb move``): an object slides.

    Attributes
    ----------
    obj : str
        The object that slides on its support (the glass, a free body; or an object the task
        builds as a MuJoCo mocap body, such as the coaster).
    distance : float
        Horizontal length of the slide (m).
    when : str
        ``"before_grasp"``: the slide ends before the hand reaches the glass;
        ``"while_carried"``: it happens while the glass is held (see
        :func:`pbdkit.sim._perturb.make_disturbance` for the timing).
    """

    obj: str
    distance: float
    when: str

    def __post_init__(self) -> None:
        if self.when not in ("before_grasp", "while_carried"):
            raise ValueError(
                f"when must be 'before_grasp' or 'while_carried', got {short(self.when)}"
            )
        if not (self.distance > 0):
            raise ValueError(f"distance must be > 0 (m), got {short(self.distance)}")


@dataclass(frozen=True)
class ObjectTurn:
    """A task's ``rotate`` disturbance (``pbdkit evaluate --perturb rotate``): an object turns
    about the vertical through its reference point (its centre), staying in its yaw range.

    Attributes
    ----------
    obj : str
        The object that turns: one placed as a pose (its range has a yaw,
        :attr:`PlacementRange.yaw`), built as a MuJoCo mocap body (the slot task's tray).
    degrees : tuple of float
        (min, max): the size of the turn is drawn uniformly in it (degrees, 0 < min <= max);
        the direction is one that keeps the object's yaw inside its range (see
        :func:`pbdkit.sim._perturb.make_disturbance`).
    when : str
        ``"before_grasp"``: the turn ends before the hand reaches the grasped object;
        ``"while_carried"``: it happens while the grasped object is held (timed as
        :class:`ObjectMove`).
    """

    obj: str
    degrees: tuple[float, float]
    when: str = "while_carried"

    def __post_init__(self) -> None:
        if self.when not in ("before_grasp", "while_carried"):
            raise ValueError(
                f"when must be 'before_grasp' or 'while_carried', got {short(self.when)}"
            )
        try:
            lo, hi = (float(v) for v in self.degrees)
        except (TypeError, ValueError):
            raise ValueError(
                f"degrees must be (min, max) in degrees, got {short(self.degrees)}"
            ) from None
        if not (math.isfinite(hi) and 0.0 < lo <= hi):
            raise ValueError(
                f"degrees must be (min, max) with 0 < min <= max, got {short(self.degrees)}"
            )
        object.__setattr__(self, "degrees", (lo, hi))


@dataclass(frozen=True, eq=False)
class TaskSpec:
    """Everything that makes a task (see the module docstring for how to write one).

    Attributes
    ----------
    name : str
        Registry key (``--task`` on the command line).
    description : str
        What the task is, in a few sentences (the report's first paragraph).
    ranges : dict str -> PlacementRange
        Object name -> placement range, in a fixed order (the order of every placement dict);
        must contain the grasped object. A range with ``low == high`` is a fixed object.
    add_objects : callable
        ``add_objects(world, objects, rng)``: adds the task's bodies, the grasped glass
        included (:func:`pbdkit.sim._world.add_glass` with ``name=grasped``), to
        the worldbody of the MuJoCo ``MjSpec``; ``objects`` holds every object's position
        (3,), ``rng`` seeds any jitter (the liquid's).
    via_points : callable
        ``via_points(objects, rng, speed) -> list[ViaPoint]``: the simulated teacher's hand path
        for a placement (durations scaled by 1 / speed).
    judge : callable
        ``judge(sim, run) -> Outcome``: success and metrics of a run, from the simulation after
        it and its :class:`RunStats`.
    patches : dict str -> str or (str, str)
        For each object the cameras can track, the name prefix of its patch's geoms; default:
        the grasped glass's red band only (``{grasped: patch_prefix(grasped)}``). An object
        placed as a pose (its range has a yaw) that moves has two patches, one at each end:
        the pair ``(prefix_a, prefix_b)``, whose midpoint the cameras locate and whose heading
        from a to b is its yaw (:mod:`pbdkit.sim._tracking`); the other objects have one.
    cameras : CameraRig, optional
        Where the two cameras stand for this task; None (default): the paper's rig
        (:data:`pbdkit.sim._world.CAMERA_POSITIONS`, looking across the table from in front
        of the robot).
    n_liquid : int
        Number of liquid spheres ``add_objects`` puts in the glass (bodies ``liquid0..``).
    move : ObjectMove, optional
        The task's ``move`` disturbance (``--perturb move``); None: the task has none.
    rotate : ObjectTurn, optional
        The task's ``rotate`` disturbance (``--perturb rotate``): an object placed as a pose
        turns; None (default): the task has none. Its largest turn must fit in half the
        object's yaw range (so that one direction always keeps the yaw inside it).
    grasped : str
        The object the gripper holds, a glass built with ``add_glass(..., name=grasped)``: the
        simulation's grasp, tilt and release checks, the record of a run, the online loop's
        held object and the push's direction are about it.
    scene : callable, optional
        ``scene(objects) -> pbdkit.Scene``: the task's obstacles (the table, a shelf, the
        walls of a basin or a tray) for a placement (every object's, as
        :func:`pbdkit.sim._world.build_scene` gets them), and its objects' shapes in their own
        frames. ``evaluate`` checks every run against it (:mod:`pbdkit.sim._obstacle`); None:
        the task declares none (no run is checked).
    """

    name: str
    description: str
    ranges: Mapping[str, PlacementRange]
    add_objects: AddObjects
    via_points: ViaPoints
    judge: Judge
    patches: Mapping[str, str | tuple[str, str]] = field(default_factory=_GraspedPatch)
    cameras: CameraRig | None = None
    n_liquid: int = 0
    move: ObjectMove | None = None
    grasped: str = "glass"
    rotate: ObjectTurn | None = None
    scene: SceneOf | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"name must be a non-empty string, got {short(self.name)}")
        ranges = dict(self.ranges)
        if not isinstance(self.grasped, str) or self.grasped not in ranges:
            raise ValueError(
                f"ranges of task {short(self.name)} must include {short(self.grasped)} (the object "
                "the "
                f"gripper holds, TaskSpec.grasped), got {list(ranges)}"
            )
        if isinstance(self.patches, _GraspedPatch):
            object.__setattr__(self, "patches", {self.grasped: patch_prefix(self.grasped)})
        for obj, r in ranges.items():
            if not isinstance(r, PlacementRange):
                raise ValueError(f"ranges[{short(obj)}] must be a PlacementRange, got {short(r)}")
            if r.low.shape != (3,) or r.high.shape != (3,) or np.any(r.low > r.high):
                raise ValueError(f"ranges[{short(obj)}] must be a box with low <= high, shape (3,)")
        unknown = sorted(set(self.patches) - set(ranges))
        if unknown:
            raise ValueError(
                f"patches of task {short(self.name)} name object(s) {unknown} without a range; "
                f"expected some of {list(ranges)}"
            )
        patches: dict[str, str | tuple[str, str]] = {}
        for obj, prefix in self.patches.items():
            r = ranges[obj]
            patches[obj] = _check_patch(self.name, obj, prefix, r.posed, not r.fixed)
        if self.cameras is not None and not isinstance(self.cameras, CameraRig):
            raise ValueError(
                f"cameras of task {short(self.name)} must be a CameraRig or None (the paper's "
                "rig), "
                f"got {short(self.cameras)}"
            )
        if self.scene is not None and not callable(self.scene):
            raise ValueError(f"scene of task {short(self.name)} must be callable or None")
        if self.n_liquid < 0:
            raise ValueError(f"n_liquid must be >= 0, got {self.n_liquid}")
        if self.move is not None and (
            not isinstance(self.move, ObjectMove) or self.move.obj not in ranges
        ):
            raise ValueError(
                f"move of task {short(self.name)} must be an ObjectMove of one of its objects "
                f"{list(ranges)}, got {short(self.move)}"
            )
        if self.rotate is not None:
            _check_turn(self.name, self.rotate, ranges)
        for what in ("add_objects", "via_points", "judge"):
            if not callable(getattr(self, what)):
                raise ValueError(f"{what} of task {short(self.name)} must be callable")
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "patches", patches)

    def __repr__(self) -> str:
        return f"TaskSpec(name={short(self.name)}, objects={list(self.ranges)})"

    @property
    def tracked_objects(self) -> tuple[str, ...]:
        """Objects that move between placements, in range order (the cameras track them)."""
        return tuple(name for name, r in self.ranges.items() if not r.fixed)

    @property
    def fixed_objects(self) -> tuple[str, ...]:
        """Objects that never move, in range order; known without vision."""
        return tuple(name for name, r in self.ranges.items() if r.fixed)

    def patch_ends(self, name: str) -> tuple[str, str] | None:
        """The two patches' prefixes (end a, end b) of a posed object ``name``, or None for an
        object with one patch (ValueError for one without a patch)."""
        if name not in self.patches:
            raise ValueError(
                f"objects: no colored patch is known for {short(name)} in the {short(self.name)} "
                "task; "
                f"expected one of {sorted(self.patches)}"
            )
        prefix = self.patches[name]
        return None if isinstance(prefix, str) else prefix

    @property
    def posed_objects(self) -> tuple[str, ...]:
        """Objects placed as poses (with a yaw range), in range order."""
        return tuple(name for name, r in self.ranges.items() if r.posed)

    def nominal_objects(self) -> dict[str, Float]:
        """Centre of every placement range: name -> position (3,), or pose (4, 4) at the
        centre of its yaw range."""
        return {name: r.nominal() for name, r in self.ranges.items()}

    def sample_objects(
        self, rng: np.random.Generator, yaw_strata: Mapping[str, tuple[int, int]] | None = None
    ) -> dict[str, Float]:
        """Placements drawn uniformly inside the ranges, name -> (3,) or (4, 4) (fixed objects
        at their place; they still take their draws from ``rng``); ``yaw_strata``: for some
        posed objects, the part (i, n) of the yaw range to draw from
        (:meth:`PlacementRange.sample`)."""
        strata = yaw_strata or {}
        return {name: r.sample(rng, strata.get(name)) for name, r in self.ranges.items()}

    def check_placement(
        self, objects: Mapping[str, npt.ArrayLike], *, fill_moving: bool = False
    ) -> dict[str, Float]:
        """The one validator of a task's object positions: every object, in range order.

        Positions are checked by :func:`pbdkit._validation.check_positions` (names, (3,),
        finite); an object the task does not have is an error; a fixed object must be at its
        fixed place (within 1e-6 m) and is filled in when left out; a moving object left out
        is an error, or its range's centre with ``fill_moving``.
        """
        if self.posed_objects:
            given = check_placements(objects, "objects")
            for k, v in given.items():
                r = self.ranges.get(k)
                if r is not None and r.posed != is_pose(v):
                    want = "a pose (4x4 or x, y, z, qw, qx, qy, qz)" if r.posed else "a position"
                    raise ValueError(
                        f"objects[{short(k)}] must be {want} for task {short(self.name)}, got "
                        f"{'a pose' if is_pose(v) else 'a position'}"
                    )
        else:
            given = check_positions(objects, "objects")
        unknown = [k for k in given if k not in self.ranges]
        if unknown:
            raise ValueError(
                f"objects: unknown object(s) {unknown} for task {short(self.name)}; expected "
                f"{list(self.ranges)}"
            )
        missing = [k for k in self.tracked_objects if k not in given]
        if missing and not fill_moving:
            raise ValueError(
                f"objects: missing position(s) for {missing}: they move between placements, so "
                f"the {short(self.name)} task needs them (only fixed objects "
                f"{list(self.fixed_objects)} are known)"
            )
        out: dict[str, Float] = {}
        for name, r in self.ranges.items():
            if name not in given:
                out[name] = r.nominal()  # a fixed range's centre is its place
                continue
            if r.fixed and not np.allclose(position_of(given[name]), r.low, rtol=0.0, atol=1e-6):
                raise ValueError(
                    f"objects[{short(name)}]: the {name} is fixed at {r.low.tolist()}, "
                    f"got {given[name].tolist()}"
                )
            out[name] = given[name]
        return out

    def full_placement(self, objects: Mapping[str, npt.ArrayLike]) -> dict[str, Float]:
        """Every object's placement: ``objects`` plus the fixed objects' positions.

        Use it where a subset of the objects is known (e.g. those of a skill that has no
        constraint on the fixed ones) and the whole scene is needed (the simulation, the
        success judge).

        Parameters
        ----------
        objects : dict str -> array-like, shape (3,) or a pose
            Placements of at least every moving object (:attr:`tracked_objects`); fixed
            objects may be given too (they must then be at their place).

        Returns
        -------
        placement : dict str -> ndarray, shape (3,) or (4, 4)
            One placement per object of the task, in range order.

        Raises
        ------
        ValueError
            An object that is not one of the task's, or a moving object without a position.
        """
        return self.check_placement(objects)


def _check_turn(task: str, turn: object, ranges: Mapping[str, PlacementRange]) -> None:
    """Refuse a ``rotate`` that is not an :class:`ObjectTurn` of an object placed as a pose,
    or a turn larger than half its yaw range."""
    if not isinstance(turn, ObjectTurn) or turn.obj not in ranges:
        raise ValueError(
            f"rotate of task {short(task)} must be an ObjectTurn of one of its objects "
            f"{list(ranges)}, got {short(turn)}"
        )
    yaw = ranges[turn.obj].yaw
    if yaw is None:
        raise ValueError(
            f"rotate of task {short(task)} turns {short(turn.obj)}, which is placed as a position: "
            "it "
            "needs a yaw range (PlacementRange.yaw)"
        )
    half = 0.5 * math.degrees(yaw[1] - yaw[0])
    if turn.degrees[1] > half + 1e-9:
        raise ValueError(
            f"rotate of task {short(task)}: a turn of up to {turn.degrees[1]:g} degrees does not "
            "fit "
            f"in {short(turn.obj)}'s yaw range from everywhere in it (at most half its width, "
            f"{half:g} degrees)"
        )


def check_task(task: object, name: str = "task") -> TaskSpec:
    """``task`` if it is a :class:`TaskSpec`; else a ValueError that says how to get one (a
    registered name is resolved at the edge, :func:`pbdkit.sim.get_task`)."""
    if not isinstance(task, TaskSpec):
        raise ValueError(
            f"{name} must be a TaskSpec (pbdkit.sim.get_task turns a registered name into its "
            f"spec), got {short(task)}"
        )
    return task
