"""Plots of a sweep's results (PNG, matplotlib Agg) and the aggregated detection-rate against
false-alarm-rate curves.

- ``OUT/plots/phase2_vs_<key>.png``: Phase II scores (RMS, mean and largest error of the
  estimated backlash change, µm; prognosis error, h) against one swept key, one line per value of
  another swept key (of those with 2-8 values, the one that moves the RMS error most), mean over
  the remaining keys and the seeds, bars ±1 standard deviation, every row as a faint dot;
- ``OUT/plots/phase2_estimators_vs_<key>.png`` (with two or more backlash estimators): the same
  scores, one series per estimator;
- ``OUT/plots/phase1_vs_<key>.png``: per Phase I method, the detection delay (h), the
  false-alarm rate on healthy post-baseline samples and the detection rate (fraction of rows
  that detected) against one swept key;
- ``OUT/plots/detection_roc.png`` and ``OUT/roc.csv``: for each method and threshold factor f
  (the control limit times f, ``score.json`` ``phase1.methods.<m>.roc``), the detection rate over
  all points and seeds against their mean false-alarm rate.

"Detected" is score.json's (:mod:`analysis.phase1.scoring`): a first alarm after the injected
onset; alarms before it are false alarms. Every method and estimator has one colour and marker
(:func:`analysis.base.registry.style`) in every figure, and each figure's legend lists every method,
also those without data in a panel.

Sweeps over many distinct values (random sampling) are drawn as scatter plots without lines.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from analysis.base.files import write_json
from analysis.base.registry import label, style
from twin.harness.sweep.results import phase1_methods, phase2_estimators, records

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
    return df[f"phase1.{method}.detection_hours"].notna().astype(float)


def _legend(fig, kind: str, names: list[str], title: str | None = None) -> None:
    """One legend for the whole figure listing every method of ``names`` in its fixed style."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=style(kind, n)[0], marker=style(kind, n)[1], ms=5,
                      label=f"{label(kind, n)} [{n}]" if label(kind, n) != n else n) for n in names]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(names), 4), fontsize=7,
               title=title, title_fontsize=7, frameon=False)


def _line(ax, df, x: str, y, label: str | None, color=None, marker: str = "o") -> None:
    """Mean ± std of y over rows sharing x (a line), or the rows themselves (a scatter)."""
    d = df.assign(_y=y).dropna(subset=["_y"])
    if d.empty:
        return
    if d[x].nunique() > MAX_LINE_VALUES:
        ax.plot(d[x], d["_y"], marker, ls="", ms=4, alpha=0.7, label=label, color=color)
    else:
        g = d.groupby(x, sort=True)["_y"]
        mean, std = g.mean(), g.std(ddof=1).fillna(0.0)
        ax.errorbar(mean.index, mean.values, yerr=std.values, marker=marker, ms=4, capsize=3,
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


def _save_with_legend(fig, path: Path, title: str | None, n_legend: int) -> Path:
    """Like :func:`_save`, leaving room at the bottom for the shared legend."""
    if title is not None:
        fig.suptitle(title, fontsize=10)
    rows = (n_legend + 3) // 4
    fig.tight_layout(rect=(0, 0.07 + 0.045 * rows, 1, 1))
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return path


def _phase1_figure(plan, df, x: str, methods: list[str], path: Path) -> Path | None:
    if not methods:
        return None
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4), squeeze=False)
    log_x = x in plan.log_columns
    for m in methods:
        color, marker = style("detectors", m)
        det = _detected(df, m)
        delay = df[f"phase1.{m}.delay_hours"].where(det > 0)
        _line(axes[0][0], df, x, delay, m, color, marker)
        _line(axes[0][1], df, x, df[f"phase1.{m}.false_alarm_rate"], m, color, marker)
        _line(axes[0][2], df, x, det, m, color, marker)
    for ax, title in zip(axes[0], ("detection delay after the onset (h)",
                                   "false-alarm rate (healthy post-baseline samples)",
                                   "detection rate (an alarm after the onset)"), strict=True):
        _xaxis(ax, df, x, log_x, len(plan.tied[x]) - 1)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][2].set_ylim(-0.05, 1.05)
    _legend(fig, "detectors", methods)
    return _save_with_legend(fig, path, f"sweep {plan.name}: Phase I against {x} ({len(df)} rows)",
                             len(methods))


def _estimators_figure(plan, df, x: str, estimators: list[str], path: Path) -> Path | None:
    """Phase II scores against ``x``, one series per backlash estimator."""
    panels = [(f"phase2.{{}}.{c.removeprefix('phase2.')}" if "prognosis" not in c
               else "phase2.{}.prognosis_error_hours", t) for c, t in PHASE2_PANELS]
    plt = _plt()
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.2), squeeze=False)
    for ax, (col, title) in zip(axes[0], panels, strict=True):
        for e in estimators:
            c = col.format(e)
            if c in df.columns:
                color, marker = style("backlash_estimators", e)
                _line(ax, df, x, df[c], e, color, marker)
        if "rms" not in col and "max_abs" not in col:
            ax.axhline(0.0, color="0.5", lw=0.8)
        _xaxis(ax, df, x, x in plan.log_columns, len(plan.tied[x]) - 1)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    _legend(fig, "backlash_estimators", estimators)
    return _save_with_legend(fig, path, f"sweep {plan.name}: Phase II estimators against {x} "
                                        f"({len(df)} rows)", len(estimators))


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
    fig, ax = plt.subplots(figsize=(6.0, 6.0))
    methods = list(dict.fromkeys(roc["method"]))
    for m, g in roc.groupby("method", sort=False):
        g = g.sort_values("threshold_factor")
        color, marker = style("detectors", m)
        ax.plot(g["false_alarm_rate"], g["detection_rate"], marker=marker, ms=3, color=color)
        own = g[np.isclose(g["threshold_factor"], 1.0)]
        ax.plot(own["false_alarm_rate"], own["detection_rate"], marker, ms=10, mfc="none",
                color=color, mew=1.5)
    ax.set_xlabel("false-alarm rate (mean over points and seeds)")
    ax.set_ylabel("detection rate (an alarm after the onset)")
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    ax.grid(alpha=0.3)
    ax.set_title(f"sweep {plan.name}: detection vs false alarms, limit x 0.25 ... 4\n"
                 f"({int(roc['rows'].max())} rows)", fontsize=9)
    _legend(fig, "detectors", methods, title="large open marker: the method's own limit")
    return _save_with_legend(fig, path, None, len(methods))


def write_plots(plan, out: str | Path, df) -> list[Path]:
    """Write the figures (and ``roc.csv``) of a sweep into ``out``; returns the files written."""

    out = Path(out)
    pdir = out / "plots"
    pdir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    ok = df[df["error"].isna()] if "error" in df.columns else df
    methods = phase1_methods(ok)
    estimators = phase2_estimators(ok)
    for x in plan.primary:  # tied keys share their values: one figure per axis
        if ok.empty or ok[x].nunique() < 2:
            continue
        for fig in (_phase2_figure(plan, ok, x, pdir / f"phase2_vs_{_slug(x)}.png"),
                    _phase1_figure(plan, ok, x, methods, pdir / f"phase1_vs_{_slug(x)}.png"),
                    _estimators_figure(plan, ok, x, estimators,
                                       pdir / f"phase2_estimators_vs_{_slug(x)}.png")
                    if len(estimators) > 1 else None):
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
