"""Shared helpers for the benchmark scripts: median timing and a plain-text table."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np


def median_time(fn: Callable[[], object], *, repeat: int, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeat`` calls (after ``warmup`` calls)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    times.sort()
    mid = len(times) // 2
    return times[mid] if len(times) % 2 else 0.5 * (times[mid - 1] + times[mid])


def fmt_time(seconds: float) -> str:
    """Human-readable duration: us, ms or s."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.1f} us"
    if seconds < 1.0:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def print_table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
    """Print a Markdown table (pasteable into benchmarks/README.md)."""
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]
    print("| " + " | ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for r in rows:
        print("| " + " | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) + " |")


def tracker_cycle(
    tracker: Any, sim: Any, track: Callable[[Any, Any], object], *, repeat: int, warmup: int = 5
) -> tuple[float, float, float]:
    """Median seconds of a camera cycle of a simulated tracker (``pbdkit.sim._tracking``) and of
    its two parts, timed inside the same cycles (medians comparable under a varying load): the
    whole cycle, rendering both images, and ``track(img_a, img_b)`` on them."""
    for _ in range(warmup):
        tracker.locate(sim)
    parts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        img_a, img_b = tracker.images(sim)
        t1 = time.perf_counter()
        track(img_a, img_b)
        t2 = time.perf_counter()
        parts.append((t2 - t0, t1 - t0, t2 - t1))
    cycle, renders, tracking = (float(v) for v in np.median(np.array(parts), axis=0))
    return cycle, renders, tracking
