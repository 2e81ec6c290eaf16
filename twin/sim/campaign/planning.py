"""The plan of a campaign: its units of work (:class:`Unit`: a Phase I capture, a Phase II session
or a dial-indicator reading) at their operating hours (h), in time order within each kind.
"""

from __future__ import annotations

from dataclasses import dataclass

from twin.sim.scenario import Scenario


@dataclass(frozen=True)
class Unit:
    """One unit of work. kind: "phase1" | "phase2" | "dial"; name: part name; index: capture or
    session index; sample: Phase I sample index (−1 otherwise); hours: operating hours."""

    kind: str
    name: str
    index: int
    hours: float
    sample: int = -1


def session_hours(s: Scenario) -> list[float]:
    p2 = s.phase2
    if p2.session_hours:
        return sorted(float(h) for h in p2.session_hours)
    out, h = [], p2.session_interval_hours / 2.0
    while h <= s.campaign.total_hours:
        out.append(h)
        h += p2.session_interval_hours
    return out


def sample_hours(s: Scenario) -> list[float]:
    """Operating hours of each Phase I sample's first capture: ``phase1.sample_hours`` when
    given (sorted), else every ``sample_interval_hours`` from ``warmup_hours`` while the
    sample's last capture is within ``total_hours``."""
    p1 = s.phase1
    if p1.sample_hours:
        return sorted(float(h) for h in p1.sample_hours)
    out, h = [], s.campaign.warmup_hours
    step = p1.capture_interval_minutes / 60.0
    while h + (s.captures_per_sample - 1) * step <= s.campaign.total_hours:
        out.append(h)
        h += p1.sample_interval_hours
    return out


def plan(s: Scenario) -> list[Unit]:
    """Every unit of the campaign, in time order within each kind."""
    units: list[Unit] = []
    if s.campaign.phase1:
        step = s.phase1.capture_interval_minutes / 60.0
        idx = 0
        for sample, h in enumerate(sample_hours(s)):
            for j in range(s.captures_per_sample):
                units.append(Unit("phase1", f"c{idx:06d}", idx, h + j * step, sample))
                idx += 1
    if s.campaign.phase2:
        for i, h in enumerate(session_hours(s)):
            units.append(Unit("phase2", f"s{i:04d}", i, h))
            n = s.dial_indicator.every_n_sessions
            if n and i % n == 0:
                units.append(Unit("dial", f"d{i:04d}", i, h))
    return units
