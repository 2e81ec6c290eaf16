"""The diagnosis report: gap maps before and after the added effects, on held-out data.

Maps show log10 of the mean t² of the statistics in each cell (1 = the twin's own spread):
channel × frequency band (Phase I), error motion × stroke segment (Phase II), channel ×
operating phase, and the gap per operating hours; plus the candidates' held-out reductions.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from analysis.dataset import DOFS  # noqa: E402
from analysis.diagnosis.signature import (  # noqa: E402
    OPERATING_PHASES,
    PHASE1_BANDS_HZ,
    PHASE1_CHANNELS,
    PHASE2_CHANNELS,
    Region,
    _band_labels,
)


def _cells(z: np.ndarray, regions, rows, cols, pick) -> np.ndarray:
    """(len(rows), len(cols)) mean z² of the statistics for which pick(region) = (row, col)."""
    acc = np.zeros((len(rows), len(cols)))
    cnt = np.zeros_like(acc)
    for v, r in zip(z, regions, strict=True):
        rc = pick(r)
        if rc is None or not np.isfinite(v) or rc[0] not in rows or rc[1] not in cols:
            continue
        i, j = rows.index(rc[0]), cols.index(rc[1])
        acc[i, j] += v * v
        cnt[i, j] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, acc / np.maximum(cnt, 1), np.nan)


def _map(ax, m: np.ndarray, rows, cols, title: str, vmax: float):
    im = ax.imshow(np.log10(np.maximum(m, 1e-3)), aspect="auto", cmap="magma", vmin=-1, vmax=vmax)
    ax.set_xticks(range(len(cols)), cols, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(rows)), rows, fontsize=7)
    ax.set_title(title, fontsize=9)
    return im


def _pair(path: Path, before: np.ndarray, after: np.ndarray, rows, cols, what: str) -> None:
    finite = np.concatenate([before[np.isfinite(before)], after[np.isfinite(after)], [10.0]])
    vmax = float(np.log10(np.max(finite)))
    fig, axes = plt.subplots(1, 2, figsize=(11, 0.35 * len(rows) + 2.2), constrained_layout=True)
    _map(axes[0], before, rows, cols, f"{what}: before (held-out)", vmax)
    im = _map(axes[1], after, rows, cols, f"{what}: after adding the effects (held-out)", vmax)
    fig.colorbar(im, ax=axes, label="log10 mean t²  (0 = twin's own spread)")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_diagnosis_report(out_dir: Path, result: dict, regions: list[Region],
                           t_heldout: dict[str, np.ndarray]) -> list[Path]:
    """Write the gap maps, the ranking chart and ``index.html`` into ``out_dir``; ``regions``
    (n,) and ``t_heldout`` {"before", "after"}: (n,) as returned by
    :func:`analysis.diagnosis.attribution.diagnose`. Returns the PNG paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    z_b, z_a = t_heldout["before"], t_heldout["after"]
    pngs = []

    bands = _band_labels(PHASE1_BANDS_HZ)
    pick1 = lambda r: (r.channel, r.bin) if r.domain == "phase1" and r.family == "band" else None  # noqa: E731
    if any(pick1(r) for r in regions):
        p = out_dir / "gap_phase1_channel_band.png"
        _pair(p, _cells(z_b, regions, list(PHASE1_CHANNELS), bands, pick1),
              _cells(z_a, regions, list(PHASE1_CHANNELS), bands, pick1),
              list(PHASE1_CHANNELS), bands, "Phase I channel × band")
        pngs.append(p)

    segs = sorted({r.bin for r in regions if r.family == "position"}, key=lambda b: float(b.split("-")[0]))
    lag_segs = sorted({r.bin for r in regions if r.family == "lag"}, key=lambda b: float(b.split("-")[0]))
    if segs:
        rows = [f"{d} profile" for d in DOFS] + ["E_XX shift"]

        def pick2(r):
            if r.family == "position":
                return f"{r.channel} profile", r.bin
            if r.family == "lag" and r.bin in lag_segs and len(lag_segs) == len(segs):
                return f"{r.channel} shift", segs[lag_segs.index(r.bin)]
            return None
        p = out_dir / "gap_phase2_position_error_motion.png"
        _pair(p, _cells(z_b, regions, rows, segs, pick2), _cells(z_a, regions, rows, segs, pick2),
              rows, segs, "Phase II error motion × stroke segment")
        pngs.append(p)

    ch_rows = [f"P1 {c}" for c in PHASE1_CHANNELS] + [f"P2 {c}" for c in PHASE2_CHANNELS]
    cols = list(OPERATING_PHASES) + ["level"]

    def pick3(r):
        tag = "P1" if r.domain == "phase1" else "P2"
        if r.family == "phase":
            return f"{tag} {r.channel}", r.bin
        if r.family == "level":
            return f"{tag} {r.channel}", "level"
        return None
    p = out_dir / "gap_operating_phase.png"
    _pair(p, _cells(z_b, regions, ch_rows, cols, pick3), _cells(z_a, regions, ch_rows, cols, pick3),
          ch_rows, cols, "channel × operating phase")
    pngs.append(p)

    hours = result.get("hours", [])
    ranking = result.get("ranking", [])
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.2), constrained_layout=True)
    if hours:
        h = [f"{r['hours']:g}" for r in hours]
        x = np.arange(len(h))
        axes[0].bar(x - 0.2, [r["heldout_gap_before"] for r in hours], 0.4, label="before")
        axes[0].bar(x + 0.2, [r["heldout_gap_after"] for r in hours], 0.4, label="after")
        axes[0].set_xticks(x, h, fontsize=7)
        axes[0].set_yscale("log")
        axes[0].legend(fontsize=7)
    axes[0].set_title("held-out gap (mean t² of the significant statistics) per operating hours", fontsize=9)
    axes[0].set_xlabel("hours")
    if ranking:
        names = [r["effect"] for r in ranking]
        red = [100 * r["heldout_reduction"] for r in ranking]
        colors = ["tab:green" if r["significant"] else "tab:gray" for r in ranking]
        axes[1].barh(range(len(names)), red, color=colors)
        axes[1].set_yticks(range(len(names)), names, fontsize=7)
        axes[1].invert_yaxis()
        axes[1].set_xlabel("held-out gap reduction, % (green: significant)")
    axes[1].set_title("candidates, first round", fontsize=9)
    p = out_dir / "gap_hours_and_ranking.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    pngs.append(p)

    rows_html = "".join(
        f"<tr><td>{i + 1}</td><td>{html.escape(a['effect'])}</td><td>{html.escape(json.dumps(a['params']))}</td>"
        f"<td>{html.escape(json.dumps(a['interval']))}</td><td>{100 * a['heldout_reduction']:.0f} %</td></tr>"
        for i, a in enumerate(result.get("added", [])))
    reg_html = "".join(
        f"<tr><td>{html.escape(' '.join([r['domain'], r['channel'], r['family'], r['bin']]))}</td>"
        f"<td>{r['calibration_gap']:.1f}</td><td>{r['heldout_gap_before']:.1f}</td>"
        f"<td>{r['heldout_gap_after']:.1f}</td></tr>"
        for r in result.get("regions", [])[:15] if r["significant"])
    imgs = "".join(f'<h2>{html.escape(q.stem.replace("_", " "))}</h2><img src="{q.name}">' for q in pngs)
    (out_dir / "index.html").write_text(
        "<!doctype html><html><head><meta charset='utf-8'><title>Gap diagnosis</title></head><body>"
        f"<h1>Gap diagnosis: {html.escape(result['verdict'])}</h1>"
        f"<p>Held-out gap {result['heldout_gap_before']:.1f} → {result['heldout_gap_after']:.1f} "
        f"(critical {result['heldout_gap_critical']:.1f}; shrink {100 * result['heldout_shrink']:.0f} %), "
        f"{result['n_significant_calibration']} of {result['n_statistics']} statistics significant on "
        "the calibration part.</p>"
        "<h2>Effects added</h2><table border=1><tr><th>step</th><th>effect</th><th>parameters</th>"
        f"<th>interval</th><th>held-out reduction</th></tr>{rows_html}</table>"
        "<h2>Regions (significant, by calibration gap; mean t²)</h2><table border=1><tr><th>region</th>"
        f"<th>calibration</th><th>held-out before</th><th>held-out after</th></tr>{reg_html}</table>"
        f"{imgs}</body></html>")
    return pngs
