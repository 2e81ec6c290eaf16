"""Why the paper's limits of GMM-MD, SOM-MQE, Isolation Forest and the autoencoder raise false
alarms on healthy samples (issue 33; the figures in docs/ci-gate.md).

1. On the ``twin gate`` cache (built if missing): each detector with the paper's limit
   (``limit="paper"``, the autoencoder also ``scaling="scalar"``) fitted on the 15 baseline samples
   of the no-wear campaign; its scores on the baseline itself (in-sample), on each baseline sample
   by a copy fitted on the other 14 (held out, leave-one-out), on the 27 healthy new samples, and
   the paper's limit; then the default limits' thresholds.
2. On the no-wear campaign's raw captures (simulated into WORKDIR if missing): where the torque
   step at the end of each acceleration falls in the autoencoder's window, in samples at 10 kHz.

Run: .venv/bin/python benchmarks/phase1_false_alarms.py [WORKDIR [GATE_CACHE]] [--record]
(defaults runs/phase1-false-alarms and the gate's default cache root; about 20 s with a warm
gate cache; ``--record``: the table of part 1 into docs/validation.json, :mod:`record`). Not part
of ``make bench``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from sklearn.base import clone

from analysis.phase1 import pipeline
from analysis.phase1.segmentation import segment_capture

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402

LABELS = {"gmm_md": "GMM-MD (MD²)", "som_mqe": "SOM-MQE (MQE)", "iforest": "Isolation Forest (s)",
          "autoencoder": "autoencoder (loss)"}
PAPER = {"gmm_md": {"limit": "paper"}, "som_mqe": {"limit": "paper"}, "iforest": {"limit": "paper"},
         "autoencoder": {"limit": "paper", "scaling": "scalar"}}


def _stats(x: np.ndarray) -> str:
    return f"mean {x.mean():.3g}, sd {x.std(ddof=1):.3g}, max {x.max():.3g}"


def _ms(x: np.ndarray) -> str:
    return f"mean {x.mean():.3g}, sd {x.std(ddof=1):.3g}"


def on_the_gate_cache(root: str | None) -> str:
    """Part 1; returns its table (Markdown)."""
    from twin.harness import gate

    rows = ["| detector | baseline, in-sample | baseline, held out | healthy new samples | paper's limit "
            "| default limit |", "|---|---|---|---|---|---|"]
    cache = gate.ensure_cache(root, "standard")
    ref = cache.phase1(cache.suite.reference)
    _, selected = pipeline.select_features(ref.X, ref.labels)
    inp = cache.phase1(cache.suite.healthy)
    nb = pipeline.N_BASELINE
    for name, params in PAPER.items():
        det = pipeline.make_detector(name, 0, **params)
        data = inp.ae if det.phase1_input == "torque_windows" else pipeline.baseline_standardised(inp.X, selected, nb)
        det.fit(data[:nb])
        scores = det.score_samples(data)
        held = np.array([clone(det).fit(np.delete(data[:nb], i, axis=0)).score_samples(data[i:i + 1])[0]
                         for i in range(nb)])
        new = det.decision_function(data)[nb:]
        if name == "autoencoder":
            cv_only = pipeline.make_detector(name, 0, scaling="scalar").fit(data[:nb])
            print(f"autoencoder: scalar scale {det.scale_[0] * 1e3:.3g} mN*m; out-of-fold limit with the "
                  f"scalar scaling {cv_only.threshold_:.4g}: "
                  f"{int(np.sum(cv_only.decision_function(data)[nb:] > cv_only.threshold_))} of {len(new)} above")
        default = pipeline.make_detector(name, 0).fit(data[:nb])
        above = int(np.sum(new > det.threshold_))
        above_default = int(np.sum(default.decision_function(data)[nb:] > default.threshold_))
        print(f"{name}: baseline in-sample {_stats(scores[:nb])}; held out {_stats(held)}; healthy new "
              f"{_stats(scores[nb:])}; paper's limit {det.threshold_:.4g}: {above} "
              f"of {len(new)} new samples above; default limit {default.threshold_:.4g}: {above_default} above")
        new_scores = scores[nb:]
        rows.append(f"| {LABELS[name]} | {_ms(scores[:nb])} | {_ms(held)} | mean {new_scores.mean():.3g}, "
                    f"max {new_scores.max():.3g} | {det.threshold_:.3g}: {above} of {len(new)} above | "
                    f"{default.threshold_:.3g}: {above_default} of {len(new)} above |")
    return "\n".join(rows) + "\n"


def torque_step_timing(work: Path) -> None:
    from analysis.dataset import open_measurements

    if not (work / "measurements.h5").is_file():
        subprocess.run([sys.executable, "-m", "twin.cli", "simulate", REPO / "scenarios/phase1-quick.toml",
                        "-o", work, "--set", "degradation.wear_rate_um_per_kh=0",
                        "--set", "campaign.total_hours=420"], check=True)
    rows = []
    with open_measurements(work / "measurements.h5") as m:
        for name in m.phase1_captures():
            c = m.phase1(name)
            for t in segment_capture(c.speed, c.fs_hz).transient:
                tq = c.torque[t.start:t.start + int(0.15 * c.fs_hz)] * t.direction
                k = int(np.argmin(np.diff(tq)))
                rows.append((c.sample, c.hours, k, tq[k + 1] - tq[k]))
    r = np.array(rows)
    values, counts = np.unique(r[:, 2], return_counts=True)
    print(f"torque step at the end of the acceleration, samples after the window's start "
          f"({len(r)} windows): " + ", ".join(f"{int(v)}: {n}" for v, n in zip(values, counts, strict=True))
          + f"; step {np.median(r[:, 3]):.3g} N*m (median)")
    samples = np.unique(r[:, 0])
    mean = np.array([r[r[:, 0] == s, 2].mean() for s in samples])
    hours = np.array([r[r[:, 0] == s, 1].min() for s in samples])
    print(f"per sample: mean position {_stats(mean)}; baseline (first 15) mean {mean[:15].mean():.2f}; "
          f"correlation with the hours {np.corrcoef(hours, mean)[0, 1]:.2f}; latest "
          f"{mean.max():.2f} at {hours[np.argmax(mean)]:g} h")


def main() -> None:
    args = [a for a in sys.argv[1:] if a != "--record"]
    work = Path(args[0]) if args else REPO / "runs/phase1-false-alarms"
    table = on_the_gate_cache(args[1] if len(args) > 1 else None)
    print(table)
    torque_step_timing(work)
    if "--record" in sys.argv[1:]:
        record("phase1_false_alarms", command=".venv/bin/python benchmarks/phase1_false_alarms.py --record",
               scale="the twin gate's standard cache: the no-wear campaign's 15 baseline and 27 healthy new samples",
               figures={}, tables={"limits": table})


if __name__ == "__main__":
    main()
