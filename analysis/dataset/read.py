"""Reading ``measurements.h5`` and ``truth.h5``: read-only wrappers that validate on access."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from analysis.dataset import schema
from analysis.dataset.attrs import _loads, from_attr
from analysis.dataset.h5file import _check_format, open_h5
from analysis.dataset.schema import DatasetError
from analysis.dataset.validate import (
    _as_number,
    _attr_fs,
    _attr_hours,
    _attr_int,
    _attr_number,
    _check_finite,
    _check_range,
    _check_shape,
    _check_size,
    _check_unit,
    _dims,
    _fmt,
    _routine,
    _shape_pattern,
    check_dtype,
)


@dataclass(frozen=True, eq=False)
class Phase1Capture:
    """One Phase I capture; arrays float64, sampled at ``fs_hz``, starting at t = 0.

    speed (n,) rad/s motor speed; torque (n,) N*m motor torque; acc1, acc2 (n, 3) m/s^2 nut
    accelerometers (x, y, z); hours: operating hours; sample: Phase I sample index.
    """

    name: str
    hours: float
    sample: int
    fs_hz: float
    speed: np.ndarray
    torque: np.ndarray
    acc1: np.ndarray
    acc2: np.ndarray


@dataclass(frozen=True, eq=False)
class Phase2Run:
    """One Phase II run; arrays float64, each at its own rate, all starting at t = 0.

    imu_acc (n, 3) m/s^2 at imu_acc_fs_hz; imu_gyro (m, 3) rad/s at imu_gyro_fs_hz;
    position_cmd (k,) m at position_cmd_fs_hz, or None for both when the run has no controller
    position (format_version 2, a stand-alone IMU); hours: operating hours of the session;
    speeds_mm_s: commanded traverse speeds in mm/s if recorded, else None; routine: the run's
    :data:`~analysis.dataset.schema.ROUTINE_ATTRS` that are recorded (``accel_mm_s2``,
    ``start_mm``, ``end_mm``, ``dwell_s``; floats).
    """

    session: str
    run: str
    hours: float
    imu_acc: np.ndarray
    imu_acc_fs_hz: float
    imu_gyro: np.ndarray
    imu_gyro_fs_hz: float
    position_cmd: np.ndarray | None
    position_cmd_fs_hz: float | None
    speeds_mm_s: tuple[float, ...] | None = None
    routine: dict[str, float] = field(default_factory=dict)


class _Reader:
    """Common part of the read-only file wrappers (context managers)."""

    _format = ""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.label = str(path)
        self._f = open_h5(path, self.label)
        try:
            self.format_version = _check_format(self.label, self._f, self._format)
        except BaseException:
            self._f.close()
            raise

    def close(self) -> None:
        self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _link(self, key: str):
        """Refuse soft and external links on the way to ``key``: the data must be in the file
        itself (an external link would read another file, a soft link alias another item)."""
        parts = [p for p in key.split("/") if p]
        for i in range(1, len(parts) + 1):
            sub = "/" + "/".join(parts[:i])
            try:
                link = self._f.get(sub, getlink=True)
            except (OSError, KeyError, RuntimeError, ValueError) as e:
                raise DatasetError(f"{self.label}: {sub} could not be read; the file may be corrupt ({e})") from None
            if link is None:
                return
            if not isinstance(link, h5py.HardLink):
                kind = "an external link" if isinstance(link, h5py.ExternalLink) else "a soft link"
                raise DatasetError(f"{self.label}: {sub} is {kind}; expected the group or dataset itself "
                                   "(links are not followed)")

    def _obj(self, key: str, kind: type, what: str):
        self._link(key)
        try:
            obj = self._f.get(key)
        except (OSError, KeyError, RuntimeError) as e:
            raise DatasetError(f"{self.label}: {key} could not be read; the file may be corrupt ({e})") from None
        if obj is None:
            raise DatasetError(f"{self.label}: {key} is missing; expected {what}")
        if not isinstance(obj, kind):
            found = "a group" if isinstance(obj, h5py.Group) else "a dataset"
            raise DatasetError(f"{self.label}: {key} is {found}; expected {what}")
        return obj

    def _attrs(self, obj: h5py.HLObject, key: str) -> dict[str, Any]:
        try:
            return dict(obj.attrs.items())
        except (OSError, KeyError, RuntimeError) as e:
            raise DatasetError(
                f"{self.label}: attributes of {key} could not be read; the file may be corrupt ({e})") from None

    def _names(self, key: str) -> list[str]:
        if key not in self._f:
            return []
        g = self._obj(key, h5py.Group, "a group")
        try:
            names = sorted(k for k in g if isinstance(g.get(k, getlink=True), h5py.HardLink)
                           and isinstance(g.get(k), h5py.Group))
        except (OSError, KeyError, RuntimeError, ValueError) as e:
            raise DatasetError(f"{self.label}: {key} could not be listed; the file may be corrupt ({e})") from None
        return names

    def _array(
        self,
        key: str,
        what: str,
        dims: tuple[int | str, ...],
        unit: str | None,
        n_expected: int | None = None,
        n_ref: str = "",
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Read and validate a dataset; return (float64 array, its attributes)."""
        ds = self._obj(key, h5py.Dataset, what)
        check_dtype(self.label, key, ds.dtype)
        _check_shape(self.label, key, ds.shape, dims, n_expected, n_ref)
        _check_size(self.label, key, ds.shape)
        attrs = self._attrs(ds, key)
        if unit is not None:
            _check_unit(self.label, key, attrs, unit)
        try:
            arr = np.asarray(ds[()], dtype=np.float64)
        except (OSError, RuntimeError, ValueError) as e:
            try:
                checked = ds.fletcher32
            except (OSError, RuntimeError, ValueError):
                checked = False
            if checked and "filter" in str(e).lower():
                raise DatasetError(
                    f"{self.label}: {key} fails its Fletcher-32 checksum: its bytes changed after it was "
                    "written (a corrupt copy or disk); restore the file from a good copy") from None
            raise DatasetError(
                f"{self.label}: {key} could not be read; the file may be truncated or corrupt ({e})") from None
        _check_finite(self.label, key, arr)
        name = key.rsplit("/", 1)[-1]
        if self._format == schema.MEASUREMENTS_FORMAT and name in schema.PHYSICAL_RANGE and unit is not None:
            _check_range(self.label, key, arr, schema.PHYSICAL_RANGE[name], unit)
        return arr, attrs

    def _json_attr(self, key: str, obj: h5py.HLObject, name: str) -> dict:
        attrs = self._attrs(obj, key)
        path = f"{key}@{name}"  # "/@axis", "/effects@json"
        if name not in attrs:
            raise DatasetError(f"{self.label}: {path} is missing; expected a JSON object string")
        return _loads(self.label, path, attrs[name])


def _sorted_by_hours(reader: _Reader, parent: str, names: list[str]) -> list[str]:
    keyed = []
    for n in names:
        key = f"{parent}/{n}"
        keyed.append((_attr_hours(reader.label, reader._attrs(reader._f[key], key), key), n))
    return [n for _, n in sorted(keyed)]


class Measurements(_Reader):
    """Read-only view of a ``measurements.h5``; validates every item when it is accessed.

    Use :func:`open_measurements`; it is a context manager (``with open_measurements(p) as m:``).
    """

    _format = schema.MEASUREMENTS_FORMAT

    def axis(self) -> dict:
        """The nominal testbed description (``/@axis``, JSON)."""
        return self._json_attr("/", self._f, "axis")

    def phase1_captures(self) -> list[str]:
        """Names of the Phase I captures, sorted by (hours, name)."""
        return _sorted_by_hours(self, "/phase1", self._names("/phase1"))

    def phase1_header(self, name: str) -> tuple[float, int, float]:
        """(hours, sample index, fs_hz) of a Phase I capture, from its attributes only (no
        array is read), validated."""
        gkey = f"/phase1/{name}"
        g = self._obj(gkey, h5py.Group, "a Phase I capture group")
        attrs = self._attrs(g, gkey)
        return (_attr_hours(self.label, attrs, gkey),
                _attr_int(self.label, attrs, gkey, "sample", "an integer Phase I sample index"),
                _attr_fs(self.label, attrs, gkey))

    def phase1(self, name: str) -> Phase1Capture:
        """One Phase I capture, validated (see :class:`Phase1Capture`)."""
        gkey = f"/phase1/{name}"
        hours, sample, fs = self.phase1_header(name)
        arrays, n = {}, None
        for ch, (unit, desc, cols) in schema.PHASE1_CHANNELS.items():
            what = f"a dataset of {desc} in {unit}, shape {_shape_pattern(_dims(cols, 'n'))}"
            arrays[ch], _ = self._array(f"{gkey}/{ch}", what, _dims(cols, "n"), unit, n, "len(speed)")
            n = len(arrays[ch])
        return Phase1Capture(name, hours, sample, fs, **arrays)

    def phase2_sessions(self) -> list[str]:
        """Names of the Phase II sessions, sorted by (hours, name)."""
        return _sorted_by_hours(self, "/phase2", self._names("/phase2"))

    def session_hours(self, session: str) -> float:
        """Operating hours of a Phase II session."""
        key = f"/phase2/{session}"
        g = self._obj(key, h5py.Group, "a Phase II session group")
        return _attr_hours(self.label, self._attrs(g, key), key)

    def phase2_runs(self, session: str) -> list[str]:
        """Names of the runs of a Phase II session, sorted."""
        key = f"/phase2/{session}"
        self._obj(key, h5py.Group, "a Phase II session group")
        return self._names(key)

    def phase2_channels(self, session: str, run: str) -> list[str]:
        """Names of the channels a Phase II run records (``position_cmd`` is optional from
        format_version 2 on)."""
        rkey = f"/phase2/{session}/{run}"
        g = self._obj(rkey, h5py.Group, "a Phase II run group")
        return [ch for ch in schema.PHASE2_CHANNELS if isinstance(g.get(ch), h5py.Dataset)]

    def phase2(self, session: str, run: str) -> Phase2Run:
        """One Phase II run, validated (see :class:`Phase2Run`)."""
        hours = self.session_hours(session)
        rkey = f"/phase2/{session}/{run}"
        g = self._obj(rkey, h5py.Group, "a Phase II run group")
        out: dict[str, Any] = {}
        for ch, (unit, desc, cols) in schema.PHASE2_CHANNELS.items():
            if ch in schema.OPTIONAL_PHASE2_CHANNELS and self.format_version >= 2 and f"{rkey}/{ch}" not in self._f:
                out[ch], out[f"{ch}_fs_hz"] = None, None
                continue
            sym = {"imu_acc": "n", "imu_gyro": "m", "position_cmd": "k"}[ch]
            what = f"a dataset of {desc} in {unit}, shape {_shape_pattern(_dims(cols, sym))}"
            arr, attrs = self._array(f"{rkey}/{ch}", what, _dims(cols, sym), unit)
            out[ch] = arr
            out[f"{ch}_fs_hz"] = _attr_fs(self.label, attrs, f"{rkey}/{ch}")
        rattrs = self._attrs(g, rkey)
        speeds = None
        if "speeds_mm_s" in rattrs:
            sp = np.asarray(rattrs["speeds_mm_s"])
            if sp.dtype.kind not in "fiu" or not np.all(np.isfinite(sp)):
                raise DatasetError(f"{self.label}: {rkey}@speeds_mm_s is {_fmt(rattrs['speeds_mm_s'])}; "
                                   "expected finite speeds in mm/s")
            speeds = tuple(float(v) for v in sp.reshape(-1))
        return Phase2Run(session, run, hours, speeds_mm_s=speeds, routine=_routine(self.label, rkey, rattrs),
                         **out)

    def dial_indicator(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Dial-indicator readings ``(hours (n,) h, backlash_um (n,) um)``, or None if absent."""
        if "dial_indicator" not in self._f:
            return None
        self._obj("/dial_indicator", h5py.Group, "a group of dial-indicator readings")
        hours, _ = self._array("/dial_indicator/hours", "a dataset of operating hours, shape (n,)", ("n",), "h")
        backlash, _ = self._array(
            "/dial_indicator/backlash_um", "a dataset of backlash readings in um, shape (n,)", ("n",), "um",
            len(hours), "len(hours)",
        )
        bad = (hours < 0) | np.r_[False, np.diff(hours) < 0]
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise DatasetError(f"{self.label}: /dial_indicator/hours[{i}] is {hours[i]:g}; expected operating "
                               "hours >= 0 that do not decrease")
        return hours, backlash

    def validate(self) -> None:
        """Read and validate everything (e.g. after converting real recordings)."""
        from analysis.dataset.axis import axis_of

        axis_of(self)
        for c in self.phase1_captures():
            self.phase1(c)
        for s in self.phase2_sessions():
            for r in self.phase2_runs(s):
                self.phase2(s, r)
        self.dial_indicator()


class Truth(_Reader):
    """Read-only view of a ``truth.h5``; use :func:`open_truth` (a context manager)."""

    _format = schema.TRUTH_FORMAT

    @property
    def onset_hours(self) -> float | None:
        """Operating hours of the injected fault onset, or None when no fault was injected."""
        attrs = self._attrs(self._f, "/")
        if "onset_hours" not in attrs:
            raise DatasetError(f"{self.label}: /@onset_hours is missing; expected a number of hours (NaN if none)")
        x = _as_number(attrs["onset_hours"])
        if x is None:
            raise DatasetError(f"{self.label}: /@onset_hours is {_fmt(attrs['onset_hours'])}; "
                               "expected a number of hours (NaN if none)")
        return None if np.isnan(x) else x

    def scenario(self) -> dict:
        """The scenario that generated the campaign (``/@scenario``, JSON)."""
        return self._json_attr("/", self._f, "scenario")

    def effects(self) -> dict:
        """Effect parameters (``/effects@json``); empty dict if none."""
        if "effects" not in self._f:
            return {}
        g = self._obj("/effects", h5py.Group, "a group")
        return self._json_attr("/effects", g, "json") if "json" in g.attrs else {}

    def timeline(self) -> dict[str, np.ndarray]:
        """All ``/timeline`` arrays, float64 (t,): ``hours``, ``preload_N``, ``backlash_um``, ..."""
        g = self._obj("/timeline", h5py.Group, "a group of (t,) arrays")
        out: dict[str, np.ndarray] = {}
        n = None
        for key in [*schema.TIMELINE_REQUIRED, *sorted(k for k in g if k not in schema.TIMELINE_REQUIRED)]:
            out[key], _ = self._array(f"/timeline/{key}", "a (t,) array", ("t",), None, n, "len(hours)")
            n = len(out[key])
        return out

    def sessions(self) -> list[str]:
        """Names of the Phase II sessions with true error motions, sorted by (hours, name)."""
        return _sorted_by_hours(self, "/phase2", self._names("/phase2"))

    def strokes(self, name: str) -> dict[str, np.ndarray] | None:
        """The true rest-to-rest travels of a session's runs per move (see
        :data:`~analysis.dataset.schema.STROKE_TRUTH`), or None if the file has none."""
        key = f"/phase2/{name}/strokes"
        if key not in self._f:
            return None
        self._obj(key, h5py.Group, "a group of per-move arrays")
        out, n = {}, None
        for k, unit in schema.STROKE_TRUTH.items():
            out[k], _ = self._array(f"{key}/{k}", "a (moves,) array", ("moves",), unit, n, "len(speed_m_s)")
            n = len(out[k])
        return out

    def session(self, name: str) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
        """``(x_m (n,) m, E (6, n) m and rad in DOFS order, attrs)`` of a Phase II session."""
        key = f"/phase2/{name}"
        g = self._obj(key, h5py.Group, "a Phase II session group")
        attrs = {k: from_attr(v) for k, v in self._attrs(g, key).items()}
        for a in schema.SESSION_TRUTH_REQUIRED:
            attrs[a] = _attr_number(self.label, attrs, key, a, "a finite number")
        x, _ = self._array(f"{key}/x_m", "a (n,) array of positions in m", ("n",), "m")
        E, _ = self._array(f"{key}/E", "a (6, n) array of error motions", (6, "n"), None, len(x), "len(x_m)")
        return x, E, attrs


def open_measurements(path: str | os.PathLike) -> Measurements:
    """Open a ``measurements.h5`` read-only; checks ``/@format`` and ``/@format_version``."""
    return Measurements(path)


def open_truth(path: str | os.PathLike) -> Truth:
    """Open a ``truth.h5`` read-only; checks ``/@format`` and ``/@format_version``."""
    return Truth(path)
