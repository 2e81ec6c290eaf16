"""Methods from outside the package (issue 17): a developer's own detector and backlash estimator,
in a package written into a temporary directory outside the repository, run through every verb
without editing a file of this package.

- default suite: ``--method mymethods:KNN`` / ``--estimator mymethods:ScaledShift`` importable
  from ``PYTHONPATH``: detect, backlash, score and report name both;
- slow (about 4 min on 2 cores): the same package pip-installed (``--no-deps``) with entry
  points in ``ballscrew_twin.detectors`` and ``ballscrew_twin.backlash_estimators``, chosen by
  name through the same verbs and a 4-point sweep (tables, ROC, plots, a point's report), then
  uninstalled.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pandas as pd
import pytest
from conftest import REFERENCE_TINY, REPO, run_twin, simulate_shared

from analysis.base import registry

PACKAGE = '''
"""A developer's own methods: a kNN detector and a scaled backlash estimator."""
import dataclasses

from sklearn.neighbors import NearestNeighbors

from analysis.phase1 import limits
from analysis.phase1.detectors import PhaseIDetector
from analysis.phase2.backlash import BacklashEstimator


class KNN(PhaseIDetector):
    """Mean distance to the k nearest baseline samples; three-sigma limit (leave-one-out)."""

    label = "kNN distance"
    _min_samples = 3

    def __init__(self, n_neighbors=3):
        self.n_neighbors = n_neighbors

    def _fit(self, X):
        k = min(self.n_neighbors, X.shape[0] - 1)
        self.nn_ = NearestNeighbors(n_neighbors=k).fit(X)
        dist, _ = self.nn_.kneighbors(X, n_neighbors=k + 1)
        self.threshold_ = limits.three_sigma(dist[:, 1:].mean(axis=1))

    def _score(self, X):
        return self.nn_.kneighbors(X)[0].mean(axis=1)


class ScaledShift(BacklashEstimator):
    """The paper's shift estimate times ``scale`` (a subclass with its own __init__(**kw))."""

    label = "Scaled shift"

    def __init__(self, scale=1.0, **kw):
        super().__init__(**kw)
        self.scale = scale

    def estimate(self, X):
        r = super().estimate(X)
        return dataclasses.replace(r, delta_backlash_shift_m=self.scale * r.delta_backlash_shift_m)
'''

PYPROJECT = '''
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "mymethods-{tag}"
version = "0.1"

[tool.setuptools]
packages = ["mymethods_{tag}"]

[project.entry-points."ballscrew_twin.detectors"]
knn_{tag} = "mymethods_{tag}:KNN"

[project.entry-points."ballscrew_twin.backlash_estimators"]
scaled_{tag} = "mymethods_{tag}:ScaledShift"
'''

# A campaign with both phases, as small as it gets: 25 Phase I samples of one 3-s capture (onset
# 172 h), two Phase II sessions (100, 250 h; ~2 µm of backlash) of one run over 200 mm.
POINT = ["campaign.total_hours=250", "phase1.captures_per_sample=1", "phase1.capture_s=3.0",
         "phase2.session_hours=[100.0, 250.0]", "phase2.runs_per_session=1", "phase2.end_mm=200.0",
         "phase2.dwell_s=1.0"]
REFERENCE = ["phase1.captures_per_sample=1", "phase1.capture_s=3.0", "phase1.sample_interval_hours=40"]


def twin(*args, pythonpath: str | None = None, check: bool = True):
    path = os.pathsep.join(p for p in (str(REPO), pythonpath) if p)
    r = run_twin(*args, check=False, env=dict(os.environ, PYTHONPATH=path, COLUMNS="400"), timeout=900)
    if check:
        assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r


def flat_text(r) -> str:
    """stdout and stderr with rich's wrapping undone."""
    return " ".join((r.stdout + r.stderr).split())


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("plugins")
    sets = [a for kv in POINT for a in ("--set", kv)]
    twin("simulate", REPO / "scenarios/demo.toml", "-o", root / "camp", *sets)
    simulate_shared(tmp_path_factory, REPO / "scenarios/paper-reference.toml", root / "ref", *REFERENCE_TINY)
    return root


def _package(root, tag: str = "") -> str:
    """Write the package (module ``mymethods`` + tag) into ``root`` (outside the repository)."""
    name = f"mymethods_{tag}" if tag else "mymethods"
    (root / name).mkdir(parents=True)
    (root / name / "__init__.py").write_text(PACKAGE)
    if tag:
        (root / "pyproject.toml").write_text(PYPROJECT.format(tag=tag))
    assert REPO not in root.parents
    return name


def _run_everything(root, camp, ref, det: str, est: str, det_name: str, est_name: str,
                    pythonpath: str | None, sweep: bool):
    """detect, backlash, score, report (and with ``sweep`` a 4-point sweep) with ``det`` and
    ``est``; asserts the names (and labels) appear in every output."""
    r = twin("detect", camp, "--reference", ref, "--method", "pca_t2", "--method", det,
             pythonpath=pythonpath)
    assert "kNN distance" in flat_text(r) and "PCA-T²" in flat_text(r)
    doc = json.loads((camp / "phase1" / "detection.json").read_text())
    assert list(doc["methods"]) == ["pca_t2", det_name]
    assert doc["methods"][det_name]["label"] == "kNN distance"
    # kNN on the selected features detects the preload loss after the onset (172 h).
    assert doc["methods"][det_name]["detection_hours"] > 172

    twin("backlash", camp, "--no-plots", pythonpath=pythonpath)  # the default, in backlash/
    r = twin("backlash", camp, "--no-plots", "--estimator", est, "--set-param", "scale=0.5",
             pythonpath=pythonpath)
    assert f"estimator {est_name} (Scaled shift)" in flat_text(r)
    bj = json.loads((camp / "backlash" / est_name / "backlash.json").read_text())
    assert bj["estimator"]["name"] == est_name
    # get_params keeps the inherited parameters of a subclass with __init__(scale, **kw).
    assert bj["parameters"]["estimator_params"]["scale"] == 0.5
    assert bj["parameters"]["estimator_params"]["dofs"] == ["E_YX", "E_ZX"]
    default = json.loads((camp / "backlash" / "backlash.json").read_text())
    for a, b in zip(bj["sessions"], default["sessions"], strict=True):
        assert a["delta_backlash_um"] == pytest.approx(0.5 * b["delta_backlash_um"], abs=1e-9)

    r = twin("score", camp, pythonpath=pythonpath)
    text = flat_text(r)
    assert "kNN distance" in text and "Scaled shift" in text and "Signal shifts" in text
    # each estimator's name beside its label, not taken for Rich markup ([shift] would be)
    assert f"[{est_name}]" in text and "Signal shifts (Eq. 6) [shift]" in text
    sc = json.loads((camp / "score.json").read_text())
    assert set(sc["phase1"]["methods"]) == {"pca_t2", det_name}
    assert list(sc["phase2_estimators"]) == ["shift", est_name]

    twin("report", camp, pythonpath=pythonpath)
    html = (camp / "report" / "index.html").read_text()
    assert "kNN distance" in html and "Scaled shift" in html and f"[{est_name}]" in html
    if not sweep:
        return

    sweep = root / "sweep.toml"
    sweep.write_text(textwrap.dedent(f"""
        name = "plugins"
        scenario = "{REPO / 'scenarios/demo.toml'}"
        seeds = [1]
        [set]
        {chr(10).join(f'"{k}" = {v}' for k, v in (kv.split("=", 1) for kv in POINT))}
        [[grid]]
        key = "degradation.wear_rate_um_per_kh"
        values = [40.0, 80.0]
        [[grid]]
        key = "sensors.imu_acc_noise_ug_per_rthz"
        values = [5.0, 20.0]
        [reference]
        scenario = "{REPO / 'scenarios/paper-reference.toml'}"
        [reference.set]
        {chr(10).join(f'"{k}" = {v}' for k, v in (kv.split("=", 1) for kv in REFERENCE))}
        [analysis]
        methods = ["pca_t2", "{det}"]
        estimators = ["shift", "{est}"]
        """))
    r = twin("sweep", sweep, "-o", root / "sw", "--methods", f"pca_t2,{det_name}",
             pythonpath=pythonpath)
    text = flat_text(r)
    assert f"{det_name} delay h" in text and f"{est_name}.rms_error_um" in text
    df = pd.read_parquet(root / "sw" / "results.parquet")
    assert len(df) == 4 and df.get("error") is None
    assert df[f"phase1.{det_name}.detection_hours"].notna().all()
    assert df[f"phase2.{est_name}.rms_error_um"].notna().all()
    assert set(pd.read_csv(root / "sw" / "roc.csv")["method"]) == {"pca_t2", det_name}
    plots = json.loads((root / "sw" / "plots" / "index.json").read_text())
    assert "plots/phase2_estimators_vs_degradation_wear_rate_um_per_kh.png" in plots
    assert "plots/detection_roc.png" in plots
    twin("report", root / "sw" / "points" / "p0000_s1", pythonpath=pythonpath)
    html = (root / "sw" / "points" / "p0000_s1" / "report" / "index.html").read_text()
    assert "kNN distance" in html and "Scaled shift" in html


def test_module_class_methods_through_every_verb(campaign, tmp_path):
    """module:Class from PYTHONPATH, nothing installed, no file of the package edited."""
    before = subprocess.run(["git", "status", "--porcelain"], cwd=REPO, capture_output=True,
                            text=True).stdout
    pkg = tmp_path / "src"
    _package(pkg)
    camp = tmp_path / "camp"
    camp.mkdir()
    for f in ("measurements.h5", "truth.h5"):
        (camp / f).symlink_to(campaign / "camp" / f)
    _run_everything(tmp_path, camp, campaign / "ref", "mymethods:KNN", "mymethods:ScaledShift",
                    "KNN", "ScaledShift", str(pkg), sweep=False)
    after = subprocess.run(["git", "status", "--porcelain"], cwd=REPO, capture_output=True,
                           text=True).stdout
    assert after == before


@pytest.mark.slow
def test_installed_entry_points_through_every_verb(campaign, tmp_path):
    """The package pip-installed with entry points; its methods are chosen by name."""
    tag = f"t{os.getpid()}"
    pkg = tmp_path / "src"
    _package(pkg, tag)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    # Built in pip's isolated build environment (setuptools from the configured index, as `make
    # venv` does): the environment's own setuptools may lack bdist_wheel.
    subprocess.run([*pip, "install", "--no-deps", str(pkg)], check=True, capture_output=True,
                   timeout=600)
    try:
        r = subprocess.run([sys.executable, "-c", "from analysis.base import registry; "
                            "print(registry.names('detectors'), registry.names('backlash_estimators'))"],
                           capture_output=True, text=True, check=True, cwd=tmp_path)
        assert f"knn_{tag}" in r.stdout and f"scaled_{tag}" in r.stdout
        camp = tmp_path / "camp"
        camp.mkdir()
        for f in ("measurements.h5", "truth.h5"):
            (camp / f).symlink_to(campaign / "camp" / f)
        _run_everything(tmp_path, camp, campaign / "ref", f"knn_{tag}", f"scaled_{tag}",
                        f"knn_{tag}", f"scaled_{tag}", None, sweep=True)
    finally:
        subprocess.run([*pip, "uninstall", "-y", f"mymethods-{tag}"], check=True,
                       capture_output=True, timeout=300)
    assert f"knn_{tag}" not in registry.names("detectors")


def test_unknown_or_bad_methods_exit_2(campaign, tmp_path):
    r = twin("backlash", campaign / "camp", "-o", tmp_path / "b", "--estimator", "nope", check=False)
    msg = flat_text(r)
    assert r.returncode == 2 and "backlash estimator 'nope' is unknown" in msg and "shift, pitch" in msg
    r = twin("backlash", campaign / "camp", "-o", tmp_path / "b", "--set-param", "bogus=1", check=False)
    msg = flat_text(r)
    assert r.returncode == 2 and "unknown parameter(s) bogus" in msg
    r = twin("detect", campaign / "camp", "--reference", campaign / "ref", "-o", tmp_path / "d",
             "--method", "nomodule:Nothing", check=False)
    msg = flat_text(r)
    assert r.returncode == 2 and "'nomodule:Nothing': cannot import it" in msg
    assert registry.style("detectors", "pca_t2") == ("tab:blue", "o")
