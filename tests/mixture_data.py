"""Trajectory data shared by the GMM tests (test_gmm.py, test_em.py, test_selection.py)."""

from __future__ import annotations

import numpy as np


def trajectories(rng: np.random.Generator, n_demos: int = 5, n_steps: int = 400) -> np.ndarray:
    """Noisy, phase-shifted demonstrations of a smooth 2-D motion, time in [0, 1] first:
    (n_demos * n_steps, 3)."""
    t = np.linspace(0.0, 1.0, n_steps)
    rows = []
    for _ in range(n_demos):
        phase = rng.normal(0.0, 0.03)
        y = np.column_stack(
            [np.sin(2 * np.pi * (t + phase)), np.cos(np.pi * t) + rng.normal(0, 0.05)]
        )
        rows.append(np.column_stack([t, y + rng.normal(0.0, 0.01, y.shape)]))
    return np.vstack(rows)


def piecewise_demos(rng: np.random.Generator, n_demos: int = 5, n_steps: int = 100) -> np.ndarray:
    """Demonstrations of a 2-D path of 4 straight segments (time 0..1), with variability."""
    knots_t = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    knots_y = np.array([[0.0, 0.0], [1.0, 0.2], [1.2, 1.2], [0.2, 1.0], [0.0, 0.0]])
    rows = []
    for _ in range(n_demos):
        t = np.linspace(0.0, 1.0, n_steps)
        warp = np.clip(t + rng.normal(0.0, 0.01) * np.sin(np.pi * t), 0, 1)
        y = np.column_stack([np.interp(warp, knots_t, knots_y[:, i]) for i in range(2)])
        rows.append(np.column_stack([t, y + rng.normal(0.0, 0.02, 2)]))
    return np.vstack(rows)
