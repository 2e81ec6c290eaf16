"""Is a recording laid out as the scenario describes? The diagnosis compares statistic by
statistic, so the recording must have the scenario's Phase I samples and captures, its Phase II
sessions and runs, every channel, and the same sampling rates and motion speeds. A recording
that differs is refused with every difference named (resampling would change the statistics
the twin is judged on: spectra up to the Nyquist frequency, the sensors' anti-aliasing).
"""

from __future__ import annotations

from pathlib import Path

from analysis.dataset import DatasetError, open_measurements

RATE_TOLERANCE = 1e-3  # relative
SCENARIO_RATE_KEYS = {"imu_acc": "sensors.imu_acc_fs_hz", "imu_gyro": "sensors.imu_gyro_fs_hz",
                      "position_cmd": "sensors.position_cmd_fs_hz"}


class LayoutError(DatasetError):
    """A recording that does not match the scenario; the message names every difference."""


def describe(path: str | Path) -> dict:
    """The layout of a ``measurements.h5``: ``phase1`` [[sample, [[capture, fs_hz, n], ...]], ...],
    ``phase2`` [[session, [[run, {channel: fs_hz}], ...]], ...] (JSON-able), and ``problems``:
    the items that could not be read (each message names file and item)."""
    out: dict = {"phase1": [], "phase2": [], "problems": []}
    with open_measurements(path) as m:
        samples: dict[int, list] = {}
        for name in m.phase1_captures():
            try:
                c = m.phase1(name)
            except DatasetError as e:
                out["problems"].append(str(e))
                continue
            samples.setdefault(c.sample, []).append([name, c.fs_hz, len(c.speed)])
        out["phase1"] = [[k, v] for k, v in sorted(samples.items())]
        for s in m.phase2_sessions():
            runs = []
            for r in m.phase2_runs(s):
                try:
                    run = m.phase2(s, r)
                except DatasetError as e:
                    out["problems"].append(str(e))
                    continue
                rates = {"imu_acc": run.imu_acc_fs_hz, "imu_gyro": run.imu_gyro_fs_hz}
                if run.position_cmd is not None:
                    rates["position_cmd"] = run.position_cmd_fs_hz
                runs.append([r, rates])
            out["phase2"].append([s, runs])
    return out


def compare(real_path: str | Path, twin: dict) -> None:
    """Raise :class:`LayoutError` unless the recording ``real_path`` (a measurements.h5) has the
    layout ``twin`` (:func:`describe` of the scenario simulated once)."""
    real = describe(real_path)
    problems: list[str] = list(real["problems"])
    r1, t1 = real["phase1"], twin["phase1"]
    if len(r1) != len(t1):
        problems.append(f"{real_path}: {len(r1)} Phase I sample(s); the scenario has {len(t1)}")
    for (sr, caps_r), (_, caps_t) in zip(r1, t1, strict=False):
        if len(caps_r) != len(caps_t):
            problems.append(f"{real_path}: Phase I sample {sr} has {len(caps_r)} capture(s); "
                            f"the scenario has {len(caps_t)}")
        for (name, fs, n), (_, fs_t, n_t) in zip(caps_r, caps_t, strict=False):
            if abs(fs - fs_t) > RATE_TOLERANCE * fs_t:
                problems.append(f"{real_path}: /phase1/{name} is sampled at {fs:g} Hz; the "
                                f"scenario's channels are at {fs_t:g} Hz (phase1.fs_hz)")
            elif abs(n - n_t) > 0.01 * n_t:
                problems.append(f"{real_path}: /phase1/{name} has {n} samples "
                                f"({n / fs:g} s); the scenario's captures have {n_t} "
                                f"({n_t / fs_t:g} s, phase1.capture_s)")
    r2, t2 = real["phase2"], twin["phase2"]
    if len(r2) != len(t2):
        problems.append(f"{real_path}: {len(r2)} Phase II session(s); the scenario has {len(t2)}")
    rate_issues: dict[tuple[str, float, float], list[str]] = {}
    for (sr, runs_r), (_, runs_t) in zip(r2, t2, strict=False):
        if len(runs_r) != len(runs_t):
            problems.append(f"{real_path}: Phase II session {sr} has {len(runs_r)} run(s); "
                            f"the scenario has {len(runs_t)}")
        for (rn, rates), (_, rates_t) in zip(runs_r, runs_t, strict=False):
            for ch, fs in rates.items():
                if abs(fs - rates_t[ch]) > RATE_TOLERANCE * rates_t[ch]:
                    rate_issues.setdefault((ch, fs, rates_t[ch]), []).append(f"/phase2/{sr}/{rn}/{ch}")
    for (ch, fs, fs_t), where in rate_issues.items():
        more = f" (and {len(where) - 1} more run(s))" if len(where) > 1 else ""
        problems.append(f"{real_path}: {where[0]} is sampled at {fs:g} Hz{more}; the scenario "
                        f"has {fs_t:g} Hz ({SCENARIO_RATE_KEYS[ch]})")
    if problems:
        shown = problems[:8] + ([f"... and {len(problems) - 8} more"] if len(problems) > 8 else [])
        raise LayoutError("the recording does not match the scenario, so it cannot be compared "
                          "statistic by statistic (fix the scenario, e.g. with --set, or the "
                          "recording): " + "; ".join(shown))
