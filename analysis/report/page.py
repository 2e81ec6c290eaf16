"""The report page: what each section says, as plain data (paragraphs, tables, figure pairs),
rendered to ``OUT/index.html`` by the Jinja2 template ``templates/report.html.j2`` (every value
HTML-escaped by the template)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jinja2

from analysis.base.files import write_text
from analysis.dataset import DatasetError
from analysis.report.compare import (
    _f,
    _finite,
    _method_names,
    _phase1_methods,
    _signed,
    compare_fig6,
    compare_fig10,
    compare_fig11,
    compare_fig12,
    compare_fig13,
)
from analysis.report.figures import Figures
from analysis.report.inputs import Inputs, ReportError, read_inputs
from analysis.report.paper import COMMANDS, PAPER_FIGURES, PAPER_T2_NOTE, PAPER_TABLE_III
from analysis.scoring import ScoreError

__all__ = ["INPUT_ERRORS", "Report", "render", "write_report"]

#: Errors the CLI turns into exit code 2.
INPUT_ERRORS = (ReportError, ScoreError, DatasetError)

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("analysis.report", "templates"),
                          autoescape=True, undefined=jinja2.StrictUndefined, keep_trailing_newline=True)

Block = dict[str, Any]


# --------------------------------------------------------------------------------------------
# Blocks: what the template knows how to draw


def _p(text: str, ident: str | None = None, cls: str | None = None) -> Block:
    return {"kind": "p", "text": text, "id": ident, "cls": cls}


def _table(headers, rows, ident: str | None = None, caption: str | None = None) -> Block:
    return {"kind": "table", "headers": list(headers), "rows": [list(map(str, r)) for r in rows],
            "id": ident, "caption": caption}


def _missing(what: str, files: list[Path], command: str, d: Path) -> Block:
    """``files`` are missing; ``command`` (``{dir}``: the campaign directory ``d``) creates them."""
    return {"kind": "missing", "what": what, "files": ", ".join(str(p) for p in files),
            "command": command.format(dir=d)}


def _heading(text: str, ident: str) -> Block:
    return {"kind": "h3", "text": text, "id": ident}


def _image(link: str, alt: str, caption: str) -> dict:
    return {"link": link, "alt": alt, "caption": caption}


def _no_figure(fig: str, phase: str, phase_missing: bool, figs: Figures, command: str) -> Block:
    """What stands in place of our figure: the phase was not run, or only its PNG is missing."""
    if phase_missing:
        return _p(f"No Fig. {fig} analogue: {phase} was not run (see above).", cls="missing")
    return _missing(f"Our Fig. {fig} analogue", [figs.source(fig)], command, figs.directory)


def _figure_pair(fig: str, link: str | None, ours_caption: str, comparison: str, missing: Block) -> Block:
    """Our figure (or ``missing``) beside the paper's findings, and the comparison line."""
    title, paper = PAPER_FIGURES[fig]
    return {"kind": "figure_pair", "fig": fig, "title": title, "paper": paper, "comparison": comparison,
            "image": _image(link, f"our Fig. {fig} analogue", f"Ours: {ours_caption}") if link else None,
            "missing": missing}


# --------------------------------------------------------------------------------------------
# Sections


def _dig(obj, keys):
    for k in keys:
        if not isinstance(obj, dict) or k not in obj:
            return None
        obj = obj[k]
    return obj


def _show(v) -> str:
    if v is None:
        return "–"
    if isinstance(v, list):
        return ", ".join(_show(x) for x in v) if v else "[]"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _scenario_rows(s: dict) -> list[tuple[str, str]]:
    """Key parameters of a scenario (the truth.h5 JSON) as (name, value) rows."""

    def g(*keys):
        return _dig(s, keys)

    d = s.get("degradation", {})
    rows = [("name", g("name")), ("description", g("description")), ("seed", g("seed")),
            ("travel / lead (mm)", f"{g('axis', 'travel_mm')} / {g('axis', 'lead_mm')}"),
            ("preload when new (N)", g("axis", "preload_N"))]
    if d.get("law") == "table":
        rows += [("degradation law", "table"),
                 ("table: hours", d.get("table_hours")),
                 ("table: preload fraction", d.get("table_preload_fraction")),
                 ("table: backlash (µm)", d.get("table_backlash_um"))]
    elif d.get("law", "wear") != "wear":  # a plug-in law (twin.sim.laws): the whole section
        rows += [("degradation law", d.get("law"))] + [
            (f"degradation: {k}", v) for k, v in d.items() if k != "law"]
    else:
        rows += [("degradation law", d.get("law")),
                 ("wear onset (h)", d.get("onset_hours")),
                 ("wear rate (µm per 1000 h)", d.get("wear_rate_um_per_kh")),
                 ("ball interference (µm)", d.get("interference_um")),
                 ("interference scatter (µm)", d.get("scatter_um"))]
    rows += [
        ("campaign length (h)", g("campaign", "total_hours")),
        ("campaign scale", g("campaign", "scale")),
        ("Phase I: sample interval (h)", g("phase1", "sample_interval_hours")),
        ("Phase I: captures per sample × length (s)",
         f"{g('phase1', 'captures_per_sample')} × {g('phase1', 'capture_s')}"),
        ("Phase I: speed (mm/s)", g("phase1", "speed_mm_s")),
        ("Phase II: session hours", g("phase2", "session_hours")
         or f"every {g('phase2', 'session_interval_hours')} h"),
        ("Phase II: runs per session", g("phase2", "runs_per_session")),
        ("Phase II: speeds (mm/s)", g("phase2", "speeds_mm_s")),
        ("Phase II: origin offset up to (mm)", g("phase2", "origin_offset_max_mm")),
        ("IMU accelerometer noise (µg/√Hz)", g("sensors", "imu_acc_noise_ug_per_rthz")),
        ("IMU gyroscope noise (µrad/s/√Hz)", g("sensors", "imu_gyro_noise_urad_s_per_rthz")),
        ("rail straightness RMS vertical / lateral (µm)",
         f"{g('geometry', 'straightness_rms_um')} / {g('geometry', 'lateral_straightness_rms_um')}"),
    ]
    return [(k, _show(v)) for k, v in rows]


def _section_scenario(inp: Inputs) -> list[Block]:
    if inp.scenario is not None:
        return [_table(("parameter", "value"), _scenario_rows(inp.scenario), "scenario-table"),
                _p(f"Injected onset of degradation: {_f(inp.onset_hours, '{:g} h')} (truth.h5)."),
                {"kind": "details", "summary": "The whole scenario (truth.h5, JSON)",
                 "text": json.dumps(inp.scenario, indent=1, sort_keys=True)}]
    out = [_missing("The scenario", [inp.directory / "truth.h5"], COMMANDS["measurements"], inp.directory),
           _p("Recordings of a real machine have no truth.h5: there are no injected values to score against.")]
    if inp.axis:
        out.append(_table(("axis (measurements.h5)", "value"),
                          [(k, _show(v)) for k, v in sorted(inp.axis.items())], "axis-table"))
    return out


def _phase1_scores(inp: Inputs, methods: dict, names: dict[str, str]) -> list[Block]:
    p1 = (inp.score or {}).get("phase1") or {}
    n = p1.get("n_samples") or (inp.details or {}).get("n_samples")
    nb = p1.get("n_baseline") or (inp.details or {}).get("n_baseline")
    out = [_p(f"{_f(n)} samples, the first {_f(nb)} the baseline; injected onset "
              f"{_f(inp.onset_hours, '{:g} h')}. Delay = detection − onset; false alarms are alarms on "
              "post-baseline samples at or before the onset.")]
    rows = []
    for k, r in methods.items():
        fa = (f"{r['false_alarms']} / {r['healthy_test_samples']}"
              if _finite(r.get("false_alarms")) and _finite(r.get("healthy_test_samples")) else "–")
        rows.append((names.get(k, k), _f(r.get("threshold"), "{:.4g}"), _f(r.get("detection_hours")),
                     _f(r.get("delay_hours"), "{:+g}"), _f(r.get("delay_samples")), fa,
                     _f(r.get("baseline_alarms"))))
    out.append(_table(("method", "limit", "detection (h)", "delay from onset (h)", "delay (samples)",
                       "false alarms / healthy", "baseline alarms"), rows, "phase1-scores"))
    if inp.score is None and inp.scenario is None:
        out.append(_p("No truth.h5: delays and false alarms cannot be scored."))
    sel = (inp.details or {}).get("selected_features")
    if sel:
        out.append(_p(f"Fisher-selected features: {', '.join(sel)}."))
    return out


def _table_iii(inp: Inputs, methods: dict, names: dict[str, str]) -> list[Block]:
    """Table III side by side: the paper's detection hours and ours."""
    ref = (methods.get("pca_t2") or {}).get("detection_hours")
    rows = []
    for key, pname, inp_col, metric, hours, note in PAPER_TABLE_III:
        r = methods.get(key) or {}
        h = r.get("detection_hours")
        vs_ref = _signed(h - ref) if _finite(h) and _finite(ref) else "–"
        rows.append((f"{pname} ({names.get(key, key)})", inp_col, metric,
                     f"{hours:g}" + ("*" if note else ""), _signed(hours - 2972.0), _f(h), vs_ref,
                     _signed(r.get("delay_hours")) if "delay_hours" in r else "–"))
    for key, r in methods.items():  # methods the paper does not have
        if key not in {t[0] for t in PAPER_TABLE_III}:
            h = r.get("detection_hours")
            rows.append((names.get(key, key), "–", "–", "–", "–", _f(h),
                         _signed(h - ref) if _finite(h) and _finite(ref) else "–",
                         _signed(r.get("delay_hours"))))
    caption = (f"Injected onset here: {_f(inp.onset_hours, '{:g} h')}. * {PAPER_TABLE_III[3][5]}. "
               + PAPER_T2_NOTE)
    out = [_heading("Table III: detection point per method, paper and ours", "table-iii"),
           _table(("method", "input (paper)", "metric (paper)", "paper: detection (h)", "paper: vs PCA (h)",
                   "ours: detection (h)", "ours: vs PCA-T² (h)", "ours: delay from injected onset (h)"),
                  rows, "table-iii", caption=caption)]
    if inp.detection is None:
        out.append(_p("Our columns are empty: Phase I was not run."))
    return out


def _section_phase1(inp: Inputs, figs: Figures, names: dict[str, str]) -> list[Block]:
    d = inp.directory
    methods = _phase1_methods(inp.score, inp.details, inp.detection)
    out: list[Block] = []
    missing = inp.detection is None
    if missing:
        out.append(_missing("Phase I", [d / "phase1" / "detection.json"], COMMANDS["phase1"], d))
    if methods:
        out += _phase1_scores(inp, methods, names)
    out += _table_iii(inp, methods, names)
    link = figs.copy("6")
    caption = ("score of each method against operating hours, its limit, the baseline, the "
               "injected onset and the detection")
    if link is None and inp.detection is not None:
        link = figs.draw_fig6(inp.detection, inp.details, inp.onset_hours, names)
        caption += " (drawn from detection.json: detection.png was missing)"
    out.append(_figure_pair("6", link, caption,
                            compare_fig6(methods, inp.onset_hours, inp.detection, names, inp.preload),
                            _no_figure("6", "Phase I", missing, figs, COMMANDS["phase1"])))
    return out


def _estimators(ests: dict) -> list[Block]:
    """Every backlash estimator found in the directory, side by side (score.json's
    ``phase2_estimators``; ``twin backlash --estimator NAME`` adds one)."""
    rows = [(f"{r.get('label') or name} [{name}]", r.get("n_sessions"),
             _f(r.get("rms_error_um"), "{:.3f}"), _f(r.get("max_abs_error_um"), "{:.3f}"),
             _f(r.get("bias_um"), "{:+.3f}"), _f(r.get("rms_error_vs_lost_motion_um"), "{:.3f}"),
             _f((r.get("prognosis") or {}).get("error_hours"), "{:+.0f}"))
            for name, r in ests.items()]
    return [_p(f"{len(ests)} backlash estimator{'s' if len(ests) != 1 else ''} found in backlash/ "
               "(the default in backlash/, others in backlash/NAME/), scored against the injected "
               "change; the tables below are the first one's."),
            _table(("estimator", "sessions", "RMS error (µm)", "largest |error| (µm)", "bias (µm)",
                    "RMS error vs lost motion (µm)", "prognosis error (h)"), rows,
                   "phase2-estimators")]


def _phase2_scored(p2: dict) -> list[Block]:
    """The per-session table and the summary of score.json's phase2."""
    k = p2.get("baseline_sessions", 1)
    against = "the first session" if k == 1 else f"the mean of the first {k} sessions"
    out = [_p(f"Change of backlash against {against} (estimated by signal shifts, Eq. 6, and by "
              "perceived pitch, Eq. 9) next to the injected change (truth.h5) and the dial indicator.")]
    rows = [(r["session"], _f(r["hours"]), _f(r["injected_delta_um"], "{:.3f}"),
             _f(r["estimated_delta_um"], "{:.3f}"), _f(r["error_um"], "{:+.3f}"),
             _f(r.get("injected_lost_motion_delta_um"), "{:.3f}"),
             _f(r.get("error_vs_lost_motion_um"), "{:+.3f}"),
             _f(r.get("pitch_estimated_delta_um"), "{:.3f}"), _f(r.get("smoothed_um"), "{:.3f}"),
             _f(r.get("dial_delta_um"), "{:.3f}")) for r in p2["sessions"]]
    out.append(_table(("session", "hours", "injected Δ (µm)", "estimated Δ (µm)", "error (µm)",
                       "injected lost-motion Δ (µm)", "error vs lost motion (µm)", "by pitch Δ (µm)",
                       "Kalman-smoothed (µm)", "dial Δ (µm)"), rows, "phase2-sessions"))
    out.append(_p("Lost motion = clearance + 2·F/K, the elastic deflection of the nut under the rail "
                  "friction F at the drive's axial stiffness K (truth.h5): what a reversal measures, and "
                  "what grows beyond the clearance as the preload falls."))
    prog = p2.get("prognosis") or {}
    limit = _f(prog.get("limit_um"))
    summary = [("RMS error (µm)", _f(p2.get("rms_error_um"), "{:.3f}")),
               ("largest |error| (µm)", _f(p2.get("max_abs_error_um"), "{:.3f}")),
               ("mean error (bias, µm)", _f(p2.get("bias_um"), "{:+.3f}")),
               ("RMS error vs lost motion (µm)", _f(p2.get("rms_error_vs_lost_motion_um"), "{:.3f}")),
               ("RMS error by pitch (µm)", _f(p2.get("pitch_rms_error_um"), "{:.3f}")),
               (f"{limit} µm crossing: predicted (h)", _f(prog.get("predicted_crossing_hours"), "{:.0f}")),
               (f"{limit} µm crossing: injected (h)", _f(prog.get("true_crossing_hours"), "{:.0f}")),
               ("prognosis error (h)", _f(prog.get("error_hours"), "{:+.0f}")),
               ("skipped runs", _f(p2.get("skipped_runs")))]
    out.append(_table(("score", "value"), summary, "phase2-summary"))
    em = p2.get("error_motions")
    if em:
        out.append(_table(("error motion", "RMS error, whole stroke", "RMS error in the resolved band",
                           "true RMS in the band", "resolved band (mm)", "unit"),
                          _error_motion_rows(em), "error-motions",
                          caption=f"Error-motion recovery against the true error motions (median over "
                                  f"{em.get('sessions')} sessions), after removing the unobservable terms "
                                  "(E_XX left out). The resolved band is where the recording's speeds, "
                                  "runs and IMU noise determine the traces to 0.2 µm (translations) or "
                                  "1 µrad (angles); outside it, the traces are not a measurement."))
    return out


def _error_motion_rows(em: dict) -> list[tuple]:
    ib = em.get("in_band") or {}
    rows = []
    for unit, label in (("rms_um", "µm"), ("rms_urad", "µrad")):
        for dof, v in em.get(unit, {}).items():
            band = (ib.get("band_mm") or {}).get(dof)
            rows.append((dof, _f(v, "{:.3g}"), _f((ib.get(unit) or {}).get(dof), "{:.3g}"),
                         _f((ib.get("true_" + unit) or {}).get(dof), "{:.3g}"),
                         "not resolved" if ib and band is None else
                         (f"{band[0]:.3g}–{band[1]:.3g}" if band else _f(None)), label))
    return rows


def _phase2_unscored(bl: dict) -> list[Block]:
    rows = [(s["session"], _f(s["hours"]), _f(s.get("delta_backlash_um_shift"), "{:.3f}"),
             _f(s.get("delta_backlash_um_pitch"), "{:.3f}"), _f(s.get("smoothed_um"), "{:.3f}"),
             _f(s.get("dial_delta_um"), "{:.3f}")) for s in bl.get("sessions", [])]
    return [_p("No truth.h5: the estimates cannot be scored."),
            _table(("session", "hours", "by shifts Δ (µm)", "by pitch Δ (µm)", "Kalman-smoothed (µm)",
                    "dial Δ (µm)"), rows, "phase2-sessions")]


def _prognosis(bl: dict) -> list[Block]:
    out = []
    if bl.get("prognosis"):
        p = bl["prognosis"]
        band = p.get("band_hours") or [None, None]
        out.append(_p(f"Prognosis (ours: the paper has none) at {_f(p.get('at_hours'))} h: "
                      f"level {_f(p.get('level_um'), '{:.3g}')} µm, "
                      f"rate {_f(p.get('rate_um_per_kh'), '{:.3g}')} µm per 1000 h; "
                      f"{_f(p.get('limit_um'))} µm reached at {_f(p.get('crossing_hours'), '{:.0f}')} h "
                      f"(95 % band {_f(band[0], '{:.0f}')}–{_f(band[1], '{:.0f}')} h)."))
    if bl.get("skipped_runs"):
        out.append(_table(("session", "run", "reason"),
                          [(r["session"], r["run"], r["reason"]) for r in bl["skipped_runs"]],
                          "skipped-runs", caption="Runs left out of the estimates"))
    return out


_PHASE2_CAPTIONS = {
    "10": ("E_XX's position shift of each session against the first, forward and reverse, whole and "
           "zoomed (as the paper), and ours: forward − reverse of the DOFs the estimate sums"),
    "11": "ΔPositionShift (forward − reverse) per DOF against operating hours",
    "12": ("γ per DOF, the DOF of the highest γ without E_XX, and ΔBacklash per DOF with their "
           "weighted sum"),
    "13": ("estimated change of backlash by shifts (a) and by pitch (b), each with its Savitzky–Golay "
           "filtered curve (as the paper); ours: the Kalman-smoothed trend, the dial indicator and the "
           "injected change"),
}


def _section_phase2(inp: Inputs, figs: Figures) -> list[Block]:
    d = inp.directory
    p2 = (inp.score or {}).get("phase2")
    bl = inp.backlash
    out: list[Block] = []
    if bl is None:
        out.append(_missing("Phase II", [d / "backlash" / "backlash.json"], COMMANDS["phase2"], d))
    ests = (inp.score or {}).get("phase2_estimators") or {}
    if ests:
        out += _estimators(ests)
    if p2:
        out += _phase2_scored(p2)
    elif bl is not None:
        out += _phase2_unscored(bl)
    if bl is not None:
        out += _prognosis(bl)
    compare = {"10": lambda: compare_fig10(bl), "11": lambda: compare_fig11(bl, p2),
               "12": lambda: compare_fig12(bl), "13": lambda: compare_fig13(bl, p2)}
    for fig, caption in _PHASE2_CAPTIONS.items():
        link = figs.copy(fig)
        if link is None and bl is not None:
            link = figs.draw_phase2(fig, bl, p2)
            caption += " (drawn from backlash.json: the PNG of twin backlash was missing)"
        cmp = "No Phase II estimates to compare." if bl is None else compare[fig]()
        out.append(_figure_pair(fig, link, caption, cmp,
                                _no_figure(fig, "Phase II", bl is None, figs,
                                           COMMANDS["phase2"] + " (with its default --plots)")))
    others = [(f, link) for f in ("7", "8", "9") if (link := figs.copy(f))]
    if others:
        out.append(_heading("Figs. 7–9: slow-speed traces, winfilt, correlation", "figs7-9"))
        out.append({"kind": "figure_row",
                    "images": [_image(link, f"our Fig. {f} analogue", f"Ours, Fig. {f} analogue")
                               for f, link in others]})
    return out


# --------------------------------------------------------------------------------------------
# The page


@dataclass
class Report:
    """What :func:`render` wrote: ``index`` (OUT/index.html), ``figures`` (PNGs in OUT/figures),
    ``missing`` (phases whose outputs were absent), ``notes``."""

    index: Path
    figures: list[Path]
    missing: list[str]
    notes: list[str]


def render(directory: str | Path, out: str | Path | None = None) -> Report:
    """Write the report of ``directory`` to ``out`` (default ``directory/report``).

    Raises:
        ReportError, DatasetError, ScoreError (all ValueError): bad or empty input, naming the
            file and what is missing; OSError: OUT cannot be written.
    """
    inp = read_inputs(directory)
    d = inp.directory
    out = Path(out) if out is not None else d / "report"
    out.mkdir(parents=True, exist_ok=True)
    figs = Figures(d, out)
    names = _method_names()
    for k, v in ((inp.detection or {}).get("methods") or {}).items():
        names.setdefault(k, v.get("label") or k)  # a module:Class detector names itself
    missing = [p for p, ok in (("Phase I", inp.detection is not None),
                               ("Phase II", inp.backlash is not None)) if not ok]
    notes = list(inp.notes)
    if missing:
        notes.append("Missing: " + ", ".join(missing) + " (see the sections above).")
    sections = [
        {"id": "scenario", "title": "Scenario", "blocks": _section_scenario(inp)},
        {"id": "phase1", "title": "Phase I: incipient-fault detection", "blocks": _section_phase1(inp, figs, names)},
        {"id": "phase2", "title": "Phase II: backlash from the IMU", "blocks": _section_phase2(inp, figs)},
    ]
    html = _ENV.get_template("report.html.j2").render(
        title=f"Ball-screw health monitoring: {inp.scenario.get('name') if inp.scenario else d.name}",
        directory=str(d), sections=sections, notes=notes)
    index = write_text(out / "index.html", html)
    return Report(index=index, figures=figs.written, missing=missing, notes=notes)


def write_report(directory: str | Path, out: str | Path | None = None) -> Path:
    """Write ``OUT/index.html`` and its PNGs for the campaign ``directory``; returns the path of
    ``index.html``. ``out`` defaults to ``directory/report``. See :func:`render` for errors."""
    return render(directory, out).index
