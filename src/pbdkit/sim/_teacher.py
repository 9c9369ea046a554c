"""A simulated teacher: kinesthetic-style demonstrations of a task on the Katana.

A person moving the arm by hand goes through a few task-space via points with the timing, the
detours and the posture of the moment. The teacher reproduces that: for random object placements
(inside the task's :attr:`pbdkit.sim.TaskSpec.ranges`) it asks the task for its via points
relative to the objects (:attr:`pbdkit.sim.TaskSpec.via_points`, with durations, via-point
jitter and a tool pitch per via point drawn by a :class:`Person`), solves each via point by damped
least-squares inverse kinematics on :func:`pbdkit.robots.katana` and interpolates with
minimum-jerk profiles, sampled at 100 Hz (the encoders' record): in task space where the hand's
path matters (holding the glass: straight lines at a constant pitch), in joint space for free
swings and for the radial approach (constant pan keeps the open fingers around the glass).
:func:`teach_one` is one demonstration for given placements; :func:`pbdkit.sim.teach` draws the
placements of several.

Structure, so that the paper's constraints emerge (Sec. III; the via points of each task are in
its module, :mod:`pbdkit.sim._taskdefs`):

- coaster: start posture -> approach the glass on the shelf from the robot's side and grasp it (the
  tool on the glass's axis: tight relative to the glass) -> lift -> carry (free via point) -> place
  it on the coaster (tight relative to the coaster) -> release -> retreat;
- basin: start posture -> grasp the glass on the table (tight relative to the glass) -> carry above
  the fixed basin -> tilt it by a wrist-roll gesture whose angle profile is the same in every
  demonstration (a joint-space constraint) -> hold while the liquid pours into the basin (the end).

The grasp is common to every task (:func:`grasp_via_points`): a side grasp, the tool axis nearly
horizontal (pitch :data:`GRASP_PITCH`, 8.6 deg down: level needs more reach than the near part of
the ranges allows), pointing radially away from the base, fingers closing horizontally. The pitch
is kept while the glass is held, so the glass stays upright while the roll is neutral, and rolling
about the tool axis tips it sideways.

Katana specifics used here: the tool pitch (elevation of the tool axis above the horizontal) is
``lift1 + lift2 - lift3`` (the three lifts are parallel axes; lift3's axis is flipped by its
``rpy = (pi, 0, 0)``) and the roll is ``wrist_roll`` itself. Position (3) + pitch + roll are five
equations for five joints; the pitch, free for the position task, is the posture (null-space)
choice the teacher varies between demonstrations.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import short
from ..data._demonstration import Demonstration
from ..robots import katana
from ..robots._ik import damped_least_squares
from ..robots._robot import Robot
from ._glass import GRASP_OFFSET
from ._tasks import TaskSpec, ViaPoint

Float = NDArray[np.float64]

RATE = 100.0  # Hz, encoder sampling rate
# Row of d(pitch)/d(theta) for the Katana (see the module docstring).
PITCH_ROW: Float = np.array([0.0, 1.0, 1.0, -1.0, 0.0])
ROLL_ROW: Float = np.array([0.0, 0.0, 0.0, 0.0, 1.0])
_TOOL_ROWS: Float = np.array([PITCH_ROW, ROLL_ROW])  # the IK's rows after the position's
APPROACH = 0.07  # m, pre-grasp distance along the tool axis (fingertips clear the glass)
# Pitch at which the glass is held (tool axis 8.6 deg below the horizontal): reachable over the
# whole placement ranges with the elbow-up branch (horizontal needs more than ~0.46 m of reach).
GRASP_PITCH = -0.15
LIMIT_MARGIN = 0.03  # rad: demonstrations keep this far from the joint limits
MAX_ATTEMPTS = 20
# Demonstrations keep every joint speed below this share of the URDF's velocity limit (the Katana's
# motors: 1.19 rad/s); faster segments are slowed down.
VELOCITY_FRACTION = 0.9


def tool_pitch(q: npt.ArrayLike) -> Float:
    """Elevation of the Katana's tool axis above the horizontal (rad), for q (n,) or (M, n)."""
    return np.asarray(q, dtype=np.float64) @ PITCH_ROW


def solve_ik(
    robot: Robot,
    x: Float,
    pitch: float,
    roll: float,
    q0: Float,
    *,
    tol: float = 1e-7,
    max_iter: int = 100,
    damping: float = 1e-3,
) -> Float:
    """Joint angles putting the tool at ``x`` with a given pitch and roll.

    The one damped least-squares IK (:func:`pbdkit.robots._ik.damped_least_squares`) on the
    position Jacobian stacked with the pitch and roll rows (:data:`PITCH_ROW`,
    :data:`ROLL_ROW`), clipped to the joint limits, from ``q0`` (which picks the elbow branch:
    consecutive samples stay on the same one).

    Parameters
    ----------
    robot : Robot
        The Katana (:func:`pbdkit.robots.katana`).
    x : ndarray, shape (3,)
        Tool point target (base frame).
    pitch, roll : float
        Tool pitch and wrist roll targets (rad).
    q0 : ndarray, shape (n,)
        Initial guess.
    tol : float
        Stop when the error norm (m and rad mixed) is below.
    max_iter : int
    damping : float
        lambda: bounds the step near singularities.

    Returns
    -------
    q : ndarray, shape (n,)

    Raises
    ------
    ValueError
        If the target is not reached within 1e-4 (out of reach or against a joint limit).
    """
    q, err = damped_least_squares(
        robot,
        x,
        q0,
        lower=robot.lower,
        upper=robot.upper,
        tol=tol,
        max_iter=max_iter,
        damping=damping,
        rows=_TOOL_ROWS,
        row_targets=(pitch, roll),
    )
    if err > 1e-4:
        raise ValueError(
            f"x: IK did not reach {np.round(x, 4).tolist()} with pitch {pitch:.3f} "
            f"(error {err:.2e}); the point is out of reach or beyond a joint limit"
        )
    return q


def _min_jerk(tau: Float) -> Float:
    # Minimum-jerk position profile s(tau), tau in [0, 1] (Flash & Hogan 1985).
    out: Float = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    return out


# Initial guess on the elbow-up branch (upper arm raised, forearm folded down): the branch every
# demonstration uses, so that the joint-space data of different demonstrations are comparable.
_ELBOW_UP = np.array([0.0, 1.2, -1.8, 0.0, 0.0])


def _ik_with_margin(robot: Robot, x: Float, pitch: float, roll: float, q0: Float) -> Float:
    q = solve_ik(robot, x, pitch, roll, q0)
    if np.any(q < robot.lower + LIMIT_MARGIN) or np.any(q > robot.upper - LIMIT_MARGIN):
        raise ValueError(f"x: {np.round(x, 4).tolist()} is reachable only near a joint limit")
    return q


def reachable_pitch(
    robot: Robot, x: Float, preferred: float, roll: float = 0.0, step: float = 0.05
) -> float:
    """The pitch nearest to ``preferred`` (on a grid of ``step``) with which the tool reaches ``x``.

    Raises
    ------
    ValueError
        If no pitch within 1.2 rad of ``preferred`` works.
    """
    guess = _ELBOW_UP.copy()
    guess[0] = math.atan2(x[1], x[0])
    for k in range(2 * round(1.2 / step) + 1):
        # preferred, then alternately lower and higher by one more step
        p = preferred + (step * ((k + 1) // 2)) * (-1.0 if k % 2 else 1.0)
        try:
            _ik_with_margin(robot, x, p, roll, guess)
        except ValueError:
            continue
        return p
    raise ValueError(f"x: no pitch reaches {np.round(x, 4).tolist()}")


def trajectory_from_via_points(
    robot: Robot, start: Float, via: list[ViaPoint], rate: float = RATE
) -> tuple[Float, Float, Float]:
    """Sample a via-point path at ``rate`` and turn it into joint angles.

    Parameters
    ----------
    robot : Robot
    start : ndarray, shape (n,)
        Initial joint angles (the start posture).
    via : list of ViaPoint
        Successive targets; each segment follows a minimum-jerk profile in (x, pitch, roll).
    rate : float
        Sampling rate (Hz).

    Returns
    -------
    t : ndarray, shape (T,)
    joints : ndarray, shape (T, n)
    gripper : ndarray, shape (T,)
        1.0 closed, 0.0 open.

    Raises
    ------
    ValueError
        If a sample cannot be reached (the caller draws another demonstration).

    Notes
    -----
    Joint speeds stay below :data:`VELOCITY_FRACTION` of the robot's velocity limits: if a
    segment would be faster, every duration is lengthened by the same factor.
    """
    vmax = VELOCITY_FRACTION * np.asarray(robot.velocity_limit, dtype=np.float64)
    vmax = np.where(vmax > 0, vmax, np.inf)  # a URDF without velocity limits: no slowing down
    stretch = 1.0
    for _ in range(4):
        t, joints, gripper = _sample_via_points(robot, start, via, rate, stretch)
        speed = float(np.max(np.abs(np.diff(joints, axis=0)) * rate / vmax))
        if speed <= 1.0:
            return t, joints, gripper
        # The motors cap joint speeds: the whole demonstration is slowed down (not only the
        # fast segment), which keeps its phases where they were in normalized time.
        stretch *= speed * 1.02
    raise ValueError("via: the demonstration exceeds the joint velocity limits even when slowed")


def _sample_via_points(
    robot: Robot, start: Float, via: list[ViaPoint], rate: float, stretch: float
) -> tuple[Float, Float, Float]:
    q = np.array(start, dtype=np.float64)
    p0 = np.concatenate([robot.fk(q), [float(q @ PITCH_ROW), float(q @ ROLL_ROW)]])
    segments = [q[None, :]]
    gs = [0.0]
    for vp in via:
        pitch = reachable_pitch(robot, vp.x, vp.pitch, vp.roll) if vp.free_pitch else vp.pitch
        p1 = np.concatenate([vp.x, [pitch, vp.roll]])
        n = max(1, round(vp.duration * stretch * rate))
        seg = _segment(robot, q, p0, p1, n, vp.joint_space)
        segments.append(seg)
        gs.extend([1.0 if vp.gripper else 0.0] * n)
        q = seg[-1].copy()
        p0 = p1
    joints = np.vstack(segments)
    t = np.arange(joints.shape[0]) / rate
    return t, joints, np.array(gs)


def _segment(robot: Robot, q: Float, p0: Float, p1: Float, n: int, joint_space: bool) -> Float:
    """Joint samples (n, n_joints) of one minimum-jerk segment from q (at p0) to p1."""
    s = _min_jerk(np.arange(1, n + 1) / n)
    if joint_space:
        # A free gesture: the person swings the joints, the hand's path is whatever follows.
        q1 = _ik_with_margin(robot, p1[:3], float(p1[3]), float(p1[4]), q)
        out: Float = q + np.outer(s, q1 - q)
        return out
    rows = []
    for sk in s:
        p = p0 + (p1 - p0) * sk
        q = _ik_with_margin(robot, p[:3], float(p[3]), float(p[4]), q)
        rows.append(q)
    return np.array(rows)


def radial(p: Float) -> Float:
    """Horizontal unit vector (3,) from the base axis towards ``p`` (3,)."""
    u = np.array([p[0], p[1], 0.0])
    out: Float = u / np.linalg.norm(u)
    return out


def between(a: Float, b: Float) -> Float:
    """The point (3,) halfway between ``a`` and ``b`` in cylindrical coordinates about the base
    axis (radius, angle and height averaged)."""
    # Not the chord's midpoint: it would come closer to the base than the arm can reach with
    # the glass held level.
    ra, rb = math.hypot(a[0], a[1]), math.hypot(b[0], b[1])
    angle = 0.5 * (math.atan2(a[1], a[0]) + math.atan2(b[1], b[0]))
    r = 0.5 * (ra + rb)
    return np.array([r * math.cos(angle), r * math.sin(angle), 0.5 * (a[2] + b[2])])


def random_start_posture(robot: Robot, rng: np.random.Generator) -> Float:
    """A teacher's start posture: the hand raised in front of the robot, with a person's
    variability (drawn from ``rng``)."""
    pan = rng.uniform(-0.15, 0.15)
    r, z = rng.uniform(0.28, 0.34), rng.uniform(0.27, 0.32)
    x = np.array([r * math.cos(pan), r * math.sin(pan), z])
    guess = _ELBOW_UP.copy()
    guess[0] = pan
    pitch = reachable_pitch(robot, x, rng.uniform(-0.8, -0.6))
    return _ik_with_margin(robot, x, pitch, rng.normal(0.0, 0.02), guess)


class Person:
    """Draws a person's variability for one demonstration: durations, via-point jitter, postures.

    Every method draws from ``rng``: a task's via points must call them in a fixed order (the
    same seed then gives the same demonstration).

    Parameters
    ----------
    rng : numpy.random.Generator
    speed : float
        Every duration is scaled by 1 / speed.

    Attributes
    ----------
    tempo : float
        This demonstration's overall tempo (duration factor).
    hold_pitch : float
        The pitch (rad) at which this person holds the glass (kept while it is held: it stays
        upright).
    """

    def __init__(self, rng: np.random.Generator, speed: float) -> None:
        self.rng = rng
        # The demonstration's overall tempo varies a lot, the rhythm within it little: the
        # phases stay roughly aligned once the demonstrations are rescaled in time (paper
        # Table I), as with a person repeating a task.
        self.tempo = float(rng.uniform(0.85, 1.2)) / speed
        self.hold_pitch = float(GRASP_PITCH + rng.normal(0.0, 0.02))

    def duration(self, mean: float) -> float:
        """A segment's duration (s) around ``mean`` at this person's tempo."""
        return float(mean * self.tempo * self.rng.uniform(0.92, 1.08))

    def jitter(self, s: float) -> Float:
        """A via point's offset (3,), normal with standard deviation ``s`` (m) per axis."""
        return self.rng.normal(0.0, s, 3)

    def free_pitch(self) -> float:
        """A pitch (rad) for a free via point (the glass is not held)."""
        return float(self.rng.uniform(-0.5, -0.15))

    def holding_pitch(self) -> float:
        """The pitch (rad) while holding the glass: :attr:`hold_pitch` and a small wobble."""
        return self.hold_pitch + float(self.rng.normal(0.0, 0.005))

    def roll(self) -> float:
        """A wrist roll (rad) near neutral."""
        return float(self.rng.normal(0.0, 0.02))


#: Vertical unit vector (base frame).
UP = np.array([0.0, 0.0, 1.0])


def grasp_via_points(
    person: Person, glass: Float, lift: float, approach_time: float
) -> list[ViaPoint]:
    """Via points of the side grasp: swing behind the glass, approach along the radius, close,
    lift.

    Parameters
    ----------
    person : Person
    glass : ndarray, shape (3,)
        The glass's position (its reference point, :mod:`pbdkit.sim._glass`).
    lift : float
        Height (m) of the lift once the glass is held.
    approach_time : float
        Mean duration (s) of the approach (slower near the table, where the arm folds more).

    Returns
    -------
    list of ViaPoint
        The last one holds the glass ``lift`` above its support.
    """
    u = radial(glass)
    grasp = glass + GRASP_OFFSET
    p = person
    hp = p.hold_pitch
    return [
        # A free swing (joint space) to a point behind and above the glass: the swing's path
        # bulges, so it must end well clear of the glass.
        ViaPoint(
            p.duration(3.0),
            grasp - (APPROACH + 0.05) * u + UP * 0.08 + p.jitter(0.01),
            p.free_pitch(),
            p.roll(),
            False,
            free_pitch=True,
            joint_space=True,
        ),
        # Approach along the radius: the pan stays constant, so a joint-space motion keeps the
        # open fingers on both sides of the glass.
        ViaPoint(
            p.duration(approach_time),
            grasp - APPROACH * u + UP * 0.01 + p.jitter(0.002),
            hp,
            0.0,
            False,
            free_pitch=True,
            joint_space=True,
        ),
        ViaPoint(p.duration(1.6), grasp, hp, 0.0, False, joint_space=True),
        ViaPoint(p.duration(0.6), grasp, hp, 0.0, True),  # close and wait for the grip
        ViaPoint(p.duration(1.0), grasp + UP * lift, p.holding_pitch(), p.roll(), True),
    ]


def _fmt(objects: Mapping[str, Float]) -> str:
    return str({k: np.round(v, 3).tolist() for k, v in objects.items()})


def teach_one(
    spec: TaskSpec,
    objects: dict[str, Float],
    rng: np.random.Generator,
    robot: Robot | None = None,
    speed: float = 1.0,
) -> Demonstration:
    """One demonstration of the task ``spec`` for given object positions.

    Parameters
    ----------
    spec : TaskSpec
        The task (:func:`pbdkit.sim.teach` takes a name too).
    objects : dict str -> ndarray, shape (3,)
        Object positions (see the task).
    rng : numpy.random.Generator
        The person's variability (timing, via points, posture).
    robot : Robot, optional
        Defaults to :func:`pbdkit.robots.katana`.
    speed : float
        Scales every duration by 1 / speed (tests use a faster teacher).

    Returns
    -------
    Demonstration
        Encoders at :data:`RATE`; gripper 1.0 while closed.
    """
    robot = katana() if robot is None else robot
    error: ValueError | None = None
    # A person never demonstrates an impossible motion: redraw the variability when a drawn path
    # leaves the reachable set.
    for _ in range(MAX_ATTEMPTS):
        try:
            q_start = random_start_posture(robot, rng)
            t, joints, gripper = trajectory_from_via_points(
                robot, q_start, spec.via_points(objects, rng, speed)
            )
        except ValueError as exc:
            error = exc
            continue
        return Demonstration(t=t, joints=joints, objects=objects, gripper=gripper)
    raise ValueError(
        f"objects: no reachable demonstration for {_fmt(objects)} after {MAX_ATTEMPTS} "
        f"attempts ({error}); keep objects inside the {short(spec.name)} task's placement ranges"
    )
