"""Reproduce the paper's Table III (Phase I detection points) at a reduced scale (issue 3).

Simulates, unless already there,
- ``scenarios/paper-rtf.toml`` with ``campaign.scale=0.2`` (2 of the paper's ten 10-s captures per
  84-h sample, the full 8693-h timeline, onset 2500 h) and Phase II off;
- ``scenarios/paper-reference.toml`` with 3 captures per sample (10 healthy, 10 preload-loss and
  10 backlash samples of 10-s captures);
then runs ``twin detect`` and prints the paper's detection hours beside ours under two rules,
each named: the paper's (the first crossing of the limit after the baseline, wherever it falls)
and the first alarm after the injected onset (``twin detect``'s detection hour; also two alarms
in a row), with the detectors' default limits and, for the four detectors
whose default limit departs from the paper's (GMM-MD, SOM-MQE, Isolation Forest, autoencoder:
``analysis/phase1/detectors.py``), with the paper's limits (``limit="paper"``, and the
autoencoder's earlier scalar scaling).

Run: .venv/bin/python benchmarks/table3_phase1.py [WORKDIR] [--record]   (default runs/table3;
``--record``: the table into docs/validation.json, :mod:`record`, and the Fig. 6 analogue into
docs/figures/fig6-paper-rtf.png). Not part of ``make bench``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from analysis.phase1.scoring import score_method

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402

ENV = dict(os.environ, PYTHONPATH=str(REPO))
TWIN = [sys.executable, "-m", "twin.cli"]
PAPER = {"pca_t2": "2972", "gmm_md": "2972", "som_mqe": "2972", "iforest": "1678*",
         "ocsvm": "3069", "autoencoder": "2972"}
PAPER_LIMITS = {"gmm_md": {"limit": "paper"}, "som_mqe": {"limit": "paper"}, "iforest": {"limit": "paper"},
                "autoencoder": {"limit": "paper", "scaling": "scalar"}}
NAMES = {"pca_t2": "PCA-T²", "gmm_md": "GMM-MD", "som_mqe": "SOM-MQE", "iforest": "IF",
         "ocsvm": "OCSVM", "autoencoder": "AE"}


def twin(*args) -> None:
    subprocess.run([*TWIN, *map(str, args)], cwd=REPO, env=ENV, check=True)


def main() -> None:
    args = [a for a in sys.argv[1:] if a != "--record"]
    work = Path(args[0]) if args else REPO / "runs/table3"
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
    scores = json.loads((out / "detection.json").read_text())["methods"]
    paper = paper_limits(rtf, out, det)
    nb, onset = det["n_baseline"], det["onset_hours"]
    print(f"\nsimulation {t1 - t0:.0f} s, detection {t2 - t1:.0f} s; injected onset "
          f"{onset} h; selected {det['selected_features']}")
    rows = ["| method | paper (h) | twin, first crossing (h) | twin, first alarm after the onset (h) "
            "| 2 in a row after the onset (h) | false alarms / healthy test | baseline alarms "
            "| paper's limits: first crossing, after the onset (h), false alarms |",
            "|---|---|---|---|---|---|---|---|"]
    sel = det["selected_features"]
    figures = {"onset_h": (onset, f"{onset:g}"), "n_selected": (len(sel), f"{len(sel)}"),
               "selected_features": (None, ", ".join(f"`{n}`" for n in sel)),
               "time_detection_s": (round(t2 - t1, 1), f"{t2 - t1:.0f} s")}
    figures["truth"] = (None, truth_text(rtf / "truth.h5", onset, scores["pca_t2"]["hours"]))
    for m, r in det["methods"].items():
        s = scores[m]
        first = score_method(s["hours"], s["scores"], s["threshold"], nb, None)
        two = score_method(s["hours"], s["scores"], s["threshold"], nb, onset, 2)
        p = paper.get(m)
        figures[f"{m}_first_crossing_h"] = (first.detection_hours, _h(first.detection_hours))
        figures[f"{m}_after_onset_h"] = (r["detection_hours"], _h(r["detection_hours"]))
        rows.append(f"| {NAMES[m]} | {PAPER[m]} | {_h(first.detection_hours)} | {_h(r['detection_hours'])} | "
                    f"{_h(two.detection_hours)} | {r['false_alarms']} / {r['healthy_test_samples']} | "
                    f"{r['baseline_alarms']} | "
                    + ("same limit" if p is None else
                       f"{_h(p['first'].detection_hours)}, {_h(p['after'].detection_hours)}, "
                       f"{p['after'].false_alarms} / {p['after'].healthy_test_samples}") + " |")
    table = "\n".join(rows)
    print(table)
    if "--record" in sys.argv[1:]:
        import shutil

        shutil.copyfile(out / "detection.png", REPO / "docs" / "figures" / "fig6-paper-rtf.png")  # Fig. 6 analogue
        record("table3_phase1", command=".venv/bin/python benchmarks/table3_phase1.py --record",
               scale="paper-rtf at campaign.scale=0.2 (2 captures per 84-h sample, 8693 h, Phase II off); "
                     "paper-reference with 3 captures per sample",
               figures=figures, tables={"table3": table})


def truth_text(path: Path, onset: float, sample_hours: list[float]) -> str:
    """The injected truth the table is read against, in words: the preload (share of its
    initial value) at the first three samples after the onset and at the paper's 2972 h, the
    backlash until then, at 6000 h and at the end."""
    import numpy as np

    from analysis.dataset import open_truth

    with open_truth(path) as t:
        tl = t.timeline()
    h, pre, bl = tl["hours"], tl["preload_N"] / tl["preload_N"][0], tl["backlash_um"]
    at = [x for x in sample_hours if x > onset][:3] + [2972.0]
    return (f"true preload at {'/'.join(f'{x:g}' for x in at)} h: "
            f"{'/'.join(f'{100 * np.interp(x, h, pre):.0f}' for x in at)} % of the initial value, backlash "
            f"≤ {bl[h <= at[-1]].max():.2f} µm until {at[-1]:g} h, {np.interp(6000.0, h, bl):.1f} µm at 6000 h, "
            f"{bl[-1]:.0f} µm at the end ({h[-1]:g} h)")


def _h(hours) -> str:
    return "-" if hours is None else f"{hours:g}"


def paper_limits(rtf: Path, out: Path, det: dict) -> dict:
    """Scores of the detectors in ``PAPER_LIMITS`` with the paper's limits, fitted as ``twin
    detect`` fits them (same features, selection, baseline and seed): ``{"first": first crossing,
    "after": after the onset}`` per detector."""
    from analysis.phase1 import pipeline

    feats = pipeline.extract(rtf / "measurements.h5")
    selected = [feats.names.index(n) for n in det["selected_features"]]
    nb = det["n_baseline"]
    Z = pipeline.baseline_standardised(feats.X, selected, nb)
    res = {}
    for m, params in PAPER_LIMITS.items():
        d = pipeline.make_detector(m, 0, **params)
        data = feats.ae if d.phase1_input == "torque_windows" else Z
        d.fit(data[:nb])
        sc = d.decision_function(data)
        res[m] = {"first": score_method(feats.hours, sc, d.threshold_, nb, None),
                  "after": score_method(feats.hours, sc, d.threshold_, nb, det["onset_hours"])}
    return res


if __name__ == "__main__":
    main()
