"""The harness that drives the simulator: the analysis chain on one campaign (:mod:`~twin.harness.chain`),
sweeps (:mod:`~twin.harness.sweep`), the Rerun view (:mod:`~twin.harness.view`), the gap diagnosis's
simulations, runner and benchmark (:mod:`~twin.harness.diagnosis`), the calibration
(:mod:`~twin.harness.calibration`).

It sits on top of the simulator (:mod:`twin`) and the analysis (:mod:`analysis`); neither imports it.
"""
