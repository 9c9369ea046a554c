"""The outcome of a reproduction (:class:`ReproductionResult`) and its file, the
``pbdkit-reproduction`` ``.npz`` archive (:meth:`ReproductionResult.save`,
:meth:`ReproductionResult.load`; its keys: :doc:`/reproduction`, "File formats")."""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._io import NpzArchive, check_format, open_npz, save_npz_atomic
from .._validation import short

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "ReproductionResult"]

Float = NDArray[np.float64]
#: The ``format`` and ``version`` of a reproduction's file. Version 1 is the layout `pbdkit
#: reproduce` always wrote; keys were added within it (the oriented constraints', the timing's,
#: then ``gripper_signal``, ``limited``, ``nominal_dt`` and ``joint_space_influence_NAME``), all
#: optional: a reader that looks keys up by name reads every file.
FORMAT_NAME = "pbdkit-reproduction"
FORMAT_VERSION = 1


@dataclass(frozen=True, eq=False)
class ReproductionResult:
    """Outcome of a reproduction.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Time of each step (steps 0 .. T-1 for a :class:`pbdkit.Skill`).
    joints : ndarray, shape (T, n)
        theta_j, within the joint limits.
    positions : ndarray, shape (T, 3)
        Hand positions x_j = f(theta_j) in the base frame.
    covariances : ndarray, shape (T, n, n)
        Covariance of the posture at each step: the fused Sigma_j of eq. (1) (information form)
        when the joint constraint is in use; Sigma^theta for the joint-only controller;
        J+ Sigma^x J+^T (rank 3) for task-only controllers.
    gripper : ndarray of bool, shape (T,)
        Generalized gripper signal > 0.5 (closed); all False if the skill has no gripper.
    gripper_signal : ndarray, shape (T,) or None
        The generalized (continuous) gripper signal, None if the skill has no gripper.
    influence : dict str -> ndarray, shape (T,)
        Share of each constraint in use in the hand's space (paper Fig. 6): tr(S P_n) / 3 for
        task constraint n, S = J Sigma J^T the hand's covariance, and 1 - their sum for the joint
        constraint. Each in [0, 1], summing to 1 at each step (:doc:`/reproduction`,
        "Influence of the constraints").
    influence_joint_space : dict str -> ndarray, shape (T,)
        Share of each constraint in joint space, tr(Sigma Lambda_c) / n, summing to 1: who
        governs the posture, including the directions the hand does not see (a task
        constraint's share is at most 3/n there). Task-only controllers: equal to ``influence``.
    task_errors : dict str -> ndarray, shape (T,)
        For every object (in use or not): ||x_j - (o(n) + x_hat^(n)_j)|| in metres, the distance
        from the hand to where that object's constraint expects it.
    used : tuple of str
        The constraints in use.
    limited : ndarray of bool, shape (T,)
        True at the steps j whose step theta_{j-1} -> theta_j was scaled down by ``step_limit``
        (the velocity limit) or ``max_step``; with motion limits (``limits``), the steps whose
        duration the limits stretched. False at step 0.
    times : ndarray, shape (T,), or None
        With motion limits: the time (s) of each sample, from 0, such that the samples played
        at these times respect the limits, starting and ending at rest (:doc:`/reproduction`,
        "Motion limits and lead-in"). None without them (:meth:`pbdkit.Skill.times` then
        spreads the steps over the skill's duration).
    velocities, accelerations : ndarray, shape (T, n), or None
        With motion limits: joint velocities and accelerations at the samples, from the timing
        (the derivatives of the cubic spline through the samples at ``times``, at rest at both
        ends; the lead-in's samples carry the time-optimal move's own, at rest where it
        arrives), e.g. for a ``JointTrajectory``.
    lead_in : ndarray of bool, shape (T,)
        True for the samples of the lead-in move from ``q0`` to the skill's first posture
        (their ``t`` is the first step's); all False without motion limits.
    nominal_dt : float
        With motion limits: the duration of a step at the demonstrations' pace (s); NaN
        without. :attr:`stretch` compares the timing with it.
    orientations : ndarray, shape (T, 3, 3), or None
        For a skill with oriented constraints: the hand's orientation R_hand at each sample
        (the tip frame's axes in the base frame, :meth:`pbdkit.Robot.fk_pose`); None for a
        skill of positions only.
    orientation_errors : dict str -> ndarray, shape (T,)
        For every oriented object (in use or not): the angle (rad) between the hand's
        orientation and the one its constraint expects, the norm of log(R_hand R_target^T).

    With motion limits the result has a sample per step of the skill plus the lead-in samples:
    T = L + n_steps. :meth:`save` writes it to a file, :meth:`load` reads it back.
    clearance : ndarray, shape (T,), or None
        With a scene (``scene=`` of :meth:`pbdkit.Skill.reproduce`): per sample, the smallest
        signed distance (m) between the arm, with what it carries, and the scene or itself
        (negative: a penetration); None without a scene.
    collisions : list of (int, str, str)
        With a scene: (sample, body, body) for every sample and pair in contact beyond the
        allowed ones (URDF link, shape and object names, sorted); empty when the run is free.
    infeasible : str or None
        With avoidance: why the run still collides (the first sample and bodies where the
        skill's constraints and the clearance cannot both hold); None when it is free.
    """

    t: Float
    joints: Float
    positions: Float
    covariances: Float
    gripper: NDArray[np.bool_]
    gripper_signal: Float | None
    influence: dict[str, Float]
    influence_joint_space: dict[str, Float]
    task_errors: dict[str, Float]
    used: tuple[str, ...]
    limited: NDArray[np.bool_]
    times: Float | None = None
    velocities: Float | None = None
    accelerations: Float | None = None
    lead_in: NDArray[np.bool_] | None = None
    nominal_dt: float = float("nan")
    orientations: Float | None = None
    orientation_errors: dict[str, Float] = dataclasses.field(default_factory=dict)
    clearance: Float | None = None
    collisions: list[tuple[int, str, str]] = dataclasses.field(default_factory=list)
    infeasible: str | None = None

    @property
    def stretch(self) -> float:
        """How much longer the motion limits made the skill's own part (after the lead-in)
        than the steps at their nominal duration: 1.0 where nothing was slowed; NaN without
        motion limits."""
        if self.times is None or self.lead_in is None:
            return float("nan")
        start = int(np.count_nonzero(self.lead_in))
        own = self.times[start:]
        nominal = self.nominal_dt * (own.shape[0] - 1)
        return float((own[-1] - own[0]) / nominal) if nominal > 0 else float("nan")

    def save(self, path: str | os.PathLike[str]) -> None:
        """Save the result to a ``pbdkit-reproduction`` ``.npz`` file (version 1), atomically and
        without pickle; :meth:`load` reads it back, every field equal.

        Parameters
        ----------
        path : str or path-like
            The file (replaced if it exists; a new one gets the mode the umask gives).

        Raises
        ------
        ValueError
            A NaN or inf in an array (naming the field and where), or a ``nominal_dt`` that is
            neither a positive number nor NaN (not known: the key is left out, as in a file
            from before it was stored): nothing is written.
        """
        _check_finite(self)
        save_npz_atomic(path, _arrays(self), what="ReproductionResult")

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ReproductionResult:
        """Load a result saved by :meth:`save` (or written by ``pbdkit reproduce --out``).

        Files written before a field was stored give its default: ``gripper_signal`` None,
        ``influence_joint_space`` empty, ``limited`` all False, ``nominal_dt`` NaN; ``used`` is
        the constraints of ``influence``.

        Parameters
        ----------
        path : str or path-like

        Returns
        -------
        result : ReproductionResult

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            A corrupt or foreign file, another format version, a key the format does not have,
            or arrays whose shapes or types do not fit together (the message names the path).
        """
        p = Path(path)
        with open_npz(p, what=f"{FORMAT_NAME} file") as data:
            check_format(data, p, FORMAT_NAME, FORMAT_VERSION)
            data.check_keys(_is_result_key)
            try:
                fields = _fields(data)
            except KeyError as exc:
                raise ValueError(
                    f"{p} is not a valid {FORMAT_NAME} file: missing key {exc}"
                ) from exc
            except ValueError as exc:
                raise ValueError(f"{p} is not a valid {FORMAT_NAME} file: {exc}") from exc
        return cls(**fields)


# The keys of a file: these, and one per constraint or object after each prefix.
_KEYS = frozenset(
    {
        "format",
        "version",
        "t",
        "joints",
        "positions",
        "gripper",
        "covariances",
        "orientations",
        "times",
        "velocities",
        "accelerations",
        "lead_in",
        "gripper_signal",
        "limited",
        "nominal_dt",
        "clearance",
        "collision_steps",
        "collision_bodies",
        "infeasible",
    }
)
_PREFIXES = {
    "influence": "influence_",
    "influence_joint_space": "joint_space_influence_",
    "task_errors": "task_error_",
    "orientation_errors": "orientation_error_",
}
_NAMED_KEY = re.compile("(?:" + "|".join(_PREFIXES.values()) + ").+")


def _is_result_key(key: str) -> bool:
    """Whether :meth:`ReproductionResult.save` may write ``key``."""
    return key in _KEYS or _NAMED_KEY.fullmatch(key) is not None


def _check_finite(res: ReproductionResult) -> None:
    """Every float array of a result to be saved finite, and ``nominal_dt`` a duration or NaN
    (not known: no timing, or a file from before it was stored); a ValueError naming the field
    otherwise."""
    for field in dataclasses.fields(res):
        value = getattr(res, field.name)
        items = value.items() if isinstance(value, dict) else [(None, value)]
        for key, arr in items:
            if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "fc":
                continue
            bad = ~np.isfinite(arr)
            if not bad.any():
                continue
            where = np.unravel_index(int(np.argmax(bad)), arr.shape)
            label = field.name if key is None else f"{field.name}[{short(key)}]"
            index = "".join(f"[{int(i)}]" for i in where)
            raise ValueError(
                f"{label}{index} is {short(arr[where].item())}: a reproduction's arrays must "
                "be finite; nothing written"
            )
    dt = res.nominal_dt
    if not (math.isnan(dt) or (math.isfinite(dt) and dt > 0)):
        raise ValueError(
            "nominal_dt must be a positive number of seconds (or NaN: not known, left out of "
            f"the file), got {short(dt)}; nothing written"
        )


def _arrays(res: ReproductionResult) -> dict[str, Any]:
    """The arrays of a result's file, by key; the keys of version 1 as `pbdkit reproduce`
    wrote them first, then those added since."""
    arrays: dict[str, Any] = {
        "format": np.array(FORMAT_NAME),
        "version": np.array(FORMAT_VERSION, dtype=np.int64),
        "t": res.t,
        "joints": res.joints,
        "positions": res.positions,
        "gripper": res.gripper,
        "covariances": res.covariances,
    }
    arrays.update({f"influence_{k}": v for k, v in res.influence.items()})
    arrays.update({f"task_error_{k}": v for k, v in res.task_errors.items()})
    if res.orientations is not None:
        arrays["orientations"] = res.orientations
    arrays.update({f"orientation_error_{k}": v for k, v in res.orientation_errors.items()})
    if res.times is not None and res.lead_in is not None:
        # Within the robot's motion limits: the timing (s), its derivatives, the lead-in.
        arrays.update(
            times=res.times,
            velocities=res.velocities,
            accelerations=res.accelerations,
            lead_in=res.lead_in,
        )
    if res.gripper_signal is not None:
        arrays["gripper_signal"] = res.gripper_signal
    arrays["limited"] = res.limited
    prefix = _PREFIXES["influence_joint_space"]
    arrays.update({f"{prefix}{k}": v for k, v in res.influence_joint_space.items()})
    if math.isfinite(res.nominal_dt):  # NaN (no timing): left out, as before it was stored
        arrays["nominal_dt"] = np.array(res.nominal_dt, dtype=np.float64)
    if res.clearance is not None:  # with a scene
        arrays["clearance"] = res.clearance
        arrays["collision_steps"] = np.array([c[0] for c in res.collisions], dtype=np.int64)
        arrays["collision_bodies"] = np.array(
            [c[1:] for c in res.collisions], dtype=np.str_
        ).reshape(-1, 2)
    if res.infeasible is not None:
        arrays["infeasible"] = np.array(res.infeasible, dtype=np.str_)
    return arrays


def _read(data: NpzArchive, key: str, shape: tuple[int, ...], kind: str = "f") -> NDArray[Any]:
    """The array ``key`` of a file, checked: its shape, and its type (``"f"``: float64, ``"b"``:
    bool)."""
    arr = data[key]
    dtype = np.dtype(np.float64) if kind == "f" else np.dtype(np.bool_)
    if arr.dtype != dtype or arr.shape != shape:
        raise ValueError(
            f"{key} must be {dtype} of shape {shape}, got {arr.dtype} of shape {arr.shape}"
        )
    return arr


def _named(data: NpzArchive, field: str, shape: tuple[int, ...]) -> dict[str, Float]:
    """The arrays of one field stored per constraint or object (``influence_NAME``, ...), in
    the file's order."""
    prefix = _PREFIXES[field]
    return {k[len(prefix) :]: _read(data, k, shape) for k in data if k.startswith(prefix)}


def _fields(data: NpzArchive) -> Mapping[str, Any]:
    """The fields of a :class:`ReproductionResult` from the arrays of its file."""
    t = data["t"]
    if t.dtype != np.float64 or t.ndim != 1 or t.shape[0] < 1:
        raise ValueError(f"t must be float64 of shape (T,), got {t.dtype} of shape {t.shape}")
    n_samples = t.shape[0]
    joints = data["joints"]
    if joints.ndim != 2:
        raise ValueError(f"joints must be float64 of shape (T, n), got shape {joints.shape}")
    n = joints.shape[1]
    joints = _read(data, "joints", (n_samples, n))
    influence = _named(data, "influence", (n_samples,))
    if not influence:
        raise ValueError("no influence_NAME key: a result has at least one constraint in use")
    timing = [k in data for k in ("times", "velocities", "accelerations")]
    if any(timing) and not all(timing):
        raise ValueError("times, velocities and accelerations go together")
    timed = all(timing)
    return {
        "t": t,
        "joints": joints,
        "positions": _read(data, "positions", (n_samples, 3)),
        "covariances": _read(data, "covariances", (n_samples, n, n)),
        "gripper": _read(data, "gripper", (n_samples,), "b"),
        "gripper_signal": (
            _read(data, "gripper_signal", (n_samples,)) if "gripper_signal" in data else None
        ),
        "influence": influence,
        "influence_joint_space": _named(data, "influence_joint_space", (n_samples,)),
        "task_errors": _named(data, "task_errors", (n_samples,)),
        "used": tuple(k for k in influence if k != "clearance"),
        "limited": (
            _read(data, "limited", (n_samples,), "b")
            if "limited" in data
            else np.zeros(n_samples, dtype=bool)
        ),
        "times": _read(data, "times", (n_samples,)) if timed else None,
        "velocities": _read(data, "velocities", (n_samples, n)) if timed else None,
        "accelerations": _read(data, "accelerations", (n_samples, n)) if timed else None,
        "lead_in": (
            _read(data, "lead_in", (n_samples,), "b")
            if "lead_in" in data
            else np.zeros(n_samples, dtype=bool)
        ),
        "nominal_dt": float(_read(data, "nominal_dt", ())) if "nominal_dt" in data else np.nan,
        "orientations": (
            _read(data, "orientations", (n_samples, 3, 3)) if "orientations" in data else None
        ),
        "orientation_errors": _named(data, "orientation_errors", (n_samples,)),
        **_collision_fields(data, n_samples),
    }


def _collision_fields(data: NpzArchive, n_samples: int) -> dict[str, Any]:
    """``clearance``, ``collisions`` and ``infeasible`` of a file (defaults without them)."""
    out: dict[str, Any] = {}
    if "clearance" in data:
        out["clearance"] = _read(data, "clearance", (n_samples,))
        steps, bodies = data["collision_steps"], data["collision_bodies"]
        if steps.dtype != np.int64 or steps.ndim != 1:
            raise ValueError(f"collision_steps must be int64 of shape (N,), got {steps.dtype}")
        if bodies.dtype.kind != "U" or bodies.shape != (steps.shape[0], 2):
            raise ValueError(
                f"collision_bodies must be strings of shape ({steps.shape[0]}, 2), got "
                f"{bodies.dtype} of shape {bodies.shape}"
            )
        if steps.size and not (int(steps.min()) >= 0 and int(steps.max()) < n_samples):
            raise ValueError(f"collision_steps must be samples in [0, {n_samples})")
        out["collisions"] = [
            (int(k), str(a), str(b)) for k, (a, b) in zip(steps, bodies, strict=True)
        ]
    if "infeasible" in data:
        note = data["infeasible"]
        if note.dtype.kind != "U" or note.shape != ():
            raise ValueError(f"infeasible must be a string, got {note.dtype} {note.shape}")
        out["infeasible"] = str(note)
    return out
