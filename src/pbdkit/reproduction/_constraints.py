"""The generalized constraints of a skill, as its reproduction uses them.

:class:`Constraints` holds a skill's GMR outputs over its whole time grid: the joint-space
constraint (theta_hat, Sigma^theta) and, for each object n, the task-space constraint
(x_hat^(n), Sigma^x(n)), position-only or oriented, with their precisions computed once.
:meth:`Constraints.world_task` places a task constraint in the robot's base frame for the
object's new position or pose (a :class:`WorldTask`).

The controllers that fuse these constraints step by step are in :mod:`pbdkit.reproduction._steps`
(and, for oriented constraints, :mod:`pbdkit.reproduction._pose_steps`); the loop of Table II
that runs them in :mod:`pbdkit.reproduction._table_ii`; the math in :doc:`/reproduction`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._rotations import check_rotation, exp_map, left_jacobian
from .._validation import check_array, short
from ..prob._frames import precision_to_world
from ..prob.gaussian import inverse_cholesky_factor

__all__ = ["Constraints", "WorldTask"]

Float = NDArray[np.float64]
#: The name of the joint-space constraint, beside the objects' (``use=["joint"]``).
JOINT = "joint"


def _not_positive_definite_at(name: str) -> Callable[[Float], str]:
    """The error message for covariances ``name`` (T, d, d) not positive definite at some steps."""

    def message(cov: Float) -> str:
        bad = [j for j in range(cov.shape[0]) if np.linalg.eigvalsh(cov[j]).min() <= 0]
        return (
            f"{name} must be positive definite at every step; it is not at steps {bad[:5]}; "
            "learn with a larger reg_covar"
        )

    return message


class Constraints:
    """Generalized constraints of a skill over its whole time grid, with precomputed precisions.

    Parameters
    ----------
    t : array-like, shape (T,)
        Time of each step.
    joint_mean : array-like, shape (T, n)
        theta_hat: expected joint angles (GMR of the joint-space GMM).
    joint_cov : array-like, shape (T, n, n)
        Sigma^theta: their covariance (positive definite).
    task_mean : dict str -> array-like, shape (T, 3) or (T, 6)
        x_hat^(n): expected hand position relative to object n: x - o(n) for a position-only
        constraint (T, 3); for an oriented one (T, 6), the hand's position in the object's
        frame R^T (x - p), then the hand's orientation relative to the object as a rotation
        vector r in the tangent space at ``rotation_base[n]`` = M: R^T R_hand = exp([r]x) M
        (left, object axes: :mod:`pbdkit._rotations`).
    task_cov : dict str -> array-like, shape (T, 3, 3) or (T, 6, 6)
        Sigma^x(n): its covariance (positive definite). Same keys and sizes as ``task_mean``.
    gripper : array-like, shape (T,), optional
        Generalized gripper signal (GMR of the gripper column of the joint-space GMM).
    rotation_base : dict str -> array-like, shape (3, 3), optional
        M for every oriented constraint (the demonstrations' mean relative orientation), and
        only for those.

    Attributes
    ----------
    names : list of str
        ``["joint", *task names]``.
    joint_prec : ndarray, shape (T, n, n)
        (Sigma^theta)^-1.
    joint_eta : ndarray, shape (T, n)
        (Sigma^theta)^-1 theta_hat.
    task_prec : dict str -> ndarray, shape (T, 3, 3) or (T, 6, 6)
        (Sigma^x(n))^-1.
    oriented : list of str
        The oriented constraints (those of ``rotation_base``).
    """

    def __init__(
        self,
        t: npt.ArrayLike,
        joint_mean: npt.ArrayLike,
        joint_cov: npt.ArrayLike,
        task_mean: Mapping[str, npt.ArrayLike],
        task_cov: Mapping[str, npt.ArrayLike],
        gripper: npt.ArrayLike | None = None,
        rotation_base: Mapping[str, npt.ArrayLike] | None = None,
    ) -> None:
        self.t = check_array(t, "t", ndim=1, min_rows=2)
        n_steps = self.t.shape[0]
        self.joint_mean = check_array(joint_mean, "joint_mean", shape=(n_steps, None))
        n = self.joint_mean.shape[1]
        self.joint_cov = check_array(joint_cov, "joint_cov", shape=(n_steps, n, n))
        if set(task_mean) != set(task_cov):
            raise ValueError(
                f"task_mean and task_cov must have the same keys, got {sorted(task_mean)} "
                f"and {sorted(task_cov)}"
            )
        if JOINT in task_mean:
            raise ValueError(
                f"task_mean: {short(JOINT)} is reserved for the joint-space constraint"
            )
        bases = {} if rotation_base is None else dict(rotation_base)
        unknown = [k for k in bases if k not in task_mean]
        if unknown:
            raise ValueError(f"rotation_base: {unknown} are not task constraints")
        self.rotation_base: dict[str, Float] = {}
        for k, m in bases.items():
            self.rotation_base[k] = check_rotation(m, f"rotation_base[{short(k)}]")
        dims = {k: 6 if k in bases else 3 for k in task_mean}
        self.task_mean = {
            k: check_array(v, f"task_mean[{short(k)}]", shape=(n_steps, dims[k]))
            for k, v in task_mean.items()
        }
        self.task_cov = {
            k: check_array(task_cov[k], f"task_cov[{short(k)}]", shape=(n_steps, dims[k], dims[k]))
            for k in task_mean
        }
        self.oriented: list[str] = [k for k in task_mean if k in bases]
        self.gripper = (
            None if gripper is None else check_array(gripper, "gripper", shape=(n_steps,))
        )
        linv = inverse_cholesky_factor(
            self.joint_cov, message=_not_positive_definite_at("joint_cov")
        )
        self.joint_prec: Float = np.swapaxes(linv, -1, -2) @ linv
        self.joint_eta: Float = np.einsum("tij,tj->ti", self.joint_prec, self.joint_mean)
        self.task_prec: dict[str, Float] = {}
        for k, cov in self.task_cov.items():
            li = inverse_cholesky_factor(
                cov, message=_not_positive_definite_at(f"task_cov[{short(k)}]")
            )
            self.task_prec[k] = np.swapaxes(li, -1, -2) @ li

    @property
    def n_steps(self) -> int:
        """T."""
        return int(self.t.shape[0])

    @property
    def n_joints(self) -> int:
        """n."""
        return int(self.joint_mean.shape[1])

    @property
    def object_names(self) -> list[str]:
        """Names of the task-space constraints (objects)."""
        return list(self.task_mean)

    @property
    def names(self) -> list[str]:
        """``["joint", *object names]``."""
        return [JOINT, *self.task_mean]

    def position_cov(self, name: str) -> Float:
        """The covariance (T, 3, 3) of the position part of task constraint ``name`` (in the
        object's frame for an oriented constraint)."""
        return self.task_cov[name][:, :3, :3]

    def world_task(self, name: str, placement: Float) -> WorldTask:
        """Task constraint ``name`` in the robot's base frame for the object at ``placement``
        (a position (3,), or a 4x4 pose for an oriented constraint; see :class:`WorldTask`).

        Position-only: target o + x_hat, precision P. Oriented, with the object's pose
        (R, p) and x_hat = [m ; r]: target position p + R m, target orientation R exp([r]x) M;
        the covariance of the world error [x - target ; log(R_hand R_target^T)] is
        B S B^T with B = blockdiag(R, R J_l(r)) (:mod:`pbdkit._rotations`: the left error
        of the object's axes is R times it in the world; J_l carries the tangent space at M to
        the one at the mean), so the precision is B^-T S^-1 B^-1
        (:func:`pbdkit.prob._frames.precision_to_world`, the frame code of
        :class:`pbdkit.FrameModel`).
        """
        mean = self.task_mean[name]
        if name not in self.rotation_base:
            pos = placement[:3, 3] if placement.shape == (4, 4) else placement
            return WorldTask(pos + mean, None, self.task_prec[name])
        rot, p = placement[:3, :3], placement[:3, 3]
        local = exp_map(mean[:, 3:])
        b = np.zeros((self.n_steps, 6, 6))
        b[:, :3, :3] = rot
        b[:, 3:, 3:] = rot @ left_jacobian(mean[:, 3:])
        return WorldTask(
            p + mean[:, :3] @ rot.T,
            rot @ local @ self.rotation_base[name],
            precision_to_world(b, self.task_prec[name]),
        )


@dataclass(frozen=True)
class WorldTask:
    """A task constraint in the robot's base frame, over the time grid
    (:meth:`Constraints.world_task`).

    Attributes
    ----------
    position : ndarray, shape (T, 3)
        Where the constraint expects the hand.
    rotation : ndarray, shape (T, 3, 3), or None
        The hand orientation it expects (oriented constraints only).
    precision : ndarray, shape (T, 3, 3) or (T, 6, 6)
        Of the error x - position, or of [x - position ; log(R_hand rotation^T)].
    """

    position: Float
    rotation: Float | None
    precision: Float
