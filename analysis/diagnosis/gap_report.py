"""The diagnosis report: gap maps before and after the added effects, on held-out data.

Maps show log10 of the mean t² of the statistics in each cell (1 = the twin's own spread):
channel × frequency band (Phase I), error motion × stroke segment (Phase II), channel ×
operating phase, and the gap per operating hours; plus the candidates' held-out reductions. On
the "after" maps, cells holding a region the added effects made worse
(:func:`analysis.diagnosis.attribution.worse_regions`) are outlined.

``index.html`` is rendered by the Jinja2 template ``templates/diagnosis.html.j2`` (autoescaped;
the style sheet is the campaign report's, ``analysis/report/templates/style.css.j2``); its
words and numbers come from :mod:`analysis.diagnosis.wording`.
"""

from __future__ import annotations

from pathlib import Path

import jinja2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from analysis.base.files import write_text  # noqa: E402
from analysis.dataset import DOFS  # noqa: E402
from analysis.diagnosis import wording as w  # noqa: E402
from analysis.diagnosis.signature import (  # noqa: E402
    OPERATING_PHASES,
    PHASE1_BANDS_HZ,
    PHASE1_CHANNELS,
    PHASE2_CHANNELS,
    Region,
    _band_labels,
)

_ENV = jinja2.Environment(
    loader=jinja2.ChoiceLoader([jinja2.PackageLoader("analysis.diagnosis", "templates"),
                                jinja2.PackageLoader("analysis.report", "templates")]),
    autoescape=True, undefined=jinja2.StrictUndefined, keep_trailing_newline=True)

#: The rules behind the flags, as the report states them.
RULES = (
    "t² of a statistic: its squared distance from the twin's seed mean in units of the twin's "
    "seed-to-seed spread; 1 is typical of the twin itself. The gap is Σ t² over the statistics "
    "significant on the calibration part; every before/after figure is on the held-out part.",
    "Interval (90 %): the hull of where the calibration Σ t² stays within max(1, reduced χ²) of "
    "its minimum and of three bootstraps (over the regions, over the response's twin seeds, over "
    "the twin's own seed-to-seed variation), widened by how far the fit moves when the response "
    "is interpolated otherwise between grid values.",
    "At the edge of the tried range: the fitted value or an end of its interval lies on the "
    "first or last value of the grid the effect was simulated on, so the true value may lie "
    "beyond it (a zero amplitude is a physical floor and is not flagged).",
    "Region made worse: a region (channel × band, operating phase, stroke segment, feature; all "
    "hours) whose held-out Σ t² over its m statistics rises by more than the χ²_m quantile at "
    "1 − α once the effect is added. Its rise outside the significant statistics is subtracted "
    "from the candidate's gain (net reduction), which ranks the candidates and must pass the "
    "selection test.",
    "Refused: a candidate that passes the selection test but, with every added candidate in, "
    "leaves more than 10 % of the gap where it acts (the significant statistics its response "
    "moves by at least the twin's spread), beyond what the twin's noise and the seed-to-seed "
    "error of its own response allow: it approximates the gap there without explaining it; the "
    "selection runs again without it and what it would have absorbed stays unexplained.",
    "Shrink, re-simulated: the twin run again with every added candidate at its fitted values "
    "(its seeds of the spread; signal artefacts post-processed on those runs), the held-out gap "
    "measured on them with the same statistic; the verdict follows it. Interpolated: from the "
    "candidates' responses on their grids (one seed, linear between grid values, added). The gap "
    "maps and the regions' \"after\" are interpolated.",
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


def _worse_cells(worse: list[dict], rows, cols, pick) -> list[tuple[int, int]]:
    """(row, column) indices of the map cells holding a region made worse."""
    out = set()
    for d in worse:
        rc = pick(Region(d["domain"], d["channel"], d["family"], d["bin"]))
        if rc is not None and rc[0] in rows and rc[1] in cols:
            out.add((rows.index(rc[0]), cols.index(rc[1])))
    return sorted(out)


def _pair(path: Path, before: np.ndarray, after: np.ndarray, rows, cols, what: str,
          worse_cells: list[tuple[int, int]] = ()) -> None:
    finite = np.concatenate([before[np.isfinite(before)], after[np.isfinite(after)], [10.0]])
    vmax = float(np.log10(np.max(finite)))
    fig, axes = plt.subplots(1, 2, figsize=(11, 0.35 * len(rows) + 2.2), constrained_layout=True)
    _map(axes[0], before, rows, cols, f"{what}: before (held-out)", vmax)
    title = f"{what}: after adding the effects (held-out)"
    if worse_cells:
        title += "\noutlined: made worse"
    im = _map(axes[1], after, rows, cols, title, vmax)
    for i, j in worse_cells:
        axes[1].add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor="cyan", lw=2))
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
    worse = result.get("worse_regions", [])
    pngs = []

    bands = _band_labels(PHASE1_BANDS_HZ)
    pick1 = lambda r: (r.channel, r.bin) if r.domain == "phase1" and r.family == "band" else None  # noqa: E731
    if any(pick1(r) for r in regions):
        p = out_dir / "gap_phase1_channel_band.png"
        _pair(p, _cells(z_b, regions, list(PHASE1_CHANNELS), bands, pick1),
              _cells(z_a, regions, list(PHASE1_CHANNELS), bands, pick1),
              list(PHASE1_CHANNELS), bands, "Phase I channel × band",
              _worse_cells(worse, list(PHASE1_CHANNELS), bands, pick1))
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
              rows, segs, "Phase II error motion × stroke segment", _worse_cells(worse, rows, segs, pick2))
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
          ch_rows, cols, "channel × operating phase", _worse_cells(worse, ch_rows, cols, pick3))
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
        red = [100 * r.get("net_reduction", r["heldout_reduction"]) for r in ranking]
        colors = ["tab:green" if r["significant"] else "tab:gray" for r in ranking]
        axes[1].barh(range(len(names)), red, color=colors)
        axes[1].set_yticks(range(len(names)), names, fontsize=7)
        axes[1].invert_yaxis()
        axes[1].set_xlabel("net held-out gap reduction, % (green: passes the test)")
    axes[1].set_title("candidates (added ones first, then the last round)", fontsize=9)
    p = out_dir / "gap_hours_and_ranking.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    pngs.append(p)

    write_text(out_dir / "index.html", render_page(result, pngs))
    return pngs


#: The least held-out reduction of a candidate whose edge flags the ranking table shows.
NOTE_FROM = 0.01

_CAPTIONS = {
    "gap_phase1_channel_band": "Phase I: channel × frequency band, before and after adding the effects.",
    "gap_phase2_position_error_motion": "Phase II: error motion × stroke segment (and the E_XX "
                                        "shift between sessions), before and after.",
    "gap_operating_phase": "Every channel × operating phase (RMS) and level, before and after.",
    "gap_hours_and_ranking": "Left: the held-out gap per operating hours. Right: the candidates' "
                             "net held-out reduction in the last round.",
}


def _worse_text(regions: list[dict]) -> str:
    if not regions:
        return ""
    more = f" and {len(regions) - 2} more" if len(regions) > 2 else ""
    return f"{len(regions)}: " + "; ".join(w.region(r) for r in regions[:2]) + more


def page_context(result: dict, pngs: list[Path]) -> dict:
    """What ``index.html`` shows, as plain strings (the template only lays them out)."""
    verdict = result["verdict"]
    cls = {"explained": "verdict-explained", "no significant gap": "verdict-none"}.get(
        verdict, "verdict-unexplained")
    facts = [f"recording {result.get('recording', '–')}", f"scenario {result.get('scenario', '–')}",
             f"{result.get('seeds', len(result.get('twin_seeds', [])))} twin seeds",
             f"α = {w.number(result.get('alpha', 0.01), 2)}",
             f"held-out gap {w.gap_number(result['heldout_gap_before'])} (the spread allows "
             f"{w.gap_number(result['heldout_gap_critical'])})"]
    if result["verdict"] != "no significant gap" or w.resimulation_summary(result):
        facts.append(f"shrink {w.shrink_phrase(result)}")
    title_of = lambda e: result.get("library", {}).get(e, {}).get("title", e)  # noqa: E731
    added = [{"step": a.get("step", i + 1), "title": title_of(a["effect"]), "effect": a["effect"],
              "kind": w.kind(result, a["effect"]), "words": w.added_phrase(result, a),
              "reduction": w.percent(a["heldout_reduction"]),
              "worse": _worse_text(a.get("worse_regions", [])),
              "params": w.parameters(result, a)}
             for i, a in enumerate(result.get("added", []))]
    refused = [{"pass": r["pass"], "title": title_of(r["effect"]), "effect": r["effect"],
                "kind": w.kind(result, r["effect"]), "words": w.owner_phrase(result, r),
                "reduction": w.percent(r["heldout_reduction"]), "n": r["footprint_statistics"],
                "left": w.percent(r["footprint_gap_left"])}
               for r in result.get("refused", [])]
    ranking = []
    for i, r in enumerate(result.get("ranking", [])):
        pars = w.parameters(result, r)
        ranking.append({
            "rank": i + 1, "title": title_of(r["effect"]), "effect": r["effect"],
            "kind": w.kind(result, r["effect"]),
            "fit": "; ".join(f"{p['label']} {p['value']} ({p['interval']})" for p in pars),
            # Edge notes where the candidate removes something: a candidate fitted to nothing
            # (its amplitude at zero) sits on an edge of the others' grids without meaning.
            "notes": [f"{p['label']}: {p['note']}" for p in pars
                      if p["note"] and r["heldout_reduction"] >= NOTE_FROM],
            "reduction": w.percent(r["heldout_reduction"]),
            "worse": (_worse_text(r.get("worse_regions", []))
                      + (f" (−{w.gap_number(r['worse_penalty'])})" if r.get("worse_penalty") else "")),
            "net": w.percent(r.get("net_reduction", r["heldout_reduction"])),
            "passes": "yes" if r["significant"] else "no"})
    worse = [{"region": w.region(r), "n": r["n_statistics"],
              "before": w.gap_number(r["heldout_gap_before"]), "after": w.gap_number(r["heldout_gap_after"]),
              "increase": w.gap_number(r["increase"]), "threshold": w.gap_number(r["threshold"])}
             for r in result.get("worse_regions", [])]
    regions = [{"region": w.region(r), "calibration": w.gap_number(r["calibration_gap"]),
                "before": w.gap_number(r["heldout_gap_before"]), "after": w.gap_number(r["heldout_gap_after"])}
               for r in [r for r in result.get("regions", []) if r["significant"]][:15]]
    found = result.get("found_by_check") or []
    blank = (f" Blank cells: statistics of {', '.join(f['channel'] for f in found)} left out (twin check flags "
             "the channel)." if found else "")
    figures = [{"link": q.name, "alt": q.stem.replace("_", " "),
                "caption": _CAPTIONS.get(q.stem, q.stem.replace("_", " ")) + blank} for q in pngs]
    rs = w.resimulation_summary(result)
    if rs is not None:
        before = result.get("verdict_interpolated", verdict)
        other = "" if before == verdict else f" (interpolated, it would be: {before})"
        resim = (f"The twin re-simulated with the added candidates at their fitted values ({rs['seeds']} "
                 f"twin seed{'s' if rs['seeds'] != 1 else ''}, signal artefacts post-processed on its "
                 f"campaigns): held-out gap {w.gap_number(rs['heldout_gap_before'])} → "
                 f"{w.gap_number(rs['heldout_gap_after'])}, shrink {w.percent(rs['heldout_shrink'])}; "
                 f"interpolated from the candidates' responses: {w.gap_number(result['heldout_gap_after'])}, "
                 f"shrink {w.percent(result['heldout_shrink'])}. The verdict follows the re-simulated "
                 f"shrink{other}.")
    elif result.get("added"):
        resim = ("Not re-simulated ("
                 f"{(result.get('resimulation') or {}).get('reason') or 'not asked for'}): the shrink is "
                 "interpolated from the candidates' responses.")
    else:
        resim = ""
    return {"title": f"Gap diagnosis: {verdict}", "verdict": verdict, "verdict_class": cls, "resim": resim,
            "answer": [{"head": h, "text": t} for h, t in w.answer_parts(result)],
            "facts": facts, "subset": w.subset_phrase(result) or "",
            "calibration": calibration_phrase(result), "added": added, "refused": refused,
            "found": "; ".join(f"{f['effect'] or f['channel'] + ' ' + f['finding']}"
                               + (f" at ±{w.with_unit(w.number(f['params']['range']), f.get('unit', ''))}"
                                  if f["params"].get("range") is not None else "") for f in found),
            "ranking": ranking, "left_out": result.get("candidates_left_out", {}),
            "worse": worse, "regions": regions, "figures": figures, "rules": list(RULES)}


def calibration_phrase(result: dict) -> str:
    """What ``twin calibrate`` fitted and measured before this diagnosis (its ``calibration``
    entry), in one paragraph; "" for a scenario that was not calibrated."""
    cal = result.get("calibration")
    if not cal:
        return ("The scenario was not calibrated (`twin calibrate`): a difference of the drive's "
                "parameters or the sensor chain shows as a gap here.")
    fitted = ", ".join(f"{v['key']} {w.number(v['value'])}" + (f" ({w.number(v['low'])}–{w.number(v['high'])})"
                                                               if v.get("low") is not None else "")
                       for v in cal["values"] if v["source"] == "fitted")
    measured = ", ".join(v["key"] for v in cal["values"] if v["source"] == "measured")
    return (f"The twin was calibrated to {cal['recording']}: fitted {fitted or 'nothing'}; measured "
            f"{measured or 'nothing'}; left at the twin's default: {', '.join(cal['defaults']) or 'nothing'}. "
            f"{cal['candidates']}{refit_phrase(result)}")


def refit_phrase(result: dict) -> str:
    """The calibration fitted again with a candidate effect in the twin (the result's ``refit``
    entries, their sentences, and ``before_refit`` when one explained), for the page; "" when none
    was tried."""
    said = " ".join(r["sentence"] for r in result.get("refit") or [])
    before = result.get("before_refit")
    if before:
        said += (f" This diagnosis is against the refitted twin, with {refit_explaining(result)} "
                 f"its only candidate; against the twin as first calibrated: {before['verdict']} (held-out gap "
                 f"{w.gap_number(before['heldout_gap_before'])} for a critical "
                 f"{w.gap_number(before['heldout_gap_critical'])}; added: {', '.join(before['added']) or 'nothing'}; "
                 f"refused: {', '.join(before['refused']) or 'nothing'}).")
    return f" {said}" if said else ""


def refit_explaining(result: dict) -> str | None:
    """The effect whose refit explains a diagnosis's ``result`` (it is the diagnosis against
    the twin refitted with it: ``before_refit``), or None."""
    if not result.get("before_refit"):
        return None
    return next((r["effect"] for r in result.get("refit") or [] if r.get("explains")), None)


def render_page(result: dict, pngs: list[Path]) -> str:
    """``index.html`` of the diagnosis ``result`` with the figures ``pngs`` (same directory)."""
    return _ENV.get_template("diagnosis.html.j2").render(**page_context(result, pngs))
