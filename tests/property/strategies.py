"""Hypothesis strategies and settings shared by the property tests.

Every strategy draws a few integers and floats (a seed among them) and builds its arrays with
``np.random.default_rng(seed)``: Hypothesis controls and shrinks the draws, numpy makes the
arrays. :data:`DETERMINISTIC` is the parent of every test's settings, so CI runs the same
examples on every run.
"""

from __future__ import annotations

import numpy as np
from hypothesis import settings
from hypothesis import strategies as st

#: The same examples on every run (derandomize, no example database), no time limit per example
#: (the first call of a test pays numpy's and scipy's import and warm-up).
DETERMINISTIC = settings(derandomize=True, database=None, deadline=None)

#: Rotation angles (rad) where the formulas of pbdkit._rotations change: the series near 0
#: (below 1e-6 for exp and J_l, 1e-4 for J_l^-1, 1.4e-4 for log3), ordinary angles, and near pi,
#: where arccos of the trace would lose its digits.
SPECIAL_ANGLES = (0.0, 1e-12, 1e-8, 1e-6, 1e-5, 1e-4, 2e-4, 0.3, 2.0, np.pi - 1e-4, np.pi - 1e-6)

#: Scales of the data: small, unit, large.
SCALES = (1e-3, 1.0, 1e3)

seeds = st.integers(0, 2**32 - 1)


@st.composite
def gmm_params(draw: st.DrawFn, max_k: int = 5, max_d: int = 6) -> tuple[np.ndarray, ...]:
    """Random valid GMM parameters (weights, means, covariances) from a drawn seed."""
    k = draw(st.integers(1, max_k))
    d = draw(st.integers(2, max_d))
    seed = draw(seeds)
    scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    rng = np.random.default_rng(seed)
    w = rng.dirichlet(np.ones(k))
    m = rng.normal(size=(k, d)) * scale
    a = rng.normal(size=(k, d, d)) * scale
    c = a @ np.swapaxes(a, 1, 2) + 1e-2 * scale**2 * np.eye(d)
    return w, m, c


def angles(max_angle: float = np.pi - 1e-6) -> st.SearchStrategy[float]:
    """Rotation angles in [0, max_angle], the :data:`SPECIAL_ANGLES` below it among them."""
    special = [a for a in SPECIAL_ANGLES if a <= max_angle]
    return st.one_of(st.sampled_from(special), st.floats(0.0, max_angle))


@st.composite
def rotation_vectors(draw: st.DrawFn, max_angle: float = np.pi - 1e-6) -> np.ndarray:
    """A rotation vector (3,): a random axis times an angle in [0, max_angle]."""
    axis = np.random.default_rng(draw(seeds)).normal(size=3)
    return np.asarray(axis / np.linalg.norm(axis) * draw(angles(max_angle)), dtype=np.float64)


@st.composite
def quaternions(draw: st.DrawFn) -> np.ndarray:
    """A quaternion (qw, qx, qy, qz) (4,), not normalized (norm 1e-3 .. 1e3 times a unit one);
    w = 0 (a half turn) or w < 0 in some."""
    q = np.random.default_rng(draw(seeds)).normal(size=4)
    q = q / np.linalg.norm(q) * draw(st.sampled_from(SCALES))
    if draw(st.booleans()):
        q[0] = -abs(q[0])
    if draw(st.integers(0, 9)) == 0:
        q[0] = 0.0
    return q


@st.composite
def gaussian_factors(
    draw: st.DrawFn, min_n: int = 1, max_n: int = 4, max_d: int = 4, d: int | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """N Gaussians in D dimensions: means (N, D), covariances (N, D, D) and their scale.

    Each covariance is Q diag(e) Q^T with Q a random rotation and e log-uniform over
    [1e-2, 1e2] times scale^2 (condition number at most 1e4), so that tolerances can be
    relative to the scale.
    """
    n = draw(st.integers(min_n, max_n))
    dims = draw(st.integers(1, max_d)) if d is None else d
    scale = draw(st.sampled_from(SCALES))
    rng = np.random.default_rng(draw(seeds))
    means = rng.normal(size=(n, dims)) * scale
    q, _ = np.linalg.qr(rng.normal(size=(n, dims, dims)))
    eig = scale**2 * 10.0 ** rng.uniform(-2.0, 2.0, size=(n, dims))
    cov = (q * eig[:, None, :]) @ np.swapaxes(q, 1, 2)
    return means, 0.5 * (cov + np.swapaxes(cov, 1, 2)), scale
