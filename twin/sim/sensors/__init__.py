"""The testbed's instruments: what they record, given the true simulated motion.

- :mod:`~twin.sim.sensors.instruments`: the measurement models of the IMU and the ball-nut
  accelerometers (``measure_*``, one recording or many at once); every public name of the package
  is importable from it.
- :mod:`~twin.sim.sensors.errors`: bias, scale-factor error and misalignment of a triaxial sensor.
- :mod:`~twin.sim.sensors.specs`: the instruments' figures (paper defaults) and the "g" constants.
- :mod:`~twin.sim.sensors.chain`: the sensor's response, its group delay and its noise.
- :mod:`~twin.sim.sensors.sampling`: reading a signal at the instrument's instants; quantisation.
- :mod:`~twin.sim.sensors.controller`: motor speed from the encoder, motor torque from the current.

Pure numpy/scipy (no MuJoCo); SI units.
"""
