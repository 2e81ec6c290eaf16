"""Whether layer (c) matched the recording: a chi-squared test of the fit's residuals.

At the solution of a weighted least-squares fit of p parameters to m statistics whose errors are
independent and Gaussian, the sum of the squared residuals (each in its standard errors) follows a
chi-squared law with m − p degrees of freedom when the model can produce the data (the
goodness-of-fit test of W. H. Press et al., "Numerical Recipes", 3rd ed., 2007, §15.1 and §15.2);
the parameters kept at their start (not informed, not told apart) are uncertain by their assumed
span, and their share of the residuals is counted as an error of the statistics
(:func:`profiled_chi2`). A twin that matches the recording's statistics worse than this lacks
something the recording holds: an unmodelled effect or an artefact of its acquisition acts on the
statistics left unmatched, or a parameter kept at its start lies beyond its assumed span. The
fitted values are then bent, and their intervals, computed as if the fit held, may not hold:
the calibration says so (the log, its JSON, the TOML) and ``twin diagnose`` says it on its page.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg, stats

#: Significance of the test: a twin that can produce the recording is called a misfit this rarely.
MISFIT_P = 0.001

#: What each statistic of layer (c) (:data:`twin.harness.calibration.values.STAT_NAMES`) reads.
STATISTIC_WORDS = {
    "inertia": "the torque's inertia in the ramps", "cruise_drag": "the torque's drag at cruise",
    "viscous_drag": "the torque's drag growing with speed", "ripple": "the ripple at its order",
    "accel": "the moves' acceleration", "dwell": "the moves' dwell",
    "vertical_mode": "the carriage's vertical mode on the nut accelerometers",
    "lateral_mode": "the carriage's lateral mode", "loop_response": "the velocity loop's response",
    "loop_ringing": "the IMU's ringing at the starts and stops",
}


def profiled_chi2(residual_se: np.ndarray, j_fitted: np.ndarray, j_kept: np.ndarray, kept_var: np.ndarray) -> float:
    """χ² of the fit's residuals with the parameters kept at their start counted over their
    assumed span: the statistics' error covariance (in their standard errors) C = I + A·P·Aᵀ,
    A = ``j_kept`` (m, k) d(residual)/d(log p) of the k kept parameters, P = diag(``kept_var``) (k,)
    their log variance; the fitted parameters refitted to the residuals under C, linearised
    (``j_fitted`` (m, p) their d(residual)/d(log p)): min over δ of (r − Jδ)ᵀ C⁻¹ (r − Jδ), r =
    ``residual_se`` (m,) (generalised least squares: the whitened problem L⁻¹r, L⁻¹J with
    C = L·Lᵀ; Press et al., §15.4). Without kept parameters and at the solution: Σ r²."""
    r = np.asarray(residual_se, float)
    if not r.size:
        return 0.0
    a = np.asarray(j_kept, float).reshape(r.size, -1)
    c = np.eye(r.size) + a @ np.diag(np.asarray(kept_var, float).reshape(-1)) @ a.T
    low = np.linalg.cholesky(c)
    rw = linalg.solve_triangular(low, r, lower=True)
    jw = linalg.solve_triangular(low, np.asarray(j_fitted, float).reshape(r.size, -1), lower=True)
    if jw.shape[1]:
        rw = rw - jw @ np.linalg.lstsq(jw, rw, rcond=None)[0]
    return float(rw @ rw)


def fit_misfit(residual_se: list[float], statistics: list[str], n_fitted: int,
               chi2: float | None = None) -> dict | None:
    """The misfit of layer (c), or None when the fit matched the recording.

    ``residual_se``: the residuals at the solution, shape (m,), in standard errors;
    ``statistics``: their names (:data:`STATISTIC_WORDS`' keys), shape (m,); ``n_fitted``: the
    parameters fitted (p); ``chi2``: their χ² with the kept parameters' span counted
    (:func:`profiled_chi2`), default Σ r². It is tested against the chi-squared quantile 1 −
    :data:`MISFIT_P` with max(m − p, 1) degrees of freedom (a fit with as many statistics as
    parameters should meet them all, and one degree of freedom keeps the test from calling its
    scatter a misfit). Returns {``chi2``, ``dof``, ``critical``, ``p``, ``statistics``: [{``statistic``,
    ``residual_se``}] those beyond the two-sided normal limit of :data:`MISFIT_P` (at least the
    largest), largest first}."""
    r = np.asarray(residual_se, float)
    if r.size != len(statistics):
        raise ValueError(f"{r.size} residuals for {len(statistics)} statistics: expected one residual each")
    if not r.size:
        return None
    dof = max(r.size - int(n_fitted), 1)
    chi2 = float(r @ r) if chi2 is None else float(chi2)
    critical = float(stats.chi2.isf(MISFIT_P, dof))
    if not chi2 > critical:
        return None
    limit = float(stats.norm.isf(MISFIT_P / 2))
    order = np.argsort(-np.abs(r))
    named = [int(i) for i in order if abs(r[i]) > limit] or [int(order[0])]
    return {"chi2": chi2, "dof": dof, "critical": critical, "p": MISFIT_P,
            "statistics": [{"statistic": statistics[i], "residual_se": float(r[i])} for i in named]}


def misfit_sentence(misfit: dict) -> str:
    """``misfit`` (:func:`fit_misfit`) in words, for the TOML, the JSON and ``twin diagnose``'s page."""
    worst = ", ".join(f"{STATISTIC_WORDS.get(s['statistic'], s['statistic'])} ({s['residual_se']:+.1f} standard "
                      "errors)" for s in misfit["statistics"])
    return (f"the twin could not match the recording: χ² {misfit['chi2']:.3g} over {misfit['dof']} degree(s) of "
            f"freedom (the parameters kept at their start counted over their span), above the limit "
            f"{misfit['critical']:.3g} at p = {misfit['p']:g}; "
            f"unmatched: {worst}. An effect the twin lacks or an artefact of the acquisition acts on them, or a "
            "value kept at the twin's default is beyond its assumed span: the fitted values may be bent by it, "
            "and their intervals assume a match")


__all__ = ["MISFIT_P", "STATISTIC_WORDS", "fit_misfit", "misfit_sentence", "profiled_chi2"]
