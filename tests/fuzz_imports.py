"""A laboratory's recordings and their import spec, written small, and the ways they get damaged,
for the importer fuzz (tests/test_fuzz_import.py).

:func:`build_lab` writes four Phase II runs (two sessions of two) of 60 samples in one of five
forms: ``csv`` (comma, decimal point, hours in the file name), ``csv_eu`` (vendor CSV: semicolon,
decimal comma, a preamble line with the hour meter above the header), ``tdms`` (hours from a file
property), ``mat`` (MATLAB v5, hours from a per-session table with a semicolon), ``mdf`` (hours
from a per-file table). :data:`FILE_MUTATIONS` damage one data file, :data:`SPEC_MUTATIONS` the
spec. Every draw comes from the generator given.

Not mutated, because nothing in the file can tell them from a measurement: bytes flipped inside
the samples of a format without checksums (TDMS, MAT v5, MDF data blocks), plausible values
changed (a spike of a few g), columns swapped under their names.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

N = 60
FS = 200.0
NAMES = ("ax", "ay", "az", "gx", "gy", "gz", "pos")
KINDS = ("csv", "csv_eu", "tdms", "mat", "mdf")
RUNS = [("1", "1"), ("1", "2"), ("2", "1"), ("2", "2")]
HOURS = {"1": 120.0, "2": 480.5}
EXT = {"csv": "csv", "csv_eu": "csv", "tdms": "tdms", "mat": "mat", "mdf": "mf4"}


def lab_run(seed: int) -> dict[str, np.ndarray]:
    """One run in the lab's units: acc in g (gravity on z), gyro in deg/s, position in mm."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / FS
    out = {"t": t, "pos": 100 * (1 - np.cos(np.pi * t / t[-1]))}
    for j, ax in enumerate("xyz"):
        out[f"a{ax}"] = rng.normal(0, 1e-3, N) + (1.0 if j == 2 else 0.0)
        out[f"g{ax}"] = rng.normal(0, 0.05, N)
    return out


def _csv_text(d: dict, sep: str, dec: str, preamble: str = "") -> str:
    rows = np.column_stack([d["t"], *(d[k] for k in NAMES)])
    lines = [sep.join(["time", *NAMES])]
    lines += [sep.join(f"{v:.12g}".replace(".", dec) for v in row) for row in rows]
    return preamble + "\n".join(lines) + "\n"


def _spec(kind: str) -> str:
    head = 'spec_version = 1\noutput = "out"\n[axis]\nlead_mm = 16.0\ntravel_mm = 300.0\n[phase2]\n'
    pattern = "name_pattern = 'S(?P<session>\\d+)_(?P<hours>[0-9.]+)h_r(?P<run>\\d+)'\n"
    pattern_no_hours = "name_pattern = 'S(?P<session>\\d+)_[0-9.]+h_r(?P<run>\\d+)'\n"
    names = {k: (f"daq.{k}" if kind == "mat" else k) for k in NAMES}
    body = {
        "csv": f'files = "runs/*.csv"\n{pattern}time_channel = "time"\n',
        "csv_eu": (f'files = "runs/*.csv"\n{pattern_no_hours}delimiter = ";"\ndecimal = ","\nheader_line = 2\n'
                   'time_channel = "time"\nhours_property = "Operating hours"\n'),
        "tdms": f'files = "runs/*.tdms"\n{pattern_no_hours}group = "IMU"\nhours_property = "Operating hours"\n',
        "mat": (f'files = "runs/*.mat"\n{pattern_no_hours}fs_hz = {FS}\n'
                'hours_table = { file = "sessions.csv", key = "session", key_column = "Session", '
                'hours_column = "Hours", decimal = "," }\n'),
        "mdf": f'files = "runs/*.mf4"\n{pattern_no_hours}hours_table = {{ file = "hours.csv" }}\n',
    }[kind]
    channels = (f'[phase2.channels]\nimu_acc = {{ channels = ["{names["ax"]}", "{names["ay"]}", "{names["az"]}"], '
                f'unit = "g" }}\nimu_gyro = {{ channels = ["{names["gx"]}", "{names["gy"]}", "{names["gz"]}"], '
                f'unit = "deg/s" }}\nposition_cmd = {{ channel = "{names["pos"]}", unit = "mm" }}\n')
    return head + body + channels


def build_lab(root: Path, kind: str) -> tuple[Path, list[Path]]:
    """Write the lab's four run files and its spec under ``root``; (spec path, run files)."""
    runs = root / "runs"
    runs.mkdir(parents=True)
    files = []
    for i, (s, r) in enumerate(RUNS):
        d = lab_run(i + 1)
        p = runs / f"S{s}_{HOURS[s]:g}h_r{r}.{EXT[kind]}"
        if kind == "csv":
            p.write_text(_csv_text(d, ",", "."))
        elif kind == "csv_eu":
            p.write_text(_csv_text(d, ";", ",", f"Operating hours;{HOURS[s]:g}".replace(".", ",") + "\n"))
        elif kind == "tdms":
            from nptdms import ChannelObject, RootObject, TdmsWriter

            with TdmsWriter(p) as w:
                w.write_segment([RootObject(properties={"Operating hours": HOURS[s]}),
                                 *(ChannelObject("IMU", k, d[k], properties={"wf_increment": 1 / FS})
                                   for k in NAMES)])
        elif kind == "mat":
            from scipy.io import savemat

            savemat(p, {"daq": {k: d[k] for k in NAMES}})
        else:
            from asammdf import MDF, Signal

            mdf = MDF(version="4.10")
            mdf.append([Signal(d[k], d["t"], name=k) for k in NAMES])
            mdf.save(p, overwrite=True)
            mdf.close()
        files.append(p)
    if kind == "mat":
        (root / "sessions.csv").write_text("Session;Hours\n1;120\n2;480,5\n")
    if kind == "mdf":
        (root / "hours.csv").write_text("file,hours\n" + "".join(f"{p.name},{HOURS[s]:g}\n"
                                                                 for p, (s, _) in zip(files, RUNS, strict=True)))
    spec = root / "import.toml"
    spec.write_text(_spec(kind))
    return spec, files


# --- mutations of one data file: (path, rng) -> description ----------------------------------------
def _pick(rng, items):
    return items[int(rng.integers(len(items)))]


def truncate(path: Path, rng) -> str:
    data = path.read_bytes()
    n = int(rng.integers(0, len(data)))
    path.write_bytes(data[:n])
    return f"cut to {n} of {len(data)} bytes"


def cut_at_line_end(path: Path, rng) -> str:
    lines = path.read_text().splitlines(keepends=True)
    k = int(rng.integers(3, len(lines)))
    path.write_text("".join(lines[:k]))
    return f"cut after line {k} of {len(lines)}"


def delete_line(path: Path, rng) -> str:
    lines = path.read_text().splitlines(keepends=True)
    k = int(rng.integers(len(lines) // 3, len(lines) - 1))
    del lines[k]
    path.write_text("".join(lines))
    return f"line {k + 1} deleted"


CELLS = ["abc", "", "1.2.3", "--", "nan", "inf", "-inf", "1e400", "0x10", "1e30", "-1e30", "#"]


def garble_cell(path: Path, rng) -> str:
    text = path.read_text()
    sep = ";" if ";" in text.splitlines()[-1] else ","
    lines = text.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("time"))
    k = int(rng.integers(first + 1, len(lines)))
    cells = lines[k].split(sep)
    j = int(rng.integers(len(cells)))
    new = _pick(rng, CELLS)
    if sep == ";":
        new = new.replace(".", ",")
    cells[j] = new
    lines[k] = sep.join(cells)
    path.write_text("\n".join(lines) + "\n")
    return f"line {k + 1} cell {j} = {new!r}"


def header_edit(path: Path, rng) -> str:
    lines = path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("time"))
    sep = ";" if ";" in lines[k] else ","
    names = lines[k].split(sep)
    j = int(rng.integers(len(names)))
    kind = _pick(rng, ["rename", "duplicate", "drop", "spaces", "case"])
    if kind == "rename":
        names[j] = names[j] + "_x"
    elif kind == "duplicate":
        names[j] = names[(j + 1) % len(names)]
    elif kind == "drop":
        del names[j]
    elif kind == "spaces":
        names[j] = f"  {names[j]}  "
    else:
        names[j] = names[j].upper()
    lines[k] = sep.join(names)
    path.write_text("\n".join(lines) + "\n")
    return f"header {kind} column {j}"


def line_delimiter(path: Path, rng) -> str:
    lines = path.read_text().splitlines()
    sep = ";" if ";" in lines[-1] else ","
    k = int(rng.integers(len(lines) // 2, len(lines)))
    lines[k] = lines[k].replace(sep, _pick(rng, ["\t", " ", "|", ",;"]))
    path.write_text("\n".join(lines) + "\n")
    return f"line {k + 1} with another delimiter"


def repeat_time(path: Path, rng) -> str:
    lines = path.read_text().splitlines()
    sep = ";" if ";" in lines[-1] else ","
    k = int(rng.integers(len(lines) // 2, len(lines) - 1))
    cells = lines[k + 1].split(sep)
    cells[0] = lines[k].split(sep)[0]
    lines[k + 1] = sep.join(cells)
    path.write_text("\n".join(lines) + "\n")
    return f"line {k + 2} repeats the time of line {k + 1}"


def junk(path: Path, rng) -> str:
    kind = _pick(rng, ["empty", "binary tail", "binary head", "bom", "no final newline", "blank lines"])
    data = path.read_bytes()
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "binary tail":
        path.write_bytes(data + rng.integers(0, 256, 40).astype(np.uint8).tobytes())
    elif kind == "binary head":
        path.write_bytes(rng.integers(0, 256, 40).astype(np.uint8).tobytes() + data)
    elif kind == "bom":
        path.write_bytes(b"\xef\xbb\xbf" + data)
    elif kind == "no final newline":
        path.write_bytes(data.rstrip(b"\n"))
    else:
        path.write_bytes(data.replace(b"\n", b"\n\n", 3))
    return kind


def flip_header_bytes(path: Path, rng) -> str:
    """Bytes flipped in the first 256 bytes: lead-in, metadata, identification blocks."""
    data = bytearray(path.read_bytes())
    k = int(rng.integers(1, 6))
    for i in rng.integers(0, min(256, len(data)), size=k):
        data[int(i)] ^= int(rng.integers(1, 256))
    path.write_bytes(bytes(data))
    return f"{k} bytes flipped in the first 256"


def _which(path: Path) -> tuple[int, str]:
    """(seed, session) of a run file written by :func:`build_lab`."""
    m = re.match(r"S(\d+)_[0-9.]+h_r(\d+)", path.name)
    return RUNS.index((m[1], m[2])) + 1, m[1]


def _rewrite(path: Path, kind: str, edit: Callable[[dict], dict], props: dict | None = None) -> None:
    """Write the run again in its format with ``edit`` applied to its channels {name: array}."""
    seed, session = _which(path)
    d = edit(lab_run(seed))
    if props is None:
        props = {"Operating hours": HOURS[session]}
    if kind == "tdms":
        from nptdms import ChannelObject, RootObject, TdmsWriter

        with TdmsWriter(path) as w:
            w.write_segment([RootObject(properties=props),
                             *(ChannelObject("IMU", k, v, properties={"wf_increment": 1 / FS})
                               for k, v in d.items() if k != "t")])
    elif kind == "mat":
        from scipy.io import savemat

        savemat(path, {"daq": {k: v for k, v in d.items() if k != "t"}})
    else:
        from asammdf import MDF, Signal

        mdf = MDF(version="4.10")
        for k, v in d.items():  # a group per channel: asammdf would resample a short one into a shared group
            if k != "t":
                mdf.append([Signal(np.asarray(v), np.arange(len(v)) / FS, name=k)])
        mdf.save(path, overwrite=True)
        mdf.close()


def _channel_edit(kind: str):
    def mutate(path: Path, rng) -> str:
        ch = _pick(rng, list(NAMES))
        how = _pick(rng, ["nan", "inf", "1e30", "drop", "rename", "short", "string", "2 columns"])
        if kind == "tdms" and how in ("string", "2 columns"):
            how = "short"
        if kind == "mdf" and how in ("string", "2 columns"):
            how = "rename"

        def edit(d):
            v = np.array(d[ch], dtype=float)
            if how == "nan":
                v[int(rng.integers(N))] = np.nan
            elif how == "inf":
                v[int(rng.integers(N))] = np.inf
            elif how == "1e30":
                v[int(rng.integers(N))] = 1e30
            elif how == "drop":
                return {k: x for k, x in d.items() if k != ch}
            elif how == "rename":
                return {(k + "_renamed" if k == ch else k): x for k, x in d.items()}
            elif how == "short":
                v = v[: N // 2]
            elif how == "string":
                return {**d, ch: "not numbers"}
            else:
                return {**d, ch: np.column_stack([v, v])}
            return {**d, ch: v}

        _rewrite(path, kind, edit)
        return f"channel {ch}: {how}"
    return mutate


def tdms_property(path: Path, rng) -> str:
    how = _pick(rng, ["no hours", "hours text", "negative hours", "rate x2", "no rate"])
    if how in ("rate x2", "no rate"):
        from nptdms import ChannelObject, RootObject, TdmsWriter

        seed, session = _which(path)
        d = lab_run(seed)
        with TdmsWriter(path) as w:
            w.write_segment([RootObject(properties={"Operating hours": HOURS[session]}),
                             *(ChannelObject("IMU", k, d[k], properties={} if how == "no rate" else
                                             {"wf_increment": 2 / FS}) for k in NAMES)])
        return how
    props = {"no hours": {}, "hours text": {"Operating hours": "a lot"},
             "negative hours": {"Operating hours": -5.0}}[how]
    _rewrite(path, "tdms", lambda d: d, props)
    return how


CSV_MUTATIONS = [truncate, cut_at_line_end, delete_line, garble_cell, header_edit, line_delimiter, repeat_time, junk]
FILE_MUTATIONS: dict[str, list] = {
    "csv": CSV_MUTATIONS,
    "csv_eu": CSV_MUTATIONS,
    "tdms": [truncate, flip_header_bytes, _channel_edit("tdms"), tdms_property],
    "mat": [truncate, flip_header_bytes, _channel_edit("mat")],
    "mdf": [truncate, flip_header_bytes, _channel_edit("mdf")],
}


# --- mutations of the spec: (spec text, rng) -> (text, description) --------------------------------
def spec_delete_line(text: str, rng) -> tuple[str, str]:
    lines = text.splitlines()
    k = int(rng.integers(len(lines)))
    return "\n".join(lines[:k] + lines[k + 1:]) + "\n", f"spec line {k + 1} ({lines[k][:30]!r}) deleted"


BAD_VALUES = ['"x"', "-1", "0", "[]", "true", "1e400", '"mV"', "{}", '"(?P<"', '"runs/nothing*.csv"']


def spec_bad_value(text: str, rng) -> tuple[str, str]:
    lines = text.splitlines()
    keyed = [i for i, line in enumerate(lines) if re.match(r"^\w+ = ", line)]
    k = _pick(rng, keyed)
    key = lines[k].split(" = ")[0]
    v = _pick(rng, BAD_VALUES)
    lines[k] = f"{key} = {v}"
    return "\n".join(lines) + "\n", f"spec {key} = {v}"


def spec_channel(text: str, rng) -> tuple[str, str]:
    how = _pick(rng, ["unit", "name", "columns", "unknown channel"])
    if how == "unit":
        return text.replace('unit = "deg/s"', 'unit = "furlong"'), "unit furlong"
    if how == "name":
        return text.replace('"ay"', '"Acc Y"').replace('"daq.ay"', '"daq.acc_y"'), "channel name changed"
    if how == "columns":
        return re.sub(r'imu_gyro = \{ channels = \[([^,]+), [^,]+, ([^\]]+)\]', r'imu_gyro = { channels = [\1, \2]',
                      text), "two of three columns"
    return text.replace("position_cmd =", "position_mm ="), "unknown format channel"


def spec_garbage(text: str, rng) -> tuple[str, str]:
    how = _pick(rng, ["not toml", "duplicate key", "version 2", "no phase", "binary"])
    if how == "not toml":
        return text + "this is = = not toml\n", how
    if how == "duplicate key":
        return text.replace("lead_mm = 16.0", "lead_mm = 16.0\nlead_mm = 10.0"), how
    if how == "version 2":
        return text.replace("spec_version = 1", "spec_version = 2"), how
    if how == "no phase":
        return text.split("[phase2]")[0], how
    return "\x00\xff" + text, how


SPEC_MUTATIONS = [spec_delete_line, spec_bad_value, spec_channel, spec_garbage]
