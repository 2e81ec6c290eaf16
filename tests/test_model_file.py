"""The shipped MJCF in models/ is the simulator's model of the new axis (it cannot go stale),
and it is complete: loaded on its own it holds still."""

import mujoco
import numpy as np
from conftest import REPO

from twin.sim.model import ModelIndex, build_mjcf, build_model
from twin.sim.scenario import Scenario, to_axis

#: Columns of qpos, sens and ctrl of the axis model, looked up by name.
IX = ModelIndex.of(build_model(to_axis(Scenario()), 2e-4))



def test_models_file_matches_builder_and_holds_still():
    s = Scenario()
    shipped = (REPO / "models/linear_axis.xml").read_text()
    assert shipped == build_mjcf(to_axis(s), s.phase1.timestep_s), \
        "models/linear_axis.xml is stale: run `twin export-model`"
    model = mujoco.MjModel.from_xml_path(str(REPO / "models/linear_axis.xml"))
    assert model.nu == IX.nu and model.nv == 8 and model.ntendon == 9
    data = mujoco.MjData(model)
    data.qpos[IX.x] = 0.2
    data.qpos[IX.screw] = 0.2 / to_axis(s).screw.radius_per_rad
    data.ctrl[0] = data.qpos[IX.screw]
    for _ in range(int(0.5 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    print("after 0.5 s: x", data.qpos[IX.x], "z", data.qpos[IX.z])
    assert abs(data.qpos[IX.x] - 0.2) < 1e-6 and abs(data.qpos[IX.z]) < 1e-6
    assert np.all(model.tendon_stiffness > 1e7)
