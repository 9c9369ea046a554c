"""Color model: a Gaussian in the CbCr plane of YCbCr (paper Section III).

Chroma is computed with the ITU-R BT.601 full-range (JPEG) transform, the one OpenCV's
``COLOR_RGB2YCrCb`` uses for 8-bit images, but in floating point (OpenCV's 8-bit output is
within 1 unit of it)::

    Cb = 128 - 0.168736 R - 0.331264 G + 0.5      B
    Cr = 128 + 0.5      R - 0.418688 G - 0.081312 B

Columns are ordered (Cb, Cr) everywhere in pbdkit (OpenCV's YCrCb orders Y, Cr, Cb).

What CbCr is and is not robust to: adding the same value to R, G and B (a change of brightness)
leaves Cb and Cr unchanged exactly, up to saturation at 0 and 255. Scaling R, G and B by a gain
``s`` (shading, exposure) scales the chroma around the neutral point: ``Cb - 128 -> s (Cb - 128)``.
Fit the model on pixels seen under the range of lighting it must handle (a labelled patch with
its shading), or raise the threshold.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import check_array, check_int, check_positive_float, short

__all__ = [
    "CBCR_FROM_RGB",
    "CBCR_OFFSET",
    "DEFAULT_MIN_CHROMA",
    "DEFAULT_THRESHOLD",
    "ColorModel",
    "cbcr_from_rgb",
    "check_image",
    "threshold_from_probability",
]

Float = NDArray[np.float64]

#: BT.601 full-range rows (Cb, Cr) applied to (R, G, B), shape (2, 3).
CBCR_FROM_RGB: Float = np.array(
    [[-0.168736, -0.331264, 0.5], [0.5, -0.418688, -0.081312]], dtype=np.float64
)
#: Offset of (Cb, Cr) for 8-bit images, shape (2,).
CBCR_OFFSET: Float = np.array([128.0, 128.0])
#: Pixels closer than this (CbCr units) to the neutral point are never a patch (ColorModel).
DEFAULT_MIN_CHROMA: float = 10.0


def threshold_from_probability(probability: float) -> float:
    """Squared Mahalanobis threshold holding ``probability`` of a 2-D Gaussian's mass.

    The squared Mahalanobis distance of a 2-D Gaussian sample is chi-square with 2 degrees of
    freedom, whose quantile has the closed form ``-2 log(1 - p)``.

    Parameters
    ----------
    probability : float
        In (0, 1), e.g. 0.99.

    Returns
    -------
    threshold : float
        0.99 gives 9.21.
    """
    p = check_positive_float(probability, "probability")
    if not p < 1.0:
        raise ValueError(f"probability must be in (0, 1), got {short(probability)}")
    return -2.0 * math.log1p(-p)


#: chi-square(2) quantile at 99%: a pixel is the model's color if d^2 <= 9.21.
DEFAULT_THRESHOLD: float = threshold_from_probability(0.99)


def check_image(
    image: object, name: str, *, size: tuple[int, int] | None = None
) -> NDArray[np.uint8]:
    """Check an 8-bit RGB image and return it C-contiguous.

    Parameters
    ----------
    image : ndarray of uint8, shape (height, width, 3)
        RGB, top row first.
    name : str
        The argument's name, used in error messages.
    size : (width, height), optional
        Required image size.

    Returns
    -------
    image : ndarray of uint8, shape (height, width, 3)
    """
    if not isinstance(image, np.ndarray):
        raise ValueError(
            f"{name} must be a numpy array of uint8 with shape (height, width, 3), "
            f"got {type(image).__name__}"
        )
    if image.dtype != np.uint8:
        raise ValueError(
            f"{name} must have dtype uint8 (8-bit RGB), got {image.dtype}; "
            "convert with np.clip(x, 0, 255).astype(np.uint8)"
        )
    if size is not None:
        want: tuple[int, ...] = (size[1], size[0], 3)
        if image.shape != want:
            raise ValueError(
                f"{name} must have shape (height, width, 3) = {want} to match its camera, "
                f"got {image.shape}"
            )
    elif image.ndim != 3 or image.shape[2] != 3 or image.shape[0] == 0 or image.shape[1] == 0:
        raise ValueError(f"{name} must have shape (height, width, 3), got {image.shape}")
    return np.ascontiguousarray(image)


def cbcr_from_rgb(image: object, *, dtype: npt.DTypeLike = np.float64) -> NDArray[Any]:
    """BT.601 full-range chroma (Cb, Cr) of an 8-bit RGB image.

    Parameters
    ----------
    image : ndarray of uint8, shape (height, width, 3)
        RGB image.
    dtype : dtype
        float64 (default) or float32 (the tracker's fast path).

    Returns
    -------
    cbcr : ndarray, shape (height, width, 2)
        Cb in channel 0, Cr in channel 1, in [0, 255].
    """
    img = check_image(image, "image")
    return _cbcr(img, np.dtype(dtype))


def _cbcr(img: NDArray[np.uint8], dtype: np.dtype[Any]) -> NDArray[Any]:
    h, w, _ = img.shape
    flat = img.reshape(-1, 3).astype(dtype)
    out = flat @ CBCR_FROM_RGB.T.astype(dtype)
    out += CBCR_OFFSET.astype(dtype)
    return np.asarray(out.reshape(h, w, 2))


class ColorModel:
    """A Gaussian N(mean, covariance) over (Cb, Cr) describing one patch color.

    A pixel has the model's color when its squared Mahalanobis distance to the Gaussian is at
    most a threshold AND its chroma is at least ``min_chroma`` away from the neutral point
    (128, 128). The second rule is not in the paper; it is needed because shading scales chroma
    towards neutral (``c - 128 -> s (c - 128)`` for a gain s), so a Gaussian fitted on a patch with
    its shadowed side reaches the neutral point, and every gray or black surface then matched
    (measured on a MuJoCo render of a dim red band on a glass: the dark-gray arm did). Gray,
    white and black pixels carry no hue; they are never a colored patch.

    Build it with :meth:`fit` from labelled images, or directly from a mean and covariance.

    Parameters
    ----------
    mean : array-like, shape (2,)
        Mean (Cb, Cr).
    covariance : array-like, shape (2, 2)
        Symmetric positive-definite covariance.
    n_samples : int
        Number of pixels the model was fitted on (0 when built directly).
    min_chroma : float
        Pixels with ``|(Cb, Cr) - (128, 128)| < min_chroma`` are never this color (0: no rule).

    Attributes
    ----------
    mean : ndarray, shape (2,)
    covariance : ndarray, shape (2, 2)
    precision : ndarray, shape (2, 2)
        Inverse covariance, computed once (through a Cholesky factor).
    n_samples : int
    min_chroma : float
    """

    def __init__(
        self,
        mean: npt.ArrayLike,
        covariance: npt.ArrayLike,
        *,
        n_samples: int = 0,
        min_chroma: float = DEFAULT_MIN_CHROMA,
    ) -> None:
        self.mean = check_array(mean, "mean", shape=(2,)).copy()
        cov = check_array(covariance, "covariance", shape=(2, 2)).copy()
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-12):
            raise ValueError(f"covariance must be symmetric, got {cov.tolist()}")
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError as exc:
            raise ValueError(
                f"covariance must be positive definite, got {cov.tolist()}; "
                "build the model with ColorModel.fit(..., min_std=...) to floor its spread"
            ) from exc
        self.covariance = cov
        inv_chol = np.linalg.solve(chol, np.eye(2))
        self.precision: Float = inv_chol.T @ inv_chol
        for arr in (self.mean, self.covariance, self.precision):
            arr.setflags(write=False)  # the precision is derived: keep them consistent
        self.n_samples = check_int(n_samples, "n_samples", minimum=0)
        self.min_chroma = check_positive_float(min_chroma, "min_chroma", allow_zero=True)

    def __repr__(self) -> str:
        std = np.sqrt(np.diag(self.covariance))
        return (
            f"ColorModel(mean=[{self.mean[0]:.2f}, {self.mean[1]:.2f}], "
            f"std=[{std[0]:.2f}, {std[1]:.2f}], n_samples={self.n_samples}, "
            f"min_chroma={self.min_chroma:g})"
        )

    @classmethod
    def fit(
        cls,
        image: object,
        mask: object,
        *,
        min_std: float = 2.0,
        min_chroma: float = DEFAULT_MIN_CHROMA,
    ) -> ColorModel:
        """Fit the Gaussian to the CbCr values of the labelled pixels of calibration images.

        Parameters
        ----------
        image : ndarray of uint8, shape (height, width, 3), or a list of them
            RGB calibration image(s). Several images taken under different lighting give a
            model that covers that lighting (pixels are pooled).
        mask : ndarray of bool, shape (height, width), or a list of them (one per image)
            True on the pixels of the patch.
        min_std : float
            Floor on the standard deviation along every direction, in CbCr units (the covariance's
            eigenvalues are raised to at least ``min_std**2``), so that a flat-colored patch or a
            tiny mask cannot give a singular or overconfident model.
        min_chroma : float
            Labelled pixels closer than this to the neutral point (highlights, deep shadow) are
            left out of the fit, and the model never matches such pixels (see the class doc).

        Returns
        -------
        model : ColorModel
        """
        if isinstance(image, (list, tuple)):
            if not isinstance(mask, (list, tuple)) or len(mask) != len(image) or not image:
                got = len(mask) if isinstance(mask, (list, tuple)) else type(mask).__name__
                raise ValueError(
                    f"mask must be a list of one mask per image ({len(image)}), got {got}"
                )
            pairs = [
                (f"image[{i}]", im, f"mask[{i}]", m)
                for i, (im, m) in enumerate(zip(image, mask, strict=True))
            ]
        else:
            pairs = [("image", image, "mask", mask)]
        samples = []
        for iname, im, mname, m in pairs:
            img = check_image(im, iname)
            sel = _check_mask(m, img.shape[:2], mname)
            samples.append(_cbcr(img, np.dtype(np.float64))[sel])
        return cls.from_samples(np.concatenate(samples), min_std=min_std, min_chroma=min_chroma)

    @classmethod
    def from_samples(
        cls,
        cbcr: npt.ArrayLike,
        *,
        min_std: float = 2.0,
        min_chroma: float = DEFAULT_MIN_CHROMA,
    ) -> ColorModel:
        """Fit the Gaussian to chroma samples.

        Parameters
        ----------
        cbcr : array-like, shape (N, 2)
            (Cb, Cr) values, N >= 1.
        min_std : float
            Floor on the standard deviation, as in :meth:`fit`.
        min_chroma : float
            Samples closer than this to (128, 128) are left out, as in :meth:`fit`.

        Returns
        -------
        model : ColorModel
        """
        x = check_array(cbcr, "cbcr", shape=(None, 2), min_rows=1)
        floor = check_positive_float(min_std, "min_std")
        mc = check_positive_float(min_chroma, "min_chroma", allow_zero=True)
        keep = ((x - CBCR_OFFSET) ** 2).sum(axis=1) >= mc**2
        if not keep.any():
            raise ValueError(
                f"all {x.shape[0]} labelled pixels are achromatic (chroma within "
                f"min_chroma={mc:g} of the neutral point 128, 128): gray, white or black; "
                "use a colored patch, light it better, or lower min_chroma"
            )
        x = x[keep]
        mean = x.mean(axis=0)
        d = x - mean
        cov = d.T @ d / x.shape[0]  # maximum-likelihood covariance
        return cls(mean, _floor_eigenvalues(cov, floor**2), n_samples=x.shape[0], min_chroma=mc)

    def mahalanobis2(self, image: object) -> Float:
        """Squared Mahalanobis distance of every pixel's chroma to the model.

        Parameters
        ----------
        image : ndarray of uint8, shape (height, width, 3)
            RGB image.

        Returns
        -------
        d2 : ndarray, shape (height, width)
            ``(c - mean)^T Sigma^-1 (c - mean)`` with ``c`` the pixel's (Cb, Cr).
        """
        img = check_image(image, "image")
        return _mahalanobis2(_cbcr(img, np.dtype(np.float64)), self.mean, self.precision)

    def classify(self, image: object, threshold: float = DEFAULT_THRESHOLD) -> NDArray[np.bool_]:
        """Pixels of the model's color: ``d^2 <= threshold`` and chroma >= ``min_chroma``.

        Parameters
        ----------
        image : ndarray of uint8, shape (height, width, 3)
            RGB image.
        threshold : float
            On the squared distance; the default is the 99% quantile of chi-square(2), 9.21.

        Returns
        -------
        mask : ndarray of bool, shape (height, width)
        """
        thr = check_positive_float(threshold, "threshold")
        img = check_image(image, "image")
        cbcr = _cbcr(img, np.dtype(np.float64))
        out = _mahalanobis2(cbcr, self.mean, self.precision) <= thr
        if self.min_chroma > 0:
            out &= ((cbcr - CBCR_OFFSET) ** 2).sum(axis=-1) >= self.min_chroma**2
        return np.asarray(out)

    def as_dict(self) -> dict[str, Any]:
        """Plain-data form (lists of floats), for JSON or ``np.savez`` files; no pickle."""
        return {
            "mean": self.mean.tolist(),
            "covariance": self.covariance.tolist(),
            "n_samples": self.n_samples,
            "min_chroma": self.min_chroma,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ColorModel:
        """Inverse of :meth:`as_dict`; validates every field."""
        if not isinstance(data, dict):
            raise ValueError(f"data must be a dict from ColorModel.as_dict, got {type(data)}")
        missing = {"mean", "covariance"} - set(data)
        if missing:
            raise ValueError(
                f"data must have keys 'mean' and 'covariance' (from ColorModel.as_dict), "
                f"missing {sorted(missing)}"
            )
        return cls(
            data["mean"],
            data["covariance"],
            n_samples=data.get("n_samples", 0),
            min_chroma=data.get("min_chroma", DEFAULT_MIN_CHROMA),
        )


def _check_mask(mask: object, hw: tuple[int, ...], name: str) -> NDArray[np.bool_]:
    if not isinstance(mask, np.ndarray):
        raise ValueError(f"{name} must be a numpy bool array of shape {hw}, got {type(mask)}")
    if mask.shape != hw:
        raise ValueError(
            f"{name} must have the image's shape (height, width) = {hw}, got {mask.shape}"
        )
    if mask.dtype != np.bool_:
        raise ValueError(f"{name} must have dtype bool, got {mask.dtype}; use mask.astype(bool)")
    count = int(np.count_nonzero(mask))
    if count == 0:
        raise ValueError(
            f"{name} must label at least one pixel of the patch, got an empty mask (0 pixels); "
            "check that the patch is in the calibration image"
        )
    return mask


def _floor_eigenvalues(cov: Float, floor: float) -> Float:
    """Raise the eigenvalues of a symmetric (2, 2) matrix to at least ``floor``."""
    w, v = np.linalg.eigh(cov)
    w = np.maximum(w, floor)
    out = (v * w) @ v.T
    return np.asarray(0.5 * (out + out.T), dtype=np.float64)


def _mahalanobis2(cbcr: NDArray[Any], mean: Float, precision: Float) -> NDArray[Any]:
    """Vectorized d^2 = p00 dx^2 + 2 p01 dx dy + p11 dy^2 over an image, shape (H, W)."""
    dt = cbcr.dtype
    dx = cbcr[..., 0] - dt.type(mean[0])
    dy = cbcr[..., 1] - dt.type(mean[1])
    d2 = dx * dx
    d2 *= dt.type(precision[0, 0])
    cross = dx * dy
    cross *= dt.type(2.0 * precision[0, 1])
    d2 += cross
    dy *= dy
    dy *= dt.type(precision[1, 1])
    d2 += dy
    return np.asarray(d2)
