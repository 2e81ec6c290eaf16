"""The paper's full campaign at reduced scale, measured end to end (prints figures; not a test).

``twin simulate scenarios/paper-rtf.toml --set campaign.scale=S`` (default S = 0.1: the full
8693-h timeline, 1 capture per Phase I sample instead of 10, 9 runs per Phase II session instead
of 90; S = 1 is the paper's campaign) on all local cores (or ``--workers N`` / ``--scheduler
ADDR``), then ``twin backlash`` on it, then ``twin detect`` against the reference set
(``scenarios/paper-reference.toml`` at the same scale, simulated too). For each step: wall time,
CPU time of its processes and the peak memory of its largest process; the size of the HDF5
files. Long: about 10-20 min on a 2-core machine for S = 0.1; S = 1 writes about 46 GB and as
much again in resumable parts before they are assembled (about 100 GB of free disk).

With ``--sessions N`` (for a disk that cannot hold the campaign and its parts at once), Phase I
is simulated alone and Phase II alone for its first N sessions, ``twin backlash`` runs on those,
and the whole campaign is projected from them (Phase I + Phase II × sessions / N). Beside it, in
the same run, ``benchmarks/bench_simulation.py``'s projection from one unit of each kind (and
MuJoCo's bare stepping on this machine): the two CPU totals, and the measured one as a ratio to
the bare stepping of the campaign's steps. ``--record`` (with ``--scale 1 --sessions N``) stores
the steps' table and the projection in docs/validation.json (``benchmarks/record.py`` writes them
into docs/validation.md).

Run: .venv/bin/python benchmarks/bench_campaign.py [--scale 0.1] [--out DIR] [--scheduler ADDR]
     [--sessions N]
     .venv/bin/python benchmarks/bench_campaign.py --scale 1 --sessions 8 --workers 1 --record
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def twin(*args: str) -> tuple[float, float, float]:
    """Run ``twin ARGS``: (wall s, CPU s of it and the processes it waited for, peak RSS MB of the
    largest of them); stops the benchmark if it fails."""
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "twin.cli", *args], cwd=REPO, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    out = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        sys.exit(f"twin {' '.join(args)} failed:\n{out}")
    return time.perf_counter() - t0, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.1)
    ap.add_argument("--out", type=Path, default=None, help="work directory (default: temporary)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--no-analysis", action="store_true", help="simulate only")
    ap.add_argument("--sessions", type=int, default=None,
                    help="Phase I alone and the first N Phase II sessions alone, then a projection")
    ap.add_argument("--record", action="store_true",
                    help="store the figures in docs/validation.json (needs --scale 1 --sessions N)")
    args = ap.parse_args()
    if args.record and not (args.sessions and args.scale == 1.0):
        ap.error(f"--record needs --scale 1 and --sessions N (got --scale {args.scale:g}, --sessions "
                 f"{args.sessions}): the docs quote the paper's campaign at full scale")
    where = (["--scheduler", args.scheduler] if args.scheduler else
             ["--workers", str(args.workers)] if args.workers else [])
    scale = ["--set", f"campaign.scale={args.scale}"]
    print(f"paper campaign at campaign.scale={args.scale} on {os.cpu_count()} cores "
          f"(load average {os.getloadavg()[0]:.1f} at the start)")

    def show(step: str, figures: tuple[float, float, float], extra: str = "") -> None:
        wall, cpu, peak = figures
        print(f"  {step:<34} {wall / 60:5.1f} min wall, {cpu / 60:5.1f} min CPU, "
              f"peak {peak:5.0f} MB{extra}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        work = args.out or Path(tmp)
        if args.sessions:
            figures = by_parts(work, scale, where, args.sessions, show, full=args.scale == 1.0)
            if args.record:
                record_parts(figures, args)
            return None
        rtf, ref = work / "rtf", work / "reference"
        step = twin("simulate", str(REPO / "scenarios/paper-rtf.toml"), "-o", str(rtf), *scale, *where)
        size = sum(p.stat().st_size for p in rtf.glob("*.h5")) / 1e9
        show("twin simulate paper-rtf", step, f", {size:.1f} GB of HDF5")
        if args.no_analysis:
            return
        show("twin backlash", twin("backlash", str(rtf), "--no-plots", *where))
        show("twin simulate paper-reference", twin(
            "simulate", str(REPO / "scenarios/paper-reference.toml"), "-o", str(ref), *scale, *where))
        show("twin detect (all six methods)",
             twin("detect", str(rtf), "--reference", str(ref), "-o", str(work / "detect")))


def by_parts(work: Path, scale: list[str], where: list[str], n: int, show, full: bool) -> dict:
    """Phase I alone, the first ``n`` Phase II sessions alone, ``twin backlash`` on those, and the
    whole campaign projected from them; each output is deleted once measured (disk). Returns the
    figures: ``steps`` [(step, (wall s, CPU s, peak MB), output GB or None)], ``sessions`` (n of
    how many), and at full scale (``full``) :func:`against_units`' comparison under ``units``."""
    import shutil

    sys.path.insert(0, str(REPO))
    from twin.sim.campaign import plan
    from twin.sim.scenario import load

    paper = str(REPO / "scenarios/paper-rtf.toml")
    units = plan(load(paper, [scale[1]]))
    hours = [u.hours for u in units if u.kind == "phase2"]
    n = min(n, len(hours))
    p1, p2 = work / "phase1", work / "phase2"
    a = twin("simulate", paper, "-o", str(p1), *scale, "--set", "campaign.phase2=false", *where)
    gb1 = (p1 / "measurements.h5").stat().st_size / 1e9
    show("twin simulate, Phase I alone", a, f", {gb1:.1f} GB")
    shutil.rmtree(p1)
    b = twin("simulate", paper, "-o", str(p2), *scale, "--set", "campaign.phase1=false",
             "--set", f"phase2.session_hours={[float(h) for h in hours[:n]]}", *where)
    gb2 = (p2 / "measurements.h5").stat().st_size / 1e9
    show(f"twin simulate, {n} of {len(hours)} Phase II sessions", b, f", {gb2:.1f} GB")
    shutil.rmtree(p2 / ".parts")
    c = twin("backlash", str(p2), "--no-plots", *where)
    show(f"twin backlash on the {n} sessions", c)
    k = len(hours) / n
    print(f"  projected for the whole campaign ({len(hours)} sessions): simulation "
          f"{(a[0] + b[0] * k) / 60:.1f} min wall (Phase I {a[0] / 60:.1f} + Phase II {b[0] * k / 60:.1f}), "
          f"twin backlash {c[0] * k / 60:.1f} min wall")
    shutil.rmtree(p2)
    out = {"sessions": (n, len(hours)), "steps": [
        ("`twin simulate paper-rtf --set campaign.phase2=false` "
         f"({sum(u.kind == 'phase1' for u in units)} captures)", a, gb1),
        (f"`twin simulate paper-rtf --set campaign.phase1=false`, {n} sessions of 90 runs", b, gb2),
        (f"`twin backlash` on those {n} sessions", c, None)]}
    if full:
        out["units"] = against_units(a[1], b[1] * k)
        out["backlash_cpu_per_session_s"] = c[1] / n
        out["backlash_cpu_all_s"] = c[1] * k
        out["peak_mb"] = max(a[2], b[2], c[2])
    return out


def against_units(phase1_cpu: float, phase2_cpu: float) -> dict:
    """The measured CPU of the paper's campaign at full scale (Phase I alone, Phase II
    projected from its first sessions) against bench_simulation's projection from one unit of
    each kind, measured now on this machine: printed, and returned (seconds; ratios)."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from bench_simulation import measure

    f = measure(90, 2)
    c = f["campaign_counts"]
    est1, est2 = f["campaign_phase1_s"], f["campaign_phase2_s"]
    bare = (c["phase1"] * f["phase1_steps"] / f["bare_steps_per_s"]
            + c["phase2"] * f["phase2_steps"] / f["phase2_bare_steps_per_s"])
    rate = f"bare {f['bare_steps_per_s']:,.0f} steps/s"
    measured = phase1_cpu + phase2_cpu
    print(f"  measured CPU {measured / 60:.1f} min = "
          f"{measured / bare:.2f}x the bare stepping of its steps (Phase I "
          f"{phase1_cpu / 60:.1f}, Phase II and dial {phase2_cpu / 60:.1f} min); "
          f"bench_simulation projects {(est1 + est2) / 60:.1f} min = {(est1 + est2) / bare:.2f}x "
          f"(Phase I {est1 / 60:.1f}, Phase II and dial {est2 / 60:.1f} min): measured / projected "
          f"{measured / (est1 + est2):.2f} ({rate})")
    return {"measured_s": measured, "phase1_s": phase1_cpu, "phase2_s": phase2_cpu, "bare_s": bare,
            "projected_s": est1 + est2, "projected_phase1_s": est1, "projected_phase2_s": est2,
            "bare_steps_per_s": f["bare_steps_per_s"]}


#: The goals the projection is held to (issue 35's and the campaign's): 2 cores, minutes.
GOAL_2CORES_MIN, GOAL_BACKLASH_2CORES_MIN, GOAL_PEAK_GB, GOAL_AGREEMENT = 15.0, 5.0, 1.5, 0.15


def record_parts(fig: dict, args) -> None:
    """Store :func:`by_parts`' figures at full scale (docs/validation.md, "Simulation speed")."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from record import record, text

    u = fig["units"]
    n, total = fig["sessions"]
    rows = ["| step | wall | CPU | peak memory | output |", "|---|---|---|---|---|"]
    for step, (wall, cpu, peak), gb in fig["steps"]:
        rows.append(f"| {step} | {wall / 60:.1f} min | {cpu / 60:.1f} min | {peak / 1024:.2f} GB | "
                    f"{'' if gb is None else f'{gb:.1f} GB'} |")
    ratio = u["measured_s"] / u["projected_s"]
    r1, r2 = u["phase1_s"] / u["projected_phase1_s"], u["phase2_s"] / u["projected_phase2_s"]
    wall2 = u["measured_s"] / 2 / 60
    back2 = fig["backlash_cpu_all_s"] / 2 / 60
    peak_gb = fig["peak_mb"] / 1024

    within = "within" if abs(ratio - 1) <= GOAL_AGREEMENT else "beyond"

    def met(ok: bool) -> str:
        return "met" if ok else "not met"

    figures = {
        "bare_steps_per_s": (u["bare_steps_per_s"], f"{u['bare_steps_per_s']:,.0f}"),
        "sessions": (float(n), f"{n}"),
        "sessions_total": (float(total), f"{total}"),
        "measured": (u["measured_s"] / 60,
                     f"{u['measured_s'] / 60:.1f} min of CPU for the simulation, "
                     f"{u['measured_s'] / u['bare_s']:.2f}× the bare stepping of its steps"),
        "parts": (u["phase1_s"] / 60, f"Phase I {u['phase1_s'] / 60:.1f}, Phase II with the dial units "
                                      f"{u['phase2_s'] / 60:.1f} min"),
        "projected": (u["projected_s"] / 60,
                      f"{u['projected_s'] / 60:.1f} min ({u['projected_s'] / u['bare_s']:.2f}×)"),
        "agreement": (ratio, f"measured / projected {text(ratio)} ({within} {GOAL_AGREEMENT * 100:g} %; Phase I "
                             f"{text(r1)}, Phase II {text(r2)})"),
        "two_cores": (wall2, f"about {wall2:.1f} min of wall time (goal ≤ {GOAL_2CORES_MIN:g} min: "
                             f"{met(wall2 <= GOAL_2CORES_MIN)})"),
        "backlash": (fig["backlash_cpu_per_session_s"],
                     f"{fig['backlash_cpu_per_session_s']:.1f} s of CPU per 90-run session, "
                     f"{fig['backlash_cpu_all_s'] / 60:.1f} min for the {total}, about {back2:.1f} min on 2 cores "
                     f"(goal ≤ {GOAL_BACKLASH_2CORES_MIN:g} min: {met(back2 <= GOAL_BACKLASH_2CORES_MIN)})"),
        "peak": (peak_gb, f"{peak_gb:.2f} GB (goal ≤ {GOAL_PEAK_GB:g} GB: {met(peak_gb <= GOAL_PEAK_GB)})"),
    }
    workers = f" --workers {args.workers}" if args.workers else ""
    record("bench_campaign",
           command=f".venv/bin/python benchmarks/bench_campaign.py --scale 1 --sessions {n}{workers} --record",
           scale=f"the paper's campaign (scenarios/paper-rtf.toml) at full scale: Phase I alone, the first {n} "
                 f"of its {total} Phase II sessions alone, twin backlash on those",
           figures=figures, tables={"steps": "\n".join(rows) + "\n"})
    print("recorded in docs/validation.json (benchmarks/record.py writes the docs)")


if __name__ == "__main__":
    main()
