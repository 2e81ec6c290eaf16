"""The recovery gate of ``twin gate`` in a method developer's own pytest suite (a pytest plugin,
registered by the entry point ``pytest11: ballscrew_twin_gate``, so it loads in every pytest
session of an environment where ``ballscrew-twin`` is installed).

Use::

    from twin.harness.gate_pytest import assert_detects_preload_loss, assert_recovers_backlash

    def test_my_estimator_recovers_backlash(twin_gate_cache):
        assert_recovers_backlash(MyEstimator(), cache=twin_gate_cache)

    def test_my_detector(twin_gate_cache):
        assert_detects_preload_loss(MyDetector(), cache=twin_gate_cache)

The fixture ``twin_gate_cache`` (session-scoped) verifies the gate's cache, building it the first
time (``--twin-gate-cache DIR`` or the environment variable ``TWIN_GATE_CACHE`` for its root;
default ``$XDG_CACHE_HOME/ballscrew-twin/gate``). The helpers also work without it (``cache=None``:
the default root, verified once per process). A failing check raises ``AssertionError`` naming
every failed check with its figure, tolerance and the exception or value that failed it.

This module imports only pytest and the standard library at import time (no NumPy, no MuJoCo):
registering the plugin costs a pytest session nothing until a test asks for the gate.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import pytest

__all__ = ["assert_detects_preload_loss", "assert_recovers_backlash", "gate_cache"]

ENV = "TWIN_GATE_CACHE"
_CACHES: dict = {}


def pytest_addoption(parser) -> None:
    parser.getgroup("ballscrew-twin gate").addoption(
        "--twin-gate-cache", action="store", default=None, metavar="DIR",
        help="root of the twin gate's cache (default: $TWIN_GATE_CACHE, else "
             "$XDG_CACHE_HOME/ballscrew-twin/gate)")


def gate_cache(root: str | os.PathLike | None = None, suite: str = "standard"):
    """The verified :class:`twin.harness.gate.GateCache` of ``suite`` under ``root`` (default
    ``$TWIN_GATE_CACHE``, else the gate's default root), built if needed; verified once per
    process and root."""
    from twin.harness.gate import ensure_cache

    root = root if root is not None else os.environ.get(ENV) or None
    key = (str(root), suite)
    if key not in _CACHES:
        _CACHES[key] = ensure_cache(root, suite, log=lambda line: None)
    return _CACHES[key]


@pytest.fixture(scope="session")
def twin_gate_cache(request):
    """The gate's verified cache (built on first use; see the module docstring)."""
    return gate_cache(request.config.getoption("--twin-gate-cache"))


def _report(results) -> str:
    return "\n".join(f"  {r.check} ({r.method}): {r.figure}; tolerance {r.tolerance}"
                     for r in results if not r.passed)


def _assert_checks(kind: str, method: Any, cache, checks: Sequence[str]) -> list:
    """Run the suite's ``kind`` checks ("backlash" or "detection"; those named in ``checks``)
    on ``method``; ``AssertionError`` naming each failed check, else the results."""
    from twin.harness.gate import run_backlash_checks, run_detection_checks, select_checks

    cache = cache if cache is not None else gate_cache()
    backlash, detection = select_checks(cache.suite, checks)
    selected, run = (backlash, run_backlash_checks) if kind == "backlash" else (detection, run_detection_checks)
    if checks and not selected:
        raise ValueError(f"checks {list(checks)}: none is a {kind} check")
    results = run(method, cache, selected)
    failed = [r for r in results if not r.passed]
    if failed:
        raise AssertionError(f"{len(failed)} of {len(results)} {kind} checks failed:\n{_report(results)}")
    return results


def assert_recovers_backlash(estimator: Any, *, cache=None, checks: Sequence[str] = ()) -> list:
    """Run the suite's backlash checks (or those named in ``checks``) on ``estimator`` (an
    unfitted instance, a registered name or ``module:Class``); ``AssertionError`` naming each
    failed check, else the list of :class:`twin.harness.gate.CheckResult`."""
    return _assert_checks("backlash", estimator, cache, checks)


def assert_detects_preload_loss(detector: Any, *, cache=None, checks: Sequence[str] = ()) -> list:
    """Run the suite's detection checks (or those named in ``checks``) on ``detector`` (an
    unfitted instance, a registered name or ``module:Class``); ``AssertionError`` naming each
    failed check, else the list of :class:`twin.harness.gate.CheckResult`."""
    return _assert_checks("detection", detector, cache, checks)
