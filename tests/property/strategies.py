"""Hypothesis strategies shared by the property tests."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st


@st.composite
def gmm_params(draw: st.DrawFn, max_k: int = 5, max_d: int = 6) -> tuple[np.ndarray, ...]:
    """Random valid GMM parameters (weights, means, covariances) from a drawn seed."""
    k = draw(st.integers(1, max_k))
    d = draw(st.integers(2, max_d))
    seed = draw(st.integers(0, 2**32 - 1))
    scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    rng = np.random.default_rng(seed)
    w = rng.dirichlet(np.ones(k))
    m = rng.normal(size=(k, d)) * scale
    a = rng.normal(size=(k, d, d)) * scale
    c = a @ np.swapaxes(a, 1, 2) + 1e-2 * scale**2 * np.eye(d)
    return w, m, c
