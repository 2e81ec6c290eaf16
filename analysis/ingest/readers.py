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

A CSV line with fewer columns than the header is refused as cut (naming the line); a file whose
last line has no line end is imported with a warning (its last values may be cut mid-number).

:func:`read_property` reads one value a file states about itself (the hour meter): a TDMS file or
group property, a MAT variable, an MDF header field (``<e name="...">`` of the header comment's
``common_properties``, or ``author``, ``department``, ``project``, ``subject``), or a ``name;value``
line above a CSV header. :func:`start_time` reads when a file was recorded (TDMS
``wf_start_time``, the MDF header's start time).
"""

from __future__ import annotations

import contextlib
import logging
import re
import sys
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
                  delimiter: str = ",", header_line: int = 1, decimal: str = ".",
                  warnings: list[str] | None = None) -> dict[str, Channel]:
    """The channels ``names`` of the file ``path`` (see the module's doc for the names); what is
    suspicious but readable is appended to ``warnings`` (a message naming the file and line)."""
    kind = reader_for(path, reader)
    if not path.is_file():
        raise ImportSpecError(f"{path}: no such file")
    names = list(dict.fromkeys(names))
    warnings = [] if warnings is None else warnings
    try:
        if kind == "csv":
            return _csv(path, names, delimiter, header_line, decimal, warnings)
        if kind == "mat":
            return _mat(path, names)
        if kind == "tdms":
            return _tdms(path, names, group, warnings)
        return _mdf(path, names)
    except ImportSpecError:
        raise
    except Exception as e:  # noqa: BLE001 - a third-party parser on a damaged file raises anything
        raise ImportSpecError(f"{path}: not a readable {kind.upper()} file ({type(e).__name__}: {e})") from None


def _missing(path: Path, name: str, available, where: str = "") -> ImportSpecError:
    avail = sorted(str(a) for a in available)
    shown = ", ".join(repr(a) for a in avail[:12]) + (f", ... ({len(avail)} in all)" if len(avail) > 12 else "")
    return ImportSpecError(f"{path}: channel {name!r} not found{where}; the file has {shown or 'no channels'}")


def _cut_lines(path: Path, delimiter: str, header_line: int, n_columns: int, warnings: list[str]) -> None:
    """Refuse a data line with fewer fields than the header's ``n_columns`` (a file cut mid-line,
    or a line lost in the middle), naming it; warn when the last line has no line end."""
    raw = path.read_bytes()
    lines = raw.decode("utf-8-sig", errors="replace").splitlines()
    data = [(i + 1, line) for i, line in enumerate(lines[header_line:], start=header_line) if line.strip()]
    if not data or len(delimiter) != 1:
        return
    counts = np.array([line.count(delimiter) + 1 for _, line in data])
    short = np.flatnonzero(counts < n_columns)
    last_no_end = not raw.endswith((b"\n", b"\r"))
    if short.size:
        k = int(short[0])
        no, line = data[k]
        if k == len(data) - 1:
            end = " and no line end" if last_no_end else ""
            raise ImportSpecError(f"{path}: line {no} is cut: it has {counts[k]} of the header's {n_columns} "
                                  f"columns{end}, the last line of the file (a copy or recording cut short?); "
                                  f"expected {n_columns} columns")
        raise ImportSpecError(f"{path}: line {no} has {counts[k]} of the header's {n_columns} columns "
                              f"({line[:60]!r}); expected {n_columns} columns on every line")
    if last_no_end:
        warnings.append(f"{path}: line {data[-1][0]} (the last) has no line end: the file may be cut "
                        "mid-number; its values were kept")


def _csv(path: Path, names: list[str], delimiter: str, header_line: int, decimal: str,
         warnings: list[str]) -> dict[str, Channel]:
    import pandas as pd

    kw = dict(sep=delimiter, skiprows=header_line - 1, decimal=decimal, skipinitialspace=True,
              encoding="utf-8-sig", engine="c" if len(delimiter) == 1 else "python")
    header = pd.read_csv(path, nrows=0, **kw).columns
    header = [str(c).strip() for c in header]
    for n in names:
        if n not in header:
            raise _missing(path, n, header, f" in the header (line {header_line})")
    _cut_lines(path, delimiter, header_line, len(header), warnings)
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
    from scipy.io import loadmat, whosmat

    _mat_sizes(path, whosmat(path))
    data = loadmat(path, squeeze_me=False, struct_as_record=True, simplify_cells=True)
    top = [k for k in data if not k.startswith("__")]
    return {n: Channel(n, _mat_pick(path, n, lambda parts: _dict_get(data, parts), top)) for n in names}


#: A MAT v5 variable may declare at most this many bytes per byte of the file (MATLAB's v7
#: compression of constant data reaches a few hundred); beyond, the header is damaged.
MAT_EXPANSION = 2000


def _mat_sizes(path: Path, variables: list[tuple[str, tuple, str]]) -> None:
    """Refuse a MAT file whose variables declare more data than the file can hold (a damaged
    header), before loading them: (name, shape, class) from ``scipy.io.whosmat``."""
    limit = MAT_EXPANSION * max(path.stat().st_size, 1024)
    for name, shape, _ in variables:
        n = 8 * int(np.prod([max(int(d), 0) for d in shape], dtype=object))
        if n > limit:
            raise ImportSpecError(f"{path}: MAT variable {name!r} declares {' x '.join(map(str, shape))} values, "
                                  f"more than a {path.stat().st_size}-byte file holds (a damaged file?); expected "
                                  "a readable MAT file")


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


class _Collect(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def _from_asammdf(u) -> bool:
    tb, files = u.exc_traceback, []
    while tb is not None:
        files.append(tb.tb_frame.f_code.co_filename)
        tb = tb.tb_next
    return isinstance(u.exc_value, AttributeError) and any("asammdf" in f for f in files)


def _drop_asammdf_del_errors() -> None:
    """From the first MDF file read on: the ``AttributeError`` that asammdf's half-built ``MDF4``
    (a file it failed to open) raises in ``__del__`` whenever it is collected is dropped instead of
    printed as "Exception ignored ... Traceback" (the refusal already says what is wrong); every
    other unraisable exception goes to the hook that was in place. Installed for good, so a
    failed open needs no garbage collection of its own while a temporary hook is in place."""
    old_hook = sys.unraisablehook
    if getattr(old_hook, "drops_asammdf_del_errors", False):
        return

    def hook(u) -> None:
        if not _from_asammdf(u):
            old_hook(u)

    hook.drops_asammdf_del_errors = True
    sys.unraisablehook = hook


@contextlib.contextmanager
def _asammdf_quiet(path: Path):
    """asammdf on a damaged file: its log records are collected (not printed), its exception
    becomes an :class:`ImportSpecError` naming ``path``, and the ``AttributeError`` of its
    half-built ``MDF4`` is dropped (:func:`_drop_asammdf_del_errors`). Yields the collecting
    handler."""
    _drop_asammdf_del_errors()
    log, handler = logging.getLogger("asammdf"), _Collect()
    propagate = log.propagate
    log.addHandler(handler)
    log.propagate = False
    err = None
    try:
        yield handler
    except ImportSpecError:
        raise
    except Exception as e:  # noqa: BLE001 - asammdf on a damaged file raises anything
        err = f"{path}: not a readable MDF file ({type(e).__name__}: {e})"
    finally:
        log.removeHandler(handler)
        log.propagate = propagate
    if err is not None:
        raise ImportSpecError(err)


def _open_mdf(path: Path):
    """``asammdf.MDF(path)``, or :class:`ImportSpecError` naming the file; call it inside
    :func:`_asammdf_quiet`."""
    from asammdf import MDF

    try:
        return MDF(path)
    except Exception as e:  # noqa: BLE001 - asammdf on a damaged file raises anything
        msg = f"{path}: not a readable MDF file ({type(e).__name__}: {e})"
    raise ImportSpecError(msg)


#: npTDMS's warnings that mean the file ends before its segments do.
_TDMS_CUT = ("less data than expected", "metadata is incomplete", "not a multiple of the chunk size")


def _tdms(path: Path, names: list[str], group: str | None, warnings: list[str] | None = None) -> dict[str, Channel]:
    try:
        from nptdms import TdmsFile
    except ImportError:
        raise ImportSpecError(f"{path}: reading TDMS needs the npTDMS package (pip install npTDMS)") from None
    # npTDMS's modules log through their own stream handlers: collected here instead, and said in
    # a refusal or a warning
    log, handler = logging.getLogger("nptdms"), _Collect()
    own = {name: lg.handlers[:] for name, lg in logging.Logger.manager.loggerDict.items()
           if name.startswith("nptdms") and isinstance(lg, logging.Logger)}
    for name in own:
        logging.getLogger(name).handlers = []
    log.addHandler(handler)
    propagate, log.propagate = log.propagate, False
    try:
        f = TdmsFile.read(path)
    finally:
        log.removeHandler(handler)
        log.propagate = propagate
        for name, handlers in own.items():
            logging.getLogger(name).handlers = handlers
    cut = [m for m in handler.messages if any(k in m for k in _TDMS_CUT)]
    if cut:
        raise ImportSpecError(f"{path}: the TDMS file is cut short (npTDMS: {'; '.join(cut)}); expected whole "
                              "segments (an interrupted copy or recording?)")
    if warnings is not None:
        warnings.extend(f"{path}: npTDMS: {m}" for m in handler.messages)
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
        import asammdf  # noqa: F401 - only whether it is installed
    except ImportError:
        raise ImportSpecError(f"{path}: reading MDF needs the asammdf package (pip install asammdf)") from None
    out = {}
    with _asammdf_quiet(path), _open_mdf(path) as mdf:
        avail = list(mdf.channels_db)
        for n in names:
            if n not in mdf.channels_db:
                raise _missing(path, n, avail)
            sig = mdf.get(n)
            t = np.asarray(sig.timestamps, dtype=np.float64)
            fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else None
            out[n] = Channel(n, np.asarray(sig.samples, dtype=np.float64), fs)
    return out


def _number(path: Path, name: str, value, where: str, decimal: str = ".") -> float:
    """``value`` (a number, or text with ``decimal`` as decimal mark) as a float; else refused."""
    if isinstance(value, (bytes, np.bytes_)):
        value = value.decode(errors="replace")
    if isinstance(value, str):
        text = value.strip()
        try:
            return float(text.replace(decimal, ".") if decimal != "." else text)
        except ValueError:
            raise ImportSpecError(f"{path}: {where} {name!r} is {value!r}; expected a number of operating "
                                  "hours") from None
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiub" or arr.size != 1:
        raise ImportSpecError(f"{path}: {where} {name!r} is {value!r}; expected one number of operating hours")
    return float(arr.reshape(-1)[0])


def read_property(path: Path, name: str, *, reader: str | None = None, group: str | None = None,
                  delimiter: str = ",", header_line: int = 1, decimal: str = ".") -> tuple[float, str]:
    """The number the file ``path`` states under ``name`` (see the module's doc) and where it was
    found (for messages); :class:`ImportSpecError` naming the file, the name and what it has."""
    kind = reader_for(path, reader)
    if not path.is_file():
        raise ImportSpecError(f"{path}: no such file")
    try:
        if kind == "tdms":
            from nptdms import TdmsFile

            with TdmsFile.open(path) as f:
                if name in f.properties:
                    return _number(path, name, f.properties[name], "file property"), f"file property {name!r}"
                groups = [g for g in f.groups() if group is None or g.name == group]
                for g in groups:
                    if name in g.properties:
                        return (_number(path, name, g.properties[name], f"group {g.name!r} property"),
                                f"group {g.name!r} property {name!r}")
                have = sorted({*f.properties, *(k for g in groups for k in g.properties)})
            raise ImportSpecError(f"{path}: property {name!r} not found in the file's or its groups' properties; "
                                  f"the file has {', '.join(map(repr, have)) or 'no properties'}")
        if kind == "mat":
            ch = _mat(path, [name])[name]
            if ch.values.size != 1:
                raise ImportSpecError(f"{path}: MAT variable {name!r} has {ch.values.size} values; expected one "
                                      "number of operating hours")
            return float(ch.values[0]), f"MAT variable {name!r}"
        if kind == "mdf":
            return _mdf_header(path, name)
        return _csv_preamble(path, name, delimiter, header_line, decimal)
    except ImportSpecError:
        raise
    except Exception as e:  # noqa: BLE001 - a third-party parser on a damaged file raises anything
        raise ImportSpecError(f"{path}: not a readable {kind.upper()} file ({type(e).__name__}: {e})") from None


def _mdf_header(path: Path, name: str) -> tuple[float, str]:
    import xml.etree.ElementTree as ET


    with _asammdf_quiet(path), _open_mdf(path) as mdf:
        h = mdf.header
        fields = {k: getattr(h, k, None) for k in ("author", "department", "project", "subject")}
        comment = h.comment or ""
    props: dict[str, str] = {}
    if comment.lstrip().startswith("<"):
        try:
            root = ET.fromstring(comment)
            props = {e.get("name"): (e.text or "") for e in root.iter("e") if e.get("name")}
        except ET.ParseError:
            props = {}
    if name in props:
        return _number(path, name, props[name], "MDF header field"), f"MDF header field {name!r}"
    if fields.get(name):
        return _number(path, name, fields[name], "MDF header field"), f"MDF header field {name!r}"
    have = sorted([*props, *(k for k, v in fields.items() if v)])
    raise ImportSpecError(f"{path}: header field {name!r} not found; the MDF header has "
                          f"{', '.join(map(repr, have)) or 'no fields'}")


def _csv_preamble(path: Path, name: str, delimiter: str, header_line: int, decimal: str) -> tuple[float, str]:
    with open(path, encoding="utf-8", errors="replace") as f:
        above = [next(f, "") for _ in range(header_line - 1)]
    seen = []
    for i, line in enumerate(above, start=1):
        parts = re.split(f"{re.escape(delimiter)}|:|=", line.strip(), maxsplit=1)
        if len(parts) == 2:
            seen.append(parts[0].strip())
            if parts[0].strip() == name:
                return _number(path, name, parts[1].strip(), f"line {i}:", decimal), f"line {i} {name!r}"
    raise ImportSpecError(f"{path}: no line {name!r}{delimiter}value above the header (line {header_line}); "
                          f"the lines above it name {', '.join(map(repr, seen)) or 'nothing'}")


def start_time(path: Path, *, reader: str | None = None, group: str | None = None):
    """When the file says it was recorded (a timezone-aware ``datetime``, UTC if the file names
    no zone): TDMS ``wf_start_time`` of a channel of ``group``, or the MDF header's start time."""
    import datetime as dt

    kind = reader_for(path, reader)
    try:
        if kind == "tdms":
            from nptdms import TdmsFile

            with TdmsFile.open(path) as f:
                for g in f.groups():
                    if group is not None and g.name != group:
                        continue
                    for c in g.channels():
                        t = c.properties.get("wf_start_time")
                        if t is not None:
                            sec = (np.datetime64(t, "us") - np.datetime64(0, "us")) / np.timedelta64(1, "s")
                            return dt.datetime.fromtimestamp(float(sec), dt.UTC)
            raise ImportSpecError(f"{path}: no channel states its wf_start_time; expected a start time "
                                  "(or hours_clock.source = 'mtime')")
        if kind == "mdf":

            with _asammdf_quiet(path), _open_mdf(path) as mdf:
                t = mdf.header.start_time
            return t if t.tzinfo is not None else t.replace(tzinfo=dt.UTC)
    except ImportSpecError:
        raise
    except Exception as e:  # noqa: BLE001 - a third-party parser on a damaged file raises anything
        raise ImportSpecError(f"{path}: not a readable {kind.upper()} file ({type(e).__name__}: {e})") from None
    raise ImportSpecError(f"{path}: a {kind.upper()} file states no start time; use hours_clock.source = "
                          "'mtime' (the file's modification time) or another source of hours")
