"""The versioned on-disk dataset of one campaign (HDF5, ``format_version`` 1).

One campaign is one directory holding two files:

- ``measurements.h5``: what a real testbed records (Phase I captures of controller and nut
  accelerometer signals, Phase II IMU runs, dial-indicator readings). Estimators read only this.
- ``truth.h5``: what only a simulator knows (preload, backlash, stiffness over time, true error
  motions, onset hours, effect parameters). Scorers read both.

The layout is described for users in ``docs/dataset-format.md``. This module holds

- the readers (:func:`open_measurements`, :func:`open_truth`), which validate on access and raise
  :class:`DatasetError` naming the file, the HDF5 key, the offending value and what was expected;
- the writers (:func:`assemble_measurements`, :func:`assemble_truth`), which write to a temporary
  file and ``os.replace`` it into place;
- :class:`PartStore`, which keeps every finished unit of work of a campaign (a capture, a
  session, ...) in its own small, atomically written HDF5 file so a campaign killed at any point
  resumes without recomputing finished work;
- the truth-leak guard (:data:`TRUTH_KEYS`, :func:`measurement_keys`, :func:`truth_mentions`).

Units are SI inside (rad/s, N*m, m/s^2, m, rad, s); names carry their unit where it is not SI
(``hours``, ``backlash_um``, ``speeds_mm_s``). Reading never executes code from a file: attributes
holding structured data are JSON (parsed with :func:`json.loads`), and datasets of object, string
or compound dtype are rejected.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

__all__ = [
    "FORMAT_VERSION",
    "SUPPORTED_VERSIONS",
    "MEASUREMENTS_FORMAT",
    "TRUTH_FORMAT",
    "PHASE1_CHANNELS",
    "PHASE2_CHANNELS",
    "DOFS",
    "TRUTH_KEYS",
    "ALLOWED_TRUTH_MENTIONS",
    "DatasetError",
    "PartStore",
    "Phase1Capture",
    "Phase2Run",
    "Measurements",
    "Truth",
    "assemble_measurements",
    "assemble_truth",
    "open_measurements",
    "open_truth",
    "measurement_keys",
    "truth_mentions",
]

MEASUREMENTS_FORMAT = "ballscrew-twin/measurements"
TRUTH_FORMAT = "ballscrew-twin/truth"
FORMAT_VERSION = 1
SUPPORTED_VERSIONS = (1,)

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
DIAL_UNITS = {"hours": "h", "backlash_um": "um"}
#: Order of the six error motions in ``truth.h5`` ``/phase2/<session>/E``.
DOFS = ("E_XX", "E_YX", "E_ZX", "E_AX", "E_BX", "E_CX")
DOF_UNITS = ("m", "m", "m", "rad", "rad", "rad")
TIMELINE_REQUIRED = ("hours", "preload_N", "backlash_um")
SESSION_TRUTH_REQUIRED = ("hours", "backlash_um", "origin_offset_m")

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

_NAME_RE = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")
_KIND_RE = re.compile(r"^[A-Za-z0-9_-]+(/[A-Za-z0-9_-]+)*$")
_PART_FORMAT = "ballscrew-twin/part"
_PART_MARKER = "__part__"
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


class DatasetError(ValueError):
    """A dataset file is unreadable or does not follow the format.

    The message names the file, the HDF5 key (``/group/dataset`` or ``/group@attribute``), the
    offending value and what was expected.
    """


# --------------------------------------------------------------------------------------------
# Validation helpers, shared by the writers (on arrays) and the readers (on h5py datasets).
# --------------------------------------------------------------------------------------------


def _shape_pattern(dims: tuple[int | str, ...]) -> str:
    inner = ", ".join(str(d) for d in dims)
    return f"({inner},)" if len(dims) == 1 else f"({inner})"


def _check_dtype(label: str, key: str, dtype: np.dtype) -> None:
    if dtype.kind not in "fiu":
        raise DatasetError(f"{label}: {key} has dtype {dtype}; expected real numbers (float or integer)")


def _check_shape(
    label: str,
    key: str,
    shape: tuple[int, ...],
    dims: tuple[int | str, ...],
    n_expected: int | None = None,
    n_ref: str = "",
) -> int:
    """Check ``shape`` against ``dims`` (ints fixed, one str the free length); return that length.

    With ``n_expected`` the free length must equal it (``n_ref`` names where it comes from),
    otherwise it must be >= 1.
    """
    sym_pos = next(i for i, d in enumerate(dims) if isinstance(d, str))
    sym = dims[sym_pos]
    if n_expected is None:
        rule = f"{sym} >= 1"
    else:
        rule = f"{sym} equal to {n_ref} = {n_expected}"
    shape = tuple(int(s) for s in shape)
    ok = len(shape) == len(dims) and all(
        shape[i] == d for i, d in enumerate(dims) if not isinstance(d, str)
    )
    if ok:
        n = shape[sym_pos]
        ok = n >= 1 if n_expected is None else n == n_expected
    if not ok:
        raise DatasetError(f"{label}: {key} has shape {shape}; expected {_shape_pattern(dims)} with {rule}")
    return shape[sym_pos]


def _check_finite(label: str, key: str, arr: np.ndarray) -> None:
    if arr.dtype.kind != "f":
        return
    with np.errstate(all="ignore"):
        if np.isfinite(arr.sum()):  # fast path: NaN and inf propagate into the sum
            return
    bad = ~np.isfinite(arr)
    count = int(np.count_nonzero(bad))
    if count == 0:  # the sum overflowed, the samples are fine
        return
    flat = int(np.flatnonzero(bad)[0])
    first: Any = flat if arr.ndim == 1 else tuple(int(i) for i in np.unravel_index(flat, arr.shape))
    plural = "value" if count == 1 else "values"
    raise DatasetError(
        f"{label}: {key} has {count} non-finite {plural} (NaN or inf), first at index {first}; "
        f"expected finite samples"
    )


def _as_str(value: Any) -> str | None:
    """A string attribute value as str (accepts bytes and 1-element arrays, as MATLAB writes)."""
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(()).item()
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("utf-8", errors="replace")
    if isinstance(value, str):
        return str(value)
    return None


def _as_number(value: Any) -> float | None:
    """A numeric attribute value as float (accepts 1-element arrays, as MATLAB writes)."""
    if isinstance(value, np.ndarray):
        if value.size != 1 or value.dtype.kind not in "fiu":
            return None
        value = value.reshape(()).item()
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value)
    return None


def _fmt(value: Any) -> str:
    s = _as_str(value)
    if s is not None:
        return repr(s)
    if isinstance(value, (np.ndarray, np.generic)):
        value = value.tolist()
    return repr(value)


def _attr_number(label: str, attrs: Mapping[str, Any], key: str, name: str, what: str) -> float:
    if name not in attrs:
        raise DatasetError(f"{label}: {key}@{name} is missing; expected {what}")
    x = _as_number(attrs[name])
    if x is None or not np.isfinite(x):
        raise DatasetError(f"{label}: {key}@{name} is {_fmt(attrs[name])}; expected {what}")
    return x


def _attr_hours(label: str, attrs: Mapping[str, Any], key: str) -> float:
    return _attr_number(label, attrs, key, "hours", "a finite number of operating hours")


def _attr_fs(label: str, attrs: Mapping[str, Any], key: str) -> float:
    what = "a finite sampling rate > 0 Hz"
    fs = _attr_number(label, attrs, key, "fs_hz", what)
    if fs <= 0:
        raise DatasetError(f"{label}: {key}@fs_hz is {_fmt(attrs['fs_hz'])}; expected {what}")
    return fs


def _attr_int(label: str, attrs: Mapping[str, Any], key: str, name: str, what: str) -> int:
    x = _attr_number(label, attrs, key, name, what)
    if x != int(x):
        raise DatasetError(f"{label}: {key}@{name} is {_fmt(attrs[name])}; expected {what}")
    return int(x)


def _check_unit(label: str, key: str, attrs: Mapping[str, Any], unit: str) -> None:
    if "unit" not in attrs:
        raise DatasetError(f"{label}: {key}@unit is missing; expected {unit!r}")
    got = _as_str(attrs["unit"])
    if got != unit:
        raise DatasetError(
            f"{label}: {key}@unit is {_fmt(attrs['unit'])}; expected {unit!r} (convert to SI before writing)")


def _check_name(label: str, key: str, name: str, what: str) -> None:
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise DatasetError(
            f"{label}: {key} has name {name!r}; expected a {what} name of letters, digits, '_', '-', '.'"
        )


# --------------------------------------------------------------------------------------------
# Attribute conversion (writing and reading), JSON.
# --------------------------------------------------------------------------------------------


def _to_attr(key: str, value: Any) -> Any:
    """Convert a Python attribute value to something h5py stores portably (MATLAB reads it)."""
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return np.uint8(value)
    if isinstance(value, (int, np.integer)):
        return np.int64(value)
    if isinstance(value, (float, np.floating)):
        return np.float64(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value)
        if arr.dtype.kind in "iuf" and arr.ndim <= 1:
            return arr.astype(np.float64 if arr.dtype.kind == "f" else np.int64)
        if arr.dtype.kind in "UO" and arr.ndim == 1 and all(isinstance(v, str) for v in arr.tolist()):
            return np.array(arr.tolist(), dtype=h5py.string_dtype())
    raise TypeError(
        f"attribute {key!r} has value {value!r} of type {type(value).__name__}; expected str, int, "
        f"float, or a 1-D list of numbers or of strings (JSON-encode anything else)"
    )


def _from_attr(value: Any) -> Any:
    """An h5py attribute value as plain Python (str, int, float, list[str]) or a numeric array."""
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("utf-8", errors="replace")
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "OSU":
            return [_from_attr(v) if not isinstance(v, str) else v for v in value.tolist()]
        return np.array(value)
    return value


def _write_attrs(obj: h5py.HLObject, attrs: Mapping[str, Any] | None) -> None:
    for name, value in (attrs or {}).items():
        obj.attrs[name] = _to_attr(name, value)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"object of type {type(o).__name__} is not JSON serialisable")


def _dumps(what: str, obj: Any, allow_nan: bool) -> str:
    try:
        return json.dumps(obj, sort_keys=True, default=_json_default, allow_nan=allow_nan)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{what} cannot be stored as JSON: {e}") from None


def _loads(label: str, key: str, text: Any) -> dict:
    s = _as_str(text)
    if s is None:
        raise DatasetError(f"{label}: {key} is {_fmt(text)}; expected a JSON string")
    try:
        obj = json.loads(s)
    except json.JSONDecodeError as e:
        raise DatasetError(f"{label}: {key} is not valid JSON ({e}); expected a JSON object") from None
    if not isinstance(obj, dict):
        raise DatasetError(f"{label}: {key} is JSON of type {type(obj).__name__}; expected a JSON object")
    return obj


# --------------------------------------------------------------------------------------------
# Opening files.
# --------------------------------------------------------------------------------------------

_TRUNC_RE = re.compile(r"truncated file: eof = (\d+).*stored_eof = (\d+)")


def _open_h5(path: str | os.PathLike, label: str) -> h5py.File:
    """Open an HDF5 file read-only; unreadable or truncated files raise :class:`DatasetError`."""
    if not os.path.exists(path):
        raise FileNotFoundError(f"{label}: no such file")
    try:
        return h5py.File(path, "r")
    except OSError as e:
        m = _TRUNC_RE.search(str(e))
        if m:
            raise DatasetError(
                f"{label}: not a readable HDF5 file: it is truncated ({m.group(1)} of {m.group(2)} "
                f"bytes present); rewrite it"
            ) from None
        raise DatasetError(
            f"{label}: not a readable HDF5 file; it may be truncated or corrupt (HDF5 says: {e})"
        ) from None


def _check_format(label: str, f: h5py.File, expected: str) -> int:
    if "format" not in f.attrs:
        raise DatasetError(f"{label}: /@format is missing; expected {expected!r}")
    got = _as_str(f.attrs["format"])
    if got != expected:
        raise DatasetError(f"{label}: /@format is {_fmt(f.attrs['format'])}; expected {expected!r}")
    supported = ", ".join(str(v) for v in SUPPORTED_VERSIONS)
    what = f"one of the supported versions: {supported}"
    version = _attr_int(label, f.attrs, "/", "format_version", what)
    if version not in SUPPORTED_VERSIONS:
        raise DatasetError(
            f"{label}: /@format_version is {version}; this reader supports format_version {supported}"
            f" (a newer ballscrew-twin may read it)"
        )
    return version


def _replace_tmp(path: Path, write) -> Path:
    """Call ``write(h5py.File)`` on ``path + '.tmp'`` and atomically move it to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(str(path) + ".tmp")
    try:
        with h5py.File(tmp, "w") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


# --------------------------------------------------------------------------------------------
# PartStore: resumable campaigns.
# --------------------------------------------------------------------------------------------


class PartStore:
    """Finished units of work of a campaign, each in its own atomically written HDF5 file.

    A part lives in ``root_dir/.parts/<kind>/<name>.h5``. It is written to a unique temporary
    file ``.<name>.<random>.tmp`` in the same directory and ``os.replace``-d into place, so a
    process killed (even with SIGKILL) at any point leaves either the complete part or no part;
    temporaries are ignored by :meth:`has`, :meth:`names` and :meth:`read`, and
    :meth:`remove_temporaries` deletes them. :meth:`has` also returns False for a part that is
    not a complete, readable part file (e.g. truncated by a disk problem), so it gets recomputed.

    Arrays are stored uncompressed in the dtype given (gzip level 1 saves under 10 % on float32
    sensor noise but makes a 100k x 8 capture 30-40x slower to write) and read back bit for bit,
    so a campaign assembled from parts of an interrupted run equals an uninterrupted one.

    ``kind`` is a relative path of names (e.g. ``"phase1"``, ``"phase2/s0007"``), ``name`` a
    file-safe name (e.g. ``"c000123"``); zero-pad numbers so that names sort. Dataset keys may
    contain ``/`` to group datasets (e.g. ``"r0003/imu_acc"``).

    Parameters
    ----------
    root_dir : campaign directory.
    fsync : also flush each part to stable storage before moving it into place (protects against
        power loss, not needed against killed processes; costs time on real disks).

    Example (a campaign runner)::

        store = PartStore(campaign_dir)
        store.remove_temporaries()            # before any writer starts
        for name in capture_names:
            if not store.has("phase1", name):
                store.write("phase1", name, {"hours": h, "sample": s, "fs_hz": 10e3},
                            {"speed": w, "torque": q, "acc1": a1, "acc2": a2})
        phase1 = ((name, attrs, data) for name, attrs, data, _ in store.items("phase1"))
    """

    def __init__(self, root_dir: str | os.PathLike, *, fsync: bool = False):
        self.root_dir = Path(root_dir)
        self.parts_dir = self.root_dir / ".parts"
        self.fsync = fsync

    def _kind_dir(self, kind: str) -> Path:
        if not isinstance(kind, str) or not _KIND_RE.match(kind):
            raise ValueError(f"part kind {kind!r}: expected names of letters, digits, '_', '-' separated by '/'")
        return self.parts_dir / kind

    def path(self, kind: str, name: str) -> Path:
        """Path of the part file ``root_dir/.parts/<kind>/<name>.h5``."""
        if not isinstance(name, str) or not _NAME_RE.match(name) or name.endswith(".tmp"):
            raise ValueError(f"part name {name!r}: expected letters, digits, '_', '-', '.' (not starting with '.')")
        return self._kind_dir(kind) / f"{name}.h5"

    def has(self, kind: str, name: str) -> bool:
        """True when the part exists and is a complete, readable part file."""
        p = self.path(kind, name)
        if not p.is_file():
            return False
        try:
            with h5py.File(p, "r") as f:
                return _as_str(f.attrs.get(_PART_MARKER)) == _PART_FORMAT
        except OSError:
            return False

    def write(
        self,
        kind: str,
        name: str,
        attrs: Mapping[str, Any],
        datasets: Mapping[str, np.ndarray],
        dataset_attrs: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> Path:
        """Store one finished unit of work atomically; return the part's path.

        ``attrs``: scalars, strings or 1-D lists (no names starting with ``__``);
        ``datasets``: arrays of real numbers, any shape, stored in their dtype;
        ``dataset_attrs``: per-dataset attributes, keyed like ``datasets``.
        An existing part of the same kind and name is replaced.
        """
        final = self.path(kind, name)
        dataset_attrs = dict(dataset_attrs or {})
        for key in attrs:
            if key.startswith("__"):
                raise ValueError(f"part {kind}/{name}: attribute {key!r}: names starting with '__' are reserved")
        arrays = {}
        for key, value in datasets.items():
            if not isinstance(key, str) or not _KIND_RE.match(key):
                raise ValueError(f"part {kind}/{name}: dataset key {key!r}: expected names separated by '/'")
            arr = np.asarray(value)
            if arr.dtype.kind not in "biuf":
                raise ValueError(f"part {kind}/{name}: dataset {key!r} has dtype {arr.dtype}; expected real numbers")
            arrays[key] = arr
        unknown = sorted(set(dataset_attrs) - set(arrays))
        if unknown:
            raise ValueError(f"part {kind}/{name}: dataset_attrs for unknown datasets {unknown}")
        final.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=final.parent, prefix=f".{name}.", suffix=".tmp")
        os.close(fd)
        try:
            with h5py.File(tmp, "w") as f:
                _write_attrs(f, attrs)
                for key in sorted(arrays):
                    ds = f.create_dataset(key, data=arrays[key])
                    _write_attrs(ds, dataset_attrs.get(key))
                f.attrs[_PART_MARKER] = _PART_FORMAT
            if self.fsync:
                _fsync_path(tmp)
            os.replace(tmp, final)
            if self.fsync:
                _fsync_path(final.parent)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return final

    def read(self, kind: str, name: str) -> tuple[dict[str, Any], dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Return ``(attrs, datasets, dataset_attrs)`` of a part, arrays in their stored dtype.

        ``dataset_attrs`` has an entry only for datasets that have attributes. Raises
        FileNotFoundError for a missing part and :class:`DatasetError` for an unreadable one.
        """
        p = self.path(kind, name)
        label = str(p)
        with _open_h5(p, label) as f:
            if _as_str(f.attrs.get(_PART_MARKER)) != _PART_FORMAT:
                raise DatasetError(f"{label}: /@{_PART_MARKER} is missing; expected {_PART_FORMAT!r}")
            attrs = {k: _from_attr(v) for k, v in f.attrs.items() if k != _PART_MARKER}
            keys: list[str] = []
            f.visititems(lambda k, obj: keys.append(k) if isinstance(obj, h5py.Dataset) else None)
            datasets: dict[str, np.ndarray] = {}
            dattrs: dict[str, dict[str, Any]] = {}
            for key in sorted(keys):
                ds = f[key]
                _check_dtype(label, "/" + key, ds.dtype)
                try:
                    datasets[key] = ds[()]
                except OSError as e:
                    raise DatasetError(f"{label}: /{key} could not be read; the file may be corrupt ({e})") from None
                if len(ds.attrs):
                    dattrs[key] = {k: _from_attr(v) for k, v in ds.attrs.items()}
        return attrs, datasets, dattrs

    def names(self, kind: str) -> list[str]:
        """Sorted names of the stored parts of ``kind`` (temporaries excluded)."""
        d = self._kind_dir(kind)
        if not d.is_dir():
            return []
        return sorted(
            p.name[:-3] for p in d.iterdir() if p.is_file() and p.name.endswith(".h5") and not p.name.startswith(".")
        )

    def items(self, kind: str) -> Iterator[tuple[str, dict, dict, dict]]:
        """Yield ``(name, attrs, datasets, dataset_attrs)`` for every part of ``kind``, by name."""
        for name in self.names(kind):
            yield (name, *self.read(kind, name))

    def remove_temporaries(self, kind: str | None = None) -> int:
        """Delete leftover temporaries of killed writes (of ``kind``, or all); return how many.

        Call it when no writer is running (e.g. when a campaign starts): it would also delete the
        temporary file of a write in progress.
        """
        base = self.parts_dir if kind is None else self._kind_dir(kind)
        if not base.is_dir():
            return 0
        n = 0
        for p in base.rglob(".*.tmp"):
            p.unlink(missing_ok=True)
            n += 1
        return n


def _fsync_path(path: str | os.PathLike) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


# --------------------------------------------------------------------------------------------
# Writers.
# --------------------------------------------------------------------------------------------


def _put(label: str, key: str, g: h5py.Group, name: str, arr: np.ndarray, attrs: Mapping[str, Any]) -> None:
    _check_finite(label, key, arr)
    ds = g.create_dataset(name, data=arr)
    _write_attrs(ds, attrs)


def _channels(
    label: str,
    gkey: str,
    datasets: Mapping[str, Any],
    spec: Mapping[str, tuple[str, str, int]],
) -> dict[str, np.ndarray]:
    unknown = sorted(set(datasets) - set(spec))
    if unknown:
        raise DatasetError(
            f"{label}: {gkey}/{unknown[0]} is not a channel of format_version {FORMAT_VERSION}; "
            f"expected only {', '.join(spec)}"
        )
    out = {}
    for ch, (unit, desc, _) in spec.items():
        if ch not in datasets:
            raise DatasetError(f"{label}: {gkey}/{ch} is missing; expected {desc} in {unit}")
        arr = np.asarray(datasets[ch])
        _check_dtype(label, f"{gkey}/{ch}", arr.dtype)
        out[ch] = arr
    return out


def _dims(cols: int, sym: str) -> tuple[int | str, ...]:
    return (sym,) if cols == 1 else (sym, cols)


def assemble_measurements(
    path: str | os.PathLike,
    axis: Mapping[str, Any],
    phase1: Iterable[tuple[str, Mapping[str, Any], Mapping[str, np.ndarray]]],
    phase2: Iterable[tuple[str, Mapping[str, Any], Iterable[tuple]]] = (),
    dial: tuple[np.ndarray, np.ndarray] | None = None,
) -> Path:
    """Write ``measurements.h5`` (format_version 1) atomically: to ``path + ".tmp"``, then replace.

    Parameters
    ----------
    path : target file, usually ``<campaign>/measurements.h5``.
    axis : nominal testbed description (JSON-serialisable dict), stored as JSON in ``/@axis``.
    phase1 : iterable of ``(capture_name, attrs, datasets)``; ``attrs`` holds ``hours`` (float,
        operating hours), ``sample`` (int, Phase I sample index), ``fs_hz`` (float) and optionally
        more scalars; ``datasets`` holds ``speed`` (n,) rad/s, ``torque`` (n,) N*m, ``acc1`` and
        ``acc2`` (n, 3) m/s^2. ``unit`` attributes are added here.
    phase2 : iterable of ``(session_name, session_attrs, runs)``; ``session_attrs`` holds
        ``hours``; ``runs`` is an iterable of ``(run_name, run_attrs, datasets, dataset_attrs)``
        with datasets ``imu_acc`` (n, 3) m/s^2, ``imu_gyro`` (m, 3) rad/s, ``position_cmd`` (k,) m,
        and ``dataset_attrs[channel]["fs_hz"]`` (Hz) for each (``unit`` is added if absent and
        checked if given); ``run_attrs`` may hold ``speeds_mm_s`` (list of float).
    dial : ``(hours, backlash_um)``, two (n,) arrays of dial-indicator readings, or None.

    Iterables are consumed lazily, one capture or run in memory at a time; pass them sorted by
    name for byte-identical files across runs. Arrays keep their dtype. Inputs are validated
    with the reader's rules (:class:`DatasetError`), and the finished file is checked by
    :func:`truth_mentions`: a name or string value revealing the injected truth raises
    ValueError and nothing is written.
    """
    path = Path(path)
    label = str(path)
    axis_json = _dumps("axis", dict(axis), allow_nan=False)

    def write(f: h5py.File) -> None:
        f.attrs["format"] = MEASUREMENTS_FORMAT
        f.attrs["format_version"] = np.int64(FORMAT_VERSION)
        f.attrs["axis"] = axis_json
        g1 = f.create_group("phase1")
        for name, attrs, datasets in phase1:
            gkey = f"/phase1/{name}"
            _check_name(label, gkey, name, "capture")
            if name in g1:
                raise DatasetError(f"{label}: {gkey} is given twice; expected unique capture names")
            attrs = dict(attrs)
            attrs["hours"] = _attr_hours(label, attrs, gkey)
            attrs["sample"] = _attr_int(label, attrs, gkey, "sample", "an integer Phase I sample index")
            attrs["fs_hz"] = _attr_fs(label, attrs, gkey)
            arrays = _channels(label, gkey, datasets, PHASE1_CHANNELS)
            n = None
            for ch, (_unit, _, cols) in PHASE1_CHANNELS.items():
                n = _check_shape(label, f"{gkey}/{ch}", arrays[ch].shape, _dims(cols, "n"), n, "len(speed)")
            g = g1.create_group(name)
            _write_attrs(g, attrs)
            for ch, (unit, _, _) in PHASE1_CHANNELS.items():
                _put(label, f"{gkey}/{ch}", g, ch, arrays[ch], {"unit": unit})
        g2 = f.create_group("phase2")
        for sname, sattrs, runs in phase2:
            skey = f"/phase2/{sname}"
            _check_name(label, skey, sname, "session")
            if sname in g2:
                raise DatasetError(f"{label}: {skey} is given twice; expected unique session names")
            sattrs = dict(sattrs)
            sattrs["hours"] = _attr_hours(label, sattrs, skey)
            gs = g2.create_group(sname)
            _write_attrs(gs, sattrs)
            for rname, rattrs, datasets, dattrs in runs:
                rkey = f"{skey}/{rname}"
                _check_name(label, rkey, rname, "run")
                if rname in gs:
                    raise DatasetError(f"{label}: {rkey} is given twice; expected unique run names")
                arrays = _channels(label, rkey, datasets, PHASE2_CHANNELS)
                dattrs = dattrs or {}
                chattrs = {}
                for ch, (unit, _, cols) in PHASE2_CHANNELS.items():
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
                gr = gs.create_group(rname)
                _write_attrs(gr, rattrs)
                for ch in PHASE2_CHANNELS:
                    _put(label, f"{rkey}/{ch}", gr, ch, arrays[ch], chattrs[ch])
        if dial is not None:
            hours, backlash = (np.asarray(a) for a in dial)
            gd = f.create_group("dial_indicator")
            _check_dtype(label, "/dial_indicator/hours", hours.dtype)
            _check_dtype(label, "/dial_indicator/backlash_um", backlash.dtype)
            n = _check_shape(label, "/dial_indicator/hours", hours.shape, ("n",))
            _check_shape(label, "/dial_indicator/backlash_um", backlash.shape, ("n",), n, "len(hours)")
            _put(label, "/dial_indicator/hours", gd, "hours", hours, {"unit": DIAL_UNITS["hours"]})
            _put(label, "/dial_indicator/backlash_um", gd, "backlash_um", backlash, {"unit": DIAL_UNITS["backlash_um"]})
        leaks = _scan_truth_mentions(f)
        if leaks:
            shown = "; ".join(leaks[:5]) + (f"; and {len(leaks) - 5} more" if len(leaks) > 5 else "")
            raise ValueError(f"{label}: refusing to write measurements that reveal the injected truth: {shown}")

    return _replace_tmp(path, write)


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
    """Write ``truth.h5`` (format_version 1) atomically: to ``path + ".tmp"``, then replace.

    Parameters
    ----------
    path : target file, usually ``<campaign>/truth.h5``.
    scenario_json : the scenario as a JSON object string, stored in ``/@scenario``.
    onset_hours : operating hours of the injected fault onset; None (stored as NaN) if none.
    timeline : 1-D arrays of equal length (t,): ``hours`` (h), ``preload_N`` (N), ``backlash_um``
        (um), plus any others (e.g. ``axial_stiffness_N_per_m``, ``drag_torque_Nm``,
        ``temperature_rise_K``); a ``unit`` attribute is inferred from the name's unit suffix.
    sessions : iterable of ``(session_name, attrs, x_m, E)``: ``attrs`` holds ``hours``,
        ``backlash_um``, ``origin_offset_m`` and optionally more scalars; ``x_m`` (n,) true
        carriage positions in m; ``E`` (6, n) true error motions E_XX, E_YX, E_ZX (m),
        E_AX, E_BX, E_CX (rad).
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
        f.attrs["format"] = TRUTH_FORMAT
        f.attrs["format_version"] = np.int64(FORMAT_VERSION)
        f.attrs["scenario"] = scenario_json
        f.attrs["onset_hours"] = np.float64(onset)
        gt = f.create_group("timeline")
        gt.attrs["onset_hours"] = np.float64(onset)  # also here, beside the injected state
        for key in TIMELINE_REQUIRED:
            if key not in timeline:
                raise DatasetError(f"{label}: /timeline/{key} is missing; expected a (t,) array")
        n = None
        for key in [*TIMELINE_REQUIRED, *(k for k in timeline if k not in TIMELINE_REQUIRED)]:
            _check_name(label, f"/timeline/{key}", key, "timeline array")
            arr = np.asarray(timeline[key])
            _check_dtype(label, f"/timeline/{key}", arr.dtype)
            n = _check_shape(label, f"/timeline/{key}", arr.shape, ("t",), n, "len(hours)")
            unit = _unit_of(key)
            _put(label, f"/timeline/{key}", gt, key, arr, {"unit": unit} if unit else {})
        gp = f.create_group("phase2")
        for name, attrs, x_m, E in sessions:
            skey = f"/phase2/{name}"
            _check_name(label, skey, name, "session")
            if name in gp:
                raise DatasetError(f"{label}: {skey} is given twice; expected unique session names")
            attrs = dict(attrs)
            for a in SESSION_TRUTH_REQUIRED:
                attrs[a] = _attr_number(label, attrs, skey, a, "a finite number")
            x_m, E = np.asarray(x_m), np.asarray(E)
            _check_dtype(label, f"{skey}/x_m", x_m.dtype)
            _check_dtype(label, f"{skey}/E", E.dtype)
            n = _check_shape(label, f"{skey}/x_m", x_m.shape, ("n",))
            _check_shape(label, f"{skey}/E", E.shape, (6, "n"), n, "len(x_m)")
            g = gp.create_group(name)
            _write_attrs(g, attrs)
            _put(label, f"{skey}/x_m", g, "x_m", x_m, {"unit": "m"})
            _put(label, f"{skey}/E", g, "E", E, {"dofs": list(DOFS), "units": list(DOF_UNITS)})
        ge = f.create_group("effects")
        ge.attrs["json"] = effects_json

    return _replace_tmp(path, write)


# --------------------------------------------------------------------------------------------
# Readers.
# --------------------------------------------------------------------------------------------


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
    position_cmd (k,) m at position_cmd_fs_hz; hours: operating hours of the session;
    speeds_mm_s: commanded traverse speeds in mm/s if recorded, else None.
    """

    session: str
    run: str
    hours: float
    imu_acc: np.ndarray
    imu_acc_fs_hz: float
    imu_gyro: np.ndarray
    imu_gyro_fs_hz: float
    position_cmd: np.ndarray
    position_cmd_fs_hz: float
    speeds_mm_s: tuple[float, ...] | None = None


class _Reader:
    """Common part of the read-only file wrappers (context managers)."""

    _format = ""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.label = str(path)
        self._f = _open_h5(path, self.label)
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

    def _obj(self, key: str, kind: type, what: str):
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
        return sorted(k for k, v in g.items() if isinstance(v, h5py.Group))

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
        _check_dtype(self.label, key, ds.dtype)
        _check_shape(self.label, key, ds.shape, dims, n_expected, n_ref)
        attrs = self._attrs(ds, key)
        if unit is not None:
            _check_unit(self.label, key, attrs, unit)
        try:
            arr = np.asarray(ds[()], dtype=np.float64)
        except OSError as e:
            raise DatasetError(
                f"{self.label}: {key} could not be read; the file may be truncated or corrupt ({e})") from None
        _check_finite(self.label, key, arr)
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

    _format = MEASUREMENTS_FORMAT

    def axis(self) -> dict:
        """The nominal testbed description (``/@axis``, JSON)."""
        return self._json_attr("/", self._f, "axis")

    def phase1_captures(self) -> list[str]:
        """Names of the Phase I captures, sorted by (hours, name)."""
        return _sorted_by_hours(self, "/phase1", self._names("/phase1"))

    def phase1(self, name: str) -> Phase1Capture:
        """One Phase I capture, validated (see :class:`Phase1Capture`)."""
        gkey = f"/phase1/{name}"
        g = self._obj(gkey, h5py.Group, "a Phase I capture group")
        attrs = self._attrs(g, gkey)
        hours = _attr_hours(self.label, attrs, gkey)
        sample = _attr_int(self.label, attrs, gkey, "sample", "an integer Phase I sample index")
        fs = _attr_fs(self.label, attrs, gkey)
        arrays, n = {}, None
        for ch, (unit, desc, cols) in PHASE1_CHANNELS.items():
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

    def phase2(self, session: str, run: str) -> Phase2Run:
        """One Phase II run, validated (see :class:`Phase2Run`)."""
        hours = self.session_hours(session)
        rkey = f"/phase2/{session}/{run}"
        g = self._obj(rkey, h5py.Group, "a Phase II run group")
        out: dict[str, Any] = {}
        for ch, (unit, desc, cols) in PHASE2_CHANNELS.items():
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
        return Phase2Run(session, run, hours, speeds_mm_s=speeds, **out)

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
        return hours, backlash

    def validate(self) -> None:
        """Read and validate everything (e.g. after converting real recordings)."""
        self.axis()
        for c in self.phase1_captures():
            self.phase1(c)
        for s in self.phase2_sessions():
            for r in self.phase2_runs(s):
                self.phase2(s, r)
        self.dial_indicator()


class Truth(_Reader):
    """Read-only view of a ``truth.h5``; use :func:`open_truth` (a context manager)."""

    _format = TRUTH_FORMAT

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
        for key in [*TIMELINE_REQUIRED, *sorted(k for k in g if k not in TIMELINE_REQUIRED)]:
            out[key], _ = self._array(f"/timeline/{key}", "a (t,) array", ("t",), None, n, "len(hours)")
            n = len(out[key])
        return out

    def sessions(self) -> list[str]:
        """Names of the Phase II sessions with true error motions, sorted by (hours, name)."""
        return _sorted_by_hours(self, "/phase2", self._names("/phase2"))

    def session(self, name: str) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
        """``(x_m (n,) m, E (6, n) m and rad in DOFS order, attrs)`` of a Phase II session."""
        key = f"/phase2/{name}"
        g = self._obj(key, h5py.Group, "a Phase II session group")
        attrs = {k: _from_attr(v) for k, v in self._attrs(g, key).items()}
        for a in SESSION_TRUTH_REQUIRED:
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


# --------------------------------------------------------------------------------------------
# Truth-leak guard.
# --------------------------------------------------------------------------------------------

_TRUTH_RES = tuple(
    (k, re.compile(rf"(?<![a-z]){re.escape(k)}(?:s|es|ed|ing)?(?![a-z])")) for k in TRUTH_KEYS
)


def _normalise(text: str) -> str:
    text = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", text)  # camelCase -> camel_Case
    return re.sub(r"[^a-z0-9]+", "_", text.lower())


def _mentions(text: str) -> list[str]:
    norm = _normalise(text)
    return [k for k, rx in _TRUTH_RES if rx.search(norm)]


def _keys_and_values(f: h5py.File) -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = [(f"/@{k}", v) for k, v in f.attrs.items()]

    def visit(name: str, obj: h5py.HLObject) -> None:
        out.append((f"/{name}", None))
        out.extend((f"/{name}@{k}", v) for k, v in obj.attrs.items())

    f.visititems(visit)
    return out


def _scan_truth_mentions(f: h5py.File) -> list[str]:
    found = []
    for key, value in _keys_and_values(f):
        checked = key
        for allowed in ALLOWED_TRUTH_MENTIONS:
            if key == allowed or key.startswith(allowed + "@") or key.startswith(allowed + "/"):
                checked = key[len(allowed):]
        hits = _mentions(checked)
        if hits:
            found.append(f"{key} (name mentions {', '.join(repr(h) for h in hits)})")
        if value is None:
            continue
        texts = [_as_str(value)] if not isinstance(value, np.ndarray) or value.dtype.kind not in "OSU" else [
            _as_str(v) for v in value.reshape(-1).tolist()
        ]
        hits = sorted({h for t in texts if t for h in _mentions(t)}, key=TRUTH_KEYS.index)
        if hits:
            found.append(f"{key} (value mentions {', '.join(repr(h) for h in hits)})")
    return found


def measurement_keys(path: str | os.PathLike) -> list[str]:
    """Every group, dataset and attribute path of an HDF5 file, sorted.

    Groups and datasets as ``/phase1/c000000/speed``, attributes as ``/phase1/c000000@hours``
    (root attributes as ``/@format``).
    """
    with _open_h5(path, str(path)) as f:
        return sorted(k for k, _ in _keys_and_values(f))


def truth_mentions(path: str | os.PathLike) -> list[str]:
    """Names and string attribute values of a file that mention a :data:`TRUTH_KEYS` word.

    Returns one line per offending key, e.g. ``"/@axis (value mentions 'preload')"``; empty for a
    clean ``measurements.h5``. Paths in :data:`ALLOWED_TRUTH_MENTIONS` are exempt by name.
    """
    with _open_h5(path, str(path)) as f:
        return _scan_truth_mentions(f)
