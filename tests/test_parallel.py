"""Trials on worker processes and on a Dask cluster give the serial results, a dead worker's
trials are run again (issue 14)."""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from typing import Any

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("distributed")

from pbdkit import Skill
from pbdkit.robots import katana
from pbdkit.sim import experiment as E
from pbdkit.sim.parallel import connect, session
from pbdkit.sim.teacher import teach


@pytest.fixture(scope="module")
def coaster() -> E.TaskSkill:
    demos = teach("coaster", 3, seed=1, speed=2.0)
    skill = Skill.learn(demos, katana(), n_steps=150, objects=E.constrained_objects("coaster"))
    return E.TaskSkill("coaster", demos, skill, 0.0, 0.0)


def _json(ev: E.Evaluation) -> str:
    data = ev.as_dict()
    data.pop("learn_seconds")
    return json.dumps(data, sort_keys=True)


def test_workers_give_the_serial_results(coaster: E.TaskSkill) -> None:
    # A disturbance drawn per trial, two controllers, the cameras: everything a trial depends
    # on travels to the workers, and the results come back in order.
    args: dict[str, Any] = {
        "task_skill": coaster,
        "controllers": ["fused", "joint"],
        "perturb": "push",
    }
    serial = E.evaluate("coaster", 3, 0, **args)
    ticks: list[tuple[int, int]] = []
    parallel = E.evaluate(
        "coaster", 3, 0, workers=2, progress=lambda d, t: ticks.append((d, t)), **args
    )
    assert _json(parallel) == _json(serial)
    assert serial.vision and serial.tracking_error_mm is not None
    assert ticks[-1] == (6, 6) and len(ticks) == 3  # one tick per trial, counting runs


def test_a_killed_workers_trials_are_run_again(coaster: E.TaskSkill) -> None:
    from distributed import LocalCluster

    args: dict[str, Any] = {"task_skill": coaster, "controllers": ["fused"], "ground_truth": True}
    serial = E.evaluate("coaster", 4, 0, **args)
    cluster = LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    )
    killed: list[int] = []

    def kill_one(done: int, total: int) -> None:
        # After the first trial, both workers are busy with the next ones: kill one of them.
        if not killed:
            pid = next(iter(cluster.workers.values())).process.pid
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    try:
        parallel = E.evaluate(
            "coaster", 4, 0, scheduler=cluster.scheduler_address, progress=kill_one, **args
        )
    finally:
        cluster.close()
    assert killed
    assert _json(parallel) == _json(serial)


def test_a_worker_with_two_threads_gives_the_serial_results(coaster: E.TaskSkill) -> None:
    # Two trials at once in one process: each thread works on its own copy of the skill.
    from distributed import LocalCluster

    args: dict[str, Any] = {"task_skill": coaster, "controllers": ["fused"], "ground_truth": True}
    serial = E.evaluate("coaster", 4, 1, **args)
    cluster = LocalCluster(
        n_workers=1, threads_per_worker=2, processes=True, dashboard_address=None
    )
    try:
        threaded = E.evaluate("coaster", 4, 1, scheduler=cluster.scheduler_address, **args)
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
    return "pbdkit.sim.experiment" in sys.modules


def _profiling() -> bool:
    import dask

    return bool(dask.config.get("distributed.worker.profile.enabled"))


def test_a_session_starts_quiet_workers_that_import_at_once() -> None:
    with session() as none:
        assert none is None  # serial: no cluster
    with session(workers=1) as client:
        # Dask's statistical profiler made trials about 25 % slower: off on our workers.
        assert list(client.run(_profiling).values()) == [False]
        # The workers import pbdkit's simulation without being sent a trial.
        deadline = time.monotonic() + 60.0
        while not all(client.run(_imported_sim).values()):
            assert time.monotonic() < deadline, "the workers did not import pbdkit.sim"
            time.sleep(0.2)
    assert client.status == "closed"
