"""One executor choice for `twin simulate`, `twin backlash` and `twin sweep`
(analysis/base/executors.py): units of a campaign sent to a real Dask scheduler, and the sessions
of `twin backlash` run on local processes or on that scheduler, give exactly what one process
gives."""

from __future__ import annotations

import json
import logging
import os
import re

import h5py
import numpy as np
import pytest
from conftest import REPO, run_twin

from analysis.base.executors import mapper
from analysis.phase2.workflow import run as backlash_run
from twin.sim.campaign import simulate_campaign
from twin.sim.scenario import load

# backlash-steps cut to three sessions (0, 2 and 20 µm) of two short runs at 100 mm/s.
TINY = ["phase2.session_hours=[100.0, 300.0, 600.0]", "phase2.runs_per_session=2",
        "phase2.dwell_s=0.3", "phase2.start_mm=150.0", "phase2.end_mm=300.0"]


@pytest.fixture(scope="module")
def scheduler():
    """The address of a real dask.distributed LocalCluster (two single-threaded processes)."""
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=logging.ERROR)
    yield cluster.scheduler_address
    cluster.close()


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory, scheduler):
    """The tiny campaign simulated in this process and on the Dask cluster."""
    s = load(REPO / "scenarios/backlash-steps.toml", TINY)
    root = tmp_path_factory.mktemp("executors")
    serial = simulate_campaign(s, root / "serial", workers=1)
    dask = simulate_campaign(s, root / "dask", scheduler=scheduler)
    return root, serial, dask


def _items(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda k, v: out.__setitem__(k, (v[()] if isinstance(v, h5py.Dataset) else None,
                                                      dict(v.attrs))))
        out["/"] = (None, dict(f.attrs))
    return out


def test_simulate_on_a_dask_scheduler_equals_one_process(campaigns):
    root, serial, dask = campaigns
    assert serial["executor"] == "this process" and dask["executor"].startswith("dask cluster at")
    assert dask["simulated"] == serial["simulated"] > 3
    for name in ("measurements.h5", "truth.h5"):
        a, b = _items(root / "serial" / name), _items(root / "dask" / name)
        assert a.keys() == b.keys()
        for k in a:
            (da, aa), (db, ab) = a[k], b[k]
            assert (da is None) == (db is None) and (da is None or np.array_equal(da, db)), (name, k)
            assert aa.keys() == ab.keys(), (name, k)
            for key in aa:
                assert np.array_equal(aa[key], ab[key]), (name, k, key)


def test_backlash_sessions_in_parallel_equal_serial(campaigns, scheduler):
    root, _, _ = campaigns
    d = root / "serial"
    docs = {}
    for label, mapping in (("serial", None), ("processes", mapper(2, prefix="session")),
                           ("dask", mapper(scheduler=scheduler, prefix="session"))):
        br = backlash_run(d, root / f"bl-{label}", plots=False, map_sessions=mapping)
        docs[label] = json.loads((root / f"bl-{label}" / "backlash.json").read_text())
        assert [s["session"] for s in docs[label]["sessions"]] == ["s0000", "s0001", "s0002"]
        assert len(br.result.error_motions) == 3
    assert docs["processes"] == docs["serial"]
    assert docs["dask"] == docs["serial"]


def test_scheduler_and_workers_exclude_each_other(tmp_path):
    for cmd in (["simulate", REPO / "scenarios/quick.toml", "-o", tmp_path / "x"],
                ["backlash", tmp_path]):
        r = run_twin(*cmd, "--workers", "2", "--scheduler", "tcp://127.0.0.1:9", check=False)
        assert r.returncode == 2 and "--scheduler and --workers exclude each other" in r.stdout + r.stderr
        assert "Traceback" not in r.stderr


def test_diagnose_on_a_dask_scheduler_equals_local_processes(scheduler, tmp_path):
    """`twin diagnose --budget-minutes --scheduler` (issue 15, item 3): the twin's seeds, a twin
    parameter's grid, an effect's grid and a signal artefact's post-processing run on the Dask
    cluster's workers (2, as the local processes), with their own cache; the subset is chosen,
    calibrated and simulated there, and the diagnosis is that of two local processes, number for
    number; only the times differ."""
    bench = REPO / "scenarios/diagnose-bench.toml"
    sets = [a for kv in ("campaign.phase2=false", "phase1.capture_s=1.0") for a in ("--set", kv)]
    run_twin("simulate", bench, "-o", tmp_path / "real", *sets, "--set", "axis.carriage_mass_kg=160",
             "--set", "seed=3", "--set", "phase1.captures_per_sample=3")
    cands = [a for c in ("axis.carriage_mass_kg", "cogging", "gain:acc1") for a in ("--candidate", c)]
    docs = {}
    for label, where in (("local", ["--workers", "2"]), ("dask", ["--scheduler", scheduler])):
        # 5 seeds: the minimum subset's 2 samples give the spread fewer degrees of freedom; each
        # candidate's response on one seed (the default 3 multiply its grid, not what runs where)
        args = ["diagnose", tmp_path / "real", "--scenario", bench, *sets, *cands, "--seeds", "5",
                "--response-seeds", "1", *where,
                "-o", tmp_path / label, "--cache", tmp_path / f"cache-{label}"]
        # 0.6 s holds no subset: refused, naming the smallest budget that does (the minimum)
        r = run_twin(*args, "--budget-minutes", "0.01", check=False)
        assert r.returncode == 2 and "is too small: give at least" in r.stderr, r.stderr[-2000:]
        least = re.search(r"give at least ([0-9.]+)", " ".join(r.stderr.split())).group(1)
        r = run_twin(*args, "--budget-minutes", least)
        assert "Traceback" not in r.stderr
        docs[label] = json.loads((tmp_path / label / "diagnosis.json").read_text())
    sub = docs["local"]["subset"]
    assert sub["phase1"]["samples"] == [0, 2] and sub["phase1"]["captures_per_sample"] == 2
    assert docs["dask"]["subset"]["workers"] == sub["workers"] == 2
    # a significant gap, every candidate fitted and the best re-simulated: the comparison below
    # compares real work
    assert docs["local"]["heldout_gap_before"] > docs["local"]["heldout_gap_critical"]
    assert sorted(c["effect"] for c in docs["local"]["ranking"]) == ["axis.carriage_mass_kg", "cogging", "gain:acc1"]
    assert docs["local"]["added"] and docs["local"]["resimulation"]["done"]
    for doc in docs.values():
        for k in ("estimated_minutes", "actual_minutes", "calibration_s", "subset_write_s", "unit_costs_s",
                  "budget_minutes"):
            doc["subset"].pop(k)
    assert docs["dask"] == docs["local"]


def test_diagnose_scheduler_errors_are_exact(tmp_path):
    bench = REPO / "scenarios/diagnose-bench.toml"
    (tmp_path / "real").mkdir()
    r = run_twin("diagnose", tmp_path / "real", "--scenario", bench, "--scheduler", "tcp://127.0.0.1:1",
                 "--workers", "2", check=False)
    assert r.returncode == 2
    assert ("error: --scheduler and --workers exclude each other: --scheduler sends the simulations to an "
            "existing dask cluster, --workers N runs them in N local processes") in " ".join(r.stderr.split())


def test_diagnose_unknown_kind_is_refused_exactly(tmp_path):
    bench = REPO / "scenarios/diagnose-bench.toml"
    (tmp_path / "real").mkdir()
    for kinds, unknown in (("physical,bogus", "['bogus']"), (",", "[]")):
        r = run_twin("diagnose", tmp_path / "real", "--scenario", bench, "--kinds", kinds, check=False)
        assert r.returncode == 2
        assert (f"error: --kinds {kinds}: unknown kind(s) of candidate {unknown}; expected one or more of "
                "physical, parameter, artefact") in " ".join(r.stderr.split())


def test_keep_freed_memory_stops_refaulting_pages():
    """After keep_freed_memory(), allocating and freeing 8 MB arrays again and again reuses the
    same memory: at most a few page faults per array instead of hundreds (the array is 2048
    pages of 4 kB)."""
    import subprocess
    import sys

    code = ("import resource, numpy as np\n"
            "from analysis.base.executors import keep_freed_memory\n"
            "def faults():\n"
            "    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt\n"
            "    for _ in range(50):\n"
            "        a = np.ones(1 << 20); b = a * 2.0; del a, b\n"
            "    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0) / 50\n"
            "before = faults()\n"
            "applied = keep_freed_memory()\n"
            "faults()\n"
            "print(applied, before, faults())\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=REPO).stdout.split()
    applied, before, after = out[0] == "True", float(out[1]), float(out[2])
    print(f"\npage faults per 8 MB allocate-and-free: {before:.0f} before, {after:.0f} after")
    if not applied:
        pytest.skip("mallopt is not available here (not Linux with glibc): nothing to check")
    assert before > 500 and after < 50


def test_twin_workers_sets_the_default_processes_and_a_bad_value_is_refused(monkeypatch, tmp_path):
    """TWIN_WORKERS sets how many local processes a command starts when not told; a value that is
    not a whole number >= 1 ends any command with exit 2 naming the variable and the value."""
    from analysis.base.executors import _LocalPool, _Serial, default_processes, make_executor

    monkeypatch.setenv("TWIN_WORKERS", "3")
    assert default_processes() == 3
    monkeypatch.setenv("TWIN_WORKERS", "1")
    with make_executor() as ex:
        assert isinstance(ex, _Serial)
    monkeypatch.delenv("TWIN_WORKERS")
    assert default_processes() == (os.cpu_count() or 1)
    with make_executor(2) as ex:
        assert isinstance(ex, _LocalPool)
    for bad in ("0", "two", "-1"):
        r = run_twin("simulate", REPO / "scenarios/quick.toml", "-o", tmp_path / "x", check=False,
                     env=dict(os.environ, PYTHONPATH=str(REPO), TWIN_WORKERS=bad))
        assert r.returncode == 2 and "Traceback" not in r.stderr
        assert (f"environment variable TWIN_WORKERS='{bad}': expected a whole number of local processes >= 1"
                in " ".join((r.stdout + r.stderr).split()))
    assert not (tmp_path / "x").exists()
