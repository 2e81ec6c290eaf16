"""The harness that drives the simulator: the analysis chain on one campaign (:mod:`~twin.harness.chain`),
sweeps (:mod:`~twin.harness.sweep`), the Rerun view (:mod:`~twin.harness.view`), the gap diagnosis
runner and its benchmark (:mod:`~twin.harness.gap_runner`, :mod:`~twin.harness.gap_benchmark`).

It sits on top of the simulator (:mod:`twin`) and the analysis (:mod:`analysis`); neither imports it.
"""
