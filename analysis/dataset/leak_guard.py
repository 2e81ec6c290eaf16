"""The truth-leak guard: no name or string value of ``measurements.h5`` may mention what only a
simulator knows (:data:`~analysis.dataset.schema.TRUTH_KEYS`)."""

from __future__ import annotations

import os
import re
from typing import Any

import h5py
import numpy as np

from analysis.dataset.h5file import open_h5
from analysis.dataset.schema import (
    ALLOWED_TRUTH_MENTIONS,
    TRUTH_KEYS,
)
from analysis.dataset.validate import as_str

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
        texts = [as_str(value)] if not isinstance(value, np.ndarray) or value.dtype.kind not in "OSU" else [
            as_str(v) for v in value.reshape(-1).tolist()
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
    with open_h5(path, str(path)) as f:
        return sorted(k for k, _ in _keys_and_values(f))


def truth_mentions(path: str | os.PathLike) -> list[str]:
    """Names and string attribute values of a file that mention a :data:`TRUTH_KEYS` word.

    Returns one line per offending key, e.g. ``"/@axis (value mentions 'preload')"``; empty for a
    clean ``measurements.h5``. Paths in :data:`ALLOWED_TRUTH_MENTIONS` are exempt by name.
    """
    with open_h5(path, str(path)) as f:
        return _scan_truth_mentions(f)
