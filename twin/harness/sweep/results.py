"""The table of a sweep's results (one row per point and seed) and its summaries."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from analysis.base.files import atomic_write
from twin.harness.sweep.plan import Plan, Task
from twin.harness.sweep.runlog import point_dir
from twin.harness.sweep.schema import RESULT_NAME

# ---------------------------------------------------------------------------------------------
# The table


def records(plan: Plan, out: str | Path) -> list[tuple[Task, dict]]:
    """(task, result.json record) of every recorded task, in table order."""
    out = Path(out)
    recs = []
    for t in sorted(plan.tasks, key=lambda t: (t.point, t.seed)):
        path = point_dir(out, t) / RESULT_NAME
        if path.is_file():
            recs.append((t, json.loads(path.read_text())))
    return recs


def results_table(plan: Plan, out: str | Path):
    """One row per recorded point and seed (sorted by point, then seed): ``point``, ``seed``,
    the swept values (one column per scenario key), ``directory`` (relative to OUT) and every
    scalar score of :func:`analysis.scoring.flat`; an ``error`` column only if a point failed."""
    import pandas as pd

    from analysis.scoring import flat

    rows, score_cols, any_error = [], [], False
    for t, rec in records(plan, out):
        row: dict[str, Any] = {"point": t.point, "seed": t.seed}
        row.update({c: t.values[c] for c in plan.columns})
        row["directory"] = f"points/{t.id}"
        scores = flat(rec["score"]) if rec.get("score") else {}
        for k in scores:
            if k not in score_cols:
                score_cols.append(k)
        row.update(scores)
        row["error"] = rec.get("error")
        any_error |= rec.get("error") is not None
        rows.append(row)
    cols = ["point", "seed", *plan.columns, "directory", *score_cols] + (["error"] if any_error else [])
    df = pd.DataFrame(rows, columns=cols)
    for c in score_cols:  # None -> missing: counts as nullable integers, the rest as floats
        ints = df[c].map(lambda v: v is None or (isinstance(v, int) and not isinstance(v, bool)))
        df[c] = df[c].astype("Int64") if ints.all() else pd.to_numeric(df[c]).astype(float)
    for c in plan.columns:
        if df[c].map(lambda v: isinstance(v, float)).any():
            df[c] = df[c].astype(float)
    return df


def write_table(df, out: str | Path) -> tuple[Path, Path]:
    out = Path(out)
    pq, csv = out / "results.parquet", out / "results.csv"
    atomic_write(pq, lambda tmp: df.to_parquet(tmp, index=False))
    atomic_write(csv, lambda tmp: df.to_csv(tmp, index=False))
    return pq, csv


# Scores shown in the summary table, in this order, if present.
KEY_SCORES = ("phase2.rms_error_um", "phase2.bias_um", "phase2.prognosis.error_hours")


def phase1_methods(df) -> list[str]:
    """The Phase I methods of a results table (columns ``phase1.<method>.delay_hours``)."""
    seen = []
    for c in df.columns:
        if c.startswith("phase1.") and c.endswith(".delay_hours"):
            seen.append(c.split(".")[1])
    return seen


def phase2_estimators(df) -> list[str]:
    """The backlash estimators of a results table (columns ``phase2.<estimator>.rms_error_um``)."""
    return [c.split(".")[1] for c in df.columns
            if c.startswith("phase2.") and c.endswith(".rms_error_um") and c.count(".") == 2]


def summary(plan: Plan, df, methods: list[str] | None = None) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the summary table: per point, the swept values, the number of seeds,
    mean ± std over seeds of the key scores, the RMS error of every backlash estimator if there
    are several, and for each of ``methods`` (default: the registered default detector) the
    Phase I delay, false-alarm rate and the fraction of seeds detected (an alarm after the
    onset). Raises ValueError naming a method the table does not have."""
    from analysis.base import registry

    score_cols = [c for c in KEY_SCORES if c in df.columns]
    have = phase1_methods(df)
    if methods is None:
        methods = [m for m in [registry.default("detectors").name] if m in have]
    missing = [m for m in methods if m not in have]
    if missing:
        raise ValueError(f"--methods {', '.join(missing)}: not in the sweep's table; expected "
                         f"some of {', '.join(have) or '(no Phase I method)'}")
    p1 = list(methods)
    ests = phase2_estimators(df)
    if len(ests) > 1:
        score_cols += [f"phase2.{e}.rms_error_um" for e in ests]
    header = [c.split(".")[-1] if len(c) > 24 else c for c in plan.primary] + ["seeds"]
    header += [c.removeprefix("phase2.") for c in score_cols]
    for m in p1:
        header += [f"{m} delay h", f"{m} FA rate", f"{m} detected"]
    rows = []

    def ms(x) -> str:
        x = np.asarray(x, float)
        x = x[np.isfinite(x)]
        if not len(x):
            return "-"
        return f"{x.mean():.3g}" + (f"±{x.std(ddof=1):.2g}" if len(x) > 1 else "")

    for _point, g in df.groupby("point", sort=True):
        row = [f"{g[c].iloc[0]:.4g}" for c in plan.primary] + [str(len(g))]
        row += [ms(g[c]) for c in score_cols]
        for m in p1:
            delay = g[f"phase1.{m}.delay_hours"]
            row += [ms(delay), ms(g[f"phase1.{m}.false_alarm_rate"]),
                    f"{int(g[f'phase1.{m}.detection_hours'].notna().sum())}/{len(g)}"]
        rows.append(row)
    return header, rows


def method_summary(df) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the Phase I methods over all rows (at each method's own limit):
    detected (an alarm after the onset), mean false-alarm rate, median delay of the detections (h)."""
    header = ["method", "detected", "mean false-alarm rate", "median delay h"]
    rows = []
    for m in phase1_methods(df):
        delay = df[f"phase1.{m}.delay_hours"]
        det = df[f"phase1.{m}.detection_hours"].notna()
        fa = df[f"phase1.{m}.false_alarm_rate"].astype(float)
        rows.append([m, f"{int(det.sum())}/{len(df)}",
                     "-" if fa.isna().all() else f"{fa.mean():.3f}",
                     "-" if not det.any() else f"{delay[det].median():g}"])
    return header, rows
