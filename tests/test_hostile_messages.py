"""Hostile inputs, fourth pass (issue 36): messages show what they were given, bounded.

A 0.5 KB YAML alias bomb expands into a nested list whose full repr is 312 MB: every message
formats values through :func:`pbdkit._validation.short` (at most 8 items a level, 3 levels,
300 characters)."""

from __future__ import annotations

import re
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from pbdkit._validation import short
from pbdkit.robots._joint_limits import read_joint_limits

SRC = Path(__file__).resolve().parent.parent / "src" / "pbdkit"


def _alias_bomb(levels: int) -> str:
    """Each level nine aliases of the one before: 9**levels strings from a few hundred bytes."""
    lines = ["x0: &x0 [" + ", ".join(['"lol"'] * 9) + "]"]
    for i in range(1, levels + 1):
        lines.append(f"x{i}: &x{i} [" + ", ".join([f"*x{i - 1}"] * 9) + "]")
    lines += [
        "joint_limits:",
        "  katana_motor1_pan_joint:",
        "    has_velocity_limits: true",
        f"    max_velocity: *x{levels}",
    ]
    return "\n".join(lines) + "\n"


def test_a_yaml_alias_bomb_is_refused_in_bounded_time_and_memory(tmp_path: Path) -> None:
    path = tmp_path / "joint_limits.yaml"
    path.write_text(_alias_bomb(8))  # 9**9 strings: 312 MB of repr before
    assert path.stat().st_size < 1000
    tracemalloc.start()
    start = time.perf_counter()
    try:
        with pytest.raises(ValueError, match="max_velocity must be a number") as info:
            read_joint_limits(path)
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert time.perf_counter() - start < 2.0
    assert peak < 20e6, peak
    assert len(str(info.value)) < 600 and "\n" not in str(info.value)


@pytest.mark.parametrize(
    "value",
    [
        "x" * 10**6,
        10**4000,
        list(range(10**5)),
        {str(i): i for i in range(10**4)},
        np.arange(10**6, dtype=np.float64),
    ],
    ids=["string", "int", "list", "dict", "array"],
)
def test_short_bounds_any_value(value: object) -> None:
    text = short(value)
    assert len(text) <= 300
    # Small values read as their repr.
    assert short("glass") == "'glass'" and short(1.5) == "1.5" and short((1, 2)) == "(1, 2)"


def test_short_survives_a_repr_that_raises() -> None:
    class Hostile:
        def __repr__(self) -> str:
            raise RuntimeError("no")

    assert "Hostile" in short(Hostile())


def test_no_message_formats_an_unbounded_repr() -> None:
    # The policy, held: an f-string's !r conversion shows a value in full; short() does not.
    offenders = [
        f"{p.relative_to(SRC)}:{i}"
        for p in sorted(SRC.rglob("*.py"))
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if re.search(r"\{[^{}]*!r\}", line)
    ]
    assert offenders == []
