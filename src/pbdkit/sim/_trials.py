"""Trials: every controller at a placement, serially or on Dask workers, under one set of
:class:`TrialConditions`.

A trial is three steps: what the skill is told (:func:`observe_trial`: the cameras, once), one
run per controller (:func:`run_trial_controller`), and the record of the trial
(:func:`assemble_trial`). :func:`run_trial` does them in a row; :func:`run_trials` runs many
trials, here or on Dask workers (:func:`pbdkit.sim._parallel.run_fanout`: the observations are
the first stage, the controller runs the second). A trial depends on nothing but its index,
placement and conditions (its disturbance is drawn from the seed and its index; physics is
deterministic), so the trials come back identical to the serial run's, in the placements' order,
whatever worker ran them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import check_int, check_positive_float, short
from ._metrics import tracking_errors
from ._obstacle import avoided_scene
from ._parallel import run_fanout
from ._perturb import Disturbance, DisturbanceSetup, check_perturb, make_disturbance
from ._runs import run_controller, run_online
from ._sensing import observation_noise, observe
from ._task_skill import TaskSkill
from ._tracking import ObjectNotSeenError, SimTracker

__all__ = [
    "ControllerOutcome",
    "Trial",
    "TrialConditions",
    "TrialJob",
    "TrialObservation",
    "assemble_trial",
    "observe_trial",
    "run_trial",
    "run_trial_controller",
    "run_trials",
    "trial_disturbance",
]

Float = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class TrialConditions:
    """How the trials of a run are run: one value, built once where the run is asked for (the
    command line, :func:`pbdkit.sim.evaluate`, ``pbdkit demo`` and ``pbdkit study``), passed
    whole to everything below.

    Attributes
    ----------
    online : bool
        Run the controllers online, in the physics loop (:func:`pbdkit.sim._runs.run_online`),
        told the positions at 15 Hz; False (default): reproduce once and play the trajectory
        (:func:`pbdkit.sim._runs.run_controller`).
    perturb : str
        A disturbance of :func:`pbdkit.sim.perturbation_names`, drawn per trial (the same for
        every controller of the trial) from ``seed`` and the trial's index; ``"none"``
        (default). Checked against the task where the run starts
        (:func:`pbdkit.sim._perturb.check_perturb`).
    ground_truth : bool
        Tell the skill the true object positions; False (default): the stereo cameras' (a
        calibrated :class:`pbdkit.sim._tracking.SimTracker`).
    seed : int
        Seeds the disturbances and the noise (an evaluation's demonstrations and placements
        too); >= 0.
    noise_mm : float
        Gaussian noise added to the positions the skill is told of the moving objects (after
        the cameras, if any), of mean 3-D length ``noise_mm`` (:func:`run_trial`); >= 0.
    avoid_scene : bool
        The fused controllers avoid the task's whole scene (:attr:`pbdkit.sim.TaskSpec.scene`),
        not only ``--perturb obstacle``'s box (offline and online). Every run is checked against the
        scene either way (:mod:`pbdkit.sim._obstacle`).

    Raises
    ------
    ValueError
        On construction: a flag that is not a bool, ``perturb`` not a string, ``seed`` not an
        integer >= 0, ``noise_mm`` not a finite number >= 0.
    """

    online: bool = False
    perturb: str = "none"
    ground_truth: bool = False
    seed: int = 0
    noise_mm: float = 0.0
    avoid_scene: bool = False

    def __post_init__(self) -> None:
        for flag in ("online", "ground_truth", "avoid_scene"):
            if not isinstance(getattr(self, flag), bool):
                raise ValueError(f"{flag} must be True or False, got {short(getattr(self, flag))}")
        if not isinstance(self.perturb, str):
            raise ValueError(f"perturb must be a perturbation's name, got {short(self.perturb)}")
        object.__setattr__(self, "seed", check_int(self.seed, "seed", minimum=0))
        noise = check_positive_float(self.noise_mm, "noise_mm", allow_zero=True)
        object.__setattr__(self, "noise_mm", noise)

    @property
    def vision(self) -> bool:
        """True when the skill is told what the cameras see (not ``ground_truth``)."""
        return not self.ground_truth


@dataclass(frozen=True, kw_only=True)
class Trial:
    """One placement of an evaluation and what every controller did there.

    Attributes
    ----------
    truth : dict str -> ndarray, shape (3,)
        The true positions of every object.
    observed : dict str -> ndarray, shape (3,), or None
        What the skill was told (the cameras' positions with vision, else ``truth``); None if
        the cameras did not locate every tracked object.
    tracking_status : dict str -> str
        The tracker's status per object when ``observed`` is None, else empty.
    tracking_error_mm : dict str -> float or None
        Distance from the observed to the true position, per tracked object (vision only).
    runs : dict str -> dict
        Per controller, :meth:`pbdkit.sim._runs.ControllerRun.as_dict` (JSON-ready), or
        ``{"success": False, "tracking_status": ...}`` when the objects were not located.
    perturb : dict
        The trial's disturbance (:meth:`pbdkit.sim.Disturbance.as_dict`;
        ``{"name": "none"}`` without one).
    """

    truth: dict[str, Float]
    observed: dict[str, Float] | None
    tracking_status: dict[str, str]
    tracking_error_mm: dict[str, float] | None
    runs: dict[str, dict[str, Any]]
    perturb: dict[str, Any] = field(default_factory=lambda: {"name": "none"})


@dataclass(frozen=True, kw_only=True)
class TrialObservation:
    """What the skill of a trial is told (:func:`observe_trial`).

    Attributes
    ----------
    told : dict str -> ndarray, shape (3,), or None
        The positions the skill is told; None if the cameras did not locate every tracked
        object.
    statuses : dict str -> str
        The tracker's status per object when ``told`` is None, else empty.
    errors_mm : dict str -> float or None
        Distance from the observed to the true position per tracked object (vision only).
    """

    told: dict[str, Float] | None
    statuses: dict[str, str]
    errors_mm: dict[str, float] | None


@dataclass(frozen=True, kw_only=True)
class ControllerOutcome:
    """One controller's run in a trial (:func:`run_trial_controller`): its name, its summary
    (:meth:`pbdkit.sim._runs.ControllerRun.as_dict`) and the trial's disturbance as it acted
    (:meth:`pbdkit.sim.Disturbance.as_dict`; None if nothing ran)."""

    controller: str
    summary: dict[str, Any]
    disturbance: dict[str, Any] | None


def observe_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    conditions: TrialConditions,
    *,
    tracker: SimTracker | None = None,
) -> TrialObservation:
    """The positions the skill of trial ``index`` is told (:func:`run_trial`): the cameras'
    with a ``tracker`` (the arm waiting at its start posture), else the truth; plus
    ``conditions.noise_mm`` of noise drawn from the seed and ``index``."""
    told: dict[str, Float] | None = truth
    statuses: dict[str, str] = {}
    errors: dict[str, float] | None = None
    if tracker is not None:
        try:
            told = observe(ts.task, truth, tracker, arm=ts.start_posture)
        except ObjectNotSeenError as exc:
            told = None
            statuses = {k: str(tr.status) for k, tr in exc.tracks.items()}
        else:
            errors = tracking_errors(told, truth, tracker.objects)
    if conditions.noise_mm > 0.0 and told is not None:
        told = observation_noise(
            ts.task, told, conditions.noise_mm, seed=conditions.seed, index=index
        )
    return TrialObservation(told=told, statuses=statuses, errors_mm=errors)


def run_trial_controller(
    ts: TaskSkill,
    seen: TrialObservation,
    truth: dict[str, Float],
    index: int,
    controller: str,
    conditions: TrialConditions,
    *,
    tracker: SimTracker | None = None,
) -> ControllerOutcome:
    """One controller of trial ``index`` (:func:`run_trial`), told ``seen``; a failure
    without running when the cameras did not locate the objects."""
    if seen.told is None:
        return ControllerOutcome(
            controller=controller,
            summary={"success": False, "tracking_status": seen.statuses},
            disturbance=None,
        )
    act = trial_disturbance(ts, conditions, truth, index=index)
    avoid = avoided_scene(ts.task, truth, act, whole=conditions.avoid_scene)
    if conditions.online:
        summary = run_online(
            ts,
            seen.told,
            controller,
            tracker=tracker,
            sim_objects=truth,
            disturbance=act,
            avoid=avoid,
        ).as_dict()
    else:
        summary = run_controller(
            ts, seen.told, controller, sim_objects=truth, disturbance=act, avoid=avoid
        ).as_dict()
    return ControllerOutcome(controller=controller, summary=summary, disturbance=act.as_dict())


def assemble_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    seen: TrialObservation,
    runs: Sequence[ControllerOutcome],
    conditions: TrialConditions,
) -> Trial:
    """The :class:`Trial` of :func:`run_trial` from its observation and its controllers' runs
    (in the order of the controllers)."""
    acted = [r.disturbance for r in runs if r.disturbance is not None]
    described = (
        acted[-1] if acted else trial_disturbance(ts, conditions, truth, index=index).as_dict()
    )
    return Trial(
        truth=truth,
        observed=seen.told,
        tracking_status=seen.statuses,
        tracking_error_mm=seen.errors_mm,
        runs={r.controller: r.summary for r in runs},
        perturb=described,
    )


def trial_disturbance(
    ts: TaskSkill, conditions: TrialConditions, truth: dict[str, Float], *, index: int = 0
) -> Disturbance:
    """The disturbance ``conditions.perturb`` of trial ``index``:
    :func:`pbdkit.sim._perturb.make_disturbance` timed on the skill's grasp (its time grid at
    :attr:`pbdkit.Skill.step_seconds`) and drawn from the seed and ``index``. A new object each
    call (a disturbance keeps state while it acts), the same disturbance for the same
    arguments."""
    grid = np.arange(ts.skill.n_steps, dtype=np.float64) * ts.skill.step_seconds
    setup = DisturbanceSetup(
        task=ts.task,
        objects=truth,
        times=grid,
        gripper=ts.skill.constraints().gripper,
        rng=np.random.default_rng([conditions.seed, 2, index]),
        skill=ts.skill,
    )
    return make_disturbance(conditions.perturb, setup)


def run_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    controllers: Sequence[str],
    conditions: TrialConditions,
    *,
    tracker: SimTracker | None = None,
    progress: Callable[[int], None] | None = None,
) -> Trial:
    """One trial of :func:`run_trials`: trial ``index``, every controller at placement ``truth``.

    Depends on nothing but its arguments (the disturbance is drawn from the seed and
    ``index``), so trials may run in any order, in any process, with the same results.
    ``progress(k)`` is called after the k-th controller's run. ``conditions.noise_mm`` > 0
    adds Gaussian noise to the positions the skill is told of the moving objects (after the
    cameras, if any): isotropic, scaled so that its mean 3-D length is ``noise_mm`` (per-axis
    standard deviation ``noise_mm / sqrt(8 / pi)``), drawn from the seed and ``index``.

    The same three steps run apart on Dask workers (:mod:`pbdkit.sim._parallel`):
    :func:`observe_trial` once, :func:`run_trial_controller` per controller, then
    :func:`assemble_trial`.
    """
    seen = observe_trial(ts, truth, index, conditions, tracker=tracker)
    runs: list[ControllerOutcome] = []
    for k, name in enumerate(controllers, start=1):
        runs.append(run_trial_controller(ts, seen, truth, index, name, conditions, tracker=tracker))
        if progress is not None:
            progress(k)
    return assemble_trial(ts, truth, index, seen, runs, conditions)


def run_trials(
    ts: TaskSkill,
    placements: Sequence[dict[str, Float]],
    controllers: Sequence[str],
    conditions: TrialConditions,
    *,
    tracker: SimTracker | None = None,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
) -> list[Trial]:
    """Execute every controller on every placement (the running half of
    :func:`pbdkit.sim.evaluate`).

    Parameters
    ----------
    ts : TaskSkill
    placements : sequence of dict str -> ndarray, shape (3,)
        True positions of every object of the task.
    controllers : sequence of str
        Names from :func:`pbdkit.skill.controller_names`.
    conditions : TrialConditions
        Online or offline, the disturbance (drawn per trial, the same for every controller of
        the trial, from the seed and the trial's index), the cameras or the truth, the noise.
    tracker : SimTracker, optional
        The cameras' tracker: the skill is told the positions it measures. Needed unless
        ``conditions.ground_truth`` (then the skill is told the true positions, and a tracker
        is not used).
    progress : callable, optional
        ``progress(done, total)`` after every execution.
    workers : int, optional
        Run the trials in this many local worker processes (a Dask ``LocalCluster``,
        :mod:`pbdkit.sim._parallel`); results are identical to the serial run. On Dask, each
        trial's observation is one task and each of its controller runs another, which waits
        for it: the last worker to finish waits for one controller run, not for a whole
        trial, and more workers than trials still all have work.
    scheduler : str, optional
        Run them on the Dask cluster at this address (``tcp://HOST:PORT``) instead.
    client : distributed.Client or pbdkit.sim._parallel.Session, optional
        Run them with this Dask client, or the client of this session (kept open: a study runs
        many evaluations on one cluster).

    Returns
    -------
    trials : list of Trial
        In the order of ``placements``.

    Raises
    ------
    ValueError
        An unknown controller or perturbation, or no ``tracker`` for trials told what the
        cameras see.
    """
    for name in controllers:
        ts.skill_for(name)  # an unknown name: ValueError before anything runs
    check_perturb(conditions.perturb, ts.task)
    if conditions.ground_truth:
        tracker = None
    elif tracker is None:
        raise ValueError(
            "tracker: the trials are told what the cameras see (conditions.ground_truth is "
            "False); give a calibrated tracker (pbdkit.sim._sensing.calibrate_tracker)"
        )
    job = TrialJob(ts=ts, controllers=tuple(controllers), tracker=tracker, conditions=conditions)
    if workers is not None or scheduler is not None or client is not None:
        # The demonstrations stay here: the workers need the skill and the task only.
        sent = replace(job, ts=replace(job.ts, demos=[]))
        seen, runs = run_fanout(
            _observe,
            _run_controller,
            sent,
            placements,
            job.controllers,
            progress=progress,
            workers=workers,
            scheduler=scheduler,
            client=client,
        )
        return [job.assemble(i, truth, seen[i], runs[i]) for i, truth in enumerate(placements)]
    total = len(placements) * len(controllers)
    out = []
    for i, truth in enumerate(placements):

        def tick(k: int, i: int = i) -> None:
            if progress is not None:
                progress(i * len(controllers) + k, total)

        out.append(job.run(i, truth, progress=tick))
    return out


@dataclass(frozen=True, kw_only=True)
class TrialJob:
    """What every trial of a run shares (the arguments of :func:`run_trial` but the trial's
    own): sent once to each Dask worker."""

    ts: TaskSkill
    controllers: tuple[str, ...]
    tracker: SimTracker | None
    conditions: TrialConditions

    def run(
        self, index: int, truth: dict[str, Float], progress: Callable[[int], None] | None = None
    ) -> Trial:
        """Trial ``index`` at placement ``truth`` (:func:`run_trial`)."""
        return run_trial(
            self.ts,
            truth,
            index,
            self.controllers,
            self.conditions,
            tracker=self.tracker,
            progress=progress,
        )

    def observe(self, index: int, truth: dict[str, Float]) -> TrialObservation:
        """What the skill of trial ``index`` is told (:func:`observe_trial`)."""
        return observe_trial(self.ts, truth, index, self.conditions, tracker=self.tracker)

    def run_controller(
        self, seen: TrialObservation, index: int, truth: dict[str, Float], controller: str
    ) -> ControllerOutcome:
        """One controller of trial ``index`` (:func:`run_trial_controller`)."""
        return run_trial_controller(
            self.ts, seen, truth, index, controller, self.conditions, tracker=self.tracker
        )

    def assemble(
        self,
        index: int,
        truth: dict[str, Float],
        seen: TrialObservation,
        runs: Sequence[ControllerOutcome],
    ) -> Trial:
        """Trial ``index`` from its parts (:func:`assemble_trial`)."""
        return assemble_trial(self.ts, truth, index, seen, runs, self.conditions)


# The two stages of a trial on a Dask worker (pbdkit.sim._parallel.run_fanout): module-level
# functions, which the workers find by reference.
def _observe(job: TrialJob, index: int, truth: dict[str, Float]) -> TrialObservation:
    return job.observe(index, truth)


def _run_controller(
    job: TrialJob, seen: TrialObservation, index: int, truth: dict[str, Float], controller: str
) -> ControllerOutcome:
    return job.run_controller(seen, index, truth, controller)
