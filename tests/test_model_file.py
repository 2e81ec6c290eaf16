"""The shipped MJCF in models/ is the model the simulator builds (it cannot go stale)."""

import mujoco

from conftest import REPO
from twin.model import NCTRL, build_mjcf
from twin.scenario import Scenario, to_axis


def test_models_file_matches_builder():
    shipped = (REPO / "models/linear_axis.xml").read_text()
    assert shipped == build_mjcf(to_axis(Scenario()), 1e-4), \
        "models/linear_axis.xml is stale: run `twin export-model`"
    model = mujoco.MjModel.from_xml_path(str(REPO / "models/linear_axis.xml"))
    assert model.nu == NCTRL and model.nv == 8 and model.ntendon == 9
