"""Inverse kinematics by damped least squares: joint angles that put an arm's tip at a position
(and an orientation), within the joint limits, for any :class:`KinematicModel`.

From q0, each iteration takes the task error e and its Jacobian A and steps

    q <- clip(q + A^T (A A^T + lambda^2 I)^-1 e, lower, upper)

(damped least squares: Wampler 1986, Nakamura & Hanafusa 1986; lambda bounds the step near a
singularity). The task is the tip position (e = x* - f(q), A = dx/dq); with an orientation R*
also e_w = log(R* R^T) with the angular rows of the 6-D Jacobian (a :class:`PoseKinematicModel`);
callers may stack constant linear rows (c^T q = b, e.g. the Katana's tool pitch). The iteration
stops at the first posture whose error norm is below ``tol``.

:func:`ik` is what :meth:`pbdkit.robots.Robot.ik` runs (inputs checked, an error when it does
not converge); :func:`damped_least_squares` is the iteration itself, with every option, for the
demonstration generators (:func:`pbdkit.datasets.reach_grasp_return`, the simulated teacher).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import check_rotation, log3
from .._validation import check_array, check_int, check_positive_float
from ._protocols import KinematicModel, PoseKinematicModel, check_robot

__all__ = ["damped_least_squares", "ik"]

Float = NDArray[np.float64]

#: lambda of :func:`ik` (m and rad): damps the steps near singularities only.
IK_DAMPING = 1e-2
#: Largest step of :func:`ik` (norm over the joints, rad or m): keeps each step in the region
#: where the linearisation holds.
IK_MAX_STEP = 0.2


def damped_least_squares(
    robot: KinematicModel,
    target: Float,
    q0: Float,
    *,
    lower: Float,
    upper: Float,
    tol: float,
    max_iter: int,
    damping: float,
    max_step: float | None = None,
    rotation: Float | None = None,
    rows: Float | None = None,
    row_targets: Sequence[float] | None = None,
) -> tuple[Float, float]:
    """Damped least-squares iteration towards a tip target (module docstring); no validation.

    Parameters
    ----------
    robot : KinematicModel
        A :class:`PoseKinematicModel` when ``rotation`` is given.
    target : ndarray, shape (3,)
        Tip position in the base frame.
    q0 : ndarray, shape (n,)
        Initial posture (it picks the solution branch).
    lower, upper : ndarray, shape (n,)
        Each iterate is clipped to [lower, upper].
    tol : float
        Stop at the first posture whose error norm is below ``tol`` (m and rad mixed).
    max_iter : int
        Number of iterations (Jacobian evaluations) at most.
    damping : float
        lambda: the step solves (A A^T + lambda^2 I) y = e.
    max_step : float, optional
        A step longer than this (norm over the joints) is scaled down to it. None: no bound.
    rotation : ndarray, shape (3, 3), optional
        Target orientation of the tip frame in the base frame: adds e_w = log(R* R^T) and the
        angular rows of the 6-D Jacobian.
    rows : ndarray, shape (k, n), optional
        Constant task rows c_i, stacked after the tip's rows, with errors b_i - c_i^T q.
    row_targets : sequence of float, length k, optional
        Their targets b_i (required with ``rows``).

    Returns
    -------
    q : ndarray, shape (n,)
        The first posture whose error is below ``tol``; else the last iterate.
    error : float
        Error norm of the posture last evaluated: ``q``'s when it is below ``tol``, else that
        of the iterate before ``q`` (the caller decides whether it is close enough).
    """
    q = np.array(q0, dtype=np.float64)
    lam2 = damping**2
    err = np.inf
    posed = cast(PoseKinematicModel, robot)  # used only with a rotation (the caller checks)
    for _ in range(max_iter):
        if rotation is None:
            x, a = robot.fk_jacobian(q)
            e = target - np.asarray(x, dtype=np.float64)
        else:
            # q is a fresh finite float64 (n,) array here: the unchecked path is safe.
            x, rot, a = posed.fk_pose_jacobian_unchecked(q)
            e = np.concatenate([target - x, log3(rotation @ rot.T)])
        if rows is not None:
            assert row_targets is not None
            # One dot product per row (as the teacher computed its pitch and roll).
            e = np.concatenate([e, [b - q @ c for b, c in zip(row_targets, rows, strict=True)]])
            a = np.vstack([a, rows])
        err = float(np.linalg.norm(e))
        if err < tol:
            return q, err
        dq = a.T @ np.linalg.solve(a @ a.T + lam2 * np.eye(e.shape[0]), e)
        if max_step is not None:
            norm = float(np.linalg.norm(dq))
            if norm > max_step:
                dq *= max_step / norm
        q = np.clip(q + dq, lower, upper)
    return q, err


def _check_start(robot: KinematicModel, q0: npt.ArrayLike | None) -> Float:
    """q0 checked: shape (n,), finite, within the limits; None: the middle of the limits."""
    lower = np.asarray(robot.lower, dtype=np.float64)
    upper = np.asarray(robot.upper, dtype=np.float64)
    n = int(robot.n_joints)
    if q0 is None:
        return 0.5 * (lower + upper)
    q = check_array(q0, "q0", shape=(n,), allow_bool=False)
    bad = np.flatnonzero((q < lower) | (q > upper))
    if bad.size:
        j = int(bad[0])
        raise ValueError(
            f"q0[{j}] (joint '{robot.joint_names[j]}') must be within the joint limits "
            f"[{lower[j]:.6g}, {upper[j]:.6g}], got {q[j]:.6g}; clip it (robot.clip) or pass "
            "q0=None (the middle of the limits)"
        )
    return q


def ik(
    robot: KinematicModel,
    target: npt.ArrayLike,
    q0: npt.ArrayLike | None = None,
    *,
    orientation: npt.ArrayLike | None = None,
    tol: float = 1e-4,
    max_iter: int = 200,
) -> Float:
    """Joint angles that put the tip at ``target`` (and ``orientation``), within the limits.

    Damped least squares (module docstring) with lambda = :data:`IK_DAMPING` and steps of at
    most :data:`IK_MAX_STEP`.

    Parameters
    ----------
    robot : KinematicModel
        A :class:`PoseKinematicModel` when ``orientation`` is given.
    target : array-like, shape (3,)
        Tip position in the base frame.
    q0 : array-like, shape (n,), optional
        Initial posture, within the joint limits; it picks the solution (elbow up or down, a
        redundant arm's null space). Default: the middle of the limits, (lower + upper) / 2.
    orientation : array-like, shape (3, 3), optional
        Tip frame orientation (its axes in the base frame); None: position only.
    tol : float
        Largest residual accepted: the norm of the position error (m) stacked with the
        orientation error (rotation vector, rad).
    max_iter : int
        Iterations at most.

    Returns
    -------
    q : ndarray, shape (n,)
        Within [lower, upper]; its residual is below ``tol``.

    Raises
    ------
    ValueError
        Bad input (the message names the argument), or no convergence: the message gives the
        residual, ``tol`` and ``max_iter`` (the target is out of reach, beyond a joint limit,
        or another ``q0`` is needed).
    """
    x = check_array(target, "target", shape=(3,), allow_bool=False)
    rot = None
    if orientation is not None:
        check_robot(robot, PoseKinematicModel)
        rot = check_rotation(orientation, "orientation")
    tol = check_positive_float(tol, "tol")
    max_iter = check_int(max_iter, "max_iter", minimum=1)
    start = _check_start(robot, q0)
    q, err = damped_least_squares(
        robot,
        x,
        start,
        lower=np.asarray(robot.lower, dtype=np.float64),
        upper=np.asarray(robot.upper, dtype=np.float64),
        tol=tol,
        max_iter=max_iter,
        damping=IK_DAMPING,
        max_step=IK_MAX_STEP,
        rotation=rot,
    )
    if not err < tol:
        what = "pose" if rot is not None else "position"
        raise ValueError(
            f"target: ik did not converge to the {what} {np.round(x, 4).tolist()}: residual "
            f"{err:.3g} >= tol={tol:g} after max_iter={max_iter} iterations; the target may be "
            "out of reach or beyond the joint limits (try another q0, or a larger max_iter)"
        )
    return q
