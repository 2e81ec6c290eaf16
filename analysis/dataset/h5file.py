"""Opening a dataset file read-only and checking its ``/@format`` and ``/@format_version``."""

from __future__ import annotations

import os
import re

import h5py

from analysis.dataset.schema import (
    SUPPORTED_VERSIONS,
    DatasetError,
)
from analysis.dataset.validate import (
    _attr_int,
    _fmt,
    as_str,
)

_TRUNC_RE = re.compile(r"truncated file: eof = (\d+).*stored_eof = (\d+)")


def open_h5(path: str | os.PathLike, label: str) -> h5py.File:
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
    got = as_str(f.attrs["format"])
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
