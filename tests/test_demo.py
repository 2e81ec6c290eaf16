"""Issue 5, check 1: ``twin demo`` (what ``make demo`` runs) at a smaller scale exits 0, writes the
report and the recording, and prints a summary whose figures are those of ``twin score`` on the
same directory; ``twin score`` on bad input exits 2 naming what is missing."""

import json
import shutil

import pytest
from conftest import run_twin


def _tables(text: str) -> str:
    """The rows of the rich tables printed (lines with the table's vertical bar)."""
    return "\n".join(line for line in text.splitlines() if line.startswith("│"))


def test_demo_writes_report_recording_and_the_score_summary(demo_run):
    out, proc = demo_run
    for path in ("measurements.h5", "truth.h5", "reference/measurements.h5", "phase1/detection.json",
                 "backlash/backlash.json", "score.json", "report/index.html", "view.rrd"):
        assert (out / path).is_file() and (out / path).stat().st_size > 0, path
    assert "report:" in proc.stderr and "recording:" in proc.stderr
    demo_score = json.loads((out / "score.json").read_text())
    demo_tables = _tables(proc.stdout)
    assert "PCA-T²" in demo_tables and "s0002" in demo_tables

    again = run_twin("score", out)
    assert _tables(again.stdout) == demo_tables
    rescored = json.loads((out / "score.json").read_text())
    # the directory scored: this copy of the test run's demo (conftest's demo_run), then the demo's
    assert rescored.pop("directory") == str(out)
    demo_score.pop("directory")
    assert rescored == demo_score

    # What the demo must show: the injected onset is 172 h; PCA-T² detects after it, within
    # three samples, with no false alarm on the healthy samples; backlash within 1 µm.
    p1 = demo_score["phase1"]
    assert p1["onset_hours"] == 172.0 and p1["n_samples"] == 25
    t2 = p1["methods"]["pca_t2"]
    print(f"\ndemo: PCA-T² detects at {t2['detection_hours']} h (onset 172 h), "
          f"false alarms {t2['false_alarms']}/{t2['healthy_test_samples']}; Phase II errors "
          + ", ".join(f"{r['error_um']:+.2f}" for r in demo_score["phase2"]["sessions"]) + " µm")
    assert t2["detection_hours"] is not None and 172.0 < t2["detection_hours"] <= 202.0
    assert t2["false_alarms"] == 0
    p2 = demo_score["phase2"]
    assert [r["session"] for r in p2["sessions"]] == ["s0000", "s0001", "s0002"]
    assert p2["sessions"][2]["injected_delta_um"] > 1.5
    assert p2["max_abs_error_um"] < 1.0


def test_score_refuses_a_directory_without_truth_or_outputs(demo_run, tmp_path):
    out, _ = demo_run
    real = tmp_path / "real"
    real.mkdir()
    shutil.copy(out / "measurements.h5", real / "measurements.h5")
    proc = run_twin("score", real, check=False)
    assert proc.returncode == 2
    assert f"{real / 'truth.h5'}: no such file; scoring needs the injected truth" in " ".join(proc.stderr.split())

    shutil.copy(out / "truth.h5", real / "truth.h5")
    proc = run_twin("score", real, check=False)
    assert proc.returncode == 2
    message = " ".join(proc.stderr.split())
    assert "found neither phase1/detection.json (twin detect) nor backlash/backlash.json" in message


@pytest.mark.validate
def test_readme_demo_figures_are_what_make_demo_prints(tmp_path):
    """README, "The two commands": ``make demo`` (``twin demo``, full scale, about a minute on
    two loaded cores) ends with the detection table and the backlash table whose figures the
    README quotes: PCA-T²'s detection hour against the injected onset, the largest error against
    the injected change and against the injected lost motion. In `make validate`, before the
    docs are rewritten from the figures just measured: a README whose figures the code no longer
    gives fails here."""
    import re

    from conftest import REPO

    readme = (REPO / "README.md").read_text()
    readme = " ".join(re.sub(r"<!-- /?fig[:\w.]* -->", "", readme).split())  # the quoted figures' markers
    m = re.search(r"PCA-T² detects the preload loss one sample after the injected onset, "
                  r"(\d+) h against (\d+) h\), the backlash table \(error within ([\d.]+) µm of the "
                  r"injected change, ([\d.]+) µm of the injected lost motion\)", readme)
    assert m, "the README no longer quotes the demo's figures in the form this test reads"
    detect_h, onset_h, err_um, err_lm_um = float(m[1]), float(m[2]), m[3], m[4]
    out = tmp_path / "demo"
    proc = run_twin("demo", "-o", out, check=False, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    tables = _tables(proc.stdout)
    sc = json.loads((out / "score.json").read_text())
    t2 = sc["phase1"]["methods"]["pca_t2"]
    assert (t2["detection_hours"], sc["phase1"]["onset_hours"]) == (detect_h, onset_h)
    assert t2["delay_samples"] == 1  # "one sample after the injected onset"
    assert re.search(rf"│ PCA-T² +│ {detect_h:g} +│", tables)
    sessions = sc["phase2"]["sessions"]
    assert f"{max(abs(r['error_um']) for r in sessions):.2f}" == err_um
    assert f"{max(abs(r['error_vs_lost_motion_um']) for r in sessions):.2f}" == err_lm_um
    print(f"\nmake demo: PCA-T² at {detect_h:g} h (onset {onset_h:g} h), errors within {err_um} µm "
          f"and {err_lm_um} µm of the lost motion, as the README says")
