"""The online controller's plans, made off its loop (:doc:`/reproduction`, "Plans off the control
loop").

A plan is the reproduction within the motion limits from a state along the way
(:func:`~pbdkit.reproduction._timing.timed_path`) and the jerk-limited motion through it
(:func:`pbdkit.motion._otg.follow`): 25-150 ms on the coaster skill, dozens of cycles of a 1 kHz
loop. :class:`ProcessPlanner` makes them in a separate process, so that the loop never waits:

- The process is a new interpreter (``python -c``), started once per controller, at lower
  priority (``os.nice`` and ``SCHED_BATCH``: its wake-up never preempts the loop), BLAS on
  one thread, the robot and the skill's run set-up sent once. Not
  ``multiprocessing``'s spawn or forkserver: both import the user's main script again in the
  worker, which runs a script without an ``if __name__ == "__main__"`` guard a second time. Not
  a thread: the GIL holds the loop for whole numpy calls (a numpy thread beside a 1 kHz loop
  delayed it by up to 3.3 ms).
- A request carries the state the commands will be in at a predicted hand-over time, the phase
  there and the object positions; the reply, the plan (a
  :class:`~pbdkit.reproduction.ReproductionResult`) and its motion (a picklable
  :class:`pbdkit.motion._motion.Motion`), or a one-line reason it could not be made.
- A thread of the loop's process reads the replies off the socket (the read releases the GIL)
  and unpickles them (0.1-0.5 ms for the coaster's plan, while the loop sleeps between its
  calls, most of the time): the loop's poll only takes a reply that is ready.

:class:`InlinePlanner` makes them where they are asked for (the controller's default: a
simulation steps it in simulated time and must not depend on the machine's speed).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import math
import os
import pickle
import socket
import subprocess
import sys
import threading
import time
import warnings
import weakref
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..motion._limits import MotionLimits
from ..motion._motion import Motion, _ruckig
from ..motion._otg import BOUNDS_TOL, follow
from ..robots._protocols import KinematicModel
from ._probabilistic_ik import SceneRun, with_scene
from ._result import ReproductionResult
from ._setup import RunSetup
from ._timing import timed_path

__all__ = [
    "PLANNER_NICE",
    "PLANNER_START_TIMEOUT",
    "InlinePlanner",
    "PlanReply",
    "PlanRequest",
    "PlanSetup",
    "Planner",
    "ProcessPlanner",
    "make_plan",
    "one_line",
]

Float = NDArray[np.float64]
PlannerKind = Literal["process", "inline"]

#: The planner process's niceness: the loop's process wins the core when both want it.
PLANNER_NICE = 5
#: Seconds the planner process may take to start (a new interpreter importing pbdkit).
PLANNER_START_TIMEOUT = 120.0


def one_line(err: BaseException) -> str:
    """An exception as one line (its type and first line)."""
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0] if text else ''}".rstrip(": ")


class PlanCollides(ValueError):
    """A plan that would collide with the controller's scene (it is not followed)."""


@dataclass(frozen=True)
class PlanSetup:
    """What every plan of a controller is made with, sent once to a planner process: the
    robot, the run set-up (its objects and start replaced per request), the motion limits the
    path is timed within and the (safety-scaled) ones the motion follows it within, and the
    seconds per step; with a ``scene``, every plan is checked against it and keeps clear of
    it (:func:`~pbdkit.reproduction._probabilistic_ik.with_scene`)."""

    robot: KinematicModel
    run: RunSetup
    limits: MotionLimits
    plan_limits: MotionLimits
    dt: float
    scene: SceneRun | None = None


@dataclass(frozen=True)
class PlanRequest:
    """A plan to make: from ``state`` (position, velocity, acceleration) at time ``t0`` (s, the
    controller's clock) and ``phase`` (steps), for these object positions. ``generation``
    tells a reply to a request the controller has since given up (a push) from the current
    one."""

    generation: int
    t0: float
    state: tuple[Float, Float, Float]
    phase: float
    objects: dict[str, Float]


@dataclass(frozen=True)
class PlanReply:
    """A plan made for a :class:`PlanRequest`: its reproduction and motion (from ``t0``), or
    ``error`` (one line) where none could be made; ``seconds``: how long it took; ``notes``:
    the warnings making it raised (their category's name and message: the controller warns
    them again in its own process)."""

    generation: int
    t0: float
    result: ReproductionResult | None
    motion: Motion | None
    error: str | None
    seconds: float
    notes: tuple[tuple[str, str], ...] = ()
    collides: bool = False  # the error: the plan would collide with the scene


#: A plan whose motion would leave the joint limits is timed again with the steps around where
#: it does this much slower each time (the follower then has room to follow a path that
#: brakes hard onto a joint limit), up to :data:`SLOWER_TRIES` times; the steps within
#: :data:`SLOWER_SPAN` s of the excursion, times the try's number (every step after half the
#: tries).
SLOWER = 1.25
SLOWER_TRIES = 8
SLOWER_SPAN = 0.25


def make_plan(setup: PlanSetup, request: PlanRequest) -> PlanReply:
    """The plan of a request (in any process): Table II from the state at the phase, timed
    within ``setup.limits`` (:func:`~pbdkit.reproduction._timing.timed_path`), and the motion
    through it from the state within ``setup.plan_limits`` and the joint limits.

    A path that brakes onto a joint limit harder than the jerk limit lets a motion follow can
    only be followed by passing the limit (its samples are within the limits; the motion
    through them is late and overshoots): the steps around it are then given more time
    (:data:`SLOWER`), until the motion stays within the joint limits.
    """
    start = time.perf_counter()
    q = request.state[0]
    run = dataclasses.replace(setup.run, objects=dict(request.objects), theta0=q)
    # From where the request starts: a start beyond a limit is the controller's guard's.
    lower = np.minimum(run.lower, q) - BOUNDS_TOL
    upper = np.maximum(run.upper, q) + BOUNDS_TOL
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        try:
            res, motion = _plan_within_bounds(setup, run, request, (lower, upper))
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as err:
            took = time.perf_counter() - start
            collides = isinstance(err, PlanCollides)
            return PlanReply(
                request.generation, request.t0, None, None, one_line(err), took, (), collides
            )
    took = time.perf_counter() - start
    notes = tuple(dict.fromkeys((w.category.__name__, str(w.message)) for w in seen))
    return PlanReply(request.generation, request.t0, res, motion, None, took, notes)


def _plan_within_bounds(
    setup: PlanSetup, run: RunSetup, request: PlanRequest, within: tuple[Float, Float]
) -> tuple[ReproductionResult, Motion]:
    """:func:`make_plan`'s reproduction and motion (Table II of ``run``, the request's), the
    steps around where the motion would leave ``within`` (the joint limits, or the start where
    it is beyond them) slowed."""
    q, v, a = request.state
    moving = bool(np.any(v))
    bounds = (run.lower, run.upper)
    slower: Float | None = None
    for attempt in range(SLOWER_TRIES + 1):
        res = _scene_path(setup, run, request.phase, v if moving else None, slower)
        assert res.times is not None
        velocities, accelerations = _at_rest_on_limits(res, bounds, moving)
        t = request.t0 + res.times
        motion = follow(
            t,
            res.joints,
            setup.plan_limits,
            velocities=velocities,
            accelerations=accelerations,
            start=(q, v, a),
            bounds=bounds,
        )
        out = motion.out_of(*within)
        if not out:
            break
        # Around each excursion, wider at every try (the whole path after half of them).
        span = SLOWER_SPAN * (attempt + 1) if 2 * attempt < SLOWER_TRIES else math.inf
        steps = np.zeros(t.shape[0] - 1, dtype=bool)
        for t_a, t_b in out:
            steps |= (t[1:] >= t_a - span) & (t[:-1] <= t_b + span)
        slower = np.ones(steps.shape[0]) if slower is None else slower
        slower = np.where(steps, slower * SLOWER, slower)
    return res, motion


def _scene_path(
    setup: PlanSetup, run: RunSetup, phase: float, velocity: Float | None, slower: Float | None
) -> ReproductionResult:
    """The plan's reproduction (:func:`~pbdkit.reproduction._timing.timed_path`) and, with a
    scene, kept clear of it; a plan that would still collide is refused (ValueError: the
    controller brings the arm to rest and says why)."""

    def remake(again: RunSetup) -> ReproductionResult:
        robot, limits, dt = setup.robot, setup.limits, setup.dt
        return timed_path(robot, again, limits, dt, phase=phase, velocity=velocity, slower=slower)

    res = remake(run)
    if setup.scene is None:
        return res
    res = with_scene(setup.robot, run, res, setup.scene, remake, warn=False)
    if res.infeasible is not None:
        raise PlanCollides(f"the plan would collide: {res.infeasible}")
    return res


def _at_rest_on_limits(
    res: ReproductionResult, bounds: tuple[Float, Float], moving: bool
) -> tuple[Float, Float]:
    """The samples' velocities and accelerations (the spline's), 0 for a joint on a joint limit
    at a sample (Table II clips a path there): the spline through a path that arrives at a
    limit and stays overshoots it, and so would a motion through its derivatives."""
    assert res.velocities is not None and res.accelerations is not None
    on = (res.joints <= bounds[0] + BOUNDS_TOL) | (res.joints >= bounds[1] - BOUNDS_TOL)
    on[0] &= not moving  # a start that moves keeps its velocity
    if not on.any():
        return res.velocities, res.accelerations
    return np.where(on, 0.0, res.velocities), np.where(on, 0.0, res.accelerations)


class Planner:
    """Where a controller's plans are made: :meth:`submit` a request, :meth:`poll` for its
    reply (None until it is ready), one at a time."""

    kind: PlannerKind

    def submit(self, request: PlanRequest) -> None:
        raise NotImplementedError

    def poll(self) -> PlanReply | None:
        raise NotImplementedError

    def close(self) -> None:
        """Release what the planner holds (a process)."""


class InlinePlanner(Planner):
    """Plans made in :meth:`submit`, in the caller's thread: its reply is ready at once."""

    kind: PlannerKind = "inline"

    def __init__(self, setup: PlanSetup) -> None:
        self._setup = setup
        self._reply: PlanReply | None = None

    def submit(self, request: PlanRequest) -> None:
        self._reply = make_plan(self._setup, request)

    def poll(self) -> PlanReply | None:
        reply, self._reply = self._reply, None
        return reply


class ProcessPlanner(Planner):
    """Plans made in a separate process (module docstring); starting it waits until the
    process has the robot and the skill (1-3 s: a new interpreter importing pbdkit).

    Parameters
    ----------
    setup : PlanSetup
        As :func:`make_plan`, sent once (its robot and run set-up must pickle).
    delay : float
        Seconds the process sleeps before each plan (tests: a slow planner).
    nice : int
        Added to the process's niceness (:data:`PLANNER_NICE`).
    """

    kind: PlannerKind = "process"

    def __init__(
        self,
        setup: PlanSetup,
        *,
        delay: float = 0.0,
        nice: int = PLANNER_NICE,
        timeout: float = PLANNER_START_TIMEOUT,
    ) -> None:
        try:
            message = pickle.dumps(
                ("setup", setup, float(delay), int(nice)),
                protocol=pickle.HIGHEST_PROTOCOL,
            )
        except (pickle.PicklingError, TypeError, AttributeError) as err:
            raise ValueError(
                f"planner='process' sends the robot and the skill to a planner process, and "
                f"they do not pickle ({one_line(err)}): use planner='inline'"
            ) from err
        ours, theirs = socket.socketpair()
        self._sock = ours
        env = dict(os.environ)
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env[var] = "1"
        # The worker imports the same pbdkit as this process, installed or not.
        here = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join([here, *filter(None, [env.get("PYTHONPATH")])])
        code = f"from pbdkit.reproduction._planner import serve; serve({theirs.fileno()})"
        self._proc = subprocess.Popen(
            [sys.executable, "-c", code],
            pass_fds=(theirs.fileno(),),
            env=env,
            stdin=subprocess.DEVNULL,
        )
        theirs.close()
        self._conn = Connection(os.dup(ours.fileno()))
        self._finalizer = weakref.finalize(self, _stop, self._proc, self._conn, ours)
        self._inbox: collections.deque[PlanReply] = collections.deque()
        # Why the process is gone (set by the reading thread, which holds no reference to the
        # planner: collecting it ends the process, and the thread with it).
        self._gone: list[str] = []
        try:
            self._conn.send_bytes(message)
            if not self._conn.poll(timeout):
                raise RuntimeError(f"the planner process did not start in {timeout:g} s")
            status = self._conn.recv()
        except (OSError, EOFError) as err:
            self.close()
            raise RuntimeError(
                f"the planner process stopped while starting (exit code {self._proc.poll()})"
            ) from err
        except RuntimeError:
            self.close()
            raise
        if status[0] != "ready":
            self.close()
            raise RuntimeError(f"the planner process could not start: {status[1]}")
        self.pid: int = self._proc.pid
        # The motions come back with Ruckig segments this process plans again where it first
        # samples one: import Ruckig now, not in the loop (4 ms, measured).
        _ruckig()

        self._reader = threading.Thread(
            target=_read_replies,
            args=(self._conn, self._proc, self._inbox, self._gone),
            name="pbdkit-planner",
            daemon=True,
        )
        self._reader.start()

    def submit(self, request: PlanRequest) -> None:
        try:
            self._conn.send_bytes(pickle.dumps(request, protocol=pickle.HIGHEST_PROTOCOL))
        except OSError:
            self._gone.append("the planner process stopped")

    def poll(self) -> PlanReply | None:
        if self._inbox:
            return self._inbox.popleft()
        if self._gone:
            return PlanReply(-1, math.nan, None, None, self._gone[0], 0.0)
        return None

    def close(self) -> None:
        self._finalizer()


def _read_replies(
    conn: Connection,
    proc: subprocess.Popen[bytes],
    inbox: collections.deque[PlanReply],
    gone: list[str],
) -> None:
    """The reading thread: each reply unpickled into ``inbox``; at the end, why in ``gone``."""
    while True:
        try:
            reply = pickle.loads(conn.recv_bytes())
        except (EOFError, OSError):
            gone.append(f"the planner process stopped (exit code {proc.poll()})")
            return
        inbox.append(reply)


def _stop(proc: subprocess.Popen[bytes], conn: Connection, sock: socket.socket) -> None:
    """End the planner process: its socket shut, it exits (at once when idle, else at the end
    of the plan it is making); killed if it has not within 2 s."""
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)  # also wakes the reading thread
    sock.close()
    conn.close()
    try:
        proc.wait(timeout=2.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def serve(fd: int) -> None:
    """The planner process: plans for requests on the socket ``fd`` until it closes."""
    conn = Connection(fd)
    try:
        _, setup, delay, nice = pickle.loads(conn.recv_bytes())
        os.nice(nice)
        # SCHED_BATCH: its wake-up when a request comes never preempts the loop's process (under
        # the default policy, at niceness +5 or +10, that held the call that sent the request
        # for a whole time slice: 3.7 ms, measured); it still gets its share of the CPU
        # (SCHED_IDLE, tried, starved it when every core was busy: no plan came).
        with contextlib.suppress(AttributeError, OSError):
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
        # A first plan, from the start, warms what the first plan would pay for (imports,
        # caches): the first reply comes in the time of the others.
        run = setup.run
        zeros = np.zeros_like(run.theta0)
        make_plan(setup, PlanRequest(0, 0.0, (run.theta0, zeros, zeros), 0.0, run.objects))
    except Exception as err:  # said to the controller, which raises it
        conn.send(("error", one_line(err)))
        return
    conn.send(("ready", os.getpid()))
    while True:
        try:
            request = pickle.loads(conn.recv_bytes())
        except (EOFError, OSError):
            os._exit(0)  # the controller closed: nothing to tidy (no interpreter teardown)
        if delay > 0:
            time.sleep(delay)
        reply = make_plan(setup, request)
        try:
            conn.send_bytes(pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL))
        except OSError:
            os._exit(0)
