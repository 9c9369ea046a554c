"""The data of a skill's constraint spaces (paper Table I): the time grid's bounds, each space's
data from the demonstrations (:func:`space_data`), and the variability floors of their GMMs.

Every demonstration is rescaled to ``n_steps`` steps (time in steps 0 .. n_steps-1,
:meth:`pbdkit.Demonstration.rescaled`), the hand positions x = f(theta) follow from one batched
forward-kinematics call, and the spaces are the joint space {t, theta, [gripper]} and, for every
object n, the task space {t, x - o(n)}; for an object given as a pose (R, p), {t, R^T (x - p), r}
with R^T R_hand = exp([r]x) M, M the demonstrations' mean relative orientation
(:func:`mean_relative_rotation`). Why the tangent space at M: :doc:`/reproduction`,
"Orientation constraints".
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, cast

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import log_map, mean_rotation
from .._validation import check_positive_float, short
from ..data._align import align as align_demos
from ..data._align import alignment_spreads
from ..data._demonstration import LIMIT_TOLERANCE, Demonstration, LimitWarning
from ..data._placement import position_of
from ..reproduction._constraints import JOINT
from ..robots._protocols import KinematicModel, PoseKinematicModel

__all__ = [
    "MAX_STEPS",
    "MIN_STEP_SECONDS",
    "TIME_FLOOR",
    "VARIABILITY_FLOOR",
    "fit_steps",
    "mean_relative_rotation",
    "space_data",
    "space_floors",
]

Float = NDArray[np.float64]
#: Default variability floors (variances): joint angles (rad^2), gripper signal, hand position
#: relative to an object (m^2), hand orientation relative to an object (rad^2). See
#: :meth:`pbdkit.Skill.learn`.
VARIABILITY_FLOOR: Mapping[str, float] = MappingProxyType(
    {"joint": 0.01**2, "gripper": 0.1**2, "task": 0.001**2, "orientation": 0.01**2}
)
TIME_FLOOR = 1e-6  # steps^2: numerical jitter on the time column
#: Largest number of steps of a skill's time grid (:meth:`pbdkit.Skill.learn`,
#: :meth:`pbdkit.Skill.load`). The constraints and a reproduction hold several (T, n, n)
#: arrays: 10**6 steps of a 7-joint arm take over 1 GB, far beyond the paper's 1000 steps; a
#: file asking for more is refused rather than exhausting memory at the first reproduction.
MAX_STEPS = 10**6
#: The shortest time step a skill may have (s): its duration over ``n_steps - 1`` steps. A
#: nanosecond is a thousand times finer than the fastest servo loop (1 MHz). Far shorter steps
#: give no motion: with a skill of 1e-300 s, the cube of the step (the jerk term of the motion
#: limits) underflows to 0, and from steps of about 1e-17 s on, the retiming to the limits
#: fails on NaN. :meth:`pbdkit.Skill.learn` and :meth:`pbdkit.Skill.load` refuse a duration
#: that gives a shorter step, or that is not finite.
MIN_STEP_SECONDS = 1e-9


def duration_problem(duration: float, n_steps: int) -> str:
    """Why a skill cannot last ``duration`` seconds over ``n_steps`` steps ("" if it can)."""
    if not math.isfinite(duration) or duration <= 0:
        return f"the duration must be finite and > 0 (s), got {short(duration)}"
    step = duration / (n_steps - 1)
    if not step >= MIN_STEP_SECONDS:
        return (
            f"a duration of {duration:.6g} s over n_steps={n_steps} steps gives a time step of "
            f"{step:.3g} s; it must be at least MIN_STEP_SECONDS = {MIN_STEP_SECONDS:g} s"
        )
    return ""


def warn_outside_limits(demos: Sequence[Demonstration], robot: KinematicModel) -> None:
    """One LimitWarning per demonstration whose joints leave the limits by > LIMIT_TOLERANCE.

    Names the joint and the sample where the excess is largest.
    """
    lower = np.asarray(robot.lower, dtype=np.float64)
    upper = np.asarray(robot.upper, dtype=np.float64)
    names = list(robot.joint_names)
    revolute = np.asarray(robot.revolute, dtype=bool)
    for i, d in enumerate(demos):
        excess = np.maximum(lower - d.joints, d.joints - upper)  # (T, n), > 0 outside
        worst = int(np.argmax(excess))
        sample, j = divmod(worst, excess.shape[1])
        if excess[sample, j] <= LIMIT_TOLERANCE:
            continue
        unit = "rad" if revolute[j] else "m"
        warnings.warn(
            f"demos[{i}]: joint '{names[j]}' reaches {d.joints[sample, j]:.6g} {unit} at "
            f"t={d.t[sample]:.6g} (sample {sample}), outside its limits "
            f"[{lower[j]:.6g}, {upper[j]:.6g}] by {excess[sample, j]:.3g}; learned as "
            "recorded, reproductions are clipped to the limits",
            LimitWarning,
            stacklevel=3,
        )


def variability_floor(reg_covar: float | Mapping[str, float] | None) -> dict[str, float]:
    """The floors per kind of dimension, from :meth:`pbdkit.Skill.learn`'s ``reg_covar``."""
    if reg_covar is None:
        return dict(VARIABILITY_FLOOR)
    if isinstance(reg_covar, Mapping):
        unknown = [k for k in reg_covar if k not in VARIABILITY_FLOOR]
        if unknown:
            raise ValueError(f"reg_covar: unknown key(s) {unknown}; use {list(VARIABILITY_FLOOR)}")
        out = dict(VARIABILITY_FLOOR)
        for k, v in reg_covar.items():
            out[k] = check_positive_float(v, f"reg_covar[{short(k)}]", allow_zero=True)
        return out
    v = check_positive_float(reg_covar, "reg_covar", allow_zero=True)
    return dict.fromkeys(VARIABILITY_FLOOR, v)


def fit_steps(n_steps: int, fit_samples: int | None) -> NDArray[np.intp]:
    """The steps of an ``n_steps`` grid each demonstration gives EM: ``fit_samples`` evenly
    spaced ones, the first and the last included (all of them for None or more)."""
    n_fit = n_steps if fit_samples is None else min(fit_samples, n_steps)
    return np.unique(np.round(np.linspace(0, n_steps - 1, n_fit)).astype(np.intp))


def space_floors(
    floors: Mapping[str, float],
    n_joints: int,
    has_gripper: bool,
    object_names: Sequence[str],
    oriented: Collection[str],
) -> dict[str, Float]:
    """The variability floor of every dimension of every space (the ``reg_covar`` of its GMM),
    from the floors per kind (:func:`variability_floor`): time (steps; a jitter only), then the
    space's own units."""
    n = n_joints
    return {
        JOINT: np.r_[TIME_FLOOR, np.full(n, floors["joint"])]
        if not has_gripper
        else np.r_[TIME_FLOOR, np.full(n, floors["joint"]), floors["gripper"]],
        **{
            k: np.r_[TIME_FLOOR, np.full(3, floors["task"])]
            if k not in oriented
            else np.r_[TIME_FLOOR, np.full(3, floors["task"]), np.full(3, floors["orientation"])]
            for k in object_names
        },
    }


def space_data(
    demos: Sequence[Demonstration],
    robot: KinematicModel,
    object_names: Sequence[str],
    n_steps: int,
    steps: npt.ArrayLike | None = None,
    *,
    rotation_base: Mapping[str, Float] | None = None,
) -> dict[str, Float]:
    """The data of every constraint space, per demonstration (paper Table I).

    Each demonstration is rescaled to ``n_steps`` steps and sampled at ``steps``; the hand
    positions x = f(theta) come from one batched forward-kinematics call.

    Parameters
    ----------
    demos : sequence of Demonstration
        Validated, with the same structure
        (:func:`pbdkit.data._demonstration.check_demonstrations`).
    robot : KinematicModel
    object_names : sequence of str
        The objects that get a task space.
    n_steps : int
    steps : array-like of int, optional
        The steps kept (default: all ``n_steps``).
    rotation_base : dict str -> ndarray (3, 3), optional
        The oriented objects (given as poses) and their mean relative orientation M.

    Returns
    -------
    data : dict str -> ndarray, shape (M, T', D)
        ``"joint"``: {t, theta (n), gripper (if the demonstrations have one)}; each object:
        {t, x - o} (a pose's position as o), or for an oriented object {t, R^T (x - p), r}
        with R^T R_hand = exp([r]x) M (module docstring); M demonstrations,
        T' = len(steps) steps, time in steps.
    """
    bases = rotation_base or {}
    idx = np.arange(n_steps) if steps is None else np.asarray(steps, dtype=np.intp)
    resampled = [d.rescaled(n_steps) for d in demos]
    m, t_len = len(resampled), idx.shape[0]
    t = np.broadcast_to(idx.astype(np.float64)[None, :, None], (m, t_len, 1))
    theta = np.stack([d.joints[idx] for d in resampled])  # (M, T', n)
    flat = theta.reshape(m * t_len, -1)
    if bases:
        # Oriented objects: Skill.learn checked that the robot is a PoseKinematicModel.
        poses = np.asarray(cast(PoseKinematicModel, robot).fk_pose(flat), dtype=np.float64)
        x = poses[:, :3, 3].reshape(m, t_len, 3)
        hand = poses[:, :3, :3].reshape(m, t_len, 3, 3)
    else:
        x = np.asarray(robot.fk(flat), dtype=np.float64).reshape(m, t_len, 3)
    cols = [t, theta]
    grips = [d.gripper[idx] for d in resampled if d.gripper is not None]
    if grips:
        cols.append(np.stack(grips)[..., None])
    out = {JOINT: np.concatenate(cols, axis=2)}
    for k in object_names:
        o = np.stack([position_of(d.objects[k]) for d in demos])[:, None, :]
        if k not in bases:
            out[k] = np.concatenate([t, x - o], axis=2)
            continue
        rot = np.stack([d.objects[k][:3, :3] for d in demos])  # (M, 3, 3)
        local = np.einsum("mji,mtj->mti", rot, x - o)  # R^T (x - p)
        rel = np.swapaxes(rot, -1, -2)[:, None] @ hand  # R^T R_hand, (M, T', 3, 3)
        r = log_map(rel @ bases[k].T)
        out[k] = np.concatenate([t, local, r], axis=2)
    return out


def mean_relative_rotation(
    demos: Sequence[Demonstration],
    robot: PoseKinematicModel,
    name: str,
    n_steps: int,
    steps: npt.ArrayLike | None = None,
) -> Float:
    """M: the Karcher mean (:func:`pbdkit._rotations.mean_rotation`) of the hand's
    orientation relative to object ``name`` (a pose), R^T R_hand, over every demonstration
    and step kept: the tangent space the skill's orientation data live in."""
    idx = np.arange(n_steps) if steps is None else np.asarray(steps, dtype=np.intp)
    rels = []
    for d in demos:
        q = d.rescaled(n_steps).joints[idx]
        hand = np.asarray(robot.fk_pose(q), dtype=np.float64)[:, :3, :3]
        rels.append(d.objects[name][:3, :3].T @ hand)
    return mean_rotation(np.concatenate(rels))


#: Skill.learn's alignment in time (pbdkit.align): the Sakoe-Chiba band and the reference.
ALIGN_BAND = 0.3
ALIGN_REFERENCE = "medoid"
#: ``align="auto"`` aligns when that makes the demonstrations' spread at least this much
#: smaller than in linear time (:func:`pbdkit.data._align.alignment_spreads`).
AUTO_ALIGN_GAIN = 0.8


@dataclass(frozen=True)
class Alignment:
    """What :meth:`pbdkit.Skill.learn` did about the demonstrations' timing
    (:attr:`pbdkit.Skill.aligned_`): true when it aligned them.

    Attributes
    ----------
    requested : str
        ``"auto"``, ``"yes"`` (``align=True``) or ``"no"`` (``align=False``).
    applied : bool
        Whether the demonstrations were aligned by dynamic time warping (:func:`pbdkit.align`)
        before they were encoded.
    band, reference : float, str
        The alignment's band and reference.
    spread_linear, spread_aligned : float
        The demonstrations' spread in linear time and aligned
        (:func:`pbdkit.data._align.alignment_spreads`); NaN where not measured (``"no"``).
    """

    requested: str
    applied: bool
    band: float = ALIGN_BAND
    reference: str = ALIGN_REFERENCE
    spread_linear: float = float("nan")
    spread_aligned: float = float("nan")

    def __bool__(self) -> bool:
        return self.applied

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready copy (NaN as None)."""

        def num(v: float) -> float | None:
            return None if v != v else float(v)

        return {
            "requested": self.requested,
            "applied": self.applied,
            "band": self.band,
            "reference": self.reference,
            "spread_linear": num(self.spread_linear),
            "spread_aligned": num(self.spread_aligned),
        }


def aligned_demonstrations(
    demos: Sequence[Demonstration], robot: KinematicModel, align: object
) -> tuple[list[Demonstration], Alignment]:
    """The demonstrations as ``Skill.learn(..., align=align)`` encodes them, and what it did.

    ``True`` aligns them (:func:`pbdkit.align`, :data:`ALIGN_BAND`, :data:`ALIGN_REFERENCE`),
    ``False`` keeps them in linear time, ``"auto"`` aligns when that reduces their spread to at
    most :data:`AUTO_ALIGN_GAIN` of the linear one.
    """
    items = list(demos)
    if align is False:
        return items, Alignment("no", False)
    if align is not True and align != "auto":
        raise ValueError(f"align must be True, False or 'auto', got {short(align)}")
    warped = align_demos(items, robot, band=ALIGN_BAND, reference=ALIGN_REFERENCE)
    linear, aligned = alignment_spreads(items, warped, robot)
    if align is True:
        return warped, Alignment("yes", True, spread_linear=linear, spread_aligned=aligned)
    use = aligned <= AUTO_ALIGN_GAIN * linear
    record = Alignment("auto", use, spread_linear=linear, spread_aligned=aligned)
    return (warped if use else items), record
