"""Scoring against the injected truth (analysis/scoring.py): known estimates in, known scores out.

The truth is that of the demo campaign (``demo_run``); the analysis outputs are written by hand,
so every expected figure is computed independently here."""

import json
import shutil

import numpy as np
import pytest

from analysis.dataset import open_truth
from analysis.scoring import THRESHOLD_FACTORS, ScoreError, flat, score


@pytest.fixture()
def scored_dir(demo_run, tmp_path):
    out, _ = demo_run
    d = tmp_path / "c"
    d.mkdir()
    shutil.copy(out / "truth.h5", d / "truth.h5")
    return d


def _write(path, obj):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj))


def test_phase2_errors_against_the_injected_change(scored_dir):
    with open_truth(scored_dir / "truth.h5") as t:
        names = t.sessions()
        hours = [t.session(n)[2]["hours"] for n in names]
        b = np.array([t.session(n)[2]["backlash_um"] for n in names])
    offsets = np.array([0.3, -0.5, 1.0])[: len(names)]
    injected = b - b[:2].mean()  # two baseline sessions
    _write(scored_dir / "backlash" / "backlash.json", {
        "parameters": {"baseline_sessions": 2},
        "sessions": [{"session": n, "hours": h, "delta_backlash_um_shift": float(v + o),
                      "delta_backlash_um_pitch": None}
                     for n, h, v, o in zip(names, hours, injected, offsets, strict=True)],
        "prognosis": {"crossing_hours": 300.0}})
    doc = score(scored_dir)
    p2 = doc["phase2"]
    assert [r["error_um"] for r in p2["sessions"]] == pytest.approx(offsets, abs=1e-12)
    assert p2["rms_error_um"] == pytest.approx(np.sqrt(np.mean(offsets ** 2)))
    assert p2["max_abs_error_um"] == pytest.approx(1.0)
    assert p2["bias_um"] == pytest.approx(offsets.mean())
    assert p2["pitch_rms_error_um"] is None and doc["phase1"] is None
    # Lost motion = clearance + 2 F / K (rail friction 12 N of the scenario, stiffness of truth.h5).
    with open_truth(scored_dir / "truth.h5") as t:
        tl = t.timeline()
        elastic = 2 * t.scenario()["axis"]["rail_friction_N"] / np.interp(hours, tl["hours"],
                                                                           tl["axial_stiffness_N_per_m"]) * 1e6
    lost = b + elastic
    assert [r["injected_lost_motion_delta_um"] for r in p2["sessions"]] == pytest.approx(lost - lost[:2].mean())
    assert [r["error_vs_lost_motion_um"] for r in p2["sessions"]] == pytest.approx(
        injected + offsets - (lost - lost[:2].mean()))
    assert elastic[0] == pytest.approx(0.276, abs=0.002)  # 2 x 12 N / 86.8 N/µm, new nut
    # The demo's truth ends at 250 h with about 2 µm: the 10 µm limit is never reached.
    assert p2["prognosis"]["true_crossing_hours"] is None and p2["prognosis"]["error_hours"] is None
    row = flat(doc)
    assert row["phase2.max_abs_error_um"] == pytest.approx(1.0)
    assert not any(k.startswith("phase1.") for k in row)


def test_phase1_detection_and_threshold_curve(scored_dir):
    with open_truth(scored_dir / "truth.h5") as t:
        onset = t.onset_hours
    hours = [10.0 * i for i in range(24)]  # 0 .. 230 h; onset 172 h
    # Baseline 15 samples at 1, healthy test samples (150..170 h) at 1.5, 3, 1.2, faulty at 2.5, 5, 8...
    scores = [1.0] * 15 + [1.5, 3.0, 1.2] + [2.5, 5.0, 8.0, 8.0, 8.0, 8.0]
    _write(scored_dir / "phase1" / "detection.json",
           {"methods": {"pca_t2": {"threshold": 2.0, "scores": scores, "hours": hours}}})
    _write(scored_dir / "phase1" / "detection_details.json", {"n_baseline": 15, "consecutive": 1})
    r = score(scored_dir)["phase1"]["methods"]["pca_t2"]
    assert onset == 172.0
    # Limit 2: the alarm at 160 h (score 3) is a false alarm; the detection is the first alarm
    # after the onset (180 h, score 2.5), one definition for the CLI, sweeps, ROC and report.
    assert r["detection_hours"] == 180.0 and r["false_alarms"] == 1 and r["healthy_test_samples"] == 3
    assert r["delay_hours"] == pytest.approx(180.0 - 172.0) and r["delay_samples"] == 1
    roc = r["roc"]
    k4 = THRESHOLD_FACTORS.index(2.0)  # limit 4: no false alarm, detects at 190 h (score 5)
    assert roc["false_alarm_rate"][k4] == 0.0 and roc["detected"][k4] and roc["delay_hours"][k4] == 18.0
    k_low = THRESHOLD_FACTORS.index(0.5)  # limit 1: all three healthy samples alarm
    assert roc["false_alarm_rate"][k_low] == 1.0 and roc["detected"][k_low]  # and still detects
    assert roc["delay_hours"][k_low] == 8.0
    assert not roc["detected"][-1]  # limit 8: nothing exceeds it
    fa = np.array(roc["false_alarm_rate"])
    assert np.all(np.diff(fa) <= 0)


def test_score_of_bad_json_names_the_file(scored_dir):
    p = scored_dir / "backlash" / "backlash.json"
    p.parent.mkdir()
    p.write_text("{not json")
    with pytest.raises(ScoreError, match=r"backlash\.json: not valid JSON"):
        score(scored_dir)
