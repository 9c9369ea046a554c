"""What the live view (:mod:`pbdkit.apps._view`) draws, computed without a browser or a server.

- :func:`make_plan`: a reproduction for a placement and what the page draws of it
  (:class:`Plan`: the driving constraint at each step, the timing);
- :func:`coarse_skill`: the same skill on a coarser time grid, for previews while dragging;
- :func:`step_gaussians` and :func:`ellipsoid_pose`: the constraints' Gaussians of the hand at a
  step, as ellipsoids;
- :func:`typical_placements`: where a skill file's objects start (a skill keeps no placements),
  and :func:`check_view_objects`: where ``--object`` puts them;
- :func:`carry_transform`: how the plan moves the object it grasps;
- :class:`LatestWins`: one planning thread that serves the newest request only;
- :func:`constraint_colors`: Fig. 6's colors.
"""

from __future__ import annotations

import math
import threading
import time
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, TypeVar

import numpy as np
from numpy.typing import NDArray

from .._rotations import exp_map, pose_matrix, quaternion_from_matrix
from .._validation import short
from ..data._placement import position_of, rotation_of
from ..reproduction._constraints import JOINT
from ..reproduction._probabilistic_ik import CollisionWarning
from ..reproduction._setup import ReachWarning

if TYPE_CHECKING:
    from ..collision import Scene
    from ..reproduction._constraints import Constraints
    from ..reproduction._result import ReproductionResult
    from ..robots._protocols import PoseKinematicModel
    from ..skill._skill import Skill

__all__ = [
    "CLEARANCE_RGB",
    "COLOR_NAMES",
    "JOINT_RGB",
    "N_SD",
    "OBJECT_RGBS",
    "LatestWins",
    "Plan",
    "camera_pose",
    "carry_transform",
    "check_view_objects",
    "coarse_skill",
    "constraint_colors",
    "ellipsoid_pose",
    "make_plan",
    "quat_wxyz",
    "step_gaussians",
    "typical_placements",
    "wxyz_of",
    "yaw_deg",
    "yaw_pose",
]

Float = NDArray[np.float64]
R = TypeVar("R")

#: Ellipsoids enclose this many standard deviations.
N_SD = 2.0
#: Latencies kept by :class:`LatestWins`.
HISTORY = 100_000
#: Fig. 6's colors (:mod:`pbdkit.apps._plots`), as RGB 0-255: the joint space, then the objects.
JOINT_RGB = (44, 160, 44)
#: The clearance constraint (a scene kept clear of) where it drives the step.
CLEARANCE_RGB = (127, 127, 127)
OBJECT_RGBS = ((214, 39, 40), (31, 119, 180), (148, 103, 189), (140, 86, 75))
COLOR_NAMES = ("red", "blue", "purple", "brown")


def constraint_colors(names: Sequence[str]) -> dict[str, tuple[int, int, int]]:
    """RGB (0-255) per constraint name (``"joint"`` and the objects in the skill's order), the
    colors of the report's Fig. 6."""
    out = {JOINT: JOINT_RGB}
    objects = [k for k in names if k != JOINT]
    out.update({k: OBJECT_RGBS[i % len(OBJECT_RGBS)] for i, k in enumerate(objects)})
    return out


class LatestWins(Generic[R]):
    """Runs ``work(request)`` in one background thread, for the newest request only.

    A request submitted while another waits replaces it (counted in :attr:`superseded`, never
    run); one submitted while ``work`` runs waits for it to finish. :attr:`latencies` holds,
    per request run, the seconds from its arrival (:meth:`submit`) to the end of ``work``, and
    :attr:`kinds` the ``kind`` it was submitted with (the last :data:`HISTORY` of each).
    An exception in ``work`` goes to ``on_error`` and the thread goes on.
    """

    def __init__(
        self,
        work: Callable[[R], None],
        on_error: Callable[[BaseException], None] | None = None,
        name: str = "pbdkit-view-planner",
    ) -> None:
        self._work = work
        self._on_error = on_error
        self._cond = threading.Condition()
        self._pending: tuple[R, float, str] | None = None
        self._busy = False
        self._closed = False
        self.superseded = 0
        self.latencies: deque[float] = deque(maxlen=HISTORY)
        self.kinds: deque[str] = deque(maxlen=HISTORY)
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, request: R, arrived: float | None = None, kind: str = "") -> None:
        """Queue ``request``, replacing one that waits; ``arrived``: its
        :func:`time.perf_counter` (default: now); ``kind``: a label kept with its latency."""
        t = time.perf_counter() if arrived is None else arrived
        with self._cond:
            if self._closed:
                return
            if self._pending is not None:
                self.superseded += 1
            self._pending = (request, t, kind)
            self._cond.notify_all()

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                assert self._pending is not None
                request, arrived, kind = self._pending
                self._pending = None
                self._busy = True
            try:
                self._work(request)
                self.latencies.append(time.perf_counter() - arrived)
                self.kinds.append(kind)
            except Exception as exc:  # reported, and the next request is served
                if self._on_error is not None:
                    self._on_error(exc)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Block until nothing waits or runs; False on timeout."""
        with self._cond:
            return self._cond.wait_for(
                lambda: self._pending is None and not self._busy, timeout=timeout
            )

    def close(self) -> None:
        """Stop the thread after the request that runs (a waiting one is dropped)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=10.0)


@dataclass(frozen=True, kw_only=True)
class Plan:
    """One reproduction for one placement, with what the page draws of it.

    Attributes
    ----------
    objects : dict str -> ndarray
        The placement planned for (the skill's objects).
    controller : str
        ``"fused"``, ``"joint"``, ``"task:OBJECT"`` (or ``"fused-position"`` for a task with
        poses).
    result : ReproductionResult
    constraints : Constraints
        Of the skill that reproduced (for the Gaussians).
    times : ndarray, shape (T,)
        Time of each step (s): :meth:`pbdkit.Skill.times`.
    driving : list of str
        Per step, the constraint with the largest share of the influence.
    seconds : float
        Time :meth:`pbdkit.Skill.reproduce` took.
    messages : list of str
        Warnings of the reproduction (an unreachable target).
    skill : Skill
        The skill that reproduced (a preview's: :func:`coarse_skill`).
    preview : bool
        A preview on a coarse grid, while an object is dragged.
    """

    objects: dict[str, Float]
    controller: str
    result: ReproductionResult
    constraints: Constraints
    times: Float
    driving: list[str]
    seconds: float
    messages: list[str]
    skill: Skill
    preview: bool = False

    @property
    def lead(self) -> int:
        """Steps of the reproduction's lead-in from its start posture (the skill's steps follow)."""
        lead_in = self.result.lead_in
        return 0 if lead_in is None else int(np.count_nonzero(lead_in))

    @property
    def end(self) -> Float:
        """The hand's planned position at the last step (m)."""
        return np.array(self.result.positions[-1], dtype=np.float64)


def make_plan(
    skill: Skill,
    objects: Mapping[str, Any],
    controller: str,
    use: list[str] | None,
    *,
    preview: bool = False,
    scene: Scene | None = None,
    avoid: bool = False,
) -> Plan:
    """Reproduce ``skill`` for ``objects`` with ``use`` and collect what the page draws
    (``preview``: ``skill`` is a :func:`coarse_skill`, and the plan says so); with a
    ``scene``, checked against it and, with ``avoid``, kept clear of it.

    Raises
    ------
    ValueError
        The reproduction has a NaN or an infinity in its joints, hand positions, times or
        influence: nothing of it could be drawn.
    """
    told = {k: np.asarray(objects[k], dtype=np.float64) for k in skill.object_names}
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ReachWarning)
        warnings.simplefilter("always", CollisionWarning)
        res = skill.reproduce(told, use=use, on_unreachable="warn", scene=scene, avoid=avoid)
    seconds = time.perf_counter() - start
    try:
        times = skill.times(res)
    except ValueError:  # no known duration: steps
        times = np.asarray(res.t, dtype=np.float64)
    _check_finite(res, times)
    names = list(res.influence)
    shares = np.stack([res.influence[k] for k in names], axis=1)
    driving = [names[i] for i in np.argmax(shares, axis=1)]
    return Plan(
        objects=told,
        controller=controller,
        result=res,
        constraints=skill.constraints(),
        times=times,
        driving=driving,
        seconds=seconds,
        messages=[str(w.message) for w in caught],
        skill=skill,
        preview=preview,
    )


def _check_finite(res: ReproductionResult, times: Float) -> None:
    """Refuse a reproduction with a NaN or an infinity in what the page shows: it would reach
    the browser as a number ("nan" in a field, a path or an arm nowhere)."""
    shown = {
        "joints": res.joints,
        "hand positions": res.positions,
        "times": times,
        **{f"influence[{k}]": v for k, v in res.influence.items()},
    }
    bad = [k for k, v in shown.items() if not np.isfinite(np.asarray(v, dtype=np.float64)).all()]
    if bad:
        raise ValueError(
            f"the reproduction gave non-finite values (NaN or inf) in {', '.join(bad)}: "
            "nothing drawn for this placement"
        )


def coarse_skill(skill: Skill, n_steps: int) -> Skill:
    """The same skill on a coarser time grid of ``n_steps`` steps, for previews.

    Every GMM's time axis (its first column, in steps) is scaled by (n_steps - 1) / (T - 1):
    an affine change of GMR's input, so that the coarse skill's constraints at each of its
    steps are exactly the full skill's at the same moment. Reproducing it runs Table II over
    fewer, longer steps (the same duration), which costs about n_steps / T of the full
    reproduction; ``benchmarks/bench_view.py`` measures how far its hand path is from the full
    one.
    """
    from ..prob._gmm import GMM
    from ..skill._skill import Skill

    if not 2 <= n_steps <= skill.n_steps:
        raise ValueError(f"n_steps must be in [2, {skill.n_steps}], got {n_steps}")
    scale = (n_steps - 1) / (skill.n_steps - 1)
    gmms = {}
    for name, g in skill.gmms.items():
        means = np.array(g.means_, dtype=np.float64)
        covs = np.array(g.covariances_, dtype=np.float64)
        means[:, 0] *= scale
        covs[:, 0, :] *= scale
        covs[:, :, 0] *= scale
        gmms[name] = GMM.from_params(g.weights_, means, covs)
    return Skill(
        skill.robot,
        gmms,
        n_steps=n_steps,
        object_names=skill.object_names,
        has_gripper=skill.has_gripper,
        reach=skill.reach,
        duration=skill.duration,
        rotation_base=skill.rotation_base,
        # The factors at the same moments: linear between the full grid's steps.
        calibration={
            k: np.interp(np.arange(n_steps) / scale, np.arange(skill.n_steps), c)
            for k, c in skill.calibration_.items()
        },
    )


def step_gaussians(plan: Plan, step: int) -> dict[str, tuple[Float, Float]]:
    """The constraints' Gaussians of the hand position at reproduction step ``step``, in the
    robot's base frame: name -> (mean (3,), covariance (3, 3)).

    An object's constraint expects the hand at o + x_hat (a position-only constraint) or
    p + R m (an oriented one: m in the object's frame, covariance R S R^T); the joint-space
    constraint at the forward kinematics of its mean posture, with covariance J S_theta J^T.
    The reproduction's steps after its lead-in are the skill's steps (a lead-in step shows
    the skill's first).
    """
    c = plan.constraints
    k = int(np.clip(step - plan.lead, 0, c.n_steps - 1))
    out: dict[str, tuple[Float, Float]] = {}
    q = c.joint_mean[k]
    x, jac = plan.skill.robot.fk_jacobian(q)
    out[JOINT] = (np.asarray(x, dtype=np.float64), jac @ c.joint_cov[k] @ jac.T)
    for name in c.object_names:
        placement = plan.objects[name]
        mean = c.task_mean[name][k, :3]
        cov = c.task_cov[name][k, :3, :3]
        rot = rotation_of(placement) if name in c.rotation_base else None
        if rot is not None:
            out[name] = (position_of(placement) + rot @ mean, rot @ cov @ rot.T)
        else:
            out[name] = (position_of(placement) + mean, cov.copy())
    return out


def ellipsoid_pose(cov: Float, n_sd: float = N_SD) -> tuple[Float, Float]:
    """Semi-axes (3,) and orientation (w, x, y, z) of the ellipsoid of ``n_sd`` standard
    deviations of a 3-D Gaussian with covariance ``cov``: a unit sphere scaled by the semi-axes
    along x, y, z, then turned by the quaternion."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    if np.linalg.det(vecs) < 0:
        vecs[:, 0] = -vecs[:, 0]
    axes = n_sd * np.sqrt(np.clip(vals, 1e-12, None))
    return axes, quat_wxyz(vecs)


def quat_wxyz(rot: Float) -> Float:
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    return quaternion_from_matrix(rot)


def camera_pose(reach: float, placements: Iterable[Any]) -> tuple[Float, Float]:
    """Where the page's camera starts, and the point it looks at: the middle of the base and
    the objects (their mean position; the base alone without any), from a distance the arm's
    ``reach`` (m; 1 if unknown) sets."""
    positions = [position_of(v) for v in placements]
    objects = np.mean(positions, axis=0) if positions else np.zeros(3)
    reach = float(reach) if np.isfinite(reach) else 1.0
    centre = 0.5 * objects + np.array([0.0, 0.0, 0.15 * reach])
    view = np.array([0.9, -1.2, 0.8])
    return centre + 1.05 * reach * view / np.linalg.norm(view), centre


def wxyz_of(value: Float) -> tuple[float, float, float, float]:
    """The (w, x, y, z) quaternion a node takes for a placement: a pose's (4x4) rotation, the
    identity for a position (3,)."""
    if value.shape == (4, 4):
        w = quat_wxyz(value[:3, :3])
        return (float(w[0]), float(w[1]), float(w[2]), float(w[3]))
    return (1.0, 0.0, 0.0, 0.0)


def yaw_deg(value: Float) -> float:
    """A pose's (4x4) yaw about the vertical (degrees)."""
    return math.degrees(math.atan2(float(value[1, 0]), float(value[0, 0])))


def yaw_pose(position: Float, yaw: float) -> Float:
    """A pose at ``position`` turned about the vertical by ``yaw`` (degrees)."""
    return pose_matrix(position, exp_map([0.0, 0.0, math.radians(yaw)]))


def check_view_objects(given: Mapping[str, Any], skill: Skill) -> dict[str, Float]:
    """Placements given for some of ``skill``'s objects (``pbdkit view --object``), checked as
    a reproduction checks them (:func:`pbdkit.reproduction._setup.check_objects`): a position,
    or a pose (x, y, z, qw, qx, qy, qz or 4x4) that an object of an oriented constraint needs.

    Returns
    -------
    placements : dict str -> ndarray, shape (3,) or (4, 4)

    Raises
    ------
    ValueError
        An object the skill does not know, or a bad placement; the message names --object.
    """
    from ..reproduction._setup import check_objects

    unknown = [k for k in given if k not in skill.object_names]
    if unknown:
        raise ValueError(
            f"--object: {short(unknown)} are not objects of the skill ({skill.object_names})"
        )
    return check_objects(
        given, skill.object_names, "--object", oriented=skill.oriented, partial=True
    )


def typical_placements(skill: Skill) -> dict[str, Float]:
    """A placement of the skill's objects as the demonstrations had them on average.

    For each object: at the step where its constraint is tightest (smallest trace of the
    position covariance), the hand of the joint-space constraint's mean posture is where the
    object's constraint expects it; the object is put there (position o = x - x_hat; for an
    oriented constraint, R = R_hand (exp([r]x) M)^T and p = x - R m). A skill file does not keep
    its demonstrations' placements; this is where ``pbdkit view --skill`` starts.
    """
    c = skill.constraints()
    robot: Any = skill.robot  # a Robot: oriented constraints need fk_pose
    out: dict[str, Float] = {}
    for name in skill.object_names:
        cov = c.task_cov[name][:, :3, :3]
        k = int(np.argmin(np.trace(cov, axis1=1, axis2=2)))
        q = np.clip(c.joint_mean[k], robot.lower, robot.upper)
        mean = c.task_mean[name][k]
        if name in c.rotation_base:
            hand = robot.fk_pose(q)
            rel = exp_map(mean[3:]) @ c.rotation_base[name]
            pose = np.eye(4)
            pose[:3, :3] = hand[:3, :3] @ rel.T
            pose[:3, 3] = hand[:3, 3] - pose[:3, :3] @ mean[:3]
            out[name] = pose
        else:
            out[name] = np.asarray(robot.fk(q), dtype=np.float64) - mean[:3]
    return out


def carry_transform(robot: PoseKinematicModel, plan: Plan, step: int) -> Float | None:
    """How the plan moves the object it grasps at reproduction step ``step``: a 4x4 transform
    to apply to the object's pose where it lies, or None before the grasp (or if the gripper
    never closes).

    From the step the gripper closes (the grasp) the object keeps its pose relative to the hand
    there: the transform is H_k H_g^-1 with H the hand's pose (:meth:`pbdkit.Robot.fk_pose`),
    g the grasp and k the step; from the step it opens again (the release) it stays where it
    was let go (k = the last closed step). A drawing of the plan, not physics: the object does
    not slip or fall.
    """
    closed = np.asarray(plan.result.gripper, dtype=bool)
    shut = np.flatnonzero(closed)
    if shut.size == 0 or step < shut[0]:
        return None
    grasp = int(shut[0])
    opened = np.flatnonzero(~closed[grasp:])
    release = grasp + int(opened[0]) - 1 if opened.size else len(closed) - 1
    k = min(step, release)
    hand_g = robot.fk_pose(plan.result.joints[grasp])
    hand_k = robot.fk_pose(plan.result.joints[k])
    return np.asarray(hand_k @ np.linalg.inv(hand_g), dtype=np.float64)
