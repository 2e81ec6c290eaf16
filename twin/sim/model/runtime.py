"""What the simulator computes from a compiled axis model at run time: the physics state at
rest (:func:`initial_state`) and the correction that turns MuJoCo's accelerometer readings into
the acceleration the implicit integrator applies (:func:`accelerometer_implicit_correction`)."""

from __future__ import annotations

import mujoco
import numpy as np

from twin.sim.model.index import ModelIndex


def initial_state(model: mujoco.MjModel, x0: float, theta0: float, flank0: float = 0.0,
                  pose: np.ndarray | None = None) -> np.ndarray:
    """Full physics state at rest: carriage at ``x0`` m, screw at ``theta0`` rad, lead flank at
    ``flank0`` m, and the carriage's (y, z, roll, pitch, yaw) ``pose`` (5,) m/rad (default 0)."""
    data = mujoco.MjData(model)
    data.joint("screw").qpos[0] = theta0
    data.joint("carriage_x").qpos[0] = x0
    data.joint("lead_flank").qpos[0] = flank0
    if pose is not None:
        data.qpos[ModelIndex.of(model).pose] = pose
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    mujoco.mj_forward(model, data)
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    return state


def accelerometer_implicit_correction(model: mujoco.MjModel, state: np.ndarray,
                                      ctrl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What turns MuJoCo's accelerometer readings into the acceleration the integrator applies.

    With the ``implicit`` and ``implicitfast`` integrators MuJoCo advances the velocity by
    v' = v + h·a_i with (M − h·D)·a_i = f, D the derivative of the passive and actuator forces
    with respect to the velocity (MuJoCo documentation, Computation chapter, "Numerical
    integration"; mujoco.readthedocs.io), while ``mjData.qacc``, from which the accelerometers
    are computed in ``mj_forward`` before the step, is the explicit a = M⁻¹·f. So
    a = a_i − h·M⁻¹·D·a_i, and an accelerometer reads −h·Sᵀ·J·M⁻¹·D·a_i more than a_i gives
    (S the site's orientation, J its translational Jacobian; MuJoCo keeps in D only the entries
    of its sparsity pattern ``D_rownnz``/``D_colind``, within a kinematic tree: a tendon's
    damping between the carriage and the screw enters a_i through its carriage entries alone).
    The integrated velocity differs from the integral of the reading by that amount: 0.65 % of
    the carriage's acceleration along the travel with the nut's passive damper (b = 0), the
    lever arm of the pitch acceleration 1.3 % long through the trucks' dampers.

    D is MuJoCo's own (``mjData.qDeriv`` after one step from ``state`` under ``ctrl``); M, J and S
    at ``state`` (the pose changes by µrad, the passive and actuator damping of the carriage's
    joints are linear). Returns (cols, G): the ``sensordata`` columns of every accelerometer and
    G (len(cols), nv) such that the reading of the applied acceleration a_i (n, nv) is
    ``sens[:, cols] + a_i @ G.T``.

    Raises ValueError for another integrator (the axis model uses implicitfast)."""
    if model.opt.integrator not in (mujoco.mjtIntegrator.mjINT_IMPLICIT,
                                    mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
        raise ValueError(f"accelerometer_implicit_correction: integrator {model.opt.integrator}; "
                         "expected implicitfast or implicit (the correction is theirs)")
    acc = [i for i in range(model.nsensor) if model.sensor_type[i] == mujoco.mjtSensor.mjSENS_ACCELEROMETER]
    cols = np.concatenate([np.arange(model.sensor_adr[i], model.sensor_adr[i] + 3) for i in acc]
                          ) if acc else np.zeros(0, dtype=int)
    nv = model.nv
    gain = np.zeros((cols.size, nv))
    if not acc:
        return cols, gain
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state, spec)
    data.ctrl[:] = ctrl
    mujoco.mj_step(model, data)  # fills qDeriv, the D of this step
    damping = np.zeros((nv, nv))
    for i in range(nv):
        a = model.D_rowadr[i]
        damping[i, model.D_colind[a:a + model.D_rownnz[i]]] = data.qDeriv[a:a + model.D_rownnz[i]]
    mujoco.mj_setState(model, data, state, spec)
    mujoco.mj_forward(model, data)
    minv_d = np.zeros((nv, nv))
    mujoco.mj_solveM(model, data, minv_d, np.ascontiguousarray(damping.T))  # rows: M⁻¹·(columns of D)
    minv_d = minv_d.T
    jac = np.zeros((3, nv))
    for k, i in enumerate(acc):
        site = model.sensor_objid[i]
        mujoco.mj_jacSite(model, data, jac, None, site)
        rot = data.site_xmat[site].reshape(3, 3)
        gain[3 * k:3 * k + 3] = model.opt.timestep * rot.T @ jac @ minv_d
    return cols, gain
