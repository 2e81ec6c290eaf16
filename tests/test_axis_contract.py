"""The axis contract (issue 14, deliverable 2): the documented example validates and drives the
estimator; wrong, wrongly spelt and missing keys are refused naming ``/@axis.<key>``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from analysis.dataset import DatasetError
from analysis.dataset.axis import AxisDescription, MissingAxisKey, run_routine
from analysis.dataset.read import Phase2Run
from analysis.phase2.backlash import estimator_for

DOC = Path(__file__).resolve().parent.parent / "docs" / "dataset-format.md"


def doc_example() -> dict:
    text = DOC.read_text(encoding="utf-8")
    block = text.split("<!-- axis-example -->\n```json\n", 1)[1].split("```", 1)[0]
    return json.loads(block)


class _File:
    """The part of :class:`analysis.dataset.Measurements` the contract reads."""

    def __init__(self, axis: dict):
        self._axis, self.label = axis, "lab.h5"

    def axis(self) -> dict:
        return self._axis


def test_doc_example_validates_and_sets_the_estimator():
    a = AxisDescription.from_dict(doc_example())
    assert (a.lead_mm, a.travel_mm, a.sensors.imu_gyroscope.range_deg_s) == (5.0, 300.0, 125.0)
    est = estimator_for(_File(doc_example()))
    assert (est.lead_m, est.travel_m) == (pytest.approx(0.005), pytest.approx(0.300))
    assert AxisDescription.from_dict(a.to_dict()) == a  # what the writer stores reads back equal


def test_routine_falls_back_on_the_contract_and_the_run_wins():
    import numpy as np

    run = Phase2Run(session="s0000", run="r0000", hours=1.0, imu_acc=np.zeros((2, 3)), imu_acc_fs_hz=1000.0,
                    imu_gyro=np.zeros((2, 3)), imu_gyro_fs_hz=1000.0, position_cmd=np.zeros(2),
                    position_cmd_fs_hz=1000.0, speeds_mm_s=None, routine={"dwell_s": 5.0})
    routine, speeds = run_routine(_File(doc_example()), run)
    assert speeds == (20.0, 100.0)
    assert routine == {"accel_mm_s2": 5000.0, "start_mm": 0.0, "end_mm": 300.0, "dwell_s": 5.0}


@pytest.mark.parametrize("edit, message", [
    ({"lead_mm": -5}, "lab.h5: /@axis.lead_mm is -5; expected a number > 0"),
    ({"lead_mm": "x"}, "lab.h5: /@axis.lead_mm is 'x'; expected input should be a valid number"),
    ({"travel_m": 0.3}, "key 'travel_m' is not part of the axis contract: write 'travel_mm'"),
    ({"axis_version": 2}, "lab.h5: /@axis.axis_version is 2; this reader supports axis_version 1"),
    ({"phase2_routine": {"speeds_mm_s": [20, "fast"]}},
     "lab.h5: /@axis.phase2_routine.speeds_mm_s.1 is 'fast'; expected input should be a valid number"),
])
def test_bad_values_are_refused_naming_the_key(edit, message):
    with pytest.raises(DatasetError) as e:
        AxisDescription.from_dict({**doc_example(), **edit}, "lab.h5")
    assert message in str(e.value)


def test_missing_key_names_key_and_analysis():
    axis = doc_example()
    del axis["lead_mm"]
    with pytest.raises(MissingAxisKey) as e:
        estimator_for(_File(axis))
    assert str(e.value).startswith("lab.h5: /@axis.lead_mm is missing; the Phase II backlash estimate "
                                   "(Eq. 9: travel L and lead p) needs it")
    assert estimator_for(_File(axis), lead_m=0.005).lead_m == 0.005  # an explicit value is no fallback
