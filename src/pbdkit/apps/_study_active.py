"""Teaching where it fails, in simulation: ``pbdkit study --active`` (:doc:`/active`).

Three teachers start from the same 2 demonstrations of the task's teacher and give one more
demonstration at a time, at the same seeds, the skill updated after each
(:meth:`pbdkit.Skill.update`):

- **suggested**: where :meth:`pbdkit.Skill.suggest` says, inside the wide ranges;
- **random**: at random placements in the same ranges;
- **space-filling**: at the candidate placement farthest from those demonstrated (maximin over
  the ranges, each axis scaled by its range), which needs no model.

The wide ranges are :func:`pbdkit.sim._active.wide_ranges` (the study's wide grids' extent).
After each demonstration, the fused controller's success is measured under physics over the
wide grid of every moving object (:func:`pbdkit.apps._study.grid_placements`), told the true
positions, without the grid's points where a skill of
:data:`~pbdkit.sim._active.SPREAD_DEMOS` demonstrations spread over the ranges fails too
(geometry no teacher fixes; listed as ``"excluded"``). A teacher that cannot show the task at
its placement (out of the arm's reach) takes its next choice (up to 8), then a random one.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write_bytes, write_json
from .._validation import check_int, short
from ..data._demonstration import Demonstration
from ..prob import SelectionWarning
from ..sim._active import SPREAD_DEMOS, spread_placements, task_skill, teach_at, wide_ranges
from ..sim._task_skill import teach
from ..sim._tasks import PlacementRange, TaskSpec, yaw_of
from ..sim._trials import TrialConditions, run_trials
from ._study import grid_placements

__all__ = [
    "ACTIVE_FULL",
    "ACTIVE_SMALL",
    "TARGET",
    "TEACHERS",
    "ActiveSize",
    "needed",
    "run_active",
    "run_active_study",
    "split_grid",
]

Float = NDArray[np.float64]

#: The teachers compared, in the order of ``study.json``'s lists.
TEACHERS = ("suggested", "random", "space_filling")
#: The success over the grid a teacher must reach ("needed").
TARGET = 0.95
#: Candidate placements of the space-filling teacher.
FILLING_CANDIDATES = 256


@dataclass(frozen=True)
class ActiveSize:
    """How large an active study is.

    Attributes
    ----------
    grid : int
        Grid points per axis of each moving object's wide grid (>= 2).
    seeds : int
        Seeds compared (the study's seed and the next ones).
    max_demos : int
        Demonstrations each teacher gives in all, from the first 2 (>= 3).
    """

    grid: int
    seeds: int
    max_demos: int

    def __post_init__(self) -> None:
        check_int(self.grid, "ActiveSize.grid", minimum=2)
        check_int(self.seeds, "ActiveSize.seeds", minimum=1)
        check_int(self.max_demos, "ActiveSize.max_demos", minimum=3, maximum=50)


#: The default: at most 10 minutes on 2 cores (the basin's physics is the slowest: 7-8 min).
ACTIVE_SMALL = ActiveSize(grid=4, seeds=2, max_demos=5)
#: ``--full``: the issue's comparison (5 seeds), for a cluster.
ACTIVE_FULL = ActiveSize(grid=11, seeds=5, max_demos=12)


def needed(curve: list[float], n_demos: list[int], target: float = TARGET) -> int | None:
    """The first number of demonstrations whose success reaches ``target``, None if none."""
    for n, rate in zip(n_demos, curve, strict=True):
        if rate >= target:
            return n
    return None


def _median_needed(values: list[int | None]) -> float | None:
    """The median over seeds (a seed that never reaches the target counts as infinity); None
    where the median is infinite."""
    med = float(np.median([math.inf if v is None else v for v in values]))
    return None if math.isinf(med) else med


def _features(spec: TaskSpec, objects: dict[str, Any], wide: dict[str, PlacementRange]) -> Float:
    """A placement's coordinates scaled by the wide ranges (x, y, and yaw for a pose)."""
    out = []
    for name, r in wide.items():
        value = np.asarray(objects[name], dtype=np.float64)
        position = value[:3, 3] if value.shape == (4, 4) else value
        span = np.maximum(r.high - r.low, 1e-9)
        out += list(position[:2] / span[:2])
        if r.yaw is not None:
            out.append(yaw_of(value) / max(r.yaw[1] - r.yaw[0], 1e-9))
    return np.array(out)


class _Teacher:
    """One teacher's choices of where to demonstrate next."""

    def __init__(self, kind: str, spec: TaskSpec, seed: int) -> None:
        self.kind, self.spec = kind, spec
        self.wide = wide_ranges(spec)
        self.rng = np.random.default_rng([seed, 39, TEACHERS.index(kind)])
        self.seed = seed

    def choices(self, skill: Any, done: list[dict[str, Any]]) -> list[dict[str, Float]]:
        """Placements to try, best first."""
        if self.kind == "random":
            return self.random(8)
        if self.kind == "space_filling":
            cands = spread_placements(self.spec, FILLING_CANDIDATES, self.seed + len(done))
            have = np.array([_features(self.spec, d, self.wide) for d in done])
            gaps = [
                float(np.min(np.linalg.norm(have - _features(self.spec, c, self.wide), axis=1)))
                for c in cands
            ]
            return [cands[i] for i in np.argsort(gaps)[::-1][:8]]
        ranges = {
            k: {"low": r.low, "high": r.high, "yaw": r.yaw}
            for k, r in self.wide.items()
            if k in skill.object_names
        }
        nominal = self.spec.nominal_objects()
        return [{**nominal, **s.objects} for s in skill.suggest(ranges, n=8, seed=self.seed)]

    def random(self, n: int) -> list[dict[str, Float]]:
        """``n`` random placements in the wide ranges (the random teacher's choices, and every
        teacher's where its own could not be shown)."""
        nominal = self.spec.nominal_objects()
        return [
            {**nominal, **{k: r.sample(self.rng) for k, r in self.wide.items()}} for _ in range(n)
        ]


def split_grid(
    grid: list[dict[str, Float]], works: list[bool]
) -> tuple[list[dict[str, Float]], list[dict[str, list[Any]]]]:
    """The grid's points where the spread skill works (kept), and the others as JSON
    (excluded: no teacher fixes them)."""
    kept = [p for p, ok in zip(grid, works, strict=True) if ok]
    excluded = [
        {k: np.asarray(v).tolist() for k, v in p.items()}
        for p, ok in zip(grid, works, strict=True)
        if not ok
    ]
    return kept, excluded


def _first_shown(spec: TaskSpec, tries: list[dict[str, Float]], seed: int) -> Demonstration | None:
    """The teacher's demonstration at the first placement it can show the task at."""
    for objects in tries:
        new = teach_at(spec, [objects], seed)[0]
        if new is not None:
            return new
    return None


def _placement_of(demo: Demonstration) -> dict[str, Any]:
    return {k: np.asarray(v) for k, v in demo.objects.items()}


def run_active(
    spec: TaskSpec,
    *,
    size: ActiveSize = ACTIVE_SMALL,
    seed: int = 0,
    client: Any = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> dict[str, Any]:
    """The comparison of the module docstring: what ``study.json``'s ``"active"`` holds."""
    if not isinstance(size, ActiveSize):
        raise ValueError(f"size must be an ActiveSize, got {short(size)}")
    check_int(seed, "seed", minimum=0)
    grid: list[dict[str, Float]] = []
    for obj in spec.tracked_objects:
        grid += grid_placements(spec, obj, size.grid)[2]
    n_demos = list(range(2, size.max_demos + 1))
    total = len(grid) * (1 + size.seeds * (1 + len(TEACHERS) * (len(n_demos) - 1)))
    done = 0

    def measure(ts: Any, places: list[dict[str, Float]], s: int, stage: str) -> list[bool]:
        nonlocal done
        trials = run_trials(
            ts, places, ["fused"], TrialConditions(ground_truth=True, seed=s), client=client
        )
        done += len(places)
        if progress is not None:
            progress(stage, done, total)
        return [bool(t.runs["fused"]["success"]) for t in trials]

    # The grid's points no teacher fixes: a skill of demonstrations spread over the ranges.
    spread = [d for d in teach_at(spec, spread_placements(spec, SPREAD_DEMOS, seed), seed) if d]
    works = measure(task_skill(spec, spread), grid, seed, "the points no teacher fixes")
    kept, excluded = split_grid(grid, works)
    per_seed: dict[str, dict[str, list[float]]] = {}
    for s in range(seed, seed + size.seeds):
        first = teach(spec, 2, seed=s)
        start = task_skill(spec, first)
        rate0 = float(np.mean(measure(start, kept, s, f"seed {s}: 2 demonstrations")))
        curves: dict[str, list[float]] = {}
        for kind in TEACHERS:
            teacher = _Teacher(kind, spec, s)
            skill, demos, curve = start.skill, list(first), [rate0]
            for n in n_demos[1:]:
                tries = teacher.choices(skill, [_placement_of(d) for d in demos])
                new = _first_shown(spec, tries, s * 1000 + n)
                if new is None:
                    new = _first_shown(spec, teacher.random(32), s * 1000 + n)
                if new is None:
                    raise RuntimeError(f"the {kind} teacher found nowhere to demonstrate")
                demos.append(new)
                with warnings.catch_warnings():  # K at the cap, said by learn: not the study's
                    warnings.simplefilter("ignore", SelectionWarning)
                    skill = skill.update(new)
                ts = task_skill(spec, demos, skill)
                curve.append(float(np.mean(measure(ts, kept, s, f"seed {s}: {kind}, {n}"))))
            curves[kind] = curve
        per_seed[str(s)] = curves
    median = {
        k: [float(np.median([per_seed[s][k][i] for s in per_seed])) for i in range(len(n_demos))]
        for k in TEACHERS
    }
    return {
        "size": asdict(size),
        "n_demos": n_demos,
        **median,
        "per_seed": per_seed,
        "needed": {
            k: _median_needed([needed(per_seed[s][k], n_demos) for s in per_seed]) for k in TEACHERS
        },
        "target": TARGET,
        "grid_points": len(grid),
        "excluded": excluded,
    }


def run_active_study(
    spec: TaskSpec,
    out: Path,
    *,
    size: ActiveSize = ACTIVE_SMALL,
    seed: int = 0,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> dict[str, Any]:
    """:func:`run_active` on Dask workers (as ``pbdkit study``), written to ``out``:
    ``study.json`` (``{"task", "seed", "active", "seconds"}``) and ``active.png`` (success
    against demonstrations per teacher), staged as :func:`pbdkit.apps._study.run_study`'s."""
    from ..sim._parallel import session
    from ._plots import figure_png
    from ._staging import staged_output

    start = time.perf_counter()
    with staged_output(Path(out), last="study.json") as stage:
        with session(workers, scheduler) as client:
            active = run_active(spec, size=size, seed=seed, client=client, progress=progress)
        result = {
            "task": spec.name,
            "seed": seed,
            "active": active,
            "seconds": time.perf_counter() - start,
        }
        atomic_write_bytes(stage / "active.png", figure_png(_plot(spec, active)))
        write_json(stage / "study.json", result)
    return result


def _plot(spec: TaskSpec, active: dict[str, Any]) -> Any:
    from ._plots import new_figure

    fig = new_figure(figsize=(5.2, 3.4))
    ax = fig.subplots()
    n = active["n_demos"]
    colors = {"suggested": "tab:blue", "random": "tab:orange", "space_filling": "tab:green"}
    for kind in TEACHERS:
        for curve in (c[kind] for c in active["per_seed"].values()):
            ax.plot(n, [100 * v for v in curve], color=colors[kind], lw=0.6, alpha=0.35)
        got = active["needed"][kind]
        label = f"{kind.replace('_', '-')} (95 %: {'-' if got is None else f'{got:g}'})"
        ax.plot(n, [100 * v for v in active[kind]], "o-", color=colors[kind], label=label)
    ax.axhline(100 * active["target"], color="0.6", lw=0.8, ls="--")
    ax.set_xlabel("demonstrations", fontsize=8)
    ax.set_ylabel("fused success over the wide grid (%)", fontsize=8)
    ax.set_ylim(-5, 105)
    ax.set_xticks(n)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(f"{spec.name} task: where to demonstrate next (median of seeds)", fontsize=9)
    fig.tight_layout()
    return fig
