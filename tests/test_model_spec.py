"""The axis model built with ``mujoco.MjSpec`` is the model the MJCF f-strings built before it
(issue 34, item 4), and its exported MJCF text is exact.

The references in ``tests/data/mjcf-3e88f11/`` are the MJCF text of ``build_mjcf`` at commit
3e88f11, the last f-string builder, written once (``git show 3e88f11:twin/sim/model.py``) for:
- ``default``: ``Scenario()`` at its Phase I step (0.2 ms), rigid base;
- ``foreign-16mm``: ``scenarios/foreign-16mm.toml`` (another lead, travel, mass, friction, drag,
  truck stiffness and servo), rigid base;
- ``backlash-slow-reversal-base``: ``scenarios/backlash-slow-reversal.toml`` (the friction
  solver's ``solreffriction``/``solimpfriction`` set) with a compliant base
  ``BaseMode(1000 kg, 200 Hz, 0.1)`` (the ninth joint ``base_x`` and the fifth wrap of the ball
  nut).
That text printed every float with ``repr`` (the shortest digits that read back as the same
double), so its compiled model carries the builder's floats exactly: the comparison is exact,
no tolerance. They pin the migration; a deliberate change of the axis model or of these
scenarios makes them obsolete (retire them with it: tests/test_model_file.py and the physics
tests cover the model from then on).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from conftest import REPO

from twin.sim.model import BaseMode, build_mjcf, build_model
from twin.sim.scenario import Scenario, load, to_axis

REFERENCES = REPO / "tests" / "data" / "mjcf-3e88f11"
CASES = {
    "default": (lambda: Scenario(), None),
    "foreign-16mm": (lambda: load("foreign-16mm"), None),
    "backlash-slow-reversal-base": (lambda: load("backlash-slow-reversal"), BaseMode(1000.0, 200.0, 0.1)),
}
# nu counts control inputs (19: the two PID actuators take three each), nactuator the actuators (15)
COUNTS = ("nq", "nv", "nbody", "njnt", "ngeom", "nsite", "ntendon", "nwrap", "nactuator", "nu", "na", "nsensor",
          "nsensordata")
KINDS = (("body", "nbody"), ("jnt", "njnt"), ("geom", "ngeom"), ("site", "nsite"), ("tendon", "ntendon"),
         ("actuator", "nactuator"), ("sensor", "nsensor"))
ARRAYS = (
    "body_parentid", "body_pos", "body_quat", "body_ipos", "body_iquat", "body_mass", "body_inertia",
    "jnt_type", "jnt_bodyid", "jnt_qposadr", "jnt_axis", "jnt_pos", "jnt_stiffness", "qpos_spring",
    "dof_damping", "dof_armature", "dof_frictionloss", "dof_solref", "dof_solimp", "dof_invweight0",
    "geom_type", "geom_bodyid", "geom_size", "geom_pos", "geom_quat", "geom_friction", "geom_contype",
    "geom_conaffinity", "geom_rgba", "site_bodyid", "site_pos", "site_size",
    "tendon_adr", "tendon_num", "tendon_limited", "tendon_range", "tendon_solref_lim",
    "tendon_solimp_lim", "tendon_stiffness", "tendon_damping", "tendon_lengthspring",
    "tendon_invweight0", "tendon_margin", "wrap_type", "wrap_objid", "wrap_prm",
    "actuator_trntype", "actuator_trnid", "actuator_gear", "actuator_dyntype", "actuator_gaintype",
    "actuator_biastype", "actuator_gainprm", "actuator_biasprm", "actuator_dynprm", "actuator_ctrlnum",
    "actuator_ctrladr", "actuator_forcelimited", "actuator_forcerange", "actuator_ctrllimited",
    "sensor_type", "sensor_objtype", "sensor_objid", "sensor_dim", "sensor_adr",
)
OPTIONS = ("timestep", "gravity", "integrator", "disableflags", "enableflags", "cone", "solver",
           "iterations", "tolerance")


def _case(name: str):
    make, base = CASES[name]
    s = make()
    return to_axis(s), s.phase1.timestep_s, base


def _binary(model: mujoco.MjModel) -> bytes:
    """The whole compiled model as MuJoCo saves it (MJB, ``mj_saveModel``): every size, array,
    option and name."""
    buf = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return buf.tobytes()


def _names(model: mujoco.MjModel, kind: str, count: str) -> list[str]:
    obj = {"jnt": "joint"}.get(kind, kind)
    return [getattr(model, obj)(i).name for i in range(getattr(model, count))]


@pytest.mark.parametrize("name", list(CASES))
def test_spec_model_equals_the_fstring_model(name):
    axis, dt, base = _case(name)
    old = mujoco.MjModel.from_xml_path(str(REFERENCES / f"{name}.xml"))
    new = build_model(axis, dt, base)
    for count in COUNTS:
        assert getattr(new, count) == getattr(old, count), count
    for kind, count in KINDS:
        assert _names(new, kind, count) == _names(old, kind, count), kind
    for field in ARRAYS:
        a, b = getattr(old, field), getattr(new, field)
        assert a.shape == b.shape and a.dtype == b.dtype, field
        assert np.array_equal(a, b), f"{field}: max |diff| {np.max(np.abs(a - b))}"
    for field in OPTIONS:
        assert np.array_equal(getattr(new.opt, field), getattr(old.opt, field)), f"opt.{field}"
    # and everything else: the saved models are the same bytes
    assert _binary(new) == _binary(old)


@pytest.mark.parametrize("name", list(CASES))
def test_exported_mjcf_compiles_to_the_simulators_model(name):
    """``twin export-model``'s text (``spec.to_xml`` at full precision, see
    twin.sim.model.export) loads back as the same model, bit for bit but for the sign of one zero:
    the ball nut's flank range is (−b/2, b/2) = (−0.0, 0.0) in the new state, and MuJoCo's writer
    leaves out a range equal to its default (0, 0), which reads back as +0.0 (the same number;
    the range is unused while ``limited`` is false, and twin.sim.model.apply_state writes it anew)."""
    axis, dt, base = _case(name)
    text = build_mjcf(axis, dt, base)
    loaded, model = mujoco.MjModel.from_xml_string(text), build_model(axis, dt, base)
    assert np.array_equal(model.tendon_range, loaded.tendon_range)
    for m in (loaded, model):
        m.tendon_range[:] += 0.0  # -0.0 + 0.0 = +0.0
    assert _binary(loaded) == _binary(model)
    assert 'limited="false"' in text
