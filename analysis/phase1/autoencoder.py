"""Autoencoder on torque signals (paper section IV (v); Table III "AE, Torque Data").

Input rows are preprocessed torque windows of equal length that hold both the transient
(acceleration) and the start of the steady state: per Phase I sample, the average of its oriented
torque windows (``analysis.phase1.features.AE_WINDOW_S`` from the start of each acceleration,
block-averaged to ``AE_RATE_HZ``), see :func:`analysis.phase1.pipeline.extract`.

Model: ``sklearn.neural_network.MLPRegressor(hidden_layer_sizes=(10,))`` trained to reproduce its
input [sklearn MLPRegressor docs], on inputs centred by the baseline mean window and divided by one
scalar (the RMS of the centred baseline). Score: reconstruction loss, the mean squared error per
row in those scaled units. Limit: mean + 3 std of the baseline losses (paper). The L2 penalty
``alpha`` = 1 keeps the network from memorising the 15 baseline rows (with sklearn's default 1e-4
the baseline losses collapse and every healthy new sample alarms on the quick campaign).
"""

from __future__ import annotations

import numpy as np
from sklearn.neural_network import MLPRegressor

from analysis.phase1 import limits
from analysis.phase1.detectors import PhaseIDetector
from analysis.registry import register

__all__ = ["TorqueAutoencoder"]


@register("detectors", "autoencoder", label="Autoencoder", color="tab:brown", marker="P")
class TorqueAutoencoder(PhaseIDetector):
    """Autoencoder novelty detector; same contract as :class:`~analysis.phase1.detectors.PhaseIDetector`.

    X: (N, m) torque windows (N*m), one row per sample. Fitted: ``mlp_``, ``mean_`` (m,),
    ``scale_`` (float), ``threshold_``.
    """

    phase1_input = "torque_windows"

    def __init__(self, hidden_units: int = 10, alpha: float = 1.0, max_iter: int = 3000, random_state: int = 0):
        self.hidden_units = hidden_units
        self.alpha = alpha
        self.max_iter = max_iter
        self.random_state = random_state

    def _fit(self, X):
        self.mean_ = X.mean(axis=0)
        rms = float(np.sqrt(np.mean((X - self.mean_) ** 2)))
        self.scale_ = rms if rms > 0 else 1.0
        Z = (X - self.mean_) / self.scale_
        self.mlp_ = MLPRegressor(hidden_layer_sizes=(self.hidden_units,), activation="tanh",
                                 alpha=self.alpha, max_iter=self.max_iter, tol=1e-6,
                                 random_state=self.random_state)
        import warnings

        from sklearn.exceptions import ConvergenceWarning
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            self.mlp_.fit(Z, Z)
        self.threshold_ = limits.three_sigma(self._score(X))

    def _score(self, X):
        Z = (X - self.mean_) / self.scale_
        R = self.mlp_.predict(Z).reshape(Z.shape)
        return np.mean((R - Z) ** 2, axis=1)
