"""The server that local Dask workers are forked from (:mod:`pbdkit.sim.parallel`).

A worker process that imports pbdkit's simulation spends about a second of a core on it, and
on a machine of few cores that second competes with the teaching and the learning. So local
workers fork from ``multiprocessing``'s forkserver, which imports :data:`PRELOAD` once. It is
started without waiting, as early as possible (``pbdkit evaluate --workers`` starts it before it
imports the simulation itself), so that its imports overlap the caller's.

This module imports neither the simulation nor Dask: the command line calls :func:`start`
first.
"""

from __future__ import annotations

import os

__all__ = ["ENVIRONMENT", "METHOD_KEY", "PRELOAD", "start"]

#: What the server imports once, for every worker forked from it (the last one freezes what
#: the others loaded: :mod:`pbdkit._freeze`).
PRELOAD: tuple[str, ...] = ("distributed", "pbdkit.sim.experiment", "pbdkit._freeze")

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
