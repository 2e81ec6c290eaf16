"""The gate's cache: each campaign simulated once and reduced to what the checks read (error
motions, Phase I features), verified against its manifest.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.base.files import package_version, sha256_of
from twin.harness.gate.suite import CACHE_ENV, MANIFEST, Campaign, GateError, Suite, get_suite

# ---------------------------------------------------------------------------------------------
# The cache


def default_root() -> Path:
    """``$XDG_CACHE_HOME/ballscrew-twin/gate`` (``~/.cache`` when XDG_CACHE_HOME is unset)."""
    base = os.environ.get(CACHE_ENV) or str(Path.home() / ".cache")
    return Path(base) / "ballscrew-twin" / "gate"


def cache_root(root: str | Path | None = None) -> Path:
    return Path(root) if root is not None else default_root()


def cache_dir(root: str | Path | None, suite: Suite) -> Path:
    """The folder of ``suite`` under ``root``: ``<suite>-v<version>-<package version>``."""
    return cache_root(root) / f"{suite.name}-v{suite.version}-{package_version()}"


def _manifest(folder: Path, suite: Suite) -> dict:
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.name != MANIFEST)
    return {"suite": suite.name, "suite_version": suite.version, "package_version": package_version(),
            "suite_fingerprint": suite.fingerprint(),
            "files": {p.relative_to(folder).as_posix(): {"sha256": sha256_of(p), "bytes": p.stat().st_size}
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
        if p.stat().st_size != meta.get("bytes") or sha256_of(p) != meta.get("sha256"):
            return f"{rel} does not match its sha256 in {MANIFEST}"
    return None


def _outputs(c: Campaign) -> list[str]:
    if c.phase2_references:
        return ["truth.h5", *(f"phase2-{r}.npz" for r in c.phase2_references)]
    return ["truth.h5", "phase1.npz"]


def _save_error_motions(path: Path, ems: list, injected_um: np.ndarray, axis: tuple[float, float]) -> None:
    """The sessions' error motions (SessionErrorMotions) with the injected change of backlash of
    each session against the first (µm) and the axis's (travel, lead) in m, as one npz."""
    from analysis.phase2.error_motion_cache import error_motion_arrays

    arrays = {**error_motion_arrays(ems), "injected_um": np.asarray(injected_um, dtype=float),
              "axis_m": np.asarray(axis, dtype=float)}
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


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
    from analysis.phase2.error_motion_cache import error_motions_from

    with np.load(path, allow_pickle=False) as z:
        travel, lead = (float(v) for v in z["axis_m"])
        return Phase2Input(error_motions_from(z, read_only=True), np.array(z["injected_um"], dtype=float),
                           travel, lead)


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
    from analysis.phase2.error_motion_cache import frozen

    with np.load(path, allow_pickle=False) as z:
        if tuple(str(n) for n in z["names"]) != tuple(FEATURE_NAMES):
            raise GateError(f"{path}: its feature names are not this package's")
        onset = float(z["onset_hours"])
        return Phase1Input(frozen(z["hours"]), frozen(z["X"]), frozen(z["ae"]),
                           None if math.isnan(onset) else onset,
                           frozen(z["labels"]) if "labels" in z else None)


def _prepared(c: Campaign, folder: Path) -> bool:
    """Whether campaign ``c`` in ``folder`` was simulated and reduced by an earlier build (its
    outputs written, its units deleted: the last step of :func:`_build_campaign`)."""
    return all((folder / n).is_file() for n in _outputs(c)) and not (folder / ".parts").exists()


def _tidy(c: Campaign, folder: Path) -> None:
    """Delete what campaign ``c`` wrote beside the files the checks read (its units last: while
    they exist the campaign counts as unfinished, :func:`_prepared`)."""
    (folder / "measurements.h5").unlink(missing_ok=True)
    for extra in folder.iterdir():
        if extra.is_file() and extra.name not in _outputs(c):
            extra.unlink()
    shutil.rmtree(folder / ".parts", ignore_errors=True)


def _build_campaign(c: Campaign, suite: Suite, folder: Path, log: Callable[[str], None]) -> None:
    """Simulate campaign ``c`` into ``folder`` (the units an interrupted build stored there are
    kept, :func:`twin.sim.campaign.simulate_campaign`) and compute what the checks read of it,
    then delete the measurements (see the module docstring)."""
    from analysis.base.executors import mapper
    from analysis.dataset import open_measurements, open_truth
    from analysis.dataset.axis import axis_of
    from analysis.injected import injected_change_um
    from analysis.phase1 import pipeline
    from analysis.phase2.backlash.campaign import session_error_motions_task
    from twin.sim.campaign import simulate_campaign
    from twin.sim.scenario import load

    if _prepared(c, folder):
        _tidy(c, folder)
        log(f"  {c.key}: kept, prepared by an interrupted build")
        return
    t0 = time.perf_counter()
    done = simulate_campaign(load(c.scenario, list(c.overrides)), folder)
    kept = f"; {done['skipped']} of {done['units']} units kept from an interrupted build" if done["skipped"] else ""
    log(f"  simulated {c.key} ({c.scenario}{''.join(' --set ' + o for o in c.overrides)}) "
        f"in {time.perf_counter() - t0:.1f} s{kept}")
    t0 = time.perf_counter()
    meas = folder / "measurements.h5"
    if c.phase2_references:
        for ref in c.phase2_references:
            with open_measurements(meas) as m:  # the error motions only: the checks estimate
                axis, sessions = axis_of(m), m.phase2_sessions()
            ems = []
            for session, (em, why) in zip(sessions, mapper(prefix="session")(
                    session_error_motions_task,
                    [(str(meas.resolve()), s, "raise", {"position_reference": ref}) for s in sessions]), strict=True):
                if em is None:
                    raise GateError(f"gate cache: campaign {c.key}, session {session}: {why}")
                ems.append(em)
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
    _tidy(c, folder)


BUILDING = "building.json"  # in a build's folder: the suite and package it is being built for


def building_dir(folder: Path, suite: Suite, fresh: bool = False) -> Path:
    """The folder a build of ``suite``'s cache ``folder`` works in (moved to ``folder`` when
    complete), with :data:`BUILDING` saying what it is being built for, so a build interrupted
    (killed, a CI job cancelled) is resumed by the next one; one built for another suite
    definition or package version, or any with ``fresh``, is cleared first."""
    tmp = folder.with_name(f"{folder.name}.building")
    want = {"suite": suite.name, "suite_version": suite.version, "package_version": package_version(),
            "suite_fingerprint": suite.fingerprint()}
    try:
        same = not fresh and json.loads((tmp / BUILDING).read_text()) == want
    except (OSError, ValueError):
        same = False
    if not same:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        (tmp / BUILDING).write_text(json.dumps(want))
    return tmp


def _build_lock(folder: Path, log: Callable[[str], None]):
    """An exclusive lock beside ``folder`` for the life of the returned file: a second process
    building the same cache waits for the first (then finds the cache built)."""
    from analysis.base.files import exclusive_lock

    return exclusive_lock(folder.with_name(f"{folder.name}.lock"),
                          f"gate cache {folder}: another process is building it; waiting for it", wait=log)


def build_cache(folder: Path, suite: Suite, log: Callable[[str], None] = print, fresh: bool = False) -> float:
    """Simulate and prepare every campaign of ``suite`` into ``folder`` (built in
    :func:`building_dir`, which keeps what an interrupted build finished, and moved into place
    when complete, with its manifest written last; ``fresh`` keeps nothing). The caller holds
    the build's lock (:func:`ensure_cache`). Returns the seconds taken."""
    t0 = time.perf_counter()
    tmp = building_dir(folder, suite, fresh)
    for i, c in enumerate(suite.campaigns):
        log(f"campaign {i + 1}/{len(suite.campaigns)}: {c.key}: {c.what}")
        _build_campaign(c, suite, tmp / "campaigns" / c.key, log)
    (tmp / BUILDING).unlink()
    (tmp / MANIFEST).write_text(json.dumps(_manifest(tmp, suite), indent=1) + "\n")
    if folder.exists():
        shutil.rmtree(folder)
    tmp.rename(folder)
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
    with _build_lock(folder, log):
        if not rebuild and verify(folder, suite) is None:  # built by the process it waited for
            log(f"gate cache {folder}: verified ({len(suite.campaigns)} campaigns)")
            return GateCache(folder, suite)
        seconds = build_cache(folder, suite, log, fresh=rebuild)
    if (why := verify(folder, suite)) is not None:
        raise GateError(f"gate cache {folder}: just built, yet {why}")
    log(f"gate cache built in {seconds:.0f} s")
    return GateCache(folder, suite, seconds)


