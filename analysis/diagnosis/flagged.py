"""What ``twin check`` finds in a recording, taken into the gap diagnosis.

A sensor that saturated (``twin check``'s clipping finding: samples piled at a converter's rail,
:mod:`analysis.ingest.check`) or a channel that holds one value throughout (a flat line) cannot
be compared with the twin statistic by statistic: its band powers, RMS levels and the error
motions computed from it are cut where the machine's signal was largest, by as much as the
machine's peaks exceed the rail. The twin's own peaks are not the machine's (a calibration that
could not read the flagged channel keeps its defaults there), so the clipping candidate of the
library, simulated on the twin, clips another part of another signal, and other candidates take
the flagged channel's gap (calibrate-benchmark case 22 named a cogging and a time offset of the
IMU for its clipped accelerometer). The check's finding is direct evidence instead, and so the
diagnosis

1. names the clipping from the finding (:func:`found_by_check`: the artefact ``clipping:<channel>``,
   its range the rail's value, with the findings behind it), before anything is fitted;
2. leaves the flagged channel's statistics out of the comparison (:func:`leave_out`: NaN in the
   recording's signature, so not tested, not fitted, not in the held-out gap), as
   ``twin calibrate`` fits nothing to a flagged channel.

A dropout (a run of held samples) is not left out: it moves its capture's statistics by the
fraction it holds, which the twin's spread and the candidates still weigh, and a time offset
between channels, which holds the first samples of a run, is one of the library's candidates.
"""

from __future__ import annotations

import re

import numpy as np

from analysis.dataset import DOFS
from analysis.diagnosis.signature import Region, Signature
from analysis.ingest.check import findings_by_channel

#: The findings of ``twin check`` after which a channel is left out (the start of their text).
LEAVES_OUT = ("clipping", "flat line")
#: The error motions are fused from both of the IMU's sensors (analysis.phase2.error_motions).
_IMU_MOTIONS = frozenset(DOFS)


def kind_of(what: str) -> str:
    """The kind of a finding, the start of its text before the colon ("clipping", "dropout",
    "flat line", ...)."""
    return str(what).split(":", 1)[0].strip()


def reads(channel: str, region: Region) -> bool:
    """Whether the statistic of ``region`` is computed from the recording's ``channel`` (acc1,
    acc2, torque, speed, imu_acc, imu_gyro): its own bands and phases, the Phase I features of
    the signal (named after it), and for the IMU's two sensors every error motion."""
    if channel in ("acc1", "acc2", "torque", "speed"):
        if region.domain != "phase1":
            return False
        if region.channel == "features":
            return f"_{channel}" in region.bin  # amp1x_acc1_x, skew_tr_torque, ...
        return region.channel == channel or region.channel.startswith(f"{channel}_")
    if channel in ("imu_acc", "imu_gyro"):
        own = "acc_" if channel == "imu_acc" else "gyro_"
        return region.domain == "phase2" and (region.channel.startswith(own) or region.channel in _IMU_MOTIONS)
    return False


def flagged_channels(check: dict | None) -> dict[str, list[dict]]:
    """{channel: [finding, ...]} of the channels ``check`` (``twin check``'s record:
    :func:`analysis.ingest.check.check_record`, its ``errors`` and ``warnings``) finds clipped or
    flat (:data:`LEAVES_OUT`), in the order found."""
    by = {ch: [f for f in fs if kind_of(f["what"]) in LEAVES_OUT] for ch, fs in findings_by_channel(check).items()}
    return {ch: fs for ch, fs in by.items() if fs}


_NUMBER = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
_RAIL = re.compile(rf"samples at the (?:maximum|minimum) {_NUMBER}|\|value\| reaches {_NUMBER}")


def rail(findings: list[dict]) -> float | None:
    """The largest |value| at which ``findings`` (one channel's) say it clipped: the converter's
    range, in the channel's unit; None when none of them gives one (a flat line)."""
    vals = []
    for f in findings:
        m = _RAIL.search(str(f["what"]))
        if m and kind_of(f["what"]) == "clipping":
            vals.append(abs(float(m.group(1) or m.group(2))))
    return max(vals) if vals else None


def found_by_check(check: dict | None, regions: list[Region], artefacts: dict) -> list[dict]:
    """The diagnosis's ``found_by_check``: one entry per channel ``check`` finds clipped or flat,
    {"effect": "clipping:<channel>" (None for a flat line, or a channel without that artefact in
    ``artefacts``, {name: Artefact}), "kind": "signal artefact", "channel", "finding" (its kind),
    "params": {"range": the rail} (clipping), "unit" (the range's, "" when not named), "findings":
    the first 5 "where: what",
    "n_findings", "statistics_left_out": how many of ``regions`` it reads}."""
    out = []
    for ch, fs in flagged_channels(check).items():
        clipped = [f for f in fs if kind_of(f["what"]) == "clipping"]
        name = f"clipping:{ch}" if clipped else None
        value = rail(clipped) if clipped else None
        known = artefacts.get(name)
        entry = {"effect": name if known is not None else None, "kind": "signal artefact", "channel": ch,
                 "finding": "clipping" if clipped else kind_of(fs[0]["what"]),
                 "params": {"range": value} if value is not None else {},
                 "unit": next((p.unit for p in known.params if p.name == "range"), "") if known is not None else "",
                 "findings": [f"{f['where']}: {f['what']}" for f in fs[:5]], "n_findings": len(fs),
                 "statistics_left_out": int(sum(reads(ch, r) for r in regions))}
        out.append(entry)
    return out


def leave_out(sig: Signature, channels) -> Signature:
    """``sig`` with the statistics read on any of ``channels`` set to NaN (not compared)."""
    channels = list(channels)
    if not channels:
        return sig
    mask = np.array([any(reads(ch, r) for ch in channels) for r in sig.regions], bool)
    return Signature(np.where(mask, np.nan, sig.values), sig.regions)


def named(result: dict) -> list[dict]:
    """What a diagnosis names, in order: the artefacts found by ``twin check``, then the
    candidates the attribution added; each {"effect", "params"}."""
    found = [{"effect": f["effect"], "params": f["params"]} for f in result.get("found_by_check", [])
             if f.get("effect")]
    return found + [{"effect": a["effect"], "params": a["params"]} for a in result.get("added", [])]
