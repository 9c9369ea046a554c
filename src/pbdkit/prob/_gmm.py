"""The GMM estimator: a scikit-learn estimator over pbdkit's EM and its choice of K.

``__init__`` only stores its arguments; ``fit(X, y=None, *, groups=None)`` sets every learned
attribute (names ending in ``_``); ``score_samples``, ``predict_proba``, ``bic``, ``aic`` and
``sample`` are ``GaussianMixture``'s, computed with the log-density EM maximizes,

    log p(x) = log sum_k pi_k N(x; mu_k, Sigma_k)                  (log-sum-exp)

and ``regress`` is Gaussian mixture regression (paper Table I, :mod:`pbdkit.prob._gmr`). EM and
its floors are in :mod:`pbdkit.prob._em`, the choice of K in :mod:`pbdkit.prob._selection`; the
math behind both: ``docs/math.md``, "Gaussian mixtures and EM" and "Choosing K".
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray
from sklearn.base import BaseEstimator, DensityMixin
from sklearn.exceptions import NotFittedError

from .._defaults import MAX_COMPONENTS
from .._threads import one_blas_thread
from .._validation import check_array, check_int, check_positive_float, short
from ._calibration import normalized_residuals
from ._em import (
    MAX_TIME_SPREAD,
    MIN_TIME_SPREAD,
    _check_covariances,
    _check_time_floor,
    _em,
    _features,
    _Fit,
    _Floor,
    _log_resp,
    _precision_factors,
    _time_bins_resp,
    _weighted_log_prob,
    scale_aware_floor,
)
from ._gmr import CovarianceMode, GMRModel, gmr_batch, gmr_precompute, gmr_step, gmr_step_1d
from ._segments import TimeSegments
from ._selection import (
    SWEEP_TOL,
    FitRows,
    ModelSelection,
    SelectionWarning,
    _cv_errors,
    _cv_scale,
    _select_by_bic,
    _select_by_cv,
    cap_warning,
    n_parameters,
    sequences_from_time,
)

__all__ = ["GMM"]

Float = NDArray[np.float64]


def _check_max_time_spread(value: object, min_time_spread: float) -> float:
    """``max_time_spread``: a number >= ``min_time_spread`` and > 0, or inf (no ceiling)."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        v = float(value)
        if v == np.inf:
            return v
        v = check_positive_float(value, "max_time_spread")
        if v >= min_time_spread:
            return v
    raise ValueError(
        f"max_time_spread must be a number >= min_time_spread ({short(min_time_spread)}) and > 0, "
        f"or inf for no ceiling, got {short(value)}"
    )


def _check_rng(
    random_state: int | np.random.Generator | np.random.RandomState | None,
) -> np.random.Generator | np.random.RandomState:
    """A numpy generator from a seed (``default_rng``), or the generator given."""
    if isinstance(random_state, (np.random.Generator, np.random.RandomState)):
        return random_state
    if random_state is None or (
        isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool)
    ):
        return np.random.default_rng(random_state)
    raise ValueError(
        "random_state must be None, an integer, a numpy Generator or a numpy RandomState, "
        f"got {short(random_state)}"
    )


class GMM(DensityMixin, BaseEstimator):  # type: ignore[misc]  # scikit-learn is untyped
    """Gaussian mixture model with time-based EM initialisation and a choice of K.

    A scikit-learn estimator (``get_params``, ``set_params``, ``sklearn.base.clone``, its repr;
    :class:`sklearn.exceptions.NotFittedError` before ``fit``) with the methods of
    ``GaussianMixture`` (``score_samples``, ``score``, ``predict_proba``, ``predict``, ``bic``,
    ``aic``, ``sample``), all from the log-density EM maximizes. EM is pbdkit's own
    (``docs/math.md``, "Gaussian mixtures and EM"), not scikit-learn's loop.

    Parameters
    ----------
    n_components : int, "auto" or "bic"
        Number of components K; ``"auto"`` chooses K in 12..``max_components`` (from 1 for
        a cap of 12 or less; :data:`~pbdkit.prob._selection.MIN_COMPONENTS`) by
        cross-validation over the sequences (``docs/math.md``, "Choosing K"; needs a time
        column and at least 2 sequences); ``"bic"`` by the effective-sample-size BIC.
    max_components : int or None
        Largest K tried when K is chosen. None (default): :data:`MAX_COMPONENTS`, the cap
        :class:`pbdkit.Skill` and the command line use too.
    reg_covar : float, array-like of shape (D,), or None
        Added to the diagonal of every covariance: one value for every dimension, or one per
        dimension. In the units of the data squared, it is a floor on the variability a
        component can claim (scikit-learn's ``reg_covar``, per dimension). None (default):
        scale-aware, :data:`REG_COVAR` (1e-6) times each column's variance and at most 1e-6
        (``docs/math.md``, "Floors and scale"): scikit-learn's 1e-6 for columns of variance 1
        or more, 0.1 % of the standard deviation at smaller scales, so the fit scales with the
        data (milliseconds, nanometres). A given value is taken as is, in the data's units; a
        time floor above :data:`MAX_TIME_FLOOR_FRACTION` of the time column's variance is
        refused (it would blur every phase of the motion).
    max_iter : int
        Maximum number of EM iterations per fit.
    tol : float
        EM convergence threshold on the per-sample log-likelihood gain.
    random_state : int, numpy RandomState or None
        Seed of the k-means initialisation (``init="kmeans"``; time-based EM is deterministic)
        and of ``sample`` when it is given none.
    time_dim : int or None
        Column holding time; used for the time-based initialisation, to find the sequences and
        as the input of the GMR that ``"auto"`` cross-validates. ``None`` falls back to k-means
        initialisation.
    init : {"time", "kmeans"}
        Initialisation of EM. ``"time"``: K consecutive bins of equal count along time; where
        ``"auto"``'s score still falls at the cap from there, the sweep runs again from the K
        consecutive segments the data change least within (:class:`TimeSegments`: a long hold
        is one segment, not many), and the cap's warning comes only if that too ends there.
    score_dims : sequence of int, optional
        Dimensions whose GMR error ``"auto"`` scores (default: every dimension but time).
    bic_samples_per_sequence : float
        ``"bic"`` only: effective number of samples per sequence (default 20).
    bic_samples : int, optional
        ``"bic"`` only: total effective sample size; overrides ``bic_samples_per_sequence``.
    min_time_spread : float
        With a time column: every component's time standard deviation is at least this
        fraction of the components' spacing, ``min_time_spread * span / K`` (span: the range of
        the time column), which keeps EM from collapsing a component onto the samples of one
        time step (``docs/math.md``, "Time floor"). Only the time marginal of a component is
        widened; its regression p(x | t) is kept. 0 disables it. Default
        :data:`MIN_TIME_SPREAD`.
    max_time_spread : float
        With a time column: every component's time standard deviation is at most this
        fraction of the components' spacing, ``max_time_spread * span / K``, so that no
        component lends its regression to the phases of its neighbours (a hand held 10 cm above
        a box pulled the grasp up 2.5 mm; ``docs/math.md``, "Time ceiling"). Only the time
        marginal is narrowed; p(x | t) is kept. ``inf`` disables it; it must be at least
        ``min_time_spread``. Default :data:`MAX_TIME_SPREAD`.
    cv_scale : {"local", "pooled"}
        ``"auto"`` only: what a left-out demonstration's squared error is divided by. ``"local"``
        (default): the demonstrations' variance at that time (:func:`local_spread`, at least
        :data:`LOCAL_SPREAD_FLOOR` of the pooled one), so a phase where they agree weighs as
        much as it is tight; ``"pooled"``: their variance pooled over time
        (:func:`pooled_spread`; pbdkit's earlier default, which lost such phases where the
        demonstrations differ elsewhere). ``docs/math.md``, "Choosing K".
    loo_residuals : bool
        With a time column and at least 2 sequences: keep, for every row, how far it falls
        outside the regression of the model fitted without its sequence, in that model's own
        covariance (``loo_residuals_``; :mod:`pbdkit.prob._calibration`). About 1 where the
        model's covariance describes demonstrations it has not seen; much more where it is
        confident and they differ. Default False.

    Attributes
    ----------
    weights_ : ndarray, shape (K,)
    means_ : ndarray, shape (K, D)
    covariances_ : ndarray, shape (K, D, D)
    n_components_ : int
        K (chosen when ``n_components`` is ``"auto"`` or ``"bic"``). The repr shows the
        constructor's arguments only (scikit-learn's), so K is read here.
    n_features_in_ : int
        D, the number of columns of X (scikit-learn's name; also ``n_dims_``).
    converged_ : bool
        Whether EM converged for the kept model.
    n_iter_ : int
        EM iterations for the kept model.
    selection_ : ModelSelection
        The K tried, their scores and the K kept.
    bic_scores_ : dict of int to float
        ``"bic"``: effective BIC of every K tried; empty otherwise.
    bic_effective_samples_ : float
        ``"bic"``: n_eff used in the BIC; NaN otherwise.
    loo_residuals_ : ndarray, shape (N,)
        With ``loo_residuals``: z of every row of X, in X's order (empty otherwise).
    """

    def __init__(
        self,
        n_components: int | Literal["auto", "bic"] = 5,
        *,
        max_components: int | None = None,
        reg_covar: float | npt.ArrayLike | None = None,
        max_iter: int = 100,
        tol: float = 1e-3,
        random_state: int | np.random.RandomState | None = None,
        time_dim: int | None = 0,
        init: Literal["time", "kmeans"] = "time",
        score_dims: Sequence[int] | None = None,
        bic_samples_per_sequence: float = 20.0,
        bic_samples: int | None = None,
        min_time_spread: float = MIN_TIME_SPREAD,
        max_time_spread: float = MAX_TIME_SPREAD,
        cv_scale: Literal["local", "pooled"] = "local",
        loo_residuals: bool = False,
    ) -> None:
        self.n_components = n_components
        self.max_components = max_components
        self.reg_covar = reg_covar
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.time_dim = time_dim
        self.init = init
        self.score_dims = score_dims
        self.bic_samples_per_sequence = bic_samples_per_sequence
        self.bic_samples = bic_samples
        self.min_time_spread = min_time_spread
        self.max_time_spread = max_time_spread
        self.cv_scale = cv_scale
        self.loo_residuals = loo_residuals

    # ------------------------------------------------------------------ fitting
    def _check_params(self, x: Float) -> tuple[str, list[int], Float]:
        """Validated (method, candidate Ks, per-dimension floor) for the data x (N, D)."""
        n_samples, n_dims = x.shape
        reg = self.reg_covar
        if reg is None:
            floor = scale_aware_floor(x)
        elif np.ndim(reg) == 0:
            floor = np.full(n_dims, check_positive_float(reg, "reg_covar", allow_zero=True))
        else:
            floor = check_array(reg, "reg_covar", shape=(n_dims,))
            if np.any(floor < 0):
                raise ValueError(f"reg_covar must be >= 0 in every dimension, got {floor.tolist()}")
        check_int(self.max_iter, "max_iter", minimum=1)
        check_positive_float(self.tol, "tol", allow_zero=True)
        if self.cv_scale not in ("local", "pooled"):
            raise ValueError(f"cv_scale must be 'local' or 'pooled', got {short(self.cv_scale)}")
        if self.init not in ("time", "kmeans"):
            raise ValueError(f"init must be 'time' or 'kmeans', got {short(self.init)}")
        if self.time_dim is not None:
            td = check_int(self.time_dim, "time_dim", minimum=0)
            if td >= n_dims:
                raise ValueError(f"time_dim must be in [0, {n_dims}) for X with {n_dims} columns")
        _check_time_floor(x, floor, None if self.time_dim is None else int(self.time_dim))
        if isinstance(self.n_components, str):
            if self.n_components not in ("auto", "bic"):
                raise ValueError(
                    "n_components must be a positive integer, 'auto' or 'bic', "
                    f"got {short(self.n_components)}"
                )
            if self.n_components == "auto" and self.time_dim is None:
                raise ValueError(
                    "n_components='auto' cross-validates a regression on time and needs "
                    "time_dim; use n_components='bic' or an integer"
                )
            kmax = MAX_COMPONENTS if self.max_components is None else self.max_components
            kmax = check_int(kmax, "max_components", minimum=1)
            kmax = min(kmax, n_samples)
            return self.n_components, list(range(1, kmax + 1)), floor
        k = check_int(self.n_components, "n_components", minimum=1)
        if k > n_samples:
            raise ValueError(
                f"X has too few samples for n_components={k}: need at least {k} rows, "
                f"got {n_samples}; lower n_components or give more data"
            )
        return "fixed", [k], floor

    def _n_eff(self, n: int, n_seq: int) -> float:
        if self.bic_samples is not None:
            return float(min(check_int(self.bic_samples, "bic_samples", minimum=1), n))
        per = check_positive_float(self.bic_samples_per_sequence, "bic_samples_per_sequence")
        return float(min(n, per * n_seq))

    def _check_groups(self, groups: npt.ArrayLike | None, x: Float) -> NDArray[np.intp]:
        if groups is None:
            if self.time_dim is None:
                return np.zeros(x.shape[0], dtype=np.intp)
            return sequences_from_time(x[:, self.time_dim])
        g = np.asarray(groups)
        if g.shape != (x.shape[0],):
            raise ValueError(f"groups must have shape ({x.shape[0]},), got {g.shape}")
        _, labels = np.unique(g, return_inverse=True)
        return np.asarray(labels, dtype=np.intp).reshape(-1)

    def _initial_resp(self, x: Float, k: int, center: Float | None = None) -> Float:
        warm: GMM | None = getattr(self, "_warm", None)
        if warm is not None and center is not None and warm.n_components_ == k:
            # A warm start (pbdkit.Skill.update): the responsibilities of an earlier fit.
            return warm.predict_proba(x + center)
        if self.init == "time" and self.time_dim is not None:
            return _time_bins_resp(x, k, self.time_dim)
        from sklearn.cluster import KMeans

        labels = KMeans(n_clusters=k, n_init=1, random_state=self.random_state).fit(x).labels_
        resp = np.zeros((x.shape[0], k))
        resp[np.arange(x.shape[0]), labels] = 1.0
        return resp

    def fit(
        self, X: npt.ArrayLike, y: object = None, *, groups: npt.ArrayLike | None = None
    ) -> GMM:
        """Fit the mixture to X by EM (choosing K if asked).

        Parameters
        ----------
        X : array-like, shape (N, D)
            Samples in rows; column ``time_dim`` (0 by default) holds time.
        y : ignored
            Ignored, present for API consistency by convention (scikit-learn's
            ``fit(X, y)``: a Pipeline passes its targets here).
        groups : array-like, shape (N,), optional
            Keyword-only. Sequence (demonstration) of every row. Default: a new sequence
            wherever the time column decreases (stacked demonstrations), or one sequence
            without a time column.

        Returns
        -------
        self : GMM
        """
        x_raw = check_array(X, "X", ndim=2, min_rows=2)
        n, d = x_raw.shape
        method, candidates, diag = self._check_params(x_raw)
        spread = check_positive_float(self.min_time_spread, "min_time_spread", allow_zero=True)
        ceiling = _check_max_time_spread(self.max_time_spread, spread)
        # A constant column with no floor gives every component a zero variance there.
        flat = np.flatnonzero((np.ptp(x_raw, axis=0) == 0.0) & (diag <= 0.0))
        if flat.size:
            j = int(flat[0])
            also = f" (so are dimensions {flat[1:].tolist()})" if flat.size > 1 else ""
            raise ValueError(
                f"X[:, {j}] is constant ({short(float(x_raw[0, j]))}) and reg_covar is 0 there"
                f"{also}: every component would have zero variance in that dimension; "
                "increase reg_covar (e.g. 1e-6, or one value per dimension), or drop the column"
            )
        grp = self._check_groups(groups, x_raw)
        n_seq = int(grp.max()) + 1
        if method == "auto" and n_seq < 2:
            raise ValueError(
                "n_components='auto' leaves one sequence out at a time and needs at least 2 "
                f"sequences, got {n_seq}; pass groups=, or use n_components='bic' or an integer"
            )
        # One canonical row order (by sequence, then time): the fit does not depend on how the
        # rows were given. A shift of every mean leaves the mixture unchanged; centring keeps
        # the Mahalanobis expansion of _weighted_log_prob free of cancellation.
        order = np.lexsort((x_raw[:, self.time_dim], grp)) if self.time_dim is not None else None
        if order is not None:
            x_raw, grp = x_raw[order], grp[order]
        center = x_raw.mean(axis=0)
        x = x_raw - center
        feats = _features(x)
        max_iter, tol = int(self.max_iter), float(self.tol)
        fits: dict[int, _Fit] = {}
        if self.time_dim is None:
            floor = _Floor(diag)
        else:
            # Time standard deviations of K components: from spread * span / K to
            # ceiling * span / K.
            span = float(np.ptp(x[:, self.time_dim]))
            floor = _Floor(diag, int(self.time_dim), spread * span, ceiling * span)

        # Screening fits of a sweep stop at a looser tolerance; the kept one is refined below.
        sweep_tol = tol if method == "fixed" else max(tol, SWEEP_TOL)

        segments: TimeSegments | None = None  # the start of a second sweep, if any

        def fit_k(k: int) -> _Fit:
            if k not in fits:
                start = segments.resp(k) if segments else self._initial_resp(x, k, center)
                fits[k] = _em(x, start, floor, max_iter, sweep_tol)
            return fits[k]

        n_eff = float("nan")
        with one_blas_thread():
            if method == "auto":
                assert self.time_dim is not None
                td = int(self.time_dim)
                score_dims = self._check_score_dims(d, td)
                scale = _cv_scale(x, grp, td, score_dims, diag, self.cv_scale)

                def cv(k: int) -> Float:
                    return _cv_errors(
                        FitRows(x, feats, fit_k(k).resp, grp, floor, td), score_dims, scale
                    )

                self.selection_ = _select_by_cv(candidates, cv, n_seq)
                message = cap_warning(self.selection_, max(candidates))
                if message is not None and self.init == "time":
                    # Still falling at the cap from equal counts: the sweep again from the
                    # segments the data change least within (a hold is one, not many).
                    fits.clear()
                    segments = TimeSegments(x, td)
                    again = _select_by_cv(candidates, cv, n_seq)
                    self.selection_ = replace(again, start="segments")
                    message = cap_warning(self.selection_, max(candidates))
                if message is not None:
                    warnings.warn(message, SelectionWarning, stacklevel=2)
            elif method == "bic":
                n_eff = self._n_eff(n, n_seq)

                def log_likelihood(k: int) -> float:
                    return fit_k(k).log_likelihood

                self.selection_ = _select_by_bic(candidates, log_likelihood, n, n_eff, d)
            else:
                k = candidates[0]
                fit_k(k)
                # K given: its cross-validated error is still recorded (the score "auto" would
                # give it), where there are sequences to leave out.
                scores, folds, n_folds = np.asarray([float("nan")]), np.zeros((0, 0)), 0
                if self.time_dim is not None and n_seq >= 2 and k <= n:
                    td = int(self.time_dim)
                    score_dims = self._check_score_dims(d, td)
                    scale = _cv_scale(x, grp, td, score_dims, diag, self.cv_scale)
                    rows = FitRows(x, feats, fits[k].resp, grp, floor, td)
                    errors = _cv_errors(rows, score_dims, scale)
                    scores, folds, n_folds = np.asarray([errors.mean()]), errors[None], n_seq
                self.selection_ = ModelSelection(method, (k,), scores, folds, k, k, n_folds)
        chosen = self.selection_.chosen
        fit = fits[chosen]
        if sweep_tol > tol:
            with one_blas_thread():
                more = _em(x, fit.resp, floor, max_iter, tol)
            fit = more._replace(n_iter=fit.n_iter + more.n_iter)
        weights, means, cov = fit.params
        self.loo_residuals_ = np.zeros(0)
        if self.loo_residuals and self.time_dim is not None and n_seq >= 2:
            td = int(self.time_dim)
            score_dims = self._check_score_dims(d, td)
            with one_blas_thread():
                z = normalized_residuals(FitRows(x, feats, fit.resp, grp, floor, td), score_dims)
            self.loo_residuals_ = np.empty_like(z)
            self.loo_residuals_[order if order is not None else slice(None)] = z
        self.weights_ = np.asarray(weights, dtype=np.float64)
        self.means_ = np.asarray(means + center, dtype=np.float64)
        self.covariances_ = 0.5 * (cov + np.swapaxes(cov, -1, -2))
        self.n_components_ = int(self.weights_.shape[0])
        self.converged_ = bool(fit.converged)
        self.n_iter_ = int(fit.n_iter)
        sel = self.selection_
        self.bic_scores_ = (
            dict(zip(sel.candidates, sel.scores.tolist(), strict=True)) if method == "bic" else {}
        )
        self.bic_effective_samples_ = n_eff
        self._finalize()
        return self

    def _check_score_dims(self, n_dims: int, time_dim: int) -> list[int]:
        if self.score_dims is None:
            return [i for i in range(n_dims) if i != time_dim]
        dims = [check_int(i, "score_dims", minimum=0) for i in self.score_dims]
        if (
            not dims
            or any(i >= n_dims or i == time_dim for i in dims)
            or len(set(dims)) < len(dims)
        ):
            raise ValueError(
                f"score_dims must be distinct dimensions in [0, {n_dims}) other than time "
                f"({time_dim}), got {list(self.score_dims)}"
            )
        return dims

    @classmethod
    def from_params(
        cls, weights: npt.ArrayLike, means: npt.ArrayLike, covariances: npt.ArrayLike
    ) -> GMM:
        """A fitted GMM from given parameters, without EM.

        Parameters
        ----------
        weights : array-like, shape (K,)
            Non-negative, summing to 1.
        means : array-like, shape (K, D)
        covariances : array-like, shape (K, D, D)
            Symmetric positive definite.

        Returns
        -------
        gmm : GMM
        """
        w = check_array(weights, "weights", ndim=1, min_rows=1)
        k = w.shape[0]
        m = check_array(means, "means", shape=(k, None))
        d = m.shape[1]
        c = check_array(covariances, "covariances", shape=(k, d, d))
        if np.any(w < 0):
            raise ValueError(f"weights must be >= 0, got min {w.min():.3g}")
        if not np.isclose(w.sum(), 1.0, rtol=0, atol=1e-8):
            raise ValueError(f"weights must sum to 1, got {w.sum():.12g}")
        _check_covariances(c, "covariances")
        gmm = cls(n_components=k)
        gmm.weights_ = w.copy()
        gmm.means_ = m.copy()
        gmm.covariances_ = c.copy()
        gmm.n_components_ = k
        gmm.converged_ = True
        gmm.n_iter_ = 0
        gmm.bic_scores_ = {}
        gmm.bic_effective_samples_ = float("nan")
        gmm.loo_residuals_ = np.zeros(0)
        gmm.selection_ = ModelSelection(
            "fixed", (k,), np.full(1, np.nan), np.zeros((0, 0)), k, k, 0
        )
        gmm._finalize()
        return gmm

    def _finalize(self) -> None:
        # What every density needs, computed once: the upper precision factors, and the centre
        # (sum_k pi_k mu_k: after an M-step the data mean that fit centres by, up to rounding)
        # that keeps the expansion of _weighted_log_prob free of cancellation.
        self.n_features_in_ = int(self.means_.shape[1])
        self._prec_factors = _precision_factors(self.covariances_)
        self._center = np.asarray(self.weights_ @ self.means_, dtype=np.float64)
        self._gmr_cache: dict[tuple[int, ...], GMRModel] = {}

    def __sklearn_is_fitted__(self) -> bool:
        return hasattr(self, "covariances_")

    def _check_fitted(self) -> None:
        if not hasattr(self, "covariances_"):
            raise NotFittedError(
                "this GMM is not fitted yet: call fit(X) or build it with GMM.from_params(...)"
            )

    # --------------------------------------------------------------- densities
    @property
    def n_dims_(self) -> int:
        self._check_fitted()
        return int(self.means_.shape[1])

    def _check_X(self, X: npt.ArrayLike, name: str = "X") -> Float:
        self._check_fitted()
        return check_array(X, name, shape=(None, self.n_dims_))

    def _densities(self, X: npt.ArrayLike) -> tuple[Float, Float]:
        """p(k | x) (N, K) and log p(x) (N,): the density EM maximizes (_weighted_log_prob)."""
        x = self._check_X(X) - self._center
        lp = _weighted_log_prob(
            _features(x), self.weights_, self.means_ - self._center, self._prec_factors
        )
        resp, log_density = _log_resp(lp)
        return np.ascontiguousarray(resp), log_density

    def score_samples(self, X: npt.ArrayLike) -> Float:
        """Log-density of the mixture at each sample.

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        log_density : ndarray, shape (N,)
        """
        return self._densities(X)[1]

    def score(self, X: npt.ArrayLike, y: object = None) -> float:
        """Mean log-likelihood per sample of X (scikit-learn's ``score``; higher is better).

        Parameters
        ----------
        X : array-like, shape (N, D)
        y : ignored
            For scikit-learn's API (model selection tools pass it).

        Returns
        -------
        score : float
        """
        return float(np.mean(self.score_samples(X)))

    def _information_criterion(self, X: npt.ArrayLike, penalty: Callable[[int], float]) -> float:
        log_density = self.score_samples(X)
        p = n_parameters(self.n_components_, self.n_dims_)
        return float(-2.0 * log_density.sum() + p * penalty(log_density.shape[0]))

    def bic(self, X: npt.ArrayLike) -> float:
        """Standard Bayesian information criterion on X: -2 log L(X) + p log N (lower is better).

        p = (K - 1) + K D + K D (D + 1) / 2 free parameters (:func:`n_parameters`).

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        bic : float
        """
        return self._information_criterion(X, lambda n: float(np.log(n)))

    def aic(self, X: npt.ArrayLike) -> float:
        """Akaike information criterion on X: -2 log L(X) + 2 p (lower is better).

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        aic : float
        """
        return self._information_criterion(X, lambda n: 2.0)

    def predict_proba(self, X: npt.ArrayLike) -> Float:
        """Responsibilities p(k | x) of each component for each sample.

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        resp : ndarray, shape (N, K)
        """
        return self._densities(X)[0]

    def predict(self, X: npt.ArrayLike) -> NDArray[np.intp]:
        """The most probable component of each sample, argmax_k p(k | x).

        Parameters
        ----------
        X : array-like, shape (N, D)

        Returns
        -------
        labels : ndarray of int, shape (N,)
        """
        return np.asarray(np.argmax(self.predict_proba(X), axis=1), dtype=np.intp)

    def sample(
        self,
        n_samples: int = 1,
        random_state: int | np.random.Generator | np.random.RandomState | None = None,
    ) -> tuple[Float, NDArray[np.intp]]:
        """Draw samples from the mixture (as scikit-learn's ``GaussianMixture.sample``).

        The number of samples of each component is multinomial with the weights; each sample is
        mu_k + L_k z with Sigma_k = L_k L_k^T (Cholesky) and z standard normal. As in
        scikit-learn, the rows are grouped by component (all of component 0 first).

        Parameters
        ----------
        n_samples : int
            Number of samples, >= 1.
        random_state : int, numpy Generator, numpy RandomState or None
            Source of randomness: an integer seeds ``numpy.random.default_rng``; ``None``
            uses the estimator's ``random_state`` (as scikit-learn does), and without one,
            fresh entropy.

        Returns
        -------
        X : ndarray, shape (n_samples, D)
        labels : ndarray of int, shape (n_samples,)
            Component of each sample.
        """
        self._check_fitted()
        n = check_int(n_samples, "n_samples", minimum=1)
        rng = _check_rng(self.random_state if random_state is None else random_state)
        w = self.weights_ / self.weights_.sum()  # from_params allows a sum 1e-8 off 1
        counts = rng.multinomial(n, w)
        chol = np.linalg.cholesky(self.covariances_)
        z = rng.standard_normal((n, self.n_dims_))
        labels = np.repeat(np.arange(self.n_components_, dtype=np.intp), counts)
        x = np.empty_like(z)
        stop = np.cumsum(counts)
        for k, (a, b) in enumerate(zip(stop - counts, stop, strict=True)):
            x[a:b] = self.means_[k] + z[a:b] @ chol[k].T
        return x, labels

    # --------------------------------------------------------------- regression
    def _gmr_model(self, in_dims: Sequence[int] | int) -> GMRModel:
        self._check_fitted()
        d = self.n_dims_
        dims_seq = [in_dims] if isinstance(in_dims, (int, np.integer)) else list(in_dims)
        dims: list[int] = []
        for i in dims_seq:
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)):
                raise ValueError(f"in_dims must hold integers, got {short(i)}")
            dims.append(int(i))
        if not dims:
            raise ValueError("in_dims must hold at least one dimension, got []")
        if any(i < 0 or i >= d for i in dims):
            raise ValueError(f"in_dims must be in [0, {d}) for a GMM of {d} dimensions, got {dims}")
        if len(set(dims)) != len(dims):
            raise ValueError(f"in_dims must be distinct, got {dims}")
        if len(dims) == d:
            raise ValueError(
                f"in_dims must leave at least one output dimension, got all {d} dimensions"
            )
        key = tuple(dims)
        model = self._gmr_cache.get(key)
        if model is None:
            model = gmr_precompute(self.weights_, self.means_, self.covariances_, key)
            self._gmr_cache[key] = model
        return model

    @staticmethod
    def _check_covariance_mode(covariance: str) -> CovarianceMode:
        if covariance not in ("exact", "paper"):
            raise ValueError(f"covariance must be 'exact' or 'paper', got {short(covariance)}")
        return covariance  # type: ignore[return-value]

    def regress(
        self,
        X_in: npt.ArrayLike,
        in_dims: Sequence[int] | int = (0,),
        covariance: CovarianceMode = "exact",
    ) -> tuple[Float, Float]:
        """Gaussian mixture regression: p(xi^O | xi^I = x) for every row of X_in (paper Table I).

        Parameters
        ----------
        X_in : array-like, shape (T, len(in_dims))
            Query values of the input dimensions (shape (T,) is accepted for one input).
        in_dims : sequence of int
            Input dimensions; the outputs are all the other dimensions, in order.
        covariance : {"exact", "paper"}
            ``"exact"``: the covariance of the conditional mixture,
            sum_k beta_k (C_k + m_k m_k^T) - m m^T. ``"paper"``: sum_k beta_k^2 C_k.

        Returns
        -------
        mean : ndarray, shape (T, D_out)
        cov : ndarray, shape (T, D_out, D_out)
        """
        model = self._gmr_model(in_dims)
        mode = self._check_covariance_mode(covariance)
        d_in = len(model.in_dims)
        x = check_array(X_in, "X_in", ndim=(1, 2))
        if x.ndim == 1 and d_in == 1:
            x = x[:, None]
        if x.ndim != 2 or x.shape[1] != d_in:
            raise ValueError(
                f"X_in must have shape (T, {d_in}) for in_dims={list(model.in_dims)}, got {x.shape}"
            )
        mean, cov = gmr_batch(model, x, mode)
        assert cov is not None
        return mean, cov

    def regress_one(
        self,
        x_in: npt.ArrayLike,
        in_dims: Sequence[int] | int = (0,),
        covariance: CovarianceMode = "exact",
    ) -> tuple[Float, Float]:
        """GMR at a single query, with minimal overhead (for a control loop).

        Parameters
        ----------
        x_in : array-like, shape (len(in_dims),) or scalar for one input
        in_dims : sequence of int
        covariance : {"exact", "paper"}

        Returns
        -------
        mean : ndarray, shape (D_out,)
        cov : ndarray, shape (D_out, D_out)
        """
        try:
            model = self._gmr_cache[in_dims]  # type: ignore[index]
        except (KeyError, TypeError, AttributeError):
            model = self._gmr_model(in_dims)
        mode: str = covariance
        if mode != "exact" and mode != "paper":
            self._check_covariance_mode(mode)
        d_in = len(model.in_dims)
        query: object = x_in
        if d_in == 1 and mode == "exact" and isinstance(query, float) and math.isfinite(query):
            mean, cov = gmr_step_1d(model, query)  # the control-loop fast path
        else:
            x = np.asarray(x_in, dtype=np.float64).reshape(-1)
            if x.shape[0] != d_in or not np.isfinite(x).all():
                raise ValueError(
                    f"x_in must be {d_in} finite value(s) for in_dims={list(model.in_dims)}, "
                    f"got {short(np.asarray(x_in))}"
                )
            mean, cov = gmr_step(model, x, covariance)
        assert cov is not None
        return mean, cov
