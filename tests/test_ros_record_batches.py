"""``pbdkit ros record --auto`` on joint states read in batches (issue 37's recorder), without
a ROS graph: the listener and the objects are stood in for, the states handed over at once."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import pbdkit.ros._record as record
from pbdkit.data._demonstration import Demonstration


class _Listener:
    """Stands in for JointStateListener: ``on_state`` is set by the recorder."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.q: np.ndarray | None = np.zeros(2)
        self.error = None
        self.on_state: Any = None


class _Sources:
    values: dict[str, np.ndarray] = {"box": np.array([0.4, 0.0, 0.1])}  # noqa: RUF012

    def subscribe(self, timeout: float, spin: Any) -> None:
        pass

    def describe(self) -> str:
        return "box"

    def check_silent(self) -> None:
        pass


def _two_takes(rate: float = 250.0) -> list[tuple[float, np.ndarray]]:
    """Rest 1 s, a 2 s move out and back, rest 1.5 s, the same again, rest 2 s."""
    t, q, out = 0.0, np.zeros(2), []
    for phase, length in [
        ("rest", 1.0),
        ("move", 2.0),
        ("rest", 1.5),
        ("move", 2.0),
        ("rest", 2.0),
    ]:
        for _ in range(int(length * rate)):
            t += 1.0 / rate
            if phase == "move":
                s = (t - 1.0) / 2.0 if t < 4.5 else (t - 4.5) / 2.0
                q = np.array([0.3, -0.2]) * np.sin(np.pi * np.clip(s, 0.0, 1.0))
            out.append((t, q.copy()))
    return out


@pytest.mark.parametrize("batch", ["one at a time", "all at once"])
def test_the_next_take_starting_in_the_batch_that_ends_one_is_recorded_whole(
    batch: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    states = _two_takes()
    listeners: list[_Listener] = []

    def listener(*args: Any, **kwargs: Any) -> _Listener:
        made = _Listener()
        listeners.append(made)
        return made

    def sleep(seconds: float) -> None:  # the recorder's spin: hand the states over
        on_state = listeners[0].on_state
        if on_state is None or not pending:
            return
        for _ in range(1 if batch == "one at a time" else len(pending)):
            on_state(*pending.pop(0))

    pending = list(states)
    monkeypatch.setattr(record, "JointStateListener", listener)
    monkeypatch.setattr(record.time, "sleep", sleep)
    saved: list[Demonstration] = []
    settings = record.RecordSettings(takes=2, auto=True, rest=1.0)
    done = record._record(
        None, ["a", "b"], _Sources(), settings, saved.append, lambda: False, lambda s: None,
        lambda: not pending and len(saved) < 2, None,
    )  # fmt: skip
    assert done == 2 and len(saved) == 2
    starts = [1.0, 4.5]  # each move's first instant
    for demo, start in zip(saved, starts, strict=True):
        # Whole: from rest (its pre-roll) through the move back to rest.
        np.testing.assert_allclose(demo.joints[0], 0.0, atol=1e-12)
        assert demo.t[-1] >= 2.0 + record.PRE_ROLL - 0.01
        # The motion's first state is in it, after a rest of about the pre-roll (the take
        # starts MOTION_START into the move, with the PRE_ROLL s before that).
        moved = np.flatnonzero(np.abs(demo.joints).max(axis=1) > 1e-9)[0]
        assert record.PRE_ROLL - 0.05 <= demo.t[moved] <= record.PRE_ROLL + 0.01, start
