"""``twin sweep`` (issue 5, checks 2, 3, 4 and 7).

One tiny sweep (Phase II only: 2 sessions of 1 run at 100 mm/s over 200 mm, 1 s dwell; 2 backlash steps x
2 IMU noise levels x 2 seeds = 8 campaigns) is run once with the default executor (local
processes, ``TWIN_WORKERS`` of them: 1 under the suite, tests/conftest.py); that table is the
reference of the other runs:
- (2) the same sweep on ``--workers 2`` (a dask LocalCluster) gives an identical table;
- (3) on a LocalCluster started here (``--scheduler``), one worker SIGKILLed while it runs a
  point: the sweep completes with every point and an identical table;
- (4) the sweep SIGKILLed (whole process group) after >= 2 points were recorded, then rerun:
  only the rest is computed (counted from OUT/sweep-log.jsonl), same table;
- (7) bad sweep files exit with code 2 and name the file, the key, the value and what is allowed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import pandas as pd
import pytest
from conftest import REPO, TWIN, run_twin

STEPS = REPO / "scenarios/backlash-steps.toml"
T0 = time.perf_counter()


@pytest.fixture(scope="module", autouse=True)
def _print_wall_time():
    """Print the module's wall time after its last test (with -s)."""
    yield
    print(f"\ntests/test_sweep.py wall time: {time.perf_counter() - T0:.1f} s")


def sweep_text(scenario_rel: str, extra: str = "", seeds: str = "[1, 2]") -> str:
    return f"""
name = "tiny"
scenario = "{scenario_rel}"
seeds = {seeds}
[set]
"phase2.session_hours" = [100.0, 300.0]
"phase2.runs_per_session" = 1
"phase2.end_mm" = 200.0
"phase2.dwell_s" = 1.0
"dial_indicator.every_n_sessions" = 2
"degradation.table_hours" = [100.0, 300.0]
"degradation.table_preload_fraction" = [1.0, 1.0]
"degradation.table_backlash_um" = [0.0, 10.0]
"campaign.total_hours" = 300.0
[[grid]]
key = "degradation.table_backlash_um[1]"
values = [5.0, 15.0]
[[grid]]
key = "sensors.imu_acc_noise_ug_per_rthz"
start = 5
stop = 20
num = 2
scale = "log"
{extra}"""


def write_sweep(directory, name="tiny.toml", extra: str = "", text: str | None = None, seeds: str = "[1, 2]"):
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / name
    path.write_text(text if text is not None else
                    sweep_text(os.path.relpath(STEPS, directory), extra, seeds))
    return path


def table(out):
    return pd.read_parquet(out / "results.parquet")


def same_as_seed_1_of(default, b) -> None:
    """``b``'s table (the one-seed sweep) is ``default``'s rows of seed 1, number for number: a
    point's result depends on its values and seed only, not on the other points or the executor."""
    want = table(default).query("seed == 1").reset_index(drop=True)
    pd.testing.assert_frame_equal(want, table(b), check_exact=True)
    head, *rows = (default / "results.csv").read_text().splitlines()
    assert head.split(",")[:2] == ["point", "seed"]
    want_csv = "\n".join([head, *(r for r in rows if r.split(",")[1] == "1")]) + "\n"
    assert (b / "results.csv").read_text() == want_csv


def log(out) -> list[dict]:
    from twin.harness.sweep import read_log

    return read_log(out)


def point_events(out, invocation=None) -> list[dict]:
    return [r for r in log(out) if r["event"] == "point" and invocation in (None, r["invocation"])]


def env():
    return dict(os.environ, PYTHONPATH=str(REPO))


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("sweep")


@pytest.fixture(scope="module")
def sweep_file(root):
    return write_sweep(root / "files")


@pytest.fixture(scope="module")
def one_seed_file(root):
    """The sweep with seed 1 only (4 points): what the other executors run, checked against
    the default run's rows of seed 1."""
    return write_sweep(root / "files", "one-seed.toml", seeds="[1]")


@pytest.fixture(scope="module")
def default_run(root, sweep_file):
    """The sweep on the default executor: the reference table of checks 2-4."""
    out = root / "default"
    t = time.perf_counter()
    r = run_twin("sweep", sweep_file, "-o", out, timeout=600)
    print(f"\ndefault executor: {time.perf_counter() - t:.1f} s\n{r.stdout}")
    return out


def test_default_table_recovers_the_injected_backlash(default_run):
    df = table(default_run)
    assert len(df) == 8
    assert list(df.columns[:4]) == ["point", "seed", "degradation.table_backlash_um[1]",
                                    "sensors.imu_acc_noise_ug_per_rthz"]
    assert list(zip(df["point"], df["seed"], strict=True)) == [(p, s) for p in range(4) for s in (1, 2)]
    assert sorted(set(df["degradation.table_backlash_um[1]"])) == [5.0, 15.0]
    assert sorted(set(df["sensors.imu_acc_noise_ug_per_rthz"])) == [5.0, 20.0]
    assert {"phase2.rms_error_um", "phase2.bias_um", "phase2.error_motion.E_ZX.rms_um"} <= set(df.columns)
    # Each point's score: the estimated change of backlash of the second session against the
    # injected one (5 or 15 µm). One run per session over 200 mm scatters by 0.20 µm (1σ) at
    # 5 µg/√Hz and 0.65 µm at 20 µg/√Hz (8 noise draws each); the tolerance is 3σ.
    for _, row in df.iterrows():
        rec = json.loads((default_run / row["directory"] / "result.json").read_text())
        s1 = rec["score"]["phase2"]["sessions"][1]
        assert s1["injected_delta_um"] == pytest.approx(row["degradation.table_backlash_um[1]"])
        tol = 0.6 if row["sensors.imu_acc_noise_ug_per_rthz"] == 5.0 else 2.0
        print(f"point {row['point']} seed {row['seed']}: injected {s1['injected_delta_um']:.1f} µm, "
              f"estimated {s1['estimated_delta_um']:.2f} µm")
        assert abs(s1["estimated_delta_um"] - s1["injected_delta_um"]) < tol
        assert row["phase2.rms_error_um"] == pytest.approx(abs(s1["error_um"]) / 2 ** 0.5)
    (end,) = [r for r in log(default_run) if r["event"] == "end"]
    assert (end["computed"], end["reused"], end["failed"]) == (8, 0, 0)
    assert end["simulated_units"] == 8 * 3  # 2 sessions + 1 dial-indicator reading per campaign
    pngs = list((default_run / "plots").glob("phase2_vs_*.png"))
    assert len(pngs) == 2 and all(p.stat().st_size > 20_000 for p in pngs)


def test_dask_local_cluster_gives_the_same_table(root, one_seed_file, default_run):
    """Check 2: --workers 2 (a real dask LocalCluster) against the default executor."""
    out = root / "workers2"
    t = time.perf_counter()
    r = run_twin("sweep", one_seed_file, "-o", out, "--workers", "2", timeout=600)
    print(f"--workers 2: {time.perf_counter() - t:.1f} s")
    assert "dask LocalCluster of 2 worker processes" in " ".join(r.stderr.split())
    same_as_seed_1_of(default_run, out)
    assert len({e["pid"] for e in point_events(out)}) == 2


def test_lost_dask_worker_does_not_lose_the_sweep(root, one_seed_file, default_run):
    """Check 3: SIGKILL one worker of the cluster while it runs a point."""
    import logging

    from distributed import Client, LocalCluster

    out = root / "killed-worker"
    t = time.perf_counter()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.CRITICAL) as cluster, Client(cluster) as client:
        proc = subprocess.Popen([*TWIN, "sweep", str(one_seed_file), "-o", str(out), "--scheduler",
                                 cluster.scheduler_address], cwd=REPO, env=env(),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.time() + 300
            while not point_events(out) and time.time() < deadline and proc.poll() is None:
                time.sleep(0.2)
            assert point_events(out), "no point was recorded"
            busy = {w: [k for k in keys if str(k).startswith("sweep-")]
                    for w, keys in client.processing().items()}
            victim = next(w for w, keys in busy.items() if keys)
            running = busy[victim][0].split("-")[1]           # sweep-<task id>-<token>
            pid = client.run(os.getpid, workers=[victim])[victim]
            os.kill(pid, signal.SIGKILL)
            killed_at = time.time()
            _, stderr = proc.communicate(timeout=600)
        finally:
            if proc.poll() is None:
                proc.kill()
    print(f"killed worker pid {pid} while it ran {running}; sweep {time.perf_counter() - t:.1f} s")
    assert proc.returncode == 0, stderr[-2000:]
    same_as_seed_1_of(default_run, out)
    events = point_events(out)
    assert sorted(e["id"] for e in events) == [f"p{p:04d}_s1" for p in range(4)]
    assert all(e["error"] is None for e in events)
    (rerun,) = [e for e in events if e["id"] == running]
    print(f"{running} recorded from pid {rerun['pid']}, {rerun['reused_units']} units reused")
    assert rerun["pid"] != pid
    (end,) = [r for r in log(out) if r["event"] == "end"]
    assert end["computed"] == 4 and end["time"] > killed_at


def test_interrupted_sweep_resumes_without_recomputing(root, one_seed_file, default_run):
    """Check 4: SIGKILL of the `twin sweep` process group after >= 2 recorded points."""
    out = root / "interrupted"
    t = time.perf_counter()
    proc = subprocess.Popen([*TWIN, "sweep", str(one_seed_file), "-o", str(out)], cwd=REPO, env=env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.time() + 300
        while len(point_events(out)) < 2 and time.time() < deadline and proc.poll() is None:
            time.sleep(0.1)
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    finished = {p.parent.name for p in (out / "points").glob("*/result.json")}
    first = {e["id"] for e in point_events(out)}
    print(f"killed after {time.perf_counter() - t:.1f} s with {len(finished)} points recorded")
    assert len(finished) >= 2 and first <= finished
    assert len(finished) < 4, "the sweep finished before it could be interrupted"
    assert not (out / "results.parquet").exists()

    r = run_twin("sweep", one_seed_file, "-o", out, timeout=600)
    print(f"resumed: {time.perf_counter() - t:.1f} s in all")
    starts = [e for e in log(out) if e["event"] == "start"]
    assert len(starts) == 2
    inv = starts[-1]["invocation"]
    (end,) = [e for e in log(out) if e["event"] == "end"]
    assert end["invocation"] == inv
    assert (end["reused"], end["computed"], end["failed"]) == (len(finished), 4 - len(finished), 0)
    second = {e["id"] for e in point_events(out, inv)}
    assert second.isdisjoint(finished) and len(second) == 4 - len(finished)
    # Units: at most 3 per point left; points cut short reuse their finished parts.
    assert end["simulated_units"] + end["reused_units"] == 3 * (4 - len(finished))
    assert f"{len(finished)} reused" in " ".join(r.stderr.split())
    same_as_seed_1_of(default_run, out)


def test_plan_expands_grid_random_and_seeds(root):
    """Grid (explicit, log-spaced), seeded random sampling (log-uniform and uniform, tied keys)
    and seeds expand to the expected points, the same on every reading."""
    import math

    from twin.harness.sweep import plan_sweep

    extra = """[random]
n = 3
seed = 7
[[random.axis]]
key = "phase2.origin_offset_max_mm"
low = 0.5
high = 2.0
scale = "log"
[[random.axis]]
key = ["geometry.straightness_rms_um", "geometry.lateral_straightness_rms_um"]
low = 0.1
high = 1.0
"""
    path = write_sweep(root / "plan", extra=extra)
    plan = plan_sweep(path)
    assert plan.n_points == 2 * 2 * 3 and len(plan.tasks) == 24 and plan.seeds == [1, 2]
    assert plan.primary == ["degradation.table_backlash_um[1]", "sensors.imu_acc_noise_ug_per_rthz",
                            "phase2.origin_offset_max_mm", "geometry.straightness_rms_um"]
    assert plan.log_columns == {"sensors.imu_acc_noise_ug_per_rthz", "phase2.origin_offset_max_mm"}
    noise = sorted({t.values["sensors.imu_acc_noise_ug_per_rthz"] for t in plan.tasks})
    assert noise == [5.0, 20.0]  # geomspace(5, 20, 2)
    draws = [(t.values["phase2.origin_offset_max_mm"], t.values["geometry.straightness_rms_um"])
             for t in plan.tasks[:6:2]]
    assert len(set(draws)) == 3
    assert all(0.5 <= a < 2.0 and 0.1 <= b < 1.0 for a, b in draws)
    # The draws: numpy's default_rng(7) uniforms mapped log-uniformly / uniformly.
    import numpy as np

    u = np.random.default_rng(7).random((3, 2))
    assert draws[0][0] == pytest.approx(math.exp(math.log(0.5) + u[0, 0] * math.log(4.0)), rel=1e-11)
    assert draws[0][1] == pytest.approx(0.1 + 0.9 * u[0, 1], rel=1e-11)
    for t in plan.tasks:
        sc = t.scenario
        assert sc["seed"] == t.seed
        assert sc["degradation"]["table_backlash_um"] == [0.0, t.values["degradation.table_backlash_um[1]"]]
        assert sc["geometry"]["lateral_straightness_rms_um"] == t.values["geometry.straightness_rms_um"]
        assert sc["phase2"]["runs_per_session"] == 1  # from [set]
    again = plan_sweep(path)
    assert [(t.id, t.values) for t in again.tasks] == [(t.id, t.values) for t in plan.tasks]


# ---------------------------------------------------------------------------------------------
# Check 7: bad sweep files


def bad(root, name: str, text: str, out=None, subprocess: bool = False) -> str:
    """Run `twin sweep` on a bad file (in this process through typer's CliRunner, or as a
    subprocess); assert exit code 2 and no traceback; return the message on one line."""
    from typer.testing import CliRunner

    from twin.cli import app

    path = write_sweep(root / "bad", f"{name}.toml", text=text)
    args = ["sweep", str(path), "-o", str(out or root / "bad" / f"out-{name}")]
    if subprocess:
        r = run_twin(*args, check=False)
        code = r.returncode
    else:
        r = CliRunner().invoke(app, args)
        code = r.exit_code
    msg = " ".join(r.stderr.split())
    print(f"{name}: exit {code}: {msg}")
    assert code == 2, msg
    assert "Traceback" not in r.stderr
    assert str(path) in msg
    return msg


def test_bad_sweep_files_exit_2_naming_the_problem(root):
    base = sweep_text(os.path.relpath(STEPS, root / "bad"))
    # An unknown key at the top level, in an axis, in [random].
    msg = bad(root, "unknown-top", "stride = 3\n" + base, subprocess=True)
    assert "unknown key `stride` (value 3)" in msg and "allowed keys at the top level:" in msg
    assert "grid" in msg and "seeds" in msg and "reference" in msg
    msg = bad(root, "unknown-axis", base.replace("num = 2", "num = 2\nstep = 0.5"))
    assert "unknown key `grid[1].step` (value 0.5)" in msg
    assert "allowed keys in [[grid]]: key, values, start, stop, num, scale" in msg
    msg = bad(root, "unknown-random", base + "[random]\nn = 2\nseed = 1\ndraws = 4\n"
              "[[random.axis]]\nkey = \"sensors.torque_noise_Nm\"\nlow = 0.001\nhigh = 0.01\n")
    assert "unknown key `random.draws` (value 4)" in msg and "allowed keys in [random]: n, seed, axis" in msg
    # An empty axis: values = [], num = 0.
    msg = bad(root, "empty", base.replace("values = [5.0, 15.0]", "values = []"))
    assert "axis `degradation.table_backlash_um[1]` (grid[0]) is empty" in msg
    assert "allowed: `values = [numbers...]`" in msg
    msg = bad(root, "num0", base.replace("num = 2", "num = 0"))
    assert "axis `sensors.imu_acc_noise_ug_per_rthz` (grid[1]) is empty" in msg and "`num` >= 1" in msg
    # A non-numeric value.
    msg = bad(root, "text", base.replace("values = [5.0, 15.0]", 'values = [5.0, "lots"]'))
    assert ("key `grid[0].values[1]` of axis `degradation.table_backlash_um[1]` (grid[0]) = 'lots' "
            "is not a number; allowed: an integer or a finite float") in msg
    # A swept key the scenario rejects: its own message, naming the point and the value.
    msg = bad(root, "range", base.replace("start = 5", "start = -5").replace('scale = "log"', ""))
    assert "point 0 (degradation.table_backlash_um[1] = 5.0, sensors.imu_acc_noise_ug_per_rthz = -5.0" in msg
    assert "key `sensors.imu_acc_noise_ug_per_rthz` = -5.0 is out of range; allowed: value >= 0" in msg
    msg = bad(root, "unknown-scenario-key", base.replace(
        'key = "sensors.imu_acc_noise_ug_per_rthz"', 'key = "sensors.imu_noise"'))
    assert "unknown key `sensors.imu_noise` (value 5.0); allowed keys in [sensors]:" in msg
    assert "imu_acc_noise_ug_per_rthz" in msg
    # A fixed override the scenario rejects, an index beyond a list.
    msg = bad(root, "fixed", base.replace('"phase2.runs_per_session" = 1', '"phase2.runs_per_session" = 0'))
    assert "[set] on" in msg and "key `phase2.runs_per_session` = 0 is out of range; allowed: value >= 1" in msg
    msg = bad(root, "index", base.replace("table_backlash_um[1]", "table_backlash_um[2]"))
    assert ("key `degradation.table_backlash_um[2]`: index 2 is beyond the list `table_backlash_um` = "
            "[0.0, 10.0] (length 2); allowed: 0 <= i < 2") in msg


def test_restart_with_another_sweep_file_exits_2(root, default_run):
    before = (default_run / "results.csv").read_text()
    text = sweep_text(os.path.relpath(STEPS, root / "bad")).replace("values = [5.0, 15.0]",
                                                                     "values = [5.0, 12.0]")
    msg = bad(root, "changed", text, out=default_run, subprocess=True)
    assert f"{default_run} holds the results of another sweep" in msg
    assert "`definition.grid[0].values`: [5.0, 15.0] there, [5.0, 12.0] in" in msg
    assert (default_run / "results.csv").read_text() == before
