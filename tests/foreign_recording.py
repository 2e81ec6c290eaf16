"""Export a twin campaign as a laboratory would hand it over (issue 14's acceptance run):
Phase I captures as NI TDMS files and Phase II runs as CSV (or TDMS) files, with the lab's own
channel names and units (rpm, N·m, mV at 100 mV/g, g, deg/s, mm) and the hours in the file
names, none of them in the project's format. ``truth.h5`` stays with the campaign, aside.

Used by tests/test_import.py and by hand::

    python tests/foreign_recording.py CAMPAIGN LAB_DIR
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

G = 9.80665
SENS_MV_PER_G = 100.0


def export(campaign: Path, lab: Path, *, phase2_format: str = "csv") -> Path:
    """Write ``lab/phase1/*.tdms`` and ``lab/phase2/*.csv`` (or ``*.tdms``); returns ``lab``."""
    from nptdms import ChannelObject, TdmsWriter

    from analysis.dataset import open_measurements

    (lab / "phase1").mkdir(parents=True, exist_ok=True)
    (lab / "phase2").mkdir(parents=True, exist_ok=True)
    with open_measurements(campaign / "measurements.h5") as m:
        for name in m.phase1_captures():
            c = m.phase1(name)
            chans = {"Motor speed": (c.speed * 60 / (2 * np.pi), "rpm"), "Motor torque": (c.torque, "Nm")}
            for acc, label in ((c.acc1, "Nut A"), (c.acc2, "Nut B")):
                for j, ax in enumerate("XYZ"):
                    chans[f"{label} {ax}"] = (acc[:, j] / G * SENS_MV_PER_G, "mV")
            path = lab / "phase1" / f"capture_{c.hours:08.2f}h_{c.sample:03d}_{name[-3:]}.tdms"
            with TdmsWriter(path) as w:
                w.write_segment([ChannelObject("Capture", k, v.astype(np.float64),
                                               properties={"wf_increment": 1.0 / c.fs_hz, "unit_string": u})
                                 for k, (v, u) in chans.items()])
        for si, s in enumerate(m.phase2_sessions()):
            for ri, r in enumerate(m.phase2_runs(s)):
                run = m.phase2(s, r)
                assert run.imu_acc_fs_hz == run.imu_gyro_fs_hz == run.position_cmd_fs_hz, "one lab clock"
                n = min(len(run.imu_acc), len(run.imu_gyro), len(run.position_cmd))
                cols = {"Time [s]": np.arange(n) / run.imu_acc_fs_hz}
                for j, ax in enumerate("XYZ"):
                    cols[f"Acc {ax} [g]"] = run.imu_acc[:n, j] / G
                for j, ax in enumerate("XYZ"):
                    cols[f"Gyro {ax} [deg/s]"] = np.rad2deg(run.imu_gyro[:n, j])
                cols["Position [mm]"] = run.position_cmd[:n] * 1e3
                stem = f"S{si + 1:02d}_{run.hours:g}h_run{ri + 1:02d}"
                if phase2_format == "csv":
                    data = np.column_stack(list(cols.values()))
                    np.savetxt(lab / "phase2" / f"{stem}.csv", data, delimiter=",", fmt="%.10g",
                               header=",".join(cols), comments="")
                else:
                    with TdmsWriter(lab / "phase2" / f"{stem}.tdms") as w:
                        inc = {"wf_increment": 1.0 / run.imu_acc_fs_hz}
                        w.write_segment([ChannelObject("IMU", k, v, properties=inc)
                                         for k, v in cols.items() if k != "Time [s]"])
    return lab


if __name__ == "__main__":
    export(Path(sys.argv[1]), Path(sys.argv[2]))
