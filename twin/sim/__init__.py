"""The simulator: the scenario and its defaults, the MuJoCo model of the axis, the rails and the
screw, the drive, the sensors, the degradation over operating hours, and the campaigns that
write ``measurements.h5`` and ``truth.h5``. It imports ``analysis`` (the dataset format, the
shared base) and nothing of ``twin.harness`` or ``twin.cli``."""
