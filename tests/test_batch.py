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
