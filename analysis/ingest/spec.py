"""The import spec: a TOML file mapping a laboratory's files onto the dataset format.

Validated by pydantic; :func:`load_spec` raises :class:`ImportSpecError` naming the spec file,
the key (``phase1.channels.acc1.unit``), the value and what is allowed. The full description
with an example per reader is ``docs/import.md``.

Layout::

    spec_version = 1
    output = "imported"                 # campaign directory, relative to the spec
    [axis]                              # the axis contract (docs/dataset-format.md)
    [phase1]                            # Phase I captures, one file each (optional)
    files = "p1/*.tdms"                 # glob relative to the spec, sorted
    name_pattern = 'h(?P<hours>[0-9.]+)_(?P<sample>\\d+)'  # regex on the file name
    fs_hz = 25600.0                     # or time_channel, or the rate the file states
    [phase1.channels]
    speed = {channel = "Motor speed", unit = "rpm"}
    acc1 = {channels = ["A1 X", "A1 Y", "A1 Z"], unit = "mV", sensitivity_mV_per_g = 100.0}
    [phase2]                            # Phase II runs, one file each (optional)
    files = "p2/*.csv"
    name_pattern = 's(?P<session>\\d+)_h(?P<hours>[0-9.]+)_r(?P<run>\\d+)'
    [phase2.channels]
    imu_acc = {channels = ["ax", "ay", "az"], unit = "g"}
    [dial]                              # dial-indicator readings (optional)
    file = "dial.csv"                   # columns hours, backlash_um
    [watch]                             # twin import --watch only (optional)
    captures_per_sample = 10            # a sample is complete with this many captures
    runs_per_session = 90               # a session is complete with this many runs

The operating hours of a phase come from exactly one of: a ``hours`` group of ``name_pattern``,
``hours_channel``, ``hours_table`` (:class:`Table`: per file, or per session / sample joined on
a group of the name), ``hours_property`` (a number the file states) or ``hours_clock``
(:class:`Clock`: the files' time stamps with an offset).
"""

from __future__ import annotations

import datetime as dt
import re
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from analysis.ingest.units import QUANTITY, UNITS
from analysis.locations import value_at

SPEC_VERSION = 1
PHASE1 = ("speed", "torque", "acc1", "acc2")
PHASE2 = ("imu_acc", "imu_gyro", "position_cmd")  # position_cmd: optional in the spec
_COLUMNS = {"speed": 1, "torque": 1, "acc1": 3, "acc2": 3, "imu_acc": 3, "imu_gyro": 3, "position_cmd": 1}


class ImportSpecError(ValueError):
    """A bad import spec or a problem in a laboratory's file (names file, channel and line)."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ChannelMap(_Model):
    """One format channel from the file's channel(s): ``channel`` for (n,) channels, ``channels``
    (x, y, z) for (n, 3) ones; ``(value * scale + offset)`` is in ``unit``, converted to SI."""

    channel: str | None = None
    channels: list[str] | None = Field(None, min_length=3, max_length=3)
    unit: str
    scale: float = 1.0
    offset: float = 0.0
    sensitivity_mV_per_g: float | None = Field(None, gt=0)
    fs_hz: float | None = Field(None, gt=0)

    @model_validator(mode="after")
    def _one(self) -> ChannelMap:
        if (self.channel is None) == (self.channels is None):
            raise ValueError("give either channel = \"name\" (one column) or channels = [x, y, z]")
        return self

    def names(self) -> list[str]:
        return [self.channel] if self.channel is not None else list(self.channels)


class Table(_Model):
    """Operating hours from a table (CSV): one line per file, session or sample.

    ``key``: what a line names: ``"file"`` (the file name, default) or a named group of
    ``name_pattern`` (``"session"``, ``"sample"``, ...), joined on its value (numbers compare as
    numbers: ``03`` matches ``3``). ``key_column`` (default: the ``key``) and ``hours_column``
    (default ``hours``) name the table's columns; ``delimiter`` (default: sniffed among
    ``, ; tab |``), ``decimal`` and ``header_line`` as for the data files."""

    file: str
    key: str = "file"
    key_column: str | None = None
    hours_column: str = "hours"
    delimiter: str | None = None
    decimal: str = "."
    header_line: int = Field(1, ge=1)

    def key_col(self) -> str:
        return self.key_column if self.key_column is not None else self.key


class Clock(_Model):
    """Operating hours from the files' own time stamps:
    ``hours = hours_at_origin + duty * (stamp - origin) / 1 h``.

    ``source``: ``"start_time"`` (the time the file states: TDMS ``wf_start_time``, the MDF
    header's start time) or ``"mtime"`` (the file's modification time, which a copy may reset);
    ``origin``: an ISO date-time (UTC unless it names its zone) at which the hour meter read
    ``hours_at_origin``; ``duty``: the fraction of the wall-clock time the axis runs (1: always)."""

    source: Literal["start_time", "mtime"] = "start_time"
    origin: dt.datetime
    hours_at_origin: float = Field(0.0, ge=0)
    duty: float = Field(1.0, gt=0, le=1)


class PhaseSpec(_Model):
    """Which files hold one phase, how to name and time them, and their channels."""

    files: str
    reader: Literal["csv", "mat", "tdms", "mdf"] | None = None
    group: str | None = None
    delimiter: str = ","
    header_line: int = Field(1, ge=1)
    decimal: str = "."
    name_pattern: str | None = None
    hours_channel: str | None = None
    hours_table: Table | None = None
    hours_property: str | None = None
    hours_clock: Clock | None = None
    max_session_span_hours: float = Field(24.0, ge=0)
    fs_hz: float | None = Field(None, gt=0)
    time_channel: str | None = None
    time_unit: Literal["s", "ms", "us"] = "s"
    channels: dict[str, ChannelMap]

    @field_validator("name_pattern")
    @classmethod
    def _regex(cls, v: str | None) -> str | None:
        if v is not None:
            try:
                re.compile(v)
            except re.error as e:
                raise ValueError(f"not a regular expression ({e})") from None
        return v

    def groups(self) -> set[str]:
        return set(re.compile(self.name_pattern).groupindex) if self.name_pattern else set()


class DialSpec(_Model):
    file: str
    delimiter: str = ","
    hours_column: str = "hours"
    backlash_um_column: str = "backlash_um"


class WatchSpec(_Model):
    """How a watched export folder (``twin import SPEC --watch``) groups its files as they come:
    a Phase I sample is complete with ``captures_per_sample`` captures and a Phase II session
    with ``runs_per_session`` runs. Without them a sample (session) is complete when a file of
    later operating hours arrives, or when the watch ends (``--once``, ``--until-idle``)."""

    captures_per_sample: int | None = Field(None, ge=1)
    runs_per_session: int | None = Field(None, ge=1)


class ImportSpec(_Model):
    """The whole spec (see the module's doc)."""

    spec_version: Literal[1] = SPEC_VERSION
    output: str
    axis: dict[str, Any] = Field(default_factory=dict)
    phase1: PhaseSpec | None = None
    phase2: PhaseSpec | None = None
    dial: DialSpec | None = None
    watch: WatchSpec | None = None

    @model_validator(mode="after")
    def _check(self) -> ImportSpec:
        if self.phase1 is None and self.phase2 is None:
            raise ValueError("the spec has neither [phase1] nor [phase2]; expected at least one")
        for phase, required in (("phase1", PHASE1), ("phase2", PHASE2)):
            p = getattr(self, phase)
            if p is None:
                continue
            unknown = sorted(set(p.channels) - set(required))
            if unknown:
                raise ValueError(f"{phase}.channels.{unknown[0]} is not a channel of {phase}; "
                                 f"expected {', '.join(required)}")
            missing = [c for c in required if c not in p.channels and c != "position_cmd"]
            if missing:
                raise ValueError(f"{phase}.channels.{missing[0]} is missing; expected the channels "
                                 f"{', '.join(required)}")
            for c, m in p.channels.items():
                cols = 1 if m.channel is not None else 3
                if cols != _COLUMNS[c]:
                    what = "channel = \"name\"" if _COLUMNS[c] == 1 else "channels = [x, y, z]"
                    raise ValueError(f"{phase}.channels.{c} has {cols} column(s); expected {what}")
                units = UNITS[QUANTITY[c]]
                if m.unit not in units:
                    raise ValueError(f"{phase}.channels.{c}.unit is {m.unit!r}; expected one of "
                                     f"{', '.join(units)} ({QUANTITY[c]})")
            g = p.groups()
            timing = ["hours" in g, p.hours_channel is not None, p.hours_table is not None,
                      p.hours_property is not None, p.hours_clock is not None]
            if sum(timing) != 1:
                raise ValueError(f"{phase}: the operating hours come from {sum(timing)} places; expected "
                                 "exactly one of a (?P<hours>...) group in name_pattern, hours_channel, "
                                 "hours_table, hours_property, hours_clock")
            if p.hours_table is not None and p.hours_table.key != "file" and p.hours_table.key not in g:
                raise ValueError(f"{phase}.hours_table.key is {p.hours_table.key!r}; expected 'file' or a "
                                 f"named group of {phase}.name_pattern ({', '.join(sorted(g)) or 'none'})")
            if phase == "phase2" and "session" not in g and p.hours_table is None and "hours" not in g \
                    and p.hours_property is None:
                raise ValueError("phase2: expected a (?P<session>...) or (?P<hours>...) group in "
                                 "name_pattern to group the runs into sessions")
        return self


def load_spec(path: str | Path) -> tuple[ImportSpec, Path]:
    """The validated spec and the directory its relative paths start from."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ImportSpecError(f"{path}: no such import spec") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ImportSpecError(f"{path}: cannot read the import spec ({e})") from None
    except tomllib.TOMLDecodeError as e:
        raise ImportSpecError(f"{path}: not valid TOML ({e})") from None
    try:
        spec = ImportSpec.model_validate(raw)
    except ValidationError as e:
        err = e.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        value = value_at(raw, err["loc"], missing="(missing)")
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "not a key of the import spec (docs/import.md)"
        if err["type"] == "missing":
            raise ImportSpecError(f"{path}: {loc} is missing (docs/import.md)") from None
        if loc:
            raise ImportSpecError(f"{path}: {loc} = {value!r}: {msg}") from None
        raise ImportSpecError(f"{path}: {msg}") from None
    return spec, path.parent
