"""The ``pbdkit`` command: a thin layer over the library.

``pbdkit demo`` runs the main job end to end and writes its results to a folder. The other
commands expose one step each.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from ._io import atomic_write_bytes

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Teach a robot arm a skill from a few demonstrations (Calinon & Billard, IROS 2008).",
)
console = Console(stderr=True)


@app.callback()
def _root() -> None:
    """Teach a robot arm a skill from a few demonstrations (Calinon & Billard, IROS 2008)."""


def _write_json(path: Path, data: object) -> None:
    atomic_write_bytes(path, (json.dumps(data, indent=2, sort_keys=True) + "\n").encode())


def run_lasa_demo(out: Path, shape: str = "GShape", max_components: int = 10) -> dict[str, object]:
    """Learn a LASA handwriting shape with GMM/GMR and write a figure and metrics.json.

    Returns the metrics written.
    """
    from .datasets import load_lasa
    from .gmm import GMM
    from .plots import plot_lasa_summary, save_figure

    out.mkdir(parents=True, exist_ok=True)
    demos = load_lasa(shape)
    n_steps = demos[0].pos.shape[0]
    t = np.linspace(0.0, 1.0, n_steps)
    x = np.vstack([np.column_stack([t, d.pos]) for d in demos])
    start = time.perf_counter()
    gmm = GMM("bic", max_components=max_components).fit(x)
    learn_s = time.perf_counter() - start
    start = time.perf_counter()
    mean, cov = gmm.regress(t[:, None])
    regress_s = time.perf_counter() - start
    positions = np.stack([d.pos for d in demos])

    def rmse(traj: np.ndarray) -> float:
        return float(
            np.mean([np.sqrt(np.mean(np.sum((traj - p) ** 2, axis=1))) for p in positions])
        )

    metrics: dict[str, object] = {
        "task": "lasa",
        "shape": shape,
        "n_demonstrations": len(demos),
        "n_steps": n_steps,
        "n_components": gmm.n_components_,
        "bic_scores": {str(k): v for k, v in gmm.bic_scores_.items()},
        "rmse_gmr_to_demos": rmse(mean),
        "rmse_pointwise_mean_to_demos": rmse(positions.mean(axis=0)),
        "final_point_error": float(np.linalg.norm(mean[-1] - positions[:, -1].mean(axis=0))),
        "learn_seconds": learn_s,
        "regress_seconds": regress_s,
    }
    fig = plot_lasa_summary(shape, t, list(positions), gmm, mean, cov)
    save_figure(fig, out / f"lasa_{shape}.png")
    _write_json(out / "metrics.json", metrics)
    return metrics


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="Folder for figures and metrics.json.")] = Path(
        "demo-output"
    ),
    task: Annotated[str, typer.Option(help="Task to run: lasa.")] = "lasa",
    shape: Annotated[str, typer.Option(help="LASA shape (task lasa).")] = "GShape",
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Run the main job: demonstrations -> GMM (K by BIC) -> GMR, with figures and metrics."""
    del seed  # the LASA job is deterministic (time-based EM initialisation)
    if task != "lasa":
        raise typer.BadParameter(f"task must be 'lasa', got {task!r}", param_hint="--task")
    with console.status(f"learning LASA shape {shape} ..."):
        metrics = run_lasa_demo(out, shape)
    table = Table(title=f"pbdkit demo: LASA {shape}")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key in ("n_components", "rmse_gmr_to_demos", "rmse_pointwise_mean_to_demos"):
        value = metrics[key]
        table.add_row(key, f"{value:.3f}" if isinstance(value, float) else str(value))
    table.add_row("learn time", f"{metrics['learn_seconds']:.2f} s")
    console.print(table)
    console.print(f"wrote {out / f'lasa_{shape}.png'} and {out / 'metrics.json'}")


def main() -> None:
    """Entry point of the ``pbdkit`` console script."""
    app()


if __name__ == "__main__":
    main()
