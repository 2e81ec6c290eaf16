"""Writing ``measurements.h5`` and ``truth.h5``: validated, to a temporary file moved into place."""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from analysis.base.files import atomic_write
from analysis.dataset import schema
from analysis.dataset.attrs import _dumps, write_attrs
from analysis.dataset.axis import AxisDescription
from analysis.dataset.leak_guard import _scan_truth_mentions
from analysis.dataset.schema import DatasetError
from analysis.dataset.validate import (
    _attr_fs,
    _attr_hours,
    _attr_int,
    _attr_number,
    _check_finite,
    _check_name,
    _check_range,
    _check_shape,
    _check_unit,
    _dims,
    _routine,
    check_dtype,
)

# Unit of a truth timeline array, inferred from the unit its name ends with (longest first).
_UNIT_SUFFIXES = (
    ("_N_per_m", "N/m"),
    ("_Nm_per_rad", "N*m/rad"),
    ("_Nm", "N*m"),
    ("_um", "um"),
    ("_mm", "mm"),
    ("_rad", "rad"),
    ("_N", "N"),
    ("_K", "K"),
    ("_m", "m"),
    ("_s", "s"),
)


def _check_new(label: str, key: str, parent: h5py.Group, name: str, what: str) -> None:
    """``name`` is a valid, not yet used name of a ``what`` (capture, session, run) in ``parent``."""
    _check_name(label, key, name, what)
    if name in parent:
        raise DatasetError(f"{label}: {key} is given twice; expected unique {what} names")


#: Largest chunk of a written dataset, bytes (HDF5's default chunk cache is 1 MiB).
CHUNK_BYTES = 512 * 1024


def chunk_shape(shape: tuple[int, ...], itemsize: int) -> tuple[int, ...] | None:
    """Chunks of whole rows (all columns of a sample together, as the readers take them), at
    most :data:`CHUNK_BYTES` each and of equal length, so that the last chunk is not mostly
    padding; None for an empty or scalar dataset (HDF5 picks)."""
    if not shape or shape[0] == 0:
        return None
    row = itemsize * int(np.prod(shape[1:], dtype=np.int64))
    most = max(CHUNK_BYTES // max(row, 1), 1)
    n_chunks = -(-shape[0] // most)
    return (-(-shape[0] // n_chunks), *shape[1:])


def _put(label: str, key: str, g: h5py.Group, name: str, arr: np.ndarray, attrs: Mapping[str, Any]) -> None:
    _check_finite(label, key, arr)
    if name in schema.PHYSICAL_RANGE and g.file.attrs.get("format") == schema.MEASUREMENTS_FORMAT:
        _check_range(label, key, arr, schema.PHYSICAL_RANGE[name], str(attrs.get("unit", "")))
    # Fletcher-32: every chunk carries a checksum that the reader verifies, so bytes changed after
    # writing (a corrupt copy, a bad disk) raise an error instead of being analysed.
    arr = np.asarray(arr)
    ds = g.create_dataset(name, data=arr, fletcher32=True, chunks=chunk_shape(arr.shape, arr.dtype.itemsize))
    write_attrs(ds, attrs)


def _channels(
    label: str,
    gkey: str,
    datasets: Mapping[str, Any],
    spec: Mapping[str, tuple[str, str, int]],
    optional: tuple[str, ...] = (),
) -> dict[str, np.ndarray]:
    unknown = sorted(set(datasets) - set(spec))
    if unknown:
        raise DatasetError(
            f"{label}: {gkey}/{unknown[0]} is not a channel of format_version {schema.FORMAT_VERSION}; "
            f"expected only {', '.join(spec)}"
        )
    out = {}
    for ch, (unit, desc, _) in spec.items():
        if ch not in datasets:
            if ch in optional:
                continue
            raise DatasetError(f"{label}: {gkey}/{ch} is missing; expected {desc} in {unit}")
        arr = np.asarray(datasets[ch])
        check_dtype(label, f"{gkey}/{ch}", arr.dtype)
        out[ch] = arr
    return out



def _new_group_attrs(label: str, key: str, parent: h5py.Group, name: str, what: str, attrs) -> dict:
    """The attributes of the new capture or session group ``key`` (a copy): refused if ``name``
    already exists in ``parent``; ``hours`` validated (:class:`DatasetError` naming the key)."""
    _check_new(label, key, parent, name, what)
    attrs = dict(attrs)
    attrs["hours"] = _attr_hours(label, attrs, key)
    return attrs


def assemble_measurements(
    path: str | os.PathLike,
    axis: Mapping[str, Any],
    phase1: Iterable[tuple[str, Mapping[str, Any], Mapping[str, np.ndarray]]],
    phase2: Iterable[tuple[str, Mapping[str, Any], Iterable[tuple]]] = (),
    dial: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Write ``measurements.h5`` (format_version 2) atomically: to ``path + ".tmp"``, then replace.

    Parameters
    ----------
    path : target file, usually ``<campaign>/measurements.h5``.
    axis : nominal testbed description, validated by the axis contract
        (:class:`~analysis.dataset.axis.AxisDescription`) and stored as JSON in ``/@axis``.
    phase1 : iterable of ``(capture_name, attrs, datasets)``; ``attrs`` holds ``hours`` (float,
        operating hours), ``sample`` (int, Phase I sample index), ``fs_hz`` (float) and optionally
        more scalars; ``datasets`` holds ``speed`` (n,) rad/s, ``torque`` (n,) N*m, ``acc1`` and
        ``acc2`` (n, 3) m/s^2. ``unit`` attributes are added here.
    phase2 : iterable of ``(session_name, session_attrs, runs)``; ``session_attrs`` holds
        ``hours``; ``runs`` is an iterable of ``(run_name, run_attrs, datasets, dataset_attrs)``
        with datasets ``imu_acc`` (n, 3) m/s^2, ``imu_gyro`` (m, 3) rad/s, ``position_cmd`` (k,) m,
        and ``dataset_attrs[channel]["fs_hz"]`` (Hz) for each (``unit`` is added if absent and
        checked if given); ``run_attrs`` may hold ``speeds_mm_s`` (list of float) and the routine's
        :data:`~analysis.dataset.schema.ROUTINE_ATTRS` (numbers).
    dial : ``(hours, backlash_um)``, two (n,) arrays of dial-indicator readings, or None.

    Iterables are consumed lazily, one capture or run in memory at a time; pass them sorted by
    name for byte-identical files across runs. Arrays keep their dtype. Inputs are validated
    with the reader's rules (:class:`DatasetError`), and the finished file is checked by
    :func:`truth_mentions`: a name or string value revealing the injected truth raises
    ValueError and nothing is written.
    """
    path = Path(path)
    label = str(path)
    axis_json = _dumps("axis", AxisDescription.from_dict(dict(axis), label).to_dict(), allow_nan=False)

    def write(f: h5py.File) -> None:
        f.attrs["format"] = schema.MEASUREMENTS_FORMAT
        f.attrs["format_version"] = np.int64(schema.FORMAT_VERSION)
        f.attrs["axis"] = axis_json
        g1 = f.create_group("phase1")
        for name, attrs, datasets in phase1:
            gkey = f"/phase1/{name}"
            attrs = _new_group_attrs(label, gkey, g1, name, "capture", attrs)
            attrs["sample"] = _attr_int(label, attrs, gkey, "sample", "an integer Phase I sample index")
            attrs["fs_hz"] = _attr_fs(label, attrs, gkey)
            arrays = _channels(label, gkey, datasets, schema.PHASE1_CHANNELS)
            n = None
            for ch, (_unit, _, cols) in schema.PHASE1_CHANNELS.items():
                n = _check_shape(label, f"{gkey}/{ch}", arrays[ch].shape, _dims(cols, "n"), n, "len(speed)")
            g = g1.create_group(name)
            write_attrs(g, attrs)
            for ch, (unit, _, _) in schema.PHASE1_CHANNELS.items():
                _put(label, f"{gkey}/{ch}", g, ch, arrays[ch], {"unit": unit})
        g2 = f.create_group("phase2")
        for sname, sattrs, runs in phase2:
            skey = f"/phase2/{sname}"
            sattrs = _new_group_attrs(label, skey, g2, sname, "session", sattrs)
            gs = g2.create_group(sname)
            write_attrs(gs, sattrs)
            for rname, rattrs, datasets, dattrs in runs:
                rkey = f"{skey}/{rname}"
                _check_new(label, rkey, gs, rname, "run")
                arrays = _channels(label, rkey, datasets, schema.PHASE2_CHANNELS, schema.OPTIONAL_PHASE2_CHANNELS)
                dattrs = dattrs or {}
                chattrs = {}
                for ch, (unit, _, cols) in schema.PHASE2_CHANNELS.items():
                    if ch not in arrays:
                        continue
                    a = dict(dattrs.get(ch, {}))
                    sym = {"imu_acc": "n", "imu_gyro": "m", "position_cmd": "k"}[ch]
                    _check_shape(label, f"{rkey}/{ch}", arrays[ch].shape, _dims(cols, sym))
                    a["fs_hz"] = _attr_fs(label, a, f"{rkey}/{ch}")
                    a.setdefault("unit", unit)
                    _check_unit(label, f"{rkey}/{ch}", a, unit)
                    chattrs[ch] = a
                rattrs = dict(rattrs or {})
                if "speeds_mm_s" in rattrs:
                    sp = np.asarray(rattrs["speeds_mm_s"], dtype=float).reshape(-1)
                    if not np.all(np.isfinite(sp)):
                        raise DatasetError(
                            f"{label}: {rkey}@speeds_mm_s is {sp.tolist()}; expected finite speeds in mm/s")
                    rattrs["speeds_mm_s"] = sp
                rattrs.update(_routine(label, rkey, rattrs))
                gr = gs.create_group(rname)
                write_attrs(gr, rattrs)
                for ch in arrays:
                    _put(label, f"{rkey}/{ch}", gr, ch, arrays[ch], chattrs[ch])
        if dial is not None:
            hours, backlash = (np.asarray(a) for a in dial)
            gd = f.create_group("dial_indicator")
            check_dtype(label, "/dial_indicator/hours", hours.dtype)
            check_dtype(label, "/dial_indicator/backlash_um", backlash.dtype)
            n = _check_shape(label, "/dial_indicator/hours", hours.shape, ("n",))
            _check_shape(label, "/dial_indicator/backlash_um", backlash.shape, ("n",), n, "len(hours)")
            _put(label, "/dial_indicator/hours", gd, "hours", hours, {"unit": schema.DIAL_UNITS["hours"]})
            _put(label, "/dial_indicator/backlash_um", gd, "backlash_um", backlash,
                 {"unit": schema.DIAL_UNITS["backlash_um"]})
        leaks = _scan_truth_mentions(f)
        if leaks:
            shown = "; ".join(leaks[:5]) + (f"; and {len(leaks) - 5} more" if len(leaks) > 5 else "")
            raise ValueError(f"{label}: refusing to write measurements that reveal the injected truth: {shown}")

    return _write_h5(path, write)


def _unit_of(name: str) -> str | None:
    if name == "hours":
        return "h"
    for suffix, unit in _UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return None


def assemble_truth(
    path: str | os.PathLike,
    scenario_json: str,
    onset_hours: float | None,
    timeline: Mapping[str, np.ndarray],
    sessions: Iterable[tuple[str, Mapping[str, Any], np.ndarray, np.ndarray]] = (),
    effects: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``truth.h5`` (format_version 2) atomically: to ``path + ".tmp"``, then replace.

    Parameters
    ----------
    path : target file, usually ``<campaign>/truth.h5``.
    scenario_json : the scenario as a JSON object string, stored in ``/@scenario``.
    onset_hours : operating hours of the injected fault onset; None (stored as NaN) if none.
    timeline : 1-D arrays of equal length (t,): ``hours`` (h), ``preload_N`` (N), ``backlash_um``
        (um), plus any others (e.g. ``axial_stiffness_N_per_m``, ``drag_torque_Nm``,
        ``temperature_rise_K``); a ``unit`` attribute is inferred from the name's unit suffix.
    sessions : iterable of ``(session_name, attrs, x_m, E[, strokes])``: ``attrs`` holds ``hours``,
        ``backlash_um``, ``origin_offset_m`` and optionally more scalars; ``x_m`` (n,) true
        carriage positions in m; ``E`` (6, n) true error motions E_XX, E_YX, E_ZX (m),
        E_AX, E_BX, E_CX (rad); ``strokes`` (optional) maps each of
        :data:`~analysis.dataset.schema.STROKE_TRUTH` to a (moves,) array: the true rest-to-rest
        travels of the session's runs, per move in time order (the runs share one motion).
    effects : effect parameters (JSON-serialisable dict), stored as JSON in ``/effects@json``.
    """
    path = Path(path)
    label = str(path)
    try:
        ok = isinstance(scenario_json, str) and isinstance(json.loads(scenario_json), dict)
    except json.JSONDecodeError:
        ok = False
    if not ok:
        raise ValueError(f"scenario_json is {scenario_json!r:.80}; expected a JSON object string")
    effects_json = _dumps("effects", dict(effects or {}), allow_nan=True)
    onset = float("nan") if onset_hours is None else float(onset_hours)

    def write(f: h5py.File) -> None:
        f.attrs["format"] = schema.TRUTH_FORMAT
        f.attrs["format_version"] = np.int64(schema.FORMAT_VERSION)
        f.attrs["scenario"] = scenario_json
        f.attrs["onset_hours"] = np.float64(onset)
        gt = f.create_group("timeline")
        gt.attrs["onset_hours"] = np.float64(onset)  # also here, beside the injected state
        for key in schema.TIMELINE_REQUIRED:
            if key not in timeline:
                raise DatasetError(f"{label}: /timeline/{key} is missing; expected a (t,) array")
        n = None
        for key in [*schema.TIMELINE_REQUIRED, *(k for k in timeline if k not in schema.TIMELINE_REQUIRED)]:
            _check_name(label, f"/timeline/{key}", key, "timeline array")
            arr = np.asarray(timeline[key])
            check_dtype(label, f"/timeline/{key}", arr.dtype)
            n = _check_shape(label, f"/timeline/{key}", arr.shape, ("t",), n, "len(hours)")
            unit = _unit_of(key)
            _put(label, f"/timeline/{key}", gt, key, arr, {"unit": unit} if unit else {})
        gp = f.create_group("phase2")
        for name, attrs, x_m, E, *rest in sessions:
            skey = f"/phase2/{name}"
            _check_new(label, skey, gp, name, "session")
            attrs = dict(attrs)
            for a in schema.SESSION_TRUTH_REQUIRED:
                attrs[a] = _attr_number(label, attrs, skey, a, "a finite number")
            x_m, E = np.asarray(x_m), np.asarray(E)
            check_dtype(label, f"{skey}/x_m", x_m.dtype)
            check_dtype(label, f"{skey}/E", E.dtype)
            n = _check_shape(label, f"{skey}/x_m", x_m.shape, ("n",))
            _check_shape(label, f"{skey}/E", E.shape, (6, "n"), n, "len(x_m)")
            g = gp.create_group(name)
            write_attrs(g, attrs)
            _put(label, f"{skey}/x_m", g, "x_m", x_m, {"unit": "m"})
            _put(label, f"{skey}/E", g, "E", E, {"dofs": list(schema.DOFS), "units": list(schema.DOF_UNITS)})
            strokes = dict(rest[0]) if rest and rest[0] else {}
            if strokes:
                gs = g.create_group("strokes")
                m_ = None
                for k in schema.STROKE_TRUTH:
                    if k not in strokes:
                        raise DatasetError(f"{label}: {skey}/strokes/{k} is missing; expected a (moves,) array")
                for k, arr in strokes.items():
                    if k not in schema.STROKE_TRUTH:
                        raise DatasetError(f"{label}: {skey}/strokes/{k} is not a stroke truth array; "
                                           f"expected only {', '.join(schema.STROKE_TRUTH)}")
                    arr = np.asarray(arr)
                    check_dtype(label, f"{skey}/strokes/{k}", arr.dtype)
                    m_ = _check_shape(label, f"{skey}/strokes/{k}", arr.shape, ("moves",), m_, "len(speed_m_s)")
                    _put(label, f"{skey}/strokes/{k}", gs, k, arr, {"unit": schema.STROKE_TRUTH[k]})
        ge = f.create_group("effects")
        ge.attrs["json"] = effects_json

    return _write_h5(path, write)


def _write_h5(path: str | os.PathLike, fill) -> Path:
    """Create the HDF5 file ``path`` atomically: ``fill(h5py.File)`` writes its content."""
    def create(tmp: Path) -> None:
        with h5py.File(tmp, "w") as f:
            fill(f)

    return atomic_write(path, create)
