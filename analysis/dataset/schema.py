"""The dataset format: file kinds, version, channels and their units, the truth-leak words.

The layout is described for users in ``docs/dataset-format.md``.
"""

from __future__ import annotations

MEASUREMENTS_FORMAT = "ballscrew-twin/measurements"
TRUTH_FORMAT = "ballscrew-twin/truth"
FORMAT_VERSION = 2
SUPPORTED_VERSIONS = (1, 2)
"""Version 2 (this writer): ``position_cmd`` became optional (a stand-alone IMU records none).
Version 1 files are read as before: every channel present."""

#: Phase I channels: name -> (unit, description, columns); columns 1 means shape (n,).
PHASE1_CHANNELS: dict[str, tuple[str, str, int]] = {
    "speed": ("rad/s", "motor speed", 1),
    "torque": ("N*m", "motor torque", 1),
    "acc1": ("m/s^2", "nut accelerometer 1 (x, y, z)", 3),
    "acc2": ("m/s^2", "nut accelerometer 2 (x, y, z)", 3),
}
#: Phase II run channels: name -> (unit, description, columns). Each has its own ``fs_hz``.
PHASE2_CHANNELS: dict[str, tuple[str, str, int]] = {
    "imu_acc": ("m/s^2", "IMU accelerometer (x, y, z)", 3),
    "imu_gyro": ("rad/s", "IMU rate gyroscope (x, y, z)", 3),
    "position_cmd": ("m", "commanded carriage position", 1),
}
#: Phase II channels a run may lack from format_version 2 on: a recording of a stand-alone IMU
#: (the paper's setup) has no controller position; the analysis then uses the IMU-based
#: position (``twin backlash --position-reference imu``).
OPTIONAL_PHASE2_CHANNELS = ("position_cmd",)
DIAL_UNITS = {"hours": "h", "backlash_um": "um"}
#: Largest magnitude a channel can physically hold (its unit as above): well beyond what the
#: paper's sensors and drive can output (section III: accelerometers of ±50 g and less, a MEMS
#: gyroscope of some ±35 rad/s (2000 °/s), a servo motor of a few thousand rpm). A sample beyond
#: it is garbage (a wrong scale factor, a flipped exponent), never analysed.
PHYSICAL_RANGE = {
    "speed": 1.0e3,           # rad/s (about 9500 rpm)
    "torque": 1.0e3,          # N*m
    "acc1": 5.0e3,            # m/s^2 (about 500 g)
    "acc2": 5.0e3,
    "imu_acc": 5.0e3,
    "imu_gyro": 1.0e2,        # rad/s (about 5700 °/s)
    "position_cmd": 1.0e2,    # m
}
#: Most values one dataset may hold: the reader converts to float64 in memory, so a file that
#: declares a larger array (an absurd dimension) is refused before any allocation (256 MiB).
MAX_VALUES = 2**25
#: Optional Phase II run attributes describing the routine (Table I of the paper), needed to
#: analyse a run from the IMU alone: name -> what it holds. ``speeds_mm_s`` is a list.
ROUTINE_ATTRS = {
    "accel_mm_s2": "the acceleration and deceleration of every move, mm/s²",
    "start_mm": "the commanded position where each forward move starts, mm",
    "end_mm": "the commanded position where each forward move ends, mm",
    "dwell_s": "the standstill after each move, s",
}
#: Order of the six error motions in ``truth.h5`` ``/phase2/<session>/E``.
DOFS = ("E_XX", "E_YX", "E_ZX", "E_AX", "E_BX", "E_CX")
DOF_UNITS = ("m", "m", "m", "rad", "rad", "rad")
TIMELINE_REQUIRED = ("hours", "preload_N", "backlash_um")
SESSION_TRUTH_REQUIRED = ("hours", "backlash_um", "origin_offset_m")
#: ``truth.h5`` ``/phase2/<session>/strokes/<name>`` (format_version 2, optional): per move of a run
#: in time order, name -> unit. The signed commanded speed, and the signed rest-to-rest travels of
#: the carriage (D of the paper's Eq. 9), of the screw (its angle times lead/2π) and of the command.
STROKE_TRUTH = {"speed_m_s": "m/s", "carriage_m": "m", "screw_m": "m", "command_m": "m"}

#: Words that only the simulator may know. No group, dataset or attribute name of
#: ``measurements.h5``, nor any string attribute value (the ``axis`` JSON included), may mention
#: one of them (whole word, case-insensitive, camelCase split, plural/-ed/-ing forms included),
#: except the paths in :data:`ALLOWED_TRUTH_MENTIONS`.
TRUTH_KEYS = (
    "preload",
    "backlash",
    "stiffness",
    "onset",
    "wear",
    "origin_offset",
    "effect",
    "truth",
    "scenario",
    "degradation",
    "fault",
    "inject",
    "seed",
    "drag_torque",
    "temperature_rise",
    "error_motion",
)
#: A dial-indicator reading is what a real lab records, so its backlash dataset is allowed.
ALLOWED_TRUTH_MENTIONS = ("/dial_indicator/backlash_um",)


class DatasetError(ValueError):
    """A dataset file is unreadable or does not follow the format.

    The message names the file, the HDF5 key (``/group/dataset`` or ``/group@attribute``), the
    offending value and what was expected.
    """
