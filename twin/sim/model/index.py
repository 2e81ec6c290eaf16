"""Where the simulator's controls, sensors and joints sit in a compiled axis model
(:class:`ModelIndex`, looked up by name), and the error a model without one of them raises."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

_RAILS = range(4)


class ModelLayoutError(RuntimeError):
    """The compiled model lacks a named element the simulator drives or reads."""


@dataclass(frozen=True)
class ModelIndex:
    """Where the simulator's controls, sensors and joints sit in a compiled axis model, looked up
    once by name (``model.actuator("servo")``, ``model.sensor("imu_acc")``, ``model.joint(...)``).

    Columns of ``data.ctrl`` (the ``<pid>`` actuators take three inputs: position, velocity,
    feed-forward): ``servo_pos``, ``servo_vel``, ``servo_ff``, ``ripple`` (screw torque, N*m),
    ``flank_pos``, ``flank_vel``, ``flank_ff`` (the lead flank), ``truck_v``, ``truck_l`` (4,)
    rail force pairs of the trucks FL FR RL RR (N), ``runout`` (2,) y, z forces at the nut (N),
    ``nut_axial``, ``stribeck`` (N). Columns of ``data.sensordata``: ``imu_acc``, ``imu_gyro``,
    ``nut1_acc``, ``nut2_acc`` (3 each) and ``servo_torque``. Entries of ``data.qpos``:
    ``screw`` (rad), ``x``, ``y``, ``z`` (m), ``roll``, ``pitch``, ``yaw`` (rad), ``flank`` (m),
    ``base`` (m; None without a compliant base). ``pose`` (5,): y, z, roll, pitch, yaw.
    """

    nu: int
    servo_pos: int
    servo_vel: int
    servo_ff: int
    ripple: int
    flank_pos: int
    flank_vel: int
    flank_ff: int
    truck_v: np.ndarray
    truck_l: np.ndarray
    runout: np.ndarray
    nut_axial: int
    stribeck: int
    imu_acc: slice
    imu_gyro: slice
    nut1_acc: slice
    nut2_acc: slice
    servo_torque: int
    screw: int
    x: int
    y: int
    z: int
    roll: int
    pitch: int
    yaw: int
    flank: int
    base: int | None
    pose: np.ndarray

    @classmethod
    def of(cls, model: mujoco.MjModel) -> ModelIndex:
        """Look every element up by name; a missing one raises :class:`ModelLayoutError`."""
        def element(kind: str, name: str):
            try:
                return getattr(model, kind)(name)
            except KeyError:
                raise ModelLayoutError(f"the axis model has no {kind} named {name!r}; the simulator "
                                       f"drives or reads it (see twin.sim.model.build_spec)") from None

        def ctrl(name: str, inputs: int = 1) -> int:
            i = element("actuator", name).id
            if model.actuator_ctrlnum[i] != inputs:
                raise ModelLayoutError(f"actuator {name!r} takes {model.actuator_ctrlnum[i]} control "
                                       f"inputs; the simulator writes {inputs}")
            return int(model.actuator_ctrladr[i])

        def sensor(name: str, dim: int) -> slice:
            i = element("sensor", name).id
            if model.sensor_dim[i] != dim:
                raise ModelLayoutError(f"sensor {name!r} has dimension {model.sensor_dim[i]}; expected {dim}")
            return slice(int(model.sensor_adr[i]), int(model.sensor_adr[i]) + dim)

        def qpos(name: str) -> int:
            return int(element("joint", name).qposadr[0])

        servo, flank = ctrl("servo", 3), ctrl("lead_flank", 3)
        pose = np.array([qpos(n) for n in ("carriage_y", "carriage_z", "carriage_roll", "carriage_pitch",
                                           "carriage_yaw")])
        has_base = any(model.joint(i).name == "base_x" for i in range(model.njnt))
        return cls(
            nu=int(model.nu), servo_pos=servo, servo_vel=servo + 1, servo_ff=servo + 2, ripple=ctrl("ripple"),
            flank_pos=flank, flank_vel=flank + 1, flank_ff=flank + 2,
            truck_v=np.array([ctrl(f"rail_v{i}") for i in _RAILS]),
            truck_l=np.array([ctrl(f"rail_l{i}") for i in _RAILS]),
            runout=np.array([ctrl("runout_y"), ctrl("runout_z")]),
            nut_axial=ctrl("nut_axial"), stribeck=ctrl("rail_stribeck"),
            imu_acc=sensor("imu_acc", 3), imu_gyro=sensor("imu_gyro", 3), nut1_acc=sensor("nut1_acc", 3),
            nut2_acc=sensor("nut2_acc", 3), servo_torque=sensor("servo_torque", 1).start,
            screw=qpos("screw"), x=qpos("carriage_x"), y=int(pose[0]), z=int(pose[1]), roll=int(pose[2]),
            pitch=int(pose[3]), yaw=int(pose[4]), flank=qpos("lead_flank"),
            base=qpos("base_x") if has_base else None, pose=pose)
