"""Trials: every controller at a placement, serially or on Dask workers.

A trial is three steps: what the skill is told (:func:`observe_trial`: the cameras, once), one
run per controller (:func:`run_trial_controller`), and the record of the trial
(:func:`assemble_trial`). :func:`run_trial` does them in a row; :func:`run_trials` runs many
trials, here or on Dask workers (:func:`pbdkit.sim._parallel.run_fanout`: the observations are
the first stage, the controller runs the second). A trial depends on nothing but its index and
placement (its disturbance is drawn from the seed and its index; physics is deterministic), so
the trials come back identical to the serial run's, in the placements' order, whatever worker
ran them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._metrics import tracking_errors
from ._parallel import run_fanout
from ._perturb import Disturbance, DisturbanceSetup, check_perturb, make_disturbance
from ._runs import run_controller, run_online
from ._sensing import observation_noise, observe
from ._task_skill import TaskSkill, start_posture, step_seconds
from ._tracking import ObjectNotSeenError, SimTracker

__all__ = [
    "ControllerOutcome",
    "Trial",
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


@dataclass(frozen=True)
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
        Per controller, :meth:`pbdkit.sim._runs.ControllerRun.summary` (JSON-ready), or
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


@dataclass(frozen=True)
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


@dataclass(frozen=True)
class ControllerOutcome:
    """One controller's run in a trial (:func:`run_trial_controller`): its name, its summary
    (:meth:`pbdkit.sim._runs.ControllerRun.summary`) and the trial's disturbance as it acted
    (:meth:`pbdkit.sim.Disturbance.as_dict`; None if nothing ran)."""

    controller: str
    summary: dict[str, Any]
    disturbance: dict[str, Any] | None


def observe_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    *,
    tracker: SimTracker | None = None,
    seed: int = 0,
    noise_mm: float = 0.0,
) -> TrialObservation:
    """The positions the skill of trial ``index`` is told (:func:`run_trial`): the cameras'
    with a ``tracker`` (the arm waiting at its start posture), else the truth; plus
    ``noise_mm`` of noise drawn from ``seed`` and ``index``."""
    told: dict[str, Float] | None = truth
    statuses: dict[str, str] = {}
    errors: dict[str, float] | None = None
    if tracker is not None:
        try:
            told = observe(ts.task, truth, tracker, arm=start_posture(ts))
        except ObjectNotSeenError as exc:
            told = None
            statuses = {k: str(tr.status) for k, tr in exc.tracks.items()}
        else:
            errors = tracking_errors(told, truth, tracker.objects)
    if noise_mm > 0.0 and told is not None:
        told = observation_noise(ts.task, told, noise_mm, seed=seed, index=index)
    return TrialObservation(told, statuses, errors)


def run_trial_controller(
    ts: TaskSkill,
    seen: TrialObservation,
    truth: dict[str, Float],
    index: int,
    controller: str,
    *,
    tracker: SimTracker | None = None,
    online: bool = False,
    perturb: str = "none",
    seed: int = 0,
) -> ControllerOutcome:
    """One controller of trial ``index`` (:func:`run_trial`), told ``seen``; a failure
    without running when the cameras did not locate the objects."""
    if seen.told is None:
        return ControllerOutcome(
            controller, {"success": False, "tracking_status": seen.statuses}, None
        )
    act = trial_disturbance(ts, perturb, truth, seed=seed, index=index)
    if online:
        summary = run_online(
            ts, seen.told, controller, tracker=tracker, sim_objects=truth, disturbance=act
        ).summary()
    else:
        summary = run_controller(
            ts, seen.told, controller, sim_objects=truth, disturbance=act
        ).summary()
    return ControllerOutcome(controller, summary, act.as_dict())


def assemble_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    seen: TrialObservation,
    runs: Sequence[ControllerOutcome],
    *,
    perturb: str = "none",
    seed: int = 0,
) -> Trial:
    """The :class:`Trial` of :func:`run_trial` from its observation and its controllers' runs
    (in the order of the controllers)."""
    acted = [r.disturbance for r in runs if r.disturbance is not None]
    described = (
        acted[-1]
        if acted
        else trial_disturbance(ts, perturb, truth, seed=seed, index=index).as_dict()
    )
    return Trial(
        truth,
        seen.told,
        seen.statuses,
        seen.errors_mm,
        {r.controller: r.summary for r in runs},
        described,
    )


def trial_disturbance(
    ts: TaskSkill, perturb: str, truth: dict[str, Float], *, seed: int, index: int = 0
) -> Disturbance:
    """The disturbance ``perturb`` of trial ``index``: :func:`pbdkit.sim._perturb.make_disturbance`
    timed on the skill's grasp and drawn from ``seed`` and ``index``. A new object each call (a
    disturbance keeps state while it acts), the same disturbance for the same arguments."""
    grid = np.arange(ts.skill.n_steps, dtype=np.float64) * step_seconds(ts)
    gripper = ts.skill.constraints().gripper
    rng = np.random.default_rng([seed, 2, index])
    return make_disturbance(perturb, DisturbanceSetup(ts.task, truth, grid, gripper, rng))


def run_trial(
    ts: TaskSkill,
    truth: dict[str, Float],
    index: int,
    controllers: Sequence[str],
    *,
    tracker: SimTracker | None = None,
    online: bool = False,
    perturb: str = "none",
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
    noise_mm: float = 0.0,
) -> Trial:
    """One trial of :func:`run_trials`: trial ``index``, every controller at placement ``truth``.

    Depends on nothing but its arguments (the disturbance is drawn from ``seed`` and
    ``index``), so trials may run in any order, in any process, with the same results.
    ``progress(k)`` is called after the k-th controller's run. ``noise_mm`` > 0 adds Gaussian
    noise to the positions the skill is told of the moving objects (after the cameras, if
    any): isotropic, scaled so that its mean 3-D length is ``noise_mm`` (per-axis standard
    deviation ``noise_mm / sqrt(8 / pi)``), drawn from ``seed`` and ``index``.

    The same three steps run apart on Dask workers (:mod:`pbdkit.sim._parallel`):
    :func:`observe_trial` once, :func:`run_trial_controller` per controller, then
    :func:`assemble_trial`.
    """
    seen = observe_trial(ts, truth, index, tracker=tracker, seed=seed, noise_mm=noise_mm)
    runs: list[ControllerOutcome] = []
    for k, name in enumerate(controllers, start=1):
        runs.append(
            run_trial_controller(
                ts, seen, truth, index, name,
                tracker=tracker, online=online, perturb=perturb, seed=seed,
            )
        )  # fmt: skip
        if progress is not None:
            progress(k)
    return assemble_trial(ts, truth, index, seen, runs, perturb=perturb, seed=seed)


def run_trials(
    ts: TaskSkill,
    placements: Sequence[dict[str, Float]],
    controllers: Sequence[str],
    *,
    tracker: SimTracker | None = None,
    progress: Callable[[int, int], None] | None = None,
    online: bool = False,
    perturb: str = "none",
    seed: int = 0,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
    noise_mm: float = 0.0,
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
    tracker : SimTracker, optional
        With a tracker the skill is told the positions the cameras measure; without, the true
        ones.
    progress : callable, optional
        ``progress(done, total)`` after every execution.
    online : bool
        Run the controllers online, in the physics loop (:func:`pbdkit.sim._runs.run_online`),
        instead of reproducing once and playing the trajectory
        (:func:`pbdkit.sim._runs.run_controller`).
    perturb : str
        A disturbance of :data:`pbdkit.sim._perturb.PERTURBATIONS`, drawn per trial (the same
        for every controller of the trial) from ``seed`` and the trial's index.
    seed : int
        Seeds the disturbances.
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
    noise_mm : float
        Noise on the positions the skill is told (:func:`run_trial`).

    Returns
    -------
    trials : list of Trial
        In the order of ``placements``.
    """
    for name in controllers:
        ts.skill_for(name)  # an unknown name: ValueError before anything runs
    check_perturb(perturb, ts.task)
    job = TrialJob(ts, tuple(controllers), tracker, online, perturb, seed, noise_mm)
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


@dataclass(frozen=True)
class TrialJob:
    """What every trial of a run shares (the arguments of :func:`run_trial` but the trial's
    own): sent once to each Dask worker."""

    ts: TaskSkill
    controllers: tuple[str, ...]
    tracker: SimTracker | None
    online: bool
    perturb: str
    seed: int
    noise_mm: float = 0.0

    def run(
        self, index: int, truth: dict[str, Float], progress: Callable[[int], None] | None = None
    ) -> Trial:
        """Trial ``index`` at placement ``truth`` (:func:`run_trial`)."""
        return run_trial(
            self.ts,
            truth,
            index,
            self.controllers,
            tracker=self.tracker,
            online=self.online,
            perturb=self.perturb,
            seed=self.seed,
            progress=progress,
            noise_mm=self.noise_mm,
        )

    def observe(self, index: int, truth: dict[str, Float]) -> TrialObservation:
        """What the skill of trial ``index`` is told (:func:`observe_trial`)."""
        return observe_trial(
            self.ts, truth, index, tracker=self.tracker, seed=self.seed, noise_mm=self.noise_mm
        )

    def run_controller(
        self, seen: TrialObservation, index: int, truth: dict[str, Float], controller: str
    ) -> ControllerOutcome:
        """One controller of trial ``index`` (:func:`run_trial_controller`)."""
        return run_trial_controller(
            self.ts, seen, truth, index, controller,
            tracker=self.tracker, online=self.online, perturb=self.perturb, seed=self.seed,
        )  # fmt: skip

    def assemble(
        self,
        index: int,
        truth: dict[str, Float],
        seen: TrialObservation,
        runs: Sequence[ControllerOutcome],
    ) -> Trial:
        """Trial ``index`` from its parts (:func:`assemble_trial`)."""
        return assemble_trial(
            self.ts, truth, index, seen, runs, perturb=self.perturb, seed=self.seed
        )


# The two stages of a trial on a Dask worker (pbdkit.sim._parallel.run_fanout): module-level
# functions, which the workers find by reference.
def _observe(job: TrialJob, index: int, truth: dict[str, Float]) -> TrialObservation:
    return job.observe(index, truth)


def _run_controller(
    job: TrialJob, seen: TrialObservation, index: int, truth: dict[str, Float], controller: str
) -> ControllerOutcome:
    return job.run_controller(seen, index, truth, controller)
