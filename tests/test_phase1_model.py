"""The persisted Phase I model (issue 32, item 1): ``twin detect --save-model`` then
``twin detect --model`` gives the same scores and alarms as fitting anew; a model of another
format version, or one whose recording differs from the campaign's, is refused naming both."""

import fractions
import json
import shutil
import zipfile

import h5py
import numpy as np
import pytest

from analysis.phase1.model_file import FORMAT_VERSION, Phase1Model
from tests.conftest import DEMO_SMALL, REFERENCE_SMALL, REPO, run_twin, simulate_shared


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    root = tmp_path_factory.mktemp("model")
    ref, demo = root / "ref", root / "demo"
    simulate_shared(tmp_path_factory, REPO / "scenarios/paper-reference.toml", ref, *REFERENCE_SMALL)
    simulate_shared(tmp_path_factory, REPO / "scenarios/demo.toml", demo, *DEMO_SMALL)
    model = root / "phase1.model"
    run_twin("detect", demo, "--reference", ref, "-o", root / "fit", "--save-model", model)
    return root, demo, model


def test_saved_model_gives_the_same_scores_and_alarms(fitted):
    root, demo, model = fitted
    proc = run_twin("detect", demo, "--model", model, "-o", root / "scored")
    assert "PCA-T²" in proc.stdout
    fit = json.loads((root / "fit/detection.json").read_text())["methods"]
    scored = json.loads((root / "scored/detection.json").read_text())["methods"]
    assert list(fit) == list(scored) == ["pca_t2", "gmm_md", "som_mqe", "iforest", "ocsvm", "autoencoder"]
    for name in fit:
        a, b = fit[name], scored[name]
        assert a["scores"] == b["scores"], name  # bit for bit
        assert a["threshold"] == b["threshold"] and a["detection_hours"] == b["detection_hours"], name
    assert fit["pca_t2"]["detection_hours"] is not None and fit["pca_t2"]["detection_hours"] > 172
    d_fit = json.loads((root / "fit/detection_details.json").read_text())
    d_scored = json.loads((root / "scored/detection_details.json").read_text())
    assert d_scored["n_baseline"] == d_fit["n_baseline"] == 15  # the model's baseline is this campaign's
    for name in fit:
        for key in ("false_alarms", "baseline_alarms", "delay_samples"):
            assert d_fit["methods"][name][key] == d_scored["methods"][name][key], (name, key)
    m = Phase1Model.load(model)
    assert m.n_baseline == 15 and m.recording == {"fs_hz": 10000.0, "channels": {
        "speed": 1, "torque": 1, "acc1": 3, "acc2": 3}}


def test_model_of_another_format_version_is_refused(fitted, tmp_path):
    _, demo, model = fitted
    other = tmp_path / "old.model"
    with zipfile.ZipFile(model) as z, zipfile.ZipFile(other, "w") as w:
        for item in z.namelist():
            data = z.read(item)
            if item == "model.json":
                doc = json.loads(data)
                doc["format_version"] = FORMAT_VERSION + 1
                data = json.dumps(doc)
            w.writestr(item, data)
    proc = run_twin("detect", demo, "--model", other, "-o", tmp_path / "out", check=False)
    assert proc.returncode == 2
    msg = " ".join(proc.stderr.split())
    assert (f"{other}: Phase I model format_version {FORMAT_VERSION + 1}; this version of "
            f"ballscrew-twin reads format_version {FORMAT_VERSION} only") in msg, msg


def test_model_refuses_a_recording_with_another_rate(fitted, tmp_path):
    _, demo, model = fitted
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(demo / "measurements.h5", other / "measurements.h5")
    with h5py.File(other / "measurements.h5", "r+") as f:
        for name in f["phase1"]:
            f[f"phase1/{name}"].attrs["fs_hz"] = np.float64(5000.0)
    proc = run_twin("detect", other, "--model", model, "-o", tmp_path / "out", check=False)
    assert proc.returncode == 2
    msg = " ".join(proc.stderr.split())
    assert (f"{other / 'measurements.h5'}: /phase1/c000000 does not match the Phase I model fitted "
            f"on {demo}: sampling rate fs_hz = 5000 Hz, the model expects 10000 Hz") in msg, msg


def test_model_with_an_untrusted_type_is_refused(fitted, tmp_path):
    import skops.io as sio

    _, _, model = fitted
    other = tmp_path / "evil.model"
    with zipfile.ZipFile(model) as z, zipfile.ZipFile(other, "w") as w:
        w.writestr("model.json", z.read("model.json"))
        w.writestr("detectors.skops", sio.dumps({"pca_t2": fractions.Fraction(1, 2)}))
    with pytest.raises(ValueError, match=r"holds type\(s\) fractions.Fraction that are not trusted"):
        Phase1Model.load(other)


def test_detect_needs_reference_or_model(fitted, tmp_path):
    _, demo, model = fitted
    proc = run_twin("detect", demo, "-o", tmp_path / "out", check=False)
    assert proc.returncode == 2
    assert "give either --reference REF" in " ".join(proc.stderr.split())
