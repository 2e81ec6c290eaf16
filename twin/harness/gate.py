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
missing, altered or stale cache is rebuilt, never trusted. The npz files are read with
``allow_pickle=False``: loading the cache executes no code from it.

Units: SI inside; µm, h and samples in the printed figures and the JUnit XML.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import shutil
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np

__all__ = ["SUITES", "BacklashCheck", "Campaign", "CheckResult", "DetectionCheck", "GateCache",
           "GateError", "Suite", "cache_root", "default_root", "ensure_cache", "junit_xml",
           "package_version", "run_backlash_checks", "run_detection_checks", "run_gate"]

CACHE_ENV = "XDG_CACHE_HOME"
MANIFEST = "manifest.json"


class GateError(ValueError):
    """Bad input to the gate (unknown suite, check or method): the command exits 2."""


# ---------------------------------------------------------------------------------------------
# The suite


@dataclass(frozen=True)
class Campaign:
    """One cached campaign: a shipped scenario with ``--set`` overrides.

    key: folder name in the cache. phase2_references: the position axes ("command", "imu") whose
    error motions the checks read (Phase II campaigns); empty for Phase I campaigns.
    """

    key: str
    scenario: str
    overrides: tuple[str, ...]
    what: str
    phase2_references: tuple[str, ...] = ()


@dataclass(frozen=True)
class BacklashCheck:
    """A Phase II recovery check.

    campaign: key of a :class:`Campaign`. position_reference: "command" or "imu" (the traces'
    position axis). context: estimator parameters set where the estimator takes them (e.g.
    ``stationary="E_XX"``, Eq. 5). estimate: "primary" (the estimator's ``primary_estimate``) or
    "pitch" (Eq. 9, ``delta_backlash_pitch_m``). Tolerance per session: max(abs_um, rel × |injected
    change|), µm.
    """

    name: str
    campaign: str
    position_reference: str
    what: str
    context: tuple[tuple[str, Any], ...] = ()
    estimate: str = "primary"
    abs_um: float = 1.0
    rel: float = 0.10

    @property
    def tolerance(self) -> str:
        return f"max({self.abs_um:g} µm, {self.rel * 100:g} %) per session"


@dataclass(frozen=True)
class DetectionCheck:
    """A Phase I check. kind "delay": the detection after the injected onset on ``fault``, at most
    ``limit`` samples after it; kind "false_alarms": alarms per healthy post-baseline sample of
    ``fault`` (up to its onset) and ``healthy`` (no degradation) together, at most ``limit``."""

    name: str
    kind: str
    limit: float
    what: str

    @property
    def tolerance(self) -> str:
        return (f"detected within {self.limit:g} samples after the onset" if self.kind == "delay"
                else f"at most {self.limit:g} false alarms per healthy sample")


@dataclass(frozen=True)
class Suite:
    """A versioned set of checks. ``version`` changes whenever a campaign, a check or a tolerance
    does (it keys the cache); ``reference``, ``fault``, ``healthy``: the Phase I campaigns."""

    name: str
    version: int
    campaigns: tuple[Campaign, ...]
    backlash: tuple[BacklashCheck, ...]
    detection: tuple[DetectionCheck, ...]
    reference: str = "reference"
    fault: str = "fault"
    healthy: str = "healthy"

    def campaign(self, key: str) -> Campaign:
        return next(c for c in self.campaigns if c.key == key)

    def fingerprint(self) -> str:
        """sha256 of the suite's definition (a cache built for another definition is stale)."""
        return hashlib.sha256(json.dumps(asdict(self), sort_keys=True, default=str).encode()).hexdigest()


NOISE2 = ("sensors.imu_acc_noise_ug_per_rthz=14.0", "sensors.imu_gyro_noise_urad_s_per_rthz=70.0")
NOISE4 = ("sensors.imu_acc_noise_ug_per_rthz=28.0", "sensors.imu_gyro_noise_urad_s_per_rthz=140.0")
EQ5 = (("stationary", "E_XX"),)

STANDARD = Suite(
    name="standard", version=1,
    campaigns=(
        Campaign("steps", "backlash-steps", (), "backlash-steps: 0, 0, 2, 5, 10, 20 µm, 100 mm/s, "
                 "10 runs, paper IMU noise", ("command",)),
        Campaign("steps-20-drift", "backlash-drift", (), "backlash-steps at 20 mm/s, 40 runs, "
                 "position_cmd drifting 0.5 ms per 1000 h against the IMU", ("command", "imu")),
        Campaign("slow-reversal", "backlash-slow-reversal", (), "0, 5, 10, 20 µm at 20 mm/s with "
                 "50 mm/s² reversals (D = L - b)", ("imu",)),
        Campaign("steps-noise2", "backlash-steps", NOISE2, "backlash-steps with twice the paper's "
                 "IMU noise (14 µg/√Hz, 70 µrad/s/√Hz)", ("command",)),
        Campaign("steps-noise4", "backlash-steps", NOISE4, "backlash-steps with four times the "
                 "paper's IMU noise (28 µg/√Hz, 140 µrad/s/√Hz)", ("command",)),
        Campaign("reference", "paper-reference", ("phase1.captures_per_sample=2", "phase1.capture_s=4.0",
                                                  "phase1.sample_interval_hours=20"),
                 "the reference data set, 5 samples per condition (Fisher selection)"),
        Campaign("fault", "phase1-quick", (), "preload loss from 172 h: 18 healthy samples "
                 "(15 baseline), 6 after the onset"),
        Campaign("healthy", "phase1-quick", ("degradation.wear_rate_um_per_kh=0", "campaign.total_hours=420"),
                 "phase1-quick without wear: 42 healthy samples"),
    ),
    backlash=(
        BacklashCheck("steps-command-100mm_s", "steps", "command",
                      "backlash-steps at 100 mm/s on the command axis (Eq. 4)"),
        BacklashCheck("steps-imu-20mm_s", "steps-20-drift", "imu",
                      "backlash-steps at 20 mm/s from the IMU alone, 40 runs (Eq. 5; the IMU axis "
                      "reads no position_cmd, so the drift is not seen)", EQ5),
        BacklashCheck("drift-eq5-command", "steps-20-drift", "command",
                      "the same campaign on the command axis, whose position_cmd drifts 0.25 ms "
                      "against the IMU over the sessions: Eq. 5 must cancel the common mode "
                      "(Eq. 4 reads 2vΔτ = up to 10 µm of it as backlash)", EQ5),
        BacklashCheck("slow-reversal-eq9", "slow-reversal", "imu",
                      "Eq. 9 (perceived pitch) on the IMU axis where the carriage travels L - b",
                      EQ5, estimate="pitch", abs_um=2.0, rel=0.20),
        BacklashCheck("noise2-command-100mm_s", "steps-noise2", "command",
                      "backlash-steps at 100 mm/s, IMU noise twice the paper's"),
        BacklashCheck("noise4-command-100mm_s", "steps-noise4", "command",
                      "backlash-steps at 100 mm/s, IMU noise four times the paper's"),
    ),
    detection=(
        DetectionCheck("detection-delay", "delay", 3,
                       "phase1-quick against the reference: samples from the injected onset "
                       "(172 h) to the detection"),
        DetectionCheck("false-alarms", "false_alarms", 0.10,
                       "alarms on the healthy post-baseline samples of phase1-quick (before its "
                       "onset) and of its no-wear variant, per healthy sample"),
    ),
)

SUITES: dict[str, Suite] = {STANDARD.name: STANDARD}


def get_suite(name: str) -> Suite:
    """The suite ``name``; :class:`GateError` naming the known suites otherwise."""
    if name not in SUITES:
        raise GateError(f"--suite {name!r} is unknown; expected one of {', '.join(SUITES)}")
    return SUITES[name]


# ---------------------------------------------------------------------------------------------
# The cache


def package_version() -> str:
    """The installed version of ``ballscrew-twin`` ("unknown" when it is not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ballscrew-twin")
    except PackageNotFoundError:
        return "unknown"


def default_root() -> Path:
    """``$XDG_CACHE_HOME/ballscrew-twin/gate`` (``~/.cache`` when XDG_CACHE_HOME is unset)."""
    base = os.environ.get(CACHE_ENV) or str(Path.home() / ".cache")
    return Path(base) / "ballscrew-twin" / "gate"


def cache_root(root: str | Path | None = None) -> Path:
    return Path(root) if root is not None else default_root()


def cache_dir(root: str | Path | None, suite: Suite) -> Path:
    """The folder of ``suite`` under ``root``: ``<suite>-v<version>-<package version>``."""
    return cache_root(root) / f"{suite.name}-v{suite.version}-{package_version()}"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _manifest(folder: Path, suite: Suite) -> dict:
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.name != MANIFEST)
    return {"suite": suite.name, "suite_version": suite.version, "package_version": package_version(),
            "suite_fingerprint": suite.fingerprint(),
            "files": {p.relative_to(folder).as_posix(): {"sha256": _sha256(p), "bytes": p.stat().st_size}
                      for p in files}}


def verify(folder: Path, suite: Suite) -> str | None:
    """None if ``folder`` holds a complete cache of ``suite`` for this package version whose every
    file matches its sha256 in the manifest; else why not (one line)."""
    path = folder / MANIFEST
    if not path.is_file():
        return f"no {MANIFEST}"
    try:
        doc = json.loads(path.read_text())
        files = doc["files"]
        key = (doc["suite"], doc["suite_version"], doc["package_version"], doc["suite_fingerprint"])
    except (ValueError, KeyError, TypeError) as exc:
        return f"{MANIFEST} unreadable ({type(exc).__name__}: {exc})"
    want = (suite.name, suite.version, package_version(), suite.fingerprint())
    if key != want:
        return f"stale: built for suite/version/package/definition {key[:3]}, this is {want[:3]}" + (
            "" if key[3] == want[3] else " (suite definition changed)")
    needed = {f"campaigns/{c.key}/{n}" for c in suite.campaigns for n in _outputs(c)}
    if missing := sorted(needed - set(files)):
        return f"{MANIFEST} lacks {missing[0]}"
    for rel, meta in files.items():
        p = folder / rel
        if not p.is_file():
            return f"{rel} is missing"
        if p.stat().st_size != meta.get("bytes") or _sha256(p) != meta.get("sha256"):
            return f"{rel} does not match its sha256 in {MANIFEST}"
    return None


def _outputs(c: Campaign) -> list[str]:
    if c.phase2_references:
        return ["truth.h5", *(f"phase2-{r}.npz" for r in c.phase2_references)]
    return ["truth.h5", "phase1.npz"]


def _save_error_motions(path: Path, ems: list, injected_um: np.ndarray, axis: tuple[float, float]) -> None:
    """The sessions' error motions (SessionErrorMotions) with the injected change of backlash of
    each session against the first (µm) and the axis's (travel, lead) in m, as one npz."""
    arrays: dict[str, np.ndarray] = {
        "sessions": np.array([e.session for e in ems]), "hours": np.array([e.hours for e in ems]),
        "injected_um": np.asarray(injected_um, dtype=float), "axis_m": np.asarray(axis, dtype=float),
        "position_reference": np.array([e.position_reference for e in ems])}
    for i, e in enumerate(ems):
        arrays[f"{i}/runs"] = np.array(e.runs)
        for part in ("combined", "slow"):
            tr = getattr(e, part)
            arrays[f"{i}/{part}/x_m"] = tr.x_m
            arrays[f"{i}/{part}/forward"] = tr.forward
            arrays[f"{i}/{part}/reverse"] = tr.reverse
            if tr.band_m is not None:
                arrays[f"{i}/{part}/band_m"] = tr.band_m
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def _frozen(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only: a method that writes into its input fails its check (naming the
    error) instead of changing what the next method is given."""
    a = np.array(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Phase2Input:
    """What a backlash check feeds the estimator: the sessions' error motions in hours order
    (the first is the reference), the injected change of each against the first (µm) and the
    axis's travel and lead (m)."""

    error_motions: list
    injected_um: np.ndarray
    travel_m: float
    lead_m: float


def _load_error_motions(path: Path) -> Phase2Input:
    from analysis.phase2.traces import DirectionalTraces, SessionErrorMotions

    with np.load(path, allow_pickle=False) as z:
        names, hours, refs = z["sessions"], z["hours"], z["position_reference"]
        ems = []
        for i, name in enumerate(names):
            parts = {part: DirectionalTraces(_frozen(z[f"{i}/{part}/x_m"]), _frozen(z[f"{i}/{part}/forward"]),
                                             _frozen(z[f"{i}/{part}/reverse"]),
                                             _frozen(z[f"{i}/{part}/band_m"]) if f"{i}/{part}/band_m" in z else None)
                     for part in ("combined", "slow")}
            ems.append(SessionErrorMotions(session=str(name), hours=float(hours[i]),
                                           runs=tuple(str(r) for r in z[f"{i}/runs"]),
                                           combined=parts["combined"], slow=parts["slow"],
                                           position_reference=str(refs[i])))
        travel, lead = (float(v) for v in z["axis_m"])
        return Phase2Input(ems, np.array(z["injected_um"], dtype=float), travel, lead)


@dataclass(frozen=True)
class Phase1Input:
    """A campaign's Phase I feature table (:class:`analysis.phase1.pipeline.FeatureTable`
    fields: hours (n,) h, X (n, 46), ae (n, m) N·m), its injected onset (h, None: no
    degradation) and, for the reference set, the condition labels (n,) (0 healthy, 1 faulty,
    -1 unused)."""

    hours: np.ndarray
    X: np.ndarray
    ae: np.ndarray
    onset_hours: float | None
    labels: np.ndarray | None


def _save_phase1(path: Path, table, onset: float | None, labels: np.ndarray | None) -> None:
    arrays = {"hours": table.hours, "X": table.X, "ae": table.ae, "names": np.array(table.names),
              "onset_hours": np.array(np.nan if onset is None else onset, dtype=float)}
    if labels is not None:
        arrays["labels"] = labels
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def _load_phase1(path: Path) -> Phase1Input:
    from analysis.phase1.features import FEATURE_NAMES

    with np.load(path, allow_pickle=False) as z:
        if tuple(str(n) for n in z["names"]) != tuple(FEATURE_NAMES):
            raise GateError(f"{path}: its feature names are not this package's")
        onset = float(z["onset_hours"])
        return Phase1Input(_frozen(z["hours"]), _frozen(z["X"]), _frozen(z["ae"]),
                           None if math.isnan(onset) else onset,
                           _frozen(z["labels"]) if "labels" in z else None)


def _build_campaign(c: Campaign, suite: Suite, folder: Path, log: Callable[[str], None]) -> None:
    """Simulate campaign ``c`` into ``folder`` and compute what the checks read of it, then delete
    the measurements (see the module docstring)."""
    from analysis.dataset import open_measurements, open_truth
    from analysis.dataset.axis import axis_of
    from analysis.injected import injected_change_um
    from analysis.phase1 import pipeline
    from analysis.phase2.backlash import campaign_backlash
    from twin.campaign import simulate_campaign
    from twin.executors import mapper
    from twin.scenario import load

    t0 = time.perf_counter()
    simulate_campaign(load(c.scenario, list(c.overrides)), folder)
    log(f"  simulated {c.key} ({c.scenario}{''.join(' --set ' + o for o in c.overrides)}) "
        f"in {time.perf_counter() - t0:.1f} s")
    t0 = time.perf_counter()
    meas = folder / "measurements.h5"
    if c.phase2_references:
        for ref in c.phase2_references:
            with open_measurements(meas) as m:
                axis = axis_of(m)
                res = campaign_backlash(m, on_bad_run="raise", position_reference=ref,
                                        map_sessions=mapper(prefix="session"))
            ems = res.error_motions
            with open_truth(folder / "truth.h5") as t:
                injected = injected_change_um(t, [e.session for e in ems])
            _save_error_motions(folder / f"phase2-{ref}.npz", ems, injected,
                                (axis.require("travel_mm", "the gate") * 1e-3,
                                 axis.require("lead_mm", "the gate") * 1e-3))
    else:
        table = pipeline.extract(meas)
        labels = None
        if c.key == suite.reference:
            labels = pipeline.reference_labels(folder / "truth.h5", table.hours)
        onset = None
        if c.key == suite.fault:
            with open_truth(folder / "truth.h5") as t:
                onset = t.onset_hours
        _save_phase1(folder / "phase1.npz", table, onset, labels)
    log(f"  prepared {c.key} in {time.perf_counter() - t0:.1f} s")
    meas.unlink()
    shutil.rmtree(folder / ".parts", ignore_errors=True)
    for extra in folder.iterdir():  # anything else the campaign wrote beside truth.h5
        if extra.is_file() and extra.name not in _outputs(c):
            extra.unlink()


def build_cache(folder: Path, suite: Suite, log: Callable[[str], None] = print) -> float:
    """Simulate and prepare every campaign of ``suite`` into ``folder`` (built beside it and moved
    into place when complete, with its manifest written last). Returns the seconds taken."""
    t0 = time.perf_counter()
    tmp = folder.with_name(f"{folder.name}.building-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    for i, c in enumerate(suite.campaigns):
        log(f"campaign {i + 1}/{len(suite.campaigns)}: {c.key}: {c.what}")
        _build_campaign(c, suite, tmp / "campaigns" / c.key, log)
    (tmp / MANIFEST).write_text(json.dumps(_manifest(tmp, suite), indent=1) + "\n")
    if folder.exists():
        shutil.rmtree(folder)
    try:
        tmp.rename(folder)
    except OSError:  # another process put a cache in place meanwhile: keep it if it verifies
        if verify(folder, suite) is not None:
            raise
        shutil.rmtree(tmp, ignore_errors=True)
    return time.perf_counter() - t0


@dataclass
class GateCache:
    """A verified cache: its folder, the suite, and the inputs loaded on first use."""

    folder: Path
    suite: Suite
    build_seconds: float | None = None
    _phase2: dict = field(default_factory=dict, repr=False)
    _phase1: dict = field(default_factory=dict, repr=False)

    def phase2(self, campaign: str, reference: str) -> Phase2Input:
        key = (campaign, reference)
        if key not in self._phase2:
            self._phase2[key] = _load_error_motions(self.folder / "campaigns" / campaign / f"phase2-{reference}.npz")
        return self._phase2[key]

    def phase1(self, campaign: str) -> Phase1Input:
        if campaign not in self._phase1:
            self._phase1[campaign] = _load_phase1(self.folder / "campaigns" / campaign / "phase1.npz")
        return self._phase1[campaign]


def ensure_cache(root: str | Path | None = None, suite: str | Suite = "standard", *, rebuild: bool = False,
                 log: Callable[[str], None] = print) -> GateCache:
    """The verified cache of ``suite`` under ``root`` (default :func:`default_root`), built first
    if it is missing, corrupt or stale (or ``rebuild``). ``log`` gets one line per step."""
    suite = get_suite(suite) if isinstance(suite, str) else suite
    folder = cache_dir(root, suite)
    why = "rebuild asked for" if rebuild else verify(folder, suite)
    if why is None:
        log(f"gate cache {folder}: verified ({len(suite.campaigns)} campaigns)")
        return GateCache(folder, suite)
    log(f"gate cache {folder}: {why}; building it (simulates {len(suite.campaigns)} campaigns)")
    folder.parent.mkdir(parents=True, exist_ok=True)
    seconds = build_cache(folder, suite, log)
    if (why := verify(folder, suite)) is not None:
        raise GateError(f"gate cache {folder}: just built, yet {why}")
    log(f"gate cache built in {seconds:.0f} s")
    return GateCache(folder, suite, seconds)


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
    from analysis import registry

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
    from analysis import registry

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
    from analysis import registry

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


# ---------------------------------------------------------------------------------------------
# JUnit XML


def junit_xml(results: Sequence[CheckResult], suite: Suite, path: str | Path) -> None:
    """Write ``results`` as JUnit XML (one ``testsuite`` per method, one ``testcase`` per check,
    ``failure`` with the figure or the error): the form Jenkins, GitLab CI, GitHub Actions
    reporters and Azure Pipelines read."""
    root = ET.Element("testsuites", name=f"twin gate {suite.name} v{suite.version}",
                      tests=str(len(results)), failures=str(sum(not r.passed for r in results)),
                      time=f"{sum(r.seconds for r in results):.3f}")
    groups: dict[tuple[str, str], list[CheckResult]] = {}
    for r in results:
        groups.setdefault((r.kind, r.method), []).append(r)
    for (kind, method), rs in groups.items():
        ts = ET.SubElement(root, "testsuite", name=f"{kind}.{method}", tests=str(len(rs)),
                           failures=str(sum(not r.passed for r in rs)), errors="0", skipped="0",
                           time=f"{sum(r.seconds for r in rs):.3f}")
        props = ET.SubElement(ts, "properties")
        for k, v in (("suite", suite.name), ("suite_version", str(suite.version)),
                     ("package_version", package_version())):
            ET.SubElement(props, "property", name=k, value=v)
        for r in rs:
            tc = ET.SubElement(ts, "testcase", classname=f"twin.gate.{kind}.{method}", name=r.check,
                               time=f"{r.seconds:.3f}")
            text = f"{r.what}\nfigure: {r.figure}\ntolerance: {r.tolerance}\n" + "".join(
                f"  {s}: injected {i:g} µm, estimated {g:.3f} µm, tolerance {t:.2f} µm\n" for s, i, g, t in r.rows)
            if not r.passed:
                f = ET.SubElement(tc, "failure", message=(r.error or f"{r.figure}; tolerance {r.tolerance}"),
                                  type="error" if r.error else "tolerance")
                f.text = text
            ET.SubElement(tc, "system-out").text = text
    ET.indent(root)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


# ---------------------------------------------------------------------------------------------
# The command


def _default(kind: str) -> list[str]:
    from analysis import registry

    return [registry.default(kind).name]


def _expand(kind: str, specs: Sequence[str]) -> list[str]:
    from analysis import registry

    out: list[str] = []
    for s in specs:
        out.extend(registry.names(kind) if s == "all" else [s])
    return resolve_methods(kind, out)


def command(estimators: Sequence[str], detectors: Sequence[str], suite: str = "standard",
            junit: str | Path | None = None, root: str | Path | None = None,
            checks: Sequence[str] = (), rebuild: bool = False, console=None) -> int:
    """``twin gate``: verify or build the cache, run the checks, print one row per check (figure,
    tolerance, verdict) and the times, write JUnit XML if asked. Returns the exit code: 0 if
    every check passed, 1 otherwise. Without ``estimators`` and ``detectors``: the default
    estimator and the default detector (the paper's methods); ``all`` stands for every
    registered one. Raises :class:`GateError` on bad input (exit 2)."""
    from rich.console import Console

    console = console or Console()
    s = get_suite(suite)
    if not estimators and not detectors:
        estimators, detectors = _default("backlash_estimators"), _default("detectors")
    estimators, detectors = _expand("backlash_estimators", estimators), _expand("detectors", detectors)
    b_checks, d_checks = select_checks(s, checks)
    if not ((b_checks and estimators) or (d_checks and detectors)):
        raise GateError(f"no check to run: {len(b_checks)} backlash checks for {len(estimators)} estimators, "
                        f"{len(d_checks)} detection checks for {len(detectors)} detectors")
    folder = cache_dir(root, s)
    if (rebuild or verify(folder, s) is not None) and not _has_simulator():
        raise GateError(f"gate cache {folder} must be built, which needs the simulator: "
                        "pip install 'ballscrew-twin[sim]' (or restore the cache folder)")
    t0 = time.perf_counter()
    cache = ensure_cache(root, s, rebuild=rebuild,
                         log=lambda line: console.print(line, markup=False, highlight=False, soft_wrap=True))
    t_cache = time.perf_counter() - t0

    def on_result(r: CheckResult) -> None:
        console.print(f"{'PASS' if r.passed else 'FAIL'}  {r.kind} {r.check} [{r.method}]: {r.figure}; "
                      f"tolerance {r.tolerance}", markup=False, highlight=False, soft_wrap=True,
                      style="green" if r.passed else "red")

    console.print(f"suite {s.name} v{s.version}, package {package_version()}", markup=False,
                  highlight=False, soft_wrap=True)
    t0 = time.perf_counter()
    results = run_gate(estimators if b_checks else [], detectors if d_checks else [], cache,
                       checks, on_result)
    t_checks = time.perf_counter() - t0
    failed = [r for r in results if not r.passed]
    how = (f"cache built in {cache.build_seconds:.0f} s" if cache.build_seconds is not None
           else f"cache verified in {t_cache:.1f} s")
    console.print(f"{len(results)} checks, {len(failed)} failed; checks took {t_checks:.1f} s, {how} "
                  f"({cache.folder})", markup=False, highlight=False, soft_wrap=True)
    if junit is not None:
        junit_xml(results, s, junit)
        console.print(f"wrote {junit}", markup=False, highlight=False)
    return 1 if failed or not results else 0


def _has_simulator() -> bool:
    import importlib.util

    return importlib.util.find_spec("mujoco") is not None
