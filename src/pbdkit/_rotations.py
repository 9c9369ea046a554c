"""Rotations and poses: the exponential map of SO(3), its Jacobians, means and fusion.

Conventions (used everywhere in pbdkit):

- A rotation vector r (3,) is the axis times the angle (rad); :func:`exp_map` gives the rotation
  matrix R = exp([r]x), :func:`log_map` the rotation vector of a matrix, with angle in [0, pi].
- Quaternions are **(qw, qx, qy, qz), w first**: pytransform3d's convention. ROS messages
  (``geometry_msgs/Quaternion``) and scipy's ``Rotation.from_quat`` use (x, y, z, w).
- A pose is a 4x4 homogeneous transform [[R, p], [0, 0, 0, 1]], or (x, y, z, qw, qx, qy, qz).
- Orientation errors are on the **left**, in the axes the rotation is expressed in:
  R = exp([e]x) R_ref, e = log(R R_ref^T).

The maps (t = |r|; Barfoot, *State Estimation for Robotics*, 2017, ch. 7):

    exp([r]x) = I + (sin t / t) [r]x + ((1 - cos t) / t^2) [r]x^2              (Rodrigues)
    J_l(r)    = I + ((1 - cos t) / t^2) [r]x + ((t - sin t) / t^3) [r]x^2
    J_l(r)^-1 = I - [r]x / 2 + (1 / t^2 - (1 + cos t) / (2 t sin t)) [r]x^2
    de/dq     = J_l(e)^-1 J_w(q)          (e = log(R R_ref^T), omega = J_w(q) dq)

Why errors on the left, the derivatives, the Karcher mean and the product of pose Gaussians:
``docs/math.md``, "Rotations and tangent spaces". Everything is batched over leading dimensions
and pure NumPy.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from ._validation import short

__all__ = [
    "as_pose",
    "check_rotation",
    "exp_map",
    "fuse_poses",
    "left_jacobian",
    "left_jacobian_inverse",
    "left_jacobian_inverse3",
    "log3",
    "log_map",
    "matrix_from_quaternion",
    "mean_rotation",
    "pose_matrix",
    "quaternion_from_matrix",
    "skew",
    "wrap_angle",
    "yaw_of",
]

Float = NDArray[np.float64]
#: Largest deviation of a given rotation matrix from orthonormal (max |R^T R - I|) that
#: :func:`as_pose` accepts (and re-orthonormalizes); beyond it the matrix is refused.
ORTHONORMAL_TOLERANCE = 1e-4
_SMALL = 1e-6  # rad: below it the series expansions are used


def yaw_of(pose: npt.ArrayLike) -> float:
    """The yaw (rad) of a pose's (4x4) or a rotation's (3x3) x axis about the vertical, in
    (-pi, pi]."""
    m = np.asarray(pose)
    return math.atan2(float(m[1, 0]), float(m[0, 0]))


def wrap_angle(angle: npt.ArrayLike) -> Float:
    """Angles (rad) wrapped into [-pi, pi)."""
    return np.asarray((np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi)


def skew(r: npt.ArrayLike) -> Float:
    """[r]x: the (..., 3, 3) cross-product matrices of vectors r (..., 3)."""
    v = np.asarray(r, dtype=np.float64)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _coefficients(theta: Float) -> tuple[Float, Float, Float]:
    """sin(t)/t, (1 - cos t)/t^2, (t - sin t)/t^3, with their series near 0."""
    small = theta < _SMALL
    t = np.where(small, 1.0, theta)
    t2 = t * t
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(t) / t)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t2)
    c = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (t - np.sin(t)) / (t2 * t))
    return a, b, c


def exp_map(r: npt.ArrayLike) -> Float:
    """Rotation matrices exp([r]x) (..., 3, 3) of rotation vectors r (..., 3) (Rodrigues)."""
    v = np.asarray(r, dtype=np.float64)
    theta = np.linalg.norm(v, axis=-1)
    a, b, _ = _coefficients(theta)
    k = skew(v)
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def quaternion_from_matrix(rot: npt.ArrayLike) -> Float:
    """Unit quaternions (qw, qx, qy, qz), w >= 0, of rotation matrices (..., 3, 3).

    Shepperd's method: the largest of the four candidate denominators is used, so the result
    is accurate at every angle, including pi.
    """
    m = np.asarray(rot, dtype=np.float64)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    tr = np.trace(m, axis1=1, axis2=2)
    diag = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    choice = np.argmax(diag, axis=1)
    q = np.empty((m.shape[0], 4))
    for i in range(m.shape[0]):
        r = m[i]
        c = choice[i]
        if c == 0:
            s = 2.0 * math.sqrt(max(1.0 + tr[i], 0.0))
            q[i] = (
                0.25 * s,
                (r[2, 1] - r[1, 2]) / s,
                (r[0, 2] - r[2, 0]) / s,
                (r[1, 0] - r[0, 1]) / s,
            )
        elif c == 1:
            s = 2.0 * math.sqrt(max(1.0 + r[0, 0] - r[1, 1] - r[2, 2], 0.0))
            q[i] = (
                (r[2, 1] - r[1, 2]) / s,
                0.25 * s,
                (r[0, 1] + r[1, 0]) / s,
                (r[0, 2] + r[2, 0]) / s,
            )
        elif c == 2:
            s = 2.0 * math.sqrt(max(1.0 + r[1, 1] - r[0, 0] - r[2, 2], 0.0))
            q[i] = (
                (r[0, 2] - r[2, 0]) / s,
                (r[0, 1] + r[1, 0]) / s,
                0.25 * s,
                (r[1, 2] + r[2, 1]) / s,
            )
        else:
            s = 2.0 * math.sqrt(max(1.0 + r[2, 2] - r[0, 0] - r[1, 1], 0.0))
            q[i] = (
                (r[1, 0] - r[0, 1]) / s,
                (r[0, 2] + r[2, 0]) / s,
                (r[1, 2] + r[2, 1]) / s,
                0.25 * s,
            )
    q[q[:, 0] < 0] *= -1.0
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(*shape, 4)


#: Quaternions whose largest absolute component is in this range are normalized by their norm
#: directly; the others (whose norm would overflow or underflow) are divided by that component
#: first.
_UNSCALED = (1e-100, 1e100)


def matrix_from_quaternion(q: npt.ArrayLike) -> Float:
    """Rotation matrices (..., 3, 3) of quaternions (qw, qx, qy, qz) (..., 4), normalized first
    (divided by their largest absolute component, then by their norm: a finite quaternion of
    any magnitude, 1e200 or 1e-300, gives its rotation; a zero one gives NaN)."""
    v = np.asarray(q, dtype=np.float64)
    # The norm of 1e200 overflows (and of 1e-200 underflows): those are scaled first; the
    # others are not, so that their rotations stay the same to the bit.
    scale = np.max(np.abs(v), axis=-1, keepdims=True)
    if np.any((scale > _UNSCALED[1]) | (scale < _UNSCALED[0])):
        v = np.where((scale > _UNSCALED[1]) | (scale < _UNSCALED[0]), v / scale, v)
    v = v / np.linalg.norm(v, axis=-1, keepdims=True)
    w, x, y, z = v[..., 0], v[..., 1], v[..., 2], v[..., 3]
    out = np.empty((*v.shape[:-1], 3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - w * z)
    out[..., 0, 2] = 2 * (x * z + w * y)
    out[..., 1, 0] = 2 * (x * y + w * z)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - w * x)
    out[..., 2, 0] = 2 * (x * z - w * y)
    out[..., 2, 1] = 2 * (y * z + w * x)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def log_map(rot: npt.ArrayLike) -> Float:
    """Rotation vectors (..., 3), angle in [0, pi], of rotation matrices (..., 3, 3).

    Through the quaternion (:func:`quaternion_from_matrix`): r = 2 atan2(s, w) v / s with
    s = norm(v), exact near 0 and near pi, where arccos of the trace loses its digits.
    """
    q = quaternion_from_matrix(rot)
    w, v = q[..., 0], q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(s, w)
    # angle / s -> 2 / w as s -> 0 (w -> 1).
    factor = np.where(s < 1e-12, 2.0 / np.where(w == 0, 1.0, w), angle / np.where(s == 0, 1.0, s))
    return np.asarray(factor[..., None] * v, dtype=np.float64)


def left_jacobian(r: npt.ArrayLike) -> Float:
    """J_l(r) (..., 3, 3): exp([r + dr]x) = exp([J_l(r) dr]x) exp([r]x) to first order."""
    v = np.asarray(r, dtype=np.float64)
    theta = np.linalg.norm(v, axis=-1)
    _, b, c = _coefficients(theta)
    k = skew(v)
    return np.eye(3) + b[..., None, None] * k + c[..., None, None] * (k @ k)


def left_jacobian_inverse(r: npt.ArrayLike) -> Float:
    """J_l(r)^-1 (..., 3, 3), in closed form (angles below pi)."""
    v = np.asarray(r, dtype=np.float64)
    theta = np.linalg.norm(v, axis=-1)
    small = theta < 1e-4
    t = np.where(small, 1.0, theta)
    # 1/t^2 - (1 + cos t) / (2 t sin t); its series 1/12 + t^2/720 near 0.
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(
            small, 1.0 / 12.0 + theta**2 / 720.0, 1.0 / t**2 - (1 + np.cos(t)) / (2 * t * np.sin(t))
        )
    k = skew(v)
    return np.asarray(np.eye(3) - 0.5 * k + d[..., None, None] * (k @ k), dtype=np.float64)


def pose_matrix(position: npt.ArrayLike, rotation: npt.ArrayLike | None = None) -> Float:
    """The 4x4 transform [[R, p], [0, 0, 0, 1]] (identity R when ``rotation`` is None)."""
    out = np.eye(4)
    out[:3, 3] = np.asarray(position, dtype=np.float64)
    if rotation is not None:
        out[:3, :3] = np.asarray(rotation, dtype=np.float64)
    return out


def _real_array(value: object, wanted: str) -> Float:
    """``value`` as a float64 array, or a ValueError "<wanted>, got ...": not numbers, or
    complex ones (the conversion would drop their imaginary part with a warning only)."""
    try:
        dtype = np.asarray(value).dtype
        arr = np.array(value, dtype=np.float64) if dtype.kind != "c" else None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{wanted}, got {short(value)}") from exc
    if arr is None:
        raise ValueError(f"{wanted} of real numbers, got complex values (dtype {dtype})")
    return arr


def as_pose(value: object, name: str = "pose") -> tuple[Float, Float | None]:
    """Read an object's placement: a position, or a pose with orientation.

    Parameters
    ----------
    value : array-like
        A position (3,) (m); a 4x4 homogeneous transform [[R, p], [0, 0, 0, 1]]; or
        (x, y, z, qw, qx, qy, qz), the quaternion **w first** (pytransform3d's convention; a
        ROS message's quaternion is (x, y, z, w): reorder it). The quaternion is normalized;
        a rotation matrix within :data:`ORTHONORMAL_TOLERANCE` of orthonormal is
        re-orthonormalized (one orthonormal to 1e-12 is kept as given), and must have
        determinant +1.
    name : str
        The argument's name, for errors.

    Returns
    -------
    position : ndarray, shape (3,)
    rotation : ndarray, shape (3, 3), or None for a position
    """
    arr = _real_array(
        value, f"{name} must be a position (3,), a 4x4 transform or (x, y, z, qw, qx, qy, qz)"
    )
    if arr.shape not in ((3,), (4, 4), (7,)):
        raise ValueError(
            f"{name} must be a position (3,), a 4x4 transform or (x, y, z, qw, qx, qy, qz) "
            f"(quaternion w first), got an array of shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    if arr.shape == (3,):
        return arr, None
    if arr.shape == (7,):
        return arr[:3].copy(), _quaternion_rotation(arr[3:], name)
    if np.max(np.abs(arr[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-9:
        raise ValueError(
            f"{name}: a 4x4 transform's last row must be [0, 0, 0, 1], got {arr[3].tolist()}"
        )
    rot = arr[:3, :3]
    # Entries of 1e200 overflow R^T R and det to inf or NaN: refused by the negated tests.
    with np.errstate(over="ignore", invalid="ignore"):
        dev = float(np.max(np.abs(rot.T @ rot - np.eye(3))))
        det = float(np.linalg.det(rot))
    if not (dev <= ORTHONORMAL_TOLERANCE and det > 0):
        raise ValueError(
            f"{name}: the rotation block of a 4x4 transform must be a rotation matrix "
            f"(orthonormal, determinant +1); it is off by {dev:.3g} with determinant "
            f"{det:.3g}"
        )
    if dev <= 1e-12:  # orthonormal to rounding: kept as given (files round-trip exactly)
        return arr[:3, 3].copy(), rot.copy()
    u, _, vt = np.linalg.svd(rot)
    return arr[:3, 3].copy(), np.asarray(u @ vt, dtype=np.float64)


def _quaternion_rotation(q: Float, name: str) -> Float:
    """The rotation matrix of a finite quaternion (qw, qx, qy, qz) of :func:`as_pose`, or a
    ValueError: a norm below 1e-9 is zero. Its norm is taken after dividing by the largest
    absolute component, so that (1e200, 0, 0, 0) is the identity, not the NaN of an
    overflowed norm."""
    scale = float(np.max(np.abs(q)))
    unit = q / scale if scale > 0 and not _UNSCALED[0] <= scale <= _UNSCALED[1] else q
    norm = float(np.linalg.norm(unit))
    size = norm if unit is q else scale * norm  # a Python float: 1e308 * 2 is inf, no warning
    if not size >= 1e-9:
        raise ValueError(f"{name}: the quaternion (qw, qx, qy, qz) = {q.tolist()} has zero norm")
    rot = matrix_from_quaternion(unit / norm)
    if not np.all(np.isfinite(rot)):  # cannot happen for a finite unit quaternion: a guard
        raise ValueError(
            f"{name}: the quaternion (qw, qx, qy, qz) = {q.tolist()} gives no rotation"
        )
    return rot


def check_rotation(value: object, name: str = "rotation") -> Float:
    """A rotation matrix (3, 3), checked as :func:`as_pose` checks a 4x4's rotation block
    (finite, orthonormal within :data:`ORTHONORMAL_TOLERANCE`, determinant +1) and
    re-orthonormalized."""
    arr = _real_array(value, f"{name} must be a rotation matrix (3, 3)")
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must be a rotation matrix (3, 3), got shape {arr.shape}")
    _, rot = as_pose(pose_matrix(np.zeros(3), arr), name)
    assert rot is not None
    return rot


def mean_rotation(rotations: npt.ArrayLike, weights: npt.ArrayLike | None = None) -> Float:
    """The (weighted) Karcher mean of rotation matrices (M, 3, 3): the rotation R minimizing
    sum_i w_i norm(log(R_i R^T))^2, from the chordal mean (the projection of sum_i w_i R_i onto
    SO(3)) by Gauss-Newton. Unique for rotations within a ball of radius pi/2."""
    rs = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    w = np.ones(rs.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    u, _, vt = np.linalg.svd(np.einsum("i,ijk->jk", w, rs))
    mean = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    for _ in range(50):
        step = np.einsum("i,ij->j", w, log_map(rs @ mean.T))
        mean = exp_map(step) @ mean
        if float(np.linalg.norm(step)) < 1e-13:
            break
    return np.asarray(mean)


def fuse_poses(
    means: npt.ArrayLike, covariances: npt.ArrayLike, max_iter: int = 50
) -> tuple[Float, Float]:
    """The product of pose Gaussians: the pose that best agrees with all of them.

    Each Gaussian i is a pose T_i = (R_i, p_i) with a 6x6 covariance S_i of the error
    [p - p_i ; log(R R_i^T)] (position first, then orientation on the left in world axes: the
    module's convention). The fused pose minimizes sum_i r_i^T S_i^-1 r_i by Gauss-Newton on
    the perturbation [dp ; dphi] (R <- exp([dphi]x) R, d log(R R_i^T) = J_l(e_i)^-1 dphi); its
    covariance is the inverse of the Gauss-Newton information sum_i G_i^T S_i^-1 G_i at the
    optimum.

    Parameters
    ----------
    means : array-like, shape (P, 4, 4)
    covariances : array-like, shape (P, 6, 6)
        Symmetric positive definite.

    Returns
    -------
    mean : ndarray, shape (4, 4)
    covariance : ndarray, shape (6, 6)
    """
    ts = np.asarray(means, dtype=np.float64)
    covs = np.asarray(covariances, dtype=np.float64)
    if ts.ndim != 3 or ts.shape[1:] != (4, 4) or covs.shape != (ts.shape[0], 6, 6):
        raise ValueError(
            f"means must be (P, 4, 4) and covariances (P, 6, 6), got {ts.shape} and {covs.shape}"
        )
    precs = np.linalg.inv(covs)
    rots, pos = ts[:, :3, :3], ts[:, :3, 3]
    # Start from the product of the position parts and the precision-weighted mean rotation.
    p_prec = np.linalg.inv(covs[:, :3, :3])
    p = np.linalg.solve(p_prec.sum(axis=0), np.einsum("pij,pj->i", p_prec, pos))
    r_weights = np.array([1.0 / np.trace(c[3:, 3:]) for c in covs])
    rot = mean_rotation(rots, r_weights)
    info = np.eye(6)
    for _ in range(max_iter):
        e = log_map(rot[None] @ np.swapaxes(rots, -1, -2))  # (P, 3)
        g = np.zeros((ts.shape[0], 6, 6))
        g[:, :3, :3] = np.eye(3)
        g[:, 3:, 3:] = left_jacobian_inverse(e)
        res = np.concatenate([p[None] - pos, e], axis=1)
        gt_p = np.swapaxes(g, -1, -2) @ precs
        info = np.einsum("pij,pjk->ik", gt_p, g)
        grad = np.einsum("pij,pj->i", gt_p, res)
        delta = -np.linalg.solve(info, grad)
        p = p + delta[:3]
        rot = exp_map(delta[3:]) @ rot
        if float(np.linalg.norm(delta)) < 1e-14:
            break
    cov = np.linalg.inv(info)
    return pose_matrix(p, rot), 0.5 * (cov + cov.T)


def log3(rot: Float) -> Float:
    """:func:`log_map` of one rotation matrix (3, 3), for control loops: a few scalar
    operations away from pi, the quaternion route near it."""
    tr = rot[0, 0] + rot[1, 1] + rot[2, 2]
    c = 0.5 * (tr - 1.0)
    vee: Float = np.array(
        [rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]], dtype=np.float64
    )
    if c > 0.99999999:  # angle below 1.4e-4 rad: sin(a) / a ~ 1 - a^2 / 6
        return np.asarray(0.5 * (1.0 + (1.0 - c) / 3.0) * vee, dtype=np.float64)
    if c > -0.999:
        angle = math.acos(c)
        return np.asarray((0.5 * angle / math.sin(angle)) * vee, dtype=np.float64)
    return np.asarray(log_map(rot), dtype=np.float64)


def left_jacobian_inverse3(r: Float) -> Float:
    """:func:`left_jacobian_inverse` of one rotation vector (3,), for control loops
    ([r]x^2 = r r^T - norm(r)^2 I)."""
    x, y, z = float(r[0]), float(r[1]), float(r[2])
    t2 = x * x + y * y + z * z
    if t2 < 1e-8:
        d = 1.0 / 12.0 + t2 / 720.0
    else:
        t = math.sqrt(t2)
        d = 1.0 / t2 - (1.0 + math.cos(t)) / (2.0 * t * math.sin(t))
    a = 1.0 - d * t2
    return np.array(
        [
            [a + d * x * x, d * x * y + 0.5 * z, d * x * z - 0.5 * y],
            [d * x * y - 0.5 * z, a + d * y * y, d * y * z + 0.5 * x],
            [d * x * z + 0.5 * y, d * y * z - 0.5 * x, a + d * z * z],
        ]
    )
