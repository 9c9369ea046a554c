"""BLAS on one thread for a block of small linear algebra (EM, DTW, a worker's task).

threadpoolctl's controller is built once per process: ``threadpool_limits`` builds one per
call, which scans the loaded libraries (3-10 ms, paid by every fit of ``Skill.learn``).
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any

__all__ = ["one_blas_thread"]

_BLAS: Any = None


def one_blas_thread() -> AbstractContextManager[Any]:
    """A context in which BLAS runs on one thread (small matrices: threads only cost)."""
    global _BLAS
    if _BLAS is None:
        from threadpoolctl import ThreadpoolController

        _BLAS = ThreadpoolController()
    limit: AbstractContextManager[Any] = _BLAS.limit(limits=1, user_api="blas")
    return limit
