"""A twin campaign written out as a laboratory hands its recordings over, with the import spec
that brings them back (``twin import``): the owner's path, end to end, where the right answers
are known.

Phase I captures (one file each) and Phase II runs (one file each) in the lab's own channel
names and units (rpm, N·m, mV at 100 mV/g, g, deg/s, mm), the hours in the file names, in one of
the formats the importer reads:

- ``csv``: a vendor export: a preamble of key/value lines, a header line, ``;`` as the
  separator and ``,`` as the decimal mark (European locale), a time column;
- ``tdms``: NI TDMS, the rate in each channel's ``wf_increment``, accelerometers in mV;
- ``mat``: MATLAB v5, a struct ``daq`` with an n × 3 matrix per sensor, the rate in the spec;
- ``mdf``: ASAM MDF 4 (asammdf), the rate from the time stamps, the hours from a table.

``truth.h5`` stays with the campaign, aside.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.dataset import open_measurements

G = 9.80665
SENS_MV_PER_G = 100.0
FORMATS = ("csv", "tdms", "mat", "mdf")
_EXT = {"csv": "csv", "tdms": "tdms", "mat": "mat", "mdf": "mf4"}


def _phase1_channels(c) -> dict[str, tuple[np.ndarray, str]]:
    chans = {"Motor speed": (c.speed * 60 / (2 * np.pi), "rpm"), "Motor torque": (c.torque, "Nm")}
    for acc, label in ((c.acc1, "Nut A"), (c.acc2, "Nut B")):
        for j, ax in enumerate("XYZ"):
            chans[f"{label} {ax}"] = (acc[:, j] / G * SENS_MV_PER_G, "mV")
    return chans


def _phase2_channels(run) -> dict[str, tuple[np.ndarray, str]]:
    if not run.imu_acc_fs_hz == run.imu_gyro_fs_hz == run.position_cmd_fs_hz:
        raise ValueError("lab export: the IMU's channels and position_cmd must share one clock")
    n = min(len(run.imu_acc), len(run.imu_gyro), len(run.position_cmd))
    chans = {}
    for j, ax in enumerate("XYZ"):
        chans[f"Acc {ax}"] = (run.imu_acc[:n, j] / G, "g")
    for j, ax in enumerate("XYZ"):
        chans[f"Gyro {ax}"] = (np.rad2deg(run.imu_gyro[:n, j]), "deg/s")
    chans["Position"] = (run.position_cmd[:n] * 1e3, "mm")
    return chans


def _write(path: Path, fmt: str, chans: dict[str, tuple[np.ndarray, str]], fs: float, group: str) -> None:
    if fmt == "csv":
        n = len(next(iter(chans.values()))[0])
        cols = {"Time [s]": np.arange(n) / fs, **{f"{k} [{u}]": v for k, (v, u) in chans.items()}}
        lines = ["Vendor;AcmeDAQ 4.2", f"Sample rate;{fs:g} Hz".replace(".", ","), "Operator;lab", "",
                 ";".join(cols)]
        data = np.column_stack(list(cols.values()))
        body = "\n".join(";".join(f"{x:.10g}".replace(".", ",") for x in row) for row in data)
        path.write_text("\n".join(lines) + "\n" + body + "\n", encoding="utf-8")
    elif fmt == "tdms":
        from nptdms import ChannelObject, TdmsWriter

        with TdmsWriter(path) as w:
            w.write_segment([ChannelObject(group, k, np.asarray(v, np.float64),
                                           properties={"wf_increment": 1.0 / fs, "unit_string": u})
                             for k, (v, u) in chans.items()])
    elif fmt == "mat":
        from scipy.io import savemat

        daq: dict[str, np.ndarray] = {}
        for k, (v, _) in chans.items():
            daq[k.replace(" ", "_")] = np.asarray(v, np.float64)
        savemat(path, {"daq": daq})
    elif fmt == "mdf":
        from asammdf import MDF, Signal

        n = len(next(iter(chans.values()))[0])
        t = np.arange(n) / fs
        mdf = MDF(version="4.10")
        mdf.append([Signal(np.asarray(v, np.float64), t, name=k.replace(" ", "_"), unit=u)
                    for k, (v, u) in chans.items()])
        mdf.save(path, overwrite=True)
        mdf.close()
    else:
        raise ValueError(f"lab export: format {fmt!r}; expected one of {', '.join(FORMATS)}")


def _channel_specs(fmt: str, phase: str) -> str:
    """The ``[<phase>.channels]`` lines of the import spec for files written by :func:`_write`."""
    def name(k: str, u: str) -> str:
        if fmt == "csv":
            return f"{k} [{u}]"
        if fmt == "tdms":
            return k
        if fmt == "mat":
            return "daq." + k.replace(" ", "_")
        return k.replace(" ", "_")

    def three(label: str, u: str) -> str:
        return "[" + ", ".join(f'"{name(f"{label} {ax}", u)}"' for ax in "XYZ") + "]"

    if phase == "phase1":
        return "\n".join([
            f'speed = {{ channel = "{name("Motor speed", "rpm")}", unit = "rpm" }}',
            f'torque = {{ channel = "{name("Motor torque", "Nm")}", unit = "Nm" }}',
            f'acc1 = {{ channels = {three("Nut A", "mV")}, unit = "mV", sensitivity_mV_per_g = {SENS_MV_PER_G:g} }}',
            f'acc2 = {{ channels = {three("Nut B", "mV")}, unit = "mV", sensitivity_mV_per_g = {SENS_MV_PER_G:g} }}'])
    return "\n".join([
        f'imu_acc = {{ channels = {three("Acc", "g")}, unit = "g" }}',
        f'imu_gyro = {{ channels = {three("Gyro", "deg/s")}, unit = "deg/s" }}',
        f'position_cmd = {{ channel = "{name("Position", "mm")}", unit = "mm" }}'])


def export(campaign: str | Path, lab: str | Path, *, phase1_format: str = "tdms",
           phase2_format: str = "csv") -> Path:
    """Write ``lab/phase1/*`` and ``lab/phase2/*`` in the formats given and ``lab/import.toml``
    (the spec, with the axis description of the campaign's ``/@axis``; output ``campaign``);
    returns the spec's path."""
    campaign, lab = Path(campaign), Path(lab)
    for fmt in (phase1_format, phase2_format):
        if fmt not in FORMATS:
            raise ValueError(f"lab export: format {fmt!r}; expected one of {', '.join(FORMATS)}")
    (lab / "phase1").mkdir(parents=True, exist_ok=True)
    (lab / "phase2").mkdir(parents=True, exist_ok=True)
    tables: dict[str, list[tuple[str, float]]] = {"phase1": [], "phase2": []}
    fs1 = fs2 = None
    with open_measurements(campaign / "measurements.h5") as m:
        axis = m.axis()
        for name in m.phase1_captures():
            c = m.phase1(name)
            fs1 = float(c.fs_hz)
            p = lab / "phase1" / f"capture_{c.hours:08.2f}h_{c.sample:03d}_{name[-3:]}.{_EXT[phase1_format]}"
            _write(p, phase1_format, _phase1_channels(c), fs1, "Capture")
            tables["phase1"].append((p.name, float(c.hours)))
        for si, s in enumerate(m.phase2_sessions()):
            for ri, r in enumerate(m.phase2_runs(s)):
                run = m.phase2(s, r)
                fs2 = float(run.imu_acc_fs_hz)
                p = lab / "phase2" / f"S{si + 1:02d}_{run.hours:g}h_run{ri + 1:02d}.{_EXT[phase2_format]}"
                _write(p, phase2_format, _phase2_channels(run), fs2, "IMU")
                tables["phase2"].append((p.name, float(run.hours)))
    parts = ["spec_version = 1", f'output = "{campaign.resolve()}"', "", _axis_toml(axis)]
    for phase, fmt, fs, pattern in (
            ("phase1", phase1_format, fs1, r"capture_(?P<hours>[0-9.]+)h_(?P<sample>\d+)_"),
            ("phase2", phase2_format, fs2, r"S(?P<session>\d+)_(?P<hours>[0-9.]+)h_run(?P<run>\d+)")):
        if fs is None:
            continue
        lines = [f"[{phase}]", f'files = "{phase}/*.{_EXT[fmt]}"']
        if fmt == "mdf":  # the hours from a table, the session and run from the name
            table = lab / f"{phase}_hours.csv"
            table.write_text("file,hours\n" + "".join(f"{f},{h!r}\n" for f, h in tables[phase]), encoding="utf-8")
            lines.append(f'hours_table = {{ file = "{table.name}" }}')
            lines.append(f"name_pattern = '{pattern.replace('(?P<hours>[0-9.]+)', '[0-9.]+')}'")
        else:
            lines.append(f"name_pattern = '{pattern}'")
        if fmt == "csv":
            lines += ['delimiter = ";"', 'decimal = ","', "header_line = 5", 'time_channel = "Time [s]"']
        elif fmt == "tdms":
            lines.append(f'group = "{"Capture" if phase == "phase1" else "IMU"}"')
        elif fmt == "mat":
            lines.append(f"fs_hz = {fs!r}")
        lines += [f"[{phase}.channels]", _channel_specs(fmt, phase), ""]
        parts.append("\n".join(lines))
    spec = lab / "import.toml"
    spec.write_text("\n".join(parts), encoding="utf-8")
    return spec


def _axis_toml(axis: dict) -> str:
    """The ``[axis]`` table of the spec from an ``/@axis`` dict (nested tables for the nested
    dicts)."""
    import json

    def val(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float)):
            return repr(v)
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        raise TypeError(type(v))

    out: list[str] = []

    def table(name: str, d: dict) -> None:
        out.append(f"[{name}]")
        subs = []
        for k, v in d.items():
            if v is None:
                continue
            if isinstance(v, dict):
                subs.append((f"{name}.{k}", v))
            else:
                out.append(f"{k} = {val(v)}")
        out.append("")
        for n, d2 in subs:
            table(n, d2)

    table("axis", {k: v for k, v in axis.items() if k != "axis_version"})
    return "\n".join(out)


__all__ = ["FORMATS", "export"]
