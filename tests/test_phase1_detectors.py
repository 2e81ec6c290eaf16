"""Check 5 of issue 3: the Phase I detectors follow the scikit-learn estimator contract.

Every detector runs through ``sklearn.utils.estimator_checks.parametrize_with_checks`` with the
paper's settings. Checks expected to fail are listed in ``EXPECTED_FAILED`` with the reason.
"""

import numpy as np
import pytest
from sklearn.utils.estimator_checks import parametrize_with_checks

from analysis.phase1.autoencoder import TorqueAutoencoder
from analysis.phase1.detectors import GMMMD, OCSVM, PCAT2, SOMMQE, IForest

MA = ("the paper's moving average of 4 samples (GMM-MD, OC-SVM) makes a row's score depend on the "
      "rows before it, by design: the rows are consecutive samples in time order")
EXPECTED_FAILED = {
    "GMMMD": {"check_methods_subset_invariance": MA, "check_methods_sample_order_invariance": MA},
    "OCSVM": {"check_methods_subset_invariance": MA, "check_methods_sample_order_invariance": MA},
}

ESTIMATORS = [PCAT2(), GMMMD(), SOMMQE(n_iterations=200), IForest(n_estimators=20), OCSVM(),
              TorqueAutoencoder(max_iter=200)]


def _expected(est):
    return EXPECTED_FAILED.get(type(est).__name__, {})


@parametrize_with_checks(ESTIMATORS, expected_failed_checks=_expected)
def test_sklearn_contract(estimator, check):
    check(estimator)


@pytest.mark.parametrize("est", ESTIMATORS, ids=lambda e: type(e).__name__)
def test_predict_is_score_above_threshold(est):
    """predict == 1 exactly where decision_function > threshold_, 0 elsewhere; an outlier far
    from the baseline alarms."""
    rng = np.random.default_rng(0)
    X = rng.normal(size=(15, 4))
    est.fit(X)
    T = np.vstack([X, rng.normal(size=(5, 4)), np.full((4, 4), 40.0)])
    s, p = est.decision_function(T), est.predict(T)
    assert set(np.unique(p)) <= {0, 1}
    np.testing.assert_array_equal(p, (s > est.threshold_).astype(int))
    print(f"{type(est).__name__}: threshold {est.threshold_:.4g}, far-outlier scores {s[-4:]}")
    assert p[-1] == 1


def test_moving_average_is_trailing_over_rows():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(15, 3))
    d = GMMMD().fit(X)
    raw = d.score_samples(X)
    ma = d.decision_function(X)
    assert ma[0] == pytest.approx(raw[0])
    assert ma[5] == pytest.approx(raw[2:6].mean())


def test_too_few_baseline_samples_is_a_clear_error():
    with pytest.raises(ValueError, match="got 1 sample"):
        PCAT2().fit(np.zeros((1, 3)))
