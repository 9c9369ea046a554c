"""Property tests of pbdkit.prob.gaussian: the product of Gaussians against its definition (the
normalised product of the densities on a grid, and the covariance-form closed form computed
independently), its commutativity and associativity, and the information form's round trip."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import logsumexp
from scipy.stats import norm

from pbdkit.prob import gaussian as G

from .strategies import DETERMINISTIC, gaussian_factors, seeds

Factors = tuple[np.ndarray, np.ndarray, float]


def _product_of_two(
    m1: np.ndarray, s1: np.ndarray, m2: np.ndarray, s2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """N(m1, S1) N(m2, S2) in covariance form, no precision formed:
    S = S1 (S1 + S2)^-1 S2, m = S2 (S1 + S2)^-1 m1 + S1 (S1 + S2)^-1 m2."""
    total = s1 + s2
    cov = s1 @ np.linalg.solve(total, s2)
    mean = s2 @ np.linalg.solve(total, m1) + s1 @ np.linalg.solve(total, m2)
    return mean, 0.5 * (cov + cov.T)


def _assert_same_gaussian(
    got: tuple[np.ndarray, np.ndarray], expected: tuple[np.ndarray, np.ndarray], rtol: float
) -> None:
    """Means and covariances equal to ``rtol`` of the covariance's scale (entries near 0 of a
    covariance, and means near 0, get the tolerance of the largest entry)."""
    mean, cov = got
    ref_mean, ref_cov = expected
    sd = float(np.sqrt(np.abs(np.diagonal(ref_cov)).max()))
    np.testing.assert_allclose(mean, ref_mean, rtol=rtol, atol=rtol * sd)
    np.testing.assert_allclose(cov, ref_cov, rtol=rtol, atol=rtol * np.abs(ref_cov).max())


@settings(DETERMINISTIC, max_examples=60)
@given(factors=gaussian_factors(d=1))
def test_product_1d_is_the_normalised_product_of_the_densities(factors: Factors) -> None:
    means, covs, _ = factors
    mean, cov = G.gaussian_product(means, covs)
    # The grid spans 12 standard deviations of the product each way around its mean.
    m, sd = float(mean[0]), float(np.sqrt(cov[0, 0]))
    x = np.linspace(m - 12.0 * sd, m + 12.0 * sd, 4001)
    sds = np.sqrt(covs[:, 0, 0])
    log_p = norm.logpdf(x[:, None], means[:, 0], sds).sum(axis=1)
    p = np.exp(log_p - logsumexp(log_p))  # normalised on the grid
    grid_mean = float(p @ x)
    grid_var = float(p @ (x - grid_mean) ** 2)
    np.testing.assert_allclose(mean[0], grid_mean, rtol=0, atol=1e-9 * sd)
    np.testing.assert_allclose(cov[0, 0], grid_var, rtol=1e-8)


@settings(DETERMINISTIC, max_examples=100)
@given(factors=gaussian_factors())
def test_product_equals_the_covariance_form_folded_pairwise(factors: Factors) -> None:
    means, covs, _ = factors
    expected = (means[0], covs[0])
    for m, s in zip(means[1:], covs[1:], strict=True):
        expected = _product_of_two(*expected, m, s)
    _assert_same_gaussian(G.gaussian_product(means, covs), expected, rtol=1e-8)


@settings(DETERMINISTIC, max_examples=100)
@given(factors=gaussian_factors(min_n=2), seed=seeds)
def test_product_is_commutative(factors: Factors, seed: int) -> None:
    means, covs, _ = factors
    order = np.random.default_rng(seed).permutation(len(means))
    _assert_same_gaussian(
        G.gaussian_product(means[order], covs[order]), G.gaussian_product(means, covs), 1e-10
    )


@settings(DETERMINISTIC, max_examples=100)
@given(factors=gaussian_factors(min_n=3), split=st.integers(1, 2))
def test_product_is_associative(factors: Factors, split: int) -> None:
    # (A B ...)(... C) = A B ... C: the product of two partial products is the whole product.
    means, covs, _ = factors
    left = G.gaussian_product(means[:split], covs[:split])
    right = G.gaussian_product(means[split:], covs[split:])
    nested = G.gaussian_product(np.stack([left[0], right[0]]), np.stack([left[1], right[1]]))
    _assert_same_gaussian(nested, G.gaussian_product(means, covs), 1e-9)


@settings(DETERMINISTIC, max_examples=100)
@given(factors=gaussian_factors(max_n=1))
def test_a_gaussian_times_itself_halves_the_covariance(factors: Factors) -> None:
    means, covs, _ = factors
    twice = G.gaussian_product(np.concatenate([means, means]), np.concatenate([covs, covs]))
    _assert_same_gaussian(twice, (means[0], 0.5 * covs[0]), 1e-10)


@settings(DETERMINISTIC, max_examples=100)
@given(factors=gaussian_factors())
def test_information_form_round_trip(factors: Factors) -> None:
    means, covs, _ = factors
    eta, prec = G.information_from_gaussian(means, covs)
    assert eta.shape == means.shape and prec.shape == covs.shape
    np.testing.assert_array_equal(prec, np.swapaxes(prec, 1, 2))
    for m, s, e, p in zip(means, covs, eta, prec, strict=True):
        # Lambda Sigma = I and Lambda^-1 eta = mu (Lambda's condition number is at most 1e4).
        np.testing.assert_allclose(p @ s, np.eye(len(m)), rtol=0, atol=1e-10)
        np.testing.assert_allclose(
            np.linalg.solve(p, e), m, rtol=1e-10, atol=1e-10 * np.abs(m).max()
        )
        # One factor in information form is the Gaussian itself.
        _assert_same_gaussian(G.product_information(m[None], p[None]), (m, s), 1e-10)
    # The product from the information form is the product from the covariance form.
    _assert_same_gaussian(G.product_information(means, prec), G.gaussian_product(means, covs), 0)
