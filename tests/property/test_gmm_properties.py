"""Property tests: a GMM fitted with the default, scale-aware floor scales with its data."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pbdkit import GMM

from .strategies import DETERMINISTIC


def _stacked_trajectories(seed: int, n_dims: int) -> np.ndarray:
    """Three noisy demonstrations of a smooth motion, time in [0, 1] first: (150, 1 + n_dims)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, 50)
    freq = rng.uniform(0.5, 2.0, n_dims)
    rows = [
        np.column_stack([t, 0.5 * np.sin(np.outer(t, freq) * np.pi + rng.normal(0, 0.05, n_dims))])
        + np.r_[0.0, rng.normal(0.0, 0.01, n_dims)]
        for _ in range(3)
    ]
    return np.vstack(rows)


@settings(DETERMINISTIC, max_examples=25)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_dims=st.integers(1, 3),
    log_scales=st.lists(st.integers(-12, 0), min_size=4, max_size=4),
)
def test_fit_scales_with_each_column(seed: int, n_dims: int, log_scales: list[int]) -> None:
    # Every column's variance is below 1 here, so reg_covar=None is 1e-6 times it before and
    # after scaling: the fit is the same up to the scaling, to rounding.
    x = _stacked_trajectories(seed, n_dims)
    s = 10.0 ** np.asarray(log_scales[: n_dims + 1], dtype=np.float64)
    ref = GMM(3).fit(x)
    scaled = GMM(3).fit(x * s)
    np.testing.assert_allclose(scaled.weights_, ref.weights_, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(scaled.means_ / s, ref.means_, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(
        scaled.covariances_ / np.outer(s, s), ref.covariances_, rtol=1e-5, atol=1e-9
    )
    t = np.linspace(0.0, 1.0, 11)[:, None]
    mean, _ = ref.regress(t)
    mean_s, _ = scaled.regress(t * s[0])
    np.testing.assert_allclose(mean_s / s[1:], mean, rtol=1e-6, atol=1e-9)
