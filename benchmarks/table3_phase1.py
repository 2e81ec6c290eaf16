"""Reproduce the paper's Table III (Phase I detection points) at a reduced scale (issue 3).

Simulates, unless already there,
- ``scenarios/paper-rtf.toml`` with ``campaign.scale=0.2`` (2 of the paper's ten 10-s captures per
  84-h sample, the full 8693-h timeline, onset 2500 h) and Phase II off;
- ``scenarios/paper-reference.toml`` with 3 captures per sample (10 healthy, 10 preload-loss and
  10 backlash samples of 10-s captures);
then runs ``twin detect`` and prints the paper's detection hours beside ours.

Run: .venv/bin/python benchmarks/table3_phase1.py [WORKDIR]   (default runs/table3; its run time
is in docs/validation.md). Not part of ``make bench``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(REPO))
TWIN = [sys.executable, "-m", "twin.cli"]
PAPER = {"pca_t2": "2972", "gmm_md": "2972", "som_mqe": "2972", "iforest": "1678*",
         "ocsvm": "3069", "autoencoder": "2972"}
NAMES = {"pca_t2": "PCA-T²", "gmm_md": "GMM-MD", "som_mqe": "SOM-MQE", "iforest": "IF",
         "ocsvm": "OCSVM", "autoencoder": "AE"}


def twin(*args) -> None:
    subprocess.run([*TWIN, *map(str, args)], cwd=REPO, env=ENV, check=True)


def main() -> None:
    work = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "runs/table3"
    rtf, ref, out = work / "rtf", work / "reference", work / "detect"
    t0 = time.perf_counter()
    if not (rtf / "measurements.h5").is_file():
        twin("simulate", REPO / "scenarios/paper-rtf.toml", "-o", rtf, "--set", "campaign.scale=0.2",
             "--set", "campaign.phase2=false")
    if not (ref / "measurements.h5").is_file():
        twin("simulate", REPO / "scenarios/paper-reference.toml", "-o", ref, "--set",
             "phase1.captures_per_sample=3")
    t1 = time.perf_counter()
    twin("detect", rtf, "--reference", ref, "-o", out)
    t2 = time.perf_counter()
    det = json.loads((out / "detection_details.json").read_text())
    print(f"\nsimulation {t1 - t0:.0f} s, detection {t2 - t1:.0f} s; injected onset "
          f"{det['onset_hours']} h; selected {det['selected_features']}")
    print("| method | paper (h) | twin (h) | delay from onset (h) | false alarms / healthy test | baseline alarms |")
    print("|---|---|---|---|---|---|")
    for m, r in det["methods"].items():
        d, delay = r["detection_hours"], r["delay_hours"]
        print(f"| {NAMES[m]} | {PAPER[m]} | {'-' if d is None else f'{d:g}'} | "
              f"{'-' if delay is None else f'{delay:g}'} | "
              f"{r['false_alarms']} / {r['healthy_test_samples']} | {r['baseline_alarms']} |")


if __name__ == "__main__":
    main()
