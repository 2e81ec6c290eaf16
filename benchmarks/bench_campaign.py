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
the bare stepping of the campaign's steps.

Run: .venv/bin/python benchmarks/bench_campaign.py [--scale 0.1] [--out DIR] [--scheduler ADDR]
     [--sessions N]
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
    args = ap.parse_args()
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
            return by_parts(work, scale, where, args.sessions, show)
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


def by_parts(work: Path, scale: list[str], where: list[str], n: int, show) -> None:
    """Phase I alone, the first ``n`` Phase II sessions alone, ``twin backlash`` on those, and the
    whole campaign projected from them; each output is deleted once measured (disk)."""
    import shutil

    sys.path.insert(0, str(REPO))
    from twin.sim.campaign import plan
    from twin.sim.scenario import load

    paper = str(REPO / "scenarios/paper-rtf.toml")
    hours = [u.hours for u in plan(load(paper, [scale[1]])) if u.kind == "phase2"]
    n = min(n, len(hours))
    p1, p2 = work / "phase1", work / "phase2"
    a = twin("simulate", paper, "-o", str(p1), *scale, "--set", "campaign.phase2=false", *where)
    show("twin simulate, Phase I alone", a, f", {(p1 / 'measurements.h5').stat().st_size / 1e9:.1f} GB")
    shutil.rmtree(p1)
    b = twin("simulate", paper, "-o", str(p2), *scale, "--set", "campaign.phase1=false",
             "--set", f"phase2.session_hours={[float(h) for h in hours[:n]]}", *where)
    show(f"twin simulate, {n} of {len(hours)} Phase II sessions", b,
         f", {(p2 / 'measurements.h5').stat().st_size / 1e9:.1f} GB")
    shutil.rmtree(p2 / ".parts")
    c = twin("backlash", str(p2), "--no-plots", *where)
    show(f"twin backlash on the {n} sessions", c)
    k = len(hours) / n
    print(f"  projected for the whole campaign ({len(hours)} sessions): simulation "
          f"{(a[0] + b[0] * k) / 60:.1f} min wall (Phase I {a[0] / 60:.1f} + Phase II {b[0] * k / 60:.1f}), "
          f"twin backlash {c[0] * k / 60:.1f} min wall")
    shutil.rmtree(p2)
    if scale[1] == "campaign.scale=1" or scale[1] == "campaign.scale=1.0":
        against_units(a[1], b[1] * k)


def against_units(phase1_cpu: float, phase2_cpu: float) -> None:
    """The measured CPU of the paper's campaign at full scale (Phase I alone, Phase II
    projected from its first sessions) against bench_simulation's projection from one unit of
    each kind, measured now on this machine."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from bench_simulation import measure

    f = measure(90, 2)
    c = f["campaign_counts"]
    est1, est2 = f["campaign_phase1_s"], f["campaign_phase2_s"]
    bare = (c["phase1"] * f["phase1_steps"] / f["bare_steps_per_s"]
            + c["phase2"] * f["phase2_steps"] / f["phase2_bare_steps_per_s"])
    rate = f"bare {f['bare_steps_per_s']:,.0f} steps/s"
    print(f"  measured CPU {(phase1_cpu + phase2_cpu) / 60:.1f} min = "
          f"{(phase1_cpu + phase2_cpu) / bare:.2f}x the bare stepping of its steps (Phase I "
          f"{phase1_cpu / 60:.1f}, Phase II and dial {phase2_cpu / 60:.1f} min); "
          f"bench_simulation projects {(est1 + est2) / 60:.1f} min = {(est1 + est2) / bare:.2f}x "
          f"(Phase I {est1 / 60:.1f}, Phase II and dial {est2 / 60:.1f} min): measured / projected "
          f"{(phase1_cpu + phase2_cpu) / (est1 + est2):.2f} ({rate})")


if __name__ == "__main__":
    main()
