"""IMU misalignment and scale error.

The IMU case is never mounted exactly square to the carriage, and the accelerometer's
sensitivity differs from its data-sheet value. A rotation ε of the sensing axes projects gravity
and the motion into the wrong axes (a pitch misalignment ε_y puts g·ε_y on the X
accelerometer); a scale error s multiplies every reading, gravity on Z included (IEEE Std
1293-2018, accelerometer model equation: scale factor, misalignment; Titterton & Weston,
Strapdown Inertial Navigation Technology, 2nd ed., ch. 8).

Parameters: pitch_urad, the misalignment about Y (``sensors.imu_misalignment_urad[1]``), and
scale_ppm, a common scale error of the three accelerometer axes
(``sensors.imu_acc_scale_error[0..2]``, in 1e-6). It acts on the dwell means of the IMU
accelerometer (gravity) and the amplitude of its signal in the transients.
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

_SCALE = tuple(f"sensors.imu_acc_scale_error[{i}]" for i in range(3))

EFFECT = register_effect(Effect(
    name="imu_misalignment",
    title="IMU misalignment and scale error",
    params=(Param("pitch_urad", keys=("sensors.imu_misalignment_urad[1]",), mode="add", low=500.0,
                  high=5000.0, grid=(-5000.0, 0.0, 5000.0), log=True, signed=True,
                  label="IMU pitch misalignment", unit="µrad"),
            Param("scale_ppm", keys=_SCALE, mode="add", low=500.0, high=5000.0,
                  grid=(-5000.0, 0.0, 5000.0), log=True, signed=True, factor=1e-6,
                  label="IMU accelerometer scale error", unit="ppm")),
    source="accelerometer scale factor and misalignment model (IEEE Std 1293-2018)",
))
