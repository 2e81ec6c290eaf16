"""The calibrate benchmark's figures over its cases (:mod:`twin.harness.calibration.benchmark`
scores each case; here the rates against issue 30's targets, and the times)."""

from __future__ import annotations

import numpy as np

#: The cases' kinds, in turn (case i is of kind CASE_KINDS[i % 4]).
CASE_KINDS = ("null", "effect", "artefact", "several")
#: Routine keys scored (scenario key: tolerance as a fraction of the drawn value, or in s for
#: the dwells: the larger of 0.1 % and one sample of the channel they are measured on).
ROUTINE_KEYS = ("phase1.speed_mm_s", "phase1.accel_mm_s2", "phase1.dwell_s", "phase2.speeds_mm_s",
                "phase2.accel_mm_s2", "phase2.dwell_s", "phase2.start_mm", "phase2.end_mm")


def case_seconds(case: dict) -> float:
    """The seconds a benchmark entry took: its simulation, export and import, its calibration,
    its diagnosis and its oracle's (those it has)."""
    return (case.get("simulate_export_import_s") or 0.0) + case["calibrate_s"] + sum(
        (case.get(part) or {}).get("seconds") or 0.0 for part in ("diagnosis", "oracle"))


def summarise(cases: list[dict]) -> dict:
    """The benchmark's figures over ``cases``."""
    routine = [v for c in cases for v in c["routine"].values()]
    params = [v for c in cases for v in c["parameters"].values()]
    per_key: dict[str, list[bool]] = {}
    for c in cases:
        for k, v in c["parameters"].items():
            per_key.setdefault(k, []).append(v["inside"])
    worst = {k: max(((c["routine"][k]["error"] or 0.0) for c in cases if k in c["routine"]), default=None)
             for k in ROUTINE_KEYS if any(k in c["routine"] for c in cases)}  # the keys the cases score
    # a routine value fitted through the servo (Phase I's acceleration and dwell, read on the motor
    # speed alone: no command is recorded) is known to its 90 % interval, which is the channel's
    # resolution here (the ramps of a few captures); within 0.1 % or inside that interval
    resolved, halfwidth = [], []
    for c in cases:
        for k, v in c["routine"].items():
            p = c["parameters"].get(k)
            fitted = p is not None and p.get("source") == "fitted"
            resolved.append(bool(v["within"] or (fitted and p["inside"])))
            if fitted:
                halfwidth.append(0.5 * (p["high"] - p["low"]) / abs(p["value"]))
    out = {"cases": len(cases),
           "routine_within": sum(v["within"] for v in routine) / max(len(routine), 1),
           "routine_within_resolution": sum(resolved) / max(len(resolved), 1),
           "routine_fitted_halfwidth_max": max(halfwidth, default=None),
           "routine_worst_error": worst,
           "parameters_inside": sum(v["inside"] for v in params) / max(len(params), 1),
           "parameter_pairs": len(params),
           "per_parameter_inside": {k: sum(v) / len(v) for k, v in per_key.items()},
           "formats_used": sorted({f for c in cases for f in c["formats"]}),
           "calibrate_s_median": float(np.median([c["calibrate_s"] for c in cases])) if cases else None,
           # a whole case: simulated and written out, imported, calibrated, diagnosed, its oracle
           "case_s_median": float(np.median([case_seconds(c) for c in cases])) if cases else None}
    ratio = [c["calibrate_s"] / c["calibrate_estimated_s"] for c in cases if c.get("calibrate_estimated_s")]
    if ratio:  # what --budget-minutes is held to: the estimate after the first simulations
        out["calibrate_actual_over_estimate"] = {"median": float(np.median(ratio)), "min": min(ratio),
                                                 "max": max(ratio)}
    failed = [c["case"] for c in cases if "diagnosis_error" in c]
    if failed:
        out["diagnosis_failed"] = failed
    diag = [c for c in cases if "diagnosis" in c]
    if diag:
        frac = lambda rows, key: (sum(bool(r["diagnosis"][key]) for r in rows) / len(rows)  # noqa: E731
                                  if rows else None)
        by = {k: [c for c in diag if c.get("kind", "null") == k] for k in CASE_KINDS}
        shrink = [c["diagnosis"]["heldout_shrink_resimulated"] for k in ("effect", "artefact")
                  for c in by[k] if c["diagnosis"]["correct"]
                  and c["diagnosis"]["heldout_shrink_resimulated"] is not None]
        out.update({
            "diagnosed": len(diag),
            "per_kind_cases": {k: len(v) for k, v in by.items()},
            "null_no_gap": frac(by["null"], "correct"),
            "effect_named_first": frac(by["effect"], "correct"),
            "effect_absorbed": sum(bool(c["diagnosis"].get("absorbed")) for c in by["effect"]),
            "artefact_named_first": frac(by["artefact"], "correct"),
            "several_all_named": frac(by["several"], "correct"),
            "several_nothing_else": frac(by["several"], "nothing_else"),
            "nothing_else": frac(diag, "nothing_else"),
            "median_shrink_resimulated_named": float(np.median(shrink)) if shrink else None,
            # the same rates over the cases whose added candidates the oracle twin names (what
            # any diagnosis can see in the recording: :func:`run_oracle`)
            "oracle_names_all": {k: sum(bool(c.get("oracle", {}).get("names_all")) for c in by[k])
                                 for k in ("effect", "artefact", "several")},
            "effect_named_first_where_visible": frac([c for c in by["effect"]
                                                      if c.get("oracle", {}).get("names_all")], "correct"),
            "artefact_named_first_where_visible": frac([c for c in by["artefact"]
                                                        if c.get("oracle", {}).get("names_all")], "correct"),
            "several_all_named_where_visible": frac([c for c in by["several"]
                                                     if c.get("oracle", {}).get("names_all")], "correct"),
            "diagnose_s_median": float(np.median([c["diagnosis"]["seconds"] for c in diag]))})
    return out
