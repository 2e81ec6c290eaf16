"""Degradation states differ only in float fields, so several run in one mujoco.rollout call and
give exactly the trajectories of separate runs."""

import numpy as np

from twin.sim import campaign as cp
from twin.sim.drive import command_profile
from twin.sim.scenario import Scenario
from twin.sim.simulate import Simulator, phase2_moves


def test_batched_conditions_equal_single_runs():
    s = Scenario()
    sim = Simulator(cp.make_world(s), 2e-4)
    p2 = s.phase2.model_copy(update={"dwell_s": 0.3, "speeds_mm_s": [100.0], "end_mm": 100.0})
    cmd = command_profile(phase2_moves(p2), sim.fs, lead_in=0.3)
    conds = [cp.condition_at(s, h, 0.001 * i) for i, h in enumerate([100.0, 4000.0, 7000.0])]
    assert conds[2].mech.backlash > 5e-6 > conds[0].mech.backlash
    batch = sim.run_batch(conds, cmd)
    for cond, b in zip(conds, batch, strict=True):
        single = sim.run(cond, cmd)
        np.testing.assert_array_equal(single.qpos, b.qpos)
        np.testing.assert_array_equal(single.sens, b.sens)
    # and the states really differ: backlash shows in the carriage position
    assert np.abs(batch[0].qpos[:, 1] - batch[2].qpos[:, 1] - 0.002).max() > 1e-6


def test_a_rollout_takes_one_thread_unless_told_and_threads_change_nothing(monkeypatch):
    """The cores are the worker processes' (``--workers``): one ``mujoco.rollout`` call runs on one
    thread by default whatever the machine (a ``--workers 1`` command used to take two cores), and
    the trajectories are the same on any number of threads."""
    import os

    from twin.sim.simulate import simulator

    threads: list[int] = []
    real = simulator.rollout.rollout

    def counted(models, datas, *args, **kw):
        threads.append(len(datas))
        return real(models, datas, *args, **kw)

    monkeypatch.setattr(simulator.rollout, "rollout", counted)
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    s = Scenario()
    sim = Simulator(cp.make_world(s), 2e-4)
    p2 = s.phase2.model_copy(update={"dwell_s": 0.2, "speeds_mm_s": [100.0], "end_mm": 60.0})
    cmd = command_profile(phase2_moves(p2), sim.fs, lead_in=0.2)
    conds = [cp.condition_at(s, h, 0.0) for h in (100.0, 7000.0, 8000.0)]
    one = sim.run_batch(conds, cmd, passes=1)
    assert threads and set(threads) == {1}
    threads.clear()
    three = sim.run_batch(conds, cmd, passes=1, nthread=3)
    assert set(threads) == {3}
    for a, b in zip(one, three, strict=True):
        np.testing.assert_array_equal(a.qpos, b.qpos)
        np.testing.assert_array_equal(a.sens, b.sens)
