"""The simulated accelerometers read the acceleration the integrator applies.

MuJoCo's ``implicitfast`` step advances the velocity with (M − h·D)⁻¹·f, D the derivative of the
passive and actuator forces with respect to the velocity, while its accelerometer sensors are
computed from the explicit M⁻¹·f (MuJoCo documentation, Computation chapter, "Numerical
integration"). Uncorrected, the IMU of a b = 0 axis (the ball nut's passive damper, D's
carriage entry −C) read 0.65 % more than the carriage's acceleration along the travel, so the
velocity integrated from the IMU ran ahead of the carriage on every ramp; the rest-side travel of
the IMU stroke timing (``analysis.phase2.strokes.rest_side_deficit``) came out 0.6–0.9 µm short
at b = 0 and not with a clearance (whose contact is a constraint, not in D), which moved Eq. 9 on
the IMU axis by about +1 µm for every backlash step (docs/error-motions.md, the Eq. 9 gate).
``twin.sim.model.accelerometer_implicit_correction`` removes it; this test checks the result on
the first acceleration ramp of a slow Phase II move, with and without a clearance: the IMU's x
reading, its gravity projection removed, integrated over the ramp, against the IMU site's
velocity change in the simulated state (``mj_objectVelocity``).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from twin.sim.campaign import condition_at, make_world
from twin.sim.model import MechanicalState, accelerometer_implicit_correction, apply_state, build_model
from twin.sim.scenario import Scenario, load, to_axis
from twin.sim.simulate import Simulator, phase2_trajectory

GRAVITY = 9.80665
SETS = ["campaign.phase1=false", "phase2.runs_per_session=1", "phase2.session_hours=[100.0]",
        "phase2.speeds_mm_s=[20.0]", "phase2.accel_mm_s2=50.0", "phase2.start_mm=100.0",
        "phase2.end_mm=120.0", "phase2.dwell_s=0.3", "degradation.law=table",
        "degradation.table_hours=[0.0, 1000.0]", "degradation.table_preload_fraction=[1.0, 1.0]",
        "degradation.table_backlash_um=[0.0, 0.0]", "axis.friction_timeconst_ms=0.4",
        "axis.friction_impedance=0.999", 'phase2.start_flank="last"']


def _site_velocity_x(sim: Simulator, qpos: np.ndarray, qvel: np.ndarray) -> float:
    """The IMU site's linear velocity along its own x axis, m/s."""
    m, d = sim.model, mujoco.MjData(sim.model)
    d.qpos[:], d.qvel[:] = qpos, qvel
    mujoco.mj_forward(m, d)
    v = np.zeros(6)
    mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, m.site("imu").id, v, 1)  # site frame
    return float(v[3])


@pytest.mark.parametrize("backlash_um", [0.0, 5.0])
def test_imu_reads_the_applied_acceleration(backlash_um):
    s = load("quick", SETS)
    sim = Simulator(make_world(s), s.phase2.timestep_s)
    cond = condition_at(s, 100.0)
    cond = dataclasses.replace(cond, mech=dataclasses.replace(cond.mech, backlash=backlash_um * 1e-6))
    traj = phase2_trajectory(sim, s.phase2, cond)
    ix, dt = traj.index, sim.timestep
    v_cmd = np.interp(traj.t, traj.cmd.t, traj.cmd.v)
    k0 = int(np.flatnonzero(v_cmd != 0.0)[0])  # the first move's first commanded step
    k1 = k0 + int(round((0.02 / 0.05 + 0.1) / dt))  # the ramp (0.4 s) and 0.1 s of cruise
    f_x = traj.sens[k0:k1, ix.imu_acc][:, 0]
    # the accelerometer's reading of gravity along its x axis: −g·sin(pitch) (µrad: roll and
    # yaw enter at their products)
    gravity = -GRAVITY * np.sin(traj.qpos[k0:k1, ix.pitch])
    integrated = float(np.sum(f_x - gravity) * dt)
    true = (_site_velocity_x(sim, traj.qpos[k1], traj.qvel[k1])
            - _site_velocity_x(sim, traj.qpos[k0], traj.qvel[k0]))
    rel = integrated / true - 1.0
    print(f"\nb = {backlash_um:g} µm: IMU's velocity change over the ramp {integrated * 1e3:.5f} mm/s, "
          f"the site's {true * 1e3:.5f} mm/s, relative {rel:+.2e}")
    assert abs(true - 0.02) < 0.002
    # uncorrected: +6.5e-3 at b = 0 (the nut's passive damper); the sum of rows against the
    # state's velocity change is exact up to the µrad changes of the pose
    assert abs(rel) < 1e-5


def test_correction_is_the_integrators():
    """At b = 0 the gain of the IMU's x reading on the carriage's x acceleration is that of the nut's
    passive damper C alone, as MuJoCo's D keeps it (its carriage entries: −C on x, −C·z_n between
    x and pitch; the screw's and the flank's are in other trees): −h·C·(1/m + z_i·z_n/I_yy), z_i
    the IMU's height above the centre of mass. With a clearance the damper is in the contact
    constraint, not in D, and the gain is 0. Another integrator is refused."""
    axis = to_axis(Scenario())
    dt = Scenario().phase2.timestep_s
    model = build_model(axis, dt)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    cols, gain = accelerometer_implicit_correction(model, state, np.zeros(model.nu))
    n_acc = int(np.sum(model.sensor_type == mujoco.mjtSensor.mjSENS_ACCELEROMETER))
    assert cols.size == 3 * n_acc and gain.shape == (cols.size, model.nv)
    imu = model.sensor("imu_acc").adr[0]
    row = int(np.flatnonzero(cols == imu)[0])
    x = model.joint("carriage_x").dofadr[0]
    c = axis.carriage
    damper = float(model.tendon_damping[model.tendon("ballnut").id])
    z_i, z_n = float(model.site("imu").pos[2]), c.nut_height - c.com_height
    expected = -dt * damper * (1.0 / c.mass + z_i * z_n / c.inertia[1])
    print(f"\nIMU x gain on a_x: {gain[row, x]:+.6f} (−h·C·(1/m + z_i·z_n/I_yy) = {expected:+.6f})")
    assert damper > 0.0
    assert gain[row, x] == pytest.approx(expected, rel=1e-6)
    apply_state(model, axis, MechanicalState(preload=axis.screw.preload, backlash=5e-6))
    cols, gain = accelerometer_implicit_correction(model, state, np.zeros(model.nu))
    assert gain[row, x] == 0.0
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    with pytest.raises(ValueError, match="implicitfast"):
        accelerometer_implicit_correction(model, state, np.zeros(model.nu))
