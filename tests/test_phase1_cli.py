"""``twin detect`` (issue 3): the happy path and check 6 (bad input exits with code 2 naming the
file, group and channel, and what was computed before the error stays in OUT)."""

import json
import shutil

import h5py
import numpy as np
import pytest

from analysis.base import registry
from tests.conftest import REFERENCE_TINY, REPO, TINY_PHASE1, run_twin, simulate_shared


@pytest.fixture(scope="module")
def dirs(tmp_path_factory):
    root = tmp_path_factory.mktemp("phase1cli")
    ref, camp = root / "ref", root / "camp"
    simulate_shared(tmp_path_factory, REPO / "scenarios/paper-reference.toml", ref, *REFERENCE_TINY)
    simulate_shared(tmp_path_factory, REPO / "scenarios/phase1-quick.toml", camp, *TINY_PHASE1)
    return root, ref, camp


def test_detect_cli_happy_path(dirs):
    root, ref, camp = dirs
    out = root / "out"
    r = run_twin("detect", camp, "--reference", ref, "-o", out)
    print(r.stdout[-2500:], r.stderr[-800:])
    assert r.returncode == 0
    assert "PCA-T²" in r.stdout and "Autoencoder" in r.stdout
    doc = json.loads((out / "detection.json").read_text())
    assert list(doc["methods"]) == list(registry.names("detectors"))  # every registered detector
    assert (out / "detection.png").stat().st_size > 20_000
    # --method restricts the methods; an unknown one is a usage error (exit 2).
    r = run_twin("detect", camp, "--reference", ref, "-o", root / "out2", "--method", "pca_t2",
                 "--method", "ocsvm")
    assert r.returncode == 0
    assert set(json.loads((root / "out2/detection.json").read_text())["methods"]) == {"pca_t2", "ocsvm"}
    r = run_twin("detect", camp, "--reference", ref, "-o", root / "out3", "--method", "no_such_method",
                 check=False)
    msg = " ".join(r.stderr.split())
    assert r.returncode == 2 and "no_such_method" in msg and ", ".join(registry.names("detectors")) in msg


def _copy(src, dst):
    shutil.copytree(src, dst)
    return dst / "measurements.h5"


def _bad_run(root, ref, camp_dir, name):
    out = root / f"out-{name}"
    # --force: past twin check's refusal, to what detect computes before its own error
    r = run_twin("detect", camp_dir, "--reference", ref, "-o", out, "--force", check=False)
    msg = " ".join(r.stderr.split())  # rich may wrap long lines
    print(f"{name}: exit {r.returncode}: {msg[-400:]}")
    return r, msg, out


def test_missing_channel(dirs):
    root, ref, camp = dirs
    h5 = _copy(camp, root / "missing")
    with h5py.File(h5, "a") as f:
        del f["/phase1/c000020/acc2"]
    r, msg, out = _bad_run(root, ref, root / "missing", "missing")
    assert r.returncode == 2
    assert "measurements.h5" in msg and "/phase1/c000020/acc2 is missing" in msg
    # Computed before the error: the reference selection and the complete samples before it.
    assert json.loads((out / "selection.json").read_text())["selected"]
    partial = (out / "features.partial.csv").read_text().splitlines()
    assert len(partial) == 1 + 20


def test_nan_capture(dirs):
    root, ref, camp = dirs
    h5 = _copy(camp, root / "nan")
    with h5py.File(h5, "a") as f:
        d = f["/phase1/c000005/torque"]
        d[...] = np.full(d.shape, np.nan, dtype=d.dtype)
    r, msg, out = _bad_run(root, ref, root / "nan", "nan")
    assert r.returncode == 2
    assert "/phase1/c000005/torque" in msg and "non-finite" in msg
    assert (out / "reference_features.csv").is_file()
    assert len((out / "features.partial.csv").read_text().splitlines()) == 1 + 5


def test_truncated_file(dirs):
    root, ref, camp = dirs
    h5 = _copy(camp, root / "trunc")
    data = h5.read_bytes()
    h5.write_bytes(data[: len(data) // 2])
    r, msg, out = _bad_run(root, ref, root / "trunc", "trunc")
    assert r.returncode == 2
    assert "measurements.h5" in msg and "truncated" in msg
    assert not (out / "selection.json").exists()  # checked before any work


def test_missing_reference_truth(dirs):
    root, ref, camp = dirs
    bad_ref = root / "ref-no-truth"
    shutil.copytree(ref, bad_ref)
    (bad_ref / "truth.h5").unlink()
    r, msg, _ = _bad_run(root, bad_ref, camp, "noref")
    assert r.returncode == 2 and "truth.h5" in msg
