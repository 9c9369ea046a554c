"""The joint space's covariance widened where left-out demonstrations fall outside it, per moment.

The product of Gaussians weighs every space by its precision, so a joint model confident where
the demonstrated postures were not wins where it should yield to the objects' constraints
(``docs/math.md``, "Calibration"). Learning measures it: the joint space's GMM keeps, for every
fitted row, the normalized residual z of its demonstration against the model fitted without it
(:mod:`pbdkit.prob._calibration`). Per step of the skill's grid,

    c(t) = clip(smooth(mean over demonstrations of z(t)), 1, CALIBRATION_MAX)

(a moving average over :data:`CALIBRATION_WINDOW` of the duration, linear in between the fitted
steps) and the GMR covariance of the joints at step t is c(t) times the fitted one: its mean is
unchanged. A model is widened, never narrowed. A skill file may hold factors for any space
(:func:`check_calibration`); learning writes the joints' only.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from .._validation import check_array, short

__all__ = [
    "CALIBRATION_MAX",
    "CALIBRATION_WINDOW",
    "check_calibration",
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
    """c(t) on the whole grid (module docstring): (n_steps,).

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
