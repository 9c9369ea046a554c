"""The paper's experiment in simulation, its public names in one place.

Teach, learn, reproduce for new placements, execute, judge; each concern has its module:

- :mod:`pbdkit.learning.naming`: the controllers by name (``"fused"``, ``"joint"``,
  ``"task:OBJECT"``);
- :mod:`pbdkit.sim.task_skill`: a task's skill (:class:`TaskSkill`, :func:`learn_task`, which
  objects get a constraint);
- :mod:`pbdkit.sim.runs`: one controller's run, offline or online;
- :mod:`pbdkit.sim.metrics`: what a run and the cameras measure;
- :mod:`pbdkit.sim.sensing`: what the skill is told (the cameras, or the truth with noise);
- :mod:`pbdkit.sim.trials`: every controller at a placement, serially or on Dask workers;
- :mod:`pbdkit.sim.evaluation`: the success rates over new placements (:func:`evaluate`).

This module re-exports their public names, where they have always been importable from
(``from pbdkit.sim import experiment as E``).
"""

from __future__ import annotations

from ..learning.naming import controller_names, controller_use
from .evaluation import ControllerStats, Evaluation, evaluate, summarize
from .metrics import (
    following_error,
    peak_speed_ratio,
    servo_peaks,
    tracking_errors,
    tracking_summary,
)
from .runs import ControllerRun, OnlineControllerRun, run_controller, run_online
from .sensing import calibrate_tracker, observation_noise, observe
from .task_skill import TaskSkill, constrained_objects, learn_task, start_posture
from .trials import (
    ControllerOutcome,
    Trial,
    TrialObservation,
    assemble_trial,
    observe_trial,
    run_trial,
    run_trial_controller,
    run_trials,
    trial_disturbance,
)

__all__ = [
    "ControllerOutcome",
    "ControllerRun",
    "ControllerStats",
    "Evaluation",
    "OnlineControllerRun",
    "TaskSkill",
    "Trial",
    "TrialObservation",
    "assemble_trial",
    "calibrate_tracker",
    "constrained_objects",
    "controller_names",
    "controller_use",
    "evaluate",
    "following_error",
    "learn_task",
    "observation_noise",
    "observe",
    "observe_trial",
    "peak_speed_ratio",
    "run_controller",
    "run_online",
    "run_trial",
    "run_trial_controller",
    "run_trials",
    "servo_peaks",
    "start_posture",
    "summarize",
    "tracking_errors",
    "tracking_summary",
    "trial_disturbance",
]
