"""Names, units and the summary shared by the view's modules."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

APP_ID = "ballscrew_twin"
#: Carriage poses logged per second of the run.
POSE_RATE_HZ = 100.0
#: Samples per sensor channel above which only every k-th sample is logged.
MAX_POINTS = 50_000
#: Default factor on the error motions in the 3D view.
EXAGGERATION = 2000.0
ENTITY_CARRIAGE = "/world/carriage"
DOF_LABELS = {"E_XX": ("positioning", "um"), "E_YX": ("horizontal straightness", "um"),
              "E_ZX": ("vertical straightness", "um"), "E_AX": ("roll", "urad"),
              "E_BX": ("pitch", "urad"), "E_CX": ("yaw", "urad")}
PHASE1_CHANNELS = (("speed", "rad/s", None), ("torque", "N*m", None),
                   ("acc1", "m/s^2", "xyz"), ("acc2", "m/s^2", "xyz"))
PHASE2_CHANNELS = (("imu_acc", "m/s^2", "xyz"), ("imu_gyro", "rad/s", "xyz"), ("position_cmd", "m", None))
RED, ORANGE, GREEN, BLUE, GREY, PURPLE = ((220, 40, 40), (240, 150, 20), (40, 160, 60),
                                          (40, 90, 220), (120, 120, 120), (150, 60, 200))


class ViewError(ValueError):
    """Bad input to ``twin view``: the message names the file, key or option and what was expected."""


@dataclass
class ViewSummary:
    """What :func:`build` put into the recording.

    Attributes:
        directory: the campaign directory.
        path: the ``.rrd`` written (None when served).
        session, run, hours: the Phase II run shown in 3D (None without Phase II data).
        error_motion_source: ``"truth.h5"``, ``"backlash/error_motions.h5"`` or ``"none"``.
        source_detail: one sentence saying where the error motions come from.
        exaggeration: factor on the error motions in the 3D view.
        n_poses: carriage poses logged on ``sim_time``.
        captures: Phase I captures logged.
        methods: Phase I methods logged from ``detection.json``.
        backlash_sessions: sessions of ``backlash.json`` logged.
        has_truth: whether ``truth.h5`` was used.
        notes: what was left out and why (printed by the CLI).
        seconds: wall time of :func:`build`.
        size_bytes: size of the written file (0 when served).
    """

    directory: Path
    path: Path | None = None
    session: str | None = None
    run: str | None = None
    hours: float | None = None
    error_motion_source: str = "none"
    source_detail: str = ""
    exaggeration: float = EXAGGERATION
    n_poses: int = 0
    captures: list[str] = field(default_factory=list)
    methods: list[str] = field(default_factory=list)
    backlash_sessions: int = 0
    has_truth: bool = False
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0
    size_bytes: int = 0


def hours_to_ns(hours) -> np.ndarray:
    """Operating hours as the ``hours`` timeline stores them: int64 ns of a duration of hours·3600 s."""
    return np.round(np.asarray(hours, dtype=np.float64) * 3600e9).astype(np.int64)
