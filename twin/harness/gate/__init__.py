"""``twin gate``: a fixed, versioned suite of recovery checks for any backlash estimator or Phase I
detector, on campaigns simulated once and cached.

What a check is
---------------
Every check runs one method on the inputs a campaign gives it and compares what comes out with
what the twin injected, against a stated tolerance:

- a **backlash check** fits the estimator on a campaign's first Phase II session and estimates
  every session (the :class:`analysis.phase2.backlash.BacklashEstimator` contract: ``fit`` takes
  a :class:`analysis.phase2.traces.SessionErrorMotions`, ``estimate`` returns a
  :class:`analysis.phase2.backlash.SessionBacklash`); the estimated change of backlash of each
  session (the estimator's primary estimate, or the pitch-based one for Eq. 9) must lie within
  max(``abs_um``, ``rel`` × injected change) of the injected change;
- a **detection check** fits the detector on the first ``N_BASELINE`` standardised,
  Fisher-selected samples (as ``twin detect`` does) and scores every sample: the delay of the
  detection after the injected onset, in samples, or the false alarms per healthy sample.

A method that raises, returns a non-finite value or a value of the wrong type or shape fails the
check with the exception or the value named; the other checks still run.

The cache
---------
``<root>/<suite>-v<suite version>-<package version>/`` (root: ``--cache`` or
``$XDG_CACHE_HOME/ballscrew-twin/gate``, ``~/.cache`` without XDG_CACHE_HOME) holds, per campaign,
its ``truth.h5`` and what the methods read of its ``measurements.h5``: the sessions' error motions
(``phase2-<reference>.npz``, one per position axis a check uses) or the Phase I feature table
(``phase1.npz``). The measurements themselves (up to 0.45 GB for a 40-run campaign at 20 mm/s)
are deleted once these are computed. ``manifest.json`` lists every file with its sha256 and the
fingerprint of the suite's definition; before any use every file is checked against it, and a
missing, altered or stale cache is rebuilt, never trusted. A build works in
``<folder>.building`` (a stopped build is resumed there) under the lock ``<folder>.lock``. The
npz files are read with
``allow_pickle=False``: loading the cache executes no code from it.

Units: SI inside; µm, h and samples in the printed figures and the JUnit XML.

Modules: :mod:`.suite` (the campaigns and checks), :mod:`.cache` (simulated once, verified),
:mod:`.checks` (running methods through them), :mod:`.command` (the verb and its JUnit XML); the
pytest plugin is :mod:`twin.harness.gate_pytest`.
"""

from twin.harness.gate.cache import (
    GateCache,
    Phase1Input,
    Phase2Input,
    build_cache,
    cache_dir,
    cache_root,
    default_root,
    ensure_cache,
    package_version,
    verify,
)
from twin.harness.gate.checks import (
    BadValue,
    CheckResult,
    method_name,
    resolve_methods,
    run_backlash_check,
    run_backlash_checks,
    run_detection_checks,
    run_gate,
    select_checks,
)
from twin.harness.gate.command import command, junit_xml
from twin.harness.gate.suite import (
    CACHE_ENV,
    EQ5,
    MANIFEST,
    NOISE2,
    NOISE4,
    STANDARD,
    SUITES,
    BacklashCheck,
    Campaign,
    DetectionCheck,
    GateError,
    Suite,
    get_suite,
)

__all__ = [
    "BacklashCheck", "BadValue", "CACHE_ENV", "Campaign", "CheckResult", "DetectionCheck", "EQ5", "GateCache",
    "GateError", "MANIFEST", "NOISE2", "NOISE4", "Phase1Input", "Phase2Input", "STANDARD", "SUITES", "Suite",
    "build_cache", "cache_dir", "cache_root", "command", "default_root", "ensure_cache", "get_suite",
    "junit_xml", "method_name", "package_version", "resolve_methods", "run_backlash_check",
    "run_backlash_checks", "run_detection_checks", "run_gate", "select_checks", "verify",
]
