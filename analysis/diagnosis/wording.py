"""The diagnosis in a person's words: fitted parameters with their units and sensible digits,
regions as places on the machine, a fit at the edge of its grid said as such, and the
one-paragraph answer at the top of the report.

Everything here reads the JSON-able result of :func:`analysis.diagnosis.attribution.diagnose`
as written to ``diagnosis.json``: how a parameter is printed (label, unit, significant digits,
the ends of its fit grid) comes from the result's ``library`` entry, which the twin writes from
its effect definitions (one source; this module never imports the twin). A parameter without
such an entry is printed by its name, without a unit, to 3 significant digits.
"""

from __future__ import annotations

import math

import numpy as np

from analysis.diagnosis.signature import DRAG_TERMS

#: A thin space that does not break: the thousands separator of large gaps ("527 764").
THIN = "\u202f"
#: The typographic minus sign.
MINUS = "\u2212"

_PHASE_WORDS = {"phase1": "Phase I", "phase2": "Phase II"}


def number(v: float, digits: int = 3) -> str:
    """``v`` to ``digits`` significant digits, positional (never 1e+03), trailing zeros and a
    trailing point dropped, a typographic minus: 0.0325 → "0.033" (2), 292.9 → "290" (2),
    −5000 → "−5000", 0.3 → "0.3". NaN/inf → "–"."""
    if v is None or not math.isfinite(v):
        return "–"
    if v == 0:
        return "0"
    s = np.format_float_positional(float(v), precision=max(1, int(digits)), unique=False,
                                   fractional=False, trim="-")
    return s.replace("-", MINUS)


def gap_number(v: float) -> str:
    """A gap (a sum or mean of t²): whole and grouped by thousands at 100 and above
    ("527 764"), else 3 significant digits ("13.6")."""
    if v is None or not math.isfinite(v):
        return "–"
    if abs(v) >= 100:
        return f"{v:,.0f}".replace(",", THIN).replace("-", MINUS)
    return number(v, 3)


def percent(fraction: float) -> str:
    """0.3769 → "38 %"."""
    if fraction is None or not math.isfinite(fraction):
        return "–"
    pc = round(100 * fraction)
    return f"{pc:.0f} %".replace("-", MINUS) if pc != 0 else "0 %"


def spec(result: dict, effect: str, param: str) -> dict:
    """How ``effect``'s ``param`` is printed: label, unit, digits (and grid, when known). A twin
    parameter's factor is printed as the absolute value of its (first) key: the quantity, its
    unit and digits, the grid times the nominal value (``scale``: what multiplies a fitted
    factor; 1 for every other parameter)."""
    lib = result.get("library", {}).get(effect, {})
    entry = lib.get("params", {}).get(param, {})
    nominal = lib.get("nominal") if lib.get("kind") == "parameter" else None
    if nominal:
        grid = entry.get("grid")
        return {"label": lib.get("quantity", param), "unit": lib.get("unit", ""),
                "digits": int(lib.get("digits", 3)), "scale": float(nominal[0]),
                "grid": [g * float(nominal[0]) for g in grid] if grid else None}
    return {"label": entry.get("label", param), "unit": entry.get("unit", ""),
            "digits": int(entry.get("digits", 3)), "grid": entry.get("grid"), "scale": 1.0}


def with_unit(text: str, unit: str) -> str:
    """ "0.033" + "N·m" → "0.033 N·m"; a ratio "×" is written against the number ("0.3×")."""
    if not unit:
        return text
    return f"{text}{unit}" if unit == "×" else f"{text} {unit}"


def value(v: float, sp: dict) -> str:
    """A parameter's value with its unit: "0.033 N·m", "18 per revolution"."""
    return with_unit(number(v, sp["digits"]), sp["unit"])


def span(lo: float, hi: float, sp: dict) -> str:
    """A range with its unit once: "0.025–0.035 N·m"."""
    return with_unit(f"{number(lo, sp['digits'])}–{number(hi, sp['digits'])}", sp["unit"])


def edge_note(edge: str | None, grid: list[float] | None, sp: dict) -> str:
    """What a fit at the edge of its grid means ("" inside): "at the lower edge of the tried
    range 0.3–1×: the true value may lie beyond"."""
    if not edge:
        return ""
    tried = f" {span(grid[0], grid[1], sp)}" if grid else ""
    if edge == "both":
        return f"the interval spans the whole tried range{tried}: the data do not bound it"
    side = "lower" if edge == "low" else "upper"
    return f"at the {side} edge of the tried range{tried}: the true value may lie beyond"


def parameters(result: dict, fit: dict) -> list[dict]:
    """One row per fitted parameter of ``fit`` (an entry of ``added`` or ``ranking``): label,
    value, interval, note (the edge). The parameter's digits, or up to 3 more where its
    interval needs them to show its width (0.102–0.103 N·m, not 0.1–0.1 N·m)."""
    rows = []
    for name, v in fit["params"].items():
        sp = spec(result, fit["effect"], name)
        lo, hi = fit.get("interval", {}).get(name, (float("nan"), float("nan")))
        v, lo, hi = v * sp["scale"], lo * sp["scale"], hi * sp["scale"]
        base = sp["digits"]
        while lo != hi and number(lo, sp["digits"]) == number(hi, sp["digits"]) \
                and sp["digits"] < base + 3:
            sp = {**sp, "digits": sp["digits"] + 1}
        grid = fit.get("grid", {}).get(name)
        grid = [g * sp["scale"] for g in grid] if grid else sp["grid"]
        rows.append({"label": sp["label"], "value": value(v, sp), "interval": span(lo, hi, sp),
                     "note": edge_note(fit.get("at_grid_edge", {}).get(name), grid, sp)})
    return rows


def fit_phrase(result: dict, fit: dict) -> str:
    """The fit in one phrase: "cogging torque 0.033 N·m (0.025–0.035 N·m), cogging order 18 per
    revolution (12–18 per revolution)"."""
    return ", ".join(f"{r['label']} {r['value']} ({r['interval']})" for r in parameters(result, fit))


def region(r: dict) -> str:
    """A region (domain, channel, family, bin) as a place on the machine: "Phase I torque,
    30-60 Hz band", "Phase II acc_x RMS in the transients", "Phase II error motion E_AX,
    stroke 18-84 mm"."""
    dom = _PHASE_WORDS.get(r["domain"], r["domain"])
    ch, fam, b = r["channel"], r["family"], r["bin"]
    if fam == "band":
        if " @" in b:
            band, speed = b.split(" @", 1)
            return f"{dom} {ch}, {band} band at {speed}"
        return f"{dom} {ch}, {b} band"
    if fam == "phase":
        return f"{dom} {ch} RMS in the {b} phase"
    if fam == "level":
        if b in ("dwell mean", *DRAG_TERMS):
            return f"{dom} {ch} {b}" + (" (fitted over the motion)" if b in DRAG_TERMS else "")
        return f"{dom} mean |{ch}| in the {b} phase"
    if fam == "feature":
        return f"{dom} feature {b}"
    if fam == "position":
        return f"{dom} error motion {ch}, stroke {b}"
    if fam == "timing":
        return f"{dom} {ch} lag behind the motor speed"
    if fam == "lag":
        return f"{dom} {ch} shift between sessions, stroke {b}"
    return f"{dom} {ch} {fam} {b}"


def _title(result: dict, effect: str) -> str:
    return result.get("library", {}).get(effect, {}).get("title", effect)


def kind(result: dict, effect: str) -> str:
    """The candidate's kind as the library entry states it: "physical effect" (simulated by
    the twin), "parameter" (a twin parameter set wrong, simulated) or "signal artefact"
    (applied to the recording's channels); "physical effect" when the entry does not say
    (results written before artefacts existed)."""
    return result.get("library", {}).get(effect, {}).get("kind", "physical effect")


def parameter_phrase(result: dict, fit: dict) -> str | None:
    """A twin parameter's fit in the owner's words, from the nominal value of the scenario the
    diagnosis ran with: "carriage mass 165 kg, not 120 kg (interval 158–171 kg)"; keys moved
    alike are joined ("guide block stiffness (vertical, lateral) 390 and 260 N/µm, not 300 and
    200 N/µm"). None for another kind or without the nominal value."""
    entry = result.get("library", {}).get(fit["effect"], {})
    nominal = entry.get("nominal")
    if entry.get("kind") != "parameter" or not nominal or len(fit["params"]) != 1:
        return None
    (name, f), = fit["params"].items()
    sp = spec(result, fit["effect"], name)
    iv = fit.get("interval", {}).get(name)
    sp = {**sp, "digits": max(sp["digits"], _digits_for(f))}
    both = lambda vals: with_unit(" and ".join(number(x, sp["digits"]) for x in vals), sp["unit"])  # noqa: E731
    text = f"{sp['label']} {both([f * n for n in nominal])}, not {both(nominal)}"
    if iv is not None and iv[0] != iv[1]:
        text += (f" (interval {parameters(result, fit)[0]['interval']})" if len(nominal) == 1 else
                 f" (interval {number(iv[0], 2)}–{number(iv[1], 2)}× the scenario's)")
    return text


def _digits_for(factor: float) -> int:
    """Digits enough to tell a fitted factor from 1 (a 3 % mis-setting is not "120 kg, not 120
    kg"): 3, or more for a factor within 1 %."""
    dev = abs(factor - 1.0)
    return 3 if dev >= 0.01 or dev == 0 else min(6, 3 + int(math.ceil(-math.log10(dev / 0.01))))


def owner_phrase(result: dict, fit: dict) -> str:
    """The fit in the owner's words: an artefact's ``phrase`` (library entry) with each
    ``{param}`` replaced by its fitted value and unit ("a 50 Hz line of 0.029 m/s² on acc1 and
    acc2 at every speed: electrical pickup"); a twin parameter's fitted and nominal values
    (:func:`parameter_phrase`); for another candidate, its title and :func:`fit_phrase`. The
    kind follows in brackets."""
    entry = result.get("library", {}).get(fit["effect"], {})
    phrase = entry.get("phrase")
    as_parameter = parameter_phrase(result, fit)
    if as_parameter:
        text = as_parameter
    elif phrase:
        vals = {n: value(v, spec(result, fit["effect"], n)) for n, v in fit["params"].items()}
        text = phrase.format(**vals)
        iv = fit.get("interval", {})
        rows = [r for n, r in zip(fit["params"], parameters(result, fit), strict=True)
                if n in iv and iv[n][0] != iv[n][1]]
        if rows:
            text += " (" + "; ".join(f"{r['label']} {r['interval']}" for r in rows) + ")"
    else:
        text = f"{_title(result, fit['effect'])}: {fit_phrase(result, fit)}"
    return f"{text} [{kind(result, fit['effect'])}]"


def added_phrase(result: dict, fit: dict) -> str:
    """:func:`owner_phrase` of an added candidate, followed by the candidates the data do not
    tell apart from it (its ``alternatives``): "support bearing stiffness 350 N/µm, not 750
    N/µm (…) [parameter], not told apart from nut stiffness 270 N/µm, not 400 N/µm (…)
    [parameter]"; an alternative that makes the same recording (:func:`same_recording`) comes
    first, as "the same recording as …"."""
    text = owner_phrase(result, fit)
    alts = fit.get("alternatives") or []
    same = [a for a in alts if same_recording(result, fit, a)]
    if same:
        text += ", the same recording as " + " or ".join(owner_phrase(result, a) for a in same)
    others = [a for a in alts if a not in same]
    if others:
        text += ", not told apart from " + " or ".join(owner_phrase(result, a) for a in others)
    return text


def same_recording(result: dict, x: dict, y: dict) -> bool:
    """Whether two fits make the same recording: a twin parameter whose ``library`` entry names
    the other as ``same_recording_above_one`` (a torque signal's noise floor and noise added on
    the torque: both white per sample), fitted above 1. No data can tell such a pair apart; the
    words say so rather than "not told apart"."""
    lib = result.get("library", {})
    return any(lib.get(a["effect"], {}).get("same_recording_above_one") == b["effect"]
               and a["params"].get("factor", 1.0) > 1.0 for a, b in ((x, y), (y, x)))


def refused_phrase(result: dict, fit: dict) -> str:
    """Why a candidate was refused (an entry of ``refused``): "base resonance …
    [physical effect] would remove 56 % of the held-out gap but leaves 38 % of the gap where it
    acts (18 statistics): it approximates the gap there, it does not explain it", and, for a fit
    at the edge of its grid, that it may beyond the tried range."""
    edges = [f"{r['label']} is {r['note']}" for r in parameters(result, fit) if r["note"]]
    return (f"{owner_phrase(result, fit)} would remove {percent(fit['heldout_reduction'])} of the "
            f"held-out gap but leaves {percent(fit['footprint_gap_left'])} of the gap where it acts "
            f"({fit['footprint_statistics']} statistics): it approximates the gap there, it does not "
            "explain it" + (f" within the tried range ({'; '.join(edges)})" if edges else ""))


def _places(rows: list[dict], k: int = 3) -> str:
    names = [region(r) for r in rows[:k]]
    if len(names) <= 1:
        return "".join(names)
    return "; ".join(names[:-1]) + " and " + names[-1]


def resimulation_summary(result: dict) -> dict | None:
    """The ``resimulation`` entry of a result when the twin was re-simulated with the added
    candidates, else None (nothing added, no gap, or results written before it existed)."""
    rs = result.get("resimulation")
    return rs if rs and rs.get("done") else None


def shrink_phrase(result: dict) -> str:
    """The held-out shrink, re-simulated and interpolated side by side: "99 % re-simulated (8
    seeds; 71 612 → 926), 99 % interpolated (→ 421)"; "no re-simulation: nothing was added"
    when the twin was not run again."""
    g0, g1 = result["heldout_gap_before"], result["heldout_gap_after"]
    rs = resimulation_summary(result)
    interp = (f"{percent(result['heldout_shrink'])} interpolated from the responses "
              f"({gap_number(g0)} → {gap_number(g1)})")
    if rs is None:
        why = (result.get("resimulation") or {}).get("reason") or "nothing was added"
        return f"{interp}; no re-simulation: {why}"
    return (f"{percent(rs['heldout_shrink'])} re-simulated with the twin seeds ({rs['seeds']} "
            f"seed{'s' if rs['seeds'] != 1 else ''}; {gap_number(g0)} → {gap_number(rs['heldout_gap_after'])}), "
            f"{interp}")


def answer(result: dict) -> str:
    """The report's opening paragraph, from the result alone: where the recording differs from
    the twin, what explains it, how sure, how much of the gap it removes, what is left."""
    return " ".join(f"{head}: {text}" if head else text for head, text in answer_parts(result))


def check_phrase(result: dict) -> str | None:
    """What ``twin check`` found and the diagnosis left out (``found_by_check``), in one
    sentence; None when it found nothing that leaves a channel out."""
    found = result.get("found_by_check") or []
    if not found:
        return None
    parts = []
    for f in found:
        what = (f"{f['channel']} clipped at ±{with_unit(number(f['params']['range']), f.get('unit', ''))}"
                if f["params"].get("range") is not None else f"{f['channel']} {f['finding']}")
        named = f" (the artefact {f['effect']})" if f.get("effect") else ""
        parts.append(f"{what}{named}, {f['n_findings']} finding{'s' if f['n_findings'] != 1 else ''} "
                     f"({f['findings'][0]}), its {f['statistics_left_out']} statistics left out of the comparison")
    named = "named from the check's evidence and " if any(f.get("effect") for f in found) else ""
    return ("twin check finds " + "; ".join(parts) + ": a saturated or flat channel cannot be compared with the "
            f"twin, so it is {named}left out, and the rest of the recording diagnosed without it.")


def answer_parts(result: dict) -> list[tuple[str, str]]:
    """:func:`answer` as (heading, sentence) pairs ("Found by twin check", "Where", "What",
    "How sure", "How much", "What is left"; an empty heading when there is no gap), for the page
    to set the headings in bold."""
    found = check_phrase(result)
    head = [("Found by twin check", found)] if found else []
    return head + _gap_parts(result)


def _gap_parts(result: dict) -> list[tuple[str, str]]:
    """:func:`answer_parts` of the statistics compared (those ``twin check`` did not leave out)."""
    n, k = result["n_statistics"], result["n_significant_calibration"]
    g0, g1 = result["heldout_gap_before"], result["heldout_gap_after"]
    crit = result["heldout_gap_critical"]
    alpha = result.get("alpha", 0.01)
    if result["verdict"] == "no significant gap":
        return [("", f"The recording is within the twin's seed-to-seed spread: {k} of {n} statistics "
                f"differ significantly on the calibration part (Holm, α = {number(alpha, 2)}), "
                f"and the held-out gap {gap_number(g0)} does not exceed what the spread allows "
                f"({gap_number(crit)}). Nothing needs to be added to the twin.")]
    sig = [r for r in result.get("regions", []) if r.get("significant")]
    hours = sorted(result.get("hours", []), key=lambda h: -(h["heldout_gap_before"] or 0))
    when = f", worst at {number(hours[0]['hours'], 6)} h of operation" if hours else ""
    out = [("Where", f"the recording differs from the twin beyond its seed-to-seed spread in {k} of "
           f"{n} statistics (Holm, α = {number(alpha, 2)}), most in {_places(sig)}{when}.")]
    added = result.get("added", [])
    refused = result.get("refused", [])
    no_fit = ("; refused: " + "; ".join(refused_phrase(result, r) for r in refused[:2])) if refused else ""
    if added:
        what = "; then ".join(added_phrase(result, a) for a in added)
        out.append(("What", f"{what}{no_fit}."))
        sure = ", ".join(f"{_title(result, a['effect'])} gains {number(a['gain'] / a['gain_threshold'], 2)}× "
                         "its significance threshold" for a in added if a.get("gain_threshold"))
        edges = [f"{r['label']} is {r['note']}" for a in added for r in parameters(result, a) if r["note"]]
        out.append(("How sure", f"{sure} on the held-out part"
                    + (f"; but {'; '.join(edges)}" if edges else "") + "."))
        rs = resimulation_summary(result)
        if rs is not None:
            out.append(("How much", f"run with the added candidates at their fitted values, the twin "
                        f"({rs['seeds']} seed{'s' if rs['seeds'] != 1 else ''}) removes "
                        f"{percent(rs['heldout_shrink'])} of the held-out gap ({gap_number(g0)} → "
                        f"{gap_number(rs['heldout_gap_after'])}; the twin's own spread allows "
                        f"{gap_number(crit)}); interpolated from the candidates' responses, "
                        f"{percent(result['heldout_shrink'])} ({gap_number(g0)} → {gap_number(g1)})."))
        else:
            out.append(("How much", f"the added candidates remove {percent(result['heldout_shrink'])} of the "
                       f"held-out gap ({gap_number(g0)} → {gap_number(g1)}; the twin's own spread "
                       f"allows {gap_number(crit)}), interpolated from their responses (no "
                       "re-simulation)."))
    else:
        best = (result.get("ranking") or [None])[0]
        if refused:
            out.append(("What", "no candidate (physical effect, twin parameter or signal artefact) explains it"
                        f"{no_fit}."))
        elif best:
            out.append(("What", "no candidate (physical effect, twin parameter or signal artefact) explains it; the "
                       f"best, {owner_phrase(result, best)}, would remove "
                       f"{percent(best.get('net_reduction', best['heldout_reduction']))} of the "
                       "held-out gap, which does not pass the selection test."))
        else:
            out.append(("What", "no candidate effect was tried."))
        out.append(("How much", f"nothing is removed (held-out gap {gap_number(g0)}; the twin's "
                    f"own spread allows {gap_number(crit)})."))
    # What is left follows the verdict: the re-simulated twin when there is one.
    rs = resimulation_summary(result)
    residual = rs["residual"] if rs is not None else result.get("residual", {})
    shrink = rs["heldout_shrink"] if rs is not None else result["heldout_shrink"]
    g1 = rs["heldout_gap_after"] if rs is not None else g1
    if result["verdict"] == "explained":
        left = ("nothing beyond the spread." if not residual.get("significant") else
                f"a small remainder ({percent(1 - shrink)} of the "
                f"gap), still beyond the spread mostly in {_places(residual.get('top_regions', []), 2)}.")
    else:
        left = (f"unexplained, {percent(g1 / g0 if g0 else 0.0)} of the gap, "
                f"mostly in {_places(residual.get('top_regions', []) or sig)}.")
    worse = result.get("worse_regions", [])
    if worse:
        left += (f" The added effects make {len(worse)} region{'s' if len(worse) > 1 else ''} worse "
                 f"than the twin as it is: {_places(worse)}.")
    out.append(("What is left", left))
    return out


def _listed(names: list, k: int = 4) -> str:
    """The first ``k`` − 1 names and the last, "…" between when there are more."""
    shown = [str(n) for n in names]
    return ", ".join(shown if len(shown) <= k else [*shown[:k - 1], "…", shown[-1]])


def subset_phrase(result: dict) -> str | None:
    """The parts of the recording a budgeted diagnosis used, in one sentence (None without a
    ``subset`` entry): samples and sessions with their hours and counts, the budget, the
    estimated and (when known) the actual time."""
    sub = result.get("subset")
    if not sub:
        return None
    parts = []
    p1, p2 = sub["phase1"], sub["phase2"]
    if p1["samples"]:
        parts.append(f"Phase I samples {_listed(p1['samples'])} ({len(p1['samples'])} of {p1['of_samples']}, "
                     f"{number(p1['hours'][0], 4)}–{number(p1['hours'][-1], 4)} h), the first "
                     f"{p1['captures_per_sample']} of {p1['of_captures_per_sample']} captures of each")
    if p2["sessions"]:
        parts.append(f"Phase II sessions {_listed(p2['sessions'])} ({len(p2['sessions'])} of "
                     f"{p2['of_sessions']}, {number(p2['hours'][0], 4)}–{number(p2['hours'][-1], 4)} h), "
                     f"the first {p2['runs_per_session']} of {p2['of_runs_per_session']} runs of each")
    took = (f", took {number(sub['actual_minutes'], 2)} min" if sub.get("actual_minutes") is not None else "")
    fit = "" if sub["fits"] else "; the smallest subset does not fit the budget"
    return (f"Diagnosed on a subset of the recording ({sub['file']}): " + "; ".join(parts)
            + f". Budget {number(sub['budget_minutes'], 3)} min on {sub['workers']} worker"
            + ("s" if sub["workers"] != 1 else "")
            + f", estimated {number(sub['estimated_minutes'], 2)} min{took}{fit}.")
