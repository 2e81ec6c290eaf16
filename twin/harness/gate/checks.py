"""Running methods through the checks: a backlash estimator on each backlash check, a Phase I
detector on each detection check, each result with its figures and why it failed.
"""

from __future__ import annotations

import copy
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.harness.gate.cache import GateCache
from twin.harness.gate.suite import BacklashCheck, DetectionCheck, GateError, Suite

# ---------------------------------------------------------------------------------------------
# Running methods through the checks


@dataclass
class CheckResult:
    """The verdict of one check for one method.

    kind: "backlash" or "detection". value: the figure compared with the tolerance (worst
    |error| in µm, delay in samples, false alarms per healthy sample), None if there is none.
    figure: the figure in words; error: the exception or bad value that failed the check.
    rows: per-session (session, injected µm, estimated µm, tolerance µm) of a backlash check.
    """

    check: str
    kind: str
    method: str
    passed: bool
    value: float | None
    figure: str
    tolerance: str
    what: str
    seconds: float
    error: str | None = None
    rows: list = field(default_factory=list)


class BadValue(ValueError):
    """A method returned a value the contract does not allow (names it)."""


def _describe(v: Any) -> str:
    shape = getattr(v, "shape", None)
    return f"{type(v).__name__}" + (f" of shape {tuple(shape)}" if shape is not None else f" {v!r}"[:80])


def _scalar(v: Any, what: str) -> float:
    """``v`` as a finite float, else :class:`BadValue` naming ``what`` and the value."""
    if v is None or isinstance(v, str | bytes):
        raise BadValue(f"{what} is {_describe(v)}; expected a number")
    try:
        arr = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise BadValue(f"{what} is {_describe(v)}; expected a number") from None
    if arr.shape != ():
        raise BadValue(f"{what} has shape {arr.shape}; expected a scalar")
    x = float(arr)
    if not math.isfinite(x):
        raise BadValue(f"{what} is {x}")
    return x


def _failure(exc: BaseException) -> str:
    if isinstance(exc, BadValue):
        return str(exc)
    where = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    at = f" (at {Path(where.filename).name}:{where.lineno})" if where else ""
    return f"{type(exc).__name__}: {exc}{at}"


def method_name(kind: str, method: Any) -> str:
    """The name a method is reported under: its registered name, else its class name."""
    from analysis.base import registry

    if isinstance(method, str):
        return registry.get(kind, method).name
    try:
        return registry.entry_of(kind, method).name
    except registry.RegistryError:
        return type(method).__name__


def _fresh(kind: str, method: Any, params: dict, defaults: dict | None = None) -> Any:
    """A fresh, unfitted instance of ``method`` (a registered name, ``module:Class`` or an
    instance, which is cloned) with ``params`` set where it takes them, and ``defaults`` where it
    takes them and (an instance) leaves them None."""
    from analysis.base import registry

    defaults = defaults or {}
    if isinstance(method, str):
        entry = registry.get(kind, method)
        return registry.create(kind, method, **{k: v for k, v in {**defaults, **params}.items()
                                                if registry.accepts(entry.factory, k)})
    try:
        from sklearn.base import clone

        est = clone(method)
    except Exception:  # noqa: BLE001 - not a scikit-learn estimator: a deep copy then
        est = copy.deepcopy(method)
    if hasattr(est, "get_params") and hasattr(est, "set_params"):
        own = est.get_params(deep=False)
        take = {k: v for k, v in defaults.items() if k in own and own[k] is None}
        take.update({k: v for k, v in params.items() if k in own})
        if take:
            est.set_params(**take)
    return est


def _backlash_value(r: Any, attr: str, session: str) -> float:
    if not hasattr(r, attr):
        raise BadValue(f"estimate({session}) returned {_describe(r)}; expected a SessionBacklash "
                       f"with {attr}")
    return _scalar(getattr(r, attr), f"estimate({session}).{attr}")


def run_backlash_check(method: Any, check: BacklashCheck, cache: GateCache) -> CheckResult:
    """Run one backlash check of ``method`` (registered name, ``module:Class`` or an unfitted
    instance) on the cached campaign; never raises for what the method does."""
    t0 = time.perf_counter()
    name = method_name("backlash_estimators", method)
    inp = cache.phase2(check.campaign, check.position_reference)
    rows, error = [], None
    try:
        params = {"travel_m": inp.travel_m, "lead_m": inp.lead_m} if isinstance(method, str) else {}
        est = _fresh("backlash_estimators", method, {**params, **dict(check.context)})
        which = getattr(est, "primary_estimate", "shift") if check.estimate == "primary" else "pitch"
        if which not in ("shift", "pitch"):
            raise BadValue(f"primary_estimate is {which!r}; expected 'shift' or 'pitch'")
        attr = f"delta_backlash_{which}_m"
        ems = inp.error_motions
        fitted = est.fit(ems[0])
        est = fitted if fitted is not None else est
        for em, inj in zip(ems, inp.injected_um, strict=True):
            got = _backlash_value(est.estimate(em), attr, em.session) * 1e6
            rows.append((em.session, float(inj), got, max(check.abs_um, check.rel * abs(float(inj)))))
    except Exception as exc:  # noqa: BLE001 - whatever the method raises fails this check only
        error = _failure(exc)
    if error is not None:
        return CheckResult(check.name, "backlash", name, False, None, f"failed: {error}", check.tolerance,
                           check.what, time.perf_counter() - t0, error, rows)
    errs = [abs(g - i) for _, i, g, _ in rows]
    k = int(np.argmax([e / t for e, (*_, t) in zip(errs, rows, strict=True)]))
    passed = all(e <= t for e, (*_, t) in zip(errs, rows, strict=True))
    s, i, g, t = rows[k]
    figure = (f"max |error| {max(errs):.2f} µm over {len(rows)} sessions (closest to its tolerance: "
              f"{s}, {g:.2f} µm for {i:g} µm injected, tolerance {t:.1f} µm)")
    return CheckResult(check.name, "backlash", name, passed, max(errs), figure, check.tolerance,
                       check.what, time.perf_counter() - t0, None, rows)


def _scores(det: Any, data: np.ndarray, n_baseline: int) -> tuple[np.ndarray, float]:
    fitted = det.fit(data[:n_baseline])
    det = fitted if fitted is not None else det
    scores = det.decision_function(data)
    arr = np.asarray(scores, dtype=float) if np.ndim(scores) else None
    if arr is None or arr.shape != (len(data),):
        raise BadValue(f"decision_function returned {_describe(scores)}; expected shape ({len(data)},)")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise BadValue(f"decision_function returned {arr[bad]} for sample {bad}")
    return arr, _scalar(getattr(det, "threshold_", None), "threshold_")


def run_detection_checks(method: Any, cache: GateCache, checks: Sequence[DetectionCheck] | None = None
                         ) -> list[CheckResult]:
    """Run the detection checks of ``method`` (registered name, ``module:Class`` or an unfitted
    instance): fit on the baseline of the fault campaign and of the healthy one (each its own
    fit, as ``twin detect`` fits per campaign), score every sample; never raises for what the
    method does."""
    from analysis.phase1 import pipeline
    from analysis.phase1.scoring import score_method

    suite = cache.suite
    checks = list(suite.detection if checks is None else checks)
    t0 = time.perf_counter()
    name = method_name("detectors", method)
    n_base = pipeline.N_BASELINE
    ref = cache.phase1(suite.reference)
    _, selected = pipeline.select_features(ref.X, ref.labels)
    scored, error = {}, None
    try:
        for key in (suite.fault, suite.healthy):
            inp = cache.phase1(key)
            det = _fresh("detectors", method, {}, {"random_state": 0})
            if getattr(det, "phase1_input", "features") == "torque_windows":
                data = inp.ae
            else:
                data = pipeline.baseline_standardised(inp.X, selected, n_base)
            scores, threshold = _scores(det, data, n_base)
            scored[key] = score_method(inp.hours, scores, threshold, n_base, inp.onset_hours)
    except Exception as exc:  # noqa: BLE001 - whatever the method raises fails its checks only
        error = _failure(exc)
    seconds = (time.perf_counter() - t0) / max(len(checks), 1)
    out = []
    for c in checks:
        if error is not None:
            out.append(CheckResult(c.name, "detection", name, False, None, f"failed: {error}", c.tolerance,
                                   c.what, seconds, error))
            continue
        fault = scored[suite.fault]
        if c.kind == "delay":
            value = None if fault.delay_samples is None else float(fault.delay_samples)
            passed = value is not None and value <= c.limit
            figure = ("no detection after the onset" if value is None else
                      f"detected at {fault.detection_hours:g} h, {fault.delay_samples} "
                      f"sample{'s' if fault.delay_samples != 1 else ''} ({fault.delay_hours:g} h) "
                      "after the onset")
        elif c.kind == "false_alarms":
            healthy = scored[suite.healthy]
            fa = fault.false_alarms + healthy.false_alarms
            n = fault.healthy_test_samples + healthy.healthy_test_samples
            value = fa / n
            passed = value <= c.limit
            figure = (f"{value:.3f} ({fa} false alarms on {n} healthy samples: {fault.false_alarms}/"
                      f"{fault.healthy_test_samples} before the onset, {healthy.false_alarms}/"
                      f"{healthy.healthy_test_samples} without wear)")
        else:
            raise GateError(f"detection check {c.name}: kind {c.kind!r}; expected 'delay' or 'false_alarms'")
        out.append(CheckResult(c.name, "detection", name, passed, value, figure, c.tolerance, c.what, seconds))
    return out


def run_backlash_checks(method: Any, cache: GateCache, checks: Sequence[BacklashCheck] | None = None
                        ) -> list[CheckResult]:
    """Every backlash check of the suite (or ``checks``) for ``method``."""
    return [run_backlash_check(method, c, cache) for c in (cache.suite.backlash if checks is None else checks)]


def select_checks(suite: Suite, names: Sequence[str]) -> tuple[list[BacklashCheck], list[DetectionCheck]]:
    """The suite's checks named in ``names`` (all when empty); :class:`GateError` for an unknown one."""
    known = [c.name for c in (*suite.backlash, *suite.detection)]
    if bad := [n for n in names if n not in known]:
        raise GateError(f"--check {bad[0]!r} is unknown; expected one of {', '.join(known)}")
    keep = set(names) or set(known)
    return ([c for c in suite.backlash if c.name in keep], [c for c in suite.detection if c.name in keep])


def resolve_methods(kind: str, specs: Sequence[str]) -> list[str]:
    """Check that every spec names a method of ``kind`` (registered name or ``module:Class``);
    :class:`GateError` naming the bad one otherwise."""
    from analysis.base import registry

    out = []
    for s in specs:
        try:
            registry.get(kind, s)
        except registry.RegistryError as exc:
            raise GateError(f"--{'estimator' if kind == 'backlash_estimators' else 'detector'}: {exc}") from None
        out.append(s)
    return out


def run_gate(estimators: Sequence[Any], detectors: Sequence[Any], cache: GateCache,
             check_names: Sequence[str] = (), on_result: Callable[[CheckResult], None] | None = None
             ) -> list[CheckResult]:
    """Every selected check for every estimator and detector, in order; ``on_result`` gets each
    result as it is known."""
    backlash_checks, detection_checks = select_checks(cache.suite, check_names)
    results: list[CheckResult] = []

    def emit(r: CheckResult) -> None:
        results.append(r)
        if on_result is not None:
            on_result(r)

    for est in estimators:
        for c in backlash_checks:
            emit(run_backlash_check(est, c, cache))
    if detection_checks:
        for det in detectors:
            for r in run_detection_checks(det, cache, detection_checks):
                emit(r)
    return results


