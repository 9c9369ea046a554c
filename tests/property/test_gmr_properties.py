"""Property tests: GMR output shapes, symmetry and positive definiteness on random mixtures."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pbdkit import GMM

from .strategies import DETERMINISTIC, gmm_params


@settings(DETERMINISTIC, max_examples=60)
@given(params=gmm_params(), n_in=st.integers(1, 2), covariance=st.sampled_from(["exact", "paper"]))
def test_regress_shapes_symmetry_and_positive_definiteness(
    params: tuple[np.ndarray, ...], n_in: int, covariance: str
) -> None:
    w, m, c = params
    d = m.shape[1]
    n_in = min(n_in, d - 1)
    gmm = GMM.from_params(w, m, c)
    scale = float(np.abs(m).max()) + 1.0
    x = np.linspace(-2 * scale, 2 * scale, 7)[:, None] * np.ones((1, n_in))
    mean, cov = gmm.regress(x, in_dims=list(range(n_in)), covariance=covariance)  # type: ignore[arg-type]
    assert mean.shape == (7, d - n_in)
    assert cov.shape == (7, d - n_in, d - n_in)
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))
    np.testing.assert_allclose(cov, np.swapaxes(cov, 1, 2), rtol=1e-9, atol=1e-12 * scale**2)
    # Positive definite up to round-off relative to the covariance's own scale.
    for s in cov:
        eig = np.linalg.eigvalsh(s)
        assert eig.min() > -1e-9 * max(eig.max(), 1e-300)


@settings(DETERMINISTIC, max_examples=40)
@given(params=gmm_params())
def test_exact_covariance_dominates_mean_of_conditionals(params: tuple[np.ndarray, ...]) -> None:
    # Law of total covariance: exact = E[C_k] + Cov[m_k] >= sum_k beta_k C_k >= paper form.
    w, m, c = params
    gmm = GMM.from_params(w, m, c)
    x = m[:, :1]
    exact = gmm.regress(x, covariance="exact")[1]
    paper = gmm.regress(x, covariance="paper")[1]
    for e, p in zip(exact, paper, strict=True):
        eig = np.linalg.eigvalsh(e - p)
        assert eig.min() >= -1e-8 * max(np.abs(eig).max(), 1e-300)
