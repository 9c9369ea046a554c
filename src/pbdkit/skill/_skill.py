"""A skill: learned from demonstrations (paper Table I), reproduced for new objects (Table II).

Learning (:meth:`Skill.learn`):

1. every demonstration is rescaled to ``n_steps`` steps and the data of every constraint space
   computed (:func:`pbdkit.skill._spaces.space_data`): the joint space {t, theta, [gripper]}
   and, for every object n, the task space {t, x - o(n)} (for an object given as a pose,
   {t, R^T (x - p), r});
2. one GMM per space (:class:`pbdkit.GMM`), K chosen per space by cross-validation, leaving one
   demonstration out at a time (``n_components="auto"``, the default; ``"bic"``: the
   effective-sample-size BIC; an int: fixed);
3. GMR over the time grid gives the constraints theta_hat, Sigma^theta, x_hat^(n), Sigma^x(n)
   (:meth:`Skill.constraints`); they do not depend on the new object placements, so they are
   computed once per skill and covariance mode and cached.

Steps 1 and 2 are :func:`pbdkit.skill._encoding.encode`'s; the skill keeps what it learned from
(:mod:`pbdkit.skill._provenance`).

Reproduction (:meth:`Skill.reproduce`) runs :func:`pbdkit.reproduction._probabilistic_ik.solve`,
online control (:meth:`Skill.controller`) a :class:`pbdkit.Controller`. The skill file
(:meth:`Skill.save`, :meth:`Skill.load`) is :mod:`pbdkit.skill._skill_file`'s. The math and the
file's keys: :doc:`/reproduction`.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._defaults import MAX_COMPONENTS
from .._io import open_npz, save_npz_atomic
from .._validation import short
from ..collision import CollisionChecker, CollisionReport, Scene
from ..data._align import align as align_demos
from ..data._demonstration import Demonstration, check_demonstrations
from ..motion._limits import LimitSpec, MotionLimits
from ..prob import GMM, ModelSelection
from ..prob._gmr import CovarianceMode
from ..reproduction._avoid import DEFAULT_MARGIN
from ..reproduction._constraints import JOINT, Constraints
from ..reproduction._controller import Controller
from ..reproduction._probabilistic_ik import SceneRun, solve
from ..reproduction._result import ReproductionResult
from ..reproduction._setup import RunOptions, step_limit_from_velocity
from ..robots._protocols import KinematicModel, PoseKinematicModel, check_robot
from ._active import ActiveMixin
from ._calibration import check_calibration
from ._encoding import encode
from ._provenance import (
    LearnOptions,
    check_learn_options,
    check_learned_from,
    learned_from,
    resolve_task_objects,
)
from ._run_limits import skill_limits
from ._skill_file import (
    FORMAT_NAME,
    MAX_DURATION,
    MAX_FILE_BYTES,
    MAX_FILE_COMPONENTS,
    read_skill,
    skill_arrays,
    skill_duration_problem,
)
from ._spaces import Alignment, space_data, warn_outside_limits

__all__ = ["DEFAULT_ALIGN", "Skill"]

#: ``Skill.learn``'s ``align`` default, chosen on evidence (:doc:`/alignment`, "In Skill.learn").
DEFAULT_ALIGN: bool | Literal["auto"] = True

Float = NDArray[np.float64]


class Skill(ActiveMixin):
    """A skill learned from demonstrations: one GMM per constraint space.

    Build it with :meth:`learn` or :meth:`load`. Built by hand, it takes what it was learned
    from as all or none of ``demonstrations``, ``learn_options`` and ``n_samples`` (checked
    against the skill as :meth:`load` checks a file's).

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
        Number of components K of each GMM (chosen per space when learned with ``"auto"`` or
        ``"bic"``: :attr:`selection_`).
    has_gripper : bool
        Whether the joint-space GMM has a gripper column.
    reach : float
        Reach of the arm from its base origin (m): 1.02 x the largest ||f(theta)|| over 4096
        random postures within the limits and all demonstrated postures.
    duration : float
        Mean duration of the demonstrations (s): a reproduction's steps span this time when it
        is executed (:meth:`times`). NaN when unknown.
    demonstrations_ : list of Demonstration or None
        The demonstrations the skill was learned from, as :meth:`learn` was given them (before
        any alignment or resampling); None for a skill built by hand or loaded from a skill
        file of version 1 or 2 (``update`` and ``suggest`` need them).
    learn_options_ : dict or None
        :meth:`learn`'s options as resolved (``n_steps``, ``n_components``, ``max_components``,
        ``reg_covar``, ``random_state``, ``fit_samples``, ``bic_samples_per_sequence``,
        ``task_objects``, ``orientation``, ``align``, ``calibrate``):
        ``Skill.learn(skill.demonstrations_, skill.robot, **skill.learn_options_)`` learns the
        same skill again, bit for bit. None with ``demonstrations_``.
    n_samples_ : dict str -> int, or None
        The number of data points each space's GMM was fitted on (every demonstration at the
        ``fit_samples`` steps kept). None with ``demonstrations_``.
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
        aligned: Alignment | None = None,
        calibration: Mapping[str, npt.ArrayLike] | None = None,
        demonstrations: Sequence[Demonstration] | None = None,
        learn_options: Mapping[str, object] | None = None,
        n_samples: Mapping[str, int] | None = None,
    ) -> None:
        self.rotation_base: dict[str, Float] = {
            k: np.asarray(v, dtype=np.float64) for k, v in (rotation_base or {}).items()
        }
        # The robot enters here, whichever way the skill is made (learn, load, by hand).
        self.robot = check_robot(
            robot, PoseKinematicModel if self.rotation_base else KinematicModel
        )
        self.duration = float(duration)
        if not (np.isnan(self.duration) or 0.0 < self.duration <= MAX_DURATION):
            raise ValueError(
                "duration must be NaN (unknown) or in (0, MAX_DURATION = "
                f"{MAX_DURATION:g}] s, got {short(duration)}"
            )
        self.n_steps = int(n_steps)
        self.object_names = list(object_names)
        self.gmms = {k: gmms[k] for k in [JOINT, *self.object_names]}
        self.has_gripper = bool(has_gripper)
        self.reach = float(reach)
        self._constraints: dict[str, Constraints] = {}
        #: What learning did about the demonstrations' timing (:class:`Alignment`; true when
        #: they were aligned in time).
        self.aligned_ = Alignment("no", False) if aligned is None else aligned
        #: The factor each space's GMR covariance is widened by at every step, (n_steps,) per
        #: space (all ones: as fitted; ``docs/math.md``, "Calibration").
        self.calibration_ = check_calibration(
            calibration, [JOINT, *self.object_names], self.n_steps
        )
        learned = check_learned_from(
            demonstrations,
            learn_options,
            n_samples,
            n_joints=self.n_joints,
            has_gripper=self.has_gripper,
            object_names=self.object_names,
            oriented=self.rotation_base,
            n_steps=self.n_steps,
            k_max=MAX_FILE_COMPONENTS,
        )
        self.demonstrations_ = None if learned is None else learned.demonstrations
        self.learn_options_ = None if learned is None else learned.options
        self.n_samples_ = None if learned is None else learned.n_samples

    def _learned_from(self, what: str) -> tuple[list[Demonstration], LearnOptions]:
        """Copies of :attr:`demonstrations_` and :attr:`learn_options_`, for the method
        ``what`` (``"update"``, ``"suggest"``): ValueError, one line, if the skill has none."""
        return learned_from(self.demonstrations_, self.learn_options_, what)

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
    def n_components_(self) -> dict[str, int]:
        """The learned K of each constraint space's GMM, name -> K."""
        return {k: int(g.n_components_) for k, g in self.gmms.items()}

    @property
    def n_components(self) -> dict[str, int]:
        """The learned K of each space: :attr:`n_components_` (a read-only alias of it, the
        name of evaluate's JSON and of the checks that read it)."""
        return self.n_components_

    @property
    def selection_(self) -> dict[str, ModelSelection]:
        """How K was chosen in each space: the K tried, their scores, the best and the kept K
        (loaded: as recorded when learned; ``"fixed"`` for files written before)."""
        return {k: g.selection_ for k, g in self.gmms.items()}

    def times(self, result: ReproductionResult) -> Float:
        """Time stamps in seconds for executing a reproduction.

        A reproduction within motion limits (the default) carries its own timing
        (:attr:`pbdkit.reproduction.ReproductionResult.times`): the steps at the demonstrations'
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
        align: bool | Literal["auto"] = DEFAULT_ALIGN,
        calibrate: bool = True,
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
            :data:`~pbdkit.skill._spaces.MIN_STEP_SECONDS`.
        robot : KinematicModel
            The arm (e.g. :func:`pbdkit.robots.katana`); its forward kinematics gives x.
        n_steps : int
            Steps of the time grid (the paper: 1000), 2 .. :data:`~pbdkit.skill._spaces.MAX_STEPS`.
        n_components : int, "auto" or "bic"
            K of every GMM; ``"auto"`` (default) chooses it per space in 12..``max_components``
            (1.. for a cap of 12 or less; :data:`pbdkit.prob._selection.MIN_COMPONENTS`)
            by leaving one demonstration out at a time (``docs/math.md``, "Choosing K"): the
            smallest K whose generalized trajectory predicts a left-out demonstration as well
            as the K tried do (within :data:`pbdkit.prob._selection.CV_TOLERANCE` of the level
            two of them reach), its error at every moment measured against the demonstrations'
            spread at that moment, so that phases where they agree (a grasp) are kept whatever
            they do elsewhere; ``"bic"``: the effective-sample-size BIC of earlier versions
            (kept for comparison).
        max_components : int
            Largest K tried. K (given or chosen) is at most
            :data:`~pbdkit.skill._skill_file.MAX_FILE_COMPONENTS` (1000), as :meth:`load` reads.
        reg_covar : float, dict or None
            The variability floor added to the diagonal of every GMM covariance: no constraint
            is tighter than it. None: :data:`~pbdkit.skill._spaces.VARIABILITY_FLOOR` (joint
            angles 0.01 rad, gripper 0.1, hand positions 1 mm, as standard deviations). A dict
            overrides some of its keys ``"joint"`` (rad^2), ``"gripper"``, ``"task"`` (m^2); a
            float applies to every dimension of every space (the units mix: rad^2 and m^2).
        random_state : int or None
            Seed passed to the GMMs: None or an integer in [0, 2**32 - 1].
        bic_samples_per_sequence : float
            ``n_components="bic"`` only: effective number of samples per demonstration (> 0,
            checked whatever ``n_components``).
        task_objects : sequence of str, optional
            The names of the objects that get a task-space constraint, among those the
            demonstrations record (default: all). An object that never moves (the basin of the
            paper's second task) carries no information about where the hand must go relative
            to it that the joint-space constraint does not already hold; leave it out to learn
            the paper's configuration.
        orientation : bool
            For the objects the demonstrations give as poses: True (default) learns the hand's
            position in each object's frame, R^T (x - p), and its orientation relative to the
            object (:doc:`/reproduction`, "Orientation constraints"), so the constraint turns
            with the object;
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

        align : bool or "auto"
            Align the demonstrations in time before encoding them (:func:`pbdkit.align`:
            dynamic time warping onto the medoid within a band of 0.3 of the duration; their
            data stay as recorded): True (the default), False (linear rescaling, the paper's),
            or ``"auto"`` (aligned when that makes their spread at least 20 % smaller than in
            linear time). What was done is :attr:`aligned_`. Why aligned by default:
            :doc:`/alignment`, "In Skill.learn".
        calibrate : bool
            Widen the joint space's GMR covariance where the demonstrations left out one at a
            time fall further outside it than outside the best-described object's space, and
            the objects' spaces alike where they fall further outside all of those than outside
            the joints' (:class:`~pbdkit.prob.GMM`'s ``loo_residuals``; ``docs/math.md``,
            "Calibration"): True (default) keeps the joints' constraint from winning the fusion
            where the demonstrated postures disagreed (postures that differ at a grasp), and
            from losing it where the objects' positions disagreed more (the basin's pour);
            False keeps the covariances EM fitted (the paper's).

        Returns
        -------
        skill : Skill
            Keeps what it learned from: :attr:`demonstrations_` (``demos``), :attr:`learn_options_`
            (these options as resolved: ``task_objects`` as the list of names,
            ``fit_samples`` at most ``n_steps``) and :attr:`n_samples_`.

        Warns
        -----
        LimitWarning
            A demonstration leaves the robot's joint limits (see ``demos``).
        SelectionWarning
            A space's K (``"auto"``) is at ``max_components`` where its score still falls; the
            message names the space and what to do.
        """
        items = check_demonstrations(demos, min_demos=2)
        check_robot(robot, KinematicModel)
        n = int(robot.n_joints)
        if items[0].n_joints != n:
            raise ValueError(f"demos have {items[0].n_joints} joints, the robot has {n} joints")
        names = resolve_task_objects(task_objects, items[0].object_names)
        # Checked and resolved as they are kept (learn_options_); K as Skill.load reads it.
        options = check_learn_options(
            {
                "n_steps": n_steps,
                "n_components": n_components,
                "max_components": max_components,
                "reg_covar": reg_covar,
                "random_state": random_state,
                "fit_samples": fit_samples,
                "bic_samples_per_sequence": bic_samples_per_sequence,
                "task_objects": names,
                "orientation": orientation,
                "align": align,
                "calibrate": calibrate,
            },
            k_max=MAX_FILE_COMPONENTS,
        )
        with np.errstate(over="ignore"):  # durations near 1e308: inf, refused next
            duration = float(np.mean([d.duration for d in items]))
        problem = skill_duration_problem(duration, options["n_steps"])
        if problem:
            raise ValueError(f"demos: {problem} (are the time stamps t in seconds?)")
        warn_outside_limits(items, robot)
        code = encode(items, robot, options)
        return cls(
            robot,
            code.gmms,
            n_steps=options["n_steps"],
            object_names=names,
            has_gripper=items[0].gripper is not None,
            reach=code.reach,
            duration=duration,
            rotation_base=code.rotation_base,
            aligned=code.aligned,
            calibration=code.calibration,
            demonstrations=items,
            learn_options=options,
            n_samples=code.n_samples,
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
            one {t, R^T (x - p), r} (:func:`~pbdkit.skill._spaces.space_data`); M demonstrations of
            T = :attr:`n_steps` steps.
        """
        items = check_demonstrations(demos, min_demos=1)
        if self.aligned_.applied and len(items) > 1:  # aligned as they were when learned
            items = align_demos(
                items, self.robot, band=self.aligned_.band, reference=self.aligned_.reference
            )
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
            raise ValueError(f"covariance must be 'exact' or 'paper', got {short(covariance)}")
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
        factor = self.calibration_
        c = Constraints(
            t,
            mean[:, :n],
            # marginal of theta: the gripper is not part of the IK
            cov[:, :n, :n] * factor[JOINT][:, None, None],
            task_mean,
            {k: v * factor[k][:, None, None] for k, v in task_cov.items()},
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
        scene: Scene | None = None,
        avoid: bool = True,
        margin: float = DEFAULT_MARGIN,
    ) -> ReproductionResult:
        """Reproduce the skill for new object positions (paper Table II), within the arm's
        velocity, acceleration and jerk limits.

        The reproduction starts with a lead-in move from ``q0`` to the skill's first posture
        (:func:`.first_posture`), then runs the Table II loop at the
        demonstrations' pace; played over :meth:`times` it stays within the limits, starting
        and ending at rest: where the limits need it, the steps get more time (the path and the
        gripper events stay with their steps; :attr:`ReproductionResult.stretch` says by how
        much). See :doc:`/reproduction`, "Motion limits and lead-in".

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
            (:doc:`/reproduction`, "Stability"). False: Table II as written.
        newton : bool
            Fused controller: the curvature of the forward kinematics where it stiffens a step,
            which removes the limit cycle of Gauss-Newton where a tight task constraint meets a
            loose joint constraint (:doc:`/reproduction`, "Stability").

        scene : pbdkit.Scene, optional
            Obstacles, and shapes for the skill's objects (:doc:`/collisions`): the result has
            ``clearance`` and ``collisions``; with ``avoid`` the fused controller keeps
            ``margin`` from them (a clearance constraint in the product, ``influence`` key
            "clearance") and warns (``CollisionWarning``, ``res.infeasible``) where it
            cannot. Needs a robot with a collision model.
        avoid : bool
            With a scene: keep clear (default) or only check (False).
        margin : float
            The clearance kept (m); a run never this close to anything is the run without
            a scene, to the bit.
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
        options = RunOptions(
            q0=q0,
            use=use,
            alpha=alpha,
            max_step=max_step,
            on_unreachable=on_unreachable,
            line_search=line_search,
            newton=newton,
        )
        dt, limits = skill_limits(self, velocity_limit, acceleration_limit, jerk_limit)
        return solve(
            self.robot,
            self.constraints(covariance),
            objects,
            options,
            reach=self.reach,
            limits=limits,
            dt=dt,
            scene=scene,
            avoid=avoid,
            margin=margin,
        )

    def check(
        self,
        joints: npt.ArrayLike,
        scene: Scene,
        *,
        objects: Mapping[str, npt.ArrayLike] | None = None,
        gripper: npt.ArrayLike | None = None,
    ) -> CollisionReport:
        """Clearance and collisions of any joint trajectory (T, n) of this skill's robot (a
        bag, another planner's) in ``scene``: :class:`~pbdkit.collision.CollisionReport`.
        ``objects`` places the skill's objects that have a shape in the scene; ``gripper``
        (T,), closed where True or > 0.5, tells the grasps (:doc:`/collisions`)."""
        return CollisionChecker(self.robot, scene, objects).check(joints, gripper)

    def motion_limits(
        self,
        velocity_limit: LimitSpec = "robot",
        acceleration_limit: LimitSpec = "robot",
        jerk_limit: LimitSpec = "robot",
    ) -> MotionLimits | None:
        """The velocity, acceleration and jerk limits :meth:`reproduce` and :meth:`controller`
        keep with these arguments (the robot's by default; a robot that declares no
        acceleration or jerk limit gets defaults derived from its velocity limits, with a
        :class:`~pbdkit.motion._limits.DefaultLimitsWarning`); None where none apply. E.g. to
        check a trajectory bag: ``write_trajectory_bag(..., limits=skill.motion_limits())``."""
        return skill_limits(self, velocity_limit, acceleration_limit, jerk_limit)[1]

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
        planner: Literal["inline", "process"] = "inline",
        scene: Scene | None = None,
        avoid: bool = True,
        margin: float = DEFAULT_MARGIN,
    ) -> Controller:
        """One closed-loop run of the skill, step by step from the measured joint angles.

        ``ctrl.step(q_measured, objects=None)`` returns the next command (:class:`Command`);
        ``ctrl.dt`` is the seconds per step (:attr:`step_seconds`), ``ctrl.done`` tells when the
        run is over; ``ctrl.stream(rate_hz)`` gives setpoints for a faster loop, its plans made
        in a separate process (the loop never waits for one). Within the
        robot's limits (the default), consecutive commands are within the velocity,
        acceleration and jerk limits at ``ctrl.dt``, the first one starting from the measured
        posture at rest; see :doc:`/reproduction`, "The online controller", for how the phase
        follows the arm.
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
        planner : {"inline", "process"}
            With limits, where :meth:`Controller.step` makes its plans: "inline" (default: it
            waits for them, 25-150 ms; a simulation's run depends only on its inputs) or
            "process" (a separate process; a real arm's loop calling ``ctrl.step`` itself never
            waits): :doc:`/reproduction`, "Plans off the control loop".
        scene, avoid, margin
            As :meth:`reproduce`, for every plan (with limits): one that would still collide
            is not followed, the arm brakes to rest and ``ctrl.fault`` says why.

        Returns
        -------
        controller : Controller
        """
        options = RunOptions(
            q0=q0,
            use=use,
            alpha=alpha,
            max_step=max_step,
            on_unreachable=on_unreachable,
            line_search=line_search,
            newton=newton,
        )
        dt, limits = skill_limits(self, velocity_limit, acceleration_limit, jerk_limit)
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
            planner=planner,
            scene=None if scene is None else SceneRun(scene, avoid, margin),
        )

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | os.PathLike[str]) -> None:
        """Save the skill to a versioned ``.npz`` file (no pickle, written atomically; its keys:
        :doc:`/reproduction`, "File formats").

        The robot is stored as its URDF text and tip frame when it is a
        :class:`~pbdkit.robots.RobotDescription` (a :class:`pbdkit.Robot`); otherwise
        :meth:`load` needs the robot again. Its velocity, acceleration and jerk limits are
        stored too (a value that is not > 0, such as a URDF's 0, is stored as inf: no limit).

        A skill that keeps what it learned from (:attr:`demonstrations_`) is written as version
        3, with its demonstrations (the arrays of :func:`pbdkit.save_demonstrations`),
        :attr:`learn_options_` and :attr:`n_samples_`; one that does not as version 2 (oriented
        constraints) or 1, which older versions of pbdkit read.

        Parameters
        ----------
        path : str or path-like

        Raises
        ------
        ValueError
            Arrays of more than :data:`~pbdkit.skill._skill_file.MAX_FILE_BYTES` (64 MiB) in
            all, which :meth:`load` would refuse (long recordings kept as demonstrations):
            nothing is written.
        """
        arrays = skill_arrays(self)
        save_npz_atomic(path, arrays, what="skill", max_bytes=MAX_FILE_BYTES)

    @classmethod
    def load(cls, path: str | os.PathLike[str], robot: KinematicModel | None = None) -> Skill:
        """Load a skill saved by :meth:`save`.

        Parameters
        ----------
        path : str or path-like
        robot : KinematicModel, optional
            The arm to use, as it is (the stored limits are checked, not applied to it): a
            :class:`~pbdkit.robots.KinematicModel`, and a
            :class:`~pbdkit.robots.PoseKinematicModel` for a skill with oriented constraints.
            Default: rebuilt from the stored URDF and tip frame with
            :meth:`pbdkit.Robot.from_urdf`, with the stored velocity, acceleration and jerk
            limits (a file without them: the URDF's velocity limits, no acceleration or jerk
            limits).

        Returns
        -------
        skill : Skill
            Reproduces bit-identical results to the skill that was saved. Of a version-3 file,
            with its :attr:`demonstrations_`, :attr:`learn_options_` and :attr:`n_samples_`
            as saved; of version 1 or 2, with None for each.

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            A corrupt or foreign file, another format version, a key the format does not have,
            arrays of more than :data:`~pbdkit.skill._skill_file.MAX_FILE_BYTES` in all,
            inconsistent content (of a version-3 file also: demonstrations that
            :func:`pbdkit.load_demonstrations` would refuse, or that do not fit the skill, and
            options that :meth:`learn` would refuse; the message names the key), or a
            ``robot`` that lacks a member the skill needs.
        """
        p = Path(path)
        # Sizes and keys are checked from the archive's headers before any array is loaded.
        with open_npz(p, what=FORMAT_NAME + " file", max_bytes=MAX_FILE_BYTES) as data:
            stored = read_skill(data, p, robot)
        keywords = {f.name: getattr(stored, f.name) for f in dataclasses.fields(stored)}
        return cls(keywords.pop("robot"), keywords.pop("gmms"), **keywords)
