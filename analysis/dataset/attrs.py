"""HDF5 attribute values to and from plain Python, and the JSON attributes of the format."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import h5py
import numpy as np

from analysis.dataset.schema import DatasetError
from analysis.dataset.validate import (
    _fmt,
    as_str,
)


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


def from_attr(value: Any) -> Any:
    """An h5py attribute value as plain Python (str, int, float, list[str]) or a numeric array."""
    if isinstance(value, (bytes, np.bytes_)):
        return bytes(value).decode("utf-8", errors="replace")
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "OSU":
            return [from_attr(v) if not isinstance(v, str) else v for v in value.tolist()]
        return np.array(value)
    return value


def write_attrs(obj: h5py.HLObject, attrs: Mapping[str, Any] | None) -> None:
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
    s = as_str(text)
    if s is None:
        raise DatasetError(f"{label}: {key} is {_fmt(text)}; expected a JSON string")
    try:
        obj = json.loads(s)
    except json.JSONDecodeError as e:
        raise DatasetError(f"{label}: {key} is not valid JSON ({e}); expected a JSON object") from None
    if not isinstance(obj, dict):
        raise DatasetError(f"{label}: {key} is JSON of type {type(obj).__name__}; expected a JSON object")
    return obj
