"""Integrity of what a capture records: no start-up transient in the channels, states and sensors
on one clock, and the analysis package free of simulator imports."""

import ast
from pathlib import Path

import numpy as np

from conftest import REPO
from twin import campaign as cp
from twin.model import Q_X, SENS_NUT1_ACC
from twin.scenario import Scenario
from twin.simulate import Simulator, phase1_capture, phase1_profile

SCEN = Scenario()
WORLD = cp.make_world(SCEN)


def test_phase1_capture_starts_settled():
    """The first 0.1 s of a capture has the same mean as the rest: the carriage starts at rest on
    its rails and the AC-coupled nut accelerometers carry no start-up step (it once carried
    0.3 g)."""
    sim = Simulator(WORLD, SCEN.phase1.timestep_s)
    sig = phase1_capture(sim, SCEN.phase1, cp.condition_at(SCEN, 100.0), cp.rng_for(0, 1, 3))
    fs = int(sig["fs_hz"])
    for ch in ("acc1", "acc2"):
        first = sig[ch][: fs // 10].mean(axis=0)
        rest_std = sig[ch][fs // 2:].std(axis=0)
        print(ch, "mean of the first 0.1 s", first, "std later", rest_std)
        assert np.all(np.abs(first) < 0.02 * rest_std + 0.01)


def test_states_and_sensors_share_one_clock():
    """Row k of qpos and of the MuJoCo sensors are both at t_k: the carriage acceleration from
    the second difference of x lines up with the nut accelerometer at lag 0."""
    sim = Simulator(WORLD, SCEN.phase1.timestep_s)
    cmd = phase1_profile(SCEN.phase1, sim.fs, cp.rng_for(0, 1, 0))
    traj = sim.run(cp.condition_at(SCEN, 100.0), cmd, passes=1)
    x = traj.qpos[:, Q_X]
    acc_x = (x[2:] - 2 * x[1:-1] + x[:-2]) / sim.timestep**2  # acceleration at row k = 1..n-2
    sensor = traj.sens[1:-1, SENS_NUT1_ACC][:, 0]
    # Judge at the edges of the acceleration phases, where a one-step misalignment is 4 m/s².
    edges = np.flatnonzero(np.abs(np.gradient(acc_x)) > 0.5)
    edges = edges[(edges > 5) & (edges < acc_x.size - 5)]
    errs = {lag: np.abs(np.roll(acc_x, lag)[edges] - sensor[edges]).mean() for lag in (-2, -1, 0, 1, 2)}
    print(len(edges), "edge samples;", {k: f"{v:.3f}" for k, v in errs.items()})
    assert len(edges) >= 4
    assert min(errs, key=errs.get) == 0
    assert errs[0] < 0.5 * min(errs[-1], errs[1])


def test_analysis_never_imports_the_simulator():
    for path in Path(REPO / "analysis").rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for name in names:
                assert name.split(".")[0] not in {"twin", "mujoco", "rerun"}, f"{path}: imports {name}"
