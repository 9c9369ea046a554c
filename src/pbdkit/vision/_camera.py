"""Pinhole cameras (no lens distortion) and their calibration from a calibration object.

Conventions
-----------
OpenCV convention throughout: a world point X (3,) is seen at camera coordinates
``x_c = R X + t`` (R world->camera rotation); the camera looks along +z_c, x_c to the right of the
image, y_c down. Pixel coordinates (u, v) = (column, row) with the centre of the top-left pixel at
(0, 0); ``[u, v, 1]^T ~ K x_c``.

MuJoCo and OpenGL cameras look along -z with y up (x right). A camera frame given that way
(MuJoCo's ``cam_xmat`` reshaped to (3, 3): columns are the camera's axes in world coordinates)
converts with ``R = diag(1, -1, -1) @ R_world_from_cam.T``; :meth:`PinholeCamera.from_fovy` does it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray
from scipy.linalg import rq

from .._validation import check_array, check_int, check_positive_float, short

__all__ = ["PinholeCamera", "calibrate_camera", "calibrate_intrinsics"]

Float = NDArray[np.float64]

_CV_FROM_GL = np.diag([1.0, -1.0, -1.0])


def _check_size(width: object, height: object) -> tuple[int, int]:
    return check_int(width, "width", minimum=1), check_int(height, "height", minimum=1)


def _check_image_size(image_size: object) -> tuple[int, int]:
    if not isinstance(image_size, (tuple, list)) or len(image_size) != 2:
        raise ValueError(f"image_size must be (width, height), got {short(image_size)}")
    return _check_size(image_size[0], image_size[1])


def _check_rotation(r: Float, name: str) -> Float:
    err = float(np.abs(r @ r.T - np.eye(3)).max())
    if err > 1e-6 or np.linalg.det(r) < 0:
        raise ValueError(
            f"{name} must be a rotation matrix (orthonormal, det +1), got |R R^T - I| = {err:.2e} "
            f"and det = {np.linalg.det(r):.3f}"
        )
    return r


def _rotation_from_rotvec(rotvec: Float) -> Float:
    r, _ = cv2.Rodrigues(rotvec.reshape(3, 1))
    return np.asarray(r, dtype=np.float64)


class PinholeCamera:
    """A calibrated pinhole camera.

    Parameters
    ----------
    K : array-like, shape (3, 3)
        Intrinsic matrix, upper triangular with K[2, 2] = 1.
    R : array-like, shape (3, 3)
        World -> camera rotation (OpenCV axes: +z forward, y down).
    t : array-like, shape (3,)
        World -> camera translation: ``x_c = R X + t``.
    width, height : int
        Image size in pixels (the paper's webcams: 320 x 240).

    Attributes
    ----------
    K, R, t : ndarray, shapes (3, 3), (3, 3), (3,)
        As given (read-only: build a new camera, e.g. with :meth:`perturbed`, to change them).
    projection_matrix : ndarray, shape (3, 4)
        ``P = K [R | t]``.
    width, height : int
    """

    def __init__(
        self, K: npt.ArrayLike, R: npt.ArrayLike, t: npt.ArrayLike, width: int, height: int
    ) -> None:
        k = check_array(K, "K", shape=(3, 3)).copy()  # copies: made read-only below
        if abs(k[2, 2] - 1.0) > 1e-9 or np.any(k[[1, 2, 2], [0, 0, 1]] != 0.0):
            raise ValueError(f"K must be upper triangular with K[2, 2] = 1, got {k.tolist()}")
        if k[0, 0] <= 0 or k[1, 1] <= 0:
            raise ValueError(f"K must have positive focal lengths, got fx={k[0, 0]}, fy={k[1, 1]}")
        self.K = k
        self.R = _check_rotation(check_array(R, "R", shape=(3, 3)), "R").copy()
        self.t = check_array(t, "t", shape=(3,)).copy()
        self.width, self.height = _check_size(width, height)
        self.projection_matrix: Float = self.K @ np.hstack([self.R, self.t[:, None]])
        for arr in (self.K, self.R, self.t, self.projection_matrix):
            arr.setflags(write=False)  # P is derived from K, R, t: keep them consistent

    def __repr__(self) -> str:
        c = self.center
        return (
            f"PinholeCamera({self.width}x{self.height}, fx={self.K[0, 0]:.1f}, "
            f"fy={self.K[1, 1]:.1f}, center=[{c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}])"
        )

    @property
    def center(self) -> Float:
        """Optical centre in world coordinates, shape (3,): ``-R^T t``."""
        return np.asarray(-self.R.T @ self.t)

    @property
    def image_size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    @classmethod
    def from_fovy(
        cls,
        fovy_deg: float,
        width: int,
        height: int,
        position: npt.ArrayLike,
        *,
        R_world_from_cam: npt.ArrayLike | None = None,
        look_at: npt.ArrayLike | None = None,
        up: npt.ArrayLike = (0.0, 0.0, 1.0),
    ) -> PinholeCamera:
        """Camera from a vertical field of view and a pose, as MuJoCo and OpenGL define them.

        Square pixels, principal point at the image centre ((width - 1)/2, (height - 1)/2 in the
        pixel-centre convention): ``fy = fx = (height / 2) / tan(fovy / 2)``.

        Parameters
        ----------
        fovy_deg : float
            Vertical field of view in degrees (MuJoCo's ``cam_fovy``), in (0, 180).
        width, height : int
            Image size in pixels.
        position : array-like, shape (3,)
            Optical centre in world coordinates (MuJoCo's ``cam_xpos``).
        R_world_from_cam : array-like, shape (3, 3), optional
            OpenGL-style camera frame: columns are the camera's right (x), up (y) and backward (z)
            axes in world coordinates; the camera looks along -z. MuJoCo's
            ``data.cam_xmat[i].reshape(3, 3)`` is exactly this.
        look_at : array-like, shape (3,), optional
            Instead of ``R_world_from_cam``: the world point on the optical axis.
        up : array-like, shape (3,)
            World direction that appears upwards in the image, with ``look_at``.

        Returns
        -------
        camera : PinholeCamera
        """
        fovy = check_positive_float(fovy_deg, "fovy_deg")
        if not fovy < 180.0:
            raise ValueError(f"fovy_deg must be in (0, 180), got {short(fovy_deg)}")
        w, h = _check_size(width, height)
        c = check_array(position, "position", shape=(3,))
        if (R_world_from_cam is None) == (look_at is None):
            raise ValueError("give exactly one of R_world_from_cam and look_at")
        if R_world_from_cam is not None:
            r_gl = _check_rotation(
                check_array(R_world_from_cam, "R_world_from_cam", shape=(3, 3)), "R_world_from_cam"
            )
        else:
            target = check_array(np.asarray(look_at), "look_at", shape=(3,))
            u = check_array(up, "up", shape=(3,))
            back = c - target
            if np.linalg.norm(back) == 0:
                raise ValueError("look_at must differ from position")
            z = back / np.linalg.norm(back)
            x = np.cross(u, z)
            if np.linalg.norm(x) < 1e-9:
                raise ValueError("up must not be parallel to the viewing direction")
            x /= np.linalg.norm(x)
            r_gl = np.column_stack([x, np.cross(z, x), z])
        f = 0.5 * h / math.tan(math.radians(fovy) / 2.0)
        k = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        r = _CV_FROM_GL @ r_gl.T
        return cls(k, r, -r @ c, w, h)

    def project(self, points: npt.ArrayLike) -> Float:
        """Pixel coordinates of world points.

        Parameters
        ----------
        points : array-like, shape (N, 3)
            World points.

        Returns
        -------
        uv : ndarray, shape (N, 2)
            (u, v) pixel coordinates; NaN for points at or behind the camera plane.
        """
        x = check_array(points, "points", shape=(None, 3))
        p = x @ self.projection_matrix[:, :3].T + self.projection_matrix[:, 3]
        z = p[:, 2:3]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.where(z > 0, p[:, :2] / np.where(z > 0, z, 1.0), np.nan)
        return np.asarray(uv)

    def depth(self, points: npt.ArrayLike) -> Float:
        """Depth z_c of world points along the optical axis, shape (N,) for points (N, 3)."""
        x = check_array(points, "points", shape=(None, 3))
        return np.asarray(x @ self.R[2] + self.t[2])

    def perturbed(
        self,
        translation: float | npt.ArrayLike = 0.0,
        rotation_deg: float | npt.ArrayLike = 0.0,
        rng: np.random.Generator | int | None = None,
    ) -> PinholeCamera:
        """A copy with a pose error, for sensitivity studies (same intrinsics).

        Parameters
        ----------
        translation : float or array-like, shape (3,)
            Displacement of the optical centre in world coordinates (metres): a vector, or a
            length applied along a random direction drawn from ``rng``.
        rotation_deg : float or array-like, shape (3,)
            Rotation of the camera about its optical centre: a rotation vector in the camera
            frame (degrees), or an angle applied about a random axis drawn from ``rng``.
        rng : numpy Generator or int, optional
            Source of the random directions (``np.random.default_rng(rng)``).

        Returns
        -------
        camera : PinholeCamera
            Its centre is ``center + translation`` and its rotation ``R_delta @ R``.
        """
        gen = np.random.default_rng(rng)
        dc = _vector_or_random(translation, "translation", gen)
        drot = np.radians(_vector_or_random(rotation_deg, "rotation_deg", gen))
        r = _rotation_from_rotvec(drot) @ self.R
        c = self.center + dc
        return PinholeCamera(self.K, r, -r @ c, self.width, self.height)

    def as_dict(self) -> dict[str, Any]:
        """Plain-data form (lists of floats), for JSON or ``np.savez`` files; no pickle."""
        return {
            "K": self.K.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "width": self.width,
            "height": self.height,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PinholeCamera:
        """Inverse of :meth:`as_dict`; validates every field."""
        if not isinstance(data, dict):
            raise ValueError(f"data must be a dict from PinholeCamera.as_dict, got {type(data)}")
        missing = {"K", "R", "t", "width", "height"} - set(data)
        if missing:
            raise ValueError(f"data is missing keys {sorted(missing)} (from PinholeCamera.as_dict)")
        return cls(data["K"], data["R"], data["t"], data["width"], data["height"])


def _vector_or_random(value: float | npt.ArrayLike, name: str, rng: np.random.Generator) -> Float:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        mag = check_positive_float(float(arr), name, allow_zero=True)
        d = rng.normal(size=3)
        return np.asarray(mag * d / np.linalg.norm(d))
    return check_array(arr, name, shape=(3,))


# -- calibration ------------------------------------------------------------------------------

_FIXED_DISTORTION = (
    cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
)


def calibrate_camera(
    object_points: npt.ArrayLike,
    image_points: npt.ArrayLike,
    image_size: tuple[int, int],
    K: npt.ArrayLike | None = None,
) -> PinholeCamera:
    """Camera pose (and intrinsics) from one view of a calibration object of known geometry.

    With ``K``: the pose by ``cv2.solvePnP`` (iterative, >= 4 points; planar objects work).
    Without: a normalized DLT (>= 6 non-coplanar points) for the projection matrix, decomposed
    into K, R, t (RQ), then refined by ``cv2.calibrateCamera`` (reprojection error, zero skew, no
    distortion). For intrinsics from several views of a planar target, see
    :func:`calibrate_intrinsics` and pass its result here as ``K``.

    Parameters
    ----------
    object_points : array-like, shape (N, 3)
        The calibration object's points in world coordinates (metres).
    image_points : array-like, shape (N, 2)
        Where they are seen, (u, v) pixels.
    image_size : (width, height)
        Image size in pixels.
    K : array-like, shape (3, 3), optional
        Known intrinsics.

    Returns
    -------
    camera : PinholeCamera
    """
    x = check_array(object_points, "object_points", shape=(None, 3))
    uv = check_array(image_points, "image_points", shape=(x.shape[0], 2))
    w, h = _check_image_size(image_size)
    if K is not None:
        k = check_array(K, "K", shape=(3, 3))
        if x.shape[0] < 4:
            raise ValueError(f"object_points must have at least 4 points with K, got {x.shape[0]}")
        ok, rvec, tvec = cv2.solvePnP(x, uv, k, None, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            raise ValueError("cv2.solvePnP failed; check that the points correspond one to one")
        r = _rotation_from_rotvec(np.asarray(rvec, dtype=np.float64))
        return PinholeCamera(k, r, np.asarray(tvec, dtype=np.float64).ravel(), w, h)
    if x.shape[0] < 6:
        raise ValueError(
            f"object_points must have at least 6 points to calibrate without K, got {x.shape[0]}"
        )
    sv = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
    if sv[2] < 1e-3 * sv[0]:
        raise ValueError(
            "object_points are coplanar: a DLT needs a non-planar calibration object; use "
            "calibrate_intrinsics with several views of a planar target, then pass K"
        )
    k0 = _decompose_projection(_dlt(x, uv))[0]  # extrinsics: re-estimated below
    k0[0, 1] = 0.0
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | _FIXED_DISTORTION
    _, k1, _, rvecs, tvecs = cv2.calibrateCamera(
        [x.astype(np.float32)], [uv.astype(np.float32)], (w, h), k0, np.zeros(5), flags=flags
    )
    r1 = _rotation_from_rotvec(np.asarray(rvecs[0], dtype=np.float64))
    return PinholeCamera(np.asarray(k1, dtype=np.float64), r1, np.ravel(tvecs[0]), w, h)


def calibrate_intrinsics(
    object_points: Sequence[npt.ArrayLike],
    image_points: Sequence[npt.ArrayLike],
    image_size: tuple[int, int],
) -> Float:
    """Intrinsics K from several views of a planar target (Zhang's method, ``cv2.calibrateCamera``).

    Parameters
    ----------
    object_points : sequence of array-like, each shape (N_i, 3)
        The target's points in its own frame (z = 0), one array per view; >= 3 views.
    image_points : sequence of array-like, each shape (N_i, 2)
        Where they are seen, (u, v) pixels.
    image_size : (width, height)
        Image size in pixels.

    Returns
    -------
    K : ndarray, shape (3, 3)
        Zero skew; lens distortion is assumed absent (not estimated).
    """
    if len(object_points) != len(image_points) or len(object_points) < 3:
        raise ValueError(
            "object_points and image_points must be sequences of the same length >= 3 (views), "
            f"got {len(object_points)} and {len(image_points)}"
        )
    w, h = _check_image_size(image_size)
    objs, imgs = [], []
    for i, (o, p) in enumerate(zip(object_points, image_points, strict=True)):
        oi = check_array(o, f"object_points[{i}]", shape=(None, 3))
        objs.append(oi.astype(np.float32))
        pi = check_array(p, f"image_points[{i}]", shape=(oi.shape[0], 2))
        imgs.append(pi.astype(np.float32))
    _, k, _, _, _ = cv2.calibrateCamera(objs, imgs, (w, h), None, None, flags=_FIXED_DISTORTION)
    return np.asarray(k, dtype=np.float64)


def _dlt(x: Float, uv: Float) -> Float:
    """Normalized DLT (Hartley & Zisserman, Alg. 7.1): P (3, 4) with u ~ P [X; 1]."""
    mx, mu = x.mean(axis=0), uv.mean(axis=0)
    sx = math.sqrt(3.0) / np.sqrt(((x - mx) ** 2).sum(axis=1)).mean()
    su = math.sqrt(2.0) / np.sqrt(((uv - mu) ** 2).sum(axis=1)).mean()
    tx = np.diag([sx, sx, sx, 1.0])
    tx[:3, 3] = -sx * mx
    tu = np.diag([su, su, 1.0])
    tu[:2, 2] = -su * mu
    xn = (x - mx) * sx
    un = (uv - mu) * su
    n = x.shape[0]
    xh = np.hstack([xn, np.ones((n, 1))])
    a = np.zeros((2 * n, 12))
    a[0::2, 0:4] = xh
    a[0::2, 8:12] = -un[:, :1] * xh
    a[1::2, 4:8] = xh
    a[1::2, 8:12] = -un[:, 1:2] * xh
    _, _, vt = np.linalg.svd(a)
    pn = vt[-1].reshape(3, 4)
    return np.asarray(np.linalg.solve(tu, pn @ tx))


def _decompose_projection(p: Float) -> tuple[Float, Float, Float]:
    """P = s K [R | t] -> K (K[2,2] = 1, positive diagonal), R (det +1), t."""
    if np.linalg.det(p[:, :3]) < 0:
        p = -p
    k_raw, r_raw = rq(p[:, :3])
    d = np.diag(np.sign(np.diag(k_raw)))
    k: Float = np.asarray(k_raw @ d, dtype=np.float64)
    r: Float = np.asarray(d @ r_raw, dtype=np.float64)
    t: Float = np.asarray(np.linalg.solve(k, p[:, 3]), dtype=np.float64)
    return k / k[2, 2], r, t
