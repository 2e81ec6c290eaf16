"""Checks shared by the writers (on arrays) and the readers (on h5py datasets and attributes).

Each raises :class:`~analysis.dataset.schema.DatasetError` naming the file, the HDF5 key, the
offending value and what was expected.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from analysis.dataset.schema import MAX_VALUES, ROUTINE_ATTRS, DatasetError

#: A group name: letters, digits, "_", "-", "." (not starting with ".").
NAME_RE = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")


def _shape_pattern(dims: tuple[int | str, ...]) -> str:
    inner = ", ".join(str(d) for d in dims)
    return f"({inner},)" if len(dims) == 1 else f"({inner})"


def check_dtype(label: str, key: str, dtype: np.dtype) -> None:
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


def _check_range(label: str, key: str, arr: np.ndarray, limit: float, unit: str) -> None:
    """Every sample within ±``limit`` (the channel's physical range, :data:`PHYSICAL_RANGE`)."""
    if arr.size == 0 or max(-float(arr.min()), float(arr.max())) <= limit:  # two reductions, no copy
        return
    mag = np.abs(arr)
    flat = int(np.argmax(mag))
    if mag.reshape(-1)[flat] <= limit:
        return
    count = int(np.count_nonzero(mag > limit))
    first: Any = flat if arr.ndim == 1 else tuple(int(i) for i in np.unravel_index(flat, arr.shape))
    raise DatasetError(
        f"{label}: {key} has {count} value(s) beyond the physical range of the channel, the largest "
        f"{arr.reshape(-1)[flat]:.6g} {unit} at index {first}; expected |x| <= {limit:g} {unit} "
        "(a wrong unit or scale factor, or corrupt data)"
    )


def _check_size(label: str, key: str, shape: tuple[int, ...]) -> None:
    """At most :data:`MAX_VALUES` values, checked on the declared shape before reading."""
    n = int(np.prod(shape, dtype=np.float64)) if shape else 1
    if n > MAX_VALUES:
        raise DatasetError(f"{label}: {key} has shape {tuple(int(s) for s in shape)} ({n} values); expected at "
                           f"most {MAX_VALUES} values per dataset")


def as_str(value: Any) -> str | None:
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
    s = as_str(value)
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
    what = "a finite number of operating hours >= 0"
    hours = _attr_number(label, attrs, key, "hours", what)
    if hours < 0:
        raise DatasetError(f"{label}: {key}@hours is {_fmt(attrs['hours'])}; expected {what}")
    return hours


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
    got = as_str(attrs["unit"])
    if got != unit:
        raise DatasetError(
            f"{label}: {key}@unit is {_fmt(attrs['unit'])}; expected {unit!r} (convert to SI before writing)")


def _check_name(label: str, key: str, name: str, what: str) -> None:
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise DatasetError(
            f"{label}: {key} has name {name!r}; expected a {what} name of letters, digits, '_', '-', '.'"
        )


def _dims(cols: int, sym: str) -> tuple[int | str, ...]:
    return (sym,) if cols == 1 else (sym, cols)


def _routine(label: str, rkey: str, rattrs: Mapping[str, Any]) -> dict[str, float]:
    """The run's routine attributes (:data:`~analysis.dataset.schema.ROUTINE_ATTRS`) that are
    present, as floats; a non-finite or non-numeric one raises :class:`DatasetError` naming it."""
    out = {}
    for key, what in ROUTINE_ATTRS.items():
        if key in rattrs:
            x = _as_number(rattrs[key])
            if x is None or not math.isfinite(x):
                raise DatasetError(f"{label}: {rkey}@{key} is {_fmt(rattrs[key])}; expected {what}")
            out[key] = float(x)
    return out
