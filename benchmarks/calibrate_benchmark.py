"""The figures of ``twin calibrate-benchmark`` (issue 30, item 3), recorded from its runs.

A case takes a quarter of an hour to an hour on the 2-core machine (docs/calibration.md gives the
recorded median): the 24 cases are longer than a CI run or a working session, so they are run by
hand, in parts, one process at a time on both cores, and this script records what the parts
measured::

    twin calibrate-benchmark -o OUT_A --cases 24 --diagnose --workers 2            # cases 0, 1, ...
    twin calibrate-benchmark -o OUT_B --cases 24 --diagnose --workers 2 --first 12  # cases 12, ...
    .venv/bin/python benchmarks/calibrate_benchmark.py --record OUT_A OUT_B

It keeps every finished case whose entry has the key the current code gives its draw (the
benchmark's, the calibration's and the diagnosis's versions, the seed, ``--diagnose``, the twin
seeds: :func:`twin.harness.calibration.benchmark.case_key`) in
``benchmarks/results/calibrate-benchmark/case-NNN.json`` (a run given ``--kept`` that directory
takes them instead of running them again), and with ``--record`` stores the summary over all
kept cases and a table of them in ``docs/validation.json`` (``calibrate_benchmark``), from
which ``benchmarks/record.py`` writes docs/calibration.md. A case whose key no longer matches
(a version was raised) is dropped with a line that says so: its figures are no longer what the
code does. ``tests/test_calibrate.py::test_the_recorded_calibrate_benchmark_is_this_codes``
fails when a kept entry's key and the code disagree.

Run: .venv/bin/python benchmarks/calibrate_benchmark.py [--record] OUT [OUT ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from record import record, text  # noqa: E402

from analysis.base.files import write_json  # noqa: E402
from twin.harness.calibration.benchmark import case_key, draws, judged_again  # noqa: E402
from twin.harness.calibration.benchmark_summary import CASE_KINDS, summarise  # noqa: E402

RESULTS = REPO / "benchmarks" / "results" / "calibrate-benchmark"
#: The benchmark as the docs state it (the CLI's defaults with ``--diagnose``).
CASES, SEED, DIAGNOSE, TWIN_SEEDS = 24, 2026, True, 6
COMMAND = ("twin calibrate-benchmark -o OUT --cases 24 --diagnose --workers 2 [--first K], then "
           ".venv/bin/python benchmarks/calibrate_benchmark.py --record OUT [OUT ...]")


def current_keys(cases: int = CASES, seed: int = SEED) -> list[str]:
    """The key of each case's draw under the current code (as ``run_benchmark`` computes it)."""
    scenarios, additions = draws(cases, seed)
    return [case_key(s, CASE_KINDS[i % len(CASE_KINDS)], *additions[i], diagnose=DIAGNOSE, seeds=TWIN_SEEDS)
            for i, s in enumerate(scenarios)]


def kept_entries(results: Path = RESULTS) -> list[dict]:
    """The recorded entries, in case order."""
    return [json.loads(f.read_text()) for f in sorted(results.glob("case-*.json"))]


def collect(outs: list[Path], results: Path = RESULTS) -> list[dict]:
    """Copy the finished cases of the runs ``outs`` whose key is the current code's into
    ``results`` (a case recorded twice: the later run's), drop the recorded ones whose key is not,
    and return all kept entries in case order, each diagnosis judged by the current rule
    (:func:`twin.harness.calibration.benchmark.judged_again`)."""
    keys = current_keys()
    results.mkdir(parents=True, exist_ok=True)
    for f in sorted(results.glob("case-*.json")):
        e = json.loads(f.read_text())
        if e.get("key") != keys[e["case"]]:
            print(f"{f.relative_to(REPO)}: dropped (measured by another version of the code)")
            f.unlink()
        else:
            write_json(f, judged_again(e), nan_as_null=True)
    for out in outs:
        for f in sorted(Path(out).glob("case-*/entry.json")):
            e = json.loads(f.read_text())
            if e.get("key") != keys[e["case"]]:
                print(f"{f}: not kept (its key is not the current code's: another version or other options)")
            elif e["kind"] != "null" and "oracle" not in e:
                print(f"{f}: not kept (its oracle was not run yet)")
            else:
                write_json(results / f"case-{e['case']:03d}.json", judged_again(e), nan_as_null=True)
    return kept_entries(results)


def percent(v: float | None) -> str:
    return text(None if v is None else 100.0 * v, "{:.0f}") + (" %" if v is not None else "")


def case_table(entries: list[dict]) -> str:
    """A row a case: its axis, what was added, the routine and the parameters scored, the verdict."""
    rows = ["| case | kind | added | lead, mass | formats | routine within 0.1 % | parameters inside "
            "their 90 % interval | diagnosis: named | right | the oracle names it |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for e in entries:
        ax = e["scenario"]["axis"]
        inactive = e.get("inactive_artefacts", [])
        added = ", ".join([*e["effects"], *(a + (" (changes no sample)" if a in inactive else "")
                                            for a in e["artefacts"])]) or "–"
        r_ok = sum(v["within"] for v in e["routine"].values())
        p_out = [k.split(".")[1] for k, v in e["parameters"].items() if not v["inside"]]
        p_ok = len(e["parameters"]) - len(p_out)
        params = f"{p_ok}/{len(e['parameters'])}" + (f" (outside: {', '.join(p_out)})" if p_out else "")
        dg = e.get("diagnosis")
        if dg is None:
            named, right = f"failed: {e.get('diagnosis_error', '–')[:80]}", "no"
        else:
            named, right = (", ".join(dg["added"]) or "nothing"), ("yes" if dg["correct"] else "no")
            if dg.get("absorbed"):
                named += f" ({', '.join(dg['absorbed'])} absorbed by the calibration)"
            if dg.get("refitted_with"):
                named += f" (the calibration fitted again with {dg['refitted_with']} in the twin)"
        oracle = "–" if e["kind"] == "null" else ("yes" if e.get("oracle", {}).get("names_all") else "no")
        axis = f"{ax['lead_mm']:g} mm, {ax['carriage_mass_kg']:g} kg"
        rows.append(f"| {e['case']} | {e['kind']} | {added} | {axis} | {'/'.join(e['formats'])} | "
                    f"{r_ok}/{len(e['routine'])} | {params} | {named} | {right} | {oracle} |")
    return "\n".join(rows) + "\n"


def figures(entries: list[dict]) -> dict[str, tuple[float | None, str]]:
    sm = summarise(entries)
    n = sm.get("per_kind_cases", {})
    out: dict[str, tuple[float | None, str]] = {
        "cases": (float(len(entries)), str(len(entries))),
        "case_list": (None, ", ".join(str(e["case"]) for e in entries) or "none"),
        "routine_within": (routine := sm["routine_within"] if entries else None, percent(routine)),
        "routine_within_resolution": (res := sm["routine_within_resolution"] if entries else None,
                                      percent(res)),
        "routine_fitted_halfwidth_max": (hw := sm.get("routine_fitted_halfwidth_max"),
                                         "–" if hw is None else f"±{100 * hw:.1f} %"),
        "parameters_inside": (inside := sm["parameters_inside"] if entries else None, percent(inside)),
        "parameter_pairs": (float(sm["parameter_pairs"]), str(sm["parameter_pairs"])),
        "calibrate_s_median": (sm["calibrate_s_median"], text(sm["calibrate_s_median"], "{:.0f}")),
        "case_min_median": (m := None if sm.get("case_s_median") is None else sm["case_s_median"] / 60,
                            f"{text(m, '{:.0f}')} min"),
        # the CASES cases one after the other, at that median
        "all_cases_h": (h := None if m is None else CASES * m / 60, f"{text(h, '{:.1f}')} hours"),
    }
    for key, kind in (("null_no_gap", "null"), ("effect_named_first", "effect"),
                      ("artefact_named_first", "artefact"), ("several_all_named", "several"),
                      ("several_nothing_else", "several")):
        v = sm.get(key)
        out[key] = (v, f"{percent(v)} of {n.get(kind, 0)}")
    for key in ("effect_named_first_where_visible", "artefact_named_first_where_visible",
                "several_all_named_where_visible"):
        v = sm.get(key)
        out[key] = (v, percent(v))
    v = sm.get("median_shrink_resimulated_named")
    out["median_shrink_resimulated_named"] = (v, percent(v))
    out["diagnosis_failed"] = (None, ", ".join(map(str, sm.get("diagnosis_failed", []))) or "none")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", nargs="*", type=Path, help="output directories of twin calibrate-benchmark runs")
    ap.add_argument("--record", action="store_true", help="store the figures in docs/validation.json")
    a = ap.parse_args(argv)
    entries = collect(a.outs)
    figs = figures(entries)
    for k, (_v, t) in figs.items():
        print(f"{k:40s} {t}")
    print(case_table(entries))
    if a.record:
        from analysis.ingest.check import CHECK_VERSION
        from twin.harness.calibration import CALIBRATE_VERSION

        record("calibrate_benchmark", command=COMMAND,
               scale=(f"cases {figs['case_list'][1]} of {CASES} (seed {SEED}, --diagnose, {TWIN_SEEDS} twin "
                      f"seeds), CALIBRATE_VERSION {CALIBRATE_VERSION}, CHECK_VERSION {CHECK_VERSION}"),
               figures=figs, tables={"cases": case_table(entries)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
