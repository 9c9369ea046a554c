"""Trials on worker processes and on a Dask cluster give the serial results, a dead worker's
trials are run again (issue 14)."""

from __future__ import annotations

import json
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("distributed")

from pbdkit.sim._evaluation import Evaluation, evaluate
from pbdkit.sim._parallel import Session, connect, session
from pbdkit.sim._task_registry import get_task
from pbdkit.sim._task_skill import TaskSkill
from pbdkit.sim._trials import TrialConditions, run_trials


@pytest.fixture(scope="module")
def coaster(small_task_skill: Callable[..., TaskSkill]) -> TaskSkill:
    return small_task_skill("coaster", 3, seed=1, n_steps=150)


def _json(ev: Evaluation) -> str:
    data = ev.as_dict()
    data.pop("learn_seconds")
    return json.dumps(data, sort_keys=True)


@pytest.mark.slow
def test_workers_give_the_serial_results(coaster: TaskSkill) -> None:
    # A disturbance drawn per trial, two controllers, the cameras: everything a trial depends
    # on travels to the workers, and the results come back in order.
    args: dict[str, Any] = {
        "task_skill": coaster,
        "controllers": ["fused", "joint"],
        "perturb": "push",
    }
    serial = evaluate("coaster", 3, 0, **args)
    ticks: list[tuple[int, int]] = []
    parallel = evaluate(
        "coaster", 3, 0, workers=2, progress=lambda d, t: ticks.append((d, t)), **args
    )
    assert _json(parallel) == _json(serial)
    assert serial.vision and serial.tracking_error_mm is not None
    assert ticks == [(k, 6) for k in range(1, 7)]  # one tick per controller run


@pytest.mark.slow
def test_a_killed_workers_trials_are_run_again(coaster: TaskSkill) -> None:
    from distributed import LocalCluster

    args: dict[str, Any] = {"task_skill": coaster, "controllers": ["fused"], "ground_truth": True}
    serial = evaluate("coaster", 4, 0, **args)
    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        # Even without a dashboard the scheduler serves HTTP, by default on 8787: another
        # cluster on the machine would make that a warning (an error here).
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
    )
    killed: list[int] = []

    def kill_one(done: int, total: int) -> None:
        # After the first trial, both workers are busy with the next ones: kill one of them.
        if not killed:
            pid = next(iter(cluster.workers.values())).process.pid
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    try:
        parallel = evaluate(
            "coaster", 4, 0, scheduler=cluster.scheduler_address, progress=kill_one, **args
        )
    finally:
        cluster.close()
    assert killed
    assert _json(parallel) == _json(serial)


@pytest.mark.slow
def test_a_worker_with_two_threads_gives_the_serial_results(coaster: TaskSkill) -> None:
    # Two trials at once in one process: each thread works on its own copy of the skill.
    from distributed import LocalCluster

    args: dict[str, Any] = {"task_skill": coaster, "controllers": ["fused"], "ground_truth": True}
    serial = evaluate("coaster", 4, 1, **args)
    cluster = LocalCluster(
        n_workers=1,
        threads_per_worker=2,
        processes=True,
        dashboard_address=None,
        # Even without a dashboard the scheduler serves HTTP, by default on 8787: another
        # cluster on the machine would make that a warning (an error here).
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
    )
    try:
        threaded = evaluate("coaster", 4, 1, scheduler=cluster.scheduler_address, **args)
    finally:
        cluster.close()
    assert _json(threaded) == _json(serial)


def test_connect_refuses_bad_arguments() -> None:
    with pytest.raises(ValueError, match="either workers"):
        connect()
    with pytest.raises(ValueError, match="either workers"):
        connect(workers=2, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(ValueError, match="workers must be an integer >= 1"):
        connect(workers=0)
    with pytest.raises(ValueError, match="cannot reach a Dask scheduler"):
        connect(scheduler="tcp://127.0.0.1:9", timeout=1.0)


def _imported_sim() -> bool:
    return all(name in sys.modules for name in ("pbdkit.sim._trials", "pbdkit.sim._taskdefs"))


def _profiling() -> bool:
    import dask

    return bool(dask.config.get("distributed.worker.profile.enabled"))


def _forked_from_a_server() -> tuple[str, int]:
    import multiprocessing

    return multiprocessing.current_process().name, os.getppid()


@pytest.mark.slow
def test_a_session_starts_quiet_workers_that_have_imported_the_simulation() -> None:
    with session() as none:
        assert none is None  # serial: no cluster
    with session(workers=2) as run:
        assert isinstance(run, Session)
        client = run.client
        # Dask's statistical profiler made trials about 25 % slower: off on our workers.
        assert list(client.run(_profiling).values()) == [False, False]
        # Forked from a server that imported pbdkit's simulation: nothing left to import.
        assert list(client.run(_imported_sim).values()) == [True, True]
        parents = {ppid for _, ppid in client.run(_forked_from_a_server).values()}
        assert len(parents) == 1 and os.getpid() not in parents
    assert client.status == "closed"


@pytest.mark.slow
def test_a_session_refuses_bad_arguments_at_once_and_reports_a_failed_start(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from pbdkit.sim import _parallel as parallel

    with pytest.raises(ValueError, match="workers must be an integer >= 1"), session(workers=0):
        pass
    with (
        pytest.raises(ValueError, match="cannot reach a Dask scheduler"),
        session(scheduler="tcp://127.0.0.1:9"),
    ):
        pass

    def fail(workers: int) -> None:
        raise OSError("no ports left")

    # The local cluster starts in a background thread: its error reaches whoever needs it.
    monkeypatch.setattr(parallel, "_local_cluster", fail)
    with session(workers=1) as run:
        assert run is not None
        with pytest.raises(OSError, match="no ports left"):
            run.client  # noqa: B018


@pytest.mark.slow
def test_one_session_runs_the_same_evaluation_twice(coaster: TaskSkill) -> None:
    # The same job scattered twice on one client (a study's maps of two objects): Dask
    # released the first one's data under the second's key ("lost dependencies").
    placements = [
        get_task("coaster").sample_objects(np.random.default_rng([3, i])) for i in range(2)
    ]
    truth = TrialConditions(ground_truth=True, seed=0)
    serial = run_trials(coaster, placements, ["fused"], truth)
    with session(workers=2) as run:
        for _ in range(3):
            again = run_trials(coaster, placements, ["fused"], truth, client=run)
            assert [t.runs for t in again] == [t.runs for t in serial]


_TWO_SESSIONS = """
import sys
from pbdkit.sim._parallel import session
assert "distributed" not in sys.modules
for _ in range(2):
    with session(workers=1) as run:
        run.client.submit(abs, -1).result()
import dask
print(dask.config.get("distributed.worker.profile.enabled"))
"""


@pytest.mark.slow
def test_sessions_one_after_another_keep_dasks_settings() -> None:
    # Each local session sets Dask's worker settings for its duration and undoes them. In a
    # process that had not imported Dask's distributed yet, undoing them deleted Dask's own
    # defaults: the second cluster failed with KeyError 'comm'.
    import subprocess

    out = subprocess.run(
        [sys.executable, "-c", _TWO_SESSIONS], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["True"]


# ----------------------------------------------------------------------------- issue 22
# A scheduler's address that is no scheduler fails within seconds, naming the address: Dask's
# client waited forever on a port that accepts and stays silent, decoded a garbage reply as
# a length of exabytes, and retried a refused connection until its timeout.


class _FakeServer:
    """A local TCP port that accepts connections and then stays silent, replies ``reply``, or
    closes them at once (``reply=None``)."""

    def __init__(self, reply: bytes | None = b"") -> None:
        import socket
        import threading

        self._reply = reply
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._accepted: list[socket.socket] = []
        self.port = self._listener.getsockname()[1]
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self._listener.accept()
            except OSError:  # closed: the test is over
                return
            if self._reply is None:
                conn.close()
                continue
            self._accepted.append(conn)
            if self._reply:
                conn.sendall(self._reply)

    def close(self) -> None:
        import socket

        self._listener.shutdown(socket.SHUT_RDWR)  # wakes the accept (close alone does not)
        self._listener.close()
        for conn in self._accepted:
            conn.close()
        self._thread.join(5.0)


def _free_port() -> int:
    import socket

    with socket.create_server(("127.0.0.1", 0)) as s:
        port: int = s.getsockname()[1]
    return port  # closed: nothing listens there now


@pytest.mark.parametrize(
    ("reply", "match"),
    [
        (b"", r"cannot reach a Dask scheduler: no answer within 1 s \(the port accepts"),
        (b"\xff" * 4096, "not a Dask scheduler"),
        # A length that fits, frames that do not: Dask's client raised "Maximum allowed
        # dimension exceeded" on such replies.
        (b"\x20" + b"\x00" * 7 + b"\x07" * 32, "not a Dask scheduler"),
        (b"HTTP/1.0 400 Bad request\r\n\r\n", "not a Dask scheduler"),
        (None, "not a Dask scheduler"),  # accepts and closes
    ],
    ids=["silent", "0xff", "frames", "http", "closes"],
)
def test_connect_fails_fast_on_a_port_that_is_not_a_scheduler(
    reply: bytes | None, match: str
) -> None:
    import threading
    import time

    server = _FakeServer(reply)
    address = f"tcp://127.0.0.1:{server.port}"
    threads = set(threading.enumerate())
    start = time.perf_counter()
    try:
        with pytest.raises(ValueError, match=match) as caught:
            connect(scheduler=address, timeout=1.0)
    finally:
        elapsed = time.perf_counter() - start
        server.close()
    assert elapsed < 5.0
    assert f"scheduler {address!r}: " in str(caught.value)
    assert "\n" not in str(caught.value)
    # Nothing left behind that would keep the process alive (Dask's client was not started).
    assert not [t for t in set(threading.enumerate()) - threads if not t.daemon]


def test_connect_and_session_fail_fast_on_a_closed_port() -> None:
    import time

    address = f"tcp://127.0.0.1:{_free_port()}"
    start = time.perf_counter()
    refused = f"scheduler '{address}': cannot reach a Dask scheduler: connection refused"
    with pytest.raises(ValueError, match=refused):
        connect(scheduler=address)  # the default timeout: Dask retried until it ran out
    with pytest.raises(ValueError, match="connection refused"), session(scheduler=address):
        pass
    assert time.perf_counter() - start < 5.0


@pytest.mark.parametrize(
    ("address", "match"),
    [
        ("tcp://127.0.0.1", "scheduler must be an address tcp://HOST:PORT, got 'tcp://127.0.0.1'"),
        ("tcp://127.0.0.1:http", "scheduler must be an address tcp://HOST:PORT"),
        ("tcp://127.0.0.1:70000", "the port must be 1-65535, got 70000"),
    ],
)
def test_connect_refuses_a_malformed_address(address: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        connect(scheduler=address)


def test_connect_refuses_a_bad_timeout() -> None:
    with pytest.raises(ValueError, match="timeout must be a number of seconds > 0, got nan"):
        connect(scheduler="tcp://127.0.0.1:1", timeout=float("nan"))


def test_connect_still_reaches_a_real_scheduler() -> None:
    from distributed import LocalCluster

    cluster = LocalCluster(
        n_workers=0,
        processes=False,
        protocol="tcp",
        dashboard_address=None,
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
    )
    try:
        client, none = connect(scheduler=cluster.scheduler_address, timeout=3.0)
        try:
            assert none is None
            assert client.scheduler_info()["address"] == cluster.scheduler_address
        finally:
            client.close()
    finally:
        cluster.close()


def test_the_command_line_reports_a_port_that_is_not_a_scheduler_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import time

    from typer.testing import CliRunner

    from pbdkit.apps._cli import app
    from pbdkit.sim import _parallel as parallel

    monkeypatch.setattr(parallel, "SCHEDULER_TIMEOUT", 1.0)
    out = tmp_path / "ev.json"
    for reply, match in ((b"", "no answer within 1 s"), (b"\xff" * 64, "not a Dask scheduler")):
        server = _FakeServer(reply)
        address = f"tcp://127.0.0.1:{server.port}"
        args = ["evaluate", "--trials", "1", "--json", str(out), "--scheduler", address]
        start = time.perf_counter()
        try:
            r = CliRunner().invoke(app, args)
        finally:
            elapsed = time.perf_counter() - start
            server.close()
        assert r.exit_code == 2, r.output
        # One line (after the progress bar's), no traceback.
        assert "Traceback" not in r.output and r.output.count("error:") == 1
        line = r.output.strip().splitlines()[-1]
        assert line.startswith(f"error: scheduler {address!r}: ") and match in line
        assert elapsed < 10.0  # the simulation's imports, then 1 s
        assert not out.exists()


# `--workers 1000` for one trial started 1000 processes on 2 cores (not done after 200 s,
# 3,594 semaphores leaked): local workers are capped at the cores and at the work.


def test_local_workers_are_capped_at_the_cores_and_the_work(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from pbdkit.sim import _forkserver

    monkeypatch.setattr(_forkserver, "cores", lambda: 4)
    assert _forkserver.local_workers(1000) == 4
    assert _forkserver.local_workers(3) == 3
    assert _forkserver.local_workers(1000, work=2) == 2
    assert _forkserver.local_workers(1000, work=0) == 1
    for bad in (0, -3, 2.0, True, "2", None):
        with pytest.raises(ValueError, match=f"workers must be an integer >= 1, got {bad!r}"):
            _forkserver.local_workers(bad)


def test_a_session_of_1000_workers_starts_one_per_core(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    from pbdkit.sim import _forkserver
    from pbdkit.sim import _parallel as parallel

    # The cluster the session and connect would start is recorded, not started.
    started: list[int] = []

    def cluster(n: int) -> parallel._Connection:
        started.append(n)
        return parallel._Connection("client", None)

    monkeypatch.setattr(parallel, "_local_cluster", cluster)
    monkeypatch.setattr(_forkserver, "start", lambda: None)
    monkeypatch.setattr(_forkserver, "cores", lambda: 3)
    with caplog.at_level("WARNING", logger=parallel.__name__):
        run = Session(workers=1000)
        assert run.client == "client"
        connect(workers=1000)
        connect(workers=2)
    assert started == [3, 3, 2]
    assert (
        caplog.messages
        == ["workers=1000: starting 3, one per core (more would only compete for the cores)"] * 2
    )


def test_the_command_line_caps_the_workers_with_a_notice(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from typer.testing import CliRunner

    from pbdkit.apps._cli import app
    from pbdkit.sim import _evaluation as evaluation
    from pbdkit.sim import _forkserver

    asked: list[int | None] = []

    def evaluate(*args: Any, workers: int | None = None, **kwargs: Any) -> None:
        asked.append(workers)
        raise ValueError("stopped here by the test")

    monkeypatch.setattr(evaluation, "evaluate", evaluate)  # where the command finds it
    monkeypatch.setattr(_forkserver, "start", lambda: None)
    monkeypatch.setattr(_forkserver, "cores", lambda: 2)
    runner = CliRunner()
    base = ["evaluate", "--trials", "3", "--workers", "1000"]
    r = runner.invoke(app, base)
    assert r.output.startswith(
        "--workers 1000: starting 2 (one per core; more would have nothing to do but compete "
        "for the cores)\n"
    )
    r = runner.invoke(app, [*base, "--trials", "1", "--controller", "fused"])
    assert "--workers 1000: starting 1 (one per trial and controller;" in r.output
    r = runner.invoke(app, [*base[:-1], "2"])
    assert "starting" not in r.output
    assert asked == [2, 1, 2]
    for bad in ("0", "-5"):
        r = runner.invoke(app, ["evaluate", "--workers", bad])
        assert r.exit_code == 2 and f"must be >= 1, got {bad}" in r.output


def test_a_local_cluster_leaves_port_8787_to_others() -> None:
    # Without a dashboard, the scheduler still served HTTP on port 8787: with another cluster
    # on the machine Dask warned "Port 8787 is already in use" (an error under pytest).
    from pbdkit.sim import _parallel as parallel

    client, cluster = parallel._local_cluster(0)
    try:
        http = cluster.scheduler.http_server
        assert (http.address, http.port != 8787) == ("127.0.0.1", True)
    finally:
        client.close()
        cluster.close()
