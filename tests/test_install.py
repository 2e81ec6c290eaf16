"""Installing as users do (issue 14, deliverable 5): the analysis and its verbs without the
simulator, Rerun or Dask; a verb whose extra is missing exits 2 naming the extra; the shipped
scenarios found by name outside a checkout; ``twin --version``.

The fast tests block the optional modules in a fresh interpreter (``sys.modules[name] = None``
makes their import fail as if they were not installed); the ``slow`` one builds the wheel and
installs it into a new virtualenv outside the checkout (about 1.5 min with pip's cache)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REFERENCE_TINY, REPO, SMALL, TINY_PHASE1, simulate_shared

OPTIONAL = ("mujoco", "rerun", "dask", "distributed")
BLOCKED = ("import sys\n"
           f"for m in {OPTIONAL!r}: sys.modules[m] = None\n"
           "sys.argv = ['twin', *sys.argv[1:]]\n"
           "from twin.cli import main\n"
           "main()\n")


def run_blocked(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-c", BLOCKED, *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def one_line(text: str) -> str:
    return " ".join(text.split())


def missing(verb: str, extra: str, what: str, module: str) -> str:
    return (f"error: twin {verb} needs {what}: {module} is not installed; install the extra with: "
            f"pip install 'ballscrew-twin[{extra}]' (or [all] for every extra)")


@pytest.mark.parametrize(("args", "message"), [
    (["simulate", "quick", "-o", "out"], missing("simulate", "sim", "MuJoCo (the simulator)", "mujoco")),
    (["demo", "-o", "out"], missing("demo", "sim", "MuJoCo (the simulator)", "mujoco")),
    (["export-model", "-o", "m.xml"], missing("export-model", "sim", "MuJoCo (the simulator)", "mujoco")),
    (["view", "."], missing("view", "view", "Rerun (the viewer)", "rerun")),
    (["diagnose", ".", "--scenario", "quick"], missing("diagnose", "sim", "MuJoCo (the simulator)", "mujoco")),
])
def test_verb_without_its_extra_exits_2_naming_it(tmp_path, args, message):
    r = run_blocked(*args, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert one_line(r.stderr) == message
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()


def test_sweep_on_a_cluster_needs_the_cluster_extra(tmp_path, monkeypatch):
    # MuJoCo present, Dask absent: a local sweep would run, --workers N (a LocalCluster) does not.
    code = BLOCKED.replace(repr(OPTIONAL), repr(("dask", "distributed")))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-c", code, "sweep", str(REPO / "scenarios/sweeps/detection.toml"),
                        "-o", "out", "--workers", "2"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 2
    assert one_line(r.stderr) == missing("sweep", "cluster", "Dask (the cluster)", "distributed")


def test_analysis_verbs_run_without_the_optional_modules(small_campaign, tmp_path):
    """``twin backlash`` and ``twin score`` on a campaign, with MuJoCo, Rerun and Dask unimportable."""
    r = run_blocked("backlash", small_campaign, "-o", tmp_path / "backlash", "--no-plots", cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "backlash" / "backlash.json").is_file()
    r = run_blocked("detect", tmp_path / "nothing", "--reference", tmp_path, cwd=tmp_path)
    assert r.returncode == 2 and "no measurements.h5" in r.stderr
    r = run_blocked("--version", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.startswith("ballscrew-twin ")


def test_shipped_scenarios_by_name(tmp_path):
    from twin.sim.scenario import ScenarioError, find_scenario, load, shipped_names

    assert {"quick", "demo", "paper-rtf", "backlash-steps"} <= set(shipped_names())
    assert load("quick") == load(REPO / "scenarios/quick.toml")
    assert find_scenario("quick.toml").resolve() == (REPO / "scenarios/quick.toml").resolve()
    with pytest.raises(ScenarioError) as e:
        find_scenario("quik")
    assert str(e.value) == ("quik: no such file, nor a shipped scenario; shipped scenarios: "
                            + ", ".join(shipped_names()))
    # A path is never a name: a missing file keeps the reader's message.
    with pytest.raises(ScenarioError, match="cannot read the scenario file"):
        load(tmp_path / "quick.toml")


def _venv_bin(venv: Path, name: str) -> Path:
    return venv / "bin" / name


@pytest.mark.slow
def test_wheel_installs_without_extras_then_with_sim(tmp_path, tmp_path_factory, small_campaign):
    """Build the wheel, install it without extras into a fresh virtualenv outside the checkout,
    run the analysis there, then add [sim] and simulate a shipped scenario by name."""
    src = tmp_path / "src"
    shutil.copytree(REPO, src, symlinks=True, ignore=shutil.ignore_patterns(
        ".venv", "build", "*.egg-info", "runs", "out", ".git", "__pycache__", ".pytest_cache"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-w", str(tmp_path / "dist"),
                    "-q"], check=True, capture_output=True)
    wheel = next((tmp_path / "dist").glob("ballscrew_twin-*.whl"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = [str(_venv_bin(venv, "python")), "-m", "pip", "install", "-q"]
    subprocess.run([*pip, str(wheel)], check=True, capture_output=True)
    work = tmp_path / "work"  # outside the checkout: nothing of REPO on the path
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    twin = str(_venv_bin(venv, "twin"))

    def run(*args):
        return subprocess.run([twin, *map(str, args)], cwd=work, env=env, capture_output=True, text=True,
                              timeout=900)

    r = subprocess.run([str(_venv_bin(venv, "python")), "-c", "import mujoco"], capture_output=True)
    assert r.returncode != 0  # really without the simulator
    r = run("--version")
    assert r.stdout.strip() == f"ballscrew-twin {wheel.name.split('-')[1]}"
    r = run("simulate", "quick", "-o", "q")
    assert r.returncode == 2
    assert one_line(r.stderr) == missing("simulate", "sim", "MuJoCo (the simulator)", "mujoco")
    # Phase I on a tiny campaign and its reference set, simulated by the checkout's environment.
    simulate_shared(tmp_path_factory, REPO / "scenarios/paper-reference.toml", tmp_path / "ref", *REFERENCE_TINY)
    simulate_shared(tmp_path_factory, REPO / "scenarios/phase1-quick.toml", tmp_path / "camp", *TINY_PHASE1)
    r = run("detect", tmp_path / "camp", "--reference", tmp_path / "ref", "-o", work / "p1",
            "--method", "pca_t2")
    assert r.returncode == 0, r.stderr[-2000:]
    assert (work / "p1" / "detection.json").is_file()
    r = run("backlash", small_campaign, "-o", work / "bl", "--no-plots")
    assert r.returncode == 0, r.stderr[-2000:]
    # Add the simulator: the shipped scenario is found by name.
    subprocess.run([*pip, f"{wheel}[sim]"], check=True, capture_output=True)
    r = run("simulate", "quick", "-o", "q", *SMALL, "--workers", "1")
    assert r.returncode == 0, r.stderr[-2000:]
    assert (work / "q" / "measurements.h5").is_file() and (work / "q" / "truth.h5").is_file()


def test_the_command_line_starts_without_the_heavy_libraries():
    """`twin` parses its arguments before it loads a numerical library beyond NumPy: the suite
    and every user run it in a fresh process (SciPy's optimize and special alone took about a
    second of its start), and `spawn` workers start the same way."""
    probe = ("import sys, twin.cli\n"
             "print(sorted({m.split('.')[0] for m in sys.modules} & {'scipy', 'sklearn', 'h5py', 'mujoco', "
             "'matplotlib', 'pandas', 'dask', 'rerun'}))")
    out = subprocess.run([sys.executable, "-c", probe], env=dict(os.environ, PYTHONPATH=str(REPO)),
                         capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
