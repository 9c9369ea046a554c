"""Trials on every core or on a Dask cluster (``pbdkit evaluate --workers N | --scheduler A``).

Dask's ``distributed`` scheduler is the one engine: ``workers=N`` starts a ``LocalCluster`` of N
single-threaded worker processes on this machine, ``scheduler="tcp://HOST:PORT"`` connects to a
running cluster (``dask scheduler`` on one machine, ``dask worker tcp://HOST:PORT`` on each of
the others; every worker needs pbdkit installed with its ``sim`` extra).

What is sent: the skill and the task once per run (scattered to every worker), then one task
per trial: its index and its placement. A trial (:func:`pbdkit.sim.experiment.run_trial`)
depends on nothing else (its disturbance is drawn from the seed and its index; physics is
deterministic), so the trials come back identical to the serial run's, in the placements'
order, whatever worker ran them. A worker that dies loses only the trials it was running: the
scheduler runs them again on another worker (up to three times, Dask's
``distributed.scheduler.allowed-failures``). An exception raised by a trial is a bug, and is
raised here.

Each worker thread runs on its own copy of the skill (a robot's pinocchio work data must not be
shared between threads), so ``dask worker --nthreads N`` is safe; one thread per core is best.

A task defined outside pbdkit must be importable on the workers (its functions are sent by
reference, as Python pickles functions): register it in a module the workers can import.
"""

from __future__ import annotations

import copy
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .tracking import SimTracker

if TYPE_CHECKING:
    from .experiment import TaskSkill, Trial

__all__ = ["WORKER_CONFIG", "TrialJob", "connect", "run_trials_dask", "session"]

Float = NDArray[np.float64]


@dataclass(frozen=True)
class TrialJob:
    """What every trial of a run shares (the arguments of
    :func:`pbdkit.sim.experiment.run_trial` but the trial's own), sent once to each worker."""

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
        """Trial ``index`` at placement ``truth`` (:func:`pbdkit.sim.experiment.run_trial`)."""
        from .experiment import run_trial

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


#: Dask settings of the local workers. The worker's statistical profiler (a look at every
#: thread's stack each 10 ms, for the dashboard's profile page) made a trial about 25 % slower
#: on this machine's 2 cores (measured: 4 coaster trials in 20.9 s against 16.2 s without it).
#: Workers of a cluster of your own take the same setting from their environment:
#: ``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False dask worker tcp://HOST:PORT``.
WORKER_CONFIG: dict[str, Any] = {"distributed.worker.profile.enabled": False}

_LOCAL = threading.local()


def _own_copy(job: TrialJob) -> TrialJob:
    """This thread's copy of ``job``: a robot's pinocchio work data must not be shared between
    threads, and a worker started with several threads (``dask worker --nthreads 4``) runs
    several trials at once on the one job it received."""
    held = getattr(_LOCAL, "job", None)
    if held is None or held[0] is not job:
        _LOCAL.job = (job, copy.deepcopy(job))
    mine: TrialJob = _LOCAL.job[1]
    return mine


def _run_one(job: TrialJob, index: int, truth: dict[str, Float]) -> Trial:
    """One trial on a worker, with BLAS on one thread (a worker is one core)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        return _own_copy(job).run(index, truth)


def connect(
    workers: int | None = None, scheduler: str | None = None, *, timeout: float = 10.0
) -> tuple[Any, Any]:
    """A Dask client: to a new local cluster of ``workers`` processes, or to ``scheduler``
    (waiting at most ``timeout`` seconds for it).

    Returns
    -------
    client : distributed.Client
    cluster : distributed.LocalCluster or None
        The cluster started here (close it after the client), None for ``scheduler``.

    Raises
    ------
    ValueError
        Both or neither given, ``workers`` < 1, or a scheduler that cannot be reached.
    """
    if (workers is None) == (scheduler is None):
        raise ValueError("give either workers (local processes) or scheduler (an address)")
    import dask
    from distributed import Client, LocalCluster

    if workers is not None:
        if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
            raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
        with dask.config.set(WORKER_CONFIG):  # the nannies pass it on to their workers
            cluster = LocalCluster(  # type: ignore[no-untyped-call]
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=40,  # logging.ERROR: a restarted worker is reported by the result
            )
        client = Client(cluster)  # type: ignore[no-untyped-call]
    else:
        cluster = None
        try:
            client = Client(scheduler, timeout=f"{timeout}s")  # type: ignore[no-untyped-call]
        except (OSError, TimeoutError) as exc:
            raise ValueError(
                f"scheduler: cannot reach a Dask scheduler at {scheduler!r}: {exc}"
            ) from exc
    _warm_up(client)
    return client, cluster


def _import_sim() -> None:
    import pbdkit.sim.experiment  # noqa: F401


def _warm_up(client: Any) -> None:
    """Have every worker import pbdkit's simulation now (about 3 s), without waiting: the
    imports overlap whatever the caller does next (teaching and learning the skill), instead
    of delaying the first trial."""
    from distributed import fire_and_forget

    for address in client.scheduler_info()["workers"]:
        fire_and_forget(client.submit(_import_sim, workers=[address], pure=False))  # type: ignore[no-untyped-call]


def session(
    workers: int | None = None, scheduler: str | None = None
) -> AbstractContextManager[Any]:
    """A Dask client for a block of work (:func:`connect`), closed (with the cluster started
    here) at its end; None when neither ``workers`` nor ``scheduler`` is given (serial).

    Connect before teaching and learning: the workers start and import while the skill is
    learned here.
    """
    if workers is None and scheduler is None:
        return nullcontext(None)
    return _connected(workers, scheduler)


@contextmanager
def _connected(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    """:func:`connect`, the client and its cluster closed at the end of the block."""
    client, cluster = connect(workers, scheduler)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_trials_dask(
    job: TrialJob,
    placements: Sequence[dict[str, Float]],
    *,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
) -> list[Trial]:
    """:func:`pbdkit.sim.experiment.run_trials` on Dask workers: ``job`` at every placement,
    on ``workers`` local processes, the cluster at ``scheduler``, or with ``client`` (its
    cluster is used and left open).

    ``progress(done, total)`` counts controller runs, as in the serial run, and advances by a
    whole trial at a time.
    """
    from distributed import as_completed

    # The demonstrations stay here: the workers need the skill and the task only.
    job = replace(job, ts=replace(job.ts, demos=[]))
    per_trial = len(job.controllers)
    total = len(placements) * per_trial
    # A client of the caller's is used and left open; otherwise one is opened for this run.
    opened = _connected(workers, scheduler) if client is None else nullcontext(client)
    with opened as client:
        shared = client.scatter(job, broadcast=True)
        futures = [
            client.submit(_run_one, shared, i, truth, pure=False)
            for i, truth in enumerate(placements)
        ]
        done = 0
        for _ in as_completed(futures):  # type: ignore[no-untyped-call]
            done += per_trial
            if progress is not None:
                progress(done, total)
        trials: list[Trial] = client.gather(futures)
    return trials
