"""The server that local Dask workers are forked from (:mod:`pbdkit.sim._parallel`), and how
many of them to start (:func:`local_workers`).

A worker process that imports pbdkit's simulation spends about a second of a core on it, and
on a machine of few cores that second competes with the teaching and the learning. So local
workers fork from ``multiprocessing``'s forkserver, which imports :data:`PRELOAD` once. It is
started without waiting, as early as possible (``pbdkit evaluate --workers`` starts it before it
imports the simulation itself), so that its imports overlap the caller's.

This module imports neither the simulation nor Dask's ``distributed``: the command line calls
:func:`local_workers` and :func:`start` first.
"""

from __future__ import annotations

import os

from .._validation import short

__all__ = ["ENVIRONMENT", "METHOD_KEY", "PRELOAD", "cores", "local_workers", "start"]

#: What the server imports once, for every worker forked from it: Dask's worker, the trials
#: (the simulation, MuJoCo included) and the built-in tasks (a task's spec reaches a worker
#: pickled, its functions by reference to their module); the last one freezes what the others
#: loaded (:mod:`pbdkit.sim._freeze`). ``multiprocessing`` skips a name it cannot import
#: without a word: ``tests/test_parallel.py`` checks that the workers have them.
PRELOAD: tuple[str, ...] = (
    "distributed",
    "pbdkit.sim._trials",
    "pbdkit.sim._taskdefs",
    "pbdkit.sim._freeze",
)

#: Dask's setting of how a nanny starts its worker process.
METHOD_KEY = "distributed.worker.multiprocessing-method"


#: A worker is one core: one BLAS and OpenMP thread in each (what Dask's nanny sets for the
#: workers it spawns; a forked worker's libraries are loaded before it could take them on).
#: A value the user set is kept.
ENVIRONMENT = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


def start(preload: tuple[str, ...] = PRELOAD) -> None:
    """Start the forkserver, once per process and without waiting for its imports.

    It starts with :data:`ENVIRONMENT`. Calls after the first do nothing (the server keeps the
    modules it preloaded; Dask's own preload list, set when its first nanny starts a worker,
    comes too late to matter). Neither Dask nor the simulation is imported here.
    """
    import multiprocessing
    import multiprocessing.forkserver as forkserver

    multiprocessing.get_context("forkserver").set_forkserver_preload(list(preload))
    for key, value in ENVIRONMENT.items():
        os.environ.setdefault(key, value)
    forkserver.ensure_running()


def cores() -> int:
    """The cores this process may run on: Dask's count (the machine's, within the process's
    CPU affinity and its cgroup's CPU quota), which is also what a ``LocalCluster`` starts by
    default."""
    # dask.system alone: Dask's distributed (a second of imports) is not needed to count.
    from dask.system import CPU_COUNT

    return int(CPU_COUNT)


def local_workers(workers: object, work: int | None = None) -> int:
    """How many local worker processes to start when ``workers`` are asked for: at most one
    per core (:func:`cores`), and at most one per work item (``work``, when the caller knows
    it: a trial's controller runs are the items of ``pbdkit evaluate``).

    A worker runs one item at a time on one core: workers beyond the cores only compete for
    them, and beyond the items they have nothing to do (1000 workers asked for one trial on 2
    cores had not started after 200 s, where the serial run takes 4 s). Callers say when the
    number is capped.

    Parameters
    ----------
    workers : int
        The number asked for (>= 1).
    work : int, optional
        The number of items that can run at once (>= 1); None when unknown.

    Returns
    -------
    n : int
        ``min(workers, cores(), work)``, at least 1.

    Raises
    ------
    ValueError
        ``workers`` is not an integer >= 1.
    """
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {short(workers)}")
    cap = cores() if work is None else min(cores(), work)
    return min(workers, max(cap, 1))
