"""Jobs on every core or on a Dask cluster (``pbdkit evaluate --workers N | --scheduler A``).

Dask's ``distributed`` scheduler is the one engine: ``workers=N`` starts a ``LocalCluster`` of N
single-threaded worker processes on this machine, ``scheduler="tcp://HOST:PORT"`` connects to a
running cluster (``dask scheduler`` on one machine, ``dask worker tcp://HOST:PORT`` on each of
the others; every worker needs pbdkit installed with its ``sim`` extra).

This module is a pure executor: :func:`run_fanout` runs the functions it is given on the
payloads it is given, and knows nothing of what they do (the trials of an evaluation,
:func:`pbdkit.sim._trials.run_trials`, are its user). What is sent: the shared payload once per
run (a task's result, fetched by each worker that needs it, and recomputed if the worker
holding it dies), then per item one job of the first stage and, per key, one job
of the second stage that depends on it; the results come back in the items' order. A worker that
dies loses only the jobs it was running (and the results it held): the scheduler runs them again
on another worker (up to three times, Dask's ``distributed.scheduler.allowed-failures``). An
exception raised by a job is raised here.

Each worker thread runs on its own copy of the shared payload (a robot's pinocchio work data
must not be shared between threads), so ``dask worker --nthreads N`` is safe; one thread per
core is best.

Start-up cost, local workers (:func:`session`): they are forked from a server process that has
imported pbdkit's simulation once (:mod:`pbdkit.sim._forkserver`), started before the learning, so
that the workers start in a fraction of a second once the skill is learned.

The functions are sent by reference, as Python pickles functions: they, and a task defined
outside pbdkit, must be importable on the workers (register such a task in a module the workers
can import).
"""

from __future__ import annotations

import copy
import importlib
import logging
import math
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, ExitStack, contextmanager, nullcontext
from typing import Any, NamedTuple, TypeVar

from .._threads import one_blas_thread
from .._validation import short
from . import _forkserver

__all__ = ["WORKER_CONFIG", "Session", "connect", "run_fanout", "session"]

S = TypeVar("S")  # the payload every job shares
Item = TypeVar("Item")
Key = TypeVar("Key")
H = TypeVar("H")  # a first-stage result
R = TypeVar("R")  # a second-stage result


#: Dask settings of the local workers. The worker's statistical profiler (a look at every
#: thread's stack each 10 ms, for the dashboard's profile page) made a trial about 25 % slower
#: on this machine's 2 cores (measured: 4 coaster trials in 20.9 s against 16.2 s without it).
#: Workers of a cluster of your own take the same setting from their environment:
#: ``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False dask worker tcp://HOST:PORT``.
WORKER_CONFIG: dict[str, Any] = {"distributed.worker.profile.enabled": False}

_LOCAL = threading.local()


class _ThreadCopy(NamedTuple):
    """A payload as received, and this thread's deep copy of it."""

    received: Any
    copy: Any


def _own_copy(shared: S) -> S:
    """This thread's copy of the shared payload: a robot's pinocchio work data must not be
    shared between threads, and a worker started with several threads (``dask worker
    --nthreads 4``) runs several jobs at once on the one payload it received."""
    held: _ThreadCopy | None = getattr(_LOCAL, "shared", None)
    if held is None or held.received is not shared:
        held = _ThreadCopy(shared, copy.deepcopy(shared))
        _LOCAL.shared = held
    mine: S = held.copy
    return mine


def _held(shared: S) -> S:
    """The payload every job of a :func:`run_fanout` shares, held as a task's result."""
    return shared


def _first(fn: Callable[[S, int, Item], H], shared: S, index: int, item: Item) -> H:
    """A first-stage job on a worker, with BLAS on one thread."""
    with one_blas_thread():
        return fn(_own_copy(shared), index, item)


def _second(
    fn: Callable[[S, H, int, Item, Key], R], shared: S, first: H, index: int, item: Item, key: Key
) -> R:
    """A second-stage job on a worker, with BLAS on one thread."""
    with one_blas_thread():
        return fn(_own_copy(shared), first, index, item, key)


#: Seconds to wait for a remote scheduler's answer (:func:`connect`, :func:`session`): a
#: scheduler sends its handshake as soon as it accepts a connection, in milliseconds on a
#: network; a port silent for this long is not one.
SCHEDULER_TIMEOUT = 5.0

_log = logging.getLogger(__name__)


def connect(
    workers: int | None = None,
    scheduler: str | None = None,
    *,
    timeout: float = SCHEDULER_TIMEOUT,
) -> tuple[Any, Any]:
    """A Dask client: to a new local cluster of ``workers`` processes, or to ``scheduler``
    (waiting at most ``timeout`` seconds for its answer).

    :func:`session` is the usual way: it starts the local workers' server before the learning
    and keeps Dask's setting that workers are forked while the cluster lives; a worker that a
    nanny restarts after this call has returned is spawned, and imports the simulation itself.

    Local workers are at most one per core (:func:`pbdkit.sim._forkserver.local_workers`; a
    warning is logged when fewer than ``workers`` start). A scheduler's address is checked
    first with a plain socket, within ``timeout`` (``_probe``): an address where nothing
    listens, nothing answers or something other than a Dask scheduler answers fails at once.

    Returns
    -------
    client : distributed.Client
    cluster : distributed.LocalCluster or None
        The cluster started here (close it after the client), None for ``scheduler``.

    Raises
    ------
    ValueError
        Both or neither given, ``workers`` < 1, or a scheduler that cannot be reached, does not
        answer within ``timeout`` or is not a Dask scheduler (the message names the address).
    """
    local = _check_arguments(workers, scheduler)
    if local is not None:
        _forkserver.start()
        with _local_config():
            return _local_cluster(local)
    return _remote(scheduler, timeout), None


def _check_arguments(workers: int | None, scheduler: str | None) -> int | None:
    """The number of local workers to start (``workers``, capped at the cores, said in a
    log line), or None for ``scheduler``."""
    if (workers is None) == (scheduler is None):
        raise ValueError("give either workers (local processes) or scheduler (an address)")
    if workers is None:
        return None
    local = _forkserver.local_workers(workers)
    if local < workers:
        _log.warning(
            "workers=%d: starting %d, one per core (more would only compete for the cores)",
            workers,
            local,
        )
    return local


def _local_config() -> AbstractContextManager[Any]:
    """Dask settings while a local cluster runs: our workers' (:data:`WORKER_CONFIG`, which
    the nannies pass on to them) and the forkserver for every worker a nanny (re)starts (the
    caller starts the server: :func:`pbdkit.sim._forkserver.start`)."""
    import dask
    import distributed  # noqa: F401  (first: see below)

    # Dask's defaults for distributed are registered when it is imported: a key set before
    # that would be deleted when the setting is undone, with the defaults under it.
    return dask.config.set({**WORKER_CONFIG, _forkserver.METHOD_KEY: "forkserver"})


class _Connection(NamedTuple):
    """A Dask client and the local cluster it was started with (None for a remote one)."""

    client: Any
    cluster: Any


def _local_cluster(workers: int) -> _Connection:
    from distributed import Client, LocalCluster

    cluster = LocalCluster(  # type: ignore[no-untyped-call]
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        # No dashboard, but the scheduler still serves its health and metrics pages over HTTP,
        # on port 8787 unless told: with another cluster on this machine, Dask warned "Port
        # 8787 is already in use" (an error where warnings are). Any free local port serves.
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        silence_logs=40,  # logging.ERROR: a restarted worker is reported by the result
    )
    try:
        client = Client(cluster)  # type: ignore[no-untyped-call]
    except BaseException:
        cluster.close()
        raise
    return _Connection(client, cluster)


def _remote(scheduler: str | None, timeout: float) -> Any:
    from distributed import Client

    if not isinstance(timeout, (int, float)) or not 0 < timeout < math.inf:
        raise ValueError(f"timeout must be a number of seconds > 0, got {short(timeout)}")
    if not isinstance(scheduler, str):
        raise ValueError(f"scheduler must be an address tcp://HOST:PORT, got {short(scheduler)}")
    _probe(scheduler, timeout)
    try:
        client = Client(scheduler, timeout=f"{timeout}s")  # type: ignore[no-untyped-call]
    except (OSError, TimeoutError, ValueError) as exc:
        raise ValueError(
            f"scheduler {short(scheduler)}: cannot reach a Dask scheduler: {exc}"
        ) from exc
    # A cluster of the user's imports pbdkit in each worker: have it start now, without
    # waiting, so that the imports overlap the teaching and the learning.
    _warm_up(client)
    return client


#: The largest first message a Dask scheduler may announce: its handshake (compression,
#: Python version, pickle protocol) is about 60 bytes. Garbage read as Dask's 8-byte length
#: announced exabytes, which Dask's own client tried to allocate.
_HANDSHAKE_BYTES = 1 << 16

#: Schemes whose servers are reached over TCP: the connection is tested for all of them, the
#: handshake only for plain ``tcp`` (in ``tls``, ``ws`` and ``wss`` it is inside the
#: encryption or the web socket).
_TCP_SCHEMES = ("tcp", "tls", "ws", "wss")


def _probe(scheduler: str, timeout: float) -> None:
    """Fail unless a Dask scheduler answers at ``scheduler`` within ``timeout`` seconds.

    Dask's client retries a refused connection until its timeout, then waits for the
    scheduler's handshake with no deadline (a port that accepts and stays silent, such as a web
    server waiting for a request, hung it for good) and decodes whatever comes back (garbage
    made it allocate exabytes). Here one blocking socket, with one deadline for connecting and
    reading: a Dask server writes its handshake as soon as it accepts (``distributed.comm``:
    an 8-byte length, then frames, the first a msgpack map), so the answer is read without
    sending anything, and decoded without pickle. No thread is started.

    Raises
    ------
    ValueError
        Naming the address: malformed, refused, no answer within ``timeout``, or not a Dask
        scheduler.
    """
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(scheduler)
        host, port = parse_host_port(location) if scheme in _TCP_SCHEMES else ("", 0)
    except ValueError as exc:
        raise ValueError(
            f"scheduler must be an address tcp://HOST:PORT, got {short(scheduler)} ({exc})"
        ) from None
    if scheme not in _TCP_SCHEMES:
        return  # Dask's other transports (inproc, ucx) are its own to check.
    if not 0 < port < 65536:
        raise ValueError(f"scheduler {short(scheduler)}: the port must be 1-65535, got {port}")
    deadline = time.monotonic() + timeout
    failed = f"scheduler {short(scheduler)}: cannot reach a Dask scheduler:"
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except ConnectionRefusedError:
        raise ValueError(
            f"{failed} connection refused (nothing listens there; start a scheduler with "
            "`dask scheduler`)"
        ) from None
    except TimeoutError:
        raise ValueError(f"{failed} no answer within {timeout:g} s") from None
    except OSError as exc:
        raise ValueError(f"{failed} {exc}") from None
    with sock:
        if scheme != "tcp":
            return
        try:
            reply = _handshake(sock, deadline)
        except TimeoutError:
            raise ValueError(
                f"{failed} no answer within {timeout:g} s (the port accepts connections, but a "
                "Dask scheduler answers at once)"
            ) from None
        except OSError as exc:
            raise ValueError(
                f"{failed} not a Dask scheduler (the connection failed before a handshake: {exc})"
            ) from None
    if reply is None:
        raise ValueError(f"{failed} not a Dask scheduler (its answer is not Dask's handshake)")


def _handshake(sock: socket.socket, deadline: float) -> dict[str, Any] | None:
    """The handshake a Dask server sends on ``sock``, or None if what arrives is not one.

    Raises
    ------
    TimeoutError
        Nothing complete before ``deadline`` (``time.monotonic()``).
    OSError
        The connection was closed or reset.
    """
    import msgpack

    # distributed.comm.tcp: the length of what follows (native "Q", as Dask writes it), then
    # the frames' count, their lengths and their bytes (distributed.protocol.utils); the
    # first frame is the message.
    (size,) = struct.unpack("Q", _receive(sock, 8, deadline))
    if not 16 < size <= _HANDSHAKE_BYTES:
        return None
    data = _receive(sock, size, deadline)
    (count,) = struct.unpack_from("Q", data)
    if count < 1 or 8 + 8 * count >= size:
        return None
    lengths = struct.unpack_from(f"{count}Q", data, 8)
    start = 8 + 8 * count
    if sum(lengths) != size - start:
        return None
    try:
        message = msgpack.unpackb(data[start : start + lengths[0]], use_list=False, raw=False)
    except Exception:  # any decoding error: not Dask's
        return None
    if not isinstance(message, dict) or "pickle-protocol" not in message:
        return None
    return message


def _receive(sock: socket.socket, n: int, deadline: float) -> bytes:
    """``n`` bytes from ``sock`` before ``deadline`` (TimeoutError), or OSError if the peer
    closes first."""
    chunks = bytearray()
    while len(chunks) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError
        sock.settimeout(left)
        chunk = sock.recv(n - len(chunks))
        if not chunk:
            raise ConnectionResetError("closed by the other side")
        chunks += chunk
    return bytes(chunks)


def _import_sim() -> None:
    # What a local worker is forked with (pbdkit.sim._forkserver.PRELOAD: pbdkit's simulation, then
    # the collector's freeze); by name, so that the executor does not import its jobs' modules.
    for name in _forkserver.PRELOAD:
        importlib.import_module(name)


def _warm_up(client: Any) -> None:
    """Have every worker import pbdkit's simulation now, without waiting: the imports overlap
    whatever the caller does next (teaching and learning the skill), instead of delaying the
    first trial."""
    from distributed import fire_and_forget

    for address in client.scheduler_info()["workers"]:
        fire_and_forget(client.submit(_import_sim, workers=[address], pure=False))  # type: ignore[no-untyped-call]


class Session:
    """Dask workers for a block of work (:func:`session`).

    Local workers: the forkserver they fork from starts here, at once and without waiting
    (:mod:`pbdkit.sim._forkserver`: its imports overlap the caller's teaching and learning); the
    cluster starts when :attr:`client` is first wanted, in a fraction of a second. Starting it
    in a background thread instead made the learning here up to twice as slow (the scheduler
    and the nannies live in this process and take the interpreter's lock). A remote scheduler
    is connected at once, so that a wrong address fails before any work.
    """

    def __init__(self, workers: int | None = None, scheduler: str | None = None) -> None:
        self._workers = _check_arguments(workers, scheduler)
        self._stack = ExitStack()
        self._result: _Connection | None = None
        if workers is None:
            self._result = _Connection(_remote(scheduler, SCHEDULER_TIMEOUT), None)
        else:
            _forkserver.start()

    @property
    def client(self) -> Any:
        """The ``distributed.Client`` (a local cluster is started on the first call)."""
        if self._result is None:
            assert self._workers is not None
            self._stack.enter_context(_local_config())
            self._result = _local_cluster(self._workers)
        return self._result.client

    def close(self) -> None:
        """Close the client, and the cluster if it was started here."""
        try:
            if self._result is not None:
                client, cluster = self._result
                client.close()
                if cluster is not None:
                    cluster.close()
        finally:
            self._stack.close()


def session(
    workers: int | None = None, scheduler: str | None = None
) -> AbstractContextManager[Session | None]:
    """A :class:`Session` for a block of work, closed (with the cluster started here) at its
    end; None when neither ``workers`` nor ``scheduler`` is given (serial).

    Open it before teaching and learning: local workers start while the skill is learned, a
    remote cluster's workers import pbdkit meanwhile.

    Local workers are at most one per core, as in :func:`connect`; a scheduler is given
    :data:`SCHEDULER_TIMEOUT` seconds to answer.

    Raises
    ------
    ValueError
        Both ``workers`` and ``scheduler`` given, ``workers`` < 1, or a scheduler that cannot
        be reached, does not answer in time or is not a Dask scheduler.
    """
    if workers is None and scheduler is None:
        return nullcontext(None)
    return _opened(workers, scheduler)


@contextmanager
def _opened(workers: int | None, scheduler: str | None) -> Iterator[Session]:
    run = Session(workers, scheduler)
    try:
        yield run
    finally:
        run.close()


def run_fanout(
    first: Callable[[S, int, Item], H],
    second: Callable[[S, H, int, Item, Key], R],
    shared: S,
    items: Sequence[Item],
    keys: Sequence[Key],
    *,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client: Any = None,
) -> tuple[list[H], list[list[R]]]:
    """Jobs of two stages on Dask workers: per item ``first(shared, i, item)``, then per key
    ``second(shared, first's result, i, item, key)``, which waits for it.

    On ``workers`` local processes, the cluster at ``scheduler``, or with ``client`` (a
    ``distributed.Client`` or a :class:`Session`; used and left open). Second-stage jobs, not
    whole items: the last worker to finish waits for one of them, and a cluster of more workers
    than items still has work for all of them.

    Parameters
    ----------
    first, second : callable
        Module-level functions (the workers import them by reference); each gets its own
        thread's copy of ``shared``.
    shared : object
        Sent once per run, held as a task's result (picklable).
    items : sequence
        One first-stage job each (picklable).
    keys : sequence
        One second-stage job each per item (picklable).
    progress : callable, optional
        ``progress(done, total)`` after every second-stage job, ``total = len(items) *
        len(keys)``.
    workers, scheduler, client
        Where the jobs run (:func:`session`).

    Returns
    -------
    firsts : list
        ``first``'s result per item, in the items' order.
    seconds : list of list
        ``second``'s results per item, in the keys' order.
    """
    from distributed import as_completed

    total = len(items) * len(keys)
    # A client of the caller's is used and left open; otherwise one is opened for this run.
    opened = session(workers, scheduler) if client is None else nullcontext(client)
    with opened as run:
        client = run.client if isinstance(run, Session) else run
        # The payload as a task's result, not scattered: a worker killed while holding the
        # only copy of scattered data loses it for good (Dask cannot recompute it) and every
        # job waiting on it is cancelled; a task's result is recomputed on another worker
        # (CI: "Removing worker ... caused the cluster to lose scattered data"). The other
        # workers fetch it from the first that has it. pure=False: a key of its own, so that
        # the same payload sent again (a study's second map) does not share a key with the
        # last one's, which Dask may be releasing.
        sent = client.submit(_held, shared, pure=False)
        heads, rows = [], []
        for i, item in enumerate(items):
            head = client.submit(_first, first, sent, i, item, pure=False)
            heads.append(head)
            rows.append(
                [
                    client.submit(_second, second, sent, head, i, item, key, pure=False)
                    for key in keys
                ]
            )
        finished = as_completed([f for row in rows for f in row])  # type: ignore[no-untyped-call]
        for done, _ in enumerate(finished, start=1):
            if progress is not None:
                progress(done, total)
        firsts, seconds = client.gather([heads, rows])
    return list(firsts), [list(row) for row in seconds]
