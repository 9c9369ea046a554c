"""A skill: learned from demonstrations (paper Table I), reproduced for new objects (Table II).

Learning (:meth:`Skill.learn`):

1. every demonstration is rescaled to ``n_steps`` steps (time in steps 0 .. n_steps-1, see
   :meth:`pbdkit.Demonstration.rescaled`);
2. the hand positions x = f(theta) follow from forward kinematics (one batched call);
3. one GMM per data space, K chosen by BIC (:class:`pbdkit.GMM`): the joint space
   {t, theta, gripper} (the gripper column only when the demonstrations have one: the paper
   generalizes the binary gripper signal with the joints) and, for every object n, the task space
   {t, x - o(n)};
4. GMR over the time grid gives the constraints theta_hat, Sigma^theta, x_hat^(n), Sigma^x(n);
   they do not depend on the new object positions, so they are computed once per skill and
   covariance mode and cached.

Reproduction (:meth:`Skill.reproduce`) runs :func:`pbdkit.reproduction._probabilistic_ik.solve`.

File format (:meth:`Skill.save` / :meth:`Skill.load`): a NumPy ``.npz`` archive, no pickle,
written atomically. Keys: ``format`` = ``"pbdkit-skill"``, ``version`` = 1, ``n_steps``
(2 .. :data:`MAX_STEPS`), ``n_joints`` (matching the GMM dimensions), ``object_names`` (N,)
unicode, ``has_gripper``, ``reach`` (m), ``robot_urdf``
(the URDF text, empty if the robot was not built from a URDF), ``robot_tip``, and for each space
``gmm_joint_*`` / ``gmm_{i}_*`` (object i in ``object_names`` order) with ``weights`` (K,),
``means`` (K, D) and ``covariances`` (K, D, D). When the robot has them (a :class:`pbdkit.Robot`
always does), ``robot_velocity_limit``, ``robot_acceleration_limit`` and ``robot_jerk_limit``:
float64 (n_joints,), rad/s, rad/s^2, rad/s^3, each > 0 or inf (no limit); :meth:`Skill.load`
rebuilds the robot with them (they win over the URDF's velocity, as a joint_limits YAML does).
These keys were added within version 1: a file without them loads as before (velocity from the
URDF, no acceleration or jerk limit). Also ``duration`` (s, NaN if unknown) and, per space,
``sel_{space}_*`` (the model selection). Version 2 (written when the skill has oriented
constraints; a skill of positions only is still written as version 1) adds ``rot_base_{i}``
(3, 3) for every oriented object i: the mean relative orientation M whose tangent space its
GMM's last three columns live in (the GMM is then over {t, R^T (x - p), r}, D = 7).
:meth:`Skill.load` judges the archive from its headers before it loads an array: any other
key, or arrays of more than :data:`MAX_FILE_BYTES` in all, are refused.

Orientation (:meth:`Skill.learn` with ``orientation=True``, the default, and objects given as
poses): for an object with pose (R, p), its task space is {t, R^T (x - p), r} with r the
hand's orientation relative to the object, R^T R_hand = exp([r]x) M: a rotation vector on the
left, in the object's axes, in the tangent space at M, the demonstrations' mean relative
orientation (Karcher mean over all their samples), not at the identity (a hand pointing down at
an upright object is 90 degrees or more from it; near 180 degrees the rotation vector would
flip). Relative orientations up to 90 degrees from M (a spread of +-90 degrees) are
represented without wrap-around. At reproduction each constraint is mapped to the world with
the object's new pose (:meth:`pbdkit.reproduction._constraints.Constraints.world_task`).
"""

from __future__ import annotations

import functools
import math
import os
import re
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._defaults import MAX_COMPONENTS
from .._io import NpzArchive, check_format, open_npz, save_npz_atomic
from .._rotations import check_rotation, log_map, mean_rotation
from .._validation import check_int, check_positive_float
from ..data._demonstration import LIMIT_TOLERANCE, Demonstration, LimitWarning, check_demonstrations
from ..data._placement import is_pose, position_of
from ..motion._limits import LimitSpec, MotionLimits
from ..prob import GMM, ModelSelection
from ..prob._gmr import CovarianceMode
from ..reproduction._constraints import JOINT, Constraints, KinematicModel
from ..reproduction._controller import Controller
from ..reproduction._probabilistic_ik import (
    ReproductionResult,
    RunOptions,
    reach_from_samples,
    solve,
    step_limit_from_velocity,
)

__all__ = [
    "MAX_COMPONENTS",
    "MAX_FILE_BYTES",
    "MAX_STEPS",
    "MIN_STEP_SECONDS",
    "VARIABILITY_FLOOR",
    "Skill",
    "mean_relative_rotation",
    "space_data",
]

Float = NDArray[np.float64]
#: Default variability floors (variances): joint angles (rad^2), gripper signal, hand position
#: relative to an object (m^2), hand orientation relative to an object (rad^2). See
#: :meth:`Skill.learn`.
VARIABILITY_FLOOR: Mapping[str, float] = MappingProxyType(
    {"joint": 0.01**2, "gripper": 0.1**2, "task": 0.001**2, "orientation": 0.01**2}
)
TIME_FLOOR = 1e-6  # steps^2: numerical jitter on the time column
#: Largest number of steps of a skill's time grid (:meth:`Skill.learn` and :meth:`Skill.load`).
#: The constraints and a reproduction hold several (T, n, n) arrays: 10**6 steps of a 7-joint
#: arm take over 1 GB, far beyond the paper's 1000 steps; a file asking for more is refused
#: rather than exhausting memory at the first reproduction.
MAX_STEPS = 10**6
#: The most bytes the arrays of a skill file may take once loaded (:meth:`Skill.load`), read
#: from the archive's headers before anything is loaded. A skill holds a few GMMs, a URDF and
#: limits: kilobytes to a few megabytes.
MAX_FILE_BYTES = 64 * 2**20
#: The shortest time step a skill may have (s): its duration over ``n_steps - 1`` steps. A
#: nanosecond is a thousand times finer than the fastest servo loop (1 MHz). Far shorter steps
#: give no motion: with a skill of 1e-300 s, the cube of the step (the jerk term of the motion
#: limits) underflows to 0, and from steps of about 1e-17 s on, the retiming to the limits
#: fails on NaN. :meth:`Skill.learn` and :meth:`Skill.load` refuse a duration that gives a
#: shorter step, or that is not finite.
MIN_STEP_SECONDS = 1e-9
FORMAT_NAME = "pbdkit-skill"
FORMAT_VERSION = 2
#: The versions :meth:`Skill.load` reads (1: positions only; 2: oriented constraints too).
READABLE_VERSIONS = (1, 2)


class Skill:
    """A skill learned from demonstrations: one GMM per constraint space.

    Build it with :meth:`learn` or :meth:`load`.

    Attributes
    ----------
    robot : KinematicModel
        The arm the skill was learned on.
    n_steps : int
        Number of steps T of the time grid (and of every reproduction).
    object_names : list of str
        Objects of the skill (task-space constraints), in a fixed order.
    constraint_names : list of str
        ``["joint", *object_names]``.
    gmms : dict str -> GMM
        The GMM of each constraint space: ``"joint"`` over {t, theta(n), [gripper]} and one per
        object over {t, x - o(n)}.
    n_components : dict str -> int
        Number of components K of each GMM (chosen by BIC when learned with ``"bic"``).
    has_gripper : bool
        Whether the joint-space GMM has a gripper column.
    reach : float
        Reach of the arm from its base origin (m): 1.02 x the largest ||f(theta)|| over 4096
        random postures within the limits and all demonstrated postures.
    duration : float
        Mean duration of the demonstrations (s): a reproduction's steps span this time when it
        is executed (:meth:`times`). NaN when unknown.
    """

    def __init__(
        self,
        robot: KinematicModel,
        gmms: Mapping[str, GMM],
        *,
        n_steps: int,
        object_names: Sequence[str],
        has_gripper: bool,
        reach: float,
        duration: float = float("nan"),
        rotation_base: Mapping[str, npt.ArrayLike] | None = None,
    ) -> None:
        self.robot = robot
        self.rotation_base: dict[str, Float] = {
            k: np.asarray(v, dtype=np.float64) for k, v in (rotation_base or {}).items()
        }
        self.duration = float(duration)
        self.n_steps = int(n_steps)
        self.object_names = list(object_names)
        self.gmms = {k: gmms[k] for k in [JOINT, *self.object_names]}
        self.has_gripper = bool(has_gripper)
        self.reach = float(reach)
        self._constraints: dict[str, Constraints] = {}

    @property
    def constraint_names(self) -> list[str]:
        """``["joint", *object_names]``."""
        return [JOINT, *self.object_names]

    @property
    def oriented(self) -> list[str]:
        """The objects whose constraint includes the hand's orientation (they need a pose at
        reproduction)."""
        return [k for k in self.object_names if k in self.rotation_base]

    @property
    def n_components(self) -> dict[str, int]:
        """K of each constraint space's GMM."""
        return {k: int(g.n_components_) for k, g in self.gmms.items()}

    @property
    def selection_(self) -> dict[str, ModelSelection]:
        """How K was chosen in each space: the K tried, their scores, the best and the kept K.

        For a skill loaded from a file, the selection recorded when it was learned (method
        ``"fixed"`` for files written before it was recorded).
        """
        return {k: g.selection_ for k, g in self.gmms.items()}

    def times(self, result: ReproductionResult) -> Float:
        """Time stamps in seconds for executing a reproduction.

        A reproduction within motion limits (the default) carries its own timing
        (:attr:`pbdkit.reproduction.ReproductionResult.times`): the steps at the
        demonstrations'
        pace, :attr:`step_seconds` each, stretched where the arm's limits need more time, after
        the lead-in from ``q0``. Otherwise the steps are spread over :attr:`duration`.

        Returns
        -------
        t : ndarray, shape (T,)
        """
        if result.times is not None:
            return np.array(result.times, dtype=np.float64)
        if not np.isfinite(self.duration) or self.duration <= 0:
            raise ValueError("this skill has no known duration; scale result.t yourself")
        return np.asarray(result.t / max(result.t[-1], 1.0) * self.duration, dtype=np.float64)

    @property
    def n_joints(self) -> int:
        """Number of joints n."""
        return int(self.robot.n_joints)

    def __repr__(self) -> str:
        return (
            f"Skill(n_steps={self.n_steps}, n_joints={self.n_joints}, "
            f"constraints={self.constraint_names}, n_components={self.n_components})"
        )

    # ------------------------------------------------------------------ learning
    @classmethod
    def learn(
        cls,
        demos: Sequence[Demonstration],
        robot: KinematicModel,
        *,
        n_steps: int = 1000,
        n_components: int | Literal["auto", "bic"] = "auto",
        max_components: int = MAX_COMPONENTS,
        reg_covar: float | Mapping[str, float] | None = None,
        random_state: int | None = 0,
        fit_samples: int | None = 100,
        bic_samples_per_sequence: float = 20.0,
        task_objects: Sequence[str] | None = None,
        orientation: bool = True,
    ) -> Skill:
        """Learn a skill from demonstrations (paper Table I).

        Parameters
        ----------
        demos : sequence of Demonstration
            At least 2, with the robot's joint count, the same object names, and a gripper
            signal in all or none. Joint angles outside the robot's limits by more than
            :data:`pbdkit.data._demonstration.LIMIT_TOLERANCE` (1e-6 rad: recorded encoders can
            graze a
            limit) give a :class:`pbdkit.data.LimitWarning` per demonstration,
            naming the
            joint, the value and the sample; they are learned as recorded, and reproductions
            are clipped to the limits anyway. Their time stamps are in seconds: their mean
            duration over ``n_steps - 1`` steps must give a step of at least
            :data:`MIN_STEP_SECONDS`.
        robot : KinematicModel
            The arm (e.g. :func:`pbdkit.robots.katana`); its forward kinematics gives x.
        n_steps : int
            Steps of the time grid (the paper: 1000), 2 .. :data:`MAX_STEPS`.
        n_components : int, "auto" or "bic"
            K of every GMM; ``"auto"`` (default) chooses it per space in 1..``max_components``
            by leaving one demonstration out at a time (``docs/math.md``, "Choosing K"): the
            smallest K whose generalized trajectory predicts a left-out demonstration as well
            as the best K does (within :data:`pbdkit.prob._selection.CV_TOLERANCE`), its error
            at every moment measured against the demonstrations' spread at that moment, so that
            phases where they agree (a grasp) are kept whatever they do elsewhere; ``"bic"``: the
            effective-sample-size BIC of earlier versions (kept for comparison).
        max_components : int
            Largest K tried.
        reg_covar : float, dict or None
            The variability floor added to the diagonal of every GMM covariance: no constraint
            is tighter than it. None: :data:`VARIABILITY_FLOOR` (joint angles 0.01 rad, gripper
            0.1, hand positions 1 mm, as standard deviations). A dict overrides some of its
            keys ``"joint"`` (rad^2), ``"gripper"``, ``"task"`` (m^2); a float applies to every
            dimension of every space (the units mix: rad^2 and m^2).
        random_state : int or None
            Seed passed to the GMMs.
        bic_samples_per_sequence : float
            ``n_components="bic"`` only: effective number of samples per demonstration.
        task_objects : sequence of str, optional
            The names of the objects that get a task-space constraint, among those the
            demonstrations record (default: all). An object that never moves (the basin of the
            paper's second task) carries no information about where the hand must go relative
            to it that the joint-space constraint does not already hold; leave it out to learn
            the paper's configuration.
        orientation : bool
            For the objects the demonstrations give as poses: True (default) learns the hand's
            position in each object's frame, R^T (x - p), and its orientation relative to the
            object (module docstring, "Orientation"), so the constraint turns with the object;
            False learns the paper's x - p (frames translate only; the objects' orientations
            are ignored), for comparison. Objects given as positions are the paper's either
            way.
        fit_samples : int or None
            Number of evenly spaced steps per demonstration given to EM (all ``n_steps`` if
            None or larger). Consecutive steps of a smooth motion carry almost no new
            information (the demonstration, not the sample, is the unit of evidence, see
            ``docs/math.md``, "Choosing K"), while EM's cost grows linearly with the points:
            with 1000 steps, 100 of them learn 5 times faster and reproduce as well
            (``benchmarks/README.md``, "Skill learning and reproduction"). The GMMs still
            model time in steps 0 .. n_steps-1.

        Returns
        -------
        skill : Skill

        Warns
        -----
        LimitWarning
            A demonstration leaves the robot's joint limits (see ``demos``).
        """
        items = check_demonstrations(demos, min_demos=2)
        if not isinstance(robot, KinematicModel):
            raise ValueError(
                "robot must provide n_joints, lower, upper, fk and fk_jacobian "
                f"(e.g. pbdkit.robots.katana()), got {type(robot).__name__}"
            )
        n = int(robot.n_joints)
        if items[0].n_joints != n:
            raise ValueError(f"demos have {items[0].n_joints} joints, the robot has {n} joints")
        n_steps = check_int(n_steps, "n_steps", minimum=2, maximum=MAX_STEPS)
        with np.errstate(over="ignore"):  # durations near 1e308: inf, refused next
            duration = float(np.mean([d.duration for d in items]))
        problem = _duration_problem(duration, n_steps)
        if problem:
            raise ValueError(f"demos: {problem} (are the time stamps t in seconds?)")
        _warn_outside_limits(items, robot)
        floors = _variability_floor(reg_covar)
        recorded = list(items[0].object_names)
        if task_objects is None:
            names = recorded
        else:
            if isinstance(task_objects, str):
                task_objects = [task_objects]
            names = list(task_objects)
            unknown = [k for k in names if k not in recorded]
            if unknown or len(set(names)) != len(names):
                raise ValueError(
                    f"task_objects must be distinct names among the recorded objects {recorded}, "
                    f"got {names}"
                )
        has_gripper = items[0].gripper is not None

        n_fit = n_steps if fit_samples is None else check_int(fit_samples, "fit_samples", minimum=2)
        steps = np.unique(np.round(np.linspace(0, n_steps - 1, min(n_fit, n_steps))).astype(int))

        oriented = [k for k in names if orientation and is_pose(items[0].objects[k])]
        if oriented and not hasattr(robot, "fk_pose"):
            raise ValueError(
                f"the objects {oriented} are poses: learning the hand's orientation needs "
                "robot.fk_pose (pbdkit.Robot has it); pass orientation=False to learn positions "
                "only"
            )
        bases = {k: mean_relative_rotation(items, robot, k, n_steps, steps) for k in oriented}
        spaces = space_data(items, robot, names, n_steps, steps, rotation_base=bases)
        data = {k: v.reshape(-1, v.shape[2]) for k, v in spaces.items()}
        groups = np.repeat(np.arange(len(items)), steps.shape[0])  # the demonstration of a row
        # Per dimension: time (steps; a jitter only), then the space's own units.
        space_floor = {
            JOINT: np.r_[TIME_FLOOR, np.full(n, floors["joint"])]
            if not has_gripper
            else np.r_[TIME_FLOOR, np.full(n, floors["joint"]), floors["gripper"]],
            **{
                k: np.r_[TIME_FLOOR, np.full(3, floors["task"])]
                if k not in bases
                else np.r_[
                    TIME_FLOOR, np.full(3, floors["task"]), np.full(3, floors["orientation"])
                ]
                for k in names
            },
        }
        gmms = {
            k: GMM(
                n_components=n_components,
                max_components=max_components,
                reg_covar=space_floor[k],
                random_state=random_state,
                # The gripper is a binary command thresholded at 0.5: K is chosen on the joints.
                score_dims=list(range(1, n + 1)) if k == JOINT else None,
                bic_samples_per_sequence=bic_samples_per_sequence,
            ).fit(X, groups=groups)
            for k, X in data.items()
        }
        theta = data[JOINT][:, 1 : n + 1]
        reach = reach_from_samples(robot, theta)
        return cls(
            robot,
            gmms,
            n_steps=n_steps,
            object_names=names,
            has_gripper=has_gripper,
            reach=reach,
            duration=duration,
            rotation_base=bases,
        )

    def training_data(self, demos: Sequence[Demonstration]) -> dict[str, Float]:
        """The data each GMM of the skill was fitted on, recomputed from ``demos`` at every
        step (what the paper's Figs. 4-5 draw).

        Parameters
        ----------
        demos : sequence of Demonstration
            The demonstrations the skill was learned from (or others with the same
            structure).

        Returns
        -------
        data : dict str -> ndarray, shape (M, T, D)
            ``"joint"``: {t, theta (, gripper)}; each object: {t, x - o}, or for an oriented
            one {t, R^T (x - p), r} (module docstring, "Orientation"); M demonstrations of
            T = :attr:`n_steps` steps.
        """
        items = check_demonstrations(demos, min_demos=1)
        return space_data(
            items, self.robot, self.object_names, self.n_steps, rotation_base=self.rotation_base
        )

    # ------------------------------------------------------------------ generalization
    def constraints(self, covariance: CovarianceMode = "exact") -> Constraints:
        """GMR of every space over the time grid (cached per covariance mode).

        Parameters
        ----------
        covariance : {"exact", "paper"}
            GMR covariance: exact conditional covariance of the mixture, or the paper's
            sum_k beta_k^2 Sigma_k.

        Returns
        -------
        constraints : Constraints
            theta_hat (T, n), Sigma^theta (T, n, n), x_hat^(n) (T, 3), Sigma^x(n) (T, 3, 3),
            gripper (T,) or None.
        """
        if covariance not in ("exact", "paper"):
            raise ValueError(f"covariance must be 'exact' or 'paper', got {covariance!r}")
        cached = self._constraints.get(covariance)
        if cached is not None:
            return cached
        n = self.n_joints
        t = np.arange(self.n_steps, dtype=np.float64)
        mean, cov = self.gmms[JOINT].regress(t[:, None], in_dims=[0], covariance=covariance)
        task_mean: dict[str, Float] = {}
        task_cov: dict[str, Float] = {}
        for k in self.object_names:
            task_mean[k], task_cov[k] = self.gmms[k].regress(
                t[:, None], in_dims=[0], covariance=covariance
            )
        c = Constraints(
            t,
            mean[:, :n],
            cov[:, :n, :n],  # marginal of theta: the gripper is not part of the IK
            task_mean,
            task_cov,
            gripper=mean[:, n] if self.has_gripper else None,
            rotation_base=self.rotation_base,
        )
        self._constraints[covariance] = c
        return c

    # ------------------------------------------------------------------ reproduction
    def reproduce(
        self,
        objects: Mapping[str, npt.ArrayLike],
        *,
        q0: npt.ArrayLike | None = None,
        use: Sequence[str] | str | None = None,
        alpha: float = 0.5,
        covariance: CovarianceMode = "exact",
        max_step: float | None = 0.1,
        on_unreachable: Literal["raise", "warn"] = "raise",
        velocity_limit: LimitSpec = "robot",
        acceleration_limit: LimitSpec = "robot",
        jerk_limit: LimitSpec = "robot",
        line_search: bool = True,
        newton: bool = True,
    ) -> ReproductionResult:
        """Reproduce the skill for new object positions (paper Table II), within the arm's
        velocity, acceleration and jerk limits.

        The reproduction starts with a lead-in move from ``q0`` to the skill's first posture
        (:func:`.first_posture`), then runs the Table II loop at the
        demonstrations' pace; played over :meth:`times` it stays within the limits, starting
        and ending at rest: where the limits need it, the steps get more time (the path and the
        gripper events stay with their steps; :attr:`ReproductionResult.stretch` says by how
        much). See :mod:`pbdkit.reproduction._probabilistic_ik`, "Motion limits".

        Parameters
        ----------
        objects : dict str -> array-like, shape (3,), (4, 4) or (7,)
            Where every object of the skill is in the robot's base frame (m): a position, or
            a pose (a 4x4 transform, or x, y, z, qw, qx, qy, qz with the quaternion w first).
            An object of an oriented constraint (:attr:`oriented`) needs a pose; for the
            others a pose's position is used (their frames translate only).
        q0 : array-like, shape (n,), optional
            Initial posture within the joint limits; default theta_hat_0 (the paper).
        use : sequence of str, optional
            None: all constraints fused. ``["joint"]``: the joint-space controller.
            ``["glass"]``: the task-space controller of that object. Several names: fused.
        alpha : float
            Null-space weight of the task-only controllers (no effect once "joint" is used).
        covariance : {"exact", "paper"}
            GMR covariance mode.
        max_step : float or None
            Largest joint-space step (Euclidean norm, rad): the trust region of the
            linearization; longer steps are scaled down, keeping their direction. None: no
            such bound.
        on_unreachable : {"raise", "warn"}
            What to do when an object's most constrained target o + x_hat is beyond
            :attr:`reach`: raise ValueError, or warn
            (:class:`pbdkit.reproduction.ReachWarning`)
            and reproduce anyway (the hand stops short; never NaN).
        velocity_limit, acceleration_limit, jerk_limit : "robot", float, array-like, or None
            Joint limits (shape (n,) when an array) in rad/s, rad/s^2, rad/s^3. ``"robot"``
            (default): the robot's
            (``robot.velocity_limit`` etc.; a joint whose value is 0, negative or inf is not
            limited); a number (every joint) or one value per joint, > 0 (inf: not limited);
            None: not limited. All three None (or a robot with none, or a skill whose
            :attr:`duration` is unknown): the loop of Table II as written, one sample per
            step, no lead-in, and :meth:`times` spreads the steps over :attr:`duration`. An
            explicit limit needs a known :attr:`duration`.
        line_search : bool
            Fused controller: halve a step that would raise the fused energy of its step
            (:mod:`pbdkit.reproduction._probabilistic_ik`, "Stability"). False: Table II as written.
        newton : bool
            Fused controller: the curvature of the forward kinematics where it stiffens a step,
            which removes the limit cycle of Gauss-Newton where a tight task constraint meets a
            loose joint constraint (:mod:`pbdkit.reproduction._probabilistic_ik`, "Stability").

        Returns
        -------
        result : ReproductionResult
            t (T,) the step of each sample, joints (T, n), positions (T, 3), covariances
            (T, n, n), gripper (T,) bool, influence and influence_joint_space dict name -> (T,),
            task_errors dict name -> (T,), limited (T,) bool (the steps the limits slowed),
            times (T,) s, velocities and accelerations (T, n), lead_in (T,) bool. T is
            n_steps plus the lead-in's samples.

        Raises
        ------
        ValueError
            Bad input, an object out of reach (``on_unreachable="raise"``), or an explicit
            limit for a skill whose :attr:`duration` is unknown.
        """
        options = RunOptions(q0, use, alpha, max_step, on_unreachable, line_search, newton)
        dt, limits = self._motion_limits(velocity_limit, acceleration_limit, jerk_limit)
        return solve(
            self.robot,
            self.constraints(covariance),
            objects,
            options,
            reach=self.reach,
            limits=limits,
            dt=dt,
        )

    def _motion_limits(
        self, velocity: LimitSpec, acceleration: LimitSpec, jerk: LimitSpec
    ) -> tuple[float, MotionLimits | None]:
        """The step duration and the limits a reproduction or controller runs within (None:
        none apply)."""
        dt = self.step_seconds
        limits = MotionLimits.from_robot(
            self.robot, self.n_joints, velocity=velocity, acceleration=acceleration, jerk=jerk
        )
        if not np.isfinite(dt):
            explicit = [
                name
                for name, spec in (
                    ("velocity_limit", velocity),
                    ("acceleration_limit", acceleration),
                    ("jerk_limit", jerk),
                )
                if spec is not None and not (isinstance(spec, str) and spec == "robot")
            ]
            if explicit:
                raise ValueError(
                    f"{explicit[0]} is per second and needs the duration of a step; it is "
                    "unknown (the skill has no known duration): pass None, or bound the steps "
                    "in rad with max_step"
                )
            return dt, None
        return dt, (limits if limits.any else None)

    @property
    def step_seconds(self) -> float:
        """Seconds per step when executed: :attr:`duration` / (n_steps - 1), as :meth:`times`
        (NaN when the duration is unknown)."""
        known = bool(np.isfinite(self.duration) and self.duration > 0)
        return self.duration / (self.n_steps - 1) if known else float("nan")

    def controller(
        self,
        objects: Mapping[str, npt.ArrayLike],
        *,
        q0: npt.ArrayLike | None = None,
        use: Sequence[str] | str | None = None,
        alpha: float = 0.5,
        covariance: CovarianceMode = "exact",
        max_step: float | None = 0.1,
        on_unreachable: Literal["raise", "warn"] = "raise",
        velocity_limit: LimitSpec = "robot",
        acceleration_limit: LimitSpec = "robot",
        jerk_limit: LimitSpec = "robot",
        line_search: bool = True,
        newton: bool = True,
        max_lag: float = 3.0,
    ) -> Controller:
        """One closed-loop run of the skill, step by step from the measured joint angles.

        ``ctrl.step(q_measured, objects=None)`` returns the next command (:class:`Command`);
        ``ctrl.dt`` is the seconds per step (:attr:`step_seconds`), ``ctrl.done`` tells when the
        run is over; ``ctrl.stream(rate_hz)`` gives setpoints for a faster loop. Within the
        robot's limits (the default), consecutive commands are within the velocity,
        acceleration and jerk limits at ``ctrl.dt``, the first one starting from the measured
        posture at rest; see :mod:`._controller` for how the phase follows the arm.
        Without limits (all three None), fed its own commands with constant objects it equals
        :meth:`reproduce` with no limits step for step (one implementation of the loop).

        Parameters
        ----------
        objects, q0, use, alpha, covariance, max_step, on_unreachable
            As :meth:`reproduce` (``q0``: only without limits, the posture the first step
            starts from; with limits the first measured posture is).
        velocity_limit, acceleration_limit, jerk_limit, line_search, newton
            As :meth:`reproduce`.
        max_lag : float
            The phase holds while the measured posture is more than this many steps (at the
            joints' top speed) behind the last command.

        Returns
        -------
        controller : Controller
        """
        options = RunOptions(q0, use, alpha, max_step, on_unreachable, line_search, newton)
        dt, limits = self._motion_limits(velocity_limit, acceleration_limit, jerk_limit)
        step_limit = None
        if limits is None:
            step_limit = step_limit_from_velocity(velocity_limit, self.robot, dt)
        return Controller(
            self.robot,
            self.constraints(covariance),
            objects,
            options,
            step_limit=step_limit,
            dt=dt,
            reach=self.reach,
            max_lag=max_lag,
            limits=limits,
        )

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | os.PathLike[str]) -> None:
        """Save the skill to a versioned ``.npz`` file (no pickle, written atomically).

        The robot is stored as its URDF text and tip frame when it has them (a
        :class:`pbdkit.Robot`); otherwise :meth:`load` needs the robot again. Its velocity,
        acceleration and jerk limits are stored too when it has them (attributes
        ``velocity_limit``, ``acceleration_limit``, ``jerk_limit`` of shape (n_joints,); a value
        that is not > 0, such as a URDF's 0, is stored as inf: no limit).

        Parameters
        ----------
        path : str or path-like
        """
        urdf = getattr(self.robot, "urdf", "")
        tip = getattr(self.robot, "tip", "")
        limits: dict[str, NDArray[np.float64]] = {}
        for kind in ("velocity", "acceleration", "jerk"):
            value = getattr(self.robot, f"{kind}_limit", None)
            arr = None if value is None else np.asarray(value, dtype=np.float64)
            if arr is not None and arr.shape == (self.n_joints,):
                limits[f"robot_{kind}_limit"] = np.where(arr > 0, arr, np.inf)
        arrays: dict[str, Any] = {
            "format": np.array(FORMAT_NAME),
            # Positions only: version 1, as before orientations (older readers load it).
            "version": np.array(FORMAT_VERSION if self.rotation_base else 1, dtype=np.int64),
            "n_steps": np.array(self.n_steps, dtype=np.int64),
            "n_joints": np.array(self.n_joints, dtype=np.int64),
            "object_names": np.array(self.object_names, dtype=np.str_)
            if self.object_names
            else np.zeros(0, dtype="<U1"),
            "has_gripper": np.array(self.has_gripper),
            "reach": np.array(self.reach),
            "duration": np.array(self.duration),
            "robot_urdf": np.array(urdf if isinstance(urdf, str) else ""),
            "robot_tip": np.array(tip if isinstance(tip, str) else ""),
            **limits,
        }
        for i, k in enumerate(self.constraint_names):
            key = "joint" if k == JOINT else str(i - 1)
            g = self.gmms[k]
            arrays[f"gmm_{key}_weights"] = g.weights_
            arrays[f"gmm_{key}_means"] = g.means_
            arrays[f"gmm_{key}_covariances"] = g.covariances_
            sel = g.selection_
            arrays[f"sel_{key}_method"] = np.array(sel.method)
            arrays[f"sel_{key}_candidates"] = np.asarray(sel.candidates, dtype=np.int64)
            arrays[f"sel_{key}_scores"] = np.asarray(sel.scores, dtype=np.float64)
            arrays[f"sel_{key}_fold_scores"] = np.asarray(sel.fold_scores, dtype=np.float64)
            arrays[f"sel_{key}_best_chosen"] = np.array([sel.best, sel.chosen], dtype=np.int64)
            if k in self.rotation_base:
                arrays[f"rot_base_{key}"] = self.rotation_base[k]
        save_npz_atomic(path, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike[str], robot: KinematicModel | None = None) -> Skill:
        """Load a skill saved by :meth:`save`.

        Parameters
        ----------
        path : str or path-like
        robot : KinematicModel, optional
            The arm to use, as it is (the stored limits are checked, not applied to it).
            Default: rebuilt from the stored URDF and tip frame with
            :meth:`pbdkit.Robot.from_urdf`, with the stored velocity, acceleration and jerk
            limits (a file without them: the URDF's velocity limits, no acceleration or jerk
            limits).

        Returns
        -------
        skill : Skill
            Reproduces bit-identical results to the skill that was saved.

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            A corrupt or foreign file, another format version, a key the format does not have,
            arrays of more than :data:`MAX_FILE_BYTES` in all, or inconsistent content.
        """
        p = Path(path)
        # Sizes and keys are checked from the archive's headers before any array is loaded.
        with open_npz(p, what=FORMAT_NAME + " file", max_bytes=MAX_FILE_BYTES) as data:
            return cls._from_archive(data, p, robot)

    @classmethod
    def _from_archive(cls, data: NpzArchive, p: Path, robot: KinematicModel | None) -> Skill:
        """The skill in an open archive (:meth:`load`)."""
        from ..robots._joint_limits import check_limit_array, joint_limits_mapping

        version = check_format(data, p, FORMAT_NAME, READABLE_VERSIONS)
        try:
            names = [str(s) for s in np.asarray(data["object_names"]).reshape(-1)]
        except KeyError as exc:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: missing key {exc}") from exc
        data.check_keys(functools.partial(_is_skill_key, n_objects=len(names)))
        try:
            n_steps = _stored_int(data["n_steps"])
            if n_steps is None or not 2 <= n_steps <= MAX_STEPS:
                raise ValueError(
                    f"n_steps must be an integer in [2, {MAX_STEPS}], got {_shown(data['n_steps'])}"
                )
            n_joints = _stored_int(data["n_joints"])
            if n_joints is None or n_joints < 1:
                raise ValueError(
                    f"n_joints must be an integer >= 1, got {_shown(data['n_joints'])}"
                )
            has_gripper = bool(data["has_gripper"])
            reach = float(data["reach"])
            duration = float(data["duration"]) if "duration" in data else float("nan")
            urdf = str(data["robot_urdf"])
            tip = str(data["robot_tip"])
            gmms: dict[str, GMM] = {}
            rotation_base: dict[str, Float] = {}
            for i, k in enumerate([JOINT, *names]):
                key = "joint" if k == JOINT else str(i - 1)
                gmms[k] = GMM.from_params(
                    data[f"gmm_{key}_weights"],
                    data[f"gmm_{key}_means"],
                    data[f"gmm_{key}_covariances"],
                )
                if f"sel_{key}_method" in data:  # files before the selection was recorded lack it
                    gmms[k].selection_ = _selection_from_arrays(data, key, k)
                if version >= 2 and f"rot_base_{key}" in data:
                    rotation_base[k] = check_rotation(data[f"rot_base_{key}"], f"rot_base_{key}")
        except KeyError as exc:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: missing key {exc}") from exc
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {exc}") from exc
        if len(set(names)) != len(names) or JOINT in names or "" in names:
            raise ValueError(
                f"{p} is not a valid {FORMAT_NAME} file: object names {names} must be unique, "
                f"non-empty and not {JOINT!r}"
            )
        d_joint = 1 + n_joints + int(has_gripper)
        dims = {k: int(g.means_.shape[1]) for k, g in gmms.items()}
        expected = {k: (d_joint if k == JOINT else 7 if k in rotation_base else 4) for k in gmms}
        if dims != expected:
            raise ValueError(
                f"{p} is not a valid {FORMAT_NAME} file: GMM dimensions {dims}, expected "
                f"{expected} for n_joints={n_joints}, gripper={has_gripper} (time, then "
                "the joints and the gripper; time and x - o for an object; time, R^T (x - p) "
                "and the relative orientation for an oriented object)"
            )
        # NaN: unknown (a skill learned before durations were stored); else as learn checks it.
        problem = "" if math.isnan(duration) else _duration_problem(duration, n_steps)
        if problem:
            raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {problem}")
        if not (np.isfinite(reach) and reach > 0):
            raise ValueError(
                f"{p} is not a valid {FORMAT_NAME} file: reach must be > 0, got {reach}"
            )
        stored_limits: dict[str, NDArray[np.float64]] = {}
        for kind in ("velocity", "acceleration", "jerk"):
            name = f"robot_{kind}_limit"
            if name in data:  # files written before the limits were stored lack them
                try:
                    stored_limits[kind] = check_limit_array(data[name], name, n_joints)
                except ValueError as exc:
                    raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {exc}") from exc
        if robot is None:
            if not urdf:
                raise ValueError(
                    f"{p} holds no URDF (the skill was learned with a robot not built from a "
                    "URDF): pass robot= to Skill.load"
                )
            from ..robots._robot import Robot

            try:
                robot = Robot.from_urdf(urdf, tip=tip or None)
                if stored_limits and robot.n_joints == n_joints:  # else refused below
                    limits = joint_limits_mapping(robot.joint_names, **stored_limits)
                    robot = Robot.from_urdf(urdf, tip=tip or None, joint_limits=limits)
            except ValueError as exc:
                raise ValueError(
                    f"{p} is not a valid {FORMAT_NAME} file: its robot URDF does not load: {exc}"
                ) from exc
        if int(robot.n_joints) != n_joints:
            raise ValueError(f"robot has {robot.n_joints} joints, the skill in {p} has {n_joints}")
        return cls(
            robot,
            gmms,
            n_steps=n_steps,
            object_names=names,
            has_gripper=has_gripper,
            reach=reach,
            duration=duration,
            rotation_base=rotation_base,
        )


_BASE_KEYS = frozenset(
    {
        "format",
        "version",
        "n_steps",
        "n_joints",
        "object_names",
        "has_gripper",
        "reach",
        "duration",
        "robot_urdf",
        "robot_tip",
        "robot_velocity_limit",
        "robot_acceleration_limit",
        "robot_jerk_limit",
    }
)
# gmm_{space}_{array} and sel_{space}_{array}: space "joint", or an object's index.
_SPACE_KEY = re.compile(
    r"(?:gmm_(?:joint|(0|[1-9][0-9]{0,8}))_(?:weights|means|covariances)"
    r"|sel_(?:joint|(0|[1-9][0-9]{0,8}))_(?:method|candidates|scores|fold_scores|best_chosen)"
    r"|rot_base_(0|[1-9][0-9]{0,8}))"
)


def _duration_problem(duration: float, n_steps: int) -> str:
    """Why a skill cannot last ``duration`` seconds over ``n_steps`` steps ("" if it can)."""
    if not math.isfinite(duration) or duration <= 0:
        return f"the duration must be finite and > 0 (s), got {duration!r}"
    step = duration / (n_steps - 1)
    if not step >= MIN_STEP_SECONDS:
        return (
            f"a duration of {duration:.6g} s over n_steps={n_steps} steps gives a time step of "
            f"{step:.3g} s; it must be at least MIN_STEP_SECONDS = {MIN_STEP_SECONDS:g} s"
        )
    return ""


def _is_skill_key(key: str, n_objects: int) -> bool:
    """Whether :meth:`Skill.save` writes ``key`` for a skill of ``n_objects`` objects."""
    if key in _BASE_KEYS:
        return True
    match = _SPACE_KEY.fullmatch(key)
    if match is None:
        return False
    index = match.group(1) or match.group(2) or match.group(3)
    return index is None or int(index) < n_objects


def _stored_int(value: NDArray[Any]) -> int | None:
    """The integer stored in a 0-d integer array of a file, or None if it holds anything else."""
    arr = np.asarray(value)
    return int(arr) if arr.shape == () and arr.dtype.kind in "iu" else None


def _shown(value: NDArray[Any]) -> str:
    arr = np.asarray(value)
    return repr(arr.tolist()) if arr.size <= 6 else f"an array of shape {arr.shape}"


def _warn_outside_limits(demos: Sequence[Demonstration], robot: KinematicModel) -> None:
    """One LimitWarning per demonstration whose joints leave the limits by > LIMIT_TOLERANCE.

    Names the joint and the sample where the excess is largest.
    """
    lower = np.asarray(robot.lower, dtype=np.float64)
    upper = np.asarray(robot.upper, dtype=np.float64)
    names = list(getattr(robot, "joint_names", None) or [str(j) for j in range(lower.shape[0])])
    revolute = getattr(robot, "revolute", None)
    for i, d in enumerate(demos):
        excess = np.maximum(lower - d.joints, d.joints - upper)  # (T, n), > 0 outside
        worst = int(np.argmax(excess))
        sample, j = divmod(worst, excess.shape[1])
        if excess[sample, j] <= LIMIT_TOLERANCE:
            continue
        unit = "m" if revolute is not None and not revolute[j] else "rad"
        warnings.warn(
            f"demos[{i}]: joint '{names[j]}' reaches {d.joints[sample, j]:.6g} {unit} at "
            f"t={d.t[sample]:.6g} (sample {sample}), outside its limits "
            f"[{lower[j]:.6g}, {upper[j]:.6g}] by {excess[sample, j]:.3g}; learned as "
            "recorded, reproductions are clipped to the limits",
            LimitWarning,
            stacklevel=3,
        )


def _variability_floor(reg_covar: float | Mapping[str, float] | None) -> dict[str, float]:
    """The floors per kind of dimension, from Skill.learn's ``reg_covar``."""
    if reg_covar is None:
        return dict(VARIABILITY_FLOOR)
    if isinstance(reg_covar, Mapping):
        unknown = [k for k in reg_covar if k not in VARIABILITY_FLOOR]
        if unknown:
            raise ValueError(f"reg_covar: unknown key(s) {unknown}; use {list(VARIABILITY_FLOOR)}")
        out = dict(VARIABILITY_FLOOR)
        for k, v in reg_covar.items():
            out[k] = check_positive_float(v, f"reg_covar[{k!r}]", allow_zero=True)
        return out
    v = check_positive_float(reg_covar, "reg_covar", allow_zero=True)
    return dict.fromkeys(VARIABILITY_FLOOR, v)


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
        with R^T R_hand = exp([r]x) M (module docstring, "Orientation"); M demonstrations,
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
        poses = np.asarray(robot.fk_pose(flat), dtype=np.float64)  # type: ignore[attr-defined]
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
    robot: KinematicModel,
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
        hand = np.asarray(robot.fk_pose(q), dtype=np.float64)[:, :3, :3]  # type: ignore[attr-defined]
        rels.append(d.objects[name][:3, :3].T @ hand)
    return mean_rotation(np.concatenate(rels))


def _selection_from_arrays(data: Mapping[str, Any], key: str, name: str) -> ModelSelection:
    """The ModelSelection stored under ``sel_{key}_*`` by :meth:`Skill.save`."""
    method = str(data[f"sel_{key}_method"])
    cand = np.asarray(data[f"sel_{key}_candidates"]).reshape(-1)
    scores = np.asarray(data[f"sel_{key}_scores"], dtype=np.float64).reshape(-1)
    folds = np.asarray(data[f"sel_{key}_fold_scores"], dtype=np.float64)
    best, chosen = (int(v) for v in np.asarray(data[f"sel_{key}_best_chosen"]).reshape(-1)[:2])
    if (
        method not in ("cv", "bic", "fixed")
        or cand.dtype.kind not in "iu"
        or scores.shape != cand.shape
        or folds.ndim != 2
        or (folds.size and folds.shape[0] != cand.shape[0])
        or best not in cand
        or chosen not in cand
    ):
        raise ValueError(f"the model selection stored for {name!r} is inconsistent")
    n_folds = folds.shape[1] if method == "cv" else 0
    return ModelSelection(method, tuple(int(k) for k in cand), scores, folds, best, chosen, n_folds)
