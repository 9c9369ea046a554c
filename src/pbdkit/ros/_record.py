"""Kinesthetic teaching on a live arm (:func:`record_takes`, the core of ``pbdkit ros record``,
issue 37): each take is one demonstration, the joints as the arm's joint states give them, the
gripper from its joint, the objects where they were at the take's start.

A take starts and stops on Enter, or (``auto``) on motion: it starts when a joint leaves the
posture it rested at by :data:`MOTION_START` (with the last :data:`PRE_ROLL` s before it, at
rest), and stops after ``rest`` s at rest (the samples of that rest but the first
:data:`PRE_ROLL` s dropped). Putting the arm in its hand-guiding mode is the user's part.

The node's messages are taken on a thread of their own (:func:`~pbdkit.ros._graph.receiving`),
into a history of :data:`HISTORY` joint states: none is lost while the recorder is busy,
saving a take or (``pbdkit ros record --suggest``) updating a skill with it for seconds while
the teacher starts the next one. Each joint state takes the gripper's opening of the same
stamp (:class:`_Hand`), not the latest one.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..data._demonstration import Demonstration
from ._graph import JointStateListener, receiving
from ._joints import JointOrder
from ._objects import ObjectSources

__all__ = ["MOTION_START", "PRE_ROLL", "RecordSettings", "Take", "record_takes"]

Float = NDArray[np.float64]

#: A joint this far (rad) from the posture the arm rested at starts a take (``auto``).
MOTION_START = 0.01
#: Seconds of rest kept before a take's motion and after it.
PRE_ROLL = 0.3
#: At rest: every joint slower than this (rad/s), from consecutive joint states.
REST_SPEED = 0.02
#: ``auto``: a take with less motion than this (s, between its pre-roll and its rest) is not
#: a demonstration (a driver's settling, a bump) and is dropped, with a line.
MIN_MOTION = 1.0
#: The joint states' subscription history: 8 s of a 250 Hz driver (or of ``pbdkit ros sim
#: --time-scale 10``) kept for a receiving thread held up (the GIL of a skill's update).
HISTORY = 2000
#: Faster than any arm (rad/s): a jump (a simulator's reset, a driver's restart) starts the
#: wait for a take afresh from where the arm is now.
JUMP_SPEED = 20.0


@dataclass(frozen=True)
class RecordSettings:
    """``pbdkit ros record``'s options."""

    joint_states: str = "/joint_states"
    joint_map: dict[str, str] = field(default_factory=dict)
    takes: int | None = None  # None: until stopped
    auto: bool = False
    rest: float = 1.0  # auto: a take stops after this long at rest
    gripper_joint: tuple[str, float, float] | None = None
    timeout: float = 5.0

    def __post_init__(self) -> None:
        if self.takes is not None and self.takes < 1:
            raise ValueError(f"--takes must be >= 1, got {self.takes}")
        if self.auto and self.takes is None:
            raise ValueError("--auto needs --takes N")
        if not self.rest > 0:
            raise ValueError(f"--rest must be > 0, got {self.rest}")


@dataclass
class Take:
    """One take as it is recorded."""

    objects: dict[str, Float]
    t: list[float] = field(default_factory=list)
    q: list[Float] = field(default_factory=list)
    gripper: list[float] = field(default_factory=list)

    def demonstration(self, with_gripper: bool) -> Demonstration:
        t = np.asarray(self.t, dtype=np.float64)
        return Demonstration(
            t=t - t[0],
            joints=np.asarray(self.q, dtype=np.float64),
            objects=self.objects,
            gripper=np.asarray(self.gripper, dtype=np.float64) if with_gripper else None,
        )


class _Auto:
    """Where a take starts and stops on motion (module docstring)."""

    def __init__(self, rest: float) -> None:
        self.rest = rest
        self.rested_at: Float | None = None  # the posture the arm rests at, between takes
        self.still_since: float | None = None
        self.last: tuple[float, Float] | None = None

    def speed(self, t: float, q: Float) -> float:
        """The fastest joint's speed from the last state to (t, q) (0 for the first)."""
        last, self.last = self.last, (t, q)
        if last is None or t <= last[0]:
            return 0.0
        return float(np.abs(q - last[1]).max() / (t - last[0]))

    def starts(self, q: Float) -> bool:
        if self.rested_at is None:
            self.rested_at = q
        return float(np.abs(q - self.rested_at).max()) > MOTION_START

    def stops(self, t: float, moving: bool) -> bool:
        if moving:
            self.still_since = None
            return False
        if self.still_since is None:
            self.still_since = t
        return t - self.still_since >= self.rest


def record_takes(
    node: Any,
    joint_names: list[str],
    sources: ObjectSources,
    settings: RecordSettings,
    *,
    save: Callable[[Demonstration], None],
    toggled: Callable[[], bool] = lambda: False,
    log: Callable[[str], None] = print,
    stop: Callable[[], bool] = lambda: False,
    on_sample: Callable[[Float, Mapping[str, Float]], None] | None = None,
) -> int:
    """Record takes until ``settings.takes`` are done or ``stop()``; each finished take goes
    to ``save`` (a Demonstration). ``toggled()`` true: Enter was pressed (start or stop a take,
    without ``auto``). ``on_sample(q, objects)``: the latest joint angles and where the
    objects are, at each turn of the loop that has new joint states (it must return at once:
    ``pbdkit ros record --view`` hands them to its page). Returns the number of takes. Raises
    TimeoutError without joint states or an object's first message within
    ``settings.timeout``."""
    with receiving(node):
        return _record(node, joint_names, sources, settings, save, toggled, log, stop, on_sample)


def _record(
    node: Any,
    joint_names: list[str],
    sources: ObjectSources,
    settings: RecordSettings,
    save: Callable[[Demonstration], None],
    toggled: Callable[[], bool],
    log: Callable[[str], None],
    stop: Callable[[], bool],
    on_sample: Callable[[Float, Mapping[str, Float]], None] | None,
) -> int:
    """:func:`record_takes`, the node's callbacks on another thread
    (:func:`~pbdkit.ros._graph.receiving`)."""
    spin = time.sleep  # the messages come meanwhile
    order = JointOrder(joint_names, settings.joint_map)
    samples: deque[tuple[float, Float]] = deque()  # appended there, taken here
    listener = JointStateListener(node, settings.joint_states, order, HISTORY)
    listener.on_state = lambda t, q: samples.append((t, q))
    hand = None if settings.gripper_joint is None else _Hand(node, settings)
    start = time.monotonic()
    while listener.q is None or (hand is not None and hand.listener.q is None):
        if listener.error is not None:
            raise ValueError(listener.error)
        if time.monotonic() - start > settings.timeout:
            missing = "the gripper joint's" if listener.q is not None else "joint"
            raise TimeoutError(
                f"no {missing} states on {settings.joint_states} in {settings.timeout:g} s"
            )
        spin(0.05)
    sources.subscribe(settings.timeout, spin)
    log(f"objects: {sources.describe()}")
    done = 0
    take: Take | None = None
    auto = _Auto(settings.rest)
    recent: list[tuple[float, Float]] = []  # the pre-roll
    prompt = "move the arm to start" if settings.auto else "Enter starts a take"
    log(f"take {done + 1}: {prompt}")
    while (settings.takes is None or done < settings.takes) and not stop():
        spin(0.01)
        sources.check_silent()
        batch = [samples.popleft() for _ in range(len(samples))]
        if on_sample is not None and batch:
            on_sample(batch[-1][1], sources.values)
        if not settings.auto and toggled():  # Enter: start or stop a take
            if take is None:
                take = _start(sources, batch[-1:], hand)
                log(f"take {done + 1}: recording (Enter stops it)")
                continue
            _append(take, batch, hand)
            done += _finish(take, hand, save, log, done)
            take = None
            if settings.takes is None or done < settings.takes:
                log(f"take {done + 1}: {prompt}")
            continue
        for t, q in batch:
            speed = auto.speed(t, q)
            moving = speed > REST_SPEED
            if take is None:
                if speed > JUMP_SPEED:  # a jump: wait afresh from here
                    recent, auto.rested_at = [], q
                recent = [(s, p) for s, p in recent if t - s <= PRE_ROLL] + [(t, q)]
                if settings.auto and auto.starts(q):
                    take = _start(sources, recent, hand)
                    auto.still_since = None
                    log(f"take {done + 1}: recording")
                continue
            _append(take, [(t, q)], hand)
            if settings.auto and auto.stops(t, moving):
                assert auto.still_since is not None
                keep = int(np.searchsorted(take.t, auto.still_since + PRE_ROLL)) + 1
                del take.t[keep:], take.q[keep:], take.gripper[keep:]  # the rest but a bit
                motion = auto.still_since - take.t[0] - PRE_ROLL
                if motion < MIN_MOTION:
                    log(f"take {done + 1}: {max(motion, 0.0):.1f} s of motion; dropped")
                else:
                    done += _finish(take, hand, save, log, done)
                take, recent, auto.rested_at = None, [], q
                if settings.takes is not None and done >= settings.takes:
                    break
                log(f"take {done + 1}: {prompt}")
                # The rest of the batch goes on: the next take may start in it (a batch read
                # late, on a loaded machine or at --time-scale 10, holds both).
    return done


class _Hand:
    """The gripper joint's openings by stamp (0 open, 1 closed), from the same joint states:
    a joint state of the arm takes the opening of its own stamp (the last one before it), so
    that a take's gripper keeps its timing however late the recorder reads the states."""

    def __init__(self, node: Any, settings: RecordSettings) -> None:
        assert settings.gripper_joint is not None
        name, self.open, self.closed = settings.gripper_joint
        self.listener = JointStateListener(node, settings.joint_states, JointOrder([name]), HISTORY)
        self.states: deque[tuple[float, float]] = deque()  # appended there, taken here
        self.listener.on_state = lambda t, q: self.states.append((t, self.opening(q[0])))

    def opening(self, position: float) -> float:
        return float(np.clip((position - self.open) / (self.closed - self.open), 0.0, 1.0))

    def at(self, t: float) -> float:
        """The opening at stamp ``t``: of the last state at or before it (the first one's
        before any); states before that one are forgotten (``t`` only grows)."""
        states = self.states
        while len(states) > 1 and states[1][0] <= t:
            states.popleft()
        if states:
            return states[0][1]
        assert self.listener.q is not None  # record_takes waits for a first state
        return self.opening(float(self.listener.q[0]))


def _start(sources: ObjectSources, first: list[tuple[float, Float]], hand: _Hand | None) -> Take:
    """A take from ``first`` on, the objects where they are now."""
    take = Take(objects={k: v.copy() for k, v in sources.values.items()})
    _append(take, first, hand)
    return take


def _append(take: Take, batch: list[tuple[float, Float]], hand: _Hand | None) -> None:
    for t, q in batch:
        take.t.append(t)
        take.q.append(q)
        take.gripper.append(0.0 if hand is None else hand.at(t))


def _finish(
    take: Take,
    hand: _Hand | None,
    save: Callable[[Demonstration], None],
    log: Callable[[str], None],
    done: int,
) -> int:
    """Save a finished take (1), or say why not (0: fewer than two states)."""
    if len(take.t) < 2:
        log(f"take {done + 1}: too short ({len(take.t)} state); not saved")
        return 0
    save(take.demonstration(hand is not None))
    log(f"take {done + 1}: {take.t[-1] - take.t[0]:.1f} s, {len(take.t)} states; saved")
    return 1
