"""Plots of a sweep's results (PNG, matplotlib Agg) and the aggregated detection-rate against
false-alarm-rate curves.

- ``OUT/plots/phase2_vs_<key>.png``: Phase II scores (RMS, mean and largest error of the
  estimated backlash change, µm; prognosis error, h) against one swept key, one line per value of
  another swept key (of those with 2-8 values, the one that moves the RMS error most), mean over
  the remaining keys and the seeds, bars ±1 standard deviation, every row as a faint dot;
- ``OUT/plots/phase1_vs_<key>.png``: per Phase I method, the detection delay (h, over the rows
  that detected after the onset), the false-alarm rate on healthy post-baseline samples and the
  detection rate (fraction of rows that detected after the onset) against one swept key;
- ``OUT/plots/detection_roc.png`` and ``OUT/roc.csv``: for each method and threshold factor f
  (the control limit times f, ``score.json`` ``phase1.methods.<m>.roc``), the detection rate over
  all points and seeds against their mean false-alarm rate. "Detected" is score.json's: the
  first alarm after the baseline comes after the injected onset; so a limit low enough to alarm
  on healthy samples loses detections, and the curve falls towards high false-alarm rates.

Sweeps over many distinct values (random sampling) are drawn as scatter plots without lines.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from analysis.files import write_json
from twin.harness.sweep.results import phase1_methods, records

__all__ = ["roc_table", "write_plots"]

MAX_LINE_VALUES = 12   # beyond this many distinct x values: scatter only
MAX_GROUPS = 8

PHASE2_PANELS = (("phase2.rms_error_um", "RMS error of Δbacklash (µm)"),
                 ("phase2.bias_um", "mean error of Δbacklash (µm)"),
                 ("phase2.max_abs_error_um", "largest |error| of Δbacklash (µm)"),
                 ("phase2.prognosis.error_hours", "prognosis error of the 10 µm crossing (h)"))


def _slug(key: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]+", "_", key).strip("_")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, title: str | None = None) -> Path:
    """Give ``fig`` its title, lay it out, write it to ``path`` (PNG, 110 dpi) and close it."""
    if title is not None:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return path


def _detected(df, method: str):
    return (df[f"phase1.{method}.delay_hours"] > 0).astype(float)


def _line(ax, df, x: str, y, label: str | None, color=None) -> None:
    """Mean ± std of y over rows sharing x (a line), or the rows themselves (a scatter)."""
    d = df.assign(_y=y).dropna(subset=["_y"])
    if d.empty:
        return
    if d[x].nunique() > MAX_LINE_VALUES:
        ax.plot(d[x], d["_y"], "o", ms=4, alpha=0.7, label=label, color=color)
    else:
        g = d.groupby(x, sort=True)["_y"]
        mean, std = g.mean(), g.std(ddof=1).fillna(0.0)
        ax.errorbar(mean.index, mean.values, yerr=std.values, marker="o", ms=4, capsize=3,
                    label=label, color=color)


def _xaxis(ax, df, x: str, log_x: bool, tied: int = 0) -> None:
    """Label the x axis with the swept key; ticks at the swept values when there are few."""
    from matplotlib.ticker import NullFormatter

    if log_x:
        ax.set_xscale("log")
    values = sorted(df[x].dropna().unique())
    if len(values) <= MAX_LINE_VALUES:
        ax.set_xticks(values, [f"{v:g}" for v in values])
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(x + (f" (and {tied} tied key{'s' if tied > 1 else ''})" if tied else ""))


def _group_column(plan, df, x: str, score: str) -> str | None:
    """The other swept key (2-8 values) whose values move ``score`` the most (largest variance of
    the group means), or None."""
    best, spread = None, -1.0
    for c in plan.primary:
        if c != x and 2 <= df[c].nunique() <= MAX_GROUPS:
            v = float(np.nan_to_num(df.groupby(c)[score].mean().var(ddof=0)))
            if v > spread:
                best, spread = c, v
    return best


def _phase2_figure(plan, df, x: str, path: Path) -> Path | None:
    panels = [(c, t) for c, t in PHASE2_PANELS if c in df.columns and df[c].notna().any()]
    if not panels:
        return None
    plt = _plt()
    group = _group_column(plan, df, x, panels[0][0])
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), squeeze=False)
    for ax, (col, title) in zip(axes[0], panels, strict=True):
        ax.plot(df[x], df[col], ".", color="0.75", zorder=0)
        if group is None:
            _line(ax, df, x, df[col], None)
        else:
            for gv, sub in df.groupby(group, sort=True):
                _line(ax, sub, x, sub[col], f"{group.split('.')[-1]} = {gv:.4g}")
        if col != "phase2.rms_error_um" and col != "phase2.max_abs_error_um":
            ax.axhline(0.0, color="0.5", lw=0.8)
        _xaxis(ax, df, x, x in plan.log_columns, len(plan.tied[x]) - 1)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    if group is not None:
        axes[0][0].legend(fontsize=7)
    return _save(fig, path, f"sweep {plan.name}: Phase II against {x} ({len(df)} rows)")


def _phase1_figure(plan, df, x: str, methods: list[str], path: Path) -> Path | None:
    if not methods:
        return None
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), squeeze=False)
    log_x = x in plan.log_columns
    for m in methods:
        det = _detected(df, m)
        delay = df[f"phase1.{m}.delay_hours"].where(det > 0)
        _line(axes[0][0], df, x, delay, m)
        _line(axes[0][1], df, x, df[f"phase1.{m}.false_alarm_rate"], m)
        _line(axes[0][2], df, x, det, m)
    for ax, title in zip(axes[0], ("detection delay after the onset (h)",
                                   "false-alarm rate (healthy post-baseline samples)",
                                   "detection rate (detected after the onset)"), strict=True):
        _xaxis(ax, df, x, log_x, len(plan.tied[x]) - 1)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][2].set_ylim(-0.05, 1.05)
    axes[0][0].legend(fontsize=7)
    return _save(fig, path, f"sweep {plan.name}: Phase I against {x} ({len(df)} rows)")


def roc_table(recs):
    """Detection rate against false-alarm rate per method and threshold factor, over all rows.

    ``recs``: (task, result record) pairs. Returns a DataFrame with columns method,
    threshold_factor, detection_rate (fraction of rows detected after the onset),
    false_alarm_rate (mean over the rows that have healthy post-baseline samples), rows."""
    import pandas as pd

    acc: dict[tuple[str, float], dict] = {}
    for _, rec in recs:
        p1 = (rec.get("score") or {}).get("phase1") or {}
        for m, r in p1.get("methods", {}).items():
            roc = r.get("roc")
            if not roc:
                continue
            for f, fa, d in zip(roc["threshold_factor"], roc["false_alarm_rate"], roc["detected"], strict=True):
                a = acc.setdefault((m, float(f)), {"fa": [], "det": []})
                a["det"].append(bool(d))
                if fa is not None:
                    a["fa"].append(float(fa))
    rows = [{"method": m, "threshold_factor": f,
             "detection_rate": float(np.mean(a["det"])) if a["det"] else np.nan,
             "false_alarm_rate": float(np.mean(a["fa"])) if a["fa"] else np.nan,
             "rows": len(a["det"])} for (m, f), a in acc.items()]
    df = pd.DataFrame(rows, columns=["method", "threshold_factor", "detection_rate",
                                     "false_alarm_rate", "rows"])
    return df  # methods in score.json order, factors ascending (insertion order)


def _roc_figure(plan, roc, path: Path) -> Path | None:
    if roc.empty:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for m, g in roc.groupby("method", sort=False):
        g = g.sort_values("threshold_factor")
        (line,) = ax.plot(g["false_alarm_rate"], g["detection_rate"], marker=".", label=m)
        own = g[np.isclose(g["threshold_factor"], 1.0)]
        ax.plot(own["false_alarm_rate"], own["detection_rate"], "o", ms=8, mfc="none",
                color=line.get_color())
    ax.set_xlabel("false-alarm rate (mean over points and seeds)")
    ax.set_ylabel("detection rate (first alarm after the baseline\ncomes after the onset)")
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, title="circle: the method's own limit", title_fontsize=7)
    ax.set_title(f"sweep {plan.name}: detection vs false alarms, limit x 0.25 ... 4\n"
                 f"({int(roc['rows'].max())} rows)", fontsize=9)
    return _save(fig, path)


def write_plots(plan, out: str | Path, df) -> list[Path]:
    """Write the figures (and ``roc.csv``) of a sweep into ``out``; returns the files written."""

    out = Path(out)
    pdir = out / "plots"
    pdir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    ok = df[df["error"].isna()] if "error" in df.columns else df
    methods = phase1_methods(ok)
    for x in plan.primary:  # tied keys share their values: one figure per axis
        if ok.empty or ok[x].nunique() < 2:
            continue
        for fig in (_phase2_figure(plan, ok, x, pdir / f"phase2_vs_{_slug(x)}.png"),
                    _phase1_figure(plan, ok, x, methods, pdir / f"phase1_vs_{_slug(x)}.png")):
            if fig is not None:
                written.append(fig)
    roc = roc_table(records(plan, out))
    if not roc.empty:
        roc.to_csv(out / "roc.csv", index=False)
        written.append(out / "roc.csv")
        fig = _roc_figure(plan, roc, pdir / "detection_roc.png")
        if fig is not None:
            written.append(fig)
    write_json(pdir / "index.json", [str(p.relative_to(out)) for p in written])
    return written
