"""The shipped sweeps' tables (docs/validation.md, "Sweeps"): both sweeps of ``scenarios/sweeps/``
run through ``twin sweep`` (the default executor, every core) into a fresh folder, then their
result tables summarised as the page quotes them.

- ``backlash-recovery.toml`` (54 Phase II campaigns): the RMS error of the backlash change per
  rail waviness × IMU noise cell (mean over the steps and seeds), per step (mean over the rest),
  the largest single error and the largest in the default cell;
- ``detection.toml`` (24 Phase I campaigns and the reference): the PCA-T² delay per wear rate ×
  torque noise cell (mean of the seeds), and per method the campaigns detected after the onset,
  their mean delay and the campaigns with a false alarm, at the detectors' default limits.

Run: .venv/bin/python benchmarks/sweep_tables.py [WORKDIR] [--record]
(default WORKDIR runs/validate/sweeps, emptied first; ``--record``: the tables and figures into
docs/validation.json, :mod:`record`; part of ``make validate``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from record import record  # noqa: E402

SWEEPS = REPO / "scenarios" / "sweeps"
STEP = "degradation.table_backlash_um[2]"
WAVINESS = "geometry.straightness_rms_um"
IMU_NOISE = "sensors.imu_acc_noise_ug_per_rthz"
WEAR = "degradation.wear_rate_um_per_kh"
TORQUE_NOISE = "sensors.torque_noise_Nm"
NAMES = {"pca_t2": "PCA-T²", "gmm_md": "GMM-MD", "som_mqe": "SOM-MQE", "iforest": "Isolation Forest",
         "ocsvm": "One-class SVM", "autoencoder": "Autoencoder"}


def sweep(name: str, out: Path) -> float:
    """``twin sweep scenarios/sweeps/NAME.toml -o OUT``; its wall time, s."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "twin.cli", "sweep", str(SWEEPS / f"{name}.toml"), "-o", str(out)],
                   cwd=REPO, check=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    return time.perf_counter() - t0


def grid_table(df, rows: str, columns: str, score: str, corner: str, row_label, column_unit: str,
               fmt: str) -> str:
    """Markdown table of ``score``'s mean over the seeds (and any other axis) of ``df``, one row
    per value of the swept key ``rows`` (labelled by ``row_label(value)``), one column per value
    of ``columns`` (``"<value> <column_unit>"``); an empty cell is "-"."""
    import pandas as pd

    cell = df.groupby([rows, columns])[score].mean().unstack()
    lines = [f"| {corner} | " + " | ".join(f"{c:g} {column_unit}" for c in cell.columns) + " |",
             "|---|" + "---|" * len(cell.columns)]
    for value, r in cell.iterrows():
        lines.append(f"| {row_label(value)} | " + " | ".join("-" if pd.isna(x) else fmt.format(x) for x in r) + " |")
    return "\n".join(lines) + "\n"


def backlash_tables(df) -> tuple[dict, dict]:
    """(figures, tables) of the backlash-recovery sweep's results ``df``."""
    table = grid_table(df, WAVINESS, IMU_NOISE, "phase2.rms_error_um", "waviness \\ IMU noise",
                       lambda w: f"{w:g} µm" + (" (default)" if w == 0.5 else ""), "µg/√Hz", "{:.3f}")
    per_step = df.groupby(STEP)["phase2.rms_error_um"].mean()
    worst = df.loc[df["phase2.max_abs_error_um"].idxmax()]
    default = df[(df[WAVINESS] == 0.5) & (df[IMU_NOISE] == 7.0)]
    figures = {
        "backlash_campaigns": (len(df), f"{len(df)}"),
        "backlash_per_step_um": (None, " / ".join(f"{v:.3f}" for v in per_step.values) + " µm for "
                                 + " / ".join(f"{s:g}" for s in per_step.index) + " µm"),
        "backlash_largest_um": (float(worst["phase2.max_abs_error_um"]),
                                f"{worst['phase2.max_abs_error_um']:.2f} µm ({worst[WAVINESS]:g} µm waviness, "
                                f"{worst[IMU_NOISE]:g} µg/√Hz)"),
        "backlash_largest_default_um": (float(default["phase2.max_abs_error_um"].max()),
                                        f"{default['phase2.max_abs_error_um'].max():.2f} µm"),
    }
    return figures, {"backlash_recovery": table}


def detection_tables(df) -> tuple[dict, dict]:
    """(figures, tables) of the detection sweep's results ``df``."""
    table = grid_table(df, WEAR, TORQUE_NOISE, "phase1.pca_t2.delay_hours", "wear rate \\ torque noise",
                       lambda w: f"{w:g} µm/kh", "N·m", "{:.0f}")
    methods = ["| method | detected after the onset | mean delay (h) | campaigns with a false alarm |",
               "|---|---|---|---|"]
    for m, name in NAMES.items():
        if f"phase1.{m}.delay_hours" not in df:
            continue
        det = df[f"phase1.{m}.detection_hours"].notna()
        fa = (df[f"phase1.{m}.false_alarm_rate"].fillna(0) > 0).sum()
        methods.append(f"| {name} | {int(det.sum())} / {len(df)} | {df[f'phase1.{m}.delay_hours'][det].mean():.0f} "
                       f"| {int(fa)} / {len(df)} |")
    figures = {"detection_campaigns": (len(df), f"{len(df)}")}
    return figures, {"detection_delay": table, "detection_methods": "\n".join(methods) + "\n"}


def main() -> None:
    import pandas as pd

    args = [a for a in sys.argv[1:] if a != "--record"]
    work = Path(args[0]) if args else REPO / "runs" / "validate" / "sweeps"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    figures, tables = {}, {}
    for name, summarise in (("backlash-recovery", backlash_tables), ("detection", detection_tables)):
        seconds = sweep(name, work / name)
        df = pd.read_parquet(work / name / "results.parquet")
        f, t = summarise(df)
        figures.update(f)
        figures[f"{name.replace('-', '_')}_wall_s"] = (round(seconds, 1), f"{seconds:.0f} s")
        tables.update(t)
        print(f"{name}: {len(df)} campaigns in {seconds:.0f} s")
        for k, v in t.items():
            print(f"{k}:\n{v}")
    for k, (_, text) in figures.items():
        print(f"{k}: {text}")
    if "--record" in sys.argv[1:]:
        record("sweep_tables", command=".venv/bin/python benchmarks/sweep_tables.py --record",
               scale="the shipped sweeps scenarios/sweeps/backlash-recovery.toml (54 campaigns) and "
                     "detection.toml (24 campaigns and the reference), default executor",
               figures=figures, tables=tables)


if __name__ == "__main__":
    main()
