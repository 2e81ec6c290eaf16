"""The axis contract: the ``/@axis`` description of ``measurements.h5``, versioned and validated.

``/@axis`` is a JSON object describing the nominal machine (no degradation state): geometry,
masses, the sensors and the Phase I and II routines, every quantity with its unit in its name
(``lead_mm``, ``carriage_mass_kg``, ``sensitivity_mV_per_g``). :class:`AxisDescription` is its
schema (pydantic); ``docs/dataset-format.md#the-axis-contract`` lists every key and which
analysis reads it. Analyses never read the raw JSON: they call :func:`axis_of` and then
:meth:`AxisDescription.require` for each key they need, which raises :class:`MissingAxisKey`
(a :class:`~analysis.dataset.schema.DatasetError`) naming the key and the analysis instead of
falling back on the twin's values.

Keys not in the contract are kept (a laboratory may add its own), except the contract's keys
spelt with another unit (``lead_m`` for ``lead_mm``), which are refused with the right name.
"""

from __future__ import annotations

import re
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, model_validator

from analysis.dataset.schema import DatasetError
from analysis.locations import value_at

#: Version of the axis contract written in ``axis_version``; a description without it is version 1.
AXIS_VERSION = 1
SUPPORTED_AXIS_VERSIONS = (1,)

# unit suffixes a key may wrongly carry instead of the contract's one
_UNIT_SUFFIX = re.compile(r"_(m|mm|um|cm|in|kg|g|lb|s|ms|hz|khz|mm_s|m_s|m_s2|mm_s2|rpm|deg|rad)$", re.I)


class _Part(BaseModel):
    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def _unit_spelling(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        stems = {}
        for name in cls.model_fields:
            stems.setdefault(_UNIT_SUFFIX.sub("", name), name)
        for key in data:
            if key in cls.model_fields or not isinstance(key, str):
                continue
            stem = _UNIT_SUFFIX.sub("", key)
            if stem != key and stem in stems:
                raise ValueError(f"key {key!r} is not part of the axis contract: write {stems[stem]!r} "
                                 f"(the unit is in the name)")
        return data


Positive = Field(None, gt=0)


class Accelerometer(_Part):
    """A (triaxial) accelerometer: sensitivity, bandwidth, noise density, rate, place."""

    count: int | None = Field(None, ge=1)
    axes: int | None = Field(None, ge=1, le=3)
    sensitivity_mV_per_g: float | None = Positive
    range_g: float | None = Positive
    bandwidth_hz: float | None = Positive
    noise_ug_per_rthz: float | None = Field(None, ge=0)
    fs_hz: float | None = Positive
    position_mm: list[float] | None = Field(None, min_length=3, max_length=3)


class Gyroscope(_Part):
    """The IMU's rate gyroscope."""

    range_deg_s: float | None = Positive
    bandwidth_hz: float | None = Positive
    noise_urad_s_per_rthz: float | None = Field(None, ge=0)
    fs_hz: float | None = Positive


class Controller(_Part):
    """The drive's controller signals (speed, torque, commanded position)."""

    fs_hz: float | None = Positive
    encoder_counts_per_rev: int | None = Field(None, ge=1)


class Sensors(_Part):
    nut_accelerometers: Accelerometer | None = None
    imu_accelerometer: Accelerometer | None = None
    imu_gyroscope: Gyroscope | None = None
    controller: Controller | None = None


class Phase1Routine(_Part):
    """The Phase I move: one speed, forward and back between ``start_mm`` and ``end_mm``."""

    speed_mm_s: float | None = Positive
    accel_mm_s2: float | None = Positive
    start_mm: float | None = None
    end_mm: float | None = None
    dwell_s: float | None = Field(None, ge=0)


class Phase2Routine(_Part):
    """The Phase II routine (Table I of the paper): speeds, acceleration, stroke, dwell."""

    speeds_mm_s: list[float] | None = Field(None, min_length=1)
    accel_mm_s2: float | None = Positive
    start_mm: float | None = None
    end_mm: float | None = None
    dwell_s: float | None = Field(None, ge=0)


class AxisDescription(_Part):
    """The ``/@axis`` JSON object (axis contract version :data:`AXIS_VERSION`). All keys optional.

    Lengths in mm, masses in kg, speeds in mm/s, accelerations in mm/s², times in s, rates in Hz.
    """

    axis_version: Literal[1] = AXIS_VERSION
    name: str | None = None
    travel_mm: float | None = Positive
    lead_mm: float | None = Positive
    screw: str | None = None
    carriage_mass_kg: float | None = Positive
    load_kg: float | None = Field(None, ge=0)
    truck_spacing_mm: float | None = Positive
    rail_spacing_mm: float | None = Positive
    sensors: Sensors | None = None
    phase1_routine: Phase1Routine | None = None
    phase2_routine: Phase2Routine | None = None

    _label: str = PrivateAttr("measurements.h5")

    @property
    def label(self) -> str:
        """The file the description was read from (for messages)."""
        return self._label

    @classmethod
    def from_dict(cls, data: Any, label: str = "measurements.h5") -> AxisDescription:
        """Validate a parsed ``/@axis``; raises :class:`DatasetError` naming ``/@axis.<key>``."""
        if not isinstance(data, dict):
            raise DatasetError(f"{label}: /@axis is {type(data).__name__}; expected a JSON object")
        version = data.get("axis_version", AXIS_VERSION)
        if version not in SUPPORTED_AXIS_VERSIONS:
            raise DatasetError(f"{label}: /@axis.axis_version is {version!r}; this reader supports "
                               f"axis_version {', '.join(map(str, SUPPORTED_AXIS_VERSIONS))}")
        try:
            out = cls.model_validate(data)
        except ValidationError as e:
            err = e.errors()[0]
            loc = ".".join(str(p) for p in err["loc"])
            value = value_at(data, err["loc"])
            where = f"/@axis.{loc}" if loc else "/@axis"
            raise DatasetError(f"{label}: {where} is {value!r}; expected {_expected(err)}") from None
        out._label = label
        return out

    def to_dict(self) -> dict[str, Any]:
        """The JSON object to store (``None`` values left out, ``axis_version`` included)."""
        return self.model_dump(exclude_none=True)

    def require(self, key: str, needed_by: str) -> Any:
        """The value of ``key`` (dotted for nested keys, e.g. ``phase2_routine.accel_mm_s2``);
        :class:`MissingAxisKey` naming the key and ``needed_by`` when it is absent."""
        obj: Any = self
        for part in key.split("."):
            obj = getattr(obj, part, None) if obj is not None else None
        if obj is None:
            raise MissingAxisKey(f"{self.label}: /@axis.{key} is missing; {needed_by} needs it "
                                 f"(see docs/dataset-format.md#the-axis-contract); add it to the axis "
                                 f"description ({_toml_hint(key)} in the import spec)")
        return obj

    def get(self, key: str, default: Any = None) -> Any:
        """The value of dotted ``key`` or ``default`` (for keys with a documented fallback)."""
        try:
            return self.require(key, "")
        except MissingAxisKey:
            return default


class MissingAxisKey(DatasetError):
    """An analysis needs an ``/@axis`` key that the recording's description does not have."""


def _toml_hint(key: str) -> str:
    *table, name = key.split(".")
    return f"[{'.'.join(['axis', *table])}] {name} = ..."


def _expected(err: dict) -> str:
    msg = err.get("msg", "")
    ctx = err.get("ctx") or {}
    if "gt" in ctx:
        return f"a number > {ctx['gt']}"
    if "ge" in ctx:
        return f"a number >= {ctx['ge']}"
    msg = msg.removeprefix("Value error, ")
    return msg[0].lower() + msg[1:] if msg else "a valid value"


def axis_of(m) -> AxisDescription:
    """The validated axis description of an open :class:`~analysis.dataset.Measurements`."""
    return AxisDescription.from_dict(m.axis(), m.label)


def run_routine(m, run) -> tuple[dict[str, float], tuple[float, ...]]:
    """The routine of a Phase II run (``accel_mm_s2``, ``start_mm``, ``end_mm``, ``dwell_s``) and
    its speeds (mm/s): the run's own attributes where recorded, else the axis contract's
    ``phase2_routine``. ``run``: a :class:`~analysis.dataset.Phase2Run` of ``m``. Keys found in
    neither are left out (the analysis that needs them names them)."""
    axis_routine = axis_of(m).phase2_routine
    base = axis_routine.model_dump(exclude_none=True) if axis_routine is not None else {}
    speeds = tuple(run.speeds_mm_s or base.pop("speeds_mm_s", ()) or ())
    base.pop("speeds_mm_s", None)
    routine = {k: float(v) for k, v in base.items() if k in ("accel_mm_s2", "start_mm", "end_mm", "dwell_s")}
    routine.update(run.routine)
    return routine, speeds
