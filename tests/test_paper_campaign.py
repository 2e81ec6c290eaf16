"""The paper's run-to-failure campaign at reduced scale (marked slow).

Run with: make test-slow   (or .venv/bin/python -m pytest -m slow -s)
"""

import numpy as np
import pytest
from conftest import REPO, run_twin

from analysis.dataset import open_measurements, open_truth

pytestmark = pytest.mark.slow


def test_paper_rtf_reduced(tmp_path):
    out = tmp_path / "rtf"
    run_twin("simulate", REPO / "scenarios/paper-rtf.toml", "-o", out,
             "--set", "phase1.captures_per_sample=1", "--set", "phase1.capture_s=2.0",
             "--set", "phase1.sample_interval_hours=1000", "--set", "phase2.runs_per_session=1",
             "--set", "phase2.dwell_s=1.0", "--set", "phase2.session_interval_hours=1000")
    with open_truth(out / "truth.h5") as t, open_measurements(out / "measurements.h5") as m:
        tl = t.timeline()
        b8000 = np.interp(8000.0, tl["hours"], tl["backlash_um"])
        p6000 = np.interp(6000.0, tl["hours"], tl["preload_N"]) / tl["preload_N"][0]
        print(f"backlash at 8000 h {b8000:.2f} µm, preload at 6000 h {100 * p6000:.1f} %")
        assert 7.0 < b8000 < 13.0 and p6000 < 0.1
        assert np.interp(2500.0, tl["hours"], tl["backlash_um"]) < 0.5
        hours, dial = m.dial_indicator()
        truth = np.array([t.session(s)[2]["backlash_um"] for s in t.sessions()])
        print("dial:", np.round(dial, 1), "truth:", np.round(truth, 1))
        assert len(dial) == len(truth) == len(m.phase2_sessions()) == 9
        assert np.abs(dial - truth).max() < 3.0  # 1.5 µm reading error by eye, 3 repeats
        assert len(m.phase1_captures()) == 9
