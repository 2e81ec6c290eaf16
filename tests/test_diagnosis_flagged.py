"""What ``twin check`` finds, taken into the gap diagnosis (analysis/diagnosis/flagged.py): a
clipped channel named from the check's evidence with its rail, its statistics left out."""

from __future__ import annotations

import numpy as np

from analysis.diagnosis.artefacts import ARTEFACTS
from analysis.diagnosis.flagged import found_by_check, leave_out, named, rail, reads
from analysis.diagnosis.signature import Region, Signature
from analysis.ingest.check import _clipped, finding_channel


def _regions() -> list[Region]:
    return [Region("phase1", "acc1_x", "band", "10-30 Hz", 0.0), Region("phase1", "acc2_z", "band", "10-30 Hz", 0.0),
            Region("phase1", "torque", "level", "steady", 0.0),
            Region("phase1", "features", "feature", "kurt_acc1_y", 0.0),
            Region("phase1", "features", "feature", "corr_tr_torque_fwd", 0.0),
            Region("phase2", "acc_x", "band", "2-5 Hz @80 mm/s", 50.0),
            Region("phase2", "gyro_z", "phase", "steady", 50.0), Region("phase2", "E_BX", "position", "0-50 mm", 50.0),
            Region("phase2", "E_XX", "lag", "10-40 mm")]


def test_a_clipping_finding_gives_its_rail_through_twin_checks_own_words():
    rng = np.random.default_rng(3)
    x = np.clip(30.0 * np.sin(np.linspace(0, 40 * np.pi, 20000)) + rng.normal(0, 0.5, 20000), -24.5, 25.0)
    top, bottom = _clipped(x, "maximum"), _clipped(x, "minimum")
    assert top and bottom
    assert rail([{"where": "/phase2/s000/r000/imu_acc[x]", "what": top}]) == 25.0
    assert rail([{"where": "w", "what": top}, {"where": "w", "what": bottom}]) == 25.0
    assert rail([{"where": "w", "what": bottom}]) == 24.5
    # the axis contract's rule: |value| reaches the sensor's range
    contract = "clipping: |value| reaches 39.2, the sensor's range is 39.2 (axis contract)"
    assert rail([{"where": "w", "what": contract}]) == 39.2
    assert rail([{"where": "w", "what": "flat line: all 100 samples are 0"}]) is None


def test_each_channel_reads_its_own_statistics_and_the_imu_every_error_motion():
    regs = _regions()
    assert [reads("acc1", r) for r in regs] == [True, False, False, True, False, False, False, False, False]
    assert [reads("torque", r) for r in regs] == [False, False, True, False, True, False, False, False, False]
    assert [reads("imu_acc", r) for r in regs] == [False] * 5 + [True, False, True, True]
    assert [reads("imu_gyro", r) for r in regs] == [False] * 6 + [True, True, True]
    assert finding_channel("/phase2/s001/r000/imu_acc[z]") == "imu_acc"
    assert finding_channel("/phase1/c003/acc2") == "acc2"


def test_found_by_check_names_the_clipping_and_leaves_the_channel_out():
    check = {"errors": [], "warnings": [
        {"level": "warning", "where": "/phase2/s000/r000/imu_acc[x]",
         "what": "clipping: 12 samples at the maximum 25 against 1 at the next value inside (24.99): a pile-up"},
        {"level": "warning", "where": "/phase2/s000/r001/imu_acc[x]",
         "what": "clipping: 11 samples at the minimum -25"},
        {"level": "warning", "where": "/phase1/c000/acc1[y]",
         "what": "dropout: 40 samples in a row hold 0.1 from index 9"},
        {"level": "warning", "where": "/phase2/s000/r000/imu_gyro[y]",
         "what": "clipping: 9 samples at the maximum 4.3"},
    ]}
    regs = _regions()
    found = found_by_check(check, regs, ARTEFACTS)
    by = {f["channel"]: f for f in found}
    assert set(by) == {"imu_acc", "imu_gyro"}  # a dropout leaves its channel in
    assert by["imu_acc"]["effect"] == "clipping:imu_acc" and by["imu_acc"]["params"] == {"range": 25.0}
    assert by["imu_acc"]["n_findings"] == 2 and by["imu_acc"]["statistics_left_out"] == 3
    assert by["imu_acc"]["unit"] == "m/s²" and by["imu_gyro"]["unit"] == ""
    from analysis.diagnosis.wording import check_phrase

    said = check_phrase({"found_by_check": found})
    assert said.startswith("twin check finds imu_acc clipped at ±25 m/s² (the artefact clipping:imu_acc), 2 findings")
    assert "imu_gyro clipped at ±4.3, 1 finding (" in said and check_phrase({"found_by_check": []}) is None
    assert "so it is named from the check's evidence and left out, and the rest" in said
    flat = found_by_check({"errors": [{"level": "error", "where": "/phase1/c000/torque",
                                       "what": "flat line: all 100 samples are 0.25"}]}, regs, ARTEFACTS)
    assert flat[0]["effect"] is None and flat[0]["finding"] == "flat line" and flat[0]["statistics_left_out"] == 2
    assert check_phrase({"found_by_check": flat}).startswith("twin check finds torque flat line, 1 finding")
    assert "so it is left out, and the rest" in check_phrase({"found_by_check": flat})
    assert by["imu_gyro"]["effect"] is None  # the library has no clipping of the gyroscope: found, not named
    sig = Signature(np.arange(len(regs), dtype=float), regs)
    out = leave_out(sig, ["imu_acc"])
    assert np.isnan(out.values).tolist() == [False] * 5 + [True, False, True, True]
    assert leave_out(sig, []) is sig
    result = {"found_by_check": found, "added": [{"effect": "cogging", "params": {"torque_Nm": 0.03}}]}
    assert [a["effect"] for a in named(result)] == ["clipping:imu_acc", "cogging"]
    assert found_by_check(None, regs, ARTEFACTS) == [] and found_by_check({"warnings": check["warnings"][2:3]},
                                                                          regs, ARTEFACTS) == []
