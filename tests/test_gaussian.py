"""Tests of pbdkit.prob.gaussian against the definitions (brute-force densities on a grid)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from pbdkit.prob import gaussian as G


def _random_spd(rng: np.random.Generator, d: int, scale: float = 1.0) -> np.ndarray:
    a = rng.normal(size=(d, d)) * scale
    return a @ a.T + 0.1 * scale**2 * np.eye(d)


def test_product_1d_equals_grid_product_of_densities() -> None:
    rng = np.random.default_rng(0)
    means = rng.normal(size=(3, 1))
    covs = np.stack([_random_spd(rng, 1) for _ in range(3)])
    mean, cov = G.gaussian_product(means, covs)
    x = np.linspace(-15, 15, 200001)
    log_p = sum(multivariate_normal(means[i], covs[i]).logpdf(x[:, None]) for i in range(3))
    p = np.exp(log_p - log_p.max())
    p /= np.trapezoid(p, x)
    grid_mean = np.trapezoid(x * p, x)
    grid_var = np.trapezoid((x - grid_mean) ** 2 * p, x)
    np.testing.assert_allclose(mean[0], grid_mean, atol=1e-8)
    np.testing.assert_allclose(cov[0, 0], grid_var, rtol=1e-6)


def test_product_2d_equals_grid_product_of_densities() -> None:
    rng = np.random.default_rng(1)
    means = rng.normal(size=(2, 2))
    covs = np.stack([_random_spd(rng, 2, 0.7) for _ in range(2)])
    mean, cov = G.gaussian_product(means, covs)
    g = np.linspace(-8, 8, 801)
    xx, yy = np.meshgrid(g, g, indexing="ij")
    pts = np.column_stack([xx.ravel(), yy.ravel()])
    log_p = multivariate_normal(means[0], covs[0]).logpdf(pts) + multivariate_normal(
        means[1], covs[1]
    ).logpdf(pts)
    w = np.exp(log_p - log_p.max())
    w /= w.sum()
    grid_mean = w @ pts
    dev = pts - grid_mean
    grid_cov = (dev * w[:, None]).T @ dev
    np.testing.assert_allclose(mean, grid_mean, atol=1e-6)
    np.testing.assert_allclose(cov, grid_cov, atol=1e-5)


def test_product_information_accepts_rank_deficient_factors() -> None:
    # Two rank-1 precisions along x and y: each alone is degenerate, their sum is not.
    means = np.array([[1.0, 5.0], [7.0, -2.0]])
    lam = np.array([[[4.0, 0.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 0.25]]])
    mean, cov = G.product_information(means, lam)
    np.testing.assert_allclose(mean, [1.0, -2.0], atol=1e-12)
    np.testing.assert_allclose(cov, np.diag([0.25, 4.0]), atol=1e-12)


def test_product_information_batched_equals_loop() -> None:
    rng = np.random.default_rng(2)
    means = rng.normal(size=(5, 3, 4))
    lam = np.stack([np.stack([_random_spd(rng, 4) for _ in range(3)]) for _ in range(5)])
    mean, cov = G.product_information(means, lam)
    for m in range(5):
        m1, c1 = G.product_information(means[m], lam[m])
        np.testing.assert_allclose(mean[m], m1, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(cov[m], c1, rtol=1e-12, atol=1e-12)


def test_product_information_singular_sum_raises() -> None:
    means = np.zeros((2, 2))
    lam = np.array([[[1.0, 0.0], [0.0, 0.0]], [[2.0, 0.0], [0.0, 0.0]]])
    with pytest.raises(ValueError, match="sum of the precisions is not positive definite"):
        G.product_information(means, lam)


def test_product_information_shape_mismatch_raises() -> None:
    with pytest.raises(ValueError, match="precisions must have shape"):
        G.product_information(np.zeros((2, 3)), np.zeros((2, 2, 2)))


def test_linear_transform_matches_monte_carlo_and_formula() -> None:
    rng = np.random.default_rng(3)
    mu = rng.normal(size=3)
    cov = _random_spd(rng, 3)
    a = rng.normal(size=(2, 3))
    b = rng.normal(size=2)
    m, c = G.linear_transform(mu, cov, a, b)
    np.testing.assert_allclose(m, a @ mu + b, rtol=1e-12)
    np.testing.assert_allclose(c, a @ cov @ a.T, rtol=1e-12)
    samples = rng.multivariate_normal(mu, cov, size=200000) @ a.T + b
    np.testing.assert_allclose(samples.mean(axis=0), m, atol=0.03)
    np.testing.assert_allclose(np.cov(samples.T), c, atol=0.1)


def test_linear_transform_bad_shapes() -> None:
    with pytest.raises(ValueError, match="A must have 3 columns"):
        G.linear_transform(np.zeros(3), np.eye(3), np.zeros((2, 4)))


def test_regularize_covariance_floor_and_diagonal() -> None:
    cov = np.array([[1.0, 1.0], [1.0, 1.0]])  # singular
    out = G.regularize_covariance(cov, 0.0, min_eigenvalue=1e-3)
    w = np.linalg.eigvalsh(out)
    np.testing.assert_allclose(w, [1e-3, 2.0], rtol=1e-10)
    out2 = G.regularize_covariance(cov, 0.5)
    np.testing.assert_allclose(out2, cov + 0.5 * np.eye(2))
    with pytest.raises(ValueError, match="reg must be finite and >= 0"):
        G.regularize_covariance(cov, -1.0)


def test_precision_and_information_form() -> None:
    rng = np.random.default_rng(4)
    cov = _random_spd(rng, 4)
    mu = rng.normal(size=4)
    eta, lam = G.information_from_gaussian(mu, cov)
    np.testing.assert_allclose(lam @ cov, np.eye(4), atol=1e-10)
    np.testing.assert_allclose(np.linalg.solve(lam, eta), mu, atol=1e-10)
    with pytest.raises(ValueError, match="covariance is not positive definite"):
        G.precision_from_covariance(-np.eye(2))


def test_log_density_matches_scipy() -> None:
    rng = np.random.default_rng(5)
    cov = _random_spd(rng, 3)
    mu = rng.normal(size=3)
    x = rng.normal(size=(10, 3))
    np.testing.assert_allclose(
        G.gaussian_log_density(x, mu, cov), multivariate_normal(mu, cov).logpdf(x), rtol=1e-12
    )


def test_nan_input_rejected() -> None:
    with pytest.raises(ValueError, match="means must be finite"):
        G.product_information(np.array([[np.nan, 0.0]]), np.eye(2)[None])


def test_inverse_cholesky_factor_is_the_inverse_of_the_lower_factor() -> None:
    rng = np.random.default_rng(6)
    cov = np.stack([_random_spd(rng, 3, scale) for scale in (1.0, 1e-9, 1e4)])
    linv = G.inverse_cholesky_factor(cov)
    upper = np.abs(np.triu(linv, 1)) / np.abs(linv).max(axis=(1, 2), keepdims=True)
    assert upper.max() < 1e-12  # lower triangular, up to the rounding of the solve
    np.testing.assert_allclose(
        linv @ np.linalg.cholesky(cov), np.broadcast_to(np.eye(3), cov.shape), atol=1e-12
    )
    # Sigma^-1 = L^-T L^-1, as precision_from_covariance computes it.
    np.testing.assert_array_equal(
        G.precision_from_covariance(cov[0]), 0.5 * (linv[0].T @ linv[0] + (linv[0].T @ linv[0]).T)
    )
    bad = cov.copy()
    bad[1] = -bad[1]
    with pytest.raises(ValueError, match="Sigma is not positive definite; add regularization"):
        G.inverse_cholesky_factor(bad, "Sigma")
    with pytest.raises(ValueError, match=r"^3 matrices, shape \(3, 3, 3\)$"):
        G.inverse_cholesky_factor(bad, message=lambda c: f"{len(c)} matrices, shape {c.shape}")
