"""Readers of a laboratory's files: CSV, MATLAB ``.mat`` (v5 and v7.3), NI TDMS, ASAM MDF.

:func:`read_channels` returns the requested channels of one file as :class:`Channel` (float64
samples, the sampling rate the file states if it states one, and how to name sample ``i`` in a
message: ``line 1234`` of a CSV file, ``sample 1233`` otherwise). Problems raise
:class:`~analysis.ingest.spec.ImportSpecError` naming the file, the channel and the line.

Channel names:

- CSV: the header's column names (``header_line``, 1-based; lines above it are skipped).
- MAT: a variable name, struct fields joined with dots (``daq.acc``), and a column of a matrix
  in brackets, 0-based (``daq.acc[2]``), in MATLAB's orientation for v5 and v7.3 alike.
- TDMS: the channel name, in ``group`` if given, else in the one group that holds it.
- MDF: the channel name (``group`` unused).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.ingest.spec import ImportSpecError

READERS = ("csv", "mat", "tdms", "mdf")
EXTENSIONS = {".csv": "csv", ".txt": "csv", ".tsv": "csv", ".mat": "mat", ".tdms": "tdms",
              ".mf4": "mdf", ".mdf": "mdf", ".dat": "mdf"}


@dataclass(frozen=True)
class Channel:
    """One channel of a file: ``values`` (n,) float64, ``fs_hz`` stated by the file or None,
    ``first_line`` the file line of sample 0 (CSV) or 0 (other formats)."""

    name: str
    values: np.ndarray
    fs_hz: float | None = None
    first_line: int = 0

    def at(self, i: int) -> str:
        """How a message names sample ``i``."""
        return f"line {self.first_line + i}" if self.first_line else f"sample {i}"


def reader_for(path: Path, reader: str | None) -> str:
    """The reader named in the spec, else the one of the file's extension."""
    if reader is not None:
        return reader
    r = EXTENSIONS.get(path.suffix.lower())
    if r is None:
        raise ImportSpecError(f"{path}: no reader for the extension {path.suffix!r}; set reader = one of "
                              f"{', '.join(READERS)} in the spec")
    return r


def read_channels(path: Path, names: list[str], *, reader: str | None = None, group: str | None = None,
                  delimiter: str = ",", header_line: int = 1, decimal: str = ".") -> dict[str, Channel]:
    """The channels ``names`` of the file ``path`` (see the module's doc for the names)."""
    kind = reader_for(path, reader)
    if not path.is_file():
        raise ImportSpecError(f"{path}: no such file")
    names = list(dict.fromkeys(names))
    try:
        if kind == "csv":
            return _csv(path, names, delimiter, header_line, decimal)
        if kind == "mat":
            return _mat(path, names)
        if kind == "tdms":
            return _tdms(path, names, group)
        return _mdf(path, names)
    except ImportSpecError:
        raise
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ImportSpecError(f"{path}: not a readable {kind.upper()} file ({type(e).__name__}: {e})") from None


def _missing(path: Path, name: str, available, where: str = "") -> ImportSpecError:
    avail = sorted(str(a) for a in available)
    shown = ", ".join(repr(a) for a in avail[:12]) + (f", ... ({len(avail)} in all)" if len(avail) > 12 else "")
    return ImportSpecError(f"{path}: channel {name!r} not found{where}; the file has {shown or 'no channels'}")


def _csv(path: Path, names: list[str], delimiter: str, header_line: int, decimal: str) -> dict[str, Channel]:
    import pandas as pd

    kw = dict(sep=delimiter, skiprows=header_line - 1, decimal=decimal, skipinitialspace=True)
    header = pd.read_csv(path, nrows=0, **kw).columns
    header = [str(c).strip() for c in header]
    for n in names:
        if n not in header:
            raise _missing(path, n, header, f" in the header (line {header_line})")
    cols = [header.index(n) for n in names]
    try:
        df = pd.read_csv(path, usecols=cols, dtype=np.float64, **kw)
    except ValueError:
        df = pd.read_csv(path, usecols=cols, dtype=str, keep_default_na=False, **kw)
        for c in df.columns:
            raw = df[c].str.strip()
            num = pd.to_numeric(raw.str.replace(decimal, ".") if decimal != "." else raw, errors="coerce")
            bad = np.flatnonzero(num.isna().to_numpy() & ~raw.str.lower().isin(["", "nan", "inf", "-inf"]))
            if bad.size:
                i = int(bad[0])
                raise ImportSpecError(f"{path}: channel {str(c).strip()!r}, line {header_line + 1 + i}: "
                                      f"{raw.iloc[i]!r} is not a number") from None
        raise
    df.columns = [str(c).strip() for c in df.columns]
    return {n: Channel(n, df[n].to_numpy(np.float64), None, header_line + 1) for n in names}


_INDEX = re.compile(r"^(?P<path>[^\[\]]+?)(\[(?P<col>\d+)\])?$")


def _mat(path: Path, names: list[str]) -> dict[str, Channel]:
    import h5py

    if h5py.is_hdf5(path):  # v7.3: HDF5, arrays stored transposed
        with h5py.File(path, "r") as f:
            return {n: Channel(n, _mat_pick(path, n, lambda parts: _h5_get(f, parts), list(f.keys())))
                    for n in names}
    from scipy.io import loadmat

    data = loadmat(path, squeeze_me=False, struct_as_record=True, simplify_cells=True)
    top = [k for k in data if not k.startswith("__")]
    return {n: Channel(n, _mat_pick(path, n, lambda parts: _dict_get(data, parts), top)) for n in names}


def _dict_get(data, parts):
    obj = data
    for p in parts:
        if not isinstance(obj, dict) or p not in obj:
            return None
        obj = obj[p]
    return np.asarray(obj)


def _h5_get(f, parts):
    import h5py

    key = "/".join(parts)
    if key not in f or not isinstance(f[key], h5py.Dataset):
        return None
    return np.asarray(f[key][()]).T  # MATLAB's orientation


def _mat_pick(path: Path, name: str, get, top) -> np.ndarray:
    m = _INDEX.match(name)
    if m is None:
        raise ImportSpecError(f"{path}: channel {name!r} is not a MAT variable name (var, var.field, var[col])")
    arr = get(m["path"].split("."))
    if arr is None:
        raise _missing(path, m["path"], top, " among the variables")
    if arr.dtype.kind not in "fiub":
        raise ImportSpecError(f"{path}: channel {name!r} holds {arr.dtype} data; expected numbers")
    arr = np.atleast_2d(arr.astype(np.float64))
    if arr.shape[0] == 1 and m["col"] is None:
        return arr[0]
    if m["col"] is None:
        if arr.shape[1] == 1:
            return arr[:, 0]
        raise ImportSpecError(f"{path}: channel {name!r} is a {arr.shape[0]} x {arr.shape[1]} matrix; "
                              f"name a column, e.g. {m['path']}[0]")
    col = int(m["col"])
    if col >= arr.shape[1]:
        raise ImportSpecError(f"{path}: channel {name!r}: column {col} of a {arr.shape[0]} x {arr.shape[1]} "
                              "matrix; expected a column index from 0")
    return arr[:, col]


def _tdms(path: Path, names: list[str], group: str | None) -> dict[str, Channel]:
    try:
        from nptdms import TdmsFile
    except ImportError:
        raise ImportSpecError(f"{path}: reading TDMS needs the npTDMS package (pip install npTDMS)") from None
    f = TdmsFile.read(path)
    groups = [group] if group is not None else [g.name for g in f.groups()]
    if group is not None and group not in [g.name for g in f.groups()]:
        raise ImportSpecError(f"{path}: TDMS group {group!r} not found; the file has "
                              f"{', '.join(repr(g.name) for g in f.groups())}")
    out = {}
    for n in names:
        hits = [f[g][n] for g in groups if n in [c.name for c in f[g].channels()]]
        if not hits:
            raise _missing(path, n, [c.name for g in groups for c in f[g].channels()],
                           f" in group {group!r}" if group else "")
        if len(hits) > 1:
            raise ImportSpecError(f"{path}: channel {n!r} is in {len(hits)} groups; set group in the spec")
        ch = hits[0]
        inc = ch.properties.get("wf_increment")
        fs = 1.0 / float(inc) if inc else None
        out[n] = Channel(n, np.asarray(ch[:], dtype=np.float64), fs)
    return out


def _mdf(path: Path, names: list[str]) -> dict[str, Channel]:
    try:
        from asammdf import MDF
    except ImportError:
        raise ImportSpecError(f"{path}: reading MDF needs the asammdf package (pip install asammdf)") from None
    out = {}
    with MDF(path) as mdf:
        avail = list(mdf.channels_db)
        for n in names:
            if n not in mdf.channels_db:
                raise _missing(path, n, avail)
            sig = mdf.get(n)
            t = np.asarray(sig.timestamps, dtype=np.float64)
            fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else None
            out[n] = Channel(n, np.asarray(sig.samples, dtype=np.float64), fs)
    return out
