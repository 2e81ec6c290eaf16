"""A representative subset of a campaign-sized recording, sized to a time budget.

The diagnosis simulates the recording's layout once per twin seed and candidate grid point, so
its cost grows with the recording. For a recording of a whole campaign (the paper's: 104 Phase
I samples of 10 captures, 103 Phase II sessions of 90 runs) it diagnoses a subset instead:

- :func:`inventory` lists the recording's parts from their attributes (no array is read);
- :func:`choose` picks K Phase I samples (their first c captures) and M Phase II sessions
  (their first r runs), spread evenly over the recording's hours with the first and the last
  always in (:func:`spread`), the largest such subset whose estimated cost
  (:class:`UnitCosts`, :class:`Workload`) fits the budget; c, r ≥ 2 so that the calibration
  (even) and held-out (odd) parts both exist. The sizes grow along one ladder (:func:`ladder`):
  first more samples and sessions at c = r = 2, then more captures and runs in each, so every
  size is non-decreasing in the budget;
- :func:`write_subset` writes those parts, with their names, hours, sample indices, sampling
  rates and routines, to a ``measurements.h5`` of the same format, which the signature code
  reads unchanged.

No randomness: the same recording, costs and budget give the same subset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.dataset import DatasetError, assemble_measurements, open_measurements

MIN_PARTS = 2  # first and last sample (session): the hours' ends
MIN_REPEATS = 2  # captures per sample, runs per session: one to fit, one held out


@dataclass(frozen=True)
class Inventory:
    """The parts of a recording. samples: [(sample index, hours of its first capture, capture
    names in time order)]; sessions: [(name, hours, run names)]; both sorted by hours."""

    samples: list[tuple[int, float, list[str]]]
    sessions: list[tuple[str, float, list[str]]]

    @property
    def captures(self) -> int:
        """Captures per sample available in every sample (the fewest)."""
        return min((len(c) for _, _, c in self.samples), default=0)

    @property
    def runs(self) -> int:
        """Runs per session available in every session (the fewest)."""
        return min((len(r) for _, _, r in self.sessions), default=0)


def inventory(path: str | Path) -> Inventory:
    """The :class:`Inventory` of the ``measurements.h5`` at ``path``, from attributes only."""
    with open_measurements(path) as m:
        by_sample: dict[int, list[tuple[float, str]]] = {}
        for name in m.phase1_captures():
            hours, sample, _ = m.phase1_header(name)
            by_sample.setdefault(sample, []).append((hours, name))
        samples = sorted((caps[0][0], k, [n for _, n in caps]) for k, caps in
                         ((k, sorted(v)) for k, v in by_sample.items()))
        sessions = [(s, m.session_hours(s), m.phase2_runs(s)) for s in m.phase2_sessions()]
    return Inventory([(k, h, names) for h, k, names in samples], sessions)


def spread(hours: list[float] | np.ndarray, k: int) -> list[int]:
    """Indices of ``k`` of the parts at ``hours`` (sorted), spread evenly over the hours: for
    each of k targets evenly spaced from the first hour to the last, the nearest part not yet
    taken (ties: the earlier); the first and the last part are always in (k ≥ 2). Sorted."""
    h = np.asarray(hours, dtype=float)
    n = h.size
    k = min(int(k), n)
    if k <= 0:
        return []
    if k == 1:
        return [0]
    free = np.ones(n, dtype=bool)
    free[[0, n - 1]] = False
    for target in np.linspace(h[0], h[-1], k)[1:-1]:
        free[int(np.argmin(np.where(free, np.abs(h - target), np.inf)))] = False
    return np.flatnonzero(~free).tolist()


@dataclass(frozen=True)
class Size:
    """K samples of c captures, M sessions of r runs."""

    samples: int
    captures: int
    sessions: int
    runs: int


def ladder(inv: Inventory) -> list[Size]:
    """Every size tried, cheapest first and each part non-decreasing along the list: from the
    minimum (2 samples × 2 captures, 2 sessions × 2 runs, or fewer where the recording has
    fewer) the samples and sessions grow together to all of them, then the captures and runs
    together to all of them. A sample with fewer than 2 captures or a session with fewer than
    2 runs raises :class:`DatasetError` naming it (nothing could be held out)."""
    for k, h, caps in inv.samples:
        if len(caps) < MIN_REPEATS:
            raise DatasetError(f"Phase I sample {k} ({h:g} h) has {len(caps)} capture(s); the diagnosis "
                               "needs at least 2 per sample (even ones to fit, odd ones held out)")
    for s, h, runs in inv.sessions:
        if len(runs) < MIN_REPEATS:
            raise DatasetError(f"Phase II session {s} ({h:g} h) has {len(runs)} run(s); the diagnosis "
                               "needs at least 2 per session (even ones to fit, odd ones held out)")
    n1, n2, c_all, r_all = len(inv.samples), len(inv.sessions), inv.captures, inv.runs
    k0, m0 = min(MIN_PARTS, n1), min(MIN_PARTS, n2)
    c0, r0 = min(MIN_REPEATS, c_all), min(MIN_REPEATS, r_all)
    out: list[Size] = []
    steps = max(n1 - k0, n2 - m0, 0)
    for i in range(steps + 1):
        f = i / steps if steps else 1.0
        out.append(Size(k0 + round(f * (n1 - k0)), c0, m0 + round(f * (n2 - m0)), r0))
    steps = max(c_all - c0, r_all - r0, 0)
    for j in range(1, steps + 1):
        f = j / steps
        out.append(Size(n1, c0 + round(f * (c_all - c0)), n2, r0 + round(f * (r_all - r0))))
    dedup: list[Size] = []
    for s in out:
        if not dedup or s != dedup[-1]:
            dedup.append(s)
    return dedup


@dataclass(frozen=True)
class UnitCosts:
    """Wall seconds on one worker. Simulating and computing the signature of: one Phase I
    capture (``capture``), one Phase II session's motion (``session``, shared by its runs),
    each run of a session (``run``: its sensors and statistics); the signature alone of the
    same (``*_signature``: what a signal artefact's post-processing recomputes)."""

    capture: float
    session: float
    run: float
    capture_signature: float
    session_signature: float
    run_signature: float


@dataclass(frozen=True)
class Workload:
    """What a diagnosis computes, in recordings of the subset's layout: ``campaigns`` twin
    campaigns simulated (seeds, candidate grid points, re-simulations), ``phase1_signatures`` /
    ``phase2_signatures`` recomputations of the Phase I / Phase II statistics (the signal
    artefacts' grid points, post-processed), on ``workers`` workers at once; ``stages``: the
    rounds of simulations that wait for the one before (each takes at least one campaign,
    however many workers)."""

    campaigns: int
    phase1_signatures: int
    phase2_signatures: int
    workers: int
    stages: int = 1


def cost_s(size: Size, costs: UnitCosts, work: Workload) -> float:
    """Estimated wall seconds of ``work`` on a subset of ``size``: in this process the first
    twin campaign (the layout check simulates it) and the recording's own signature; the
    other campaigns' and the post-processings' unit costs summed and divided by the workers
    (they are independent tasks; the batching of campaigns only makes them cheaper), but no
    less than one campaign per stage. Not counted: starting the workers, the gap test and the
    report (seconds, whatever the size)."""
    p1 = size.samples * size.captures
    p1_sim, p1_sig = p1 * costs.capture, p1 * costs.capture_signature
    p2_sim = size.sessions * (costs.session + size.runs * costs.run)
    p2_sig = size.sessions * (costs.session_signature + size.runs * costs.run_signature)
    first = min(work.campaigns, 1)
    parallel = ((work.campaigns - first) * (p1_sim + p2_sim) + work.phase1_signatures * p1_sig
                + work.phase2_signatures * p2_sig)
    return (max(parallel / max(work.workers, 1), work.stages * (p1_sim + p2_sim))
            + first * (p1_sim + p2_sim) + p1_sig + p2_sig)


@dataclass(frozen=True)
class Subset:
    """The parts chosen: ``samples`` [(sample index, hours of its first capture)] with their
    first ``captures`` captures, ``sessions`` [(name, hours)] with their first ``runs`` runs;
    ``size`` their counts; ``fits``: whether the estimated cost is within the budget (False:
    the minimum, which does not fit); ``estimated_s`` its estimated cost."""

    samples: list[tuple[int, float]]
    captures: int
    sessions: list[tuple[str, float]]
    runs: int
    fits: bool
    estimated_s: float

    def to_json(self, inv: Inventory) -> dict:
        """The ``subset`` entry of ``diagnosis.json`` (without the budget and the times)."""
        return {"phase1": {"samples": [k for k, _ in self.samples], "hours": [h for _, h in self.samples],
                           "captures_per_sample": self.captures, "of_samples": len(inv.samples),
                           "of_captures_per_sample": inv.captures},
                "phase2": {"sessions": [s for s, _ in self.sessions], "hours": [h for _, h in self.sessions],
                           "runs_per_session": self.runs, "of_sessions": len(inv.sessions),
                           "of_runs_per_session": inv.runs},
                "fits": self.fits}


def check_budget(budget_s: float) -> float:
    """The budget in seconds, or ValueError naming it unless positive and finite."""
    b = float(budget_s)
    if not (math.isfinite(b) and b > 0):
        raise ValueError(f"time budget is {budget_s:g} s; expected a positive, finite number of seconds")
    return b


def choose(inv: Inventory, costs: UnitCosts, work: Workload, budget_s: float) -> Subset:
    """The largest size of :func:`ladder` whose :func:`cost_s` is within ``budget_s`` (the
    minimum, with ``fits`` False, when none is), its parts spread over the hours
    (:func:`spread`)."""
    budget_s = check_budget(budget_s)
    sizes = ladder(inv)
    est = [cost_s(s, costs, work) for s in sizes]
    ok = [i for i, e in enumerate(est) if e <= budget_s]
    i = ok[-1] if ok else 0
    return _parts(inv, sizes[i], bool(ok), est[i])


def minimum(inv: Inventory) -> Subset:
    """The smallest subset (the first size of :func:`ladder`), estimated cost unknown (NaN)."""
    return _parts(inv, ladder(inv)[0], False, float("nan"))


def _parts(inv: Inventory, size: Size, fits: bool, estimated_s: float) -> Subset:
    ks = spread([h for _, h, _ in inv.samples], size.samples)
    ms = spread([h for _, h, _ in inv.sessions], size.sessions)
    return Subset([(inv.samples[j][0], inv.samples[j][1]) for j in ks], size.captures,
                  [(inv.sessions[j][0], inv.sessions[j][1]) for j in ms], size.runs, fits, estimated_s)


def write_subset(src: str | Path, dst: str | Path, inv: Inventory, sub: Subset) -> Path:
    """Write the parts of ``sub`` of the recording ``src`` (whose :func:`inventory` is ``inv``)
    to ``dst``, a ``measurements.h5`` of the same format: the same axis description, the chosen
    captures (names, hours, sample index, rate, arrays) and runs (session names and hours, run
    names, routine attributes, channels and rates), and every dial-indicator reading. Only the
    chosen parts are read."""
    samples = {k for k, _ in sub.samples}
    sessions = {s for s, _ in sub.sessions}
    with open_measurements(src) as m:
        def phase1():
            for k, _, names in inv.samples:
                if k in samples:
                    for name in names[:sub.captures]:
                        c = m.phase1(name)
                        yield name, {"hours": c.hours, "sample": c.sample, "fs_hz": c.fs_hz}, \
                            {"speed": c.speed, "torque": c.torque, "acc1": c.acc1, "acc2": c.acc2}

        def runs(s: str, names: list[str]):
            for r in names[:sub.runs]:
                run = m.phase2(s, r)
                data = {"imu_acc": run.imu_acc, "imu_gyro": run.imu_gyro}
                rates = {"imu_acc": {"fs_hz": run.imu_acc_fs_hz}, "imu_gyro": {"fs_hz": run.imu_gyro_fs_hz}}
                if run.position_cmd is not None:
                    data["position_cmd"] = run.position_cmd
                    rates["position_cmd"] = {"fs_hz": run.position_cmd_fs_hz}
                attrs = dict(run.routine)
                if run.speeds_mm_s is not None:
                    attrs["speeds_mm_s"] = list(run.speeds_mm_s)
                yield r, attrs, data, rates

        def phase2():
            for s, hours, names in inv.sessions:
                if s in sessions:
                    yield s, {"hours": hours}, runs(s, names)

        try:
            return assemble_measurements(dst, m.axis(), phase1(), phase2(), m.dial_indicator())
        except DatasetError as exc:
            raise DatasetError(f"writing the subset of {src} to {dst}: {exc}") from None

