"""Silent garbage (issue 14, deliverable 7): what must be refused or skipped with a reason, never
analysed: bytes changed after writing (Fletcher-32), values beyond a sensor's physical range,
negative or decreasing hours, wrongly typed axis metadata, absurd dimensions, links."""

import json
import shutil

import h5py
import numpy as np
import pytest

from analysis.dataset import DatasetError, open_measurements
from tests.conftest import run_twin


def one_line(text: str) -> str:
    return " ".join(text.split())


@pytest.fixture
def copy(small_campaign, tmp_path):
    d = tmp_path / "camp"
    d.mkdir()
    shutil.copy(small_campaign / "measurements.h5", d)
    return d, d / "measurements.h5"


def _first_run(h5):
    with open_measurements(h5) as m:
        s = m.phase2_sessions()[0]
        return s, m.phase2_runs(s)[0]


def test_every_dataset_carries_a_checksum_and_flipped_bytes_are_named(copy):
    d, h5 = copy
    s, r = _first_run(h5)
    key = f"/phase2/{s}/{r}/imu_gyro"
    with h5py.File(h5, "r") as f:
        kinds = []
        f.visititems(lambda k, o: kinds.append(o.fletcher32) if isinstance(o, h5py.Dataset) else None)
        assert kinds and all(kinds)
        info = f[key].id.get_chunk_info(0)
        good = f[key][()]
    data = bytearray(h5.read_bytes())
    for i in range(info.byte_offset + 8, info.byte_offset + 28):  # 20 bytes inside the data
        data[i] ^= 0x5A
    h5.write_bytes(bytes(data))
    with open_measurements(h5) as m, pytest.raises(DatasetError) as e:
        m.phase2(s, r)
    assert str(e.value) == (f"{h5}: {key} fails its Fletcher-32 checksum: its bytes changed after it was "
                            "written (a corrupt copy or disk); restore the file from a good copy")
    assert good.shape[1] == 3
    # twin backlash skips that run, naming it and the reason, and analyses the others.
    r_ = run_twin("backlash", d, "--no-plots", "--force", check=False)  # past twin check's refusal
    assert r_.returncode == 0, r_.stderr
    doc = json.loads((d / "backlash" / "backlash.json").read_text())
    assert {(x["session"], x["run"]) for x in doc["skipped_runs"]} == {(s, r)}
    assert "Fletcher-32 checksum" in doc["skipped_runs"][0]["reason"]


def test_gyro_beyond_its_physical_range_is_skipped_with_the_reason(copy):
    d, h5 = copy
    s, r = _first_run(h5)
    key = f"/phase2/{s}/{r}/imu_gyro"
    with h5py.File(h5, "a") as f:
        arr, attrs = f[key][()], dict(f[key].attrs)
        arr[5, 1] = 1e30
        del f[key]
        ds = f.create_dataset(key, data=arr)
        ds.attrs.update(attrs)
    with open_measurements(h5) as m, pytest.raises(DatasetError) as e:
        m.phase2(s, r)
    assert str(e.value) == (f"{h5}: {key} has 1 value(s) beyond the physical range of the channel, the largest "
                            "1e+30 rad/s at index (5, 1); expected |x| <= 100 rad/s (a wrong unit or scale "
                            "factor, or corrupt data)")
    out = run_twin("backlash", d, "--no-plots", "--force", check=False)  # past twin check's refusal
    assert out.returncode == 0
    assert f"warning: skipped session {s} run {r}: " in one_line(out.stderr)
    out = run_twin("backlash", d, "--no-plots", "--strict", check=False)
    assert out.returncode == 2 and "beyond the physical range" in out.stderr


def test_negative_hours_are_refused(copy):
    d, h5 = copy
    s, _ = _first_run(h5)
    with h5py.File(h5, "a") as f:
        f[f"/phase2/{s}"].attrs["hours"] = -1.0
    out = run_twin("backlash", d, "--no-plots", "--force", check=False)  # the reader's own refusal
    assert out.returncode == 2
    assert one_line(out.stderr) == (f"error: {h5}: /phase2/{s}@hours is -1.0; expected a finite number of "
                                    "operating hours >= 0")


def test_decreasing_dial_hours_are_refused(copy):
    _, h5 = copy
    with h5py.File(h5, "a") as f:
        if "dial_indicator" not in f:
            pytest.skip("no dial-indicator readings in this campaign")
        hours = f["/dial_indicator/hours"][()]
        hours[1] = hours[0] - 1.0
        f["/dial_indicator/hours"][...] = hours
    with open_measurements(h5) as m, pytest.raises(DatasetError) as e:
        m.dial_indicator()
    assert str(e.value) == (f"{h5}: /dial_indicator/hours[1] is {hours[1]:g}; expected operating hours >= 0 "
                            "that do not decrease")


@pytest.mark.parametrize(("value", "shown"), [("x", "'x'"), (-5, "-5"), ([1, 2], "[1, 2]")])
def test_wrongly_typed_lead_is_refused(copy, value, shown):
    """The axis contract (analysis.dataset.axis) refuses it, naming the key and the value."""
    d, h5 = copy
    with h5py.File(h5, "a") as f:
        axis = json.loads(f.attrs["axis"])
        axis["lead_mm"] = value
        f.attrs["axis"] = json.dumps(axis)
    out = run_twin("backlash", d, "--no-plots", check=False)  # twin check's error, listed in the refusal
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert one_line(out.stderr).startswith(f"error: {h5}: twin check finds 1 error(s), so twin backlash refuses "
                                           f"the recording (--force analyses it anyway): /@axis: {h5}: "
                                           f"/@axis.lead_mm is {shown}; expected ")
    out = run_twin("backlash", d, "--no-plots", "--force", check=False)  # the axis contract's own refusal
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert f"error: {h5}: /@axis.lead_mm is {shown}; expected " in one_line(out.stderr)


def test_absurd_dimension_and_links_are_refused_before_reading(copy):
    _, h5 = copy
    s, r = _first_run(h5)
    key = f"/phase2/{s}/{r}/imu_acc"
    with h5py.File(h5, "a") as f:
        attrs = dict(f[key].attrs)
        del f[key]
        ds = f.create_dataset(key, shape=(10**9, 3), dtype="f4", chunks=(1024, 3))
        ds.attrs.update(attrs)
        gkey = f"/phase2/{s}/{r}/imu_gyro"
        del f[gkey]
        f[gkey] = h5py.ExternalLink("/etc/hostname", "/x")
    with open_measurements(h5) as m, pytest.raises(DatasetError) as e:
        m.phase2(s, r)
    assert str(e.value) == (f"{h5}: {key} has shape (1000000000, 3) (3000000000 values); expected at most "
                            "33554432 values per dataset")
    with h5py.File(h5, "a") as f:
        del f[key]
        f[key] = h5py.SoftLink(f"/phase2/{s}/{r}/position_cmd")
    with open_measurements(h5) as m, pytest.raises(DatasetError) as e:
        m.phase2(s, r)
    assert str(e.value) == (f"{h5}: {key} is a soft link; expected the group or dataset itself (links are not "
                            "followed)")


def test_writer_refuses_values_beyond_the_physical_range(tmp_path):
    from analysis.dataset import assemble_measurements

    n = 100
    cap = {"speed": np.full(n, 2e3), "torque": np.zeros(n), "acc1": np.zeros((n, 3)), "acc2": np.zeros((n, 3))}
    with pytest.raises(DatasetError) as e:
        assemble_measurements(tmp_path / "m.h5", {"lead_mm": 10.0},
                              [("c000000", {"hours": 0.0, "sample": 0, "fs_hz": 1000.0}, cap)])
    assert str(e.value).startswith(f"{tmp_path / 'm.h5'}: /phase1/c000000/speed has 100 value(s) beyond the "
                                   "physical range of the channel, the largest 2000 rad/s at index 0")
    assert not (tmp_path / "m.h5").exists()
