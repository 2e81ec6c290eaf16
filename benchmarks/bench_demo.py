"""Benchmark: wall time of ``twin demo`` (what ``make demo`` runs) on all local cores.

Runs ``twin demo -o TMP`` in a fresh directory (nothing reused), reports the total wall time,
the time of each stage from the demo's own log lines, and the peak resident memory of the
command and its children (``resource.getrusage(RUSAGE_CHILDREN)``, the largest single process).

With ``--record`` (what ``make validate`` runs) the figures the README quotes are stored in
docs/validation.json (:mod:`record`): the demo's PCA-T² detection hour and the injected onset,
the largest backlash error against the injected change and against the lost motion, the wall time;
then ``twin view`` on the demo's output: the recording's size, the time to write it (the
command's own figure) and the whole command's wall time, start-up included.

Usage: .venv/bin/python benchmarks/bench_demo.py [--record]
"""

from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402
from record import text as _num  # noqa: E402

from analysis.base.executors import default_processes  # noqa: E402


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "demo"
        env = dict(os.environ, PYTHONPATH=str(REPO))
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "twin.cli", "demo", "-o", str(out)], cwd=REPO,
                              env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            sys.exit(f"twin demo failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        size_mb = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) / 1e6
        print(f"twin demo on {default_processes()} processes: {wall:.1f} s wall "
              f"(issue 5 budget: 600 s); peak RSS of one process {peak_mb:.0f} MB; "
              f"output {size_mb:.0f} MB")
        for line in proc.stderr.splitlines():
            if line.startswith(("scenario", "demo done")) or "units simulated" in line:
                print("  " + line.strip())
        procs = default_processes()  # what `twin demo` starts
        sc = json.loads((out / "score.json").read_text())
        t2 = sc["phase1"]["methods"]["pca_t2"]
        err = max(abs(r["error_um"]) for r in sc["phase2"]["sessions"])
        err_lm = max(abs(r["error_vs_lost_motion_um"]) for r in sc["phase2"]["sessions"])
        print(f"PCA-T² detects at {t2['detection_hours']:g} h (onset {sc['phase1']['onset_hours']:g} h, "
              f"{t2['delay_samples']} sample(s) after); backlash error within {err:.2f} µm of the injected "
              f"change, {err_lm:.2f} µm of the lost motion")
        tables = demo_tables(sc)
        print(tables["phase1"], tables["phase2"], sep="\n\n")
        prog = sc["phase2"].get("prognosis") or {}
        t0 = time.perf_counter()
        view = subprocess.run([sys.executable, "-m", "twin.cli", "view", str(out)], cwd=REPO, env=env,
                              capture_output=True, text=True)
        view_wall = time.perf_counter() - t0
        said = " ".join((view.stdout + view.stderr).split())
        m = re.search(r"wrote \S+ \(([0-9.]+) MB\) in ([0-9.]+) s", said)
        if view.returncode != 0 or not m:
            sys.exit(f"twin view failed ({view.returncode}):\n{view.stdout[-2000:]}{view.stderr[-3000:]}")
        print(f"twin view on the demo: {m[1]} MB written in {m[2]} s; the command {view_wall:.1f} s wall")
        if "--record" in sys.argv[1:]:
            record("bench_demo", command=".venv/bin/python benchmarks/bench_demo.py --record",
                   scale="twin demo (scenarios/demo.toml), all local cores", figures={
                       "pca_t2_detection_h": (t2["detection_hours"], f"{t2['detection_hours']:g}"),
                       "onset_h": (sc["phase1"]["onset_hours"], f"{sc['phase1']['onset_hours']:g}"),
                       "pca_t2_delay_samples": (t2["delay_samples"], f"{t2['delay_samples']}"),
                       "backlash_error_um": (round(err, 2), f"{err:.2f}"),
                       "backlash_error_lost_motion_um": (round(err_lm, 2), f"{err_lm:.2f}"),
                       "wall_s": (round(wall), f"{wall:.0f}"),
                       "peak_rss_gb": (round(peak_mb / 1024, 2), f"{peak_mb / 1024:.2f}"),
                       "output_mb": (round(size_mb), f"{size_mb:.0f}"),
                       "processes": (procs, f"{procs}"),
                       "view_mb": (float(m[1]), m[1]),
                       "view_write_s": (float(m[2]), m[2]),
                       "view_wall_s": (round(view_wall, 1), f"{view_wall:.1f}"),
                       "predicted_crossing_h": (prog.get("predicted_crossing_hours"),
                                                _num(prog.get("predicted_crossing_hours"), "{:.0f}")),
                       "true_crossing_h": (prog.get("true_crossing_hours"),
                                           _num(prog.get("true_crossing_hours"), "{:.0f}"))},
                   tables=tables)


def demo_tables(sc: dict) -> dict[str, str]:
    """The demo's detection table and backlash table (Markdown) from its ``score.json``."""
    p1 = ["| method | detection h | delay h | false alarms / healthy |", "|---|---|---|---|"]
    for r in sc["phase1"]["methods"].values():
        p1.append(f"| {r['label']} | {_num(r['detection_hours'], '{:g}')} | {_num(r['delay_hours'], '{:g}')} "
                  f"| {r['false_alarms']} / {r['healthy_test_samples']} |")
    p2 = ["| hours | injected Δ backlash µm | estimated µm | error µm | injected Δ lost motion µm "
          "| error vs it µm | dial µm |", "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(sc["phase2"]["sessions"]):
        est = "0 (reference)" if i == 0 else _num(r["estimated_delta_um"])
        p2.append(f"| {r['hours']:g} | {_num(r['injected_delta_um'])} | {est} | {_num(r['error_um'], '{:+.2f}')} "
                  f"| {_num(r['injected_lost_motion_delta_um'])} | {_num(r['error_vs_lost_motion_um'], '{:+.2f}')} "
                  f"| {_num(r['dial_delta_um'], '{:.1f}')} |")
    return {"phase1": "\n".join(p1), "phase2": "\n".join(p2)}


if __name__ == "__main__":
    main()
