"""Figures: GMM ellipses, GMR mean with its covariance tube, demonstrations.

matplotlib is imported inside each function (the core never needs it), with the non-interactive
Agg backend so figures render on a machine without a screen. Functions draw on the axes they are
given or return a new figure; saving is the caller's business (:func:`save_figure` writes a PNG
atomically).
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ._io import atomic_write_bytes

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from .gmm import GMM

__all__ = ["plot_gmm_ellipses", "plot_gmr_tube", "plot_lasa_summary", "save_figure"]

Float = NDArray[np.float64]


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Figure, path: str | os.PathLike[str], *, dpi: int = 110) -> None:
    """Render ``fig`` to PNG and write it atomically to ``path``."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    atomic_write_bytes(path, buf.getvalue())


def plot_gmm_ellipses(
    ax: Axes,
    gmm: GMM,
    dims: tuple[int, int],
    *,
    n_std: float = 1.0,
    color: str = "tab:orange",
    alpha: float = 0.35,
) -> None:
    """Draw each component's covariance ellipse (``n_std`` standard deviations) in two dims.

    Parameters
    ----------
    ax : matplotlib Axes
    gmm : GMM
        A fitted mixture.
    dims : (int, int)
        The dimensions shown on the x and y axes.
    """
    from matplotlib.patches import Ellipse

    i, j = dims
    for mean, cov in zip(gmm.means_, gmm.covariances_, strict=True):
        c = cov[np.ix_([i, j], [i, j])]
        w, v = np.linalg.eigh(c)
        w = np.maximum(w, 0.0)
        angle = float(np.degrees(np.arctan2(v[1, 1], v[0, 1])))
        ell = Ellipse(
            (float(mean[i]), float(mean[j])),
            width=float(2 * n_std * np.sqrt(w[1])),
            height=float(2 * n_std * np.sqrt(w[0])),
            angle=angle,
            facecolor=color,
            edgecolor="k",
            linewidth=0.6,
            alpha=alpha,
        )
        ax.add_patch(ell)
        ax.plot(mean[i], mean[j], "k.", markersize=4)


def plot_gmr_tube(
    ax: Axes,
    t: Float,
    mean: Float,
    std: Float,
    *,
    color: str = "tab:blue",
    label: str | None = "GMR",
    n_std: float = 2.0,
) -> None:
    """GMR mean over time with a band of +- ``n_std`` standard deviations.

    Parameters
    ----------
    t : ndarray, shape (T,)
    mean : ndarray, shape (T,)
    std : ndarray, shape (T,)
    """
    ax.fill_between(t, mean - n_std * std, mean + n_std * std, color=color, alpha=0.25, lw=0)
    ax.plot(t, mean, color=color, lw=2, label=label)


def plot_lasa_summary(
    name: str,
    t: Float,
    demos: Sequence[Float],
    gmm: GMM,
    mean: Float,
    cov: Float,
) -> Figure:
    """A LASA shape: demonstrations, GMM ellipses and GMR in the plane, and each coordinate
    over time with the GMR covariance tube.

    Parameters
    ----------
    name : str
    t : ndarray, shape (T,)
        Time (the GMR input).
    demos : sequence of ndarray, shape (T, 2)
    gmm : GMM
        Fitted over {t, x1, x2}.
    mean : ndarray, shape (T, 2)
    cov : ndarray, shape (T, 2, 2)
    """
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    ax = axes[0]
    for k, d in enumerate(demos):
        ax.plot(d[:, 0], d[:, 1], color="0.55", lw=1, label="demonstrations" if k == 0 else None)
    plot_gmm_ellipses(ax, gmm, (1, 2))
    ax.plot(mean[:, 0], mean[:, 1], color="tab:blue", lw=2, label="GMR mean")
    ax.plot(mean[-1, 0], mean[-1, 1], "k*", markersize=10, label="target")
    ax.set_title(f"LASA {name}: K = {gmm.n_components_} components")
    ax.set_xlabel("x1")
    ax.set_ylabel("x2")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    for dim in range(2):
        ax = axes[dim + 1]
        for d in demos:
            ax.plot(t, d[:, dim], color="0.6", lw=0.8)
        plot_gmr_tube(ax, t, mean[:, dim], np.sqrt(cov[:, dim, dim]), label="GMR +- 2 sd")
        ax.set_xlabel("t")
        ax.set_ylabel(f"x{dim + 1}")
        ax.set_title(f"x{dim + 1} over time")
        ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    figure: Figure = fig
    return figure
