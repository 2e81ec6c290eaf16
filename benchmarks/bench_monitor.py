"""Latency and memory of ``twin monitor`` (issue 32, item 5; prints figures; not a test).

1. Simulates the reference set (reduced) and a Phase I campaign with the paper's captures (ten
   10-s captures per sample at 10 kHz; ``phase1-quick`` to 175 h: 17 samples) through
   ``twin simulate --live``, and fits the model (``twin detect --save-model``).
2. Latency: publishes the campaign's units one by one into a fresh source folder as a DAQ
   would (data file, then manifest, each by atomic rename) and calls the monitor's step right
   after each manifest appears: the time from a capture's arrival to its summary, and from the
   arrival of a sample's last capture to its ``sample scored`` event in the log. The running
   monitor adds its polling delay (``--poll``, 0.2 s by default: 0.1 s on average) on top.
3. Soak: ``--soak N`` captures (default 10 000) published the same way (hard links of the
   campaign's captures under new sequence numbers, so the disk holds them once), the resident
   memory of the process printed every ``N/10`` captures.

``--record`` (``make validate``) stores the figures docs/monitoring.md and docs/validation.md quote
in docs/validation.json.

Run: TWIN_WORKERS=1 .venv/bin/python benchmarks/bench_monitor.py [--out DIR] [--soak N] [--record]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402

TWIN = [sys.executable, "-m", "twin.cli"]


def twin(*args) -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    subprocess.run([*TWIN, *map(str, args)], cwd=REPO, env=env, check=True, capture_output=True)


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def publish(src: Path, data: Path, manifest: dict, seq: int, link: bool) -> None:
    """A DAQ's way: the data file, then its manifest, each moved into place."""
    name = f"{seq:06d}-{manifest['kind']}-{manifest['name']}"
    tmp = src / f".{name}.h5.tmp"
    if link:
        os.link(data, tmp)
    else:
        shutil.copyfile(data, tmp)
    os.replace(tmp, src / f"{name}.h5")
    man = {**manifest, "seq": seq, "file": f"{name}.h5"}
    tmp = src / f".{name}.json.tmp"
    tmp.write_text(json.dumps(man))
    os.replace(tmp, src / f"{name}.json")


def pct(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q * (len(xs) - 1))))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--soak", type=int, default=10_000)
    ap.add_argument("--record", action="store_true", help="store the figures in docs/validation.json")
    a = ap.parse_args()
    out = a.out or Path(tempfile.mkdtemp(prefix="bench-monitor-"))
    ref, camp, model = out / "ref", out / "campaign", out / "phase1.model"
    t = time.perf_counter()
    if not (ref / "measurements.h5").is_file():
        twin("simulate", REPO / "scenarios/paper-reference.toml", "-o", ref, "--set",
             "phase1.captures_per_sample=2", "--set", "phase1.capture_s=4.0", "--set",
             "phase1.sample_interval_hours=20")
    if not (camp / "live/end.json").is_file():
        twin("simulate", REPO / "scenarios/phase1-quick.toml", "-o", camp, "--set", "phase1.capture_s=10.0",
             "--set", "phase1.captures_per_sample=10", "--set", "campaign.total_hours=175",
             "--live", "--speedup", "1e12")
    if not model.is_file():
        twin("detect", camp, "--reference", ref, "-o", out / "detect", "--save-model", model)
    print(f"setup (simulation, fit): {time.perf_counter() - t:.0f} s in {out}")

    from twin.harness.monitor import Monitor

    live = camp / "live"
    units = [json.loads(p.read_text()) for p in sorted(live.glob("[0-9]*.json"))]
    units = [u for u in units if u["kind"] == "phase1"]

    # --- latency ---
    src = out / "latency-src"
    shutil.rmtree(src, ignore_errors=True)
    shutil.rmtree(out / "latency-state", ignore_errors=True)
    src.mkdir()
    (src / "source.json").write_text((live / "source.json").read_text())
    scored = []
    mon = Monitor(src, model, out / "latency-state", say=lambda s: None,
                  on_event=lambda e: scored.append(e) if e["event"] == "sample scored" else None)
    mon._resume()
    per_capture, per_sample = [], []
    for u in units:
        before = len(scored)
        publish(src, live / u["file"], u, u["seq"], link=False)
        t0 = time.perf_counter()
        mon.step()
        dt = time.perf_counter() - t0
        (per_sample if len(scored) > before else per_capture).append(dt)
    print(f"latency on {len(units)} captures of 10 s at 10 kHz ({len(per_sample)} samples of "
          f"{units[0]['captures_in_sample']}), from the manifest's arrival:")
    print(f"  capture read and summarised: median {statistics.median(per_capture):.3f} s, "
          f"95 % {pct(per_capture, 0.95):.3f} s, max {max(per_capture):.3f} s")
    print(f"  last capture of a sample to 'sample scored' in the log: median "
          f"{statistics.median(per_sample):.3f} s, 95 % {pct(per_sample, 0.95):.3f} s, "
          f"max {max(per_sample):.3f} s (+ the polling delay, --poll 0.2 s)")

    # --- soak ---
    src = out / "soak-src"
    shutil.rmtree(src, ignore_errors=True)
    shutil.rmtree(out / "soak-state", ignore_errors=True)
    src.mkdir()
    (src / "source.json").write_text((live / "source.json").read_text())
    mon = Monitor(src, model, out / "soak-state", say=lambda s: None)
    mon._resume()
    n_cap = units[0]["captures_in_sample"]
    step = max(1, a.soak // 10)
    t0 = time.perf_counter()
    rows = []
    print(f"soak: {a.soak} captures; resident memory (MB) every {step}:")
    for i in range(a.soak):
        u = units[i % len(units)]
        sample = i // n_cap
        man = {**u, "sample": sample, "hours": 2.0 + 10.0 * sample + 0.5 * (i % n_cap)}
        publish(src, live / u["file"], man, i, link=True)
        mon.step()
        if (i + 1) % step == 0:
            el = time.perf_counter() - t0
            rows.append((i + 1, rss_mb(), el))
            print(f"  {i + 1:6d} captures  {rows[-1][1]:7.1f} MB  {el:7.0f} s  ({el / (i + 1):.3f} s per capture)")
    log_mb = (out / "soak-state/events.jsonl").stat().st_size / 1e6
    print(f"events: {mon.state.n_events}, log {log_mb:.1f} MB")
    if a.record:
        (n1, rss1, el1), (n, rss, el) = rows[0], rows[-1]
        figures = {"capture_median_s": statistics.median(per_capture), "capture_p95_s": pct(per_capture, 0.95),
                   "capture_max_s": max(per_capture), "sample_median_s": statistics.median(per_sample),
                   "sample_p95_s": pct(per_sample, 0.95), "sample_max_s": max(per_sample),
                   "per_capture_first_s": el1 / n1, "per_capture_all_s": el / n}
        record("bench_monitor", command="TWIN_WORKERS=1 .venv/bin/python benchmarks/bench_monitor.py --record",
               scale=f"{len(units)} captures of 10 s at 10 kHz ({len(per_sample)} samples), soak of {n} captures",
               figures={**{k: (round(v, 3), f"{v:.3f}") for k, v in figures.items()},
                        "soak_captures": (n, f"{n:,}".replace(",", " ")),
                        "soak_first_captures": (n1, f"{n1:,}".replace(",", " ")),
                        "rss_first_mb": (round(rss1, 1), f"{rss1:.1f}"), "rss_last_mb": (round(rss, 1), f"{rss:.1f}"),
                        "soak_s": (round(el), f"{el:.0f}"), "events": (mon.state.n_events, f"{mon.state.n_events}"),
                        "log_mb": (round(log_mb, 1), f"{log_mb:.1f}")})


if __name__ == "__main__":
    main()
