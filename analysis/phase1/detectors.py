"""The six Phase I fault detectors of the paper (section IV, Fig. 6, Table III) as scikit-learn
estimators (the autoencoder is in :mod:`analysis.phase1.autoencoder`).

Common contract (all detectors):

- ``fit(X, y=None)``: X (N, p) baseline samples (the paper's first 15 samples), standardised
  features; y is ignored. Sets ``threshold_`` and ``n_features_in_``.
- ``decision_function(X)``: (n,) novelty score oriented so that **score > threshold_ is an alarm**.
  For the detectors with a moving average (GMM-MD, OC-SVM: ``moving_average=4``) the rows of X must
  be consecutive samples in time order; the average is trailing over those rows.
- ``score_samples(X)``: (n,) the same score without the moving average.
- ``predict(X)``: (n,) int, **1 = alarm, 0 = normal** (not scikit-learn's outlier convention of
  -1/1, which this package does not use anywhere).
- ``threshold_``: float, the control limit on the score.

Control limits for new samples. The baseline is small (the paper's 15 samples), and a limit
computed from the scores of the very samples a flexible model was fitted on is biased low: those
samples score lower than new healthy samples do (the apparent-error bias of Efron 1983, JASA 78,
316-331; Hastie, Tibshirani & Friedman, *The Elements of Statistical Learning*, 2nd ed., 2009,
section 7.4). Measured on the gate's healthy campaigns (docs/ci-gate.md): SOM-MQE's in-sample
baseline MQE has mean 0.98, new healthy samples 3.03, so 11 of 30 crossed its three-sigma limit.
By default (``limit="cv"``) the score-based detectors (SOM-MQE, Isolation Forest, autoencoder)
therefore apply their limit rule to **out-of-fold** baseline scores: the baseline rows are split
into ``cv`` contiguous blocks in time order (blocked cross-validation; Roberts et al. 2017,
Ecography 40, 913-929), each block is scored by a copy fitted on the other rows, and the final
model is fitted on all rows. GMM-MD uses the exact F limit for new observations instead of the
beta limit for the baseline's own points (Tracy, Young & Mason 1992). ``limit="paper"`` gives the
paper's limits. PCA-T² and the one-class SVM already have limits for new samples.

Library conventions are those of the scikit-learn documentation cited per class.
Every random draw comes from ``random_state``.
"""

from __future__ import annotations

import numpy as np
from minisom import MiniSom
from sklearn.base import BaseEstimator, clone
from sklearn.decomposition import PCA
from sklearn.ensemble import IsolationForest
from sklearn.mixture import GaussianMixture
from sklearn.svm import OneClassSVM
from sklearn.utils.validation import check_is_fitted, validate_data

from analysis.base.registry import register
from analysis.params import InheritedParams
from analysis.phase1 import limits

__all__ = ["GMMMD", "OCSVM", "PCAT2", "SOMMQE", "IForest", "PhaseIDetector"]


class PhaseIDetector(InheritedParams, BaseEstimator):
    """Base class: validation, moving average, ``predict`` (1 alarm / 0 normal).

    ``phase1_input``: what the pipeline feeds ``fit`` and ``decision_function``: "features"
    (the baseline-standardised, Fisher-selected features) or "torque_windows" (the averaged
    torque windows of the autoencoder). ``get_params`` includes the parameters of parent classes
    when a subclass's ``__init__`` forwards ``**kwargs`` (:class:`analysis.params.InheritedParams`).
    """

    _min_samples = 2
    phase1_input = "features"

    def fit(self, X, y=None):
        X = validate_data(self, X, dtype=np.float64)
        n = X.shape[0]
        need = self._min_samples_for(getattr(self, "limit", None))
        if n < need:
            raise ValueError(f"{type(self).__name__} needs at least {need} baseline "
                             f"samples; got {n} sample{'s' if n != 1 else ''} (n_samples = {n})")
        self._fit(X)
        return self

    def _fit(self, X: np.ndarray) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _check_limit(self, allowed: tuple[str, ...]) -> None:
        if self.limit not in allowed:
            raise ValueError(f"limit = {self.limit!r}; expected one of {', '.join(map(repr, allowed))}")

    def _min_samples_for(self, limit: str) -> int:
        """Baseline rows needed: ``_min_samples``, and with ``limit="cv"`` enough that every
        training fold has at least two rows."""
        return max(self._min_samples, 3) if limit == "cv" else self._min_samples

    def _out_of_fold_scores(self, X: np.ndarray) -> np.ndarray:
        """(N,) score of every baseline row by a copy of this detector (``limit="paper"``, the
        same parameters and ``random_state``) fitted on the other rows: ``min(cv, N)`` contiguous
        folds in row (time) order, so no random draw; :func:`numpy.array_split` sizes them.
        Scores before any moving average (``score_samples``)."""
        n = X.shape[0]
        k = int(self.cv)
        if k < 2:
            raise ValueError(f"cv = {self.cv!r}; expected at least 2 folds")
        out = np.empty(n)
        for test in np.array_split(np.arange(n), min(k, n)):
            train = np.setdiff1d(np.arange(n), test)
            m = clone(self).set_params(limit="paper")
            m._fit(X[train])
            out[test] = m._score(X[test])
        return out

    def _score(self, X: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def score_samples(self, X) -> np.ndarray:
        """(n,) novelty score per row, before any moving average; larger is more novel."""
        check_is_fitted(self, "threshold_")
        X = validate_data(self, X, dtype=np.float64, reset=False)
        return self._score(X)

    def decision_function(self, X) -> np.ndarray:
        """(n,) score (moving-averaged if ``moving_average`` > 1); > ``threshold_`` is an alarm."""
        s = self.score_samples(X)
        return limits.moving_average(s, getattr(self, "moving_average", 1))

    def predict(self, X) -> np.ndarray:
        """(n,) int: 1 where the score exceeds ``threshold_`` (alarm), else 0."""
        return (self.decision_function(X) > self.threshold_).astype(int)


def _pca(X: np.ndarray, variance: float) -> PCA:
    """PCA keeping the fewest components that explain >= ``variance`` of the variance; at least 1,
    at most N-1 (so that the limits' degrees of freedom stay positive)."""
    n, p = X.shape
    full = PCA(svd_solver="full").fit(X)
    ratio = np.nan_to_num(full.explained_variance_ratio_, nan=0.0)
    a = int(np.searchsorted(np.cumsum(ratio), variance - 1e-12) + 1) if ratio.sum() > 0 else 1
    a = max(1, min(a, n - 1, p))
    return PCA(n_components=a, svd_solver="full").fit(X)


@register("detectors", "pca_t2", label="PCA-T²", color="tab:blue", marker="o", default=True)
class PCAT2(PhaseIDetector):
    """PCA with Hotelling's T^2 (paper section IV, Eq. 2; NIST/SEMATECH e-Handbook §6.5.4.3).

    T^2 = sum_j t_j^2 / lambda_j over the a retained components (``variance`` = 0.95 of the
    baseline variance), lambda_j = ``PCA.explained_variance_`` (N-1 denominator) [sklearn PCA docs].
    ``limit="new"`` (default): a(N-1)(N+1)/(N(N-a)) F_{1-alpha}(a, N-a), the exact limit for a
    new observation, which is what the test samples are; ``limit="paper"``: the paper's Eq. 2
    without the (N+1)/N factor. Fitted: ``pca_``, ``n_components_`` (a), ``threshold_``.
    """

    def __init__(self, variance: float = 0.95, alpha: float = 0.01, limit: str = "new"):
        self.variance = variance
        self.alpha = alpha
        self.limit = limit

    def _fit(self, X):
        if self.limit not in ("new", "paper"):
            raise ValueError(f"limit = {self.limit!r}; expected 'new' or 'paper'")
        self.pca_ = _pca(X, self.variance)
        self.n_components_ = int(self.pca_.n_components_)
        f = limits.t2_limit_new if self.limit == "new" else limits.t2_limit_paper
        self.threshold_ = f(X.shape[0], self.n_components_, self.alpha)

    def _score(self, X):
        t = self.pca_.transform(X)
        lam = np.maximum(self.pca_.explained_variance_, np.finfo(float).tiny)
        return np.sum(t ** 2 / lam, axis=1)


@register("detectors", "gmm_md", label="GMM-MD", color="tab:orange", marker="s")
class GMMMD(PhaseIDetector):
    """One-component Gaussian mixture on the PCs, Mahalanobis distance, beta limit (paper (i)).

    Score: MD^2 = (t - mu)^T Sigma^-1 (t - mu) on the a principal components kept as in
    :class:`PCAT2`, with ``GaussianMixture(n_components=1, covariance_type="full")`` [sklearn
    GaussianMixture docs; its covariance is the MLE (divisor N) plus ``reg_covar``]. Limit
    (:mod:`analysis.phase1.limits`, Tracy, Young & Mason 1992, J. Quality Technology 24, 88-95):
    ``limit="new"`` (default): a(N+1)/(N-a) F_{1-alpha}(a, N-a), exact for a new observation,
    which is what the scored samples are; ``limit="paper"``: the paper's beta limit
    (N-1) Beta_{1-alpha}(a/2, (N-a-1)/2), exact for the baseline's own points, on new points it
    alarms far more often than alpha (measured in ``tests/test_phase1_limits.py``: 0.14 at
    alpha = 0.01, N = 15, a = 3). Trailing moving average of ``moving_average`` = 4 samples on the
    score (paper).
    """

    _min_samples = 3

    def __init__(self, variance: float = 0.95, alpha: float = 0.01, moving_average: int = 4,
                 limit: str = "new", random_state: int = 0):
        self.variance = variance
        self.alpha = alpha
        self.moving_average = moving_average
        self.limit = limit
        self.random_state = random_state

    def _fit(self, X):
        self._check_limit(("new", "paper"))
        n = X.shape[0]
        pca = _pca(X, self.variance)
        a = int(pca.n_components_)
        a = max(1, min(a, n - 2))  # the beta limit needs N - a - 1 > 0
        self.pca_ = PCA(n_components=a, svd_solver="full").fit(X)
        self.n_components_ = a
        self.gmm_ = GaussianMixture(n_components=1, covariance_type="full", reg_covar=1e-9,
                                    init_params="random_from_data",
                                    random_state=self.random_state).fit(self.pca_.transform(X))
        f = limits.md2_limit_new if self.limit == "new" else limits.md2_beta_limit
        self.threshold_ = f(n, a, self.alpha)

    def _score(self, X):
        d = self.pca_.transform(X) - self.gmm_.means_[0]
        return np.einsum("ij,jk,ik->i", d, self.gmm_.precisions_[0], d)


@register("detectors", "som_mqe", label="SOM-MQE", color="tab:green", marker="^")
class SOMMQE(PhaseIDetector):
    """Self-organising map, minimum quantisation error, three-sigma limit (paper (ii)).

    A ``som_rows`` x ``som_cols`` MiniSom [MiniSom docs] trained on the baseline for
    ``n_iterations`` steps (random order from ``random_state``). Score: MQE = min_j ||x - w_j||
    (Euclidean, computed here from the weights). Limit: mean + 3 std (paper) of the baseline MQE,
    ``limit="cv"`` (default) of the out-of-fold MQE (``cv`` folds, module docstring),
    ``limit="paper"`` of the in-sample MQE, which the map was trained to make small. The paper gives
    no map size; 3 x 3 has fewer nodes than the 15 baseline samples, so the map cannot put a node
    on every baseline sample (with 4 x 4 it nearly does and the in-sample MQE collapses).
    """

    def __init__(self, som_rows: int = 3, som_cols: int = 3, sigma: float = 1.0,
                 learning_rate: float = 0.5, n_iterations: int = 1000, limit: str = "cv", cv: int = 5,
                 random_state: int = 0):
        self.som_rows = som_rows
        self.som_cols = som_cols
        self.sigma = sigma
        self.learning_rate = learning_rate
        self.n_iterations = n_iterations
        self.limit = limit
        self.cv = cv
        self.random_state = random_state

    def _fit(self, X):
        self._check_limit(("cv", "paper"))
        som = MiniSom(self.som_rows, self.som_cols, X.shape[1], sigma=self.sigma,
                      learning_rate=self.learning_rate, random_seed=self.random_state)
        som.random_weights_init(X)
        som.train(X, self.n_iterations, random_order=True)
        self.weights_ = som.get_weights().reshape(-1, X.shape[1]).copy()
        base = self._out_of_fold_scores(X) if self.limit == "cv" else self._score(X)
        self.threshold_ = limits.three_sigma(base)

    def _score(self, X):
        d = np.linalg.norm(X[:, None, :] - self.weights_[None, :, :], axis=2)
        return d.min(axis=1)


@register("detectors", "iforest", label="Isolation Forest", color="tab:red", marker="D")
class IForest(PhaseIDetector):
    """Isolation Forest (paper (iii); Liu, Ting & Zhou 2008, ICDM, 413-422).

    Score: the paper's anomaly score s = 2^(-E[h(x)]/c(psi)) = ``-IsolationForest.score_samples``
    [scikit-learn IsolationForest documentation]. Limit: ``limit="paper"``: the fixed
    ``threshold`` 0.5 (with ``contamination="auto"``, s > 0.5 is exactly sklearn's
    ``predict == -1``); ``limit="cv"`` (default): mean + 3 std of the out-of-fold baseline scores
    (``cv`` folds, module docstring), the paper's rule for SOM-MQE and the autoencoder, capped at
    the highest in-sample baseline score. Why not 0.5: Liu et al. (section 2) note that s is close
    to 0.5 for every point of a sample without distinct anomalies; with the 15-sample baseline
    every tree sees all of it (psi = 15) and the healthy samples' scores straddle 0.5 (measured on
    the gate's healthy campaigns: out-of-fold baseline mean 0.49, sd 0.03; new healthy samples
    mean 0.51, 16 of 30 above 0.5). Why the cap: the score is bounded. A split value is drawn
    between the node's smallest and largest *baseline* value, so a point beyond the baseline's
    range is isolated like the most extreme baseline point: far outside in every feature it scores
    0.62-0.67, barely above the highest in-sample score (0.57-0.62), and 1000 standard deviations
    out in a single feature only 0.45-0.53 (measured on six baselines of 15 draws of 4 Gaussian features and on the
    gate's baseline). Without the cap the three-sigma limit can lie above every score the forest
    can give. What stays: the Isolation Forest sees a fault only where it moves several features
    beyond the baseline's range at once.
    """

    def __init__(self, n_estimators: int = 100, threshold: float = 0.5, limit: str = "cv", cv: int = 5,
                 random_state: int = 0):
        self.n_estimators = n_estimators
        self.threshold = threshold
        self.limit = limit
        self.cv = cv
        self.random_state = random_state

    def _fit(self, X):
        self._check_limit(("cv", "paper"))
        self.forest_ = IsolationForest(n_estimators=self.n_estimators, contamination="auto",
                                       random_state=self.random_state).fit(X)
        if self.limit == "cv":
            self.threshold_ = min(limits.three_sigma(self._out_of_fold_scores(X)), float(self._score(X).max()))
        else:
            self.threshold_ = float(self.threshold)

    def _score(self, X):
        return -self.forest_.score_samples(X)


@register("detectors", "ocsvm", label="One-class SVM", color="tab:purple", marker="v")
class OCSVM(PhaseIDetector):
    """One-class SVM with a linear kernel, threshold 0, moving average of 4 (paper (iv)).

    sklearn's ``OneClassSVM.decision_function`` is > 0 for inliers and < 0 for outliers [sklearn
    docs]; the score here is its negative, so > 0 (``threshold_``) is an alarm. ``nu`` bounds the
    fraction of baseline samples outside the learned half-space.

    A linear one-class SVM separates the data from the *origin* (Schoelkopf et al. 2001). On
    baseline-standardised features the baseline's mean *is* the origin, the problem is degenerate
    (w ~ 0, rho = 0) and every score is ~0. With
    ``reflect`` = r (default 3) the SVM therefore works on ``u = r - |x|``: a baseline sample lies
    inside the positive box (0, r] per feature, away from the origin, and a feature drifting
    beyond r standard deviations in either direction moves the sample through the origin side of
    the separating hyperplane. The kernel on u is linear. ``reflect=None`` uses x as it is.
    """

    def __init__(self, nu: float = 0.05, moving_average: int = 4, reflect: float | None = 3.0):
        self.nu = nu
        self.moving_average = moving_average
        self.reflect = reflect

    def _map(self, X):
        return X if self.reflect is None else self.reflect - np.abs(X)

    def _fit(self, X):
        self.svm_ = OneClassSVM(kernel="linear", nu=self.nu).fit(self._map(X))
        self.threshold_ = 0.0

    def _score(self, X):
        return -self.svm_.decision_function(self._map(X))
