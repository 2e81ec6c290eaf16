"""Autoencoder on torque signals (paper section IV (v); Table III "AE, Torque Data").

Input rows are preprocessed torque windows of equal length that hold both the transient
(acceleration) and the start of the steady state: per Phase I sample, the average of its oriented
torque windows (``analysis.phase1.features.AE_WINDOW_S`` from the start of each acceleration,
block-averaged to ``AE_RATE_HZ``), see :func:`analysis.phase1.pipeline.extract`.

Model: ``sklearn.neural_network.MLPRegressor(hidden_layer_sizes=(10,))`` trained to reproduce its
input [sklearn MLPRegressor docs], on inputs standardised with the baseline: ``scaling="point"``
(default) each time point by the baseline's mean and standard deviation at that point (the usual
per-input standardisation of a network's inputs, LeCun, Bottou, Orr & Mueller, "Efficient
BackProp", 1998, section 4.3; the paper standardises its features the same way);
``scaling="scalar"``: centred by the baseline mean window and divided by one scalar, the RMS of the
centred baseline (this package's earlier choice). Score: reconstruction loss, the mean squared
error per row in those scaled units. Limit: mean + 3 std of baseline losses (paper),
``limit="cv"`` (default) of out-of-fold losses (``cv`` contiguous folds, the standardisation
refitted in each; :mod:`analysis.phase1.detectors`), ``limit="paper"`` of the in-sample losses.
The L2 penalty ``alpha`` = 1 keeps the network from memorising the 15 baseline rows (with
sklearn's default 1e-4 the baseline losses collapse).

Why per point: each window holds the end of the acceleration, a torque step of about 0.9 N·m that
falls inside one 1-ms block, and its timing relative to the window's start varies by 0.1-0.3 ms
between healthy windows (951-956 samples at 10 kHz on ``phase1-quick`` without wear;
``benchmarks/phase1_false_alarms.py``). With one scalar scale (about 2 mN·m, the noise of the
steady part) that single block dominated the loss of healthy samples (a sample whose steps came
0.14 ms later than the baseline's on average scored 15.6 against a baseline maximum of 3.0); per
point it is divided by its own, larger, baseline spread, while a change of drag torque from
preload loss moves every point.
"""

from __future__ import annotations

import numpy as np
from sklearn.neural_network import MLPRegressor

from analysis.base.registry import register
from analysis.phase1 import limits
from analysis.phase1.detectors import PhaseIDetector

__all__ = ["TorqueAutoencoder"]


@register("detectors", "autoencoder", label="Autoencoder", color="tab:brown", marker="P")
class TorqueAutoencoder(PhaseIDetector):
    """Autoencoder novelty detector; same contract as :class:`~analysis.phase1.detectors.PhaseIDetector`.

    X: (N, m) torque windows (N*m), one row per sample. Fitted: ``mlp_``, ``mean_`` (m,) N*m,
    ``scale_`` (m,) N*m (one value repeated with ``scaling="scalar"``), ``threshold_``.
    """

    phase1_input = "torque_windows"

    def __init__(self, hidden_units: int = 10, alpha: float = 1.0, max_iter: int = 3000,
                 scaling: str = "point", limit: str = "cv", cv: int = 5, random_state: int = 0):
        self.hidden_units = hidden_units
        self.alpha = alpha
        self.max_iter = max_iter
        self.scaling = scaling
        self.limit = limit
        self.cv = cv
        self.random_state = random_state

    def _fit(self, X):
        self._check_limit(("cv", "paper"))
        if self.scaling not in ("point", "scalar"):
            raise ValueError(f"scaling = {self.scaling!r}; expected 'point' or 'scalar'")
        self.mean_ = X.mean(axis=0)
        if self.scaling == "point":
            sd = X.std(axis=0, ddof=1) if X.shape[0] > 1 else np.zeros(X.shape[1])
            self.scale_ = np.where(sd > 0, sd, 1.0)
        else:
            rms = float(np.sqrt(np.mean((X - self.mean_) ** 2)))
            self.scale_ = np.full(X.shape[1], rms if rms > 0 else 1.0)
        Z = (X - self.mean_) / self.scale_
        self.mlp_ = MLPRegressor(hidden_layer_sizes=(self.hidden_units,), activation="tanh",
                                 alpha=self.alpha, max_iter=self.max_iter, tol=1e-6,
                                 random_state=self.random_state)
        import warnings

        from sklearn.exceptions import ConvergenceWarning
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            self.mlp_.fit(Z, Z)
        base = self._out_of_fold_scores(X) if self.limit == "cv" else self._score(X)
        self.threshold_ = limits.three_sigma(base)

    def _score(self, X):
        Z = (X - self.mean_) / self.scale_
        R = self.mlp_.predict(Z).reshape(Z.shape)
        return np.mean((R - Z) ** 2, axis=1)
