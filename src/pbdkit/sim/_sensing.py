"""What the robot is told of a placement: the cameras' positions, or the truth with noise.

Vision in the loop (default of :func:`pbdkit.sim.evaluate`): the skill is told the
positions the stereo tracker measures (:mod:`pbdkit.sim._tracking`, calibrated once per
evaluation, :func:`calibrate_tracker`), while the simulated world keeps the true ones
(:func:`observe`); an object placed as a pose (the slot task's block and tray) is told as the
pose its two marks give. A placement whose objects the cameras cannot locate raises
:class:`pbdkit.sim._tracking.ObjectNotSeenError`; it never falls back to the true positions.
Without the cameras the skill is told the truth, with :func:`observation_noise` if asked.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._validation import short
from ._scene import Simulation
from ._task_skill import TaskSkill
from ._tasks import TaskSpec
from ._tracking import SimTracker, observed_objects

__all__ = ["calibrate_tracker", "observation_noise", "observe"]

Float = NDArray[np.float64]


def observe(
    spec: TaskSpec,
    truth: dict[str, Float],
    tracker: SimTracker,
    arm: npt.ArrayLike | None = None,
) -> dict[str, Float]:
    """Object positions the cameras give for a placement (fixed objects passed through).

    Builds the scene of the task ``spec`` with the objects at ``truth`` and the arm at ``arm``,
    runs one tracker cycle and closes the scene. The arm must be out of the cameras' way: a
    patch partly hidden gives a biased position, not a refusal (``bench_tracking.py``, arm at
    rest q = 0: up to 10.5 mm on the coaster and 32 mm on the glass on the table; none at a
    start posture).

    Parameters
    ----------
    spec : TaskSpec
        The task.
    truth : dict str -> ndarray, shape (3,) or (4, 4)
        True placements of the objects of the task (a posed object's pose); fixed ones may be
        left out (they are added from the task's ranges).
    tracker : SimTracker
        Calibrated on the task.
    arm : array-like, shape (n,), optional
        Arm joint angles while the cameras look (e.g.
        :attr:`pbdkit.sim.TaskSkill.start_posture`); default q = 0.

    Returns
    -------
    objects : dict str -> ndarray, shape (3,) or (4, 4)
        Every object of the task, whatever the skill constrains: tracked positions for the
        tracked objects (a posed object's tracked pose: :mod:`pbdkit.sim._tracking`), the true
        ones for the others (fixed objects, known without vision).

    Raises
    ------
    ObjectNotSeenError
        If a tracked object is not located.
    """
    truth = spec.full_placement(truth)
    sim = Simulation.from_task(spec, truth)
    try:
        if arm is not None:
            sim.set_joints(arm)
        fixed = {k: v for k, v in truth.items() if k not in tracker.objects}
        seen = observed_objects(sim, tracker, fixed)
    finally:
        sim.close()
    return {k: seen[k] for k in truth}


def calibrate_tracker(ts: TaskSkill) -> SimTracker:
    """The stereo tracker of a task, calibrated on its nominal placement with the arm at the
    skill's start posture (where it waits while the cameras look;
    :attr:`pbdkit.sim.TaskSkill.start_posture`)."""
    calib = Simulation.from_task(ts.task, ts.task.nominal_objects())
    try:
        return SimTracker.from_simulation(calib, at_nominal=False, arm=ts.start_posture)
    finally:
        calib.close()


def observation_noise(
    task: TaskSpec, objects: dict[str, Float], noise_mm: float, *, seed: int, index: int
) -> dict[str, Float]:
    """``objects`` with Gaussian noise on the moving objects, of mean 3-D length ``noise_mm``
    (see :func:`pbdkit.sim._trials.run_trial`), drawn from ``seed`` and ``index``; a pose's
    position gets the noise, its orientation is kept."""
    if not (noise_mm >= 0.0 and math.isfinite(noise_mm)):
        raise ValueError(f"noise_mm must be a finite number >= 0, got {short(noise_mm)}")
    rng = np.random.default_rng([seed, 3, index])
    sd = 1e-3 * noise_mm / math.sqrt(8.0 / math.pi)
    moving = set(task.tracked_objects)
    out: dict[str, Float] = {}
    for k, v in objects.items():
        if k not in moving:
            out[k] = v
        elif v.shape == (4, 4):
            out[k] = v.copy()
            out[k][:3, 3] += rng.normal(0.0, sd, 3)
        else:
            out[k] = v + rng.normal(0.0, sd, 3)
    return out
