"""Where a skill works: ``pbdkit study`` (a map of the table, a learning curve, noise tolerance).

Three questions a researcher asks of a learned skill, each answered by many physics runs
(:func:`pbdkit.sim._trials.run_trials`, in parallel with ``workers`` / ``scheduler``):

1. **Generalization map.** For each object that moves, a grid of placements over the table
   spanning twice the demonstrated range on each side of its centre (the range is drawn), the
   other objects at their nominal place; every controller runs at every grid point. The paper
   evaluates inside the demonstrated range only; the map shows how far beyond it each
   controller carries.
2. **Learning curve.** The fused controller's success rate against the number of
   demonstrations (2 to 10), each skill learned from that many demonstrations of the
   simulated teacher, over random placements inside the range.
3. **Tracking-noise tolerance.** The fused controller's success rate against Gaussian noise
   added to the positions the skill is told (mean 3-D error 0 to 10 mm,
   :func:`pbdkit.sim._sensing.observation_noise`), with the paper's tracking error,
   5.9 +- 2.8 mm, marked.

The runs are told the true positions (plus the noise of 3.): the map and the curve measure the
skill, not the cameras, whose own error is measured by ``pbdkit evaluate``. Placements follow
the task's own seeds: ``seed`` teaches the demonstrations and draws the random placements.

:data:`SMALL` (the default) takes minutes on 2 cores; :data:`FULL` (``--full``) is meant for a
cluster (``--scheduler``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write_bytes, write_json
from .._validation import check_int, check_positive_float, short
from ..sim._task_skill import constrained_objects, learn_task
from ..sim._tasks import PlacementRange, TaskSpec, check_task, yaw_of, yaw_pose
from ..sim._trials import TrialConditions, run_trials
from ..skill._naming import controller_names
from ._staging import staged_output

if TYPE_CHECKING:
    from ..sim._task_skill import TaskSkill

__all__ = [
    "FULL",
    "PAPER_TRACKING_MM",
    "SMALL",
    "StudySize",
    "check_study",
    "grid_placements",
    "run_study",
]

Float = NDArray[np.float64]

#: The paper's tracking error (Sec. III), mean +- standard deviation (mm).
PAPER_TRACKING_MM = (5.9, 2.8)


def _as_tuple(name: str, value: object, *, empty: str = "") -> tuple[Any, ...]:
    """``value`` as a non-empty tuple, or a ValueError naming ``name`` (``empty``: what to give
    instead of an empty one)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise ValueError(f"{name} must be a tuple, got {short(value)}")
    items = tuple(value)
    if not items:
        hint = f" ({empty})" if empty else ""
        raise ValueError(f"{name} must not be empty{hint}, got ()")
    return items


def _check_unique(name: str, items: tuple[Any, ...]) -> None:
    if len(set(items)) != len(items):
        raise ValueError(f"{name} must not repeat a value, got {short(items)}")


@dataclass(frozen=True)
class StudySize:
    """How many runs a study makes.

    Attributes
    ----------
    grid : int
        Grid points per axis of each map (grid x grid placements, every controller).
    demos : tuple of int
        Numbers of demonstrations of the learning curve.
    curve_trials : int
        Random placements per number of demonstrations (fused controller).
    noise_mm : tuple of float
        Mean 3-D noise levels (mm).
    noise_trials : int
        Random placements per noise level (fused controller).
    map_controllers : tuple of str, optional
        The controllers of the maps (default, None: every one of the skill).

    Raises
    ------
    ValueError
        On construction, for a size no study can run: ``grid`` < 2 (a map needs two points per
        axis), a number of demonstrations < 2 (a skill needs two), trials < 1, a noise level
        that is negative or not finite, an empty or repeated list, an empty
        ``map_controllers`` (give None for every controller). The controllers' names are
        checked against the task by :func:`run_study`, before any physics.
    """

    grid: int
    demos: tuple[int, ...]
    curve_trials: int
    noise_mm: tuple[float, ...]
    noise_trials: int
    map_controllers: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        check_int(self.grid, "StudySize.grid", minimum=2)  # a map needs two points per axis
        check_int(self.curve_trials, "StudySize.curve_trials", minimum=1)
        check_int(self.noise_trials, "StudySize.noise_trials", minimum=1)
        # Sequences are kept as tuples: the size stays frozen and hashable.
        demos = _as_tuple("StudySize.demos", self.demos)
        for i, n in enumerate(demos):
            check_int(n, f"StudySize.demos[{i}]", minimum=2)  # a skill needs two
        _check_unique("StudySize.demos", demos)
        noise = _as_tuple("StudySize.noise_mm", self.noise_mm)
        for i, v in enumerate(noise):
            check_positive_float(v, f"StudySize.noise_mm[{i}]", allow_zero=True)
        _check_unique("StudySize.noise_mm", noise)
        object.__setattr__(self, "demos", demos)
        object.__setattr__(self, "noise_mm", noise)
        if self.map_controllers is not None:
            names = _as_tuple(
                "StudySize.map_controllers", self.map_controllers, empty="None: every controller"
            )
            if not all(isinstance(k, str) for k in names):
                raise ValueError(
                    f"StudySize.map_controllers must hold controller names, got {short(names)}"
                )
            _check_unique("StudySize.map_controllers", names)
            object.__setattr__(self, "map_controllers", names)

    def runs(self, n_maps: int, n_controllers: int) -> int:
        """Physics runs of a study with ``n_maps`` maps of ``n_controllers`` controllers (or
        of :attr:`map_controllers`)."""
        if self.map_controllers is not None:
            n_controllers = len(self.map_controllers)
        grid = n_maps * self.grid**2 * n_controllers
        return grid + len(self.demos) * self.curve_trials + len(self.noise_mm) * self.noise_trials


SMALL = StudySize(
    grid=5, demos=(2, 3, 5, 7, 10), curve_trials=6, noise_mm=(0, 2, 4, 6, 8, 10), noise_trials=6
)
FULL = StudySize(
    grid=11,
    demos=tuple(range(2, 11)),
    curve_trials=40,
    noise_mm=tuple(float(v) for v in range(11)),
    noise_trials=40,
)


def grid_placements(
    spec: TaskSpec, obj: str, n: int
) -> tuple[Float, Float, list[dict[str, Float]]]:
    """An n x n grid of placements of ``obj`` spanning twice its range's half-width on each side
    of the range's centre (x, y; z at its support), the other objects at their nominal place.
    For an object placed as a pose (a yaw range), the grid is over x and the yaw instead (y at
    the range's centre), the yaw spanning twice its range's half-width on each side too.

    Returns
    -------
    xs, ys : ndarray, shape (n,)
        The grid's coordinates: x (m), and y (m) or the yaw (rad) for a posed object.
    placements : list of dict
        Row-major: placement ``i * n + j`` has ``obj`` at ``(xs[j], ys[i])``.
    """
    r = spec.ranges[obj]
    if r.fixed:
        raise ValueError(
            f"{short(obj)} is fixed in the {short(spec.name)} task: there is nothing to map"
        )
    c, h = r.center, 0.5 * (r.high - r.low)
    xs = np.linspace(c[0] - 2 * h[0], c[0] + 2 * h[0], n)
    if r.yaw is not None:
        yc, yh = 0.5 * (r.yaw[0] + r.yaw[1]), 0.5 * (r.yaw[1] - r.yaw[0])
        ys = np.linspace(yc - 2 * yh, yc + 2 * yh, n)
    else:
        ys = np.linspace(c[1] - 2 * h[1], c[1] + 2 * h[1], n)
    nominal = spec.nominal_objects()
    out = []
    for y in ys:
        for x in xs:
            p = {k: v.copy() for k, v in nominal.items()}
            p[obj] = np.array([x, y, c[2]]) if r.yaw is None else yaw_pose([x, c[1], c[2]], y)
            out.append(p)
    return xs, ys, out


def _map_box(r: PlacementRange) -> tuple[Float, Float]:
    """The demonstrated range in a map's coordinates: (x, y), or (x, yaw) for a pose."""
    if r.yaw is None:
        return r.low[:2].copy(), r.high[:2].copy()
    return np.array([r.low[0], r.yaw[0]]), np.array([r.high[0], r.yaw[1]])


def _map_point(r: PlacementRange, placed: Float) -> Float:
    """A placement in a map's coordinates (:func:`_map_box`)."""
    if r.yaw is None:
        return np.asarray(placed[:2], dtype=np.float64)
    return np.array([placed[0, 3], yaw_of(placed)])


def _rate(trials: Sequence[Any], name: str) -> float:
    return float(np.mean([bool(t.runs[name]["success"]) for t in trials])) if trials else 0.0


def run_study(
    spec: TaskSpec,
    out: Path,
    *,
    size: StudySize = SMALL,
    seed: int = 0,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    learn: Callable[..., TaskSkill] | None = None,
) -> dict[str, Any]:
    """Run the three studies of the module docstring for the task ``spec`` and write their
    report.

    Writes ``study.json`` (every success rate, the sizes, the timings), one
    ``map_OBJECT.png`` per moving object, ``learning_curve.png``, ``noise.png`` and
    ``report.html`` to ``out``. ``study.json`` is strict JSON: a rate with nothing to count
    is ``null`` (``inside_range`` when no grid point lies inside the demonstrated range, as
    with ``grid=2``, whose points are all outside it).

    The arguments are checked before any physics runs. The files are written to a hidden
    folder inside ``out`` and moved into ``out`` once the study has succeeded, so that a
    study that fails leaves ``out`` as it found it: without new files, and removed if the
    study created it.

    Parameters
    ----------
    spec : TaskSpec
    out : Path
        Output folder (created, with its missing parents).
    size : StudySize
        :data:`SMALL` or :data:`FULL`, or your own.
    seed : int
        Teaches the demonstrations and draws the placements (>= 0).
    workers, scheduler
        Run the trials on Dask workers (as ``pbdkit evaluate``): ``workers`` local processes
        or the cluster at ``scheduler``; one cluster serves the whole study.
    progress : callable, optional
        ``progress(stage, done, total)`` after every batch of runs.
    learn : callable, optional
        ``learn(spec, n_demos=n, seed=seed)`` returns the ``TaskSkill`` learned from ``n``
        demonstrations of the task (the skill of the maps and the noise, ``n = 5``, then one
        per number of the learning curve). Default: :func:`pbdkit.sim.learn_task`
        (the simulated teacher, the full time grid); inject a faster or a different learner.

    Returns
    -------
    study : dict
        What ``study.json`` holds.

    Raises
    ------
    ValueError
        Before any physics: the checks of :func:`check_study`, and ``out`` not a directory.
    """
    from ..sim._parallel import session

    spec = check_study(spec, size=size, seed=seed, learn=learn)
    out = Path(out)
    learn = learn_task if learn is None else learn
    start = time.perf_counter()
    with staged_output(out, last="study.json") as stage:
        with session(workers, scheduler) as client:
            result = _run(spec, stage, size, seed, client, progress, learn)
        result["seconds"] = time.perf_counter() - start
        write_json(stage / "study.json", result)
        _write_report(spec, stage, result)
    return result


def check_study(
    spec: TaskSpec,
    *,
    size: StudySize = SMALL,
    seed: int = 0,
    learn: Callable[..., TaskSkill] | None = None,
) -> TaskSpec:
    """Check the arguments of :func:`run_study` (it calls this first; a command line calls it
    before it shows progress) and return the task's spec.

    The controllers of ``size.map_controllers`` must be those of the skill the default
    learner gives (fused, joint and one per moving object); with an injected ``learn``, one
    per object of the task, then those of the skill learned (checked before its runs).

    Raises
    ------
    ValueError
        ``spec`` not a TaskSpec, ``size`` not a :class:`StudySize`, an unknown controller,
        ``seed`` not an integer >= 0.
    """
    spec = check_task(spec, "spec")
    if not isinstance(size, StudySize):
        raise ValueError(f"size must be a StudySize (SMALL, FULL or your own), got {short(size)}")
    check_int(seed, "seed", minimum=0)
    # An injected learner may constrain any object of the task (the fixed basin too).
    objects = constrained_objects(spec) if learn is None else list(spec.ranges)
    known = controller_names(objects)
    for name in size.map_controllers or ():
        if name not in known:
            raise ValueError(
                f"StudySize.map_controllers must name controllers of {known}, got {short(name)}"
            )
    return spec


def _run(
    spec: TaskSpec,
    out: Path,
    size: StudySize,
    seed: int,
    client: Any,
    progress: Callable[[str, int, int], None] | None,
    learn: Callable[..., TaskSkill],
) -> dict[str, Any]:
    from ._plots import figure_png

    ts = learn(spec, n_demos=5, seed=seed)
    # The runs are told the true positions (module docstring): the skill is measured, not the
    # cameras.
    conditions = TrialConditions(ground_truth=True, seed=seed)
    names = list(size.map_controllers or ts.controllers)
    maps_of = list(spec.tracked_objects)
    total = size.runs(len(maps_of), len(names))
    done = 0

    def tick(stage: str, n: int) -> None:
        nonlocal done
        done += n
        if progress is not None:
            progress(stage, done, total)

    result: dict[str, Any] = {
        "task": spec.name,
        "seed": seed,
        "size": asdict(size),
        "controllers": names,
        "n_components": ts.skill.n_components_,
        "maps": {},
    }
    # 1. Generalization maps.
    for obj in maps_of:
        xs, ys, placements = grid_placements(spec, obj, size.grid)
        trials = run_trials(ts, placements, names, conditions, client=client)
        tick(f"map of the {obj}", len(placements) * len(names))
        success = {
            k: np.array([bool(t.runs[k]["success"]) for t in trials]).reshape(len(ys), len(xs))
            for k in names
        }
        r = spec.ranges[obj]
        low, high = _map_box(r)
        result["maps"][obj] = {
            "x": xs.tolist(),
            # y (m), or for a posed object its yaw (rad)
            ("yaw" if r.posed else "y"): ys.tolist(),
            "range": [low.tolist(), high.tolist()],
            "success": {k: v.astype(int).tolist() for k, v in success.items()},
            "inside_range": {k: _inside_rate(v, xs, ys, low, high) for k, v in success.items()},
            "overall": {k: float(v.mean()) for k, v in success.items()},
        }
        demos_at = np.array([_map_point(r, d.objects[obj]) for d in ts.demos])
        fig = _plot_map(spec, obj, xs, ys, success, low, high, demos_at, yaw=r.posed)
        atomic_write_bytes(out / f"map_{obj}.png", figure_png(fig))
    # 2. Learning curve (fused).
    rng = np.random.default_rng([seed, 5])
    curve_places = [spec.sample_objects(rng) for _ in range(size.curve_trials)]
    curve = []
    for n in size.demos:
        ts_n = ts if n == len(ts.demos) else learn(spec, n_demos=n, seed=seed)
        trials = run_trials(ts_n, curve_places, ["fused"], conditions, client=client)
        tick(f"learning curve, {n} demonstrations", len(curve_places))
        curve.append({"n_demos": n, "success_rate": _rate(trials, "fused"),
                      "n_components": ts_n.skill.n_components_})  # fmt: skip
    result["learning_curve"] = curve
    atomic_write_bytes(out / "learning_curve.png", figure_png(_plot_curve(spec, curve, size)))
    # 3. Noise tolerance (fused).
    rng = np.random.default_rng([seed, 6])
    noise_places = [spec.sample_objects(rng) for _ in range(size.noise_trials)]
    noise = []
    for level in size.noise_mm:
        noisy = replace(conditions, noise_mm=float(level))
        trials = run_trials(ts, noise_places, ["fused"], noisy, client=client)
        tick(f"noise {level:g} mm", len(noise_places))
        noise.append({"noise_mm": float(level), "success_rate": _rate(trials, "fused")})
    result["noise"] = noise
    atomic_write_bytes(out / "noise.png", figure_png(_plot_noise(spec, noise, size)))
    return result


def _inside_rate(
    success: NDArray[np.bool_], xs: Float, ys: Float, low: Float, high: Float
) -> float | None:
    """The success rate over the grid points inside the range; None if there are none (JSON
    null: NaN is not JSON)."""
    inside = (
        (xs[None, :] >= low[0] - 1e-9)
        & (xs[None, :] <= high[0] + 1e-9)
        & (ys[:, None] >= low[1] - 1e-9)
        & (ys[:, None] <= high[1] + 1e-9)
    )
    return float(success[inside].mean()) if inside.any() else None


def _plot_map(
    spec: TaskSpec,
    obj: str,
    xs: Float,
    ys: Float,
    success: dict[str, NDArray[np.bool_]],
    low: Float,
    high: Float,
    demos_at: Float,
    *,
    yaw: bool = False,
) -> Any:
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Rectangle

    from ._plots import new_figure

    fig = new_figure(figsize=(3.2 * len(success), 3.4))
    axes = fig.subplots(1, len(success), squeeze=False)[0]
    dx, dy = (xs[1] - xs[0]) / 2, (ys[1] - ys[0]) / 2
    cmap = ListedColormap(["#d9534f", "#5cb85c"])
    sy = float(np.degrees(1.0)) if yaw else 1e3  # the y axis: yaw in degrees, or y in mm
    for ax, (name, ok) in zip(axes, success.items(), strict=True):
        extent = (1e3 * (xs[0] - dx), 1e3 * (xs[-1] + dx), sy * (ys[0] - dy), sy * (ys[-1] + dy))
        ax.imshow(ok.astype(float), origin="lower", extent=extent, cmap=cmap, vmin=0, vmax=1,
                  aspect="auto" if yaw else "equal")  # fmt: skip
        ax.add_patch(Rectangle((1e3 * low[0], sy * low[1]), 1e3 * (high[0] - low[0]),
                               sy * (high[1] - low[1]), fill=False, lw=1.5, ec="k"))  # fmt: skip
        ax.plot(1e3 * demos_at[:, 0], sy * demos_at[:, 1], "k+", ms=6, label="demonstrated")
        ax.set_title(f"{name}: {100 * ok.mean():.0f} %", fontsize=9)
        ax.set_xlabel(f"{obj} x (mm)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel(f"{obj} yaw (deg)" if yaw else f"{obj} y (mm)", fontsize=8)
    axes[0].legend(fontsize=7, loc="lower left")
    fig.suptitle(
        f"{spec.name} task: success (green) with the {obj} "
        + ("placed along x and turned" if yaw else "placed over the table")
        + "; box: the "
        "demonstrated range, +: the demonstrations",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def _plot_curve(spec: TaskSpec, curve: list[dict[str, Any]], size: StudySize) -> Any:
    from ._plots import new_figure

    fig = new_figure(figsize=(4.8, 3.2))
    ax = fig.subplots()
    n = [c["n_demos"] for c in curve]
    rate = [100 * c["success_rate"] for c in curve]
    ax.plot(n, rate, "o-", color="k")
    ax.axvline(5, color="0.6", lw=0.8, ls="--", label="the paper: 5")
    ax.set_xlabel("demonstrations", fontsize=8)
    ax.set_ylabel(f"fused success (%), {size.curve_trials} placements", fontsize=8)
    ax.set_ylim(-5, 105)
    ax.set_xticks(n)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7)
    ax.set_title(f"{spec.name} task: how many demonstrations", fontsize=9)
    fig.tight_layout()
    return fig


def _plot_noise(spec: TaskSpec, noise: list[dict[str, Any]], size: StudySize) -> Any:
    from ._plots import new_figure

    fig = new_figure(figsize=(4.8, 3.2))
    ax = fig.subplots()
    mean, sd = PAPER_TRACKING_MM
    ax.axvspan(mean - sd, mean + sd, color="0.9", label=f"paper's cameras: {mean} +- {sd} mm")
    ax.axvline(mean, color="0.5", lw=0.8)
    ax.plot([c["noise_mm"] for c in noise], [100 * c["success_rate"] for c in noise], "o-",
            color="k")  # fmt: skip
    ax.set_xlabel("tracking noise: mean 3-D error (mm)", fontsize=8)
    ax.set_ylabel(f"fused success (%), {size.noise_trials} placements", fontsize=8)
    ax.set_ylim(-5, 105)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(f"{spec.name} task: tolerance to tracking error", fontsize=9)
    fig.tight_layout()
    return fig


def _percent(rate: float | None) -> str:
    """A rate for the report's tables; "-" where there was nothing to count."""
    return "-" if rate is None else f"{100 * rate:.0f} %"


def _write_report(spec: TaskSpec, out: Path, result: dict[str, Any]) -> None:
    from ._report import Figure, Section, write_report

    sections = []
    for obj, m in result["maps"].items():
        rows = [
            [k, _percent(m["inside_range"][k]), _percent(m["overall"][k])]
            for k in result["controllers"]
        ]
        posed = "yaw" in m
        grid = (
            f"x and yaw ({len(m['x'])} x {len(m['yaw'])}; y at the range's centre)"
            if posed
            else f"x and y ({len(m['x'])} x {len(m['y'])})"
        )
        sections.append(
            Section(
                f"Where the skill works: the {obj} "
                + ("placed and turned" if posed else "over the table"),
                paragraphs=[
                    f"The {obj} on a grid over {grid} spanning twice its demonstrated range on "
                    "each side (box), the other objects at their nominal place; every "
                    "controller at every point, told the true positions."
                ],
                tables={"Success rate": (["controller", "inside the range", "whole grid"], rows)},
                figures=[Figure((out / f"map_{obj}.png").read_bytes(), f"Map of the {obj}.")],
            )
        )
    curve_rows = [
        [c["n_demos"], f"{100 * c['success_rate']:.0f} %",
         ", ".join(f"{k} {v}" for k, v in c["n_components"].items())]
        for c in result["learning_curve"]
    ]  # fmt: skip
    sections.append(
        Section(
            "How many demonstrations",
            tables={"Fused success": (["demonstrations", "success", "K per space"], curve_rows)},
            figures=[Figure((out / "learning_curve.png").read_bytes(), "Learning curve.")],
        )
    )
    noise_rows = [[c["noise_mm"], f"{100 * c['success_rate']:.0f} %"] for c in result["noise"]]
    sections.append(
        Section(
            "How much tracking error",
            paragraphs=[
                "Gaussian noise added to the positions the fused controller is told (isotropic, "
                "the level is its mean 3-D length); grey band: the paper's cameras, "
                f"{PAPER_TRACKING_MM[0]} +- {PAPER_TRACKING_MM[1]} mm."
            ],
            tables={"Fused success": (["noise (mm)", "success"], noise_rows)},
            figures=[Figure((out / "noise.png").read_bytes(), "Noise tolerance.")],
        )
    )
    write_report(
        out / "report.html",
        f"pbdkit study: the {spec.name} task",
        sections,
        intro=f"{result['size']} - {result['seconds']:.0f} s of wall time.",
    )
