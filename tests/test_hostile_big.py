"""Hostile inputs, fourth pass (issue 36, items 4, 6, 8, 9 and 18): sizes and values that were
accepted and then failed far from where they were given.

- Item 4: a skill learned on a fine grid reproduces (retime's taper spans a time, not a number of
  steps: on 0.5 ms steps it crept along the path and a 60000-step skill raised after 200 rounds).
- Item 6: ``pbdkit evaluate --trials 1000000000`` is a one-line error at once (it drew the
  placements at 11 MB/s before the first trial).
- Item 8: ``save_demonstrations`` refuses what ``load_demonstrations`` would refuse (the size cap
  of a file's arrays), writing nothing.
- Item 9: a velocity, acceleration or jerk limit outside the range of real arms (1e-300, 1e300)
  is refused where it is given (reproduce's keywords, a joint_limits.yaml, MotionLimits), not
  inside the trajectory generator.
- Item 18: a NaN or inf is never written: a reproduction's file refuses it naming the field, the
  JSON writer (``pbdkit evaluate --json``) naming where it is; a value not known is left out or
  written null.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import types
import warnings
from pathlib import Path

import numpy as np
import pytest
from hostile import bounded
from typer.testing import CliRunner

from pbdkit import _io
from pbdkit._io import write_json
from pbdkit.apps._cli import app
from pbdkit.data._demonstration import Demonstration, load_demonstrations, save_demonstrations
from pbdkit.motion._limits import (
    MotionLimits,
    RetimeWarning,
    motion_peaks,
    retime,
    times_from_durations,
)
from pbdkit.reproduction._result import ReproductionResult
from pbdkit.robots import katana_urdf_path
from pbdkit.robots._robot import Robot
from pbdkit.skill._skill import Skill

KATANA = MotionLimits(np.full(2, 1.19), np.full(2, 6.0), np.full(2, 60.0))


def _one_line(exc: pytest.ExceptionInfo[BaseException], *fragments: str) -> None:
    text = str(exc.value)
    assert "\n" not in text and len(text) < 400, text
    for fragment in fragments:
        assert fragment in text, text


# ----------------------------------------------------------------------------- item 4
def _back_and_forth(dt: float) -> np.ndarray:
    """Two joints going back and forth at half the Katana's top speed, corners rounded over
    0.2 s, sampled every ``dt`` s: the same motion whatever ``dt``."""
    t = np.arange(0.0, 4.0 + 1e-9, dt)
    q = 0.5 * 1.19 * np.abs((t % 2.0) - 1.0)
    k = round(0.1 / dt)
    q = np.convolve(np.pad(q, k, mode="edge"), np.ones(2 * k + 1) / (2 * k + 1), mode="valid")
    return np.c_[q, 0.5 * q]


def test_retime_times_a_finely_sampled_path_as_a_coarse_one() -> None:
    """The same motion sampled at 10 ms and 0.5 ms: 7.3 s and 877 s before (the taper of 10
    steps, 5 ms on the fine grid, crept along the path a taper per round), now 7.3 and 30 s."""
    coarse = retime(_back_and_forth(0.01), 0.01, KATANA).sum()
    q = _back_and_forth(0.0005)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RetimeWarning)
        h = retime(q, 0.0005, KATANA)
    assert np.all(h >= 0.0005)
    assert motion_peaks(times_from_durations(h), q, KATANA).worst <= 1.0 + 1e-9
    assert h.sum() < 6.0 * coarse, (h.sum(), coarse)


def test_a_skill_learned_on_a_fine_grid_reproduces(
    demos: list[Demonstration], robot: Robot, limits: MotionLimits
) -> None:
    """n_steps=20000 (the synthetic skill's own grid: 200): timed within the limits, 14 times
    the demonstrations' pace (167 before; issue 36: a 60000-step skill raised RuntimeError)."""
    skill = Skill.learn(demos, robot, n_steps=20000, random_state=0)
    glass = np.mean([d.objects["glass"] for d in demos], axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RetimeWarning)
        res = skill.reproduce({"glass": glass})
    assert res.joints.shape[0] > 20000
    assert motion_peaks(skill.times(res), res.joints, limits).worst <= 1.0 + 1e-9
    assert res.stretch < 30.0, res.stretch


# ----------------------------------------------------------------------------- item 6
@pytest.fixture
def no_simulation(monkeypatch: pytest.MonkeyPatch) -> None:
    """The simulator's modules replaced by stand-ins that fail the test when reached."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the command started working before checking --trials")

    for name in ("pbdkit.sim", "pbdkit.sim._evaluation", "pbdkit.sim._trials"):
        fake = types.ModuleType(name)
        fake.__getattr__ = lambda attr: refuse  # type: ignore[method-assign]
        monkeypatch.setitem(sys.modules, name, fake)


@pytest.mark.usefixtures("no_simulation")
@pytest.mark.parametrize("trials", ["100001", "1000000000", "0"])
def test_evaluate_refuses_trials_beyond_the_cap_at_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, trials: str
) -> None:
    monkeypatch.chdir(tmp_path)
    with bounded(seconds=3.0, megabytes=30.0):
        result = CliRunner().invoke(app, ["evaluate", "--trials", trials])
    assert result.exit_code == 2, result.output
    text = result.output.strip()
    assert text.startswith("error: ") and "\n" not in text, text
    assert "--trials" in text and "100000" in text and trials in text, text
    assert list(tmp_path.iterdir()) == []


def test_sim_evaluate_refuses_trials_beyond_the_cap_before_learning(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    pytest.importorskip("mujoco")
    from pbdkit.sim import _evaluation

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("evaluate started learning before checking trials")

    monkeypatch.setattr(_evaluation, "learn_task", refuse)
    with pytest.raises(ValueError, match=r"^trials must be <= 100000, got 1000000000$"):
        _evaluation.evaluate("coaster", 10**9, 0)


# ----------------------------------------------------------------------------- item 8
def _demos(n_demos: int, n_samples: int) -> list[Demonstration]:
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 2.0, n_samples)
    return [
        Demonstration(t, rng.normal(0.0, 0.1, (n_samples, 5)), {"glass": np.array([0.4, 0, 0.1])})
        for _ in range(n_demos)
    ]


def test_demonstrations_that_could_not_be_loaded_are_not_saved(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """200 demonstrations of 10**5 samples took 1.44 GB of arrays in a 735 MB file, beyond the
    loader's 1 GiB: the cap made 100 kB here, the same check."""
    monkeypatch.setattr(_io, "MAX_NPZ_BYTES", 100_000)
    small = _demos(2, 200)  # 2 x 200 x 6 floats: 19 kB
    save_demonstrations(small, tmp_path / "small.npz")
    assert len(load_demonstrations(tmp_path / "small.npz")) == 2
    big = _demos(4, 600)  # 115 kB: the loader would refuse it
    with pytest.raises(ValueError, match=r"^demos: the file would hold 115 kB") as exc:
        save_demonstrations(big, tmp_path / "big.npz")
    _one_line(exc, "demos: ", "115 kB", "100 kB", "MAX_NPZ_BYTES", "nothing written")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.npz"]


# ----------------------------------------------------------------------------- item 9
# pbdkit.motion._limits.LIMIT_RANGES, as the messages show them.
RANGES = {
    "velocity_limit": "[0.001, 1e+09] rad/s",
    "acceleration_limit": "[0.001, 1e+09] rad/s^2",
    "jerk_limit": "[0.01, 1e+09] rad/s^3",
}


@pytest.mark.parametrize(
    ("keyword", "value", "shown"),
    [
        ("velocity_limit", 1e-300, "1e-300"),  # a multi-line dump from inside Ruckig
        ("velocity_limit", 1e-9, "1e-09"),  # "ValueError: -101 is not a valid Result."
        ("velocity_limit", 1e300, "1e+300"),
        ("acceleration_limit", 1e-300, "1e-300"),
        ("jerk_limit", 1e-300, "1e-300"),
        ("jerk_limit", 1e300, "1e+300"),
    ],
)
def test_reproduce_refuses_a_limit_no_arm_has(
    skill: Skill, demos: list[Demonstration], keyword: str, value: float, shown: str
) -> None:
    glass = demos[0].objects["glass"]
    with pytest.raises(ValueError, match=rf"^{keyword}\[0\] must be in") as exc:
        skill.reproduce({"glass": glass}, **{keyword: value})  # type: ignore[arg-type]
    _one_line(exc, f"{keyword}[0] must be in {RANGES[keyword]}", shown)


def test_motion_limits_refuse_a_limit_no_arm_has_and_take_every_real_arm() -> None:
    with pytest.raises(ValueError, match=r"^velocity\[1\] must be in") as exc:
        MotionLimits(np.array([1.0, 1e-300]), np.ones(2), np.ones(2))
    _one_line(exc, "velocity[1] must be in [0.001, 1e+09] rad/s", "1e-300")
    with pytest.raises(ValueError, match=r"^jerk\[1\] must be in") as exc:
        MotionLimits(np.ones(2), np.ones(2), np.array([np.inf, 1e300]))
    _one_line(exc, "jerk[1] must be in [0.01, 1e+09] rad/s^3", "1e+300")
    # The Katana, a Franka Panda, the ends of the ranges, and no limit at all.
    for v, a, j in [(1.19, 6.0, 60.0), (2.61, 15.0, 7500.0), (1e-3, 1e-3, 1e-2), (1e9, 1e9, 1e9)]:
        lim = MotionLimits(np.full(2, v), np.full(2, a), np.full(2, j))
        assert lim.scaled(0.995).velocity[0] == pytest.approx(0.995 * v)  # margins stay usable
    assert not MotionLimits.unlimited(3).any


def _limits_from_file(path: Path) -> MotionLimits:
    """The limits of the Katana with the joint_limits.yaml ``path``."""
    robot = Robot.from_urdf(katana_urdf_path(), tip="tool", joint_limits=path)
    return MotionLimits.from_robot(robot, robot.n_joints)


def test_a_limit_no_arm_has_in_a_joint_limits_file_never_reaches_the_generator(
    tmp_path: Path,
) -> None:
    path = tmp_path / "joint_limits.yaml"
    path.write_text(
        "joint_limits:\n  lift1:\n    has_velocity_limits: true\n    max_velocity: 1.0e-300\n"
    )
    # Refused by the file's reader or by the limits made of it: never a Ruckig error.
    with pytest.raises(ValueError, match=r"velocity.*1e-300") as exc:
        _limits_from_file(path)
    _one_line(exc)


# ----------------------------------------------------------------------------- item 18
@pytest.fixture(scope="module")
def free_result(skill: Skill, demos: list[Demonstration]) -> ReproductionResult:
    """The synthetic skill reproduced as the paper's loop (no limits: nominal_dt NaN)."""
    none = {"velocity_limit": None, "acceleration_limit": None, "jerk_limit": None}
    return skill.reproduce({"glass": demos[0].objects["glass"]}, **none)  # type: ignore[arg-type]


def test_a_reproduction_with_a_nan_is_not_saved(
    free_result: ReproductionResult, tmp_path: Path
) -> None:
    joints = free_result.joints.copy()
    joints[7, 2] = np.nan
    with pytest.raises(ValueError, match=r"^joints\[7\]\[2\] is nan") as exc:
        dataclasses.replace(free_result, joints=joints).save(tmp_path / "r.npz")
    _one_line(exc, "joints[7][2] is nan", "nothing written")
    errors = {k: v.copy() for k, v in free_result.task_errors.items()}
    errors["glass"][3] = np.inf
    with pytest.raises(ValueError, match=r"^task_errors\['glass'\]\[3\] is inf") as exc:
        dataclasses.replace(free_result, task_errors=errors).save(tmp_path / "r.npz")
    _one_line(exc, "task_errors['glass'][3] is inf")
    with pytest.raises(ValueError, match=r"^nominal_dt must be a positive number") as exc:
        dataclasses.replace(free_result, nominal_dt=math.inf).save(tmp_path / "r.npz")
    _one_line(exc, "nominal_dt must be a positive number", "inf")
    assert list(tmp_path.iterdir()) == []
    # No timing: nominal_dt is not known; left out of the file, NaN again when loaded.
    free_result.save(tmp_path / "r.npz")
    with np.load(tmp_path / "r.npz") as data:
        assert "nominal_dt" not in data.files
        assert all(np.isfinite(data[k]).all() for k in data.files if data[k].dtype.kind == "f")
    assert math.isnan(ReproductionResult.load(tmp_path / "r.npz").nominal_dt)


def test_json_refuses_a_nan_naming_where_and_writes_none_as_null(tmp_path: Path) -> None:
    path = tmp_path / "evaluation.json"
    data = {
        "controllers": {"fused": {"metrics": {"peak_jerk": {"mean": 1.0, "max": float("nan")}}}},
        "runs": {"fused": [{"success": True}, {"following_error_rad": np.float64(np.inf)}]},
    }
    with pytest.raises(
        ValueError, match=r"controllers\.fused\.metrics\.peak_jerk\.max is nan"
    ) as exc:
        write_json(path, data)
    _one_line(exc, str(path), "null", "nothing written")
    del data["controllers"]
    with pytest.raises(ValueError, match=r"runs\.fused\[1\]\.following_error_rad is inf") as exc:
        write_json(path, data)
    _one_line(exc)
    with pytest.raises(ValueError, match=r"placements\[1\]\[0\] is nan") as exc:
        write_json(path, {"placements": np.array([[0.1, 0.2], [np.nan, 0.3]])})
    _one_line(exc)
    assert list(tmp_path.iterdir()) == []
    # What a run has none of is None: null, and the file is JSON.
    write_json(path, {"metrics": {"peak_jerk": None}, "n": np.int64(3)})
    assert json.loads(path.read_text()) == {"metrics": {"peak_jerk": None}, "n": 3}


def test_a_skill_or_frame_model_that_could_not_be_loaded_is_not_saved(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, skill: Skill
) -> None:
    """Skill and FrameModel files are read with their own caps (64 MiB, 16 MiB): their save
    refuses what their load would, nothing written (here with the caps made small)."""
    import pbdkit.prob._frames as frames
    import pbdkit.skill._skill as skill_module

    skill.save(tmp_path / "ok.npz")
    monkeypatch.setattr(skill_module, "MAX_FILE_BYTES", 1000)
    with pytest.raises(ValueError, match=r"^skill: the file would hold .* nothing written$"):
        skill.save(tmp_path / "big.npz")
    t = np.linspace(0.0, 1.0, 20)
    trajs = [np.column_stack([t, t + i]) for i in range(3)]
    model = frames.FrameModel.learn(
        trajs, [[(np.eye(1), np.array([float(i)]))] for i in range(3)], n_components=2
    )
    monkeypatch.setattr(frames, "MAX_FILE_BYTES", 100)
    with pytest.raises(ValueError, match=r"^FrameModel: the file would hold"):
        model.save(tmp_path / "fm.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.npz"]
