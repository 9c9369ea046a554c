"""Tests of pbdkit.reproduction._result: a reproduction's result and its file (the
``pbdkit-reproduction`` .npz of ``pbdkit reproduce --out``), saved and loaded back."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from synthetic_teacher import Q_REACH

from pbdkit._rotations import exp_map
from pbdkit.data._demonstration import Demonstration, save_demonstrations
from pbdkit.reproduction._result import ReproductionResult
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill

DICTS = ("influence", "influence_joint_space", "task_errors", "orientation_errors")


def assert_equal_results(a: ReproductionResult, b: ReproductionResult) -> None:
    """Every field of ``a`` and ``b`` equal: arrays bit for bit, dicts in the same order."""
    for field in dataclasses.fields(ReproductionResult):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if field.name in DICTS:
            assert list(x) == list(y), field.name
            for k in x:
                np.testing.assert_array_equal(x[k], y[k], err_msg=f"{field.name}[{k!r}]")
                assert x[k].dtype == y[k].dtype
        elif isinstance(x, np.ndarray):
            assert isinstance(y, np.ndarray) and x.dtype == y.dtype, field.name
            np.testing.assert_array_equal(x, y, err_msg=field.name)
        elif isinstance(x, float):
            assert x == y or (np.isnan(x) and np.isnan(y)), field.name
        else:
            assert x == y, field.name


def oriented_result(rng: np.random.Generator, n_samples: int = 7, n: int = 7) -> ReproductionResult:
    """A result with every field filled, oriented constraints and a timing included."""
    a = rng.normal(size=(n_samples, n, n))
    shares = rng.dirichlet(np.ones(3), size=n_samples).T
    return ReproductionResult(
        t=np.r_[0.0, 0.0, np.arange(n_samples - 2, dtype=np.float64)],
        joints=rng.normal(size=(n_samples, n)),
        positions=rng.normal(size=(n_samples, 3)),
        covariances=a @ np.swapaxes(a, 1, 2),
        gripper=rng.random(n_samples) > 0.5,
        gripper_signal=rng.random(n_samples),
        influence={"joint": shares[0], "mug": shares[1], "tray": shares[2]},
        influence_joint_space={"joint": shares[2], "mug": shares[0], "tray": shares[1]},
        task_errors={"mug": rng.random(n_samples), "tray": rng.random(n_samples)},
        used=("joint", "mug", "tray"),
        limited=rng.random(n_samples) > 0.7,
        times=np.cumsum(rng.random(n_samples)),
        velocities=rng.normal(size=(n_samples, n)),
        accelerations=rng.normal(size=(n_samples, n)),
        lead_in=np.arange(n_samples) < 2,
        nominal_dt=0.02,
        orientations=exp_map(rng.normal(size=(n_samples, 3))),
        orientation_errors={"mug": rng.random(n_samples)},
    )


@pytest.fixture(scope="module")
def results(skill: Skill, robot: Robot) -> dict[str, ReproductionResult]:
    """Reproductions of the synthetic glass skill: timed (a lead-in, velocities), as the paper's
    loop (no limits), and a task-only controller."""
    glass = robot.fk(Q_REACH)
    free = {"velocity_limit": None, "acceleration_limit": None, "jerk_limit": None}
    return {
        "timed": skill.reproduce({"glass": glass}, q0=robot.lower * 0.5 + robot.upper * 0.5),
        "free": skill.reproduce({"glass": glass}, **free),
        "task": skill.reproduce({"glass": glass}, use=["glass"], **free),
    }


@pytest.mark.parametrize("kind", ["timed", "free", "task"])
def test_a_reproduction_saved_loads_back_equal(
    results: dict[str, ReproductionResult], kind: str, tmp_path: Path
) -> None:
    res = results[kind]
    path = tmp_path / "repro.npz"
    res.save(path)
    back = ReproductionResult.load(path)
    assert_equal_results(res, back)
    assert back.stretch == res.stretch or np.isnan(res.stretch)
    with np.load(path, allow_pickle=False) as data:
        assert str(data["format"]) == "pbdkit-reproduction" and int(data["version"]) == 1
        assert ("times" in data.files) == (kind == "timed")


def test_every_field_round_trips(tmp_path: Path) -> None:
    res = oriented_result(np.random.default_rng(0))
    res.save(tmp_path / "r.npz")
    assert_equal_results(res, ReproductionResult.load(tmp_path / "r.npz"))
    # Saved again over the first file: replaced, equal again.
    res2 = dataclasses.replace(res, gripper_signal=None, orientations=None, orientation_errors={})
    res2.save(tmp_path / "r.npz")
    assert_equal_results(res2, ReproductionResult.load(tmp_path / "r.npz"))


def test_a_file_written_before_the_added_keys_loads(
    results: dict[str, ReproductionResult], tmp_path: Path
) -> None:
    # The keys `pbdkit reproduce --out` wrote before the result saved itself.
    res = results["timed"]
    arrays: dict[str, Any] = {
        "format": np.array("pbdkit-reproduction"),
        "version": np.array(1, dtype=np.int64),
        "t": res.t,
        "joints": res.joints,
        "positions": res.positions,
        "gripper": res.gripper,
        "covariances": res.covariances,
        **{f"influence_{k}": v for k, v in res.influence.items()},
        **{f"task_error_{k}": v for k, v in res.task_errors.items()},
        "times": res.times,
        "velocities": res.velocities,
        "accelerations": res.accelerations,
        "lead_in": res.lead_in,
    }
    np.savez_compressed(tmp_path / "old.npz", **arrays)
    back = ReproductionResult.load(tmp_path / "old.npz")
    kept = dataclasses.replace(
        res,
        gripper_signal=None,
        influence_joint_space={},
        limited=np.zeros(res.t.shape[0], dtype=bool),
        nominal_dt=float("nan"),
    )
    assert_equal_results(kept, back)


def test_a_new_file_gets_the_mode_of_the_umask(
    results: dict[str, ReproductionResult], tmp_path: Path
) -> None:
    old = os.umask(0o027)
    try:
        results["free"].save(tmp_path / "r.npz")
    finally:
        os.umask(old)
    assert (tmp_path / "r.npz").stat().st_mode & 0o777 == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.npz"]  # no temporary left


def test_corrupt_foreign_and_other_files_are_refused(
    results: dict[str, ReproductionResult], skill: Skill, tmp_path: Path
) -> None:
    with pytest.raises(FileNotFoundError, match="pbdkit-reproduction file not found"):
        ReproductionResult.load(tmp_path / "none.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(np.random.default_rng(1).bytes(300))
    with pytest.raises(ValueError, match=r"corrupt\.npz is not a NumPy \.npz archive"):
        ReproductionResult.load(corrupt)
    skill.save(tmp_path / "skill.npz")
    with pytest.raises(ValueError, match=r"skill\.npz is not a pbdkit-reproduction file"):
        ReproductionResult.load(tmp_path / "skill.npz")
    demo = Demonstration(t=[0.0, 1.0], joints=np.zeros((2, 5)))
    save_demonstrations([demo], tmp_path / "demos.npz")
    with pytest.raises(ValueError, match=r"demos\.npz is not a pbdkit-reproduction file"):
        ReproductionResult.load(tmp_path / "demos.npz")

    good = tmp_path / "good.npz"
    results["free"].save(good)
    with np.load(good, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}

    def refused(name: str, match: str, **changes: Any) -> None:
        path = tmp_path / name
        np.savez(path, **{k: v for k, v in {**arrays, **changes}.items() if v is not None})
        with pytest.raises(ValueError, match=rf"{name} .*{match}"):
            ReproductionResult.load(path)

    refused("v2.npz", r"of version 2; this pbdkit reads version 1", version=np.array(2))
    refused("extra.npz", r"unknown key\(s\) 'secret'", secret=np.zeros(3))
    refused("short.npz", r"missing key 'positions'", positions=None)
    refused("shape.npz", r"joints must be float64 of shape \(\d+, 5\)", joints=np.zeros((3, 5)))
    refused("type.npz", r"gripper must be bool", gripper=np.zeros(arrays["t"].shape[0]))
    refused("none.npz", r"no influence_NAME key", influence_joint=None, influence_glass=None)
    refused("half.npz", r"times, velocities and accelerations go together", times=arrays["t"])
    # A pickled object array is refused before anything is loaded.
    path = tmp_path / "pickle.npz"
    np.savez(path, **arrays, t_obj=np.array([object()], dtype=object))
    with pytest.raises(ValueError, match=r"pickle\.npz .*object array"):
        ReproductionResult.load(path)
