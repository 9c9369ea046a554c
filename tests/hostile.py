"""Shared by the hostile-input tests (issue 36): a block that must end in bounded time and
memory."""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def bounded(seconds: float, megabytes: float | None) -> Iterator[None]:
    """Fail unless the block ends within ``seconds`` and ``megabytes`` of traced allocations
    (None: untraced; tracing slows PyYAML's pure-Python loader twentyfold)."""
    if megabytes is not None:
        tracemalloc.start()
    start = time.perf_counter()
    try:
        yield
    finally:
        elapsed = time.perf_counter() - start
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert elapsed < seconds, f"{elapsed:.2f} s"
    assert megabytes is None or peak < megabytes * 1e6, f"{peak / 1e6:.1f} MB"
