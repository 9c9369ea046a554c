"""The loop of Table II: the step of the controller a run asks for (:func:`make_step`) over the
time grid (:func:`_table_ii`), and the :class:`ReproductionResult` of its path
(:func:`_path_result`).

The steps and the loops over them are in :mod:`._steps` (positions) and :mod:`._pose_steps`
(oriented constraints); :doc:`/reproduction` has their math.
"""

from __future__ import annotations

from typing import cast

import numpy as np
from numpy.typing import NDArray

from .._rotations import log_map
from ..robots._protocols import KinematicModel, PoseKinematicModel
from ._constraints import JOINT
from ._pose_steps import PoseFusedStep, PoseTaskStep, _pose_loop
from ._result import ReproductionResult
from ._setup import RunSetup
from ._steps import (
    ControllerStep,
    FusedStep,
    JointStep,
    LoopOutput,
    TaskStep,
    _fused_loop,
    _joint_only,
    _task_loop,
)

__all__ = ["make_step"]

Float = NDArray[np.float64]


def _path_result(
    robot: KinematicModel,
    run: RunSetup,
    steps: Float,
    path: LoopOutput,
    *,
    times: Float | None = None,
    velocities: Float | None = None,
    accelerations: Float | None = None,
    lead: NDArray[np.bool_] | None = None,
    nominal_dt: float = float("nan"),
) -> ReproductionResult:
    """A :class:`ReproductionResult` from a path and the phase of its samples (``steps``); with
    motion limits, its timing (:func:`pbdkit.reproduction._timing.timed_path`)."""
    c, objs = run.constraints, run.objects
    joints, positions, covs, influence, influence_js, limited = path
    index = np.asarray(np.floor(steps + 1e-9), dtype=np.intp)
    world = {k: c.world_task(k, o) for k, o in objs.items()}
    task_errors = {
        k: np.linalg.norm(positions - w.position[index], axis=1) for k, w in world.items()
    }
    orientations = None
    orientation_errors: dict[str, Float] = {}
    if c.oriented:
        # Oriented constraints: setup_run checked that the robot is a PoseKinematicModel.
        pose_robot = cast(PoseKinematicModel, robot)
        orientations = np.asarray(pose_robot.fk_pose(joints), dtype=np.float64)[:, :3, :3]
        for k, w in world.items():
            if w.rotation is not None:
                err = log_map(orientations @ np.swapaxes(w.rotation[index], -1, -2))
                orientation_errors[k] = np.linalg.norm(err, axis=1)
    signal = None if c.gripper is None else c.gripper[index].copy()
    closed = np.zeros(index.shape[0], dtype=bool) if signal is None else signal > 0.5
    return ReproductionResult(
        t=np.asarray(steps, dtype=np.float64),
        joints=joints,
        positions=positions,
        covariances=covs,
        gripper=closed,
        gripper_signal=signal,
        influence=influence,
        influence_joint_space=influence_js,
        task_errors=task_errors,
        used=tuple(run.used),
        limited=limited,
        times=times,
        velocities=velocities,
        accelerations=accelerations,
        lead_in=np.zeros(joints.shape[0], dtype=bool) if lead is None else lead,
        nominal_dt=nominal_dt,
        orientations=orientations,
        orientation_errors=orientation_errors,
    )


def make_step(robot: KinematicModel, run: RunSetup) -> ControllerStep:
    """The step of the controller ``run`` asks for (its constraints in use): the one place
    the offline loop (:func:`pbdkit.reproduction._probabilistic_ik.solve`) and the online
    controller get it from."""
    if any(k in run.constraints.rotation_base for k in run.tasks):
        # Oriented constraints: setup_run checked that the robot is a PoseKinematicModel.
        pose_robot = cast(PoseKinematicModel, robot)
        return (
            PoseFusedStep(pose_robot, run) if JOINT in run.used else PoseTaskStep(pose_robot, run)
        )
    if JOINT not in run.used:
        return TaskStep(robot, run)
    if run.tasks:
        return FusedStep(robot, run)
    return JointStep(run)


def _table_ii(
    robot: KinematicModel,
    run: RunSetup,
    theta0: Float,
    *,
    start: int = 0,
    step: ControllerStep | None = None,
) -> LoopOutput:
    """The loop of the controller ``run`` asks for, from ``theta0`` at step ``start``: joints,
    positions, covariances, influence (hand space and joint space) and the mask of scaled
    steps, for steps ``start`` .. T - 1 (row 0: ``theta0``). ``step``: the controller's step
    (:func:`make_step`), if already built."""
    c = run.constraints
    step = make_step(robot, run) if step is None else step
    if isinstance(step, FusedStep):
        return _fused_loop(c, run.tasks, theta0, step, start=start)
    if isinstance(step, JointStep):
        joints, limited = _joint_only(step, theta0, start=start)
        positions = np.asarray(robot.fk(joints), dtype=np.float64)
        ones = {JOINT: np.ones(c.n_steps - start)}
        covs = c.joint_cov[start:].copy()
        return LoopOutput(joints, positions, covs, ones, {JOINT: ones[JOINT].copy()}, limited)
    if isinstance(step, (PoseFusedStep, PoseTaskStep)):
        return _pose_loop(c, step, theta0, start=start)
    assert isinstance(step, TaskStep)
    joints, positions, covs, influence, limited = _task_loop(step, theta0, start=start)
    # Rank-3 covariance: no joint-space precision to compare; the task-space shares.
    influence_js = {k: v.copy() for k, v in influence.items()}
    return LoopOutput(joints, positions, covs, influence, influence_js, limited)
