"""The gate's suite: its campaigns and checks, versioned (:data:`SUITES`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from typing import Any

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


