"""What the experiment measures: a run's summary (the task's metrics, the arm's speeds and the
servo stream's peaks over the limits) and the statistics of the cameras' tracking errors: in
position (mm, every tracked object) and in yaw (degrees, the objects placed as poses)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..data._placement import position_of
from ..motion._limits import MotionPeaks
from ._execute import ExecutionResult, stream_peaks

__all__ = [
    "following_error",
    "peak_speed_ratio",
    "run_summary",
    "servo_peaks",
    "tracking_errors",
    "tracking_summary",
    "yaw_errors",
    "yaw_summary",
]

Float = NDArray[np.float64]


def following_error(
    execution: ExecutionResult, exclude: tuple[float, float] | None = None
) -> float:
    """Largest distance (rad) of a measured joint angle from the servo reference (recorded
    samples): a real drive faults beyond its following-error limit. ``exclude`` as
    :func:`peak_speed_ratio`."""
    err = np.abs(execution.joints - execution.targets).max(axis=1)
    if exclude is not None:
        t = execution.t
        err = err[(t < exclude[0]) | (t > exclude[1])]
    return float(err.max()) if err.size else 0.0


def peak_speed_ratio(
    execution: ExecutionResult,
    velocity_limit: Float,
    exclude: tuple[float, float] | None = None,
) -> float:
    """Largest measured joint speed over the velocity limits (recorded samples, 50 Hz).

    ``exclude``: a window of run time (s) left out, where an external force drives the arm
    (:meth:`pbdkit.sim.Disturbance.force_window`).
    """
    dq = np.abs(np.diff(execution.joints, axis=0)) / np.diff(execution.t)[:, None]
    ratio = (dq / velocity_limit).max(axis=1) if dq.size else np.zeros(0)
    if exclude is not None:
        t = execution.t[1:]
        ratio = ratio[(t < exclude[0]) | (execution.t[:-1] > exclude[1])]
    return float(ratio.max()) if ratio.size else 0.0


def servo_peaks(
    execution: ExecutionResult, exclude: tuple[float, float] | None = None
) -> MotionPeaks:
    """Peak velocity, acceleration and jerk of what the servos were sent (every physics step,
    from the trajectory's start to the end of the settling time) over the arm's limits: a real
    drive refuses a setpoint stream beyond them.

    ``exclude``: a window of run time (s) left out, as :func:`peak_speed_ratio` (the
    setpoints restart from the arm where a push moved it). Without, the peaks the run
    recorded (:attr:`pbdkit.sim.ExecutionResult.servo_peaks`).
    """
    if exclude is None:
        return execution.servo_peaks
    return stream_peaks(
        execution.servo_targets, execution.servo_period, execution.servo_limits, exclude
    )


def run_summary(
    execution: ExecutionResult,
    velocity_limit: Float | None,
    exclude: tuple[float, float] | None = None,
) -> dict[str, Any]:
    out: dict[str, Any] = {"success": bool(execution.outcome.success)}
    out.update({k: _finite(v) for k, v in execution.outcome.metrics.items()})
    if velocity_limit is not None:
        ratio = peak_speed_ratio(execution, velocity_limit, exclude)
        out["peak_speed_ratio"] = _finite(ratio)
    out["following_error_rad"] = _finite(following_error(execution, exclude))
    out.update({k: _finite(v) for k, v in servo_peaks(execution, exclude).as_dict().items()})
    return out


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def tracking_errors(
    observed: dict[str, Float], truth: dict[str, Float], names: Sequence[str]
) -> dict[str, float]:
    """3-D distance (mm) between observed and true positions of the objects ``names`` (the
    position of a pose)."""
    return {
        k: 1e3 * float(np.linalg.norm(position_of(observed[k]) - position_of(truth[k])))
        for k in names
    }


def yaw_errors(
    observed: dict[str, Float], truth: dict[str, Float], names: Sequence[str]
) -> dict[str, float]:
    """Yaw error (degrees, absolute, wrapped to [0, 180]) between observed and true poses of
    the objects ``names`` that are poses in both (others are left out)."""
    out: dict[str, float] = {}
    for k in names:
        a, b = observed[k], truth[k]
        if a.shape == (4, 4) and b.shape == (4, 4):
            d = math.atan2(float(a[1, 0]), float(a[0, 0])) - math.atan2(
                float(b[1, 0]), float(b[0, 0])
            )
            out[k] = abs(math.degrees(math.remainder(d, 2 * math.pi)))
    return out


def tracking_summary(errors: Sequence[dict[str, float]]) -> dict[str, Any] | None:
    """Mean and standard deviation (mm) of tracking errors, pooled and per object.

    Parameters
    ----------
    errors : sequence of dict str -> float
        One dict per observed placement (from :func:`tracking_errors`).

    Returns
    -------
    summary : dict or None
        ``{"mean", "std", "max", "n", "per_object": {name: {"mean", "std", "max", "n"}}}``;
        None when nothing was observed.
    """

    return _summary(errors, "std")


def yaw_summary(errors: Sequence[dict[str, float]]) -> dict[str, Any] | None:
    """Mean and standard deviation (degrees) of yaw errors, pooled and per object.

    Parameters
    ----------
    errors : sequence of dict str -> float
        One dict per observed placement (from :func:`yaw_errors`: the posed objects only).

    Returns
    -------
    summary : dict or None
        ``{"mean", "sd", "max", "n", "per_object": {name: {"mean", "sd", "max", "n"}}}``
        (``"sd"``: the population standard deviation, as ``tracking_summary``'s ``"std"``);
        None when no posed object was observed.
    """

    return _summary(errors, "sd")


def _summary(errors: Sequence[dict[str, float]], sd_key: str) -> dict[str, Any] | None:
    """Pooled and per-object mean, standard deviation (population, under ``sd_key``), max and
    count of per-placement errors; None when there are none."""

    def stats(v: NDArray[np.float64]) -> dict[str, Any]:
        return {"mean": float(v.mean()), sd_key: float(v.std()), "max": float(v.max()), "n": len(v)}

    pooled = np.array([e for row in errors for e in row.values()], dtype=np.float64)
    if pooled.size == 0:
        return None
    names = list(dict.fromkeys(k for row in errors for k in row))
    per = {k: stats(np.array([row[k] for row in errors if k in row])) for k in names}
    return {**stats(pooled), "per_object": per}
