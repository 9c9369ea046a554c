"""GMM: the scikit-learn estimator (parameters, fit, densities, sampling, from_params), errors."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import sklearn
from mixture_data import trajectories
from scipy.special import logsumexp
from scipy.stats import multivariate_normal
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.mixture import GaussianMixture
from sklearn.utils import estimator_checks
from sklearn.utils.validation import check_is_fitted

from pbdkit import GMM
from pbdkit._defaults import MAX_COMPONENTS
from pbdkit.prob import SelectionWarning


def _known_model() -> GMM:
    """Two well-separated, correlated components in 2-D."""
    return GMM.from_params(
        [0.3, 0.7],
        [[0.0, 0.0], [3.0, -1.0]],
        [[[1.0, 0.5], [0.5, 2.0]], [[0.3, -0.1], [-0.1, 0.2]]],
    )


def test_fit_sets_learned_attributes_with_shapes() -> None:
    rng = np.random.default_rng(0)
    x = trajectories(rng)
    gmm = GMM(4).fit(x)
    assert gmm.n_components_ == 4
    assert gmm.weights_.shape == (4,)
    assert gmm.means_.shape == (4, 3)
    assert gmm.covariances_.shape == (4, 3, 3)
    np.testing.assert_allclose(gmm.weights_.sum(), 1.0, atol=1e-12)
    np.testing.assert_allclose(gmm.covariances_, np.swapaxes(gmm.covariances_, 1, 2))
    assert gmm.converged_
    # Time-based initialisation: components ordered along time.
    assert np.all(np.diff(gmm.means_[:, 0]) > 0)


def test_init_stores_arguments_only() -> None:
    gmm = GMM("bic", max_components=3, reg_covar=1e-4, random_state=3)
    assert gmm.n_components == "bic" and gmm.max_components == 3 and gmm.random_state == 3
    assert not hasattr(gmm, "weights_")


def test_get_params_lists_every_constructor_argument() -> None:
    gmm = GMM("auto", max_components=7, reg_covar=np.array([1e-6, 1e-3, 1e-3]), score_dims=[1])
    params = gmm.get_params()
    assert set(params) == set(inspect.signature(GMM.__init__).parameters) - {"self"}
    for name, value in params.items():
        assert value is getattr(gmm, name), name


def test_clone_gives_an_unfitted_estimator_with_equal_params() -> None:
    rng = np.random.default_rng(21)
    x = trajectories(rng)
    gmm = GMM(3, reg_covar=np.array([1e-6, 1e-4, 1e-4]), tol=1e-4, random_state=5).fit(x)
    copy = clone(gmm)
    assert type(copy) is GMM and copy is not gmm
    assert not hasattr(copy, "weights_") and not hasattr(copy, "n_components_")
    with pytest.raises(NotFittedError):
        check_is_fitted(copy)
    check_is_fitted(gmm)
    a, b = gmm.get_params(), copy.get_params()
    assert set(a) == set(b)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name])
    assert b["reg_covar"] is not a["reg_covar"]  # a copy: refitting one leaves the other alone
    np.testing.assert_array_equal(copy.fit(x).means_, gmm.means_)


def test_set_params_round_trip_and_repr() -> None:
    gmm = GMM()
    assert gmm.set_params(n_components="bic", max_components=4, tol=1e-5) is gmm
    assert gmm.get_params()["n_components"] == "bic" and gmm.tol == 1e-5
    assert GMM(**gmm.get_params()).get_params() == gmm.get_params()
    with pytest.raises(ValueError, match="Invalid parameter 'n_states' for estimator"):
        gmm.set_params(n_states=3)
    # scikit-learn's repr: the arguments that differ from the defaults, before and after fit.
    assert repr(GMM()) == "GMM()"
    assert repr(gmm) == "GMM(max_components=4, n_components='bic', tol=1e-05)"
    gmm.fit(trajectories(np.random.default_rng(22), n_demos=2, n_steps=50))
    assert repr(gmm) == "GMM(max_components=4, n_components='bic', tol=1e-05)"


@pytest.mark.parametrize(
    "check",
    [
        "check_get_params_invariance",
        "check_set_params",
        "check_estimator_cloneable",
        "check_estimator_repr",
        "check_parameters_default_constructible",
        "check_no_attributes_set_in_init",
        "check_do_not_raise_errors_in_init_or_set_params",
        "check_dont_overwrite_parameters",
        "check_estimators_overwrite_params",
        "check_estimators_unfitted",
        "check_fit_check_is_fitted",
        "check_n_features_in",
        "check_estimators_pickle",
        "check_fit_idempotent",
    ],
)
def test_scikit_learn_estimator_checks(check: str) -> None:
    if not hasattr(estimator_checks, check):  # added in later scikit-learn versions
        pytest.skip(f"{check} is not in scikit-learn {sklearn.__version__}")
    getattr(estimator_checks, check)("GMM", GMM())


_UNFITTED_CALLS: dict[str, Callable[[GMM], Any]] = {
    "score_samples": lambda g: g.score_samples(np.zeros((2, 2))),
    "score": lambda g: g.score(np.zeros((2, 2))),
    "predict_proba": lambda g: g.predict_proba(np.zeros((2, 2))),
    "predict": lambda g: g.predict(np.zeros((2, 2))),
    "bic": lambda g: g.bic(np.zeros((2, 2))),
    "aic": lambda g: g.aic(np.zeros((2, 2))),
    "sample": lambda g: g.sample(3),
    "regress": lambda g: g.regress(np.zeros((2, 1))),
    "regress_one": lambda g: g.regress_one(0.5),
    "n_dims_": lambda g: g.n_dims_,
}


@pytest.mark.parametrize("method", sorted(_UNFITTED_CALLS))
@pytest.mark.parametrize("fresh", [True, False])
def test_every_method_raises_not_fitted_error_before_fit(method: str, fresh: bool) -> None:
    # A new estimator, and a clone of a fitted one.
    gmm = GMM(2) if fresh else clone(_known_model())
    with pytest.raises(NotFittedError, match=r"not fitted yet: call fit\(X\) or build it") as err:
        _UNFITTED_CALLS[method](gmm)
    assert isinstance(err.value, ValueError) and isinstance(err.value, AttributeError)


def test_time_based_fit_is_deterministic() -> None:
    rng = np.random.default_rng(1)
    x = trajectories(rng)
    a = GMM(5, random_state=0).fit(x)
    b = GMM(5, random_state=123).fit(x)
    np.testing.assert_array_equal(a.means_, b.means_)


def test_score_samples_and_bic_equal_scikit_learn() -> None:
    rng = np.random.default_rng(3)
    x = trajectories(rng)
    gmm = GMM(3).fit(x)
    sk = GaussianMixture(3, covariance_type="full")
    sk.weights_, sk.means_, sk.covariances_ = gmm.weights_, gmm.means_, gmm.covariances_
    sk.precisions_cholesky_ = np.linalg.cholesky(np.linalg.inv(gmm.covariances_))
    np.testing.assert_allclose(gmm.score_samples(x), sk.score_samples(x), rtol=1e-10)
    np.testing.assert_allclose(gmm.bic(x), sk.bic(x), rtol=1e-10)
    resp = gmm.predict_proba(x)
    np.testing.assert_allclose(resp, sk.predict_proba(x), atol=1e-10)
    np.testing.assert_allclose(gmm.aic(x), sk.aic(x), rtol=1e-10)
    np.testing.assert_allclose(gmm.score(x), sk.score(x), rtol=1e-10)
    np.testing.assert_array_equal(gmm.predict(x), sk.predict(x))
    # Away from the data too (the expansion of _weighted_log_prob is centred on the mixture).
    q = rng.uniform(-3.0, 3.0, x.shape)
    np.testing.assert_allclose(gmm.score_samples(q), sk.score_samples(q), rtol=1e-10)
    np.testing.assert_allclose(gmm.predict_proba(q), sk.predict_proba(q), atol=1e-10)


def test_aic_bic_and_score_against_an_independent_log_likelihood() -> None:
    rng = np.random.default_rng(20)
    gmm = _known_model()
    x = rng.normal(size=(50, 2)) * 2.0
    # Independent: scipy's densities, log L = sum_j log sum_k pi_k N(x_j; mu_k, Sigma_k).
    log_pdf = np.column_stack(
        [
            np.log(w) + multivariate_normal(m, c).logpdf(x)
            for w, m, c in zip(gmm.weights_, gmm.means_, gmm.covariances_, strict=True)
        ]
    )
    log_density = logsumexp(log_pdf, axis=1)
    log_l = float(log_density.sum())
    p = 1 + 2 * 2 + 2 * 3  # (K - 1) weights, K D means, K D (D + 1) / 2 covariances
    np.testing.assert_allclose(gmm.score_samples(x), log_density, rtol=1e-12)
    assert gmm.aic(x) == pytest.approx(-2.0 * log_l + 2.0 * p, rel=1e-12)
    assert gmm.bic(x) == pytest.approx(-2.0 * log_l + p * np.log(len(x)), rel=1e-12)
    assert gmm.score(x) == pytest.approx(log_l / len(x), rel=1e-12)
    assert gmm.score(x) == float(np.mean(gmm.score_samples(x)))
    resp = np.exp(log_pdf - log_density[:, None])
    np.testing.assert_allclose(gmm.predict_proba(x), resp, atol=1e-12)
    np.testing.assert_array_equal(gmm.predict(x), np.argmax(resp, axis=1))


def test_sample_statistics_match_the_model() -> None:
    gmm = _known_model()
    n = 200_000
    x, labels = gmm.sample(n, random_state=0)
    assert x.shape == (n, 2) and labels.shape == (n,) and labels.dtype == np.intp
    # Component frequencies: binomial, standard error sqrt(w (1 - w) / n) = 0.001.
    np.testing.assert_allclose(np.bincount(labels) / n, gmm.weights_, atol=0.005)
    # Rows grouped by component, as scikit-learn's.
    assert np.all(np.diff(labels) >= 0)
    for k in range(2):
        xk = x[labels == k]
        cov = gmm.covariances_[k]
        se_mean = np.sqrt(np.diag(cov) / len(xk))
        np.testing.assert_allclose(xk.mean(axis=0), gmm.means_[k], atol=5 * se_mean.max())
        # Standard error of a sample covariance entry: sqrt((S_ii S_jj + S_ij^2) / n).
        se_cov = np.sqrt((np.outer(np.diag(cov), np.diag(cov)) + cov**2) / len(xk))
        assert np.all(np.abs(np.cov(xk.T) - cov) <= 5 * se_cov)
    # The mixture's moments: m = sum_k pi_k mu_k, S = sum_k pi_k (Sigma_k + mu_k mu_k^T) - m m^T.
    w, mu, sigma = gmm.weights_, gmm.means_, gmm.covariances_
    m = w @ mu
    s = np.einsum("k,kij->ij", w, sigma + mu[:, :, None] * mu[:, None, :]) - np.outer(m, m)
    np.testing.assert_allclose(x.mean(axis=0), m, atol=0.02)
    np.testing.assert_allclose(np.cov(x.T), s, atol=0.03)


def test_sample_is_seeded() -> None:
    gmm = _known_model()
    a, la = gmm.sample(100, random_state=3)
    b, lb = gmm.sample(100, random_state=np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(la, lb)
    assert not np.array_equal(a, gmm.sample(100, random_state=4)[0])
    # Without a random_state, the estimator's (scikit-learn's rule).
    seeded = _known_model().set_params(random_state=3)
    np.testing.assert_array_equal(seeded.sample(100)[0], a)
    np.testing.assert_array_equal(seeded.sample(100)[0], a)  # an integer seed: same draws
    x, labels = gmm.sample(random_state=np.random.RandomState(0))
    assert x.shape == (1, 2) and labels.shape == (1,)
    with pytest.raises(ValueError, match="n_samples must be >= 1, got 0"):
        gmm.sample(0)
    with pytest.raises(ValueError, match="random_state must be None, an integer"):
        gmm.sample(2, random_state="seed")  # type: ignore[arg-type]


def test_from_params_round_trip_and_errors() -> None:
    rng = np.random.default_rng(6)
    x = trajectories(rng)
    gmm = GMM(3).fit(x)
    copy = GMM.from_params(gmm.weights_, gmm.means_, gmm.covariances_)
    np.testing.assert_array_equal(copy.score_samples(x), gmm.score_samples(x))
    bad = gmm.covariances_.copy()
    bad[1] = np.diag([1.0, 1.0, 0.0])
    with pytest.raises(ValueError, match=r"covariances\[1\] must be positive definite"):
        GMM.from_params(gmm.weights_, gmm.means_, bad)
    with pytest.raises(ValueError, match="weights must sum to 1"):
        GMM.from_params(gmm.weights_ * 2, gmm.means_, gmm.covariances_)
    with pytest.raises(ValueError, match="weights must be >= 0"):
        GMM.from_params([1.5, -0.5, 0.0], gmm.means_, gmm.covariances_)
    with pytest.raises(ValueError, match=r"means must have shape \(3, \*\)"):
        GMM.from_params(gmm.weights_, gmm.means_[:2], gmm.covariances_)
    with pytest.raises(ValueError, match=r"covariances must have shape \(3, 3, 3\)"):
        GMM.from_params(gmm.weights_, gmm.means_, gmm.covariances_[:, :2, :2])
    asym = gmm.covariances_.copy()
    asym[0, 0, 1] += 1.0
    with pytest.raises(ValueError, match=r"covariances\[0\] must be symmetric"):
        GMM.from_params(gmm.weights_, gmm.means_, asym)


def test_fit_bad_input() -> None:
    with pytest.raises(ValueError, match="X must be 2-D"):
        GMM(2).fit(np.zeros(10))
    with pytest.raises(ValueError, match="X must be finite"):
        GMM(2).fit(np.array([[0.0, 1.0], [np.inf, 2.0], [1.0, 2.0]]))
    with pytest.raises(ValueError, match="too few samples for n_components=5"):
        GMM(5).fit(np.random.default_rng(0).random((3, 2)))
    with pytest.raises(ValueError, match="X must have at least 2 rows"):
        GMM(1).fit(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="n_components must be a positive integer, 'auto' or"):
        GMM("aic").fit(np.zeros((5, 2)))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="n_components must be >= 1"):
        GMM(0).fit(np.zeros((5, 2)))
    with pytest.raises(ValueError, match=r"time_dim must be in \[0, 2\)"):
        GMM(1, time_dim=2).fit(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="reg_covar must be finite and >= 0"):
        GMM(1, reg_covar=-1.0).fit(np.zeros((5, 2)))
    gmm = GMM(1).fit(np.random.default_rng(0).random((10, 2)))
    with pytest.raises(ValueError, match=r"X must have shape \(\*, 2\)"):
        gmm.score_samples(np.zeros((3, 3)))


@pytest.mark.parametrize("n_components", [1, 3, "auto", "bic"])
@pytest.mark.parametrize("init", ["time", "kmeans"])
def test_constant_column_without_reg_covar_names_the_dimension(
    n_components: int | str, init: str
) -> None:
    t = np.tile(np.linspace(0.0, 10.0, 40), 3)
    x = np.column_stack([t, np.sin(t), np.full(t.size, 0.1)])
    gmm = GMM(n_components, reg_covar=0.0, init=init, max_components=3)  # type: ignore[arg-type]
    with pytest.raises(
        ValueError, match=r"X\[:, 2\] is constant \(0.1\) and reg_covar is 0 there.*reg_covar \(e"
    ):
        gmm.fit(x)
    # A floor in that dimension alone is enough.
    GMM(2, reg_covar=[0.0, 0.0, 1e-6], init=init, random_state=0).fit(x)


def test_a_component_without_variance_names_the_component_and_dimension() -> None:
    # The gripper-like column is 0 over the first half of time and 1 over the second: each
    # time bin of the initialisation holds one value only.
    t = np.tile(np.linspace(0.0, 10.0, 40), 3)
    x = np.column_stack([t, np.sin(t), (t > 5.0).astype(float)])
    with pytest.raises(
        ValueError,
        match=r"component 0 has variance 0 in dimension 2 \(degenerate data\); increase reg_covar",
    ):
        GMM(2, reg_covar=0.0).fit(x)


# ----------------------------------------------------------------------------- API (issue 22)
def test_max_components_default_is_the_module_cap() -> None:
    # GMM(max_components=10) used to disagree with MAX_COMPONENTS = 30 (Skill's and the CLI's).
    assert GMM().max_components is None and repr(GMM()) == "GMM()"
    x = trajectories(np.random.default_rng(30), n_demos=3, n_steps=40)
    gmm = GMM("auto", min_time_spread=0.0).fit(x)
    assert max(gmm.selection_.candidates) == MAX_COMPONENTS
    with pytest.warns(SelectionWarning, match="K is at the cap, max_components=5"):
        capped = GMM("auto", max_components=5, min_time_spread=0.0).fit(x)
    assert max(capped.selection_.candidates) == 5


def test_fit_has_scikit_learns_signature_and_ignores_y() -> None:
    fit = inspect.signature(GMM.fit).parameters
    assert list(fit)[:3] == ["self", "X", "y"] and fit["y"].default is None
    assert fit["groups"].kind is inspect.Parameter.KEYWORD_ONLY
    # A Pipeline's y (targets, or integer labels) is ignored, without a warning: groups are
    # keyword-only.
    x = trajectories(np.random.default_rng(32), n_demos=2, n_steps=50)
    plain = GMM(3).fit(x)
    labels = np.arange(len(x))
    for y in (np.linspace(0.0, 1.0, len(x)), labels, np.arange(len(x) - 1), [[1, 2]], "labels"):
        np.testing.assert_array_equal(GMM(3).fit(x, y).means_, plain.means_)
    both = GMM(3).fit(x, np.arange(len(x)), groups=np.repeat([0, 1], 50))
    np.testing.assert_array_equal(both.means_, plain.means_)
