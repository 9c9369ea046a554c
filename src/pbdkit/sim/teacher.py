"""A simulated teacher: kinesthetic-style demonstrations of the two tasks on the Katana.

A person moving the arm by hand goes through a few task-space via points with the timing, the
detours and the posture of the moment. The teacher reproduces that: for random object placements
(inside :data:`pbdkit.sim.tasks.PLACEMENT_RANGES`) it lays out via points relative to the objects,
draws durations, via-point jitter and a tool pitch per via point, solves each via point by damped
least-squares inverse kinematics on :func:`pbdkit.robots.katana` and interpolates with
minimum-jerk profiles, sampled at 100 Hz (the encoders' record): in task space where the hand's
path matters (holding the glass: straight lines at a constant pitch), in joint space for free
swings and for the radial approach (constant pan keeps the open fingers around the glass).

Structure, so that the paper's constraints emerge (Sec. III):

- coaster: start posture -> approach the glass on the shelf from the robot's side and grasp it (the
  tool on the glass's axis: tight relative to the glass) -> lift -> carry (free via point) -> place
  it on the coaster (tight relative to the coaster) -> release -> retreat;
- basin: start posture -> grasp the glass on the table (tight relative to the glass) -> carry above
  the fixed basin -> tilt it by a wrist-roll gesture whose angle profile is the same in every
  demonstration (a joint-space constraint) -> hold while the liquid pours into the basin (the end).

Grasps are side grasps: the tool axis nearly horizontal (pitch :data:`GRASP_PITCH`, 8.6 deg down:
level needs more reach than the near part of the ranges allows), pointing radially away from the
base, fingers closing horizontally. The pitch is kept while the glass is held, so the glass stays
upright while the roll is neutral, and rolling about the tool axis tips it sideways.

Katana specifics used here: the tool pitch (elevation of the tool axis above the horizontal) is
``lift1 + lift2 - lift3`` (the three lifts are parallel axes; lift3's axis is flipped by its
``rpy = (pi, 0, 0)``) and the roll is ``wrist_roll`` itself. Position (3) + pitch + roll are five
equations for five joints; the pitch, free for the position task, is the posture (null-space)
choice the teacher varies between demonstrations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ..demos import Demonstration
from ..robot import Robot
from ..robots import katana
from . import tasks as T

Float = NDArray[np.float64]

RATE = 100.0  # Hz, encoder sampling rate
# Row of d(pitch)/d(theta) for the Katana (see the module docstring).
PITCH_ROW: Float = np.array([0.0, 1.0, 1.0, -1.0, 0.0])
ROLL_ROW: Float = np.array([0.0, 0.0, 0.0, 0.0, 1.0])
# Pouring gesture (basin task): wrist-roll angle reached, rad. Past 90 deg the open top points
# downwards and the spheres run out.
POUR_ROLL = 2.0
POUR_SHIFT = 0.06  # m, hand position behind the basin's centre, against the pouring direction
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
    """Joint angles putting the tool at ``x`` with a given pitch and roll (damped least squares).

    Iterates ``q += A^T (A A^T + lambda^2 I)^-1 e`` with A the position Jacobian stacked with the
    pitch and roll rows and e the error, clipped to the joint limits, from ``q0`` (which picks
    the elbow branch: consecutive samples stay on the same one).

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
    q = np.array(q0, dtype=np.float64)
    lam2 = damping**2
    err = np.inf
    for _ in range(max_iter):
        xq, jac = robot.fk_jacobian(q)
        e = np.concatenate([x - xq, [pitch - q @ PITCH_ROW, roll - q @ ROLL_ROW]])
        err = float(np.linalg.norm(e))
        if err < tol:
            return q
        a = np.vstack([jac, PITCH_ROW, ROLL_ROW])
        q = np.clip(
            q + a.T @ np.linalg.solve(a @ a.T + lam2 * np.eye(5), e), robot.lower, robot.upper
        )
    if err > 1e-4:
        raise ValueError(
            f"x: IK did not reach {np.round(x, 4).tolist()} with pitch {pitch:.3f} "
            f"(error {err:.2e}); the point is out of reach or beyond a joint limit"
        )
    return q


@dataclass(frozen=True)
class ViaPoint:
    """A waypoint of the teacher's hand.

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


def _radial(p: Float) -> Float:
    u = np.array([p[0], p[1], 0.0])
    out: Float = u / np.linalg.norm(u)
    return out


def _between(a: Float, b: Float) -> Float:
    # Halfway in cylindrical coordinates about the base axis: the chord's midpoint would come
    # closer to the base than the arm can reach with the glass held level.
    ra, rb = math.hypot(a[0], a[1]), math.hypot(b[0], b[1])
    angle = 0.5 * (math.atan2(a[1], a[0]) + math.atan2(b[1], b[0]))
    r = 0.5 * (ra + rb)
    return np.array([r * math.cos(angle), r * math.sin(angle), 0.5 * (a[2] + b[2])])


def start_posture(robot: Robot, rng: np.random.Generator) -> Float:
    """A start posture: the hand raised in front of the robot, with a person's variability."""
    pan = rng.uniform(-0.15, 0.15)
    r, z = rng.uniform(0.28, 0.34), rng.uniform(0.27, 0.32)
    x = np.array([r * math.cos(pan), r * math.sin(pan), z])
    guess = _ELBOW_UP.copy()
    guess[0] = pan
    pitch = reachable_pitch(robot, x, rng.uniform(-0.8, -0.6))
    return _ik_with_margin(robot, x, pitch, rng.normal(0.0, 0.02), guess)


class _Person:
    """Draws a person's variability: durations, via-point jitter, postures."""

    def __init__(self, rng: np.random.Generator, speed: float) -> None:
        self.rng = rng
        # The demonstration's overall tempo varies a lot, the rhythm within it little: the
        # phases stay roughly aligned once the demonstrations are rescaled in time (paper
        # Table I), as with a person repeating a task.
        self.tempo = float(rng.uniform(0.85, 1.2)) / speed
        # The pitch at which this person holds the glass (kept while it is held: it stays upright).
        self.hold_pitch = float(GRASP_PITCH + rng.normal(0.0, 0.02))

    def d(self, mean: float) -> float:
        return float(mean * self.tempo * self.rng.uniform(0.92, 1.08))

    def jit(self, s: float) -> Float:
        return self.rng.normal(0.0, s, 3)

    def free_pitch(self) -> float:
        return float(self.rng.uniform(-0.5, -0.15))

    def hold(self) -> float:
        return self.hold_pitch + float(self.rng.normal(0.0, 0.005))

    def roll(self) -> float:
        return float(self.rng.normal(0.0, 0.02))


_UP = np.array([0.0, 0.0, 1.0])


def _grasp_via_points(
    person: _Person, glass: Float, lift: float, approach_time: float
) -> list[ViaPoint]:
    # Side grasp: come in along the radial direction at the glass's height, close, lift.
    u = _radial(glass)
    grasp = glass + T.GRASP_OFFSET
    p = person
    hp = p.hold_pitch
    return [
        # A free swing (joint space) to a point behind and above the glass: the swing's path
        # bulges, so it must end well clear of the glass.
        ViaPoint(
            p.d(3.0),
            grasp - (APPROACH + 0.05) * u + _UP * 0.08 + p.jit(0.01),
            p.free_pitch(),
            p.roll(),
            False,
            free_pitch=True,
            joint_space=True,
        ),
        # Approach along the radius: the pan stays constant, so a joint-space motion keeps the
        # open fingers on both sides of the glass.
        ViaPoint(
            p.d(approach_time),
            grasp - APPROACH * u + _UP * 0.01 + p.jit(0.002),
            hp,
            0.0,
            False,
            free_pitch=True,
            joint_space=True,
        ),
        ViaPoint(p.d(1.6), grasp, hp, 0.0, False, joint_space=True),
        ViaPoint(p.d(0.6), grasp, hp, 0.0, True),  # close and wait for the grip
        ViaPoint(p.d(1.0), grasp + _UP * lift, p.hold(), p.roll(), True),
    ]


def coaster_via_points(
    objects: dict[str, Float], rng: np.random.Generator, speed: float = 1.0
) -> list[ViaPoint]:
    """Via points of the coaster task for given glass and coaster positions."""
    person = _Person(rng, speed)
    p = person
    g, c = objects["glass"], objects["coaster"]
    uc = _radial(c)
    # Glass bottom 2 mm above the coaster's top when released: it drops onto it.
    place = c + _UP * (T.GLASS_PATCH_CENTER + 0.002) + T.GRASP_OFFSET
    grasp = g + T.GRASP_OFFSET
    carry = _between(grasp, place) + _UP * rng.uniform(0.10, 0.15) + p.jit(0.015)
    return [
        *_grasp_via_points(person, g, 0.06, 1.6),
        ViaPoint(p.d(1.8), carry, p.hold(), p.roll(), True),
        ViaPoint(p.d(1.5), place + _UP * 0.05 + p.jit(0.005), p.hold(), 0.0, True),
        ViaPoint(p.d(1.0), place, p.hold_pitch, 0.0, True),
        ViaPoint(p.d(0.6), place, p.hold_pitch, 0.0, False),  # open and wait
        ViaPoint(
            p.d(1.8),
            place - APPROACH * uc + p.jit(0.002),
            p.hold_pitch,
            p.roll(),
            False,
            free_pitch=True,
            joint_space=True,
        ),
        ViaPoint(
            p.d(2.5),
            place - APPROACH * uc + _UP * 0.08 + p.jit(0.01),
            p.free_pitch(),
            p.roll(),
            False,
            free_pitch=True,
            joint_space=True,
        ),
    ]


def basin_via_points(
    objects: dict[str, Float], rng: np.random.Generator, speed: float = 1.0
) -> list[ViaPoint]:
    """Via points of the basin task for a given glass position (the basin is fixed)."""
    person = _Person(rng, speed)
    p = person
    g, b = objects["glass"], objects["basin"]
    grasp = g + T.GRASP_OFFSET
    # A positive roll tips the glass's mouth towards the tangential direction d (the roll axis
    # points back along the tool). The liquid slides out along the wall and flies ~10 cm further
    # (it leaves at ~0.7 m/s): pour low, from behind the basin's centre.
    ub = _radial(b)
    d_pour = np.array([-ub[1], ub[0], 0.0])
    pour = b + _UP * rng.uniform(0.13, 0.15) - POUR_SHIFT * d_pour + p.jit(0.008)
    carry = _between(grasp, pour) + _UP * rng.uniform(0.06, 0.10) + p.jit(0.015)
    # The gesture: the same roll profile in every demonstration (joint space), fixed durations.
    return [
        # Near the table the arm folds more: the approach turns the wrist farther, slower.
        *_grasp_via_points(person, g, 0.08, 2.6),
        ViaPoint(p.d(1.6), carry, p.hold(), p.roll(), True),
        ViaPoint(p.d(1.4), pour, p.hold(), 0.0, True),
        # The pour ends the demonstration, as in the paper (joint space most constrained "at the
        # end of the motion"): tilt, then hold while the liquid runs out.
        ViaPoint(p.d(4.0), pour, p.hold_pitch, POUR_ROLL + p.roll(), True),
        ViaPoint(p.d(2.0), pour, p.hold_pitch, POUR_ROLL + p.roll(), True),
    ]


def _fmt(objects: dict[str, Float]) -> str:
    return str({k: np.round(v, 3).tolist() for k, v in objects.items()})


def teach_one(
    task: str,
    objects: dict[str, Float],
    rng: np.random.Generator,
    robot: Robot | None = None,
    speed: float = 1.0,
) -> Demonstration:
    """One demonstration of ``task`` for given object positions.

    Parameters
    ----------
    task : {"coaster", "basin"}
    objects : dict str -> ndarray, shape (3,)
        Object positions (see :mod:`pbdkit.sim.tasks`).
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
    T.check_task(task)
    robot = katana() if robot is None else robot
    make_via = coaster_via_points if task == "coaster" else basin_via_points
    error: ValueError | None = None
    # A person never demonstrates an impossible motion: redraw the variability when a drawn path
    # leaves the reachable set.
    for _ in range(MAX_ATTEMPTS):
        try:
            q_start = start_posture(robot, rng)
            t, joints, gripper = trajectory_from_via_points(
                robot, q_start, make_via(objects, rng, speed)
            )
        except ValueError as exc:
            error = exc
            continue
        return Demonstration(t=t, joints=joints, objects=objects, gripper=gripper)
    raise ValueError(
        f"objects: no reachable demonstration for {_fmt(objects)} after {MAX_ATTEMPTS} "
        f"attempts ({error}); keep objects inside PLACEMENT_RANGES"
    )


def teach(
    task: str, n_demos: int = 5, seed: int | None = None, speed: float = 1.0
) -> list[Demonstration]:
    """Kinesthetic-style demonstrations of ``task`` for random object placements.

    Parameters
    ----------
    task : {"coaster", "basin"}
    n_demos : int
        Number of demonstrations (>= 1).
    seed : int, optional
        Seeds the placements and the person's variability.
    speed : float
        Scales every duration by 1 / speed.

    Returns
    -------
    list of Demonstration
        Object positions drawn uniformly in :data:`pbdkit.sim.tasks.PLACEMENT_RANGES`.
    """
    T.check_task(task)
    if n_demos < 1:
        raise ValueError(f"n_demos must be >= 1, got {n_demos}")
    rng = np.random.default_rng(seed)
    robot = katana()
    demos = []
    for _ in range(n_demos):
        objects = T.sample_objects(task, rng)
        demos.append(teach_one(task, objects, rng, robot, speed))
    return demos
