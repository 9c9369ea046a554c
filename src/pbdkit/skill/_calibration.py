"""The covariances widened where left-out demonstrations fall further outside one than another.

The product of Gaussians weighs every space by its precision, so a joint model confident where
the demonstrated postures were not wins where it should yield to the objects' constraints, and
an object's model confident where the placements made the demonstrations disagree wins where
the posture should (``docs/math.md``, "Calibration"). Learning measures it: every space's GMM
keeps, for every fitted row, the normalized residual z of its demonstration against the model
fitted without it (:mod:`pbdkit.prob._calibration`). Per space and step of the skill's grid,

    z_s(t) = clip(smooth(mean over demonstrations of z(t)), 1, CALIBRATION_MAX)

(a moving average over :data:`CALIBRATION_WINDOW` of the duration, linear in between the fitted
steps). The fused mean depends on the spaces' precisions relative to each other only. With
r(t) = z_joint(t) / min over objects of z_o(t) (the joints against the best-described object),

    c_joint(t) = clip(r(t), 1, CALIBRATION_MAX)          c_o(t) = clip(1 / r(t), 1, CALIBRATION_MAX)

the same c_o for every object, and the GMR covariance of each space at step t is c(t) times the
fitted one: its mean is unchanged. Where an object describes its left-out demonstrations
(z_o = 1) the joints are widened by their own z, as if alone; where every object is further off
than the joints, the objects are widened together, their balance among themselves kept. Nothing
is narrowed. A skill without objects: c_joint = z_joint. A skill file may hold factors for any
space (:func:`check_calibration`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from .._validation import check_array, short
from ..reproduction._constraints import JOINT

__all__ = [
    "CALIBRATION_MAX",
    "CALIBRATION_WINDOW",
    "check_calibration",
    "space_factors",
    "step_factors",
]

Float = NDArray[np.float64]

#: The largest factor a covariance is widened by (a standard deviation 100 times the fitted
#: one): past it the constraint is as good as absent already.
CALIBRATION_MAX = 1e4
#: The moving average's width, as a fraction of the duration: a left-out demonstration's
#: residuals are correlated over a few percent of it (one phase), and five demonstrations make
#: a noisy mean at a single step.
CALIBRATION_WINDOW = 0.05


def step_factors(z: Float, steps: NDArray[np.intp], n_demos: int, n_steps: int) -> Float:
    """One space's z_s(t) on the whole grid (module docstring): (n_steps,).

    Parameters
    ----------
    z : ndarray, shape (n_demos * len(steps),)
        The normalized residuals of the fitted rows, demonstration by demonstration, each at
        ``steps``.
    steps : ndarray of int, shape (S,)
        The fitted steps, increasing, in [0, n_steps).
    """
    per_step = z.reshape(n_demos, steps.shape[0]).mean(axis=0)
    width = max(1, round(CALIBRATION_WINDOW * steps.shape[0]))
    smooth = uniform_filter1d(per_step, width, mode="nearest")
    grid = np.interp(np.arange(n_steps, dtype=np.float64), steps.astype(np.float64), smooth)
    return np.asarray(np.clip(grid, 1.0, CALIBRATION_MAX), dtype=np.float64)


def space_factors(joint: Float, objects: Mapping[str, Float]) -> dict[str, Float]:
    """c(t) of every space (module docstring): (n_steps,) each, by name (``"joint"`` and the
    objects').

    Parameters
    ----------
    joint : ndarray, shape (n_steps,)
        The joints' :func:`step_factors`.
    objects : mapping str -> ndarray, shape (n_steps,)
        The objects' :func:`step_factors`; none: the joints' own factors alone.
    """
    if not objects:
        return {JOINT: joint}
    ratio = joint / np.min(np.stack(list(objects.values())), axis=0)
    widen = np.clip(1.0 / ratio, 1.0, CALIBRATION_MAX)
    return {
        JOINT: np.clip(ratio, 1.0, CALIBRATION_MAX),
        **{k: widen.copy() for k in objects},
    }


def check_calibration(
    calibration: Mapping[str, npt.ArrayLike] | None, names: list[str], n_steps: int
) -> dict[str, Float]:
    """Every space's factors, (n_steps,) each in [1, CALIBRATION_MAX]; ones where not given."""
    given = dict(calibration or {})
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise ValueError(f"calibration: {unknown} are not spaces of the skill ({names})")
    out: dict[str, Float] = {}
    for k in names:
        if k not in given:
            out[k] = np.ones(n_steps)
            continue
        c = check_array(given[k], f"calibration[{short(k)}]", shape=(n_steps,))
        if not np.all((c >= 1.0) & (c <= CALIBRATION_MAX)):
            raise ValueError(
                f"calibration[{short(k)}] must be in [1, {CALIBRATION_MAX:g}] at every step, got "
                f"values in [{short(float(c.min()))}, {short(float(c.max()))}]"
            )
        out[k] = c
    return out
